//! The `imu-channel` scenario (seed 001 §4, docs/methods.md §M19): the pitch-rate gyro of an
//! aircraft in longitudinal flight, 135 samples at 1 Hz (the paper's 135 points, with its
//! 5 s input/output delay read as a 5-sample embedding), with one of seed 001's four
//! sensor fault modes from k = 80 on, and optionally injected spikes for the outlier
//! filter. Sits upstream of the `channel` monitor and the seed 001 experiment.
//!
//! Signal. The paper's flight-control model (its eqs. 1–2) is not in the text we have,
//! so the true pitch rate is a pitch oscillation of growing amplitude,
//! `q(k) = A(k) (3 sin(2πk/40 + 0.5) + sin(2πk/20 + 0.5))` °/s with `A(k) = 0.8 + 0.4 k/135`
//! (the growth is what a model trained once cannot follow and a sliding window can; the
//! phase puts k = 80 at q ≈ 2 °/s and rising, so a failure `out = 0` and a stuck output
//! are real changes, not coincidences with the signal), measured with white noise
//! σ = 0.3 °/s. Faults use [`FaultKind`] from [`super::faults`] on this scalar
//! channel, as seed 001 §1 defines them: stuck `out = C` (the reading at the onset,
//! held), constant gain `out = K·u` (K = 1.5), constant bias `out = u + M` (M = 1 °/s)
//! and complete failure `out = 0`. Spikes (outliers): ±15 °/s on single samples every
//! 15 samples from k = 20, alternating in sign.

use rand_distr::{Distribution, Normal};

use super::SimError;
use super::faults::FaultKind;
use super::rng::{self, Stream};
use navguard_core::epoch::Epoch;

/// Samples in the paper's run.
pub const SAMPLES: usize = 135;
/// Fault onset, sample index (seed 001 §4.2).
pub const FAULT_K: usize = 80;
/// The channel's name in the epochs.
pub const CHANNEL: &str = "gyro";
/// Measurement noise, °/s.
pub const NOISE_DPS: f64 = 0.3;
/// Spike magnitude, °/s.
pub const SPIKE_DPS: f64 = 15.0;

/// The four fault modes of seed 001 §1 with the magnitudes of the module doc.
pub fn fault_modes() -> [(&'static str, FaultKind); 4] {
    [
        ("stuck", FaultKind::Stuck),
        ("gain", FaultKind::Gain { k: 1.5 }),
        ("bias", FaultKind::Bias { m: 1.0 }),
        ("failure", FaultKind::Failure),
    ]
}

/// The true pitch rate at sample `k`, °/s.
pub fn truth(k: usize) -> f64 {
    truth_at(k as f64)
}

/// The true pitch rate at sample `k` of the paper's record, `k < 0` included (the
/// lead-in of [`simulate_with_lead_in`]): before the record the amplitude grows
/// exponentially into its k = 0 value and slope, `A(k) = 0.8 exp(k/270)`, so the
/// oscillation keeps growing at the record's relative rate (≈ 0.37 % a sample) rather
/// than changing regime at k = 0.
pub fn truth_at(k: f64) -> f64 {
    use std::f64::consts::TAU;
    let amplitude = if k >= 0.0 {
        0.8 + 0.4 * k / 135.0
    } else {
        0.8 * (k / 270.0).exp()
    };
    amplitude * (3.0 * (TAU * k / 40.0 + 0.5).sin() + (TAU * k / 20.0 + 0.5).sin())
}

/// One gyro record.
#[derive(Debug, Clone, PartialEq)]
pub struct ImuChannelRun {
    /// True rate, °/s.
    pub truth: Vec<f64>,
    /// Measured rate (noise, fault, spikes), °/s.
    pub measured: Vec<f64>,
    /// Indices of injected spikes.
    pub spikes: Vec<usize>,
    /// Index of the fault onset in this record (`FAULT_K` plus the lead-in).
    pub fault_k: usize,
}

impl ImuChannelRun {
    /// The record as monitor epochs (`t = k` s, `channels {gyro}`).
    pub fn epochs(&self) -> Vec<Epoch> {
        self.measured
            .iter()
            .enumerate()
            .map(|(k, &v)| Epoch {
                t: k as f64,
                channels: Some(vec![(CHANNEL.to_owned(), vec![v])]),
                ..Default::default()
            })
            .collect()
    }
}

/// Applies a seed 001 fault to the healthy reading `u` (stuck holds `held`, the reading at
/// the onset); `elapsed` is the time since the onset for a ramp. `Missing` keeps `u`.
pub fn apply_fault(kind: FaultKind, u: f64, held: f64, elapsed: f64) -> f64 {
    match kind {
        FaultKind::Stuck => held,
        FaultKind::Gain { k } => k * u,
        FaultKind::Bias { m } => u + m,
        FaultKind::Step { value } => u + value,
        FaultKind::Ramp { rate } => u + rate * elapsed,
        FaultKind::Failure => 0.0,
        FaultKind::Missing => u,
    }
}

/// Simulates `samples` readings with an optional fault from `FAULT_K` on and optional spikes.
pub fn simulate(
    seed: u64,
    samples: usize,
    fault: Option<FaultKind>,
    spikes: bool,
) -> Result<ImuChannelRun, SimError> {
    simulate_with_lead_in(seed, 0, samples, fault, spikes)
}

/// [`simulate`] with `lead_in` fault-free samples before the paper's record (the same
/// oscillation at its starting amplitude), so a monitor that needs a healthy history
/// has one before k = 80: sample `lead_in + k` is the record's sample k, and the fault
/// starts at `lead_in + FAULT_K`. Spikes stay on the record's own indices (shifted).
pub fn simulate_with_lead_in(
    seed: u64,
    lead_in: usize,
    samples: usize,
    fault: Option<FaultKind>,
    spikes: bool,
) -> Result<ImuChannelRun, SimError> {
    if samples == 0 {
        return Err(SimError::param("samples", "must be ≥ 1"));
    }
    // The gyro is an inertial sensor: the INS stream.
    let mut rng = rng::stream(seed, Stream::Ins);
    let noise = Normal::new(0.0, NOISE_DPS).map_err(|e| SimError::param("noise", e.to_string()))?;
    let total = lead_in + samples;
    let truth: Vec<f64> = (0..total)
        .map(|k| truth_at(k as f64 - lead_in as f64))
        .collect();
    let mut measured: Vec<f64> = truth.iter().map(|&q| q + noise.sample(&mut rng)).collect();
    let fault_k = lead_in + FAULT_K;
    if let Some(kind) = fault {
        let held = measured.get(fault_k).copied().unwrap_or(0.0);
        for (k, v) in measured.iter_mut().enumerate().skip(fault_k) {
            *v = apply_fault(kind, *v, held, (k - fault_k) as f64);
        }
    }
    let spike_at: Vec<usize> = if spikes {
        (lead_in + 20..total).step_by(15).collect()
    } else {
        Vec::new()
    };
    for (i, &k) in spike_at.iter().enumerate() {
        measured[k] += if i % 2 == 0 { SPIKE_DPS } else { -SPIKE_DPS };
    }
    Ok(ImuChannelRun {
        truth,
        measured,
        spikes: spike_at,
        fault_k,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_fault_mode_acts_from_k80_as_seed_001_defines_it() {
        let clean = simulate(1, SAMPLES, None, false).unwrap();
        for (name, kind) in fault_modes() {
            let run = simulate(1, SAMPLES, Some(kind), false).unwrap();
            assert_eq!(run.measured[..FAULT_K], clean.measured[..FAULT_K], "{name}");
            let (u, v) = (clean.measured[100], run.measured[100]);
            let want = match name {
                "stuck" => clean.measured[FAULT_K],
                "gain" => 1.5 * u,
                "bias" => u + 1.0,
                _ => 0.0,
            };
            assert!((v - want).abs() < 1e-12, "{name}: {v} vs {want}");
        }
    }

    #[test]
    fn spikes_alternate_and_noise_is_small() {
        let run = simulate(2, SAMPLES, None, true).unwrap();
        assert_eq!(run.spikes, vec![20, 35, 50, 65, 80, 95, 110, 125]);
        assert!((run.measured[20] - run.truth[20] - SPIKE_DPS).abs() < 0.5);
        assert!((run.measured[35] - run.truth[35] + SPIKE_DPS).abs() < 0.5);
        let quiet: f64 = (0..SAMPLES)
            .filter(|k| !run.spikes.contains(k))
            .map(|k| (run.measured[k] - run.truth[k]).abs())
            .fold(0.0, f64::max);
        assert!(quiet < 5.0 * NOISE_DPS, "{quiet}");
        assert!(simulate(2, 0, None, false).is_err());
    }

    #[test]
    fn a_lead_in_prepends_healthy_samples_and_shifts_the_onset() {
        let run = simulate_with_lead_in(3, 200, SAMPLES, Some(FaultKind::Failure), false).unwrap();
        assert_eq!(run.measured.len(), 200 + SAMPLES);
        assert_eq!(run.fault_k, 200 + FAULT_K);
        assert_ne!(run.measured[run.fault_k - 1], 0.0);
        assert_eq!(run.measured[run.fault_k], 0.0);
        // The record's truth is the paper's, shifted; the lead-in grows into it.
        assert!((run.truth[200 + 50] - truth(50)).abs() < 1e-12);
        assert!((run.truth[0] - truth_at(-200.0)).abs() < 1e-12);
        assert_eq!(simulate(3, SAMPLES, None, false).unwrap().fault_k, FAULT_K);
    }
}
