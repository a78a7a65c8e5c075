//! Calibration under the live feedback (docs/methods.md §M25): a monitor whose learning
//! or filtering depends on its own decisions (a channel predictor that learns only while
//! healthy, a filter that stops updating on a suspect aid) has a statistic whose law
//! depends on the threshold. Replaying with every threshold out of reach measures a
//! process that never freezes; a threshold set from it fails more often live.
//!
//! So the calibration part of the data is replayed with the candidate level *in reach*,
//! and the level searched for is a fixed point: the largest level `u` such that, with `u`
//! live, at most `allowed_below(n, far, confidence)` epochs fall below `u` (the same
//! binomial promise as [`super::calibrate`]). The first candidate is the out-of-reach
//! proposal; if it holds live, nothing larger can (larger levels only fail more). If it
//! does not, the level the live run's data give is tried next, until one holds; then the
//! gap between the largest level that held and the smallest that did not is halved
//! geometrically until their ratio is within [`TOLERANCE`]. Every selected test searches
//! its own level in the same replays; the others run at their configured thresholds.
//!
//! Then the whole recording is replayed once with the proposals live: on the calibration
//! part each must still hold (else the search is reported without a fixed point), and the
//! share of the held-out part (the end of the data) each fails is reported; a proposal
//! failing more than `max_transfer × far` of it is refused as not transferring.

use super::{
    CalibrateError, CalibrationLine, Holdout, OUT_OF_REACH, Proposal, TestCalibration, TestSample,
    allowed_below, calibrate, epochs_needed, level_at, tail,
};
use crate::detect::{ThresholdSpec, chi2};
use crate::epoch::Epoch;
use crate::monitor::Monitor;
use crate::monitor::guards::is_guard;

/// The search stops when the largest level that held and the smallest that did not are
/// within this ratio.
pub const TOLERANCE: f64 = 1.05;

/// Runs of exceedances averaging fewer epochs are taken as independent. At the rates
/// calibration serves (≤ 1e-2) independent exceedances average under 1.01 epochs, but one
/// chance pair among a few dozen exceedances gives 1.03–1.1; a pair among three, 1.5
/// (probability ≈ 3/n).
pub const MIN_BURST: f64 = 1.5;

/// What to calibrate and how.
#[derive(Debug, Clone, PartialEq)]
pub struct LiveOptions {
    /// The false-alarm rate per epoch and test asked.
    pub far: f64,
    /// Confidence that the true rate at a proposal is at most `far`.
    pub confidence: f64,
    /// The tests to calibrate by name; `None`: the monitor's main tests (every χ² test but
    /// the `.drift` and `.stuck` guards).
    pub tests: Option<Vec<String>>,
    /// The share of the epochs, at the end, held out to measure the proposal on (0: none).
    pub holdout: f64,
    /// The largest held-out rate accepted, as a multiple of `far`.
    pub max_transfer: f64,
    /// Most replays of the calibration part in the search.
    pub max_replays: usize,
}

impl LiveOptions {
    /// The defaults for `far` and `confidence`: main tests, half the data held out, a
    /// transfer limit of 2 × `far`, at most 12 replays.
    pub fn new(far: f64, confidence: f64) -> Self {
        LiveOptions {
            far,
            confidence,
            tests: None,
            holdout: 0.5,
            max_transfer: 2.0,
            max_replays: 12,
        }
    }

    fn check(&self) -> Result<(), CalibrateError> {
        if !(self.far > 0.0 && self.far < 1.0) {
            return Err(CalibrateError::Range("far"));
        }
        if !(self.confidence > 0.0 && self.confidence < 1.0) {
            return Err(CalibrateError::Range("confidence"));
        }
        if !(0.0..=0.9).contains(&self.holdout) {
            return Err(CalibrateError::Option(
                "holdout must lie in [0, 0.9]".into(),
            ));
        }
        if !(self.max_transfer >= 1.0 && self.max_transfer.is_finite()) {
            return Err(CalibrateError::Option(
                "max_transfer must be at least 1".into(),
            ));
        }
        if self.max_replays == 0 {
            return Err(CalibrateError::Option(
                "max_replays must be at least 1".into(),
            ));
        }
        Ok(())
    }
}

/// One test's tails in one replay, before and after the split, and its Σ statistic and
/// Σ dof over all epochs (the noise scale is a property of the whole recording).
#[derive(Debug, Default)]
pub(super) struct Tails {
    pub(super) before: Vec<f64>,
    pub(super) after: Vec<f64>,
    pub(super) sums: (f64, f64),
}

/// Calibrates the selected tests of `monitor` on `epochs` under the live feedback (module
/// doc). The monitor is reset before each replay and left as the last one leaves it.
pub fn calibrate_live(
    monitor: &mut dyn Monitor,
    epochs: &[Epoch],
    options: &LiveOptions,
) -> Result<Vec<CalibrationLine>, CalibrateError> {
    options.check()?;
    let selected = select(monitor, options.tests.as_deref())?;
    let own: Vec<Option<ThresholdSpec>> = monitor
        .tests_mut()
        .slots()
        .iter()
        .map(|s| s.own_spec)
        .collect();
    let split = epochs.len() - (options.holdout * epochs.len() as f64).floor() as usize;
    let (far, confidence) = (options.far, options.confidence);

    // The out-of-reach replay: the first candidates and the noise scales.
    let mut specs = own.clone();
    for &i in &selected {
        specs[i] = Some(ThresholdSpec::Threshold(OUT_OF_REACH));
    }
    let first = replay(monitor, epochs, &specs, split)?;
    let mut results: Vec<TestCalibration> = selected
        .iter()
        .map(|&i| calibrate(&sample_of(monitor, i, &first[i], own[i]), far, confidence))
        .collect::<Result<_, _>>()?;
    if options.holdout > 0.0 {
        refuse_short(
            &mut results,
            &selected,
            &first,
            far,
            confidence,
            options.holdout,
        );
    }

    let mut searches: Vec<Search> = selected
        .iter()
        .zip(&results)
        .enumerate()
        .filter_map(|(result, (&index, r))| match r.proposal {
            Proposal::Calibrated { p_fa, .. } => Some(Search::new(index, result, p_fa)),
            _ => None,
        })
        .collect();
    let mut replays = 0;
    while replays < options.max_replays && searches.iter().any(|s| !s.done) {
        for s in &searches {
            specs[s.index] = Some(ThresholdSpec::PFa(s.candidate()));
        }
        let run = replay(monitor, &epochs[..split], &specs, split)?;
        replays += 1;
        for s in searches.iter_mut().filter(|s| !s.done) {
            s.update(&run[s.index].before, far, confidence);
        }
    }
    for s in &searches {
        results[s.result].replays = replays;
    }
    finish(
        monitor,
        epochs,
        split,
        options,
        &own,
        &searches,
        &mut results,
    )?;
    Ok(results.iter().map(CalibrationLine::from).collect())
}

/// Refuses every test that has too few epochs in either part for the rate asked, saying
/// how many epochs both parts need together.
fn refuse_short(
    results: &mut [TestCalibration],
    selected: &[usize],
    first: &[Tails],
    far: f64,
    confidence: f64,
    holdout: f64,
) {
    let needed = epochs_needed(far, confidence);
    let total = [holdout, 1.0 - holdout]
        .iter()
        .map(|share| (needed as f64 / share).ceil() as usize)
        .fold(needed, usize::max);
    for (r, &i) in results.iter_mut().zip(selected) {
        let (before, after) = (first[i].before.len(), first[i].after.len());
        if before < needed || after < needed {
            r.epochs = before + after;
            r.proposal = Proposal::TooShort { needed: total };
        }
    }
}

/// The final replay over all epochs with every found level live: the fixed point checked
/// on the calibration part, the transfer measured on the held-out part.
fn finish(
    monitor: &mut dyn Monitor,
    epochs: &[Epoch],
    split: usize,
    options: &LiveOptions,
    own: &[Option<ThresholdSpec>],
    searches: &[Search],
    results: &mut [TestCalibration],
) -> Result<(), CalibrateError> {
    let mut specs = own.to_vec();
    for s in searches {
        if let Some(level) = s.held {
            specs[s.index] = Some(ThresholdSpec::PFa(level));
        }
    }
    let run = replay(monitor, epochs, &specs, split)?;
    for s in searches {
        let r = &mut results[s.result];
        let replays = r.replays;
        let tails = &run[s.index];
        let n = tails.before.len();
        let runs = s.held.map(|level| Runs::at(&tails.before, level));
        let burst = s.burst.max(runs.map_or(1.0, Runs::burst));
        let needed = epochs_needed(options.far / burst, options.confidence);
        if burst > 1.0 && n < needed {
            r.proposal = Proposal::Bursty { needed, burst };
            continue;
        }
        let (Some(level), Some(runs)) = (s.held, runs) else {
            r.proposal = Proposal::NoFixedPoint { replays };
            continue;
        };
        if runs.runs > allowed_below(n, options.far / burst, options.confidence) {
            r.proposal = Proposal::NoFixedPoint { replays };
            continue;
        }
        let below = runs.below;
        r.proposal = Proposal::Calibrated {
            p_fa: level,
            threshold: chi2::threshold(r.dof, level).unwrap_or(f64::NAN),
            below,
        };
        if options.holdout > 0.0 && !tails.after.is_empty() {
            let n = tails.after.len();
            let rate = tails.after.iter().filter(|&&u| u < level).count() as f64 / n as f64;
            r.holdout = Some(Holdout { epochs: n, rate });
            if rate > options.max_transfer * options.far {
                r.proposal = Proposal::NoTransfer {
                    p_fa: level,
                    rate,
                    limit: options.max_transfer,
                };
            }
        }
    }
    Ok(())
}

/// The indices of the tests to calibrate: those named, or the main tests.
fn select(
    monitor: &mut dyn Monitor,
    names: Option<&[String]>,
) -> Result<Vec<usize>, CalibrateError> {
    let bank = monitor.tests_mut();
    let calibratable = |i: usize| !bank.slots()[i].own_policy;
    match names {
        None => Ok((0..bank.slots().len())
            .filter(|&i| calibratable(i) && !is_guard(&bank.slots()[i].name))
            .collect()),
        Some(names) => {
            let mut out = Vec::new();
            for name in names {
                match bank.index_of(name) {
                    Some(i) if calibratable(i) => {
                        if !out.contains(&i) {
                            out.push(i);
                        }
                    }
                    _ => {
                        let known: Vec<&str> = (0..bank.slots().len())
                            .filter(|&i| calibratable(i))
                            .map(|i| &*bank.slots()[i].name)
                            .collect();
                        return Err(CalibrateError::UnknownTest {
                            name: name.clone(),
                            known: known.join(", "),
                        });
                    }
                }
            }
            Ok(out)
        }
    }
}

/// A [`TestSample`] of test `index` from one replay's calibration part (its sums over
/// all epochs).
fn sample_of(
    monitor: &mut dyn Monitor,
    index: usize,
    tails: &Tails,
    own_spec: Option<ThresholdSpec>,
) -> TestSample {
    let slot = &monitor.tests_mut().slots()[index];
    TestSample {
        test: slot.name.to_string(),
        dof: slot.dof,
        tails: tails.before.clone(),
        sums: tails.sums,
        own_spec,
    }
}

/// Replays `epochs` through `monitor` (reset first) with test `i`'s spec `specs[i]`
/// (`None`: the monitor's), returning every test's tails before and after epoch `split`.
pub(super) fn replay(
    monitor: &mut dyn Monitor,
    epochs: &[Epoch],
    specs: &[Option<ThresholdSpec>],
    split: usize,
) -> Result<Vec<Tails>, CalibrateError> {
    monitor.reset();
    let bank = monitor.tests_mut();
    for (i, &spec) in specs.iter().enumerate() {
        // Levels are in (0, 0.5] and raw thresholds positive: valid for every dof.
        let _ = bank.set_test_spec(i, spec);
    }
    let mut tails: Vec<Tails> = specs.iter().map(|_| Tails::default()).collect();
    for (index, epoch) in epochs.iter().enumerate() {
        let report = monitor
            .step(epoch)
            .map_err(|source| CalibrateError::Step { index, source })?;
        for o in report.tests {
            let (v, tail) = (o.statistic.value, tail(&o.statistic));
            let t = &mut tails[o.index];
            t.sums.0 += v;
            t.sums.1 += f64::from(o.statistic.dof);
            if index < split {
                t.before.push(tail);
            } else {
                t.after.push(tail);
            }
        }
    }
    Ok(tails)
}

/// The exceedances of a level in one replay's tails (in epoch order) and the runs of
/// consecutive ones they form.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Runs {
    below: usize,
    runs: usize,
}

impl Runs {
    fn at(tails: &[f64], level: f64) -> Self {
        let (mut below, mut runs, mut inside) = (0, 0, false);
        for &u in tails {
            let now = u < level;
            below += usize::from(now);
            runs += usize::from(now && !inside);
            inside = now;
        }
        Runs { below, runs }
    }

    /// Mean run length, taken as 1 (independent exceedances) below [`MIN_BURST`].
    fn burst(self) -> f64 {
        let mean = self.below as f64 / self.runs.max(1) as f64;
        if mean < MIN_BURST { 1.0 } else { mean }
    }
}

/// One test's fixed-point search over levels (module doc).
#[derive(Debug)]
struct Search {
    /// The test's index in the bank.
    index: usize,
    /// Its calibration in the results.
    result: usize,
    /// The largest level that held live.
    held: Option<f64>,
    /// The smallest level that did not.
    failed: Option<f64>,
    /// The next level to try.
    next: f64,
    /// The largest mean length of a run of consecutive exceedances seen (1 for
    /// independent ones): the promise counts runs at rate `far / burst`.
    burst: f64,
    done: bool,
}

impl Search {
    fn new(index: usize, result: usize, first: f64) -> Self {
        Search {
            index,
            result,
            held: None,
            failed: None,
            next: first,
            burst: 1.0,
            done: false,
        }
    }

    fn candidate(&self) -> f64 {
        if self.done {
            self.held.unwrap_or(self.next)
        } else {
            self.next
        }
    }

    /// Takes the tails of a replay with `next` live.
    fn update(&mut self, tails: &[f64], far: f64, confidence: f64) {
        let tried = self.next;
        let runs = Runs::at(tails, tried);
        self.burst = self.burst.max(runs.burst());
        if tails.len() < epochs_needed(far / self.burst, confidence) {
            // Too few epochs for runs this long at any level: reported as such.
            self.done = true;
            return;
        }
        let allowed = allowed_below(tails.len(), far / self.burst, confidence);
        if runs.runs <= allowed {
            self.held = Some(tried);
        } else {
            self.failed = Some(tried);
        }
        // The level with about `allowed` runs of the present length below it.
        let allowed = (allowed as f64 * self.burst).floor() as usize;
        match (self.held, self.failed) {
            (Some(lo), Some(hi)) if hi / lo > TOLERANCE => self.next = (lo * hi).sqrt(),
            // The level this run's data give is below the one tried.
            (None, _) => self.next = level_at(tails, allowed + 1).min(tried / TOLERANCE),
            // The first level holds live (nothing larger can), or the gap is closed.
            _ => self.done = true,
        }
    }
}

#[cfg(test)]
mod tests;
