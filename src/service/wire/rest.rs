//! REST bodies: session create requests, monitor specs, threshold views and updates.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::detect::PolicyConfig;
use crate::monitor::MonitorKind;

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
    /// Effective threshold per test.
    pub tests: BTreeMap<String, TestThreshold>,
}
