//! Thresholds, policies and alarm levels of a session's monitors: the view the threshold
//! routes answer, a `PUT` applied all or nothing, and the configuration re-applied after a
//! checkpoint restore (docs/architecture.md §A3, §A14).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::SessionCore;
use super::rule::AlarmLevel;
use crate::detect::{PolicyConfig, ThresholdSpec};
use crate::monitor::TestBank;

/// One test's own threshold: exactly one of `p_fa` and `threshold`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TestThresholdSpec {
    /// False-alarm probability for the test's dof.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub p_fa: Option<f64>,
    /// Raw threshold.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threshold: Option<f64>,
}

/// `PUT /api/v1/sessions/{id}/monitors/{name}/threshold` body.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThresholdUpdate {
    /// New false-alarm probability.
    #[serde(default)]
    pub p_fa: Option<f64>,
    /// New raw threshold.
    #[serde(default)]
    pub threshold: Option<f64>,
    /// New policy.
    #[serde(default)]
    pub policy: Option<PolicyConfig>,
    /// New alarm level for the monitor.
    #[serde(default)]
    pub alarm_level: Option<AlarmLevel>,
    /// Per-test thresholds to set (a test's `p_fa` or `threshold`), or with `null` to
    /// return to the monitor's. Tests not named keep what they have.
    #[serde(default)]
    pub tests: Option<BTreeMap<String, Option<TestThresholdSpec>>>,
}

/// A test's effective threshold, as reported by the threshold routes.
#[derive(Debug, Clone, Serialize)]
pub struct TestThreshold {
    /// Degrees of freedom.
    pub dof: u32,
    /// Effective threshold.
    pub threshold: f64,
    /// False-alarm probability that threshold gives for the dof.
    pub p_fa: f64,
    /// The test has a threshold of its own (per-test setting or its kind's default),
    /// which the monitor's `p_fa`/`threshold` does not change.
    pub own: bool,
}

/// Threshold and policy of one monitor (`GET`/`PUT …/threshold`).
#[derive(Debug, Clone, Serialize)]
pub struct ThresholdView {
    /// Monitor name.
    pub monitor: String,
    /// The stated false-alarm probability, when the spec is a probability.
    pub p_fa: Option<f64>,
    /// The stated raw threshold, when the spec is a raw value.
    pub threshold: Option<f64>,
    /// Decision policy.
    pub policy: PolicyConfig,
    /// Which state change is an alarm.
    pub alarm_level: AlarmLevel,
    /// Effective threshold per test.
    pub tests: BTreeMap<String, TestThreshold>,
}

/// A refused threshold change: the field (`p_fa`, `policy`, `tests.<name>`; `None` for
/// the body as a whole) and why. Nothing was changed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{reason}")]
pub struct ThresholdRefusal {
    /// The offending field.
    pub field: Option<String>,
    /// Why it was refused.
    pub reason: String,
}

impl ThresholdRefusal {
    fn at(field: impl Into<String>, reason: impl ToString) -> Self {
        ThresholdRefusal {
            field: Some(field.into()),
            reason: reason.to_string(),
        }
    }
}

/// A test's own threshold spec from its wire form: exactly one of `p_fa` and
/// `threshold`, each in range.
pub fn test_spec(wire: &TestThresholdSpec) -> Result<ThresholdSpec, String> {
    if wire.p_fa.is_none() && wire.threshold.is_none() {
        return Err("give `p_fa` or `threshold` (or null to follow the monitor's)".into());
    }
    ThresholdSpec::from_parts(wire.p_fa, wire.threshold).map_err(|e| e.to_string())
}

/// Why a test name is refused: the monitor has no such test (its tests listed).
pub fn unknown_test(test: &str, bank: &TestBank) -> String {
    let names: Vec<&str> = bank.slots().iter().map(|s| &*s.name).collect();
    format!(
        "no test '{test}' in this monitor; its tests are {}",
        names.join(", ")
    )
}

/// What a monitor had before a change was applied, to undo it when it cannot be stored.
#[derive(Debug, Clone)]
pub struct Undo {
    index: usize,
    bank: TestBank,
    level: AlarmLevel,
}

/// The bank `update` makes of `bank`: everything is applied to a copy, so a refused part
/// changes nothing.
fn updated_bank(bank: &TestBank, update: &ThresholdUpdate) -> Result<TestBank, ThresholdRefusal> {
    let mut bank = bank.clone();
    if update.p_fa.is_some() || update.threshold.is_some() {
        let spec = ThresholdSpec::from_parts(update.p_fa, update.threshold)
            .map_err(|e| ThresholdRefusal::at("p_fa", e))?;
        bank.set_spec(spec)
            .map_err(|e| ThresholdRefusal::at("p_fa", e))?;
    }
    if let Some(policy) = update.policy {
        policy
            .check()
            .map_err(|e| ThresholdRefusal::at("policy", e))?;
        bank.set_policy(policy);
    }
    for (test, spec) in update.tests.iter().flatten() {
        let field = format!("tests.{test}");
        let Some(i) = bank.index_of(test) else {
            return Err(ThresholdRefusal::at(field, unknown_test(test, &bank)));
        };
        let own = spec
            .map(|s| test_spec(&s))
            .transpose()
            .map_err(|e| ThresholdRefusal::at(field.clone(), e))?;
        bank.set_test_spec(i, own)
            .map_err(|e| ThresholdRefusal::at(field, e))?;
    }
    Ok(bank)
}

impl SessionCore {
    /// The thresholds, policy and alarm level of monitor `index`.
    pub fn threshold_view(&self, index: usize) -> ThresholdView {
        let member = &self.roster[index];
        let bank = self.engines[index].tests();
        let spec = bank.spec();
        ThresholdView {
            monitor: member.name.clone(),
            p_fa: spec.p_fa_part(),
            threshold: spec.threshold_part(),
            policy: bank.policy(),
            alarm_level: member.rule.level,
            tests: bank
                .slots()
                .iter()
                .map(|s| {
                    let own = s.own_spec.unwrap_or(spec);
                    let p_fa = own.p_fa(s.dof).unwrap_or(f64::NAN);
                    (
                        s.name.to_string(),
                        TestThreshold {
                            dof: s.dof,
                            threshold: s.threshold,
                            p_fa,
                            own: s.own_spec.is_some(),
                        },
                    )
                })
                .collect(),
        }
    }

    /// Applies `update` to monitor `index` from the next epoch on, all or nothing, and
    /// shows the new thresholds in the statistics. Returns what undoes it.
    pub fn apply_threshold(
        &mut self,
        index: usize,
        update: &ThresholdUpdate,
    ) -> Result<Undo, ThresholdRefusal> {
        if update.p_fa.is_none()
            && update.threshold.is_none()
            && update.policy.is_none()
            && update.alarm_level.is_none()
            && update.tests.is_none()
        {
            return Err(ThresholdRefusal {
                field: None,
                reason: "give `p_fa` or `threshold`, `policy`, `alarm_level` and/or `tests`".into(),
            });
        }
        let bank = updated_bank(self.engines[index].tests(), update)?;
        let undo = Undo {
            index,
            bank: std::mem::replace(self.engines[index].tests_mut(), bank),
            level: self.roster[index].rule.level,
        };
        if let Some(level) = update.alarm_level {
            self.roster[index].rule.level = level;
        }
        self.show_thresholds(index);
        Ok(undo)
    }

    /// Puts back what a change replaced (it could not be stored).
    pub fn undo_threshold(&mut self, undo: Undo) {
        *self.engines[undo.index].tests_mut() = undo.bank;
        self.roster[undo.index].rule.level = undo.level;
        self.show_thresholds(undo.index);
    }

    /// Copies monitor `index`'s thresholds into its tests' statistics.
    fn show_thresholds(&mut self, index: usize) {
        self.each_test_of(index, |slot, stats| stats.threshold = slot.threshold);
    }
}

/// Gives `restored` the thresholds and policies of `configured` (built from the stored
/// spec) where they differ, as a `PUT …/threshold` would, keeping the restored counters
/// where the configuration did not change.
pub(super) fn reapply_configuration(restored: &mut TestBank, configured: &TestBank) {
    if restored.policy() != configured.policy() {
        restored.set_policy(configured.policy());
    }
    if restored.spec() != configured.spec() {
        // The configured spec was valid when it was built from; it stays valid here.
        let _ = restored.set_spec(configured.spec());
    }
    for (i, slot) in configured.slots().iter().enumerate() {
        let differs = restored
            .slots()
            .get(i)
            .is_some_and(|r| r.own_spec != slot.own_spec);
        if differs {
            let _ = restored.set_test_spec(i, slot.own_spec);
        }
    }
}
