//! Per-session statistics (`GET /api/v1/sessions/{id}/stats` and the `stats`
//! event): per monitor and test, counts, statistic summary, time in each state,
//! the detection delay of the last alarm and the consistency diagnostics; per
//! monitor with a protection level, its availability timeline. Updated by the
//! session core as it commits epochs.

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::rule::Severity;
use crate::detect::Health;
use crate::detect::consistency::ConsistencySummary;
use crate::monitor::gnss::GnssOutputs;
use crate::monitor::{Availability, Integrity, MonitorKind, TestName, TestOutcome};

/// Availability changes kept in a monitor's timeline.
pub const TIMELINE_SPANS: usize = 64;

/// Seconds spent in each state, by epoch time.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct TimeInState {
    /// Healthy, s.
    pub healthy: f64,
    /// Suspect, s.
    pub suspect: f64,
    /// Isolated, s.
    pub isolated: f64,
}

/// Statistics of one test.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct TestStats {
    /// Current state.
    pub state: Health,
    /// Epoch time the current state was entered.
    pub state_since_t: Option<f64>,
    /// Degrees of freedom.
    pub dof: u32,
    /// Threshold in force.
    pub threshold: f64,
    /// Epochs on which the test ran.
    pub epochs: u64,
    /// Epochs whose statistic exceeded the threshold.
    pub exceedances: u64,
    /// Alarms raised (transitions of severity `alarm`).
    pub alarms: u64,
    /// Warnings raised (transitions of severity `warning`: into suspect under the
    /// default alarm level, or any while the monitor converges).
    #[serde(default)]
    pub warnings: u64,
    /// Last statistic.
    pub last: Option<f64>,
    /// Last statistic / threshold.
    pub last_test_ratio: Option<f64>,
    /// Mean statistic.
    pub mean: Option<f64>,
    /// Largest statistic.
    pub max: Option<f64>,
    /// Time in each state.
    pub time_in_state_s: TimeInState,
    /// Seconds from the first exceedance of the episode to the last alarm.
    pub last_alarm_delay_s: Option<f64>,
    /// NIS mean, lag-1 autocorrelation and the `consistency` flag of the test's
    /// normalised innovation (docs/methods.md §M22); absent for tests fed none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub consistency: Option<ConsistencySummary>,
    #[serde(skip)]
    sum: f64,
    #[serde(skip)]
    last_t: Option<f64>,
    #[serde(skip)]
    episode_start_t: Option<f64>,
}

/// The running values a test's statistics keep off the wire (the sum behind `mean`, the
/// last epoch time behind `time_in_state_s`, the episode start behind the delays), for a
/// session checkpoint.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct TestRunning {
    sum: f64,
    last_t: Option<f64>,
    episode_start_t: Option<f64>,
}

impl TestStats {
    /// The running values behind the published ones (for a checkpoint).
    pub fn running(&self) -> TestRunning {
        TestRunning {
            sum: self.sum,
            last_t: self.last_t,
            episode_start_t: self.episode_start_t,
        }
    }

    /// Restores the running values of a checkpoint.
    pub fn set_running(&mut self, r: TestRunning) {
        self.sum = r.sum;
        self.last_t = r.last_t;
        self.episode_start_t = r.episode_start_t;
    }

    /// Empty statistics for a test.
    pub fn new(dof: u32, threshold: f64) -> Self {
        TestStats {
            state: Health::Healthy,
            state_since_t: None,
            dof,
            threshold,
            epochs: 0,
            exceedances: 0,
            alarms: 0,
            warnings: 0,
            last: None,
            last_test_ratio: None,
            mean: None,
            max: None,
            time_in_state_s: TimeInState::default(),
            last_alarm_delay_s: None,
            consistency: None,
            sum: 0.0,
            last_t: None,
            episode_start_t: None,
        }
    }

    /// Records one evaluation at epoch time `t`. Returns the detection delay to put on
    /// the log entry when this outcome enters suspect or isolated (the caller then
    /// [`TestStats::count`]s it with its severity).
    pub fn record(&mut self, t: f64, outcome: &TestOutcome) -> f64 {
        let s = outcome.statistic;
        if let Some(last_t) = self.last_t {
            let dt = (t - last_t).max(0.0);
            match self.state {
                Health::Healthy => self.time_in_state_s.healthy += dt,
                Health::Suspect => self.time_in_state_s.suspect += dt,
                Health::Isolated => self.time_in_state_s.isolated += dt,
            }
        }
        self.last_t = Some(t);
        self.epochs += 1;
        self.threshold = s.threshold;
        self.sum += s.value;
        self.last = Some(s.value);
        self.last_test_ratio = Some(s.test_ratio());
        self.mean = Some(self.sum / self.epochs as f64);
        self.max = Some(self.max.map_or(s.value, |m| m.max(s.value)));
        if s.exceeds() {
            self.exceedances += 1;
            // An episode starts at the first exceedance seen while healthy.
            if self.episode_start_t.is_none() {
                self.episode_start_t = Some(t);
            }
        }
        let health = outcome.decision.health;
        let mut delay = 0.0;
        if health != self.state {
            self.state = health;
            self.state_since_t = Some(t);
            if health == Health::Healthy {
                self.episode_start_t = None;
            } else {
                delay = self.episode_delay(t);
            }
        } else if health == Health::Healthy && !s.exceeds() {
            self.episode_start_t = None;
        }
        delay
    }

    /// Seconds from the first exceedance of the current episode to `t`.
    pub fn episode_delay(&self, t: f64) -> f64 {
        t - self.episode_start_t.unwrap_or(t)
    }

    /// Counts one log entry of `severity` raised after `delay_s`.
    pub fn count(&mut self, severity: Severity, delay_s: f64) {
        match severity {
            Severity::Alarm => {
                self.alarms += 1;
                self.last_alarm_delay_s = Some(delay_s);
            }
            Severity::Warning => self.warnings += 1,
        }
    }
}

/// Seconds spent in each availability, by epoch time.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct TimeInAvailability {
    /// Converging, s.
    pub converging: f64,
    /// Available, s.
    pub available: f64,
    /// Unavailable, s.
    pub unavailable: f64,
}

/// One stretch of the availability timeline.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct AvailabilitySpan {
    /// Availability over the stretch.
    pub state: Availability,
    /// Epoch time it began, s.
    pub from_t: f64,
    /// Epoch time it ended (`None`: still in force).
    pub to_t: Option<f64>,
}

/// A number that JSON wrote as `null` (serde_json writes a non-finite `f64` so) reads
/// back as NaN.
fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// Integrity availability of a monitor with a protection level (docs/methods.md §M24).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct IntegrityStats {
    /// Availability now.
    pub state: Availability,
    /// Epoch time it was entered.
    pub state_since_t: f64,
    /// Last protection level, m; none yet (a strapdown still aligning) is NaN, `null` on
    /// the wire.
    #[serde(deserialize_with = "nan_if_null")]
    pub protection_level: f64,
    /// Alert limit, m.
    pub alert_limit: f64,
    /// Largest protection level since the monitor converged, m.
    pub max_protection_level: Option<f64>,
    /// Time in each availability.
    pub time_s: TimeInAvailability,
    /// Changes of availability since the stream started.
    pub changes: u64,
    /// The last [`TIMELINE_SPANS`] stretches, oldest first.
    pub timeline: VecDeque<AvailabilitySpan>,
    #[serde(skip)]
    last_t: f64,
}

impl IntegrityStats {
    /// The last epoch time behind `time_s` (kept off the wire; for a checkpoint).
    pub fn running_t(&self) -> f64 {
        self.last_t
    }

    /// Restores [`IntegrityStats::running_t`] from a checkpoint.
    pub fn set_running_t(&mut self, t: f64) {
        self.last_t = t;
    }

    /// The statistics of a stream whose first integrity epoch is `integrity` at `t`.
    pub fn new(t: f64, integrity: &Integrity) -> Self {
        let mut stats = IntegrityStats {
            state: integrity.state,
            state_since_t: t,
            protection_level: integrity.protection_level,
            alert_limit: integrity.alert_limit,
            max_protection_level: None,
            time_s: TimeInAvailability::default(),
            changes: 0,
            timeline: VecDeque::from([AvailabilitySpan {
                state: integrity.state,
                from_t: t,
                to_t: None,
            }]),
            last_t: t,
        };
        stats.note_level(integrity);
        stats
    }

    fn note_level(&mut self, integrity: &Integrity) {
        self.protection_level = integrity.protection_level;
        self.alert_limit = integrity.alert_limit;
        if integrity.state != Availability::Converging {
            let pl = integrity.protection_level;
            self.max_protection_level = Some(self.max_protection_level.map_or(pl, |m| m.max(pl)));
        }
    }

    /// Records one epoch; returns the previous availability when it changed.
    pub fn record(&mut self, t: f64, integrity: &Integrity) -> Option<Availability> {
        let dt = (t - self.last_t).max(0.0);
        match self.state {
            Availability::Converging => self.time_s.converging += dt,
            Availability::Available => self.time_s.available += dt,
            Availability::Unavailable => self.time_s.unavailable += dt,
        }
        self.last_t = t;
        self.note_level(integrity);
        if integrity.state == self.state {
            return None;
        }
        let from = self.state;
        self.state = integrity.state;
        self.state_since_t = t;
        self.changes += 1;
        if let Some(last) = self.timeline.back_mut() {
            last.to_t = Some(t);
        }
        self.timeline.push_back(AvailabilitySpan {
            state: integrity.state,
            from_t: t,
            to_t: None,
        });
        if self.timeline.len() > TIMELINE_SPANS {
            self.timeline.pop_front();
        }
        Some(from)
    }
}

/// A geodetic position: latitude and longitude in degrees, height in m.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct Position {
    /// Latitude, degrees.
    pub lat: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Ellipsoidal height, m.
    pub h: f64,
}

/// The latest position of a `federated` monitor: its corrected solution and the
/// raw INS position it corrected, at the last INS epoch. Plain `Copy` data, so
/// the actor updates it per epoch without allocating; observers sample it at the
/// stats rate to draw the tracks.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct Track {
    /// Time of the INS epoch, s.
    pub t: f64,
    /// Corrected solution (the `result` frame's `solution`, without velocity).
    pub solution: Position,
    /// The epoch's INS position as received (with `input: imu`, the mechanized one, which
    /// after the feedback is the solution).
    pub ins: Position,
    /// With `input: imu`, the strapdown alignment state.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alignment: Option<crate::monitor::federated::Alignment>,
}

/// The latest epoch of a `gnss` monitor: its outputs (the `result` frame's) and time.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct GnssSnapshot {
    /// Time of the epoch, s.
    pub t: f64,
    /// The monitor's outputs at that epoch, shared with its report.
    #[serde(flatten)]
    pub outputs: Arc<GnssOutputs>,
}

/// Statistics of one monitor.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct MonitorStats {
    /// Monitor kind.
    #[serde(rename = "type")]
    pub kind: MonitorKind,
    /// Epochs consumed.
    pub epochs: u64,
    /// Worst (largest) last test ratio over its tests.
    pub worst_test_ratio: Option<f64>,
    /// Per test.
    pub tests: BTreeMap<TestName, TestStats>,
    /// `federated` only: the latest corrected and raw INS positions; absent
    /// before the first INS epoch and for other kinds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub track: Option<Track>,
    /// `federated` with `input: imu` only: the strapdown's alignment state after its last
    /// IMU epoch (before the first solution too, when there is no track yet).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alignment: Option<crate::monitor::federated::Alignment>,
    /// `gnss` only: the latest epoch with pseudoranges; absent before it and for other
    /// kinds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gnss: Option<GnssSnapshot>,
    /// Monitors with a protection level: availability now and its timeline; absent
    /// before the first epoch that reports one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub integrity: Option<IntegrityStats>,
}

/// Statistics of one session.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SessionStats {
    /// Session id.
    pub session: String,
    /// An ingest stream is attached.
    pub connected: bool,
    /// Frames accepted since the session started.
    pub frames: u64,
    /// Epochs processed.
    pub epochs: u64,
    /// Frames refused.
    pub frame_errors: u64,
    /// Time of the last epoch.
    pub last_t: Option<f64>,
    /// Wall-clock time of the last frame, Unix ms.
    pub last_frame_at_ms: Option<i64>,
    /// Server wall-clock time of this snapshot, Unix ms (to age `last_frame_at_ms`
    /// without trusting the client's clock).
    pub published_at_ms: i64,
    /// Epochs per second over the last second of wall-clock time (0 when detached).
    pub epochs_per_s: f64,
    /// Per monitor.
    pub monitors: BTreeMap<String, MonitorStats>,
}

impl SessionStats {
    /// Alarms counted, summed over every monitor and test.
    pub fn alarms(&self) -> u64 {
        self.monitors
            .values()
            .flat_map(|m| m.tests.values())
            .map(|t| t.alarms)
            .sum()
    }

    /// Warnings counted, summed over every monitor and test.
    pub fn warnings(&self) -> u64 {
        self.monitors
            .values()
            .flat_map(|m| m.tests.values())
            .map(|t| t.warnings)
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::{PolicyConfig, ThresholdSpec};
    use crate::monitor::TestBank;

    #[test]
    fn stats_track_time_in_state_exceedances_and_alarm_delay() {
        let policy = PolicyConfig::Counters { n1: 10, n2: 1 };
        let mut bank = TestBank::new(&[("r", 1)], ThresholdSpec::Threshold(10.0), policy).unwrap();
        let mut stats = TestStats::new(1, 10.0);
        let values = [1.0, 20.0, 30.0, 1.0, 1.0];
        let mut delays = vec![];
        for (k, v) in values.iter().enumerate() {
            let o = bank.evaluate(0, *v);
            let delay = stats.record(k as f64, &o);
            if o.previous != o.decision.health && o.decision.health != Health::Healthy {
                let severity = crate::session::AlarmLevel::Isolated
                    .severity(o.decision.health)
                    .unwrap();
                stats.count(severity, delay);
            }
            delays.push(delay);
        }
        // t=1 suspect (delay 0), t=2 isolated (delay 1 s from the first exceedance).
        assert_eq!(delays, vec![0.0, 0.0, 1.0, 0.0, 0.0]);
        assert_eq!(stats.exceedances, 2);
        // Under the default alarm level the suspect entry is a warning.
        assert_eq!((stats.alarms, stats.warnings), (1, 1));
        // t=3 still isolated (t1 = 1), t=4 healthy again (t1 = 0).
        assert_eq!(stats.state, Health::Healthy);
        assert_eq!(stats.state_since_t, Some(4.0));
        assert_eq!(stats.max, Some(30.0));
        assert!((stats.mean.unwrap() - 53.0 / 5.0).abs() < 1e-12);
        assert_eq!(
            stats.time_in_state_s,
            TimeInState {
                healthy: 1.0,
                suspect: 1.0,
                isolated: 2.0
            }
        );
        assert_eq!(stats.last_alarm_delay_s, Some(1.0));
    }

    fn sample() -> SessionStats {
        let mut test = TestStats::new(2, 5.99);
        test.alarms = 3;
        test.last = Some(1.25);
        let position = Position {
            lat: 30.0,
            lon: -114.5,
            h: 3.0,
        };
        let mut monitors = BTreeMap::new();
        monitors.insert(
            "nav".to_owned(),
            MonitorStats {
                kind: MonitorKind::Federated,
                epochs: 7,
                worst_test_ratio: Some(0.2),
                tests: BTreeMap::from([(TestName::from("gnss"), test.clone())]),
                track: Some(Track {
                    t: 1.5,
                    solution: position,
                    ins: position,
                    alignment: None,
                }),
                alignment: None,
                gnss: None,
                integrity: None,
            },
        );
        monitors.insert(
            "track".to_owned(),
            MonitorStats {
                kind: MonitorKind::Linear,
                epochs: 7,
                worst_test_ratio: None,
                tests: BTreeMap::from([(TestName::from("r"), test)]),
                track: None,
                alignment: None,
                gnss: None,
                integrity: None,
            },
        );
        SessionStats {
            session: "s1".to_owned(),
            connected: true,
            frames: 9,
            epochs: 7,
            frame_errors: 1,
            last_t: Some(1.5),
            last_frame_at_ms: Some(1_700_000_000_000),
            published_at_ms: 1_700_000_000_050,
            epochs_per_s: 20.0,
            monitors,
        }
    }

    #[test]
    fn session_stats_read_back_what_the_server_writes_byte_for_byte() {
        let written = serde_json::to_string(&sample()).unwrap();
        let read: SessionStats = serde_json::from_str(&written).unwrap();
        assert_eq!(serde_json::to_string(&read).unwrap(), written);
        assert_eq!(read.monitors["nav"].kind, MonitorKind::Federated);
        assert!(read.monitors["track"].track.is_none());
    }

    #[test]
    fn monitor_kind_is_written_as_its_wire_name() {
        let v = serde_json::to_value(sample()).unwrap();
        assert_eq!(v["monitors"]["nav"]["type"], "federated");
        assert_eq!(v["monitors"]["track"]["type"], "linear");
        assert!(v["monitors"]["track"].get("track").is_none());
    }

    #[test]
    fn session_alarms_sum_over_monitors_and_tests() {
        assert_eq!(sample().alarms(), 6);
        assert_eq!(sample().warnings(), 0);
    }

    #[test]
    fn a_protection_level_not_yet_known_goes_out_as_null_and_reads_back_as_nan() {
        let aligning = Integrity {
            state: Availability::Converging,
            protection_level: f64::NAN,
            alert_limit: 40.0,
        };
        let s = IntegrityStats::new(3.0, &aligning);
        let text = serde_json::to_string(&s).unwrap();
        assert!(text.contains("\"protection_level\":null"), "{text}");
        let back: IntegrityStats = serde_json::from_str(&text).unwrap();
        assert!(back.protection_level.is_nan());
        assert_eq!(
            (back.state, back.alert_limit),
            (Availability::Converging, 40.0)
        );
        assert_eq!(
            back.max_protection_level, None,
            "never the max while converging"
        );
    }

    #[test]
    fn availability_timeline_records_time_and_changes() {
        let at = |state, pl| Integrity {
            state,
            protection_level: pl,
            alert_limit: 25.0,
        };
        let mut s = IntegrityStats::new(0.0, &at(Availability::Converging, 80.0));
        assert_eq!(s.record(1.0, &at(Availability::Converging, 40.0)), None);
        assert_eq!(
            s.record(2.0, &at(Availability::Available, 20.0)),
            Some(Availability::Converging)
        );
        assert_eq!(s.record(5.0, &at(Availability::Available, 21.0)), None);
        assert_eq!(
            s.record(6.0, &at(Availability::Unavailable, 30.0)),
            Some(Availability::Available)
        );
        assert_eq!(
            s.time_s,
            TimeInAvailability {
                converging: 2.0,
                available: 4.0,
                unavailable: 0.0
            }
        );
        assert_eq!(s.changes, 2);
        assert_eq!(
            s.max_protection_level,
            Some(30.0),
            "converging levels are left out"
        );
        assert_eq!(s.timeline.len(), 3);
        assert_eq!(s.timeline[1].to_t, Some(6.0));
        assert_eq!(s.timeline[2].to_t, None);
        for k in 0..100 {
            let state = if k % 2 == 0 {
                Availability::Available
            } else {
                Availability::Unavailable
            };
            s.record(7.0 + k as f64, &at(state, 1.0));
        }
        assert_eq!(s.timeline.len(), TIMELINE_SPANS);
    }
}
