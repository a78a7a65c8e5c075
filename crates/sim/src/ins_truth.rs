//! The simulated INS: true INS errors propagated with the 15-state error model of
//! `filter::ins` (the same Φ the monitor's filters use, so a consistent filter sees
//! consistent errors), and the INS output = truth corrupted by those errors. Sits
//! between the truth path (`trajectory`, `track`) and the epochs of `scenario`.
//!
//! Per INS step of Δt (docs/methods.md §M4): `x_{k+1} = Φ_k x_k + w_k` with `Φ_k` the
//! series `I + FΔt + (FΔt)²/2` of [`discretize`] over [`error_dynamics`] linearised
//! about the truth — applied to `x` as `x + FΔt x + ½ FΔt (FΔt x)`, the same product
//! without forming the 15 × 15 `Φ` (two matrix–vector products instead of a
//! matrix–matrix one per tick; a test checks it against `discretize`) — and
//! `w_k = G_k √(QΔt) n_k`, `n_k ~ N(0, I₆)`: exactly `N(0, Q_d)` with
//! `Q_d = G Q Gᵀ Δt` of `discretize` (Q_d has rank 6, so sampling through G is
//! exact and needs no factorisation).
//!
//! Initial errors (seed 004 §3): attitude `φ = [−5″, 5″, 30″]` as given; velocity
//! 0.1 m/s and position 10 m on each ENU axis with a random sign; true constant
//! biases of the configured magnitude (0.002 °/h, 10 µg) on each body axis with a
//! random sign. Output: position `apply_offset(truth, δp)`, velocity `v + δv`,
//! attitude from `C̃_bⁿ = exp(−[φ×]) C_bⁿ` (equal to `(I − [φ×]) C_bⁿ` to first order,
//! but exactly orthogonal), specific force `f_b + ∇ + w_a` where `w_a` is the same
//! accelerometer white-noise draw that drives δv over the step, as a rate
//! (`√(PSD/Δt) n`).
//!
//! Fidelity: the truth follows docs/methods.md §M4's model exactly as the filters use it,
//! without the `δω_in(δv, δp)` and gravity terms — so without the Schuler loop.
//! Unaided, a tilt φ then drives `δv ≈ g φ t`, `δp ≈ g φ t²/2` instead of an
//! 84-minute oscillation bounded near `R φ`: `ship(1)`'s pure INS drifts ≈ 2.9 km in
//! the hour (a full model would stay within a few hundred metres). With aids every
//! second this does not show, and sharing the model keeps the monitor's NEES/NIS
//! checks exact rather than approximate.
//!
//! [`discretize`]: navguard_core::filter::ins::discretize

use nalgebra::{Rotation3, Vector3};
use rand::Rng;
use rand::rngs::StdRng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use super::rng::{Stream, stream};
use super::truth::Truth;
use super::{SimError, check_non_negative};
use navguard_core::epoch::InsBlock;
use navguard_core::filter::ins::{
    ACC, ATT, ErrorVector, GYRO, ImuErrors, NavSolution, POS, VEL, error_dynamics, noise_input,
};
use navguard_core::geo;
use navguard_core::monitor::federated::InitSigma;

/// Arc-seconds → radians.
const ARCSEC: f64 = std::f64::consts::PI / 180.0 / 3600.0;

/// How the true INS errors start and evolve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct InsErrorConfig {
    /// Bias magnitudes and white-noise densities.
    pub imu: ImuErrors,
    /// Initial misalignment `[φ_e, φ_n, φ_u]`, arc-seconds (seed 004: `[−5, 5, 30]`).
    pub init_att_arcsec: [f64; 3],
    /// Initial velocity error per ENU axis, m/s (sign drawn per axis).
    pub init_vel_mps: f64,
    /// Initial position error per ENU axis, m (sign drawn per axis).
    pub init_pos_m: f64,
    /// Whether to sample the IMU white noise (off: deterministic error growth).
    pub white_noise: bool,
}

impl Default for InsErrorConfig {
    /// Seed 004 §3's INS.
    /// The magnitudes are the `federated` monitor's default initial σs; only the
    /// sign of the east misalignment is the seed's own.
    fn default() -> Self {
        let init = InitSigma::default();
        let [east, north, up] = init.att_sigma_arcsec;
        InsErrorConfig {
            imu: ImuErrors::default(),
            init_att_arcsec: [-east, north, up],
            init_vel_mps: init.vel_sigma_mps,
            init_pos_m: init.pos_sigma_m,
            white_noise: true,
        }
    }
}

impl InsErrorConfig {
    /// Checks that every magnitude is finite and not negative.
    pub fn check(&self) -> Result<(), SimError> {
        let imu = &self.imu;
        check_non_negative("imu.gyro_bias_dph", imu.gyro_bias_dph)?;
        check_non_negative("imu.accel_bias_ug", imu.accel_bias_ug)?;
        check_non_negative("imu.arw_deg_rthr", imu.arw_deg_rthr)?;
        check_non_negative("imu.vrw_mps_rthr", imu.vrw_mps_rthr)?;
        check_non_negative("init_vel_mps", self.init_vel_mps)?;
        check_non_negative("init_pos_m", self.init_pos_m)?;
        if self.init_att_arcsec.iter().any(|a| !a.is_finite()) {
            return Err(SimError::param("init_att_arcsec", "must be finite"));
        }
        Ok(())
    }
}

/// The true INS error state and its propagation.
#[derive(Debug, Clone)]
pub struct InsErrorSim {
    x: ErrorVector,
    imu: ImuErrors,
    white_noise: bool,
    rng: StdRng,
}

/// `Φ x` for `Φ = I + FΔt + (FΔt)²/2` (as `filter::ins::discretize`) without forming `Φ`.
fn propagate(nav: &NavSolution, x: &ErrorVector, dt: f64) -> ErrorVector {
    let fdt = error_dynamics(nav) * dt;
    let fx = fdt * x;
    x + fx + fdt * fx * 0.5
}

fn random_sign(rng: &mut StdRng) -> f64 {
    if rng.random_bool(0.5) { 1.0 } else { -1.0 }
}

impl InsErrorSim {
    /// Draws the initial errors and true biases of `cfg` from `seed`'s INS stream.
    ///
    /// # Errors
    /// [`SimError::InvalidParameter`] if `cfg` does not pass [`InsErrorConfig::check`].
    pub fn new(cfg: &InsErrorConfig, seed: u64) -> Result<Self, SimError> {
        cfg.check()?;
        let mut rng = stream(seed, Stream::Ins);
        let mut x = ErrorVector::zeros();
        for i in 0..3 {
            x[ATT + i] = cfg.init_att_arcsec[i] * ARCSEC;
            x[VEL + i] = cfg.init_vel_mps * random_sign(&mut rng);
            x[POS + i] = cfg.init_pos_m * random_sign(&mut rng);
            x[GYRO + i] = cfg.imu.gyro_bias_rps() * random_sign(&mut rng);
            x[ACC + i] = cfg.imu.accel_bias_mps2() * random_sign(&mut rng);
        }
        Ok(InsErrorSim {
            x,
            imu: cfg.imu,
            white_noise: cfg.white_noise,
            rng,
        })
    }

    /// Starts from a given error state (biases included), for tests and studies.
    pub fn from_state(x0: ErrorVector, imu: ImuErrors, white_noise: bool, seed: u64) -> Self {
        InsErrorSim {
            x: x0,
            imu,
            white_noise,
            rng: stream(seed, Stream::Ins),
        }
    }

    /// The current true error state (INS − truth).
    pub fn errors(&self) -> &ErrorVector {
        &self.x
    }

    /// The INS output at `truth` (with the current errors), then propagates the
    /// errors over `dt` seconds to the next epoch.
    pub fn step(&mut self, truth: &Truth, dt: f64) -> InsBlock {
        let (n_g, n_a) = if self.white_noise {
            let mut draw = || Vector3::from_fn(|_, _| self.rng.sample::<f64, _>(StandardNormal));
            (draw(), draw())
        } else {
            (Vector3::zeros(), Vector3::zeros())
        };
        let c_bn = truth.c_bn();
        let phi = self.x.fixed_rows::<3>(ATT).into_owned();
        let dv = self.x.fixed_rows::<3>(VEL).into_owned();
        let dp = self.x.fixed_rows::<3>(POS).into_owned();
        let accel_bias = self.x.fixed_rows::<3>(ACC).into_owned();
        let lla = geo::apply_offset(&truth.lla, &dp);
        let c_tilde = Rotation3::new(-phi).matrix() * c_bn;
        let accel_rate_sigma = if dt > 0.0 {
            (self.imu.accel_noise_psd() / dt).sqrt()
        } else {
            0.0
        };
        let f_b = truth.f_b + accel_bias + n_a * accel_rate_sigma;
        let vel = truth.vel + dv;
        let out = InsBlock {
            lat: lla.lat,
            lon: lla.lon,
            h: lla.h,
            vel: [vel.x, vel.y, vel.z],
            att: geo::euler_from_dcm(&c_tilde),
            f_b: Some([f_b.x, f_b.y, f_b.z]),
        };
        if dt > 0.0 {
            let nav = NavSolution {
                lla: truth.lla,
                vel: truth.vel,
                c_bn,
                f_n: c_bn * truth.f_b,
            };
            let g = noise_input(&nav);
            let mut n = nalgebra::SVector::<f64, 6>::zeros();
            n.fixed_rows_mut::<3>(0)
                .copy_from(&(n_g * (self.imu.gyro_noise_psd() * dt).sqrt()));
            n.fixed_rows_mut::<3>(3)
                .copy_from(&(n_a * (self.imu.accel_noise_psd() * dt).sqrt()));
            self.x = propagate(&nav, &self.x, dt) + g * n;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trajectory::TrajectoryBuilder;
    use approx::assert_relative_eq;
    use nalgebra::SMatrix;
    use navguard_core::detect::chi2;
    use navguard_core::filter::ins::NoiseInput;
    use navguard_core::filter::ins::discretize;
    use navguard_core::geo::Lla;

    fn at_rest(seconds: f64) -> Vec<Truth> {
        let start = Lla {
            lat: 30f64.to_radians(),
            lon: 114f64.to_radians(),
            h: 0.0,
        };
        TrajectoryBuilder::new(start, 0.0, 0.0)
            .straight(seconds)
            .build()
            .unwrap()
            .sample(10.0, seconds)
            .unwrap()
    }

    #[test]
    fn zero_noise_and_zero_biases_keep_the_errors_at_zero() {
        let start = Lla {
            lat: 30f64.to_radians(),
            lon: 114f64.to_radians(),
            h: 0.0,
        };
        let truth = TrajectoryBuilder::new(start, 10.0, 1.0)
            .turn(1.0, 0.05)
            .straight(30.0)
            .build()
            .unwrap()
            .sample(10.0, 60.0)
            .unwrap();
        let mut sim = InsErrorSim::from_state(ErrorVector::zeros(), ImuErrors::default(), false, 1);
        for s in &truth {
            let ins = sim.step(s, 0.1);
            assert_eq!(sim.errors(), &ErrorVector::zeros());
            assert_relative_eq!(ins.lat, s.lla.lat, epsilon = 1e-15);
            assert_relative_eq!(ins.lon, s.lla.lon, epsilon = 1e-14);
            assert_eq!(ins.vel, [s.vel.x, s.vel.y, s.vel.z]);
            assert_relative_eq!(
                Vector3::from(ins.att),
                Vector3::from(s.att),
                epsilon = 1e-12
            );
            assert_eq!(ins.f_b, Some([s.f_b.x, s.f_b.y, s.f_b.z]));
        }
    }

    #[test]
    fn an_accelerometer_bias_grows_position_error_as_half_b_t_squared() {
        // Level, heading north: body y is north. 10 s of a 1e-3 m/s² forward bias.
        let b = 1e-3;
        let mut x0 = ErrorVector::zeros();
        x0[ACC + 1] = b;
        let mut sim = InsErrorSim::from_state(x0, ImuErrors::default(), false, 1);
        let truth = at_rest(10.0);
        for s in &truth[..100] {
            let ins = sim.step(s, 0.1);
            assert_relative_eq!(ins.f_b.unwrap()[1], s.f_b.y + b, epsilon = 1e-15);
        }
        // Φ's second-order series integrates a constant exactly; Coriolis (2Ω t ≈ 1.5e-3) aside.
        assert_relative_eq!(sim.errors()[POS + 1], 0.5 * b * 100.0, max_relative = 1e-3);
        assert_relative_eq!(sim.errors()[VEL + 1], b * 10.0, max_relative = 1e-3);
        // The INS position is displaced north by that much.
        let ins = sim.step(&truth[100], 0.1);
        let d = geo::local_offset(
            &Lla {
                lat: ins.lat,
                lon: ins.lon,
                h: ins.h,
            },
            &truth[100].lla,
        );
        assert_relative_eq!(d.y, 0.05, max_relative = 1e-3);
    }

    #[test]
    fn initial_errors_follow_seed_004_with_random_signs() {
        let sim = InsErrorSim::new(&InsErrorConfig::default(), 3).unwrap();
        let x = sim.errors();
        assert_relative_eq!(x[ATT], -5.0 * ARCSEC);
        assert_relative_eq!(x[ATT + 2], 30.0 * ARCSEC);
        for i in 0..3 {
            assert_relative_eq!(x[POS + i].abs(), 10.0);
            assert_relative_eq!(x[VEL + i].abs(), 0.1);
            assert_relative_eq!(x[GYRO + i].abs(), ImuErrors::default().gyro_bias_rps());
            assert_relative_eq!(x[ACC + i].abs(), 9.806_65e-5, max_relative = 1e-12);
        }
        let other = InsErrorSim::new(&InsErrorConfig::default(), 4).unwrap();
        assert_ne!(x, other.errors(), "different seeds draw different signs");
        let bad = InsErrorConfig {
            init_pos_m: -1.0,
            ..InsErrorConfig::default()
        };
        assert!(InsErrorSim::new(&bad, 1).is_err());
    }

    #[test]
    fn propagation_applies_the_phi_of_discretize() {
        let start = Lla {
            lat: 0.6,
            lon: 2.0,
            h: 30.0,
        };
        let truth = &TrajectoryBuilder::new(start, 12.0, 0.4)
            .turn(0.5, 0.05)
            .build()
            .unwrap()
            .sample(10.0, 5.0)
            .unwrap()[20];
        let c_bn = truth.c_bn();
        let nav = NavSolution {
            lla: truth.lla,
            vel: truth.vel,
            c_bn,
            f_n: c_bn * truth.f_b,
        };
        let x = ErrorVector::from_fn(|i, _| (i as f64 + 1.0) * if i < 3 { 1e-4 } else { 0.3 });
        let (phi, _) = discretize(
            &error_dynamics(&nav),
            &noise_input(&nav),
            &ImuErrors::default(),
            0.1,
        );
        assert_relative_eq!(
            propagate(&nav, &x, 0.1),
            phi * x,
            max_relative = 1e-14,
            epsilon = 1e-18
        );
    }

    #[test]
    fn sampled_noise_has_the_covariance_of_discretize() {
        let truth = &at_rest(1.0)[0];
        let c_bn = truth.c_bn();
        let nav = NavSolution {
            lla: truth.lla,
            vel: truth.vel,
            c_bn,
            f_n: c_bn * truth.f_b,
        };
        let imu = ImuErrors::default();
        let dt = 0.1;
        let g: NoiseInput = noise_input(&nav);
        let (_, qd) = discretize(&error_dynamics(&nav), &g, &imu, dt);
        let q =
            SMatrix::<f64, 6, 6>::from_diagonal(&nalgebra::SVector::<f64, 6>::from_fn(|i, _| {
                if i < 3 {
                    imu.gyro_noise_psd() * dt
                } else {
                    imu.accel_noise_psd() * dt
                }
            }));
        assert_relative_eq!(g * q * g.transpose(), qd, epsilon = 1e-30);

        // One seeded step from zero errors leaves x = G n, which must be N(0, Q_d).
        // For each direction u (every attitude/velocity axis and every pair sum, so
        // the cross terms count too) Σ (uᵀx)² / uᵀQ_d u is χ²(runs); it must lie in
        // the two-sided 99.99 % interval (21 directions: ≤ 0.21 % false alarms in all).
        let runs: u64 = 4000;
        let samples: Vec<ErrorVector> = (0..runs)
            .map(|seed| {
                let mut sim = InsErrorSim::from_state(ErrorVector::zeros(), imu, true, seed);
                sim.step(truth, dt);
                *sim.errors()
            })
            .collect();
        // Position and biases are driven by nothing in one step: exactly zero, as Q_d says.
        for i in POS..navguard_core::filter::ins::N {
            assert_eq!(qd[(i, i)], 0.0, "Q_d[{i},{i}]");
            assert!(samples.iter().all(|x| x[i] == 0.0), "x[{i}] moved");
        }
        let mut directions = Vec::new();
        for i in 0..6 {
            directions.push(ErrorVector::ith(i, 1.0));
            for j in i + 1..6 {
                directions.push(ErrorVector::ith(i, 1.0) + ErrorVector::ith(j, 1.0));
            }
        }
        assert_eq!(directions.len(), 21);
        let lo = chi2::threshold(runs as u32, 1.0 - 5e-5).unwrap();
        let hi = chi2::threshold(runs as u32, 5e-5).unwrap();
        for u in &directions {
            let variance = (u.transpose() * qd * u)[0];
            assert!(variance > 0.0, "uᵀQ_d u for u = {u}");
            let stat: f64 = samples.iter().map(|x| u.dot(x).powi(2)).sum::<f64>() / variance;
            assert!(stat > lo && stat < hi, "u = {u}: {lo} < {stat} < {hi}");
        }
        // The test has power: a noise 10 % too strong in variance would be caught.
        assert!(hi / (runs as f64) < 1.1);
    }

    #[test]
    fn vertical_velocity_random_walk_matches_the_vrw() {
        // δv_u at rest is driven by the accelerometer noise only (fⁿ × φ has no up
        // component for fⁿ straight up): σ(T) = √(PSD·T). 400 seeded runs of 10 s;
        // the sample variance must lie in the two-sided χ²(400) 99.9 % interval.
        let imu = ImuErrors::default();
        let truth = at_rest(10.0);
        let runs = 400;
        let sum_sq: f64 = (0..runs)
            .map(|seed| {
                let mut sim = InsErrorSim::from_state(ErrorVector::zeros(), imu, true, seed);
                for s in &truth[..100] {
                    sim.step(s, 0.1);
                }
                sim.errors()[VEL + 2].powi(2)
            })
            .sum();
        let sigma2 = imu.accel_noise_psd() * 10.0;
        let stat = sum_sq / sigma2;
        let lo = chi2::threshold(400, 0.9995).unwrap();
        let hi = chi2::threshold(400, 0.0005).unwrap();
        assert!(stat > lo && stat < hi, "{lo} < {stat} < {hi}");
    }
}
