//! The `rimu` scenario (docs/methods.md §M19, seed 002 §3): a redundant gyro set sampled at
//! 100 Hz with white rate noise from the angle random walk, steady and manoeuvring
//! (climb) flight, and one bias or drift fault on one gyro. Upstream of
//! `monitor::rimu` and the seed 002 experiment; also makes the classifier's
//! training windows. Deterministic from the seed ([`super::rng`] streams).
//!
//! Units: ARW `N` in °/√h is `N·(π/180)/60` rad/√s; sampled white rate noise of that
//! ARW has per-sample standard deviation `σ = ARW/√dt` rad/s (the angle increment's
//! variance ARW²·dt spread over dt: σ² = ARW²/dt). 0.5 °/√h at 100 Hz gives
//! σ = 1.4544e-4 / √0.01 = 1.4544e-3 rad/s (0.0833 °/s).

use nalgebra::DMatrix;
use rand::Rng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};
use serde::Serialize;

use super::SimError;
use super::rng::{self, Stream};
use navguard_core::detect::parity;
use navguard_core::monitor::rimu::{RATE_HZ, default_sigma};

/// Earth rate at seed 002's start latitude 50.25° N, rad/s, as (north, up): the rate a
/// level, north-heading vehicle in steady flight senses (x forward = north, z up).
const EARTH_RATE: f64 = 7.292_115e-5;
const START_LAT_DEG: f64 = 50.25;

/// A gyro fault, in multiples of the gyro's σ (seed 002 Table 2).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum GyroFaultKind {
    /// A constant bias of `n·σ` from the onset.
    Bias(f64),
    /// A drift of `n·σ` per second from the onset.
    Drift(f64),
}

impl GyroFaultKind {
    /// Seed 002's four faults: 5σ and 6σ bias, 3σ/s and 4σ/s drift.
    pub const SEED002: [GyroFaultKind; 4] = [
        GyroFaultKind::Bias(5.0),
        GyroFaultKind::Bias(6.0),
        GyroFaultKind::Drift(3.0),
        GyroFaultKind::Drift(4.0),
    ];

    /// The error it adds `elapsed_s` after the onset, for gyro noise `sigma`.
    pub fn offset(self, elapsed_s: f64, sigma: f64) -> f64 {
        if elapsed_s < 0.0 {
            return 0.0;
        }
        match self {
            GyroFaultKind::Bias(n) => n * sigma,
            GyroFaultKind::Drift(n) => n * sigma * elapsed_s,
        }
    }

    /// A short label: `bias 5σ`, `drift 3σ/s`.
    pub fn label(self) -> String {
        match self {
            GyroFaultKind::Bias(n) => format!("bias {n}σ"),
            GyroFaultKind::Drift(n) => format!("drift {n}σ/s"),
        }
    }
}

/// A fault on one gyro from `onset_s`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GyroFault {
    /// Gyro index (0-based row of H).
    pub gyro: usize,
    /// What the fault does.
    pub kind: GyroFaultKind,
    /// Onset, s.
    pub onset_s: f64,
}

/// The flight segment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum Flight {
    /// Level, unaccelerated flight: the gyros sense only the Earth rate.
    Steady,
    /// A climb of `duration_s` from `start_s`: the pitch rate rises and falls as
    /// `q_max·sin(π(t − start)/duration)`, reaching pitch `climb_deg` at the end.
    Climb {
        /// Start of the pull-up, s.
        start_s: f64,
        /// Length of the pull-up, s.
        duration_s: f64,
        /// Flight-path (pitch) angle reached, degrees.
        climb_deg: f64,
    },
}

impl Flight {
    /// Seed 002's manoeuvre: a 4 s climb from 30 s (pitch 5° reached at 34 s).
    pub fn seed002_climb() -> Self {
        Flight::Climb {
            start_s: 30.0,
            duration_s: 4.0,
            climb_deg: 5.0,
        }
    }

    /// True body rate at `t`, rad/s (x forward, y left wing, z up).
    pub fn omega(&self, t: f64) -> [f64; 3] {
        let lat = START_LAT_DEG.to_radians();
        let mut w = [EARTH_RATE * lat.cos(), 0.0, EARTH_RATE * lat.sin()];
        if let Flight::Climb {
            start_s,
            duration_s,
            climb_deg,
        } = *self
            && t >= start_s
            && t <= start_s + duration_s
        {
            // ∫ q_max sin(π s/T) ds over [0, T] = 2 q_max T/π = climb angle.
            let q_max = climb_deg.to_radians() * std::f64::consts::PI / (2.0 * duration_s);
            w[1] += q_max * (std::f64::consts::PI * (t - start_s) / duration_s).sin();
        }
        w
    }
}

/// One run of the gyro set.
#[derive(Debug, Clone, PartialEq)]
pub struct RimuRun {
    /// Mounting matrix (m × 3).
    pub h: DMatrix<f64>,
    /// Per-gyro noise σ, rad/s.
    pub sigma: Vec<f64>,
    /// One sample every 0.01 s.
    pub samples: Vec<RimuSample>,
    /// The injected fault.
    pub fault: Option<GyroFault>,
}

/// One 100 Hz sample.
#[derive(Debug, Clone, PartialEq)]
pub struct RimuSample {
    /// Time, s.
    pub t: f64,
    /// Gyro outputs `v = Hω + ε (+ fault)`, rad/s.
    pub gyros: Vec<f64>,
    /// True body rate ω, rad/s.
    pub omega: [f64; 3],
}

/// What to simulate.
#[derive(Debug, Clone, PartialEq)]
pub struct RimuSimParams {
    /// Scenario seed.
    pub seed: u64,
    /// Mounting matrix (m × 3); default seed 002's three orthogonal + one skewed.
    pub h: DMatrix<f64>,
    /// Per-sample noise σ, rad/s, the same for every gyro.
    pub sigma: f64,
    /// First sample time, s.
    pub start_s: f64,
    /// Last sample time, s (exclusive).
    pub end_s: f64,
    /// The flight.
    pub flight: Flight,
    /// The fault, if any.
    pub fault: Option<GyroFault>,
}

impl RimuSimParams {
    /// Seed 002 scenario 1: steady flight 22–28 s, faults from 25 s.
    pub fn steady(seed: u64, fault: Option<(usize, GyroFaultKind)>) -> Self {
        RimuSimParams {
            seed,
            h: parity::default_h(),
            sigma: default_sigma(),
            start_s: 22.0,
            end_s: 28.0,
            flight: Flight::Steady,
            fault: fault.map(|(gyro, kind)| GyroFault {
                gyro,
                kind,
                onset_s: 25.0,
            }),
        }
    }

    /// Seed 002 scenario 2: 28–34 s, a climb from 30 s, faults from 31 s.
    pub fn manoeuvring(seed: u64, fault: Option<(usize, GyroFaultKind)>) -> Self {
        RimuSimParams {
            start_s: 28.0,
            end_s: 34.0,
            flight: Flight::seed002_climb(),
            fault: fault.map(|(gyro, kind)| GyroFault {
                gyro,
                kind,
                onset_s: 31.0,
            }),
            ..Self::steady(seed, None)
        }
    }
}

/// Simulates the gyro set: `v_k = H ω(t_k) + σ n_k (+ fault)`.
pub fn simulate(params: &RimuSimParams) -> Result<RimuRun, SimError> {
    let m = params.h.nrows();
    if params.h.ncols() != 3 || m < 3 {
        return Err(SimError::param("h", "must be m × 3 with m ≥ 3"));
    }
    super::check_positive("sigma", params.sigma)?;
    if params.end_s.is_nan() || params.end_s <= params.start_s {
        return Err(SimError::param("end_s", "must be after start_s"));
    }
    if let Some(f) = params.fault
        && f.gyro >= m
    {
        return Err(SimError::InvalidFault {
            index: 0,
            reason: format!("gyro {} does not exist (m = {m})", f.gyro),
        });
    }
    let mut rng = rng::stream(params.seed, Stream::Ins);
    let n = ((params.end_s - params.start_s) * RATE_HZ).round() as usize;
    let samples = (0..n)
        .map(|k| {
            let t = params.start_s + k as f64 / RATE_HZ;
            let omega = params.flight.omega(t);
            let gyros = (0..m)
                .map(|i| {
                    let hw: f64 = (0..3).map(|j| params.h[(i, j)] * omega[j]).sum();
                    let noise: f64 = StandardNormal.sample(&mut rng);
                    let fault = match params.fault {
                        Some(f) if f.gyro == i => f.kind.offset(t - f.onset_s, params.sigma),
                        _ => 0.0,
                    };
                    hw + params.sigma * noise + fault
                })
                .collect();
            RimuSample { t, gyros, omega }
        })
        .collect();
    Ok(RimuRun {
        h: params.h.clone(),
        sigma: vec![params.sigma; m],
        samples,
        fault: params.fault,
    })
}

/// Labelled raw windows for the isolation classifier (seed 002 §3): one gyro's
/// steady-flight output, `n_normal` fault-free windows (label −1) and `n_fault` windows
/// with the seed 002 faults in turn (label +1), each `window` samples long. Bias windows
/// end 6 to `window` samples after the onset (what the window holds when the parity
/// test fires within a second); drift windows end 0.5–3 s after the onset (a 3σ/s drift
/// takes about that long to reach the parity threshold).
pub fn training_windows(
    seed: u64,
    sigma: f64,
    window: usize,
    n_normal: usize,
    n_fault: usize,
) -> (Vec<Vec<f64>>, Vec<f64>) {
    let mut rng = rng::stream(seed, Stream::Dropouts);
    let steady = Flight::Steady;
    // The skewed gyro's axis: it senses the Earth rate along [1, 1, 1]/√3.
    let w = steady.omega(0.0);
    let level = (w[0] + w[1] + w[2]) * parity::SKEW;
    let noise = |rng: &mut StdRng| -> Vec<f64> {
        (0..window)
            .map(|_| {
                let z: f64 = StandardNormal.sample(rng);
                level + sigma * z
            })
            .collect()
    };
    let mut x = Vec::with_capacity(n_normal + n_fault);
    let mut y = Vec::with_capacity(n_normal + n_fault);
    for _ in 0..n_normal {
        x.push(noise(&mut rng));
        y.push(-1.0);
    }
    for i in 0..n_fault {
        let kind = GyroFaultKind::SEED002[i % 4];
        let mut v = noise(&mut rng);
        let end_after_s = match kind {
            GyroFaultKind::Bias(_) => rng.random_range(6..=window) as f64 / RATE_HZ,
            GyroFaultKind::Drift(_) => rng.random_range(0.5..3.0),
        };
        for (k, s) in v.iter_mut().enumerate() {
            // Sample k of the window is (window − 1 − k)/rate before its end.
            let elapsed = end_after_s - (window - 1 - k) as f64 / RATE_HZ;
            *s += kind.offset(elapsed, sigma);
        }
        x.push(v);
        y.push(1.0);
    }
    (x, y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arw_of_half_a_degree_per_root_hour_gives_the_stated_sigma() {
        // 0.5°/√h = 0.5·(π/180)/60 rad/√s = 1.454441e-4; /√0.01 → 1.454441e-3 rad/s.
        assert!((default_sigma() - 1.454_441e-3).abs() < 1e-9);
    }

    #[test]
    fn simulation_is_deterministic_and_has_the_stated_noise_and_fault() {
        let fault = Some((0, GyroFaultKind::Bias(5.0)));
        let a = simulate(&RimuSimParams::steady(3, fault)).unwrap();
        let b = simulate(&RimuSimParams::steady(3, fault)).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.samples.len(), 600);
        let s = default_sigma();
        // Gyro 1 (y axis) before and after: mean ≈ 0, std ≈ σ; gyro 0 after 25 s: mean ≈ 5σ.
        let after: Vec<f64> = a
            .samples
            .iter()
            .filter(|x| x.t >= 25.0)
            .map(|x| x.gyros[0])
            .collect();
        let mean = after.iter().sum::<f64>() / after.len() as f64;
        assert!((mean - 5.0 * s).abs() < 0.25 * s, "{mean}");
        let y: Vec<f64> = a.samples.iter().map(|x| x.gyros[1]).collect();
        let my = y.iter().sum::<f64>() / y.len() as f64;
        let sd = (y.iter().map(|v| (v - my).powi(2)).sum::<f64>() / y.len() as f64).sqrt();
        assert!((sd / s - 1.0).abs() < 0.1, "{sd}");
    }

    #[test]
    fn climb_reaches_its_pitch_angle() {
        let f = Flight::seed002_climb();
        let dt = 1e-3;
        let pitch: f64 = (0..4000)
            .map(|k| f.omega(30.0 + k as f64 * dt)[1] * dt)
            .sum();
        assert!(
            (pitch.to_degrees() - 5.0).abs() < 1e-3,
            "{}",
            pitch.to_degrees()
        );
    }

    #[test]
    fn training_windows_have_the_requested_labels() {
        let (x, y) = training_windows(1, default_sigma(), 96, 10, 8);
        assert_eq!((x.len(), y.len()), (18, 18));
        assert!(x.iter().all(|w| w.len() == 96));
        assert_eq!(y.iter().filter(|&&l| l > 0.0).count(), 8);
    }
}
