//! The session core (docs/architecture.md §A3): everything a session decides, with no
//! async and no I/O. It holds the roster (each monitor's name, kind, alarm rule and test
//! names), the monitors themselves, the statistics and their 1 Hz history, and the
//! stream's position. It steps epochs through the monitors and commits each stepped
//! epoch into an ordered list of [`Effect`]s (state changes with their log entries,
//! availability changes, standing alarms raised at convergence), which whoever runs the
//! session carries out: the server's actor stores and announces them, the experiments
//! count them. Both therefore apply one alarm rule ([`rule`]).
//!
//! - [`rule`]: severities, alarm levels, warnings while converging.
//! - [`records`]: the alarm-log entry, state and availability changes.
//! - [`thresholds`]: threshold views, `PUT`s applied all or nothing, undo.
//! - [`checkpoint`]: the core's state as checkpoint bytes and back.
//! - [`stats`], [`history`]: per-test statistics and their 1 Hz history.

mod commit;

pub mod checkpoint;
pub mod history;
pub mod records;
pub mod rule;
pub mod stats;
pub mod thresholds;

#[cfg(test)]
mod tests;

use std::sync::Arc;
use std::time::{Duration, Instant};

pub use commit::Effect;
pub use records::{AlarmRecord, AvailabilityChange, Raised, StateChange};
pub use rule::{AlarmLevel, AlarmRule, Severity};
pub use stats::SessionStats;
pub use thresholds::{
    TestThreshold, TestThresholdSpec, ThresholdRefusal, ThresholdUpdate, ThresholdView, Undo,
};

use crate::detect::Health;
use crate::epoch::Epoch;
use crate::monitor::tests_bank::TestSlot;
use crate::monitor::{EpochError, Monitor, MonitorKind, MonitorReport, StepError, TestName};
use history::History;
use stats::{MonitorStats, TestStats};

/// One monitor of a session as the core keeps it beside the monitor itself: committing
/// an epoch needs only this, so the monitors can step the next epochs meanwhile.
#[derive(Debug, Clone)]
pub struct Member {
    /// Name, unique in the session.
    pub name: String,
    /// Monitor kind.
    pub kind: MonitorKind,
    /// Its alarm level and last availability.
    pub rule: AlarmRule,
    /// Its tests' names, in the order of its test bank.
    pub tests: Vec<TestName>,
}

/// A monitor to run in a session: its name, the monitor, its alarm level.
pub struct Seat {
    /// Name, unique in the session.
    pub name: String,
    /// The monitor, built.
    pub monitor: Box<dyn Monitor>,
    /// Which state change of its tests is an alarm.
    pub alarm_level: AlarmLevel,
}

/// Why a frame is refused before anything changes.
#[derive(Debug, thiserror::Error)]
pub enum FrameRefusal {
    /// The frame's first epoch is earlier than the stream's last one.
    #[error("t = {t} goes back from {last}")]
    TimeBackwards {
        /// The frame's first epoch time.
        t: f64,
        /// The stream's last epoch time.
        last: f64,
    },
    /// A monitor cannot take epoch `index` of the frame.
    #[error("{error}")]
    Epoch {
        /// The epoch's index in the frame.
        index: usize,
        /// What the monitor said.
        error: EpochError,
    },
}

/// A test the previous stream left suspect or isolated, back to healthy as a new stream
/// starts: announced, and its open log entries cleared at `t` (the last epoch time).
#[derive(Debug, Clone, PartialEq)]
pub struct Returned {
    /// Monitor name.
    pub monitor: String,
    /// Test name.
    pub test: TestName,
    /// The state it left.
    pub from: Health,
    /// The previous stream's last epoch time.
    pub t: Option<f64>,
}

/// Some epochs stepped through every monitor (see [`step_slice`]): the monitors and
/// epochs (moved in and handed back), each stepped epoch's reports (`None` for a monitor
/// that failed on it) and the first failure (epoch index, monitor index, error).
pub struct Slice {
    /// The monitors, handed back.
    pub engines: Vec<Box<dyn Monitor>>,
    /// The epochs, handed back.
    pub epochs: Vec<Epoch>,
    /// Per stepped epoch, per monitor, its report.
    pub stepped: Vec<Vec<Option<MonitorReport>>>,
    /// The first numerical failure: epoch index, monitor index, error.
    pub failure: Option<(usize, usize, StepError)>,
    /// Compute time the slice took.
    pub elapsed: Duration,
}

/// Steps every monitor through the epochs from `from`, until the frame ends, a monitor
/// fails (that epoch is the last, stepped by the others) or the slice has used `budget`
/// of compute. Takes and hands back its inputs, so it can run on another thread.
pub fn step_slice(
    mut engines: Vec<Box<dyn Monitor>>,
    epochs: Vec<Epoch>,
    from: usize,
    budget: Duration,
) -> Slice {
    let start = Instant::now();
    let mut stepped = Vec::new();
    let mut failure = None;
    for (i, epoch) in epochs.iter().enumerate().skip(from) {
        let (reports, failed) = step_epoch(&mut engines, epoch);
        stepped.push(reports);
        if let Some((k, e)) = failed {
            failure.get_or_insert((i, k, e));
            break;
        }
        if start.elapsed() >= budget {
            break;
        }
    }
    Slice {
        engines,
        epochs,
        stepped,
        failure,
        elapsed: start.elapsed(),
    }
}

/// Steps every monitor once; a monitor that fails leaves its state unchanged and reports
/// `None`, and the first failure is returned beside.
fn step_epoch(
    engines: &mut [Box<dyn Monitor>],
    epoch: &Epoch,
) -> (Vec<Option<MonitorReport>>, Option<(usize, StepError)>) {
    let mut reports = Vec::with_capacity(engines.len());
    let mut failure = None;
    for (k, engine) in engines.iter_mut().enumerate() {
        match engine.step(epoch) {
            Ok(report) => reports.push(Some(report)),
            Err(e) => {
                reports.push(None);
                failure.get_or_insert((k, e));
            }
        }
    }
    (reports, failure)
}

/// A session's decisions, statistics and monitors (see the module's documentation).
pub struct SessionCore {
    id: Arc<str>,
    roster: Vec<Member>,
    /// The monitors, in roster order; empty while they step on another thread.
    engines: Vec<Box<dyn Monitor>>,
    stats: SessionStats,
    history: History,
    /// The stream's last committed epoch time.
    last_t: Option<f64>,
    /// Epochs committed on the stream.
    stream_epochs: u64,
}

impl SessionCore {
    /// A session of `seats` keeping `history_samples` seconds of history.
    pub fn new(id: &str, seats: Vec<Seat>, history_samples: usize) -> Self {
        let (roster, engines): (Vec<Member>, Vec<Box<dyn Monitor>>) = seats
            .into_iter()
            .map(|seat| {
                let member = Member {
                    name: seat.name,
                    kind: seat.monitor.kind(),
                    rule: AlarmRule::new(seat.alarm_level),
                    tests: seat
                        .monitor
                        .tests()
                        .slots()
                        .iter()
                        .map(|s| s.name.clone())
                        .collect(),
                };
                (member, seat.monitor)
            })
            .unzip();
        let stats = initial_stats(id, &roster, &engines);
        let history = History::new(history_samples, &stats);
        SessionCore {
            id: Arc::from(id),
            roster,
            engines,
            stats,
            history,
            last_t: None,
            stream_epochs: 0,
        }
    }

    /// The session id.
    pub fn id(&self) -> &Arc<str> {
        &self.id
    }

    /// The monitors' names, kinds, rules and test names, in session order.
    pub fn roster(&self) -> &[Member] {
        &self.roster
    }

    /// The index of monitor `name`.
    pub fn find(&self, name: &str) -> Option<usize> {
        self.roster.iter().position(|m| m.name == name)
    }

    /// The statistics as committed.
    pub fn stats(&self) -> &SessionStats {
        &self.stats
    }

    /// The statistics, for the fields the runner keeps (frames, connection, rates).
    pub fn stats_mut(&mut self) -> &mut SessionStats {
        &mut self.stats
    }

    /// The 1 Hz history of the statistics.
    pub fn history(&self) -> &History {
        &self.history
    }

    /// The stream's last committed epoch time.
    pub fn last_t(&self) -> Option<f64> {
        self.last_t
    }

    /// Epochs committed on the stream (the recording's epoch index of the next one).
    pub fn stream_epochs(&self) -> u64 {
        self.stream_epochs
    }

    /// The monitors, in roster order (empty while they step elsewhere).
    pub fn engines(&self) -> &[Box<dyn Monitor>] {
        &self.engines
    }

    /// Takes the monitors out to step them on another thread ([`step_slice`]).
    pub fn take_engines(&mut self) -> Vec<Box<dyn Monitor>> {
        std::mem::take(&mut self.engines)
    }

    /// Gives the monitors back after a step.
    pub fn put_engines(&mut self, engines: Vec<Box<dyn Monitor>>) {
        self.engines = engines;
    }

    /// Replaces the monitors with freshly built ones of the same names (a step job that
    /// lost them): alarm levels as given, availabilities forgotten.
    pub fn rebuild(&mut self, seats: Vec<Seat>) {
        for (member, seat) in self.roster.iter_mut().zip(&seats) {
            member.rule = AlarmRule::new(seat.alarm_level);
        }
        self.engines = seats.into_iter().map(|s| s.monitor).collect();
    }

    /// Steps every monitor through one epoch in place (the experiments' loop; the server
    /// steps slices, [`step_slice`]). Commit the reports with [`SessionCore::commit`].
    pub fn step(
        &mut self,
        epoch: &Epoch,
    ) -> (Vec<Option<MonitorReport>>, Option<(usize, StepError)>) {
        step_epoch(&mut self.engines, epoch)
    }

    /// Checks a whole frame against the session before anything changes, `last_t` being
    /// the time of the last epoch before it.
    pub fn check_frame(&self, epochs: &[Epoch], last_t: Option<f64>) -> Result<(), FrameRefusal> {
        if let (Some(last), Some(first)) = (last_t, epochs.first())
            && first.t < last
        {
            return Err(FrameRefusal::TimeBackwards { t: first.t, last });
        }
        for (index, epoch) in epochs.iter().enumerate() {
            for (m, engine) in self.roster.iter().zip(&self.engines) {
                engine
                    .check_epoch(&m.name, epoch)
                    .map_err(|error| FrameRefusal::Epoch { index, error })?;
            }
        }
        Ok(())
    }

    /// Starts a new stream: every monitor afresh (filters, counters, availability), the
    /// stream's position and history forgotten. Returns the tests the previous stream
    /// left suspect or isolated, now healthy.
    pub fn restart(&mut self) -> Vec<Returned> {
        let t = self.last_t;
        let mut returned = Vec::new();
        for (m, engine) in self.roster.iter_mut().zip(&mut self.engines) {
            for slot in engine.tests().slots() {
                let from = slot.policy.health();
                if from != Health::Healthy {
                    let (monitor, test) = (m.name.clone(), slot.name.clone());
                    returned.push(Returned {
                        monitor,
                        test,
                        from,
                        t,
                    });
                }
            }
            engine.reset();
            m.rule.availability = None;
        }
        self.last_t = None;
        self.stream_epochs = 0;
        self.history.clear();
        for index in 0..self.roster.len() {
            self.each_test_of(index, |slot, stats| {
                stats.state = slot.policy.health();
                stats.consistency = None;
            });
            if let Some(stats) = self.stats.monitors.get_mut(&self.roster[index].name) {
                stats.integrity = None;
            }
        }
        returned
    }

    /// Copies each test's consistency diagnostics into the statistics (when they are
    /// published, not per epoch).
    pub fn refresh_consistency(&mut self) {
        for index in 0..self.engines.len() {
            self.each_test_of(index, |slot, stats| {
                stats.consistency = slot.consistency.summary();
            });
        }
    }

    /// Runs `f` on every test slot of monitor `index` with its statistics: the one place
    /// where the statistics (by name) meet the test bank (by position).
    fn each_test_of(&mut self, index: usize, mut f: impl FnMut(&mut TestSlot, &mut TestStats)) {
        let (Some(member), Some(engine)) = (self.roster.get(index), self.engines.get_mut(index))
        else {
            return;
        };
        let Some(monitor_stats) = self.stats.monitors.get_mut(&member.name) else {
            return;
        };
        for slot in engine.tests_mut().slots_mut() {
            if let Some(stats) = monitor_stats.tests.get_mut(&slot.name) {
                f(slot, stats);
            }
        }
    }
}

/// Empty statistics for the roster's monitors and tests.
fn initial_stats(id: &str, roster: &[Member], engines: &[Box<dyn Monitor>]) -> SessionStats {
    SessionStats {
        session: id.to_owned(),
        connected: false,
        frames: 0,
        epochs: 0,
        frame_errors: 0,
        last_t: None,
        last_frame_at_ms: None,
        published_at_ms: 0,
        epochs_per_s: 0.0,
        monitors: roster
            .iter()
            .zip(engines)
            .map(|(member, m)| {
                let tests = m
                    .tests()
                    .slots()
                    .iter()
                    .map(|s| (s.name.clone(), TestStats::new(s.dof, s.threshold)))
                    .collect();
                let stats = MonitorStats {
                    kind: member.kind,
                    epochs: 0,
                    worst_test_ratio: None,
                    tests,
                    track: None,
                    alignment: None,
                    gnss: None,
                    integrity: None,
                };
                (member.name.clone(), stats)
            })
            .collect(),
    }
}
