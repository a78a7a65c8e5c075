//! REST bodies: session create requests, monitor specs, threshold views and updates.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use navguard_core::detect::PolicyConfig;
use navguard_core::monitor::MonitorKind;

use navguard_core::session::{AlarmLevel, TestThresholdSpec};

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

fn empty_object() -> serde_json::Value {
    serde_json::Value::Object(serde_json::Map::new())
}

/// The `tests` of a `PUT …/threshold` body that sets every calibrated test's proposed
/// level as its own `p_fa` (refused tests are left out).
pub fn calibrated_tests(
    lines: &[navguard_core::monitor::calibrate::CalibrationLine],
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
