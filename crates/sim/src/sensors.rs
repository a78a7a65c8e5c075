//! Aiding sensors: GNSS position and velocity, DVL body velocity with a
//! scale-factor error, CNS latitude/longitude — each with white Gaussian noise,
//! its own rate and optional random dropouts, then passed through the
//! [`FaultInjector`]. Reads the truth (`trajectory`, `track`), writes the aid
//! blocks of the domain [`Epoch`] that `scenario` emits.
//!
//! Defaults (docs/methods.md §M19, seed 004 §3; the σs are the `federated`
//! monitor's config defaults, so the monitor's model matches them): GNSS σ 10 m per ENU axis (height too)
//! and 0.1 m/s per axis at 1 Hz; DVL σ 0.1 m/s per body axis with a scale-factor
//! error of +1e-3 (`v_b = (1 + k) C_nᵇ vⁿ + w`: over the ground, no current) at
//! 1 Hz; CNS σ 450 m on latitude and on longitude (north and east metres) at
//! 0.1 Hz; no dropouts. Seed 004 gives no rates: these are typical of a ship's
//! receiver, log and star tracker fix cycle. Every rate must divide the INS rate
//! (an aid is read at INS ticks `k` with `k mod (f_INS / f_aid) = 0`, so the first
//! reading is at t = 0).
//!
//! Noise streams are per sensor and drawn whether or not a reading drops out
//! or is faulted, so the same seed gives the same noise under any fault list.

use nalgebra::Vector3;
use rand::Rng;
use rand::rngs::StdRng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use super::faults::{Channel, FaultInjector};
use super::rng::{Stream, stream};
use super::truth::Truth;
use super::{SimError, check_non_negative, check_positive};
use navguard_core::epoch::Aid;
use navguard_core::epoch::{CnsBlock, Epoch, GnssBlock};
use navguard_core::geo::{self, Lla};
use navguard_core::monitor::federated::{CnsNoise, DvlNoise, GnssNoise};

/// GNSS receiver.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GnssSpec {
    /// Fix rate, Hz.
    pub rate_hz: f64,
    /// Position noise per ENU axis, m.
    pub pos_sigma_m: f64,
    /// Velocity noise per ENU axis, m/s.
    pub vel_sigma_mps: f64,
    /// Whether fixes carry velocity.
    pub velocity: bool,
    /// Probability that a fix is missing.
    pub dropout_prob: f64,
}

/// Doppler velocity log.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DvlSpec {
    /// Reading rate, Hz.
    pub rate_hz: f64,
    /// Velocity noise per body axis, m/s.
    pub vel_sigma_mps: f64,
    /// Scale-factor error k (`(1 + k)·v`).
    pub scale_error: f64,
    /// Probability that a reading is missing.
    pub dropout_prob: f64,
}

/// Celestial navigation fix.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CnsSpec {
    /// Fix rate, Hz.
    pub rate_hz: f64,
    /// Noise on latitude and on longitude, expressed in metres (north, east).
    pub pos_sigma_m: f64,
    /// Probability that a fix is missing.
    pub dropout_prob: f64,
}

impl Default for GnssSpec {
    fn default() -> Self {
        let noise = GnssNoise::default();
        GnssSpec {
            rate_hz: 1.0,
            pos_sigma_m: noise.pos_sigma_m,
            vel_sigma_mps: noise.vel_sigma_mps,
            velocity: true,
            dropout_prob: 0.0,
        }
    }
}

impl Default for DvlSpec {
    fn default() -> Self {
        DvlSpec {
            rate_hz: 1.0,
            vel_sigma_mps: DvlNoise::default().vel_sigma_mps,
            scale_error: 1e-3,
            dropout_prob: 0.0,
        }
    }
}

impl Default for CnsSpec {
    fn default() -> Self {
        CnsSpec {
            rate_hz: 0.1,
            pos_sigma_m: CnsNoise::default().pos_sigma_m,
            dropout_prob: 0.0,
        }
    }
}

/// Which aids a scenario carries (`None`: absent) and their specifications.
/// The default is seed 004's full set.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensorConfig {
    /// GNSS receiver.
    pub gnss: Option<GnssSpec>,
    /// Doppler velocity log.
    pub dvl: Option<DvlSpec>,
    /// Celestial navigation.
    pub cns: Option<CnsSpec>,
}

impl Default for SensorConfig {
    fn default() -> Self {
        SensorConfig {
            gnss: Some(GnssSpec::default()),
            dvl: Some(DvlSpec::default()),
            cns: Some(CnsSpec::default()),
        }
    }
}

impl SensorConfig {
    /// The aids present, in the order gnss, dvl, cns.
    pub fn aids(&self) -> Vec<Aid> {
        let mut aids = Vec::new();
        if self.gnss.is_some() {
            aids.push(Aid::Gnss);
        }
        if self.dvl.is_some() {
            aids.push(Aid::Dvl);
        }
        if self.cns.is_some() {
            aids.push(Aid::Cns);
        }
        aids
    }
}

/// INS ticks between readings of an aid at `rate_hz`.
fn period_ticks(field: &str, rate_hz: f64, ins_rate_hz: f64) -> Result<u64, SimError> {
    check_positive(field, rate_hz)?;
    let ratio = ins_rate_hz / rate_hz;
    let ticks = ratio.round();
    if ticks < 1.0 || (ratio - ticks).abs() > 1e-9 * ratio {
        return Err(SimError::param(
            field,
            format!("{rate_hz} Hz must divide the INS rate of {ins_rate_hz} Hz"),
        ));
    }
    Ok(ticks as u64)
}

fn check_prob(field: &str, p: f64) -> Result<(), SimError> {
    if (0.0..=1.0).contains(&p) {
        Ok(())
    } else {
        Err(SimError::param(
            field,
            format!("must be in [0, 1], got {p}"),
        ))
    }
}

fn normal3(rng: &mut StdRng) -> Vector3<f64> {
    Vector3::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal))
}

/// Metres per unit of `[lon, lat, h]` at `p`, for the fault injector.
fn position_scale(p: &Lla) -> [f64; 3] {
    let r = geo::radii(p.lat);
    [
        (r.prime_vertical + p.h) * p.lat.cos(),
        r.meridian + p.h,
        1.0,
    ]
}

/// The aid sensors of one run: specifications, periods and noise streams.
#[derive(Debug, Clone)]
pub struct AidSensors {
    cfg: SensorConfig,
    periods: [u64; 3],
    rngs: [StdRng; 3],
    dropouts: StdRng,
}

impl AidSensors {
    /// Validates `cfg` against the INS rate and seeds the noise streams from `seed`.
    ///
    /// # Errors
    /// [`SimError::InvalidParameter`] naming the field for a rate that does not
    /// divide `ins_rate_hz`, a negative σ or a probability outside [0, 1].
    pub fn new(cfg: &SensorConfig, ins_rate_hz: f64, seed: u64) -> Result<Self, SimError> {
        check_positive("ins_rate_hz", ins_rate_hz)?;
        let mut periods = [0; 3];
        if let Some(g) = &cfg.gnss {
            periods[0] = period_ticks("gnss.rate_hz", g.rate_hz, ins_rate_hz)?;
            check_non_negative("gnss.pos_sigma_m", g.pos_sigma_m)?;
            check_non_negative("gnss.vel_sigma_mps", g.vel_sigma_mps)?;
            check_prob("gnss.dropout_prob", g.dropout_prob)?;
        }
        if let Some(d) = &cfg.dvl {
            periods[1] = period_ticks("dvl.rate_hz", d.rate_hz, ins_rate_hz)?;
            check_non_negative("dvl.vel_sigma_mps", d.vel_sigma_mps)?;
            if !d.scale_error.is_finite() {
                return Err(SimError::param("dvl.scale_error", "must be finite"));
            }
            check_prob("dvl.dropout_prob", d.dropout_prob)?;
        }
        if let Some(c) = &cfg.cns {
            periods[2] = period_ticks("cns.rate_hz", c.rate_hz, ins_rate_hz)?;
            check_non_negative("cns.pos_sigma_m", c.pos_sigma_m)?;
            check_prob("cns.dropout_prob", c.dropout_prob)?;
        }
        Ok(AidSensors {
            cfg: *cfg,
            periods,
            rngs: [
                stream(seed, Stream::Gnss),
                stream(seed, Stream::Dvl),
                stream(seed, Stream::Cns),
            ],
            dropouts: stream(seed, Stream::Dropouts),
        })
    }

    /// Whether a reading due now drops out (one uniform draw per due reading).
    fn drops(&mut self, p: f64) -> bool {
        self.dropouts.random::<f64>() < p
    }

    /// Fills `epoch`'s aid blocks for INS tick `k` (time `truth.t`) with the aids
    /// due at that tick, noisy and faulted.
    pub fn observe(
        &mut self,
        k: u64,
        truth: &Truth,
        faults: &mut FaultInjector,
        epoch: &mut Epoch,
    ) {
        let t = truth.t;
        if let Some(spec) = self.cfg.gnss.filter(|_| k % self.periods[0] == 0) {
            let d = normal3(&mut self.rngs[0]) * spec.pos_sigma_m;
            let v = truth.vel + normal3(&mut self.rngs[0]) * spec.vel_sigma_mps;
            let dropped = self.drops(spec.dropout_prob);
            let p = geo::apply_offset(&truth.lla, &d);
            let mut pos = [p.lon, p.lat, p.h];
            let pos_ok = faults.apply(
                Aid::Gnss,
                Channel::Position,
                t,
                &mut pos,
                &position_scale(&p),
            );
            let mut vel = [v.x, v.y, v.z];
            let vel_ok = faults.apply(Aid::Gnss, Channel::Velocity, t, &mut vel, &[1.0; 3]);
            if pos_ok && !dropped {
                epoch.gnss = Some(GnssBlock {
                    lat: pos[1],
                    lon: pos[0],
                    h: pos[2],
                    vel: (spec.velocity && vel_ok).then_some(vel),
                    pos_sigma: None,
                    vel_sigma: None,
                });
            }
        }
        if let Some(spec) = self.cfg.dvl.filter(|_| k % self.periods[1] == 0) {
            let v_b = truth.c_bn().transpose() * truth.vel * (1.0 + spec.scale_error)
                + normal3(&mut self.rngs[1]) * spec.vel_sigma_mps;
            let dropped = self.drops(spec.dropout_prob);
            let mut vel = [v_b.x, v_b.y, v_b.z];
            if faults.apply(Aid::Dvl, Channel::Velocity, t, &mut vel, &[1.0; 3]) && !dropped {
                epoch.dvl_vel_b = Some(vel);
            }
        }
        if let Some(spec) = self.cfg.cns.filter(|_| k % self.periods[2] == 0) {
            let n = normal3(&mut self.rngs[2]);
            let d = Vector3::new(n.x, n.y, 0.0) * spec.pos_sigma_m;
            let dropped = self.drops(spec.dropout_prob);
            let p = geo::apply_offset(&truth.lla, &d);
            let mut pos = [p.lon, p.lat];
            if faults.apply(
                Aid::Cns,
                Channel::Position,
                t,
                &mut pos,
                &position_scale(&p),
            ) && !dropped
            {
                epoch.cns = Some(CnsBlock {
                    lat: pos[1],
                    lon: pos[0],
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trajectory::TrajectoryBuilder;
    use navguard_core::detect::chi2;

    fn cruising() -> Truth {
        let start = Lla {
            lat: 30f64.to_radians(),
            lon: 114f64.to_radians(),
            h: 0.0,
        };
        TrajectoryBuilder::new(start, 10.0, 0.7)
            .straight(1.0)
            .build()
            .unwrap()
            .sample(1.0, 1.0)
            .unwrap()
            .remove(0)
    }

    /// Two-sided 99.9 % χ²(n) check that `sum_sq / σ²` is plausible for n draws.
    fn assert_chi2(sum_sq: f64, sigma: f64, n: u32, what: &str) {
        let stat = sum_sq / (sigma * sigma);
        let (lo, hi) = (
            chi2::threshold(n, 0.9995).unwrap(),
            chi2::threshold(n, 0.0005).unwrap(),
        );
        assert!(stat > lo && stat < hi, "{what}: {lo} < {stat} < {hi}");
    }

    #[test]
    fn noise_has_the_configured_standard_deviations() {
        let truth = cruising();
        let mut sensors = AidSensors::new(&SensorConfig::default(), 10.0, 11).unwrap();
        let mut faults = FaultInjector::new(Vec::new()).unwrap();
        let n = 2000;
        let mut sums = [0.0; 10];
        let c_nb = truth.c_bn().transpose();
        let v_b = c_nb * truth.vel * (1.0 + 1e-3);
        for i in 0..n {
            let mut e = Epoch::default();
            sensors.observe(100 * i, &truth, &mut faults, &mut e);
            let (Some(g), Some(dvl), Some(cns)) = (e.gnss, e.dvl_vel_b, e.cns) else {
                panic!("all aids due at k = 100 i")
            };
            let dp = geo::local_offset(
                &Lla {
                    lat: g.lat,
                    lon: g.lon,
                    h: g.h,
                },
                &truth.lla,
            );
            let dv = Vector3::from(g.vel.unwrap()) - truth.vel;
            let dd = Vector3::from(dvl) - v_b;
            let dc = geo::local_offset(
                &Lla {
                    lat: cns.lat,
                    lon: cns.lon,
                    h: 0.0,
                },
                &truth.lla,
            );
            let errs = [dp.x, dp.y, dp.z, dv.x, dv.y, dv.z, dd.x, dd.y, dc.x, dc.y];
            for (s, e) in sums.iter_mut().zip(errs) {
                *s += e * e;
            }
        }
        let sigmas = [10.0, 10.0, 10.0, 0.1, 0.1, 0.1, 0.1, 0.1, 450.0, 450.0];
        for (i, (s, sigma)) in sums.iter().zip(sigmas).enumerate() {
            assert_chi2(*s, sigma, n as u32, &format!("error component {i}"));
        }
    }

    #[test]
    fn aids_follow_their_rates_and_dropouts() {
        let truth = cruising();
        let cfg = SensorConfig {
            gnss: Some(GnssSpec {
                dropout_prob: 0.3,
                ..GnssSpec::default()
            }),
            ..SensorConfig::default()
        };
        let mut sensors = AidSensors::new(&cfg, 10.0, 5).unwrap();
        let mut faults = FaultInjector::new(Vec::new()).unwrap();
        let (mut gnss, mut dvl, mut cns) = (0, 0, 0);
        for k in 0..20_000 {
            let mut e = Epoch::default();
            sensors.observe(k, &truth, &mut faults, &mut e);
            gnss += usize::from(e.gnss.is_some());
            dvl += usize::from(e.dvl_vel_b.is_some());
            cns += usize::from(e.cns.is_some());
            if k % 10 != 0 {
                assert!(e.gnss.is_none() && e.dvl_vel_b.is_none());
            }
        }
        assert_eq!((dvl, cns), (2000, 200));
        // 2000 GNSS fixes due, 30 % dropped: binomial σ ≈ 20.5, allow 4σ.
        assert!((1400 - 82..=1400 + 82).contains(&gnss), "{gnss}");
    }

    #[test]
    fn rates_that_do_not_divide_the_ins_rate_are_refused() {
        let cfg = SensorConfig {
            cns: Some(CnsSpec {
                rate_hz: 3.0,
                ..CnsSpec::default()
            }),
            ..SensorConfig::default()
        };
        let e = AidSensors::new(&cfg, 10.0, 1).unwrap_err();
        assert!(
            matches!(e, SimError::InvalidParameter { ref field, .. } if field == "cns.rate_hz"),
            "{e}"
        );
        let cfg = SensorConfig {
            dvl: Some(DvlSpec {
                dropout_prob: 2.0,
                ..DvlSpec::default()
            }),
            ..SensorConfig::default()
        };
        assert!(AidSensors::new(&cfg, 10.0, 1).is_err());
    }
}
