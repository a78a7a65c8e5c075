//! Drift and stuck tests beside an innovation χ² test (docs/methods.md §M23): the
//! `<test>.drift` windowed-mean test ([`WindowTest`] on whitened innovations, known
//! covariance `I`, calibrated by batch means once enough healthy blocks exist) and the
//! `<test>.stuck` variance-collapse test ([`StuckTest`], docs/methods.md §M21), each a test
//! of its own in the monitor's [`TestBank`] under the monitor's policy. The `linear`
//! monitor guards its `residual` test with them, the `federated` monitor each aid's test.
//!
//! A guarded filter's decision is the *combination* of its tests' decisions
//! ([`combine`]): the worst health, an update only if every test allows it, fusion only
//! if every test allows it. So a drift test's first exceedance stops the aid's update
//! under counters (predict only) exactly as its χ² test's would: a fused aid that went on
//! updating would partly absorb its own drift into the solution it is tested against.
//!
//! Both tests take the normalised innovation `ν = L⁻¹ r` (`S = L Lᵀ`) of the guarded
//! test, or a fixed part of it (the federated GNSS test's position components).

use serde::{Deserialize, Serialize};

use super::{ConfigError, StepError, TestBank, TestOutcome};
use crate::detect::stuck::{self, StuckParams, StuckTest};
use crate::detect::window::{WindowParams, WindowTest};
use crate::detect::{Decision, Health, PolicyConfig, PolicyState, ThresholdError, ThresholdSpec};
use crate::filter::kalman::FilterError;

/// Default drift window, epochs of the guarded test (docs/methods.md §M23): a windowed mean
/// of length `w` on a ramp detected after `n` epochs is most sensitive at `w ≈ 2n/3`, where
/// it needs only ≈ 4 % more epochs than the matched ramp test; seed 004's 10 m GNSS at 1 Hz
/// detects a 1 m/s drift after about 18 epochs, hence 12 (8–15 measure alike on 20 seeds).
pub const DEFAULT_DRIFT_WINDOW: usize = 12;
/// Most window lengths one drift test combines (Bonferroni over them).
pub const MAX_DRIFT_WINDOWS: usize = 4;
/// Longest drift window, epochs.
pub const MAX_DRIFT_WINDOW: usize = 1000;
/// Largest stuck-test window, differences.
pub const MAX_STUCK_K: usize = 1000;

/// The `drift` block of a guarded test (`linear`'s top level, each federated aid's
/// section): a windowed-mean test on its normalised innovations (docs/methods.md §M23).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DriftConfigWire {
    /// Run the test. Default true for a block that is given (a section's own default
    /// says whether a missing block runs).
    pub enabled: bool,
    /// Window lengths in epochs of the guarded test (1 to [`MAX_DRIFT_WINDOWS`] distinct
    /// values, each 1 to [`MAX_DRIFT_WINDOW`]). Default `[12]` ([`DEFAULT_DRIFT_WINDOW`]).
    pub windows: Vec<usize>,
    /// The test's own false-alarm probability per epoch; default: the monitor's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub p_fa: Option<f64>,
    /// The test's own raw threshold (on its χ² scale); excludes `p_fa`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub threshold: Option<f64>,
}

impl Default for DriftConfigWire {
    fn default() -> Self {
        DriftConfigWire {
            enabled: true,
            windows: vec![DEFAULT_DRIFT_WINDOW],
            p_fa: None,
            threshold: None,
        }
    }
}

impl DriftConfigWire {
    /// A block that turns the test off.
    pub fn disabled() -> Self {
        DriftConfigWire {
            enabled: false,
            ..DriftConfigWire::default()
        }
    }
}

/// The `stuck` block of a guarded test: a variance-collapse test on its normalised
/// innovations (docs/methods.md §M21, §M23).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StuckConfigWire {
    /// Run the test. Default true for a block that is given.
    pub enabled: bool,
    /// Successive differences in the window (2 to [`MAX_STUCK_K`]). Default 8.
    pub k: usize,
    /// The test's own false-alarm probability per epoch; default 1e-6 (whatever the
    /// monitor's: a freeze is an exact condition, so the test can afford near silence).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub p_fa: Option<f64>,
    /// The test's own raw threshold (χ²(1) scale); excludes `p_fa`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub threshold: Option<f64>,
}

impl Default for StuckConfigWire {
    fn default() -> Self {
        StuckConfigWire {
            enabled: true,
            k: stuck::DEFAULT_K,
            p_fa: None,
            threshold: None,
        }
    }
}

impl StuckConfigWire {
    /// A block that turns the test off.
    pub fn disabled() -> Self {
        StuckConfigWire {
            enabled: false,
            ..StuckConfigWire::default()
        }
    }
}

/// A validated drift test.
#[derive(Debug, Clone, PartialEq)]
pub struct DriftConfig {
    /// Window lengths, epochs.
    pub windows: Vec<usize>,
    /// Its own threshold spec; `None` follows the monitor's.
    pub spec: Option<ThresholdSpec>,
}

/// A validated stuck test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StuckConfig {
    /// Differences in the window.
    pub k: usize,
    /// Its threshold spec (its own: default p_fa 1e-6).
    pub spec: ThresholdSpec,
}

/// The guards of one test, validated.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GuardConfig {
    /// The drift test, when enabled.
    pub drift: Option<DriftConfig>,
    /// The stuck test, when enabled.
    pub stuck: Option<StuckConfig>,
}

/// Whether `test` is a drift or stuck guard of another test (`<test>.drift`,
/// `<test>.stuck`), as opposed to a monitor's main test.
pub fn is_guard(test: &str) -> bool {
    test.ends_with(".drift") || test.ends_with(".stuck")
}

/// `path.field`, or `field` at the root.
fn at(path: &str, field: &str) -> String {
    if path.is_empty() {
        field.to_owned()
    } else {
        format!("{path}.{field}")
    }
}

/// The optional `p_fa` / `threshold` pair of a block at `path`.
fn own_spec(
    path: &str,
    p_fa: Option<f64>,
    threshold: Option<f64>,
) -> Result<Option<ThresholdSpec>, ConfigError> {
    match (p_fa, threshold) {
        (Some(_), Some(_)) => Err(ConfigError::new(path, "give p_fa or threshold, not both")),
        (Some(p), None) if !(p > 0.0 && p < 1.0) => {
            Err(ConfigError::new(at(path, "p_fa"), "must be in (0, 1)"))
        }
        (None, Some(t)) if !(t.is_finite() && t > 0.0) => Err(ConfigError::new(
            at(path, "threshold"),
            "must be a finite number > 0",
        )),
        (Some(p), None) => Ok(Some(ThresholdSpec::PFa(p))),
        (None, Some(t)) => Ok(Some(ThresholdSpec::Threshold(t))),
        (None, None) => Ok(None),
    }
}

impl DriftConfigWire {
    /// Validates the block at `path` (`drift`, `gnss.drift`, …); `None` when disabled.
    /// A disabled block is checked too, so a bad value is refused whatever `enabled` says.
    pub fn validate(&self, path: &str) -> Result<Option<DriftConfig>, ConfigError> {
        let field = at(path, "windows");
        if self.windows.is_empty() || self.windows.len() > MAX_DRIFT_WINDOWS {
            return Err(ConfigError::new(
                field,
                format!("must list 1 to {MAX_DRIFT_WINDOWS} window lengths"),
            ));
        }
        for (i, &n) in self.windows.iter().enumerate() {
            if !(1..=MAX_DRIFT_WINDOW).contains(&n) {
                return Err(ConfigError::new(
                    format!("{field}[{i}]"),
                    format!("must be 1 to {MAX_DRIFT_WINDOW} epochs"),
                ));
            }
            if self.windows[..i].contains(&n) {
                return Err(ConfigError::new(
                    format!("{field}[{i}]"),
                    "duplicate window",
                ));
            }
        }
        let spec = own_spec(path, self.p_fa, self.threshold)?;
        Ok(self.enabled.then(|| DriftConfig {
            windows: self.windows.clone(),
            spec,
        }))
    }
}

impl StuckConfigWire {
    /// Validates the block at `path` (`stuck`, `gnss.stuck`, …); `None` when disabled.
    pub fn validate(&self, path: &str) -> Result<Option<StuckConfig>, ConfigError> {
        if !(2..=MAX_STUCK_K).contains(&self.k) {
            return Err(ConfigError::new(
                at(path, "k"),
                format!("must be 2 to {MAX_STUCK_K} differences"),
            ));
        }
        let spec = own_spec(path, self.p_fa, self.threshold)?
            .unwrap_or(ThresholdSpec::PFa(stuck::DEFAULT_P_FA));
        Ok(self.enabled.then_some(StuckConfig { k: self.k, spec }))
    }
}

/// Validates a test's `drift` and `stuck` blocks under `path` (empty at the root).
pub fn validate(
    path: &str,
    drift: &DriftConfigWire,
    stuck: &StuckConfigWire,
) -> Result<GuardConfig, ConfigError> {
    Ok(GuardConfig {
        drift: drift.validate(&at(path, "drift"))?,
        stuck: stuck.validate(&at(path, "stuck"))?,
    })
}

/// How severe a health is: healthy < suspect < isolated.
fn severity(h: Health) -> u8 {
    match h {
        Health::Healthy => 0,
        Health::Suspect => 1,
        Health::Isolated => 2,
    }
}

/// The worse of two healths.
pub fn worse(a: Health, b: Health) -> Health {
    if severity(b) > severity(a) { b } else { a }
}

/// The decision for a filter guarded by two tests: the worse health, an update only if
/// both allow it, fusion only if both allow it. `reset` is left to the caller (it depends
/// on the filter's previous combined health, not on one test's).
pub fn combine(a: Decision, b: Decision) -> Decision {
    Decision {
        health: worse(a.health, b.health),
        update: a.update && b.update,
        fuse: a.fuse && b.fuse,
        reset: false,
    }
}

/// What a test that did not run this epoch asks of the filter, given its state: no update
/// unless healthy (or under `traditional`), no fusion when isolated.
fn standing(bank: &TestBank, index: usize) -> Decision {
    let policy = &bank.slots()[index].policy;
    let health = policy.health();
    Decision {
        health,
        update: health == Health::Healthy || policy.config() == PolicyConfig::Traditional,
        fuse: health != Health::Isolated,
        reset: false,
    }
}

/// One guard: its index in the bank and its running test.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Guard<T> {
    index: usize,
    test: T,
}

/// The drift and stuck tests of one guarded test (serde: a monitor checkpoint saves them,
/// [`InnovationGuards::restored`] checks them).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct InnovationGuards {
    drift: Option<Guard<WindowTest>>,
    stuck: Option<Guard<StuckTest>>,
    dim: usize,
}

/// One epoch's evaluation of the guards, committed with the monitor's step.
#[derive(Debug, Clone, Default)]
pub struct GuardPreview {
    drift: Option<(TestOutcome, PolicyState)>,
    stuck: Option<(TestOutcome, PolicyState)>,
}

fn step_error(_: impl std::fmt::Display) -> StepError {
    StepError::Filter(FilterError::NonFinite("drift or stuck test input"))
}

impl InnovationGuards {
    /// Registers `{name}.drift` (dof `dim`) and `{name}.stuck` (dof 1) in `bank` as
    /// `config` asks, over inputs of `dim` components.
    pub fn new(
        bank: &mut TestBank,
        name: &str,
        dim: usize,
        config: &GuardConfig,
    ) -> Result<Self, ThresholdError> {
        let drift = match &config.drift {
            Some(d) => {
                let index = bank.add_test(&format!("{name}.drift"), dim as u32, d.spec)?;
                let test = WindowTest::with_known_covariance(
                    WindowParams::new(dim, &d.windows),
                    nalgebra::DMatrix::identity(dim, dim),
                )
                .expect("the identity is a valid covariance");
                Some(Guard { index, test })
            }
            None => None,
        };
        let stuck = match &config.stuck {
            Some(s) => {
                let index = bank.add_test(&format!("{name}.stuck"), 1, Some(s.spec))?;
                let params = StuckParams {
                    k: s.k,
                    ..StuckParams::new(dim)
                };
                Some(Guard {
                    index,
                    test: StuckTest::new(params),
                })
            }
            None => None,
        };
        Ok(InnovationGuards { drift, stuck, dim })
    }

    /// `saved` (read from a checkpoint) as the running state of these guards: the same
    /// tests at the same bank indices over inputs of the same dimension, each test's state
    /// fitting its parameters; the reason otherwise.
    pub fn restored(&self, saved: InnovationGuards) -> Result<InnovationGuards, String> {
        if saved.dim != self.dim {
            return Err(format!(
                "guards over {} components, the monitor's over {}",
                saved.dim, self.dim
            ));
        }
        let drift = match (&self.drift, saved.drift) {
            (None, None) => None,
            (Some(mine), Some(theirs)) if theirs.index == mine.index => Some(Guard {
                index: mine.index,
                test: mine.test.restored(theirs.test)?,
            }),
            _ => return Err("another drift test".into()),
        };
        let stuck = match (&self.stuck, saved.stuck) {
            (None, None) => None,
            (Some(mine), Some(theirs)) if theirs.index == mine.index => Some(Guard {
                index: mine.index,
                test: mine.test.restored(theirs.test)?,
            }),
            _ => return Err("another stuck test".into()),
        };
        Ok(InnovationGuards {
            drift,
            stuck,
            dim: self.dim,
        })
    }

    /// True when neither test runs.
    pub fn is_empty(&self) -> bool {
        self.drift.is_none() && self.stuck.is_none()
    }

    /// The bank indices of the guards' tests.
    pub fn indices(&self) -> impl Iterator<Item = usize> + '_ {
        self.drift
            .iter()
            .map(|g| g.index)
            .chain(self.stuck.iter().map(|g| g.index))
    }

    /// The tests' values for this epoch's input and their previewed policy steps,
    /// changing nothing; a test still warming up gives none.
    pub fn preview(&self, bank: &TestBank, input: &[f64]) -> Result<GuardPreview, StepError> {
        let mut out = GuardPreview::default();
        self.preview_into(bank, input, &mut out)?;
        Ok(out)
    }

    /// [`InnovationGuards::preview`] written into `out` (a caller's buffer: no preview is
    /// moved through the step). On an error `out` is left partly written.
    pub fn preview_into(
        &self,
        bank: &TestBank,
        input: &[f64],
        out: &mut GuardPreview,
    ) -> Result<(), StepError> {
        out.drift = None;
        out.stuck = None;
        if let Some(g) = &self.drift
            && let Some(v) = g.test.evaluate(input).map_err(step_error)?
        {
            out.drift = Some(bank.preview(g.index, v.value, self.dim as u32)?);
        }
        if let Some(g) = &self.stuck
            && let Some(v) = g.test.evaluate(input).map_err(step_error)?
        {
            out.stuck = Some(bank.preview(g.index, v.value, 1)?);
        }
        Ok(())
    }

    /// `decision` combined with the guards' decisions for this epoch (`preview`), or,
    /// for a guard that did not run, with what its standing state asks.
    pub fn combined(
        &self,
        bank: &TestBank,
        preview: &GuardPreview,
        decision: Decision,
    ) -> Decision {
        let mut d = decision;
        if let Some(g) = &self.drift {
            d = combine(
                d,
                preview
                    .drift
                    .as_ref()
                    .map_or_else(|| standing(bank, g.index), |p| p.0.decision),
            );
        }
        if let Some(g) = &self.stuck {
            d = combine(
                d,
                preview
                    .stuck
                    .as_ref()
                    .map_or_else(|| standing(bank, g.index), |p| p.0.decision),
            );
        }
        d.reset = decision.reset && d.health == Health::Healthy;
        d
    }

    /// `decision` (the guarded test's idle decision on an epoch without data) combined
    /// with the guards' idle decisions.
    pub fn idle(&self, bank: &TestBank, decision: Decision) -> Decision {
        let mut d = decision;
        for i in self.indices() {
            d = combine(d, bank.idle(i));
        }
        d.update = false;
        d
    }

    /// The worst health among the guards' tests now (before this epoch's commit).
    pub fn worst_health(&self, bank: &TestBank) -> Health {
        self.indices()
            .map(|i| bank.slots()[i].policy.health())
            .fold(Health::Healthy, worse)
    }

    /// Commits a preview (taking its outcomes, so it is left empty): the policy states, the
    /// outcomes appended to `tests`, and the input to both tests (`healthy`: the guarded
    /// filter's combined health this epoch was healthy, so the input may enter the healthy
    /// history).
    pub fn commit(
        &mut self,
        bank: &mut TestBank,
        preview: &mut GuardPreview,
        input: &[f64],
        healthy: bool,
        tests: &mut Vec<TestOutcome>,
    ) {
        if let Some(g) = &mut self.drift {
            if let Some((outcome, state)) = preview.drift.take() {
                bank.commit(g.index, state);
                tests.push(outcome);
            }
            // Checked by the preview (same input), so it cannot fail here.
            let _ = g.test.commit(input, healthy);
        }
        if let Some(g) = &mut self.stuck {
            if let Some((outcome, state)) = preview.stuck.take() {
                bank.commit(g.index, state);
                tests.push(outcome);
            }
            let _ = g.test.commit(input, healthy);
        }
    }

    /// Forgets the inputs seen (a new stream).
    pub fn reset(&mut self) {
        if let Some(g) = &mut self.drift {
            g.test.reset();
        }
        if let Some(g) = &mut self.stuck {
            g.test.reset();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn drift(v: serde_json::Value) -> Result<Option<DriftConfig>, ConfigError> {
        serde_json::from_value::<DriftConfigWire>(v)
            .unwrap()
            .validate("gnss.drift")
    }

    #[test]
    fn a_given_block_is_enabled_with_the_defaults() {
        let d = drift(json!({})).unwrap().unwrap();
        assert_eq!(d.windows, vec![DEFAULT_DRIFT_WINDOW]);
        assert_eq!(d.spec, None);
        let d = drift(json!({"windows": [5, 20], "p_fa": 1e-4}))
            .unwrap()
            .unwrap();
        assert_eq!(d.windows, vec![5, 20]);
        assert_eq!(d.spec, Some(ThresholdSpec::PFa(1e-4)));
        assert_eq!(drift(json!({"enabled": false})).unwrap(), None);
        let s = StuckConfigWire::default()
            .validate("stuck")
            .unwrap()
            .unwrap();
        assert_eq!(s.spec, ThresholdSpec::PFa(stuck::DEFAULT_P_FA));
        assert_eq!(s.k, stuck::DEFAULT_K);
    }

    #[test]
    fn bad_blocks_name_the_exact_field() {
        let cases = [
            (json!({"windows": []}), "gnss.drift.windows"),
            (json!({"windows": [1, 2, 3, 4, 5]}), "gnss.drift.windows"),
            (json!({"windows": [0]}), "gnss.drift.windows[0]"),
            (json!({"windows": [10, 10]}), "gnss.drift.windows[1]"),
            (json!({"windows": [2000]}), "gnss.drift.windows[0]"),
            (json!({"p_fa": 1.5}), "gnss.drift.p_fa"),
            (json!({"threshold": -1}), "gnss.drift.threshold"),
            (json!({"p_fa": 0.01, "threshold": 3}), "gnss.drift"),
            (
                json!({"enabled": false, "windows": [0]}),
                "gnss.drift.windows[0]",
            ),
        ];
        for (v, field) in cases {
            assert_eq!(drift(v.clone()).unwrap_err().field, field, "{v}");
        }
        let stuck = |v: serde_json::Value| {
            serde_json::from_value::<StuckConfigWire>(v)
                .unwrap()
                .validate("stuck")
                .unwrap_err()
                .field
        };
        assert_eq!(stuck(json!({"k": 1})), "stuck.k");
        assert_eq!(stuck(json!({"p_fa": 0})), "stuck.p_fa");
        assert_eq!(stuck(json!({"threshold": 0})), "stuck.threshold");
        assert_eq!(stuck(json!({"p_fa": 1e-6, "threshold": 30})), "stuck");
    }

    #[test]
    fn combined_decisions_take_the_worst_health_and_need_every_test_to_agree() {
        let healthy = Decision {
            health: Health::Healthy,
            update: true,
            fuse: true,
            reset: true,
        };
        let suspect = Decision {
            health: Health::Suspect,
            update: false,
            fuse: true,
            reset: false,
        };
        let isolated = Decision {
            health: Health::Isolated,
            update: false,
            fuse: false,
            reset: false,
        };
        let d = combine(healthy, suspect);
        assert_eq!((d.health, d.update, d.fuse), (Health::Suspect, false, true));
        let d = combine(suspect, isolated);
        assert_eq!(
            (d.health, d.update, d.fuse),
            (Health::Isolated, false, false)
        );
        assert_eq!(worse(Health::Isolated, Health::Healthy), Health::Isolated);
        assert!(
            !combine(healthy, healthy).reset,
            "the caller decides resets"
        );
    }

    #[test]
    fn guards_register_their_tests_and_a_drift_stops_the_update() {
        let mut bank = TestBank::new(
            &[("residual", 2)],
            ThresholdSpec::PFa(1e-3),
            PolicyConfig::counters_default(),
        )
        .unwrap();
        let config =
            validate("", &DriftConfigWire::default(), &StuckConfigWire::default()).unwrap();
        let mut g = InnovationGuards::new(&mut bank, "residual", 2, &config).unwrap();
        let names: Vec<_> = bank.slots().iter().map(|s| (&*s.name, s.dof)).collect();
        assert_eq!(
            names,
            vec![
                ("residual", 2),
                ("residual.drift", 2),
                ("residual.stuck", 1)
            ]
        );
        // χ²(1) at 1e-6, the stuck test's own spec.
        assert!((bank.slots()[2].threshold - 23.9281).abs() < 1e-3);
        let healthy = Decision {
            health: Health::Healthy,
            update: true,
            fuse: true,
            reset: false,
        };
        // A mean of 2σ per component: after a full window the drift test fires.
        let mut tests = Vec::new();
        let mut stopped = None;
        for k in 0..DEFAULT_DRIFT_WINDOW as u32 {
            let input = [2.0 + 0.1 * f64::from(k % 3), 2.0 - 0.1 * f64::from(k % 2)];
            let mut p = g.preview(&bank, &input).unwrap();
            let d = g.combined(&bank, &p, healthy);
            if !d.update && stopped.is_none() {
                stopped = Some(k);
            }
            g.commit(
                &mut bank,
                &mut p,
                &input,
                d.health == Health::Healthy,
                &mut tests,
            );
            // The commit took the outcomes: a preview is committed once.
            assert!(p.drift.is_none() && p.stuck.is_none());
        }
        assert_eq!(
            stopped,
            Some(DEFAULT_DRIFT_WINDOW as u32 - 1),
            "the first full window"
        );
        assert_eq!(tests.last().unwrap().name.as_ref(), "residual.drift");
        assert_eq!(bank.slots()[1].policy.health(), Health::Suspect);
        assert_eq!(g.worst_health(&bank), Health::Suspect);
        let idle = g.idle(&bank, healthy);
        assert_eq!((idle.health, idle.update), (Health::Suspect, false));
        g.reset();
    }
}
