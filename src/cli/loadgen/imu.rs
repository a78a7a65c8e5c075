//! The raw-IMU workload of `navguard loadgen --input imu`: a synthetic car's exact IMU
//! rates at 100 Hz with a 1 Hz GNSS fix on every 100th epoch, for a `federated` monitor
//! with `input: imu` (docs/performance.md, "Raw IMU sessions at 100 Hz").
//!
//! The car stands still for [`STATIC_S`] (long enough for the drive config's levelling),
//! accelerates forward at [`ACCEL_MPS2`] to [`CRUISE_MPS`], then weaves gently (the
//! heading rate a sine of [`TURN_RATE_DPS`] amplitude), level throughout. The body
//! motion is integrated into ENU position and velocity, and the rates follow from the
//! mechanization equations solved for the sensors (as `navguard_sim`'s truth does):
//! `fⁿ = v̇ⁿ + (2ω_ie + ω_en) × vⁿ + [0, 0, γ]`, `f_b = C_nᵇ fⁿ`,
//! `ω_ib^b = C_nᵇ (ω_ie + ω_en) + ω_nb^b`. The seed picks the start position and heading,
//! so sessions on different seeds differ.

use nalgebra::{Matrix3, Vector3};
use navguard_core::epoch::{Epoch, GnssBlock, ImuBlock};
use navguard_core::geo::{self, Lla};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde_json::Value;

/// IMU sampling rate, Hz.
pub(super) const IMU_RATE_HZ: f64 = 100.0;
/// A GNSS fix rides on every this many IMU epochs (1 Hz).
pub(super) const GNSS_EVERY: usize = 100;
/// Standing still first, s: the drive config levels over 10 s.
pub(super) const STATIC_S: f64 = 12.0;
/// Forward acceleration while speeding up, m/s².
pub(super) const ACCEL_MPS2: f64 = 1.0;
/// Cruising speed, m/s.
pub(super) const CRUISE_MPS: f64 = 10.0;
/// When the weaving starts, s (3 s after reaching the cruising speed).
const TURN_START_S: f64 = STATIC_S + CRUISE_MPS / ACCEL_MPS2 + 3.0;
/// Peak heading rate of the weaving, °/s (0.5 m/s² sideways at cruise).
pub(super) const TURN_RATE_DPS: f64 = 3.0;
/// Period of the weaving, s.
const TURN_PERIOD_S: f64 = 40.0;

/// The body motion at one instant: level, no sideslip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Motion {
    /// Forward speed, m/s.
    pub(super) speed: f64,
    /// Forward acceleration, m/s².
    pub(super) accel: f64,
    /// Heading, rad clockwise from north.
    pub(super) heading: f64,
    /// Heading rate, rad/s.
    pub(super) heading_rate: f64,
}

impl Motion {
    /// The motion `t` seconds into the drive, starting at `heading0` (rad).
    pub(super) fn at(t: f64, heading0: f64) -> Motion {
        let accel_end = STATIC_S + CRUISE_MPS / ACCEL_MPS2;
        let (speed, accel) = if t < STATIC_S {
            (0.0, 0.0)
        } else if t < accel_end {
            (ACCEL_MPS2 * (t - STATIC_S), ACCEL_MPS2)
        } else {
            (CRUISE_MPS, 0.0)
        };
        // ψ̇ = A sin(2π s / P) from TURN_START_S, so ψ = ψ0 + A P / 2π (1 − cos(2π s / P)).
        let (heading, heading_rate) = if t < TURN_START_S {
            (heading0, 0.0)
        } else {
            let a = TURN_RATE_DPS.to_radians();
            let phase = std::f64::consts::TAU * (t - TURN_START_S) / TURN_PERIOD_S;
            (
                heading0 + a * TURN_PERIOD_S / std::f64::consts::TAU * (1.0 - phase.cos()),
                a * phase.sin(),
            )
        };
        Motion {
            speed,
            accel,
            heading,
            heading_rate,
        }
    }

    /// Velocity east, north, up, m/s.
    pub(super) fn vel_enu(&self) -> Vector3<f64> {
        let (s, c) = self.heading.sin_cos();
        Vector3::new(self.speed * s, self.speed * c, 0.0)
    }

    /// `v̇ⁿ`: the forward acceleration plus the turn's centripetal part, m/s².
    fn vel_dot_enu(&self) -> Vector3<f64> {
        let (s, c) = self.heading.sin_cos();
        let turn = self.speed * self.heading_rate;
        Vector3::new(self.accel * s + turn * c, self.accel * c - turn * s, 0.0)
    }

    /// `C_bⁿ` of the level body at this heading.
    fn c_bn(&self) -> Matrix3<f64> {
        geo::dcm_body_to_nav(0.0, 0.0, self.heading)
    }
}

/// One epoch of the drive: what is sent, and the truth at its time.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct DriveEpoch {
    /// The epoch: `imu` rates, and `gnss` on every [`GNSS_EVERY`]th.
    pub(super) epoch: Epoch,
    /// True position.
    pub(super) lla: Lla,
    /// True motion.
    pub(super) motion: Motion,
}

/// The start position (around 40° N, 105° W, 1,600 m) and heading (rad) of `seed`'s drive.
pub(super) fn start_of(seed: u64) -> (Lla, f64) {
    let mut rng = StdRng::seed_from_u64(seed);
    let lla = Lla {
        lat: (40.0 + rng.random_range(-0.5..0.5f64)).to_radians(),
        lon: (-105.0 + rng.random_range(-0.5..0.5f64)).to_radians(),
        h: 1600.0,
    };
    (lla, rng.random_range(0.0..std::f64::consts::TAU))
}

/// The first `epochs` epochs of `seed`'s drive. From `fault_at` (s) on, every GNSS fix is
/// moved `fault_step_m` north (a position step fault); the truth is not.
pub(super) fn drive(
    epochs: usize,
    seed: u64,
    fault_at: Option<f64>,
    fault_step_m: f64,
) -> Vec<DriveEpoch> {
    let (mut lla, heading0) = start_of(seed);
    let dt = 1.0 / IMU_RATE_HZ;
    let mut out = Vec::with_capacity(epochs);
    let mut last_vel = Vector3::zeros();
    for k in 0..epochs {
        let t = k as f64 / IMU_RATE_HZ;
        let motion = Motion::at(t, heading0);
        let vel = motion.vel_enu();
        if k > 0 {
            // Trapezoid of the velocity over the step.
            lla = geo::apply_offset(&lla, &((last_vel + vel) * (0.5 * dt)));
        }
        last_vel = vel;
        let (f_b, w_b) = body_rates(&lla, &motion);
        let gnss = (k % GNSS_EVERY == 0).then(|| {
            let fix = match fault_at {
                Some(at) if t >= at => {
                    geo::apply_offset(&lla, &Vector3::new(0.0, fault_step_m, 0.0))
                }
                _ => lla,
            };
            GnssBlock {
                lat: fix.lat,
                lon: fix.lon,
                h: fix.h,
                vel: Some(vel.into()),
                pos_sigma: None,
                vel_sigma: None,
            }
        });
        out.push(DriveEpoch {
            epoch: Epoch {
                t,
                gnss,
                imu: Some(ImuBlock {
                    accel: f_b.into(),
                    gyro: w_b.into(),
                    dt: None,
                }),
                ..Epoch::default()
            },
            lla,
            motion,
        });
    }
    out
}

/// The exact specific force (m/s²) and angular rate (rad/s) in the body frame.
fn body_rates(lla: &Lla, m: &Motion) -> (Vector3<f64>, Vector3<f64>) {
    let vel = m.vel_enu();
    let w_ie = geo::earth_rate_enu(lla.lat);
    let w_en = geo::transport_rate_enu(lla.lat, lla.h, &vel);
    let f_n = m.vel_dot_enu()
        + (2.0 * w_ie + w_en).cross(&vel)
        + Vector3::new(0.0, 0.0, geo::normal_gravity(lla.lat, lla.h));
    let c_nb = m.c_bn().transpose();
    // Heading grows clockwise seen from above: a turn about the body's −up axis.
    let w_nb = Vector3::new(0.0, 0.0, -m.heading_rate);
    (c_nb * f_n, c_nb * (w_ie + w_en) + w_nb)
}

/// The monitor config: the real drive's (`navguard experiment drive`), with the IMU
/// mounted along the body axes and the antenna on it, as the synthetic rates are.
pub(super) fn monitor_config() -> Value {
    let mut config =
        navguard_sim::drive_config::drive_config(&navguard_sim::drive_config::AidNoise::default());
    config["strapdown"]["mounting_deg"] = serde_json::json!([0.0, 0.0, 0.0]);
    config["strapdown"]["gnss_lever_arm_m"] = serde_json::json!([0.0, 0.0, 0.0]);
    config
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use navguard_core::detect::{Health, PolicyConfig, ThresholdSpec};
    use navguard_core::monitor::federated::{Alignment, FederatedConfig, FederatedMonitor};
    use navguard_core::monitor::{Monitor, Outputs};
    use navguard_core::strapdown::{Increments, Strapdown};

    /// 60 s of the drive.
    const EPOCHS: usize = 6_000;

    #[test]
    fn standing_still_the_specific_force_is_normal_gravity_and_the_rate_the_earths() {
        let d = drive(1_000, 7, None, 0.0);
        for e in &d {
            let imu = e.epoch.imu.unwrap();
            let g = geo::normal_gravity(e.lla.lat, e.lla.h);
            assert_relative_eq!(Vector3::from(imu.accel).norm(), g, max_relative = 1e-12);
            assert_relative_eq!(
                Vector3::from(imu.gyro).norm(),
                geo::OMEGA_IE,
                max_relative = 1e-12
            );
        }
    }

    #[test]
    fn a_fix_rides_on_every_hundredth_epoch_with_the_true_velocity() {
        let d = drive(1_001, 3, None, 0.0);
        for (k, e) in d.iter().enumerate() {
            assert_eq!(e.epoch.gnss.is_some(), k % GNSS_EVERY == 0, "epoch {k}");
            assert_relative_eq!(e.epoch.t, k as f64 / IMU_RATE_HZ);
        }
        assert_eq!(d.iter().filter(|e| e.epoch.gnss.is_some()).count(), 11);
        let g = d[0].epoch.gnss.as_ref().unwrap();
        assert_eq!(
            (g.lat, g.lon, g.h),
            (d[0].lla.lat, d[0].lla.lon, d[0].lla.h)
        );
    }

    #[test]
    fn mechanizing_the_rates_reproduces_the_speed_profile_and_the_track() {
        let d = drive(EPOCHS, 2, None, 0.0);
        let first = &d[0];
        let c0 = geo::dcm_body_to_nav(0.0, 0.0, first.motion.heading);
        let mut mech = Strapdown::new(first.lla, Vector3::zeros(), c0);
        let dt = 1.0 / IMU_RATE_HZ;
        for pair in d.windows(2) {
            let (a, b) = (pair[0].epoch.imu.unwrap(), pair[1].epoch.imu.unwrap());
            let mean = |x: [f64; 3], y: [f64; 3]| (Vector3::from(x) + Vector3::from(y)) * 0.5;
            mech.step(&Increments {
                dtheta: (mean(a.gyro, b.gyro) * dt).into(),
                dv: (mean(a.accel, b.accel) * dt).into(),
                dt,
            });
            let truth = &pair[1];
            let t = truth.epoch.t;
            // Speed up at 1 m/s² from 12 s, 10 m/s from 22 s on.
            let profile = (ACCEL_MPS2 * (t - STATIC_S)).clamp(0.0, CRUISE_MPS);
            assert_relative_eq!(truth.motion.speed, profile, epsilon = 1e-9);
            let dv = mech.vel() - truth.motion.vel_enu();
            assert!(dv.norm() < 0.05, "t {t}: velocity off by {dv}");
        }
        let last = d.last().unwrap();
        let off = geo::local_offset(&mech.lla(), &last.lla);
        assert!(off.norm() < 1.0, "after 60 s the track is {off} m off");
        // The weaving turns the car by up to 2 A P / 2π = 38°.
        let turned = d
            .iter()
            .map(|e| (e.motion.heading - first.motion.heading).to_degrees())
            .fold(0.0f64, f64::max);
        assert!((35.0..40.0).contains(&turned), "turned {turned}°");
    }

    #[test]
    fn the_drive_is_the_same_for_a_seed_and_differs_between_seeds() {
        assert_eq!(drive(300, 5, None, 0.0), drive(300, 5, None, 0.0));
        let (a, b) = (drive(300, 5, None, 0.0), drive(300, 6, None, 0.0));
        assert_ne!(a[0].lla, b[0].lla);
        assert_ne!(a[0].motion.heading, b[0].motion.heading);
    }

    #[test]
    fn the_drive_monitor_aligns_then_runs_the_gnss_test_without_alarms() {
        let config = FederatedConfig::from_json(&monitor_config()).unwrap();
        let mut m = FederatedMonitor::new(
            config,
            PolicyConfig::Counters { n1: 10, n2: 5 },
            ThresholdSpec::PFa(1e-3),
        )
        .unwrap();
        let mut aligned_at = None;
        let mut gnss_tests = 0;
        for e in drive(EPOCHS, 4, None, 0.0) {
            let r = m.step(&e.epoch).unwrap();
            let Outputs::Federated { alignment, .. } = &r.outputs else {
                panic!("a federated report");
            };
            if *alignment == Some(Alignment::Aligned) && aligned_at.is_none() {
                aligned_at = Some(e.epoch.t);
            }
            for test in &r.tests {
                assert_eq!(test.decision.health, Health::Healthy, "t {}", e.epoch.t);
                gnss_tests += usize::from(&*test.name == "gnss");
            }
        }
        // Levelled over the stop, heading from the first fix at 3 m/s (15 s).
        let at = aligned_at.expect("the monitor aligned");
        assert!(
            (STATIC_S..=STATIC_S + 5.0).contains(&at),
            "aligned at {at} s"
        );
        // One gnss test a fix from alignment to the end (60 s).
        assert!(gnss_tests >= 40, "{gnss_tests} gnss tests");
    }
}
