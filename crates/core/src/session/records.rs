//! What a session's decisions produce: the alarm-log entry, a test's state change and a
//! monitor's availability change. They are sent as the `alarm`, `state` and
//! `availability` messages and stored in the alarm log, so their serde form is the wire
//! contract (openapi/openapi.yaml).

use serde::{Deserialize, Serialize};

use super::rule::Severity;
use crate::detect::{Health, Statistic};
use crate::monitor::Availability;

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

/// What names a log entry before it is stored: where, what and how loud.
#[derive(Debug, Clone, PartialEq)]
pub struct Raised<'a> {
    /// Session id.
    pub session: &'a str,
    /// Monitor name.
    pub monitor: &'a str,
    /// Test name.
    pub test: &'a str,
    /// The state entered.
    pub state: Health,
    /// Alarm or warning.
    pub severity: Severity,
    /// Epoch time, s.
    pub t: f64,
    /// The test's statistic, threshold and dof at `t`.
    pub statistic: Statistic,
    /// Seconds from the episode's first exceedance to `t`.
    pub delay_s: f64,
}

impl AlarmRecord {
    /// The one way a log entry is made: id 0 and `raised_at_ms` 0 until whoever stores it
    /// stamps the wall-clock time and the store gives the id.
    pub fn raised(r: Raised<'_>) -> Self {
        AlarmRecord {
            id: 0,
            severity: r.severity,
            session: r.session.to_owned(),
            monitor: r.monitor.to_owned(),
            test: r.test.to_owned(),
            state: r.state,
            t: r.t,
            statistic: r.statistic.value,
            threshold: r.statistic.threshold,
            dof: r.statistic.dof,
            test_ratio: r.statistic.test_ratio(),
            delay_s: r.delay_s,
            raised_at_ms: 0,
            cleared_t: None,
        }
    }
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
