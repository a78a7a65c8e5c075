//! Committing one stepped epoch (docs/architecture.md §A2 steps 5–6): the statistics and
//! history are updated and the epoch's decisions come out as [`Effect`]s, in the order
//! they must be carried out: every test's state change (monitors in session order, tests
//! in report order), then every availability change, each followed by the alarms its
//! convergence raises.

use super::SessionCore;
use super::records::{AlarmRecord, AvailabilityChange, Raised, StateChange};
use super::rule::Severity;
use super::stats::{GnssSnapshot, IntegrityStats, MonitorStats, Position, Track};
use crate::detect::Statistic;
use crate::epoch::Epoch;
use crate::monitor::{Availability, Integrity, MonitorReport, Outputs, TestOutcome};

/// One decision of a committed epoch, to carry out in order.
#[derive(Debug, Clone, PartialEq)]
pub enum Effect {
    /// A test's health changed. Entering suspect or isolated, `entry` is its log entry
    /// (committed before the change is announced; `change.log_id` is its id then);
    /// returning to healthy, `entry` is `None` and the test's open entries are cleared at
    /// `change.t`.
    State {
        /// The change, its severity set.
        change: StateChange,
        /// The log entry to store, entering suspect or isolated.
        entry: Option<AlarmRecord>,
    },
    /// A monitor's integrity availability changed: never an alarm.
    Availability(AvailabilityChange),
    /// A test that stood in an alarm state while its monitor converged, raised as an
    /// alarm now that it has (docs/methods.md §M24).
    Standing(AlarmRecord),
}

impl Effect {
    /// The log entry this effect stores, if any.
    pub fn entry(&self) -> Option<&AlarmRecord> {
        match self {
            Effect::State { entry, .. } => entry.as_ref(),
            Effect::Standing(entry) => Some(entry),
            Effect::Availability(_) => None,
        }
    }
}

/// A test's change found while committing, before its severity is decided.
struct Transition {
    monitor: usize,
    outcome: TestOutcome,
    delay_s: f64,
}

impl SessionCore {
    /// Makes one stepped epoch current (`reports` per monitor, `None` for one that failed
    /// on it: its state is unchanged) and appends its effects to `effects`. An epoch that
    /// no monitor took must not be committed.
    pub fn commit(
        &mut self,
        epoch: &Epoch,
        reports: &[Option<MonitorReport>],
        effects: &mut Vec<Effect>,
    ) {
        let t = epoch.t;
        self.stream_epochs += 1;
        self.last_t = Some(t);
        self.stats.epochs += 1;
        self.stats.last_t = Some(t);
        let mut transitions = Vec::new();
        let mut availability = Vec::new();
        for (index, report) in reports.iter().enumerate() {
            let (Some(report), Some(member)) = (report, self.roster.get_mut(index)) else {
                continue;
            };
            let Some(stats) = self.stats.monitors.get_mut(&member.name) else {
                continue;
            };
            record_tests(stats, t, report, index, &mut transitions);
            if let Some(integrity) = &report.integrity {
                match record_integrity(stats, t, integrity) {
                    Some(from) => availability.push((index, from, *integrity)),
                    None => {
                        member.rule.availability.get_or_insert(integrity.state);
                    }
                }
            }
            record_track(stats, t, report, epoch);
        }
        for transition in transitions {
            effects.push(self.state_effect(t, transition));
        }
        for (index, from, integrity) in availability {
            self.availability_effects(index, t, from, &integrity, effects);
        }
        self.history.offer(t, &self.stats);
    }

    /// The effect of one test's change, counted in its statistics.
    fn state_effect(&mut self, t: f64, transition: Transition) -> Effect {
        let Transition {
            monitor: index,
            outcome,
            delay_s,
        } = transition;
        let member = &self.roster[index];
        let to = outcome.decision.health;
        let severity = member.rule.severity(to);
        let entry = severity.map(|severity| {
            AlarmRecord::raised(Raised {
                session: &self.id,
                monitor: &member.name,
                test: &outcome.name,
                state: to,
                severity,
                t,
                statistic: outcome.statistic,
                delay_s,
            })
        });
        let change = StateChange {
            session: self.id.to_string(),
            monitor: member.name.clone(),
            test: outcome.name.to_string(),
            t,
            from: outcome.previous,
            to,
            severity,
            log_id: None,
        };
        if let Some(severity) = severity {
            self.count(index, &outcome.name, severity, delay_s);
        }
        Effect::State { change, entry }
    }

    /// The availability change of monitor `index`, then, when it has just converged, an
    /// alarm for every test standing in a state its alarm level counts as an alarm (a
    /// warning while converging): a fault present from the start is not lost. The tests'
    /// states are read from the statistics, as committed up to this epoch. A monitor whose
    /// first report is already past convergence held nothing back, so raises nothing.
    fn availability_effects(
        &mut self,
        index: usize,
        t: f64,
        from: Availability,
        integrity: &Integrity,
        effects: &mut Vec<Effect>,
    ) {
        let member = &mut self.roster[index];
        // Alarms were held back only while the monitor was seen converging: a first report
        // already past convergence announced its tests' changes at their own level.
        let held_back = member.rule.availability == Some(Availability::Converging);
        member.rule.availability = Some(integrity.state);
        effects.push(Effect::Availability(AvailabilityChange {
            session: self.id.to_string(),
            monitor: member.name.clone(),
            t,
            from,
            to: integrity.state,
            protection_level: integrity.protection_level,
            alert_limit: integrity.alert_limit,
        }));
        if from != Availability::Converging || !held_back {
            return;
        }
        let member = &self.roster[index];
        let Some(stats) = self.stats.monitors.get(&member.name) else {
            return;
        };
        let mut standing = Vec::new();
        for test in &member.tests {
            let Some(s) = stats.tests.get(test) else {
                continue;
            };
            if member.rule.stands_in_alarm(s.state) {
                let statistic = Statistic {
                    value: s.last.unwrap_or(0.0),
                    threshold: s.threshold,
                    dof: s.dof,
                };
                let delay_s = s.episode_delay(t);
                standing.push(AlarmRecord::raised(Raised {
                    session: &self.id,
                    monitor: &member.name,
                    test,
                    state: s.state,
                    severity: Severity::Alarm,
                    t,
                    statistic,
                    delay_s,
                }));
            }
        }
        for entry in standing {
            self.count(index, &entry.test, Severity::Alarm, entry.delay_s);
            effects.push(Effect::Standing(entry));
        }
    }

    /// Counts one log entry in its test's statistics.
    fn count(&mut self, index: usize, test: &str, severity: Severity, delay_s: f64) {
        let name = &self.roster[index].name;
        if let Some(stats) = self
            .stats
            .monitors
            .get_mut(name)
            .and_then(|m| m.tests.get_mut(test))
        {
            stats.count(severity, delay_s);
        }
    }
}

/// Records a monitor's test outcomes in its statistics, noting each change of health.
fn record_tests(
    stats: &mut MonitorStats,
    t: f64,
    report: &MonitorReport,
    monitor: usize,
    transitions: &mut Vec<Transition>,
) {
    stats.epochs += 1;
    let mut worst: Option<f64> = None;
    for outcome in &report.tests {
        let Some(test) = stats.tests.get_mut(&outcome.name) else {
            continue;
        };
        let delay_s = test.record(t, outcome);
        let ratio = outcome.statistic.test_ratio();
        worst = Some(worst.map_or(ratio, |w| w.max(ratio)));
        if outcome.previous != outcome.decision.health {
            transitions.push(Transition {
                monitor,
                outcome: outcome.clone(),
                delay_s,
            });
        }
    }
    if worst.is_some() {
        stats.worst_test_ratio = worst;
    }
}

/// Records a monitor's integrity; returns the previous availability when it changed (a
/// stream starts converging: a first epoch in another state is a change).
fn record_integrity(
    stats: &mut MonitorStats,
    t: f64,
    integrity: &Integrity,
) -> Option<Availability> {
    match &mut stats.integrity {
        Some(s) => s.record(t, integrity),
        None => {
            stats.integrity = Some(IntegrityStats::new(t, integrity));
            (integrity.state != Availability::Converging).then_some(Availability::Converging)
        }
    }
}

/// Moves a federated monitor's track, or a gnss monitor's snapshot. The track moves only
/// on INS epochs (the snapshot on epochs with pseudoranges): on the others the monitor
/// repeats its last solution, which is already recorded with its own time.
fn record_track(stats: &mut MonitorStats, t: f64, report: &MonitorReport, epoch: &Epoch) {
    if let (Outputs::Gnss(outputs), Some(_)) = (&report.outputs, &epoch.gnss_raw) {
        stats.gnss = Some(GnssSnapshot {
            t,
            outputs: outputs.clone(),
        });
        return;
    }
    let Outputs::Federated {
        solution,
        alignment,
        ..
    } = &report.outputs
    else {
        return;
    };
    if epoch.imu.is_some() && alignment.is_some() {
        stats.alignment = *alignment;
    }
    let ins = match (&epoch.ins, &epoch.imu, solution) {
        (Some(ins), _, Some(_)) => Position {
            lat: ins.lat.to_degrees(),
            lon: ins.lon.to_degrees(),
            h: ins.h,
        },
        (None, Some(_), Some(s)) => Position {
            lat: s.lat,
            lon: s.lon,
            h: s.h,
        },
        // Aligning: the alignment state moves, the position stays the last one.
        (None, Some(_), None) => {
            if let Some(track) = &mut stats.track {
                track.alignment = *alignment;
            }
            return;
        }
        _ => return,
    };
    if let Some(s) = solution {
        stats.track = Some(Track {
            t,
            solution: Position {
                lat: s.lat,
                lon: s.lon,
                h: s.h,
            },
            ins,
            alignment: *alignment,
        });
    }
}
