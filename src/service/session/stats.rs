//! Per-session statistics (`GET /api/v1/sessions/{id}/stats` and the `stats`
//! event): per monitor and test, counts, statistic summary, time in each state
//! and the detection delay of the last alarm. Updated by the session actor.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::detect::Health;
use crate::monitor::{MonitorKind, TestName, TestOutcome};

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
    /// Alarms raised (transitions into suspect or isolated).
    pub alarms: u64,
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
    #[serde(skip)]
    sum: f64,
    #[serde(skip)]
    last_t: Option<f64>,
    #[serde(skip)]
    episode_start_t: Option<f64>,
}

impl TestStats {
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
            last: None,
            last_test_ratio: None,
            mean: None,
            max: None,
            time_in_state_s: TimeInState::default(),
            last_alarm_delay_s: None,
            sum: 0.0,
            last_t: None,
            episode_start_t: None,
        }
    }

    /// Records one evaluation at epoch time `t`. Returns the detection delay
    /// to put on the alarm when this outcome raises one.
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
                self.alarms += 1;
                delay = t - self.episode_start_t.unwrap_or(t);
                self.last_alarm_delay_s = Some(delay);
            }
        } else if health == Health::Healthy && !s.exceeds() {
            self.episode_start_t = None;
        }
        delay
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
    /// The epoch's INS position as received.
    pub ins: Position,
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
            delays.push(stats.record(k as f64, &o));
        }
        // t=1 suspect (delay 0), t=2 isolated (delay 1 s from the first exceedance).
        assert_eq!(delays, vec![0.0, 0.0, 1.0, 0.0, 0.0]);
        assert_eq!(stats.exceedances, 2);
        assert_eq!(stats.alarms, 2);
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
                }),
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
    }
}
