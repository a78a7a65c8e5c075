//! The alarm rule (docs/architecture.md §A2 step 5): which state change of a test is an
//! *alarm*, which a *warning*, and when a monitor with a protection level raises the
//! alarms it held back while converging (docs/methods.md §M24). The server's sessions
//! and the experiments' scorecards both decide through this file.

use serde::{Deserialize, Serialize};

use crate::detect::Health;
use crate::monitor::Availability;

/// How loud a state change is: an `alarm` is stored, announced as an `alarm` event and
/// counted; a `warning` is stored and announced only as a `state` event.
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

/// Which state change is an *alarm*: entering `isolated` only (the default: entering
/// `suspect` is then a *warning*, stored and announced as a `state` event but not as an
/// `alarm`), or entering `suspect` already. Under the `classic` and `traditional`
/// policies a test never is suspect, so both read the same.
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

/// The rule of one monitor: its alarm level and the availability it last reported.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct AlarmRule {
    /// Which state change of its tests is an alarm.
    pub level: AlarmLevel,
    /// Availability at the last epoch that reported one; `None` for a monitor without a
    /// protection level and before its first such epoch (a stream starts converging).
    pub availability: Option<Availability>,
}

impl AlarmRule {
    /// The rule of a monitor at the start of a stream.
    pub fn new(level: AlarmLevel) -> Self {
        AlarmRule {
            level,
            availability: None,
        }
    }

    /// The severity of a test entering `to`: a warning while the monitor is still
    /// converging (docs/methods.md §M24), else what the alarm level says; `None` for the
    /// return to healthy.
    pub fn severity(&self, to: Health) -> Option<Severity> {
        let severity = self.level.severity(to)?;
        Some(if self.availability == Some(Availability::Converging) {
            Severity::Warning
        } else {
            severity
        })
    }

    /// Whether a test standing in `state` when the monitor converges is raised then as an
    /// alarm: a fault present from the start is not lost in the warnings of convergence.
    pub fn stands_in_alarm(&self, state: Health) -> bool {
        self.level.severity(state) == Some(Severity::Alarm)
    }
}

/// The log entries `(t, state, severity)` a monitor without a protection level writes for
/// one test's health trace `(t, health)` under `level`: one per change into suspect or
/// isolated (the trace starts healthy, as a stream does).
pub fn trace_entries(trace: &[(f64, Health)], level: AlarmLevel) -> Vec<(f64, Health, Severity)> {
    let rule = AlarmRule::new(level);
    let mut previous = Health::Healthy;
    let mut entries = Vec::new();
    for &(t, health) in trace {
        if health != previous
            && let Some(severity) = rule.severity(health)
        {
            entries.push((t, health, severity));
        }
        previous = health;
    }
    entries
}
