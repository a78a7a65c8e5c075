//! Outbound events: the `result`, `state`, `alarm` and `error` messages the server sends.

use std::collections::BTreeMap;

use serde::ser::SerializeMap;
use serde::{Deserialize, Serialize, Serializer};

use super::ingest::{FrameError, FrameErrorCode};
use crate::detect::{Health, Statistic};
use crate::monitor::{Availability, Integrity, MonitorReport, TestOutcome};

/// How loud a state change is (docs/architecture.md §A2): an `alarm` is stored,
/// announced as an `alarm` event and counted; a `warning` is stored and announced only
/// as a `state` event.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Severity {
    /// An alarm.
    #[default]
    Alarm,
    /// A warning.
    Warning,
}

impl Severity {
    /// The wire and store name.
    pub fn as_str(self) -> &'static str {
        match self {
            Severity::Alarm => "alarm",
            Severity::Warning => "warning",
        }
    }

    /// Parses the store name.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "alarm" => Some(Severity::Alarm),
            "warning" => Some(Severity::Warning),
            _ => None,
        }
    }
}

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

/// A monitor's integrity on the wire: availability, protection level, alert limit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct IntegrityWire {
    /// `converging`, `available` or `unavailable`.
    pub state: Availability,
    /// Protection level, m.
    pub protection_level: f64,
    /// Alert limit, m.
    pub alert_limit: f64,
}

impl From<&Integrity> for IntegrityWire {
    fn from(i: &Integrity) -> Self {
        IntegrityWire {
            state: i.state,
            protection_level: i.protection_level,
            alert_limit: i.alert_limit,
        }
    }
}

/// One monitor's part of a `result` frame.
#[derive(Debug, Clone, Serialize)]
pub struct MonitorResultWire<'a> {
    /// Tests that ran this epoch, by name.
    pub tests: TestsWire<'a>,
    /// Integrity availability, for monitors with a protection level.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub integrity: Option<IntegrityWire>,
    /// Monitor outputs, flattened beside `tests`.
    #[serde(flatten)]
    pub outputs: &'a crate::monitor::Outputs,
}

/// The tests of one report as a JSON object keyed by test name in name order, as a
/// `BTreeMap` of them writes it (a name given twice keeps its last outcome), but without
/// building that map when the report already lists its tests in name order.
#[derive(Debug, Clone, Copy)]
pub struct TestsWire<'a>(pub &'a [TestOutcome]);

impl Serialize for TestsWire<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let result = |o: &TestOutcome| TestResultWire::new(&o.statistic, o.decision.health);
        let tests = self.0;
        let mut map = serializer.serialize_map(Some(tests.len()))?;
        if tests.windows(2).all(|w| w[0].name < w[1].name) {
            for o in tests {
                map.serialize_entry(&*o.name, &result(o))?;
            }
        } else {
            let sorted: BTreeMap<&str, &TestOutcome> =
                tests.iter().map(|o| (&*o.name, o)).collect();
            for (name, o) in sorted {
                map.serialize_entry(name, &result(o))?;
            }
        }
        map.end()
    }
}

/// Builds the wire form of one monitor's report.
pub fn monitor_result(report: &MonitorReport) -> MonitorResultWire<'_> {
    MonitorResultWire {
        tests: TestsWire(&report.tests),
        integrity: report.integrity.as_ref().map(IntegrityWire::from),
        outputs: &report.outputs,
    }
}

/// Room for one `result` frame: a federated monitor's is about 800 bytes.
pub const RESULT_FRAME_BYTES: usize = 1024;

/// The `result` frame of one epoch.
#[derive(Serialize)]
struct ResultFrame<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    t: f64,
    monitors: BTreeMap<&'a str, MonitorResultWire<'a>>,
}

/// Appends one epoch's `result` frame to `out`: its time and each reporting monitor's
/// result by name (a monitor that failed on the epoch is left out by the caller). The
/// session actor writes a frame's results into one buffer and sends each as a slice of it.
pub fn write_result_frame<'a>(
    out: impl std::io::Write,
    t: f64,
    monitors: impl IntoIterator<Item = (&'a str, &'a MonitorReport)>,
) {
    let monitors = monitors
        .into_iter()
        .map(|(name, report)| (name, monitor_result(report)))
        .collect();
    let frame = ResultFrame {
        kind: "result",
        t,
        monitors,
    };
    // Numbers, strings and maps with string keys serialise into a Vec without error.
    let _ = serde_json::to_writer(out, &frame);
}

/// The text of one epoch's `result` frame (see [`write_result_frame`]).
pub fn result_frame<'a>(
    t: f64,
    monitors: impl IntoIterator<Item = (&'a str, &'a MonitorReport)>,
) -> String {
    let mut out = Vec::with_capacity(RESULT_FRAME_BYTES);
    write_result_frame(&mut out, t, monitors);
    String::from_utf8(out).unwrap_or_default()
}

/// An entry of the alarm log: a test's transition into suspect or isolated, as stored
/// (alarms and warnings) and sent (alarms, as the `alarm` event).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct AlarmRecord {
    /// Store id (increasing).
    pub id: i64,
    /// `alarm` or `warning` (docs/architecture.md §A2); entries stored before severities
    /// existed read as `alarm`.
    #[serde(default)]
    pub severity: Severity,
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
    /// Entering suspect or isolated: `alarm` or `warning`; absent on the return to
    /// healthy.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub severity: Option<Severity>,
    /// The alarm-log entry of this change (absent on the return to healthy, and `-1`
    /// when the store failed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub log_id: Option<i64>,
}

/// A change of a monitor's integrity availability (docs/methods.md §M24): not a fault,
/// so neither stored as an alarm nor counted as one.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct AvailabilityChange {
    /// Session id.
    pub session: String,
    /// Monitor name.
    pub monitor: String,
    /// Epoch time, s.
    pub t: f64,
    /// Previous availability (a stream starts `converging`).
    pub from: Availability,
    /// New availability.
    pub to: Availability,
    /// Protection level, m.
    pub protection_level: f64,
    /// Alert limit, m.
    pub alert_limit: f64,
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
