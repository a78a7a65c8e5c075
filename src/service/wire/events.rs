//! Outbound events: the `result`, `state`, `alarm` and `error` messages the server sends.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::ingest::{FrameError, FrameErrorCode};
use crate::detect::{Health, Statistic};
use crate::monitor::MonitorReport;

// ------------------------------------------------------------- server messages

/// One test's result in a `result` frame.
#[derive(Debug, Clone, Serialize)]
pub struct TestResultWire {
    /// The statistic.
    pub statistic: f64,
    /// Effective threshold.
    pub threshold: f64,
    /// Degrees of freedom.
    pub dof: u32,
    /// statistic / threshold.
    pub test_ratio: f64,
    /// Health after this epoch.
    pub state: Health,
}

impl TestResultWire {
    /// From a statistic and the decided health.
    pub fn new(s: &Statistic, state: Health) -> Self {
        TestResultWire {
            statistic: s.value,
            threshold: s.threshold,
            dof: s.dof,
            test_ratio: s.test_ratio(),
            state,
        }
    }
}

/// One monitor's part of a `result` frame.
#[derive(Debug, Clone, Serialize)]
pub struct MonitorResultWire<'a> {
    /// Tests that ran this epoch.
    pub tests: BTreeMap<crate::monitor::TestName, TestResultWire>,
    /// Monitor outputs, flattened beside `tests`.
    #[serde(flatten)]
    pub outputs: &'a crate::monitor::Outputs,
}

/// Builds the wire form of one monitor's report.
pub fn monitor_result(report: &MonitorReport) -> MonitorResultWire<'_> {
    MonitorResultWire {
        tests: report
            .tests
            .iter()
            .map(|o| {
                (
                    o.name.clone(),
                    TestResultWire::new(&o.statistic, o.decision.health),
                )
            })
            .collect(),
        outputs: &report.outputs,
    }
}

/// An alarm: a test's transition into suspect or isolated, as stored and sent.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct AlarmRecord {
    /// Store id (increasing).
    pub id: i64,
    /// Session id.
    pub session: String,
    /// Monitor name.
    pub monitor: String,
    /// Test name.
    pub test: String,
    /// The state entered: `suspect` or `isolated`.
    pub state: Health,
    /// Epoch time of the transition, s.
    pub t: f64,
    /// Statistic at the transition.
    pub statistic: f64,
    /// Threshold at the transition.
    pub threshold: f64,
    /// Degrees of freedom.
    pub dof: u32,
    /// statistic / threshold.
    pub test_ratio: f64,
    /// Seconds from the first exceedance of this episode to the alarm.
    pub delay_s: f64,
    /// Wall-clock time the alarm was raised, Unix milliseconds.
    pub raised_at_ms: i64,
    /// Epoch time the test returned to healthy, once it has.
    pub cleared_t: Option<f64>,
}

/// A health change of one test.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct StateChange {
    /// Session id.
    pub session: String,
    /// Monitor name.
    pub monitor: String,
    /// Test name.
    pub test: String,
    /// Epoch time, s.
    pub t: f64,
    /// Previous state.
    pub from: Health,
    /// New state.
    pub to: Health,
}

/// The `error` event.
#[derive(Debug, Clone, Serialize)]
pub struct ErrorEvent<'a> {
    /// Always `error`.
    #[serde(rename = "type")]
    pub kind: &'static str,
    /// Stable code.
    pub code: FrameErrorCode,
    /// Reason.
    pub message: &'a str,
    /// Offending epoch within a batch, when known.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub index: Option<usize>,
}

impl<'a> From<&'a FrameError> for ErrorEvent<'a> {
    fn from(e: &'a FrameError) -> Self {
        ErrorEvent {
            kind: "error",
            code: e.code,
            message: &e.message,
            index: e.index,
        }
    }
}

/// Wraps a serialisable body as `{"type": kind, ...body}`.
#[derive(Debug, Clone, Serialize)]
pub struct Tagged<'a, T: Serialize> {
    /// Message type.
    #[serde(rename = "type")]
    pub kind: &'static str,
    /// The body, flattened.
    #[serde(flatten)]
    pub body: &'a T,
}

/// Serialises `{"type": kind, ...body}` to a string.
pub fn tagged<T: Serialize>(kind: &'static str, body: &T) -> String {
    serde_json::to_string(&Tagged { kind, body }).unwrap_or_else(|e| {
        // Serialising our own plain structs cannot fail; keep the socket alive if it ever does.
        format!(r#"{{"type":"error","code":"internal","message":"{e}"}}"#)
    })
}
