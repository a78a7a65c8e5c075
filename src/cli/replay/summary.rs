//! What the replay saw and says at the end: the socket reader's tally of the
//! server's messages (errors, alarms, state changes, results; `--messages` copies
//! them as received, to compare a replayed recording with the original), the
//! summary built from it and the session's final `/stats`, and its text form.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use anyhow::Context;
use navguard_core::session::SessionStats;
use serde::Serialize;

use super::stream::Sent;
use crate::cli::http::ServerEvent;
use crate::cli::thousands;

/// Alarm events kept individually for `--summary-json` (the rest are counted).
const MAX_ALARM_EVENTS: usize = 100_000;
/// Error messages kept as examples.
const MAX_ERROR_SAMPLES: usize = 5;

/// Alarms of one monitor, test and state.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub(super) struct AlarmGroup {
    /// Monitor name.
    pub monitor: String,
    /// Test name.
    pub test: String,
    /// State entered.
    pub state: String,
    /// Alarms.
    pub count: u64,
    /// Epoch time of the first, s.
    pub first_t: f64,
    /// Epoch time of the last, s.
    pub last_t: f64,
}

/// One alarm as received.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub(super) struct AlarmEvent {
    /// Monitor name.
    pub monitor: String,
    /// Test name.
    pub test: String,
    /// State entered.
    pub state: String,
    /// Epoch time, s.
    pub t: f64,
}

/// What the socket reader saw.
#[derive(Debug, Default)]
pub(super) struct Tally {
    errors: BTreeMap<String, u64>,
    error_samples: Vec<String>,
    /// Error events received.
    pub(super) error_total: u64,
    /// Of those, `numerical` ones (their frames were counted as accepted too).
    pub(super) numerical: u64,
    alarms: BTreeMap<(String, String, String), AlarmGroup>,
    alarm_events: Vec<AlarmEvent>,
    /// Alarm events received.
    pub(super) alarm_total: u64,
    states: u64,
    results: u64,
    /// Why the current socket ended, once it has.
    pub(super) closed: Option<String>,
    /// `--messages`: where every result, state and alarm message goes.
    messages: Option<std::io::BufWriter<std::fs::File>>,
}

impl Tally {
    /// `result` messages received.
    pub(super) fn results(&self) -> u64 {
        self.results
    }

    /// A tally that copies messages to `messages` (`--messages`) when given.
    pub(super) fn new(messages: Option<std::io::BufWriter<std::fs::File>>) -> Self {
        Self {
            messages,
            ..Self::default()
        }
    }

    /// Counts one text message from the server.
    pub(super) fn take(&mut self, text: &str) {
        let Ok(event) = serde_json::from_str::<ServerEvent>(text) else {
            return;
        };
        if let (Some(out), ServerEvent::Result | ServerEvent::State(_) | ServerEvent::Alarm(_)) =
            (&mut self.messages, &event)
        {
            use std::io::Write as _;
            let _ = writeln!(out, "{text}");
        }
        match event {
            ServerEvent::Error(e) => {
                self.error_total += 1;
                if e.code == "numerical" {
                    self.numerical += 1;
                }
                if self.error_samples.len() < MAX_ERROR_SAMPLES {
                    self.error_samples
                        .push(format!("{}: {}", e.code, e.message));
                }
                *self.errors.entry(e.code).or_default() += 1;
            }
            ServerEvent::Alarm(alarm) => {
                let t = alarm.t;
                let key = (alarm.monitor, alarm.test, alarm.state.as_str().to_owned());
                self.alarm_total += 1;
                if self.alarm_events.len() < MAX_ALARM_EVENTS {
                    self.alarm_events.push(AlarmEvent {
                        monitor: key.0.clone(),
                        test: key.1.clone(),
                        state: key.2.clone(),
                        t,
                    });
                }
                let group = self.alarms.entry(key.clone()).or_insert(AlarmGroup {
                    monitor: key.0,
                    test: key.1,
                    state: key.2,
                    count: 0,
                    first_t: t,
                    last_t: t,
                });
                group.count += 1;
                group.last_t = t;
            }
            ServerEvent::State(_) => self.states += 1,
            ServerEvent::Result => self.results += 1,
            ServerEvent::Other => {}
        }
    }

    /// Writes out what `--messages` still buffers.
    pub(super) fn flush_messages(&mut self) -> anyhow::Result<()> {
        if let Some(mut out) = self.messages.take() {
            use std::io::Write as _;
            out.flush().context("writing --messages")?;
        }
        Ok(())
    }
}

/// The end-of-run summary (`--summary-json` writes it).
#[derive(Debug, Clone, Serialize)]
pub(super) struct ReplaySummary {
    /// Session id.
    pub session: String,
    /// The session was created by this run.
    pub created: bool,
    /// Epochs sent.
    pub epochs_sent: u64,
    /// Frames sent.
    pub frames_sent: u64,
    /// Wall-clock seconds from the first frame to the end of the drain.
    pub wall_s: f64,
    /// Error events by code.
    pub errors: BTreeMap<String, u64>,
    /// Up to five error messages.
    pub error_samples: Vec<String>,
    /// Alarms by monitor, test and state.
    pub alarm_groups: Vec<AlarmGroup>,
    /// Every alarm received (up to 100,000), in order.
    pub alarms: Vec<AlarmEvent>,
    /// State-change events received.
    pub state_changes: u64,
    /// The session's `/stats` at the end, read through the service's own type.
    pub stats: SessionStats,
}

impl ReplaySummary {
    /// The summary of a run: what was sent, what the socket reader saw (alarm
    /// groups in the order of their first alarm) and the session's final stats.
    pub(super) fn new(
        session: String,
        created: bool,
        sent: Sent,
        wall_s: f64,
        tally: Tally,
        stats: SessionStats,
    ) -> Self {
        let mut alarm_groups: Vec<AlarmGroup> = tally.alarms.into_values().collect();
        alarm_groups.sort_by(|a, b| a.first_t.total_cmp(&b.first_t));
        Self {
            session,
            created,
            epochs_sent: sent.epochs,
            frames_sent: sent.frames,
            wall_s,
            errors: tally.errors,
            error_samples: tally.error_samples,
            alarm_groups,
            alarms: tally.alarm_events,
            state_changes: tally.states,
            stats,
        }
    }
}

fn num(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "—".to_owned(), |x| format!("{x:.digits$}"))
}

/// Renders the summary as text.
pub(super) fn render(s: &ReplaySummary) -> String {
    let mut out = String::new();
    let rate = if s.wall_s > 0.0 {
        s.epochs_sent as f64 / s.wall_s
    } else {
        0.0
    };
    let _ = writeln!(
        out,
        "session {}{}: sent {} epochs in {} frames, {:.1} s ({} epochs/s)",
        s.session,
        if s.created { " (created)" } else { "" },
        thousands(s.epochs_sent),
        thousands(s.frames_sent),
        s.wall_s,
        thousands(rate.round() as u64)
    );
    if s.errors.is_empty() {
        let _ = writeln!(out, "errors: none");
    } else {
        let list: Vec<String> = s.errors.iter().map(|(c, n)| format!("{c} {n}")).collect();
        let _ = writeln!(out, "errors: {}", list.join(", "));
        for sample in &s.error_samples {
            let _ = writeln!(out, "  e.g. {sample}");
        }
    }
    let total: u64 = s.alarm_groups.iter().map(|g| g.count).sum();
    let _ = writeln!(out, "alarms: {total} ({} state changes)", s.state_changes);
    if !s.alarm_groups.is_empty() {
        let _ = writeln!(
            out,
            "  {:<12} {:<8} {:<9} {:>6} {:>10} {:>10}",
            "monitor", "test", "state", "count", "first t", "last t"
        );
        for g in &s.alarm_groups {
            let _ = writeln!(
                out,
                "  {:<12} {:<8} {:<9} {:>6} {:>10.2} {:>10.2}",
                g.monitor, g.test, g.state, g.count, g.first_t, g.last_t
            );
        }
    }
    render_stats(&mut out, &s.stats);
    out
}

/// The stats part of the summary: session counts, then one row per test.
fn render_stats(out: &mut String, view: &SessionStats) {
    let _ = writeln!(
        out,
        "stats: {} epochs processed, {} frames, {} refused, last t {}",
        thousands(view.epochs),
        thousands(view.frames),
        view.frame_errors,
        num(view.last_t, 2)
    );
    let _ = writeln!(
        out,
        "  {:<12} {:<8} {:<9} {:>8} {:>7} {:>6} {:>9} {:>10} {:>9} {:>27} {:>7}",
        "monitor",
        "test",
        "state",
        "epochs",
        "exceed",
        "alarms",
        "threshold",
        "mean λ",
        "max λ",
        "healthy/suspect/isolated s",
        "delay"
    );
    for (name, m) in &view.monitors {
        for (test, t) in &m.tests {
            let time = &t.time_in_state_s;
            let _ = writeln!(
                out,
                "  {:<12} {:<8} {:<9} {:>8} {:>7} {:>6} {:>9} {:>10} {:>9} {:>27} {:>7}",
                name,
                test,
                t.state.as_str(),
                t.epochs,
                t.exceedances,
                t.alarms,
                num(Some(t.threshold), 2),
                num(t.mean, 3),
                num(t.max, 1),
                format!(
                    "{}/{}/{}",
                    num(Some(time.healthy), 0),
                    num(Some(time.suspect), 0),
                    num(Some(time.isolated), 0)
                ),
                num(t.last_alarm_delay_s, 1)
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use navguard::service::wire::{AlarmRecord, StateChange, tagged};
    use navguard_core::detect::Health;

    fn alarm(test: &str, t: f64) -> String {
        let record = AlarmRecord {
            id: 1,
            session: "s1".into(),
            monitor: "nav".into(),
            test: test.into(),
            state: Health::Suspect,
            t,
            statistic: 30.0,
            threshold: 20.0,
            dof: 3,
            test_ratio: 1.5,
            delay_s: 0.0,
            raised_at_ms: 0,
            cleared_t: None,
            severity: Default::default(),
        };
        tagged("alarm", &record)
    }

    #[test]
    fn tally_groups_alarms_and_counts_errors() {
        let mut t = Tally::default();
        for (i, test) in ["gnss", "gnss", "dvl"].iter().enumerate() {
            t.take(&alarm(test, i as f64 + 1.5));
        }
        t.take(r#"{"type":"error","code":"time_backwards","message":"m"}"#);
        t.take(r#"{"type":"error","code":"numerical","message":"n \"quoted\""}"#);
        let change = StateChange {
            session: "s1".into(),
            monitor: "nav".into(),
            test: "gnss".into(),
            t: 1.5,
            from: Health::Healthy,
            to: Health::Suspect,
            severity: None,
            log_id: None,
        };
        t.take(&tagged("state", &change));
        t.take(r#"{"type":"result","t":1.0,"monitors":{}}"#);
        t.take(r#"{"type":"ready","session":"s1"}"#);
        assert_eq!(t.alarm_total, 3);
        let g = &t.alarms[&("nav".into(), "gnss".into(), "suspect".into())];
        assert_eq!((g.count, g.first_t, g.last_t), (2, 1.5, 2.5));
        assert_eq!(
            (t.error_total, t.numerical, t.states, t.results),
            (2, 1, 1, 1)
        );
        assert_eq!(t.errors["time_backwards"], 1);
        assert_eq!(t.error_samples[1], r#"numerical: n "quoted""#);
    }
}
