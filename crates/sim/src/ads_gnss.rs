//! The `ads-gnss` scenario (seed 000 §4, docs/methods.md §M19): an aircraft flying home straight
//! and level on air data after an INS failure, 800 s at 1 Hz, heading 135°, from 34° N
//! 109° E (the paper's "longitude 34°, latitude 109°" is read as swapped: 109° cannot be
//! a latitude) at 1200 m. It yields the monitored channel `dh` = GNSS height minus
//! barometric height, with a GNSS height fault injected through [`super::faults`]:
//! the paper's 1 m/s ramp from 400 s to 600 s (seed 000 eq. 25), and the variants of its
//! Table 2 (90 m and 100 m steps, 2 m/s ramp, over the same interval). Sits upstream of
//! the `channel` monitor and the seed 000 experiment.
//!
//! Noise models. The paper names the error states (eq. 22: wind, air-speed scale factor
//! and a barometric height error δh_b "correlated in time with correlation time τ_b";
//! eq. 23: GNSS position and velocity errors) but gives no values, so we pick:
//! - barometric height error δh_b: first-order Gauss–Markov, σ_b = 1 m, τ_b = 120 s
//!   (after the barometric setting, a slowly wandering metre);
//! - GNSS height error: white, σ_g = 2 m (a 10-satellite fix, as the paper's sky);
//! - truth height: 1200 m plus an altitude-hold wander of
//!   `15 sin(2πt/120) + 5 sin(2πt/37 + 0.7)` m — level flight is never perfectly flat, and
//!   the wander is what the paper's Fig. 3 predicts (it cancels in `dh`).
//!
//! The horizontal track (200 m/s along 135°) only places the epochs' GNSS fixes.

use rand_distr::{Distribution, Normal};

use super::faults::{Channel, Fault, FaultInjector, FaultKind};
use super::rng::{self, Stream};
use super::{SimError, check_non_negative, check_positive};
use navguard_core::epoch::Aid;
use navguard_core::epoch::Epoch;
use navguard_core::epoch::{AdsBlock, GnssBlock};
use navguard_core::geo;

/// The channel's name in the epochs.
pub const CHANNEL: &str = "dh";

/// Fault onset of seed 000, s.
pub const FAULT_START_S: f64 = 400.0;
/// Fault end of seed 000, s.
pub const FAULT_END_S: f64 = 600.0;

/// Scenario parameters (defaults: seed 000 §4 and the module doc's noise models).
#[derive(Debug, Clone, PartialEq)]
pub struct AdsGnssParams {
    /// Seed of every random stream.
    pub seed: u64,
    /// Length, s.
    pub duration_s: f64,
    /// Sample interval, s.
    pub dt_s: f64,
    /// Start latitude, longitude (deg), height (m).
    pub start: (f64, f64, f64),
    /// Heading, deg from north.
    pub heading_deg: f64,
    /// Ground speed, m/s.
    pub speed_mps: f64,
    /// GNSS height white noise, m.
    pub gnss_sigma_m: f64,
    /// Barometric error Gauss–Markov σ, m.
    pub baro_sigma_m: f64,
    /// Barometric error correlation time, s.
    pub baro_tau_s: f64,
    /// Faults on the GNSS height (the `gnss.position` channel, component 2, metres).
    pub faults: Vec<FaultKind>,
    /// Fault interval `[start, end)`, s.
    pub fault_interval_s: (f64, f64),
}

impl Default for AdsGnssParams {
    fn default() -> Self {
        AdsGnssParams {
            seed: 0,
            duration_s: 800.0,
            dt_s: 1.0,
            start: (34.0, 109.0, 1200.0),
            heading_deg: 135.0,
            speed_mps: 200.0,
            gnss_sigma_m: 2.0,
            baro_sigma_m: 1.0,
            baro_tau_s: 120.0,
            faults: vec![FaultKind::Ramp { rate: 1.0 }],
            fault_interval_s: (FAULT_START_S, FAULT_END_S),
        }
    }
}

/// The four fault cases of seed 000 Table 2, labelled as there.
pub fn table2_faults() -> [(&'static str, FaultKind); 4] {
    [
        ("90 m step", FaultKind::Step { value: 90.0 }),
        ("100 m step", FaultKind::Step { value: 100.0 }),
        ("1 m/s ramp", FaultKind::Ramp { rate: 1.0 }),
        ("2 m/s ramp", FaultKind::Ramp { rate: 2.0 }),
    ]
}

/// One flight: per sample, time, truth and measured heights, and the channel.
#[derive(Debug, Clone, PartialEq)]
pub struct AdsGnssRun {
    /// Sample times, s.
    pub t: Vec<f64>,
    /// True height, m.
    pub truth_h: Vec<f64>,
    /// GNSS height (faults included), m.
    pub gnss_h: Vec<f64>,
    /// Barometric height, m.
    pub baro_h: Vec<f64>,
    /// Whether a fault acts on the sample.
    pub faulty: Vec<bool>,
    /// GNSS latitude, longitude, rad.
    pub lat_lon: Vec<(f64, f64)>,
}

impl AdsGnssRun {
    /// The monitored channel `dh = gnss_h − baro_h`.
    pub fn channel(&self) -> Vec<f64> {
        self.gnss_h
            .iter()
            .zip(&self.baro_h)
            .map(|(g, b)| g - b)
            .collect()
    }

    /// The flight as monitor epochs: `gnss`, `ads` and `channels {dh}`.
    pub fn epochs(&self) -> Vec<Epoch> {
        let dh = self.channel();
        (0..self.t.len())
            .map(|k| Epoch {
                t: self.t[k],
                gnss: Some(GnssBlock {
                    lat: self.lat_lon[k].0,
                    lon: self.lat_lon[k].1,
                    h: self.gnss_h[k],
                    vel: None,
                    pos_sigma: None,
                    vel_sigma: None,
                }),
                ads: Some(AdsBlock {
                    baro_h: self.baro_h[k],
                    tas: None,
                }),
                channels: Some(vec![(CHANNEL.to_owned(), vec![dh[k]])]),
                ..Default::default()
            })
            .collect()
    }
}

/// The altitude-hold wander added to the start height, m (module doc).
pub fn wander_m(t: f64) -> f64 {
    use std::f64::consts::TAU;
    15.0 * (TAU * t / 120.0).sin() + 5.0 * (TAU * t / 37.0 + 0.7).sin()
}

/// Simulates one flight.
pub fn simulate(p: &AdsGnssParams) -> Result<AdsGnssRun, SimError> {
    check_positive("duration_s", p.duration_s)?;
    check_positive("dt_s", p.dt_s)?;
    check_non_negative("gnss_sigma_m", p.gnss_sigma_m)?;
    check_non_negative("baro_sigma_m", p.baro_sigma_m)?;
    check_positive("baro_tau_s", p.baro_tau_s)?;
    check_non_negative("speed_mps", p.speed_mps)?;
    let (start, end) = p.fault_interval_s;
    let faults: Vec<Fault> = p
        .faults
        .iter()
        .map(|&kind| Fault {
            aid: Aid::Gnss,
            channel: Channel::Position,
            component: 2,
            kind,
            start_s: start,
            end_s: Some(end),
        })
        .collect();
    let mut injector = FaultInjector::new(faults.clone())?;
    let mut gnss_rng = rng::stream(p.seed, Stream::Gnss);
    // The barometer is an air-data sensor: its own stream (the INS stream is unused here).
    let mut baro_rng = rng::stream(p.seed, Stream::Ins);
    let white =
        Normal::new(0.0, 1.0).map_err(|e| SimError::param("gnss_sigma_m", e.to_string()))?;
    // First-order Gauss–Markov, exact discretisation: x⁺ = φx + σ√(1−φ²) w.
    let phi = (-p.dt_s / p.baro_tau_s).exp();
    let q = p.baro_sigma_m * (1.0 - phi * phi).sqrt();
    let mut baro_err = p.baro_sigma_m * white.sample(&mut baro_rng);
    let n = (p.duration_s / p.dt_s).round() as usize;
    let (lat0, lon0, h0) = (p.start.0.to_radians(), p.start.1.to_radians(), p.start.2);
    let r = geo::radii(lat0);
    let (sin_h, cos_h) = p.heading_deg.to_radians().sin_cos();
    let mut run = AdsGnssRun {
        t: Vec::with_capacity(n),
        truth_h: Vec::with_capacity(n),
        gnss_h: Vec::with_capacity(n),
        baro_h: Vec::with_capacity(n),
        faulty: Vec::with_capacity(n),
        lat_lon: Vec::with_capacity(n),
    };
    for k in 0..n {
        let t = k as f64 * p.dt_s;
        let h = h0 + wander_m(t);
        let dist = p.speed_mps * t;
        let lat = lat0 + dist * cos_h / (r.meridian + h);
        let lon = lon0 + dist * sin_h / ((r.prime_vertical + h) * lat0.cos());
        let mut fix = [lon, lat, h + p.gnss_sigma_m * white.sample(&mut gnss_rng)];
        injector.apply(Aid::Gnss, Channel::Position, t, &mut fix, &[1.0, 1.0, 1.0]);
        if k > 0 {
            baro_err = phi * baro_err + q * white.sample(&mut baro_rng);
        }
        run.t.push(t);
        run.truth_h.push(h);
        run.gnss_h.push(fix[2]);
        run.baro_h.push(h + baro_err);
        run.faulty.push(faults.iter().any(|f| f.is_active(t)));
        run.lat_lon.push((fix[1], fix[0]));
    }
    Ok(run)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_adds_rate_times_elapsed_inside_the_interval_only() {
        let clean = simulate(&AdsGnssParams {
            faults: vec![],
            ..Default::default()
        })
        .unwrap();
        let ramp = simulate(&AdsGnssParams::default()).unwrap();
        assert_eq!(clean.t.len(), 800);
        for k in [0, 399, 600, 799] {
            assert_eq!(clean.gnss_h[k], ramp.gnss_h[k], "k = {k}");
            assert!(!ramp.faulty[k]);
        }
        for k in [400, 450, 599] {
            let d = ramp.gnss_h[k] - clean.gnss_h[k];
            assert!((d - (k as f64 - 400.0)).abs() < 1e-9, "k = {k}: {d}");
            assert!(ramp.faulty[k]);
        }
        // The barometer is untouched by the GNSS fault.
        assert_eq!(clean.baro_h, ramp.baro_h);
    }

    #[test]
    fn channel_noise_matches_the_chosen_models() {
        let run = simulate(&AdsGnssParams {
            faults: vec![],
            duration_s: 20_000.0,
            ..Default::default()
        })
        .unwrap();
        let dh = run.channel();
        let mean = dh.iter().sum::<f64>() / dh.len() as f64;
        let var = dh.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / dh.len() as f64;
        // var(n_g − δh_b) = σ_g² + σ_b² = 4 + 1.
        assert!((var - 5.0).abs() < 0.3, "{var}");
        // Heading 135°: the aircraft moves south-east.
        let (lat_end, lon_end) = run.lat_lon[run.t.len() - 1];
        assert!(lat_end < 34f64.to_radians() && lon_end > 109f64.to_radians());
    }
}
