//! REST bodies: session create requests, monitor specs, threshold views and updates.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::detect::{Health, PolicyConfig};
use crate::monitor::MonitorKind;

use super::events::Severity;

/// Which state change is an *alarm* (docs/architecture.md §A2): entering `isolated`
/// only (the default: entering `suspect` is then a *warning*, stored and announced as a
/// `state` event but not as an `alarm`), or entering `suspect` already. Under the
/// `classic` and `traditional` policies a test never is suspect, so both read the same.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlarmLevel {
    /// Entering `suspect` (and `isolated`) raises an alarm.
    Suspect,
    /// Entering `isolated` raises an alarm; entering `suspect` a warning.
    #[default]
    Isolated,
}

impl AlarmLevel {
    /// The severity of entering `state` (`None` for healthy).
    pub fn severity(self, state: Health) -> Option<Severity> {
        match (state, self) {
            (Health::Healthy, _) => None,
            (Health::Isolated, _) | (Health::Suspect, AlarmLevel::Suspect) => Some(Severity::Alarm),
            (Health::Suspect, AlarmLevel::Isolated) => Some(Severity::Warning),
        }
    }
}

/// `POST /api/v1/sessions` body.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CreateSession {
    /// Optional id; generated when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<String>,
    /// The monitors to run on the stream.
    pub monitors: Vec<MonitorSpecWire>,
    /// Send one `result` per epoch back on the ingest socket.
    #[serde(default)]
    pub echo: bool,
    /// Which state change is an alarm, for every monitor that does not say (default
    /// `isolated`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alarm_level: Option<AlarmLevel>,
    /// Record every accepted frame (default: the server's `--record`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub record: Option<bool>,
}

/// One monitor in a session spec, as the user writes it and as it is stored.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MonitorSpecWire {
    /// Name, unique within the session.
    pub name: String,
    /// Monitor kind.
    #[serde(rename = "type")]
    pub kind: MonitorKind,
    /// Kind-specific configuration.
    #[serde(default = "empty_object")]
    pub config: serde_json::Value,
    /// Decision policy (default classic).
    #[serde(default)]
    pub policy: PolicyConfig,
    /// False-alarm probability (exclusive with `threshold`; default 0.002).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub p_fa: Option<f64>,
    /// Raw threshold (exclusive with `p_fa`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threshold: Option<f64>,
    /// Which state change is an alarm for this monitor (default: the session's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alarm_level: Option<AlarmLevel>,
    /// Per-test thresholds that override the monitor's `p_fa`/`threshold` (e.g. from
    /// `navguard calibrate`), by test name (`thresholds` on the wire: a monitor's view
    /// also has `tests`).
    #[serde(
        default,
        rename = "thresholds",
        skip_serializing_if = "BTreeMap::is_empty"
    )]
    pub tests: BTreeMap<String, TestThresholdSpec>,
}

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

fn empty_object() -> serde_json::Value {
    serde_json::Value::Object(serde_json::Map::new())
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

/// The `tests` of a `PUT …/threshold` body that sets every calibrated test's proposed
/// level as its own `p_fa` (refused tests are left out).
pub fn calibrated_tests(
    lines: &[crate::monitor::calibrate::CalibrationLine],
) -> BTreeMap<String, TestThresholdSpec> {
    lines
        .iter()
        .filter_map(|l| {
            Some((
                l.test.clone(),
                TestThresholdSpec {
                    p_fa: Some(l.p_fa?),
                    threshold: None,
                },
            ))
        })
        .collect()
}
