//! Thresholds calibrated from fault-free data (docs/methods.md §M25): run a session's
//! monitors over recorded epochs with every test's threshold out of reach (so every
//! epoch is healthy and every filter updates, as in fault-free operation), collect
//! each test's statistic, and propose per test the threshold that gives a requested
//! false-alarm rate on that data, with a confidence bound.
//!
//! Statistics of one test may have several dofs (GNSS with and without velocity), so
//! each value is first mapped to its χ² upper-tail probability `u = 1 − F_χ²(dof)(v)`
//! (for the calibrated window tests this is their own tail, [`crate::detect::window`]).
//! A threshold is then a tail level `u*`: an epoch fails when `u < u*`. With `N` values
//! and `k` of them below `u*`, the true rate `F(u*)` of the `k`-th smallest value is
//! `Beta(k, N − k + 1)`; the proposal is the largest `k` for which
//! `P(Beta(k, N − k + 1) ≤ far) ≥ confidence`, i.e. `P(Bin(N, far) ≥ k) ≥ confidence`, so
//! the proposed level keeps the true rate at or below `far` with that confidence. It
//! needs `N ≥ ln(1 − confidence)/ln(1 − far)` epochs (about 3/far at 95 %); with fewer,
//! the test is refused, saying how many it needs. Values of consecutive epochs are
//! correlated (windowed tests especially), so the bound is optimistic by the ratio of
//! real to effective samples; the report states the count used.
//!
//! This module's replay is the out-of-reach one; [`live`] searches the level again with
//! the threshold in reach and checks it on held-out epochs, which is what the CLI and the
//! REST route run.
//!
//! The proposal is returned as the test's own `p_fa` (the level `u*`: each dof then gets
//! `F⁻¹_χ²(dof)(1 − u*)`) and, for the test's primary dof, the equivalent raw threshold,
//! beside the χ² threshold at `p_fa = far` it replaces and the rate that one would give
//! on this data.

use serde::Serialize;
use statrs::distribution::{Binomial, DiscreteCDF};

use super::{Monitor, StepError};
use crate::detect::{ThresholdSpec, chi2};
use crate::epoch::Epoch;

/// A threshold out of reach of any fault-free statistic, so calibration runs see only
/// healthy epochs. Not larger: the federated HPL needs the non-centrality that gives its
/// P_MD at the threshold, which is searched up to 1e8 (docs/methods.md §M1, §M7).
const OUT_OF_REACH: f64 = 1e7;

/// Why a test could not be calibrated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibrateError {
    /// The requested rate or confidence is not in (0, 1).
    #[error("{0} must lie in (0, 1)")]
    Range(&'static str),
    /// An option of a live calibration is out of its range.
    #[error("{0}")]
    Option(String),
    /// A test asked for is not one of the monitor's calibratable tests.
    #[error("no calibratable test '{name}' (the monitor's: {known})")]
    UnknownTest {
        /// The name asked for.
        name: String,
        /// The monitor's calibratable tests.
        known: String,
    },
    /// A monitor failed numerically on an epoch.
    #[error("epoch {index}: {source}")]
    Step {
        /// Index of the epoch in the data.
        index: usize,
        /// The failure.
        source: StepError,
    },
}

/// One test's statistics over the data.
#[derive(Debug, Clone, PartialEq)]
pub struct TestSample {
    /// Test name.
    pub test: String,
    /// The test's primary dof.
    pub dof: u32,
    /// Upper-tail probability of each epoch's statistic under its own dof.
    pub tails: Vec<f64>,
    /// Σ statistic and Σ dof over the epochs, for the noise scale.
    pub sums: (f64, f64),
    /// The test's own threshold spec before the run (a guard's `p_fa`, such as the stuck
    /// test's, or a per-test setting); `None` when it follows the monitor's.
    pub own_spec: Option<ThresholdSpec>,
}

impl TestSample {
    /// `sqrt(Σ statistic / Σ dof)`: the factor on the measurement σ that makes the mean
    /// χ² statistic equal its dof (1 when the noise model is right). For the `gnss`
    /// monitor's `raim` test it is the `config.sigma.scale` multiplier the data need.
    pub fn noise_scale(&self) -> Option<f64> {
        (self.sums.1 > 0.0).then(|| (self.sums.0 / self.sums.1).sqrt())
    }
}

/// What calibration proposes for one test.
#[derive(Debug, Clone, PartialEq)]
pub enum Proposal {
    /// A calibrated level.
    Calibrated {
        /// The tail level `u*` to set as the test's own `p_fa`.
        p_fa: f64,
        /// The raw threshold that level gives at the primary dof.
        threshold: f64,
        /// Epochs below the level in the data (`k`).
        below: usize,
    },
    /// Too few epochs for the rate asked.
    TooShort {
        /// Epochs needed.
        needed: usize,
    },
    /// The data's level would lower the threshold of a test with its own, stricter spec
    /// (a guard): it is left as it is.
    Stricter {
        /// The level the data would give.
        p_fa: f64,
        /// The test's own spec, kept.
        own: ThresholdSpec,
    },
    /// Exceedances come in runs of consecutive epochs (mean length `burst`), so the data
    /// hold fewer independent chances than epochs: too few for the rate asked ([`live`]).
    Bursty {
        /// Epochs of the calibration part needed at that burst length.
        needed: usize,
        /// Mean length of a run of exceedances.
        burst: f64,
    },
    /// Replayed with the candidate threshold in reach, no level kept the rate within
    /// `far` on the calibration epochs ([`live`]).
    NoFixedPoint {
        /// Replays tried.
        replays: usize,
    },
    /// The level calibrated on the first part of the data fails the held-out part more
    /// often than the transfer limit allows ([`live`]).
    NoTransfer {
        /// The level calibrated.
        p_fa: f64,
        /// The share of held-out epochs it fails.
        rate: f64,
        /// The transfer limit, a multiple of `far`.
        limit: f64,
    },
}

/// How a proposal did on held-out epochs ([`live`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Holdout {
    /// Held-out epochs on which the test ran.
    pub epochs: usize,
    /// The share of them the proposal fails (live thresholds, so learning freezes as it
    /// would in operation).
    pub rate: f64,
}

/// The calibration of one test.
#[derive(Debug, Clone, PartialEq)]
pub struct TestCalibration {
    /// Test name.
    pub test: String,
    /// Primary dof.
    pub dof: u32,
    /// Epochs on which the test ran.
    pub epochs: usize,
    /// The χ² threshold at `p_fa = far` for the primary dof (what the proposal replaces).
    pub chi2_threshold: f64,
    /// The share of epochs that χ² threshold would fail on this data.
    pub chi2_rate: f64,
    /// The proposal.
    pub proposal: Proposal,
    /// [`TestSample::noise_scale`].
    pub noise_scale: Option<f64>,
    /// Replays with the candidate threshold in reach ([`live`]; 0 for an out-of-reach
    /// calibration alone).
    pub replays: usize,
    /// The proposal on held-out epochs, when checked ([`live`]).
    pub holdout: Option<Holdout>,
}

/// One test's calibration as reported (CLI table, JSON and the REST answer).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CalibrationLine {
    /// Test name.
    pub test: String,
    /// Primary dof.
    pub dof: u32,
    /// Epochs on which the test ran.
    pub epochs: usize,
    /// The χ² threshold at `p_fa = far` it replaces.
    pub chi2_threshold: f64,
    /// The share of epochs that χ² threshold fails on the data.
    pub chi2_rate: f64,
    /// The proposed level, as the test's own `p_fa`, when calibrated.
    pub p_fa: Option<f64>,
    /// The raw threshold that level gives at the primary dof.
    pub threshold: Option<f64>,
    /// Why not, when refused.
    pub refused: Option<String>,
    /// `sqrt(Σ statistic / Σ dof)`: the factor on the measurement σ that makes the mean
    /// statistic its dof (docs/methods.md §M25).
    pub noise_scale: Option<f64>,
    /// Replays of the calibration epochs with the candidate threshold in reach (the
    /// fixed-point search); absent for an out-of-reach calibration.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub replays: Option<usize>,
    /// Held-out epochs on which the proposal was measured; absent when none were held out.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub holdout_epochs: Option<usize>,
    /// The share of held-out epochs the proposal fails.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub holdout_rate: Option<f64>,
}

impl From<&TestCalibration> for CalibrationLine {
    fn from(c: &TestCalibration) -> Self {
        let (p_fa, threshold, refused) = match c.proposal {
            Proposal::Calibrated {
                p_fa, threshold, ..
            } => (Some(p_fa), Some(threshold), None),
            Proposal::TooShort { needed } => (
                None,
                None,
                Some(format!(
                    "too short: {} epochs, the rate asked needs at least {needed}",
                    c.epochs
                )),
            ),
            Proposal::Stricter { p_fa, own } => (
                None,
                None,
                Some(format!(
                    "kept: the data's level (p_fa {p_fa:.3e}) would lower the threshold below the test's own ({})",
                    describe(own)
                )),
            ),
            Proposal::Bursty { needed, burst } => (
                None,
                None,
                Some(format!(
                    "too short for bursts: exceedances come in runs of {burst:.1} epochs on average, so the rate asked needs at least {needed} calibration epochs ({} here)",
                    c.epochs
                )),
            ),
            Proposal::NoFixedPoint { replays } => (
                None,
                None,
                Some(format!(
                    "no fixed point: in {replays} replays with the threshold in reach, no level kept the rate asked"
                )),
            ),
            Proposal::NoTransfer { p_fa, rate, limit } => (
                None,
                None,
                Some(format!(
                    "does not transfer: the level calibrated on the first part (p_fa {p_fa:.3e}) fails {rate:.3e} of the held-out epochs, above {limit} × the rate asked"
                )),
            ),
        };
        CalibrationLine {
            test: c.test.clone(),
            dof: c.dof,
            epochs: c.epochs,
            chi2_threshold: c.chi2_threshold,
            chi2_rate: c.chi2_rate,
            p_fa,
            threshold,
            refused,
            noise_scale: c.noise_scale,
            replays: (c.replays > 0).then_some(c.replays),
            holdout_epochs: c.holdout.map(|h| h.epochs),
            holdout_rate: c.holdout.map(|h| h.rate),
        }
    }
}

/// A threshold spec as a reader would write it.
fn describe(spec: ThresholdSpec) -> String {
    match spec {
        ThresholdSpec::PFa(p) => format!("p_fa {p:e}"),
        ThresholdSpec::Threshold(t) => format!("threshold {t}"),
    }
}

/// Calibrates every test of `monitor` on `epochs` ([`sample`] then [`calibrate`]).
pub fn calibrate_monitor(
    monitor: &mut dyn Monitor,
    epochs: &[Epoch],
    far: f64,
    confidence: f64,
) -> Result<Vec<CalibrationLine>, CalibrateError> {
    sample(monitor, epochs)?
        .iter()
        .map(|s| calibrate(s, far, confidence).map(|c| CalibrationLine::from(&c)))
        .collect()
}

/// Runs `monitor` over `epochs` with every test's threshold out of reach and collects
/// each test's tails. The monitor is reset first and left as the run leaves it.
pub fn sample(
    monitor: &mut dyn Monitor,
    epochs: &[Epoch],
) -> Result<Vec<TestSample>, CalibrateError> {
    let bank = monitor.tests_mut();
    // Each test's own spec is read before the run puts every threshold out of reach.
    let slots: Vec<(String, u32, Option<ThresholdSpec>, bool)> = bank
        .slots()
        .iter()
        .map(|s| (s.name.to_string(), s.dof, s.own_spec, s.own_policy))
        .collect();
    let out_of_reach = ThresholdSpec::Threshold(OUT_OF_REACH);
    // A raw threshold is valid for every dof, so this cannot fail.
    let _ = bank.set_spec(out_of_reach);
    let specs = vec![Some(out_of_reach); slots.len()];
    let tails = live::replay(monitor, epochs, &specs, epochs.len())?;
    // A test with its own policy and threshold (a protection level against its alert
    // limit) is not a χ² test: nothing to calibrate.
    Ok(slots
        .into_iter()
        .zip(tails)
        .filter(|((.., own_policy), _)| !own_policy)
        .map(|((test, dof, own_spec, _), t)| TestSample {
            test,
            dof,
            tails: t.before,
            sums: t.sums,
            own_spec,
        })
        .collect())
}

/// A statistic's upper-tail probability under the χ² law of its dof (1 for a zero).
fn tail(statistic: &crate::detect::Statistic) -> f64 {
    if statistic.value > 0.0 {
        chi2::false_alarm_probability(statistic.dof, statistic.value).unwrap_or(0.0)
    } else {
        1.0
    }
}

/// The smallest number of epochs that can support a rate of `far` at `confidence`.
pub fn epochs_needed(far: f64, confidence: f64) -> usize {
    ((1.0 - confidence).ln() / (1.0 - far).ln()).ceil() as usize
}

/// How many of `n` epochs may fall below a level whose true rate is at most `far` with
/// `confidence`: `k − 1` for the largest `k` with `P(Bin(n, far) ≥ k) ≥ confidence`
/// (`k = 1` holds once `n` reaches [`epochs_needed`]).
pub fn allowed_below(n: usize, far: f64, confidence: f64) -> usize {
    let Ok(bin) = Binomial::new(far, n as u64) else {
        return 0;
    };
    let mut k = 1;
    while k < n && 1.0 - bin.cdf(k as u64) >= confidence {
        k += 1;
    }
    k - 1
}

/// The `k`-th smallest of `tails` (1-based), clamped to a usable level: an epoch fails
/// when its tail is below it.
fn level_at(tails: &[f64], k: usize) -> f64 {
    let mut sorted = tails.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted[(k - 1).min(sorted.len() - 1)].clamp(1e-300, 0.5)
}

/// Proposes a threshold for one test at false-alarm rate `far` with `confidence`.
pub fn calibrate(
    sample: &TestSample,
    far: f64,
    confidence: f64,
) -> Result<TestCalibration, CalibrateError> {
    if !(far > 0.0 && far < 1.0) {
        return Err(CalibrateError::Range("far"));
    }
    if !(confidence > 0.0 && confidence < 1.0) {
        return Err(CalibrateError::Range("confidence"));
    }
    let n = sample.tails.len();
    let dof = sample.dof.max(1);
    let chi2_threshold = chi2::threshold(dof, far).unwrap_or(f64::NAN);
    let chi2_rate = if n == 0 {
        0.0
    } else {
        sample.tails.iter().filter(|&&u| u < far).count() as f64 / n as f64
    };
    let needed = epochs_needed(far, confidence);
    let mut proposal = Proposal::TooShort { needed };
    if n >= needed {
        let k = allowed_below(n, far, confidence) + 1;
        let level = level_at(&sample.tails, k);
        let threshold = chi2::threshold(dof, level).unwrap_or(f64::NAN);
        proposal = match sample.own_spec {
            // A guard's threshold is never lowered below the one its own spec gives.
            Some(own @ ThresholdSpec::PFa(p)) if level > p => {
                Proposal::Stricter { p_fa: level, own }
            }
            Some(own @ ThresholdSpec::Threshold(t)) if threshold < t => {
                Proposal::Stricter { p_fa: level, own }
            }
            _ => Proposal::Calibrated {
                p_fa: level,
                threshold,
                below: k - 1,
            },
        };
    }
    Ok(TestCalibration {
        test: sample.test.clone(),
        dof,
        epochs: n,
        chi2_threshold,
        chi2_rate,
        proposal,
        noise_scale: sample.noise_scale(),
        replays: 0,
        holdout: None,
    })
}

pub mod live;

#[cfg(test)]
mod tests;
