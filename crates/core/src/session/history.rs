//! A bounded history of a session's decimated statistics (docs/architecture.md §A12):
//! one sample per second of epoch time, the last `capacity` of them, so a dashboard
//! opened mid-run draws the past before the live `stats` messages continue it
//! (`GET /api/v1/sessions/{id}/history?since=`). Kept compactly (statistics as `f32`,
//! states as a byte), about 10 bytes per test per sample (40 more for a `gnss`
//! monitor's levels and errors); restarted with each stream.

use std::collections::VecDeque;

use serde::Serialize;

use super::stats::{GnssSnapshot, SessionStats, Track};
use crate::detect::Health;
use crate::monitor::{Availability, TestName};

/// Seconds of epoch time between samples.
pub const PERIOD_S: f64 = 1.0;

/// One test at one sample: last statistic, threshold, state.
#[derive(Debug, Clone, Copy, PartialEq)]
struct TestPoint {
    last: f32,
    threshold: f32,
    state: Health,
}

/// A `gnss` monitor's latest pseudorange epoch at one sample: its time, protection
/// levels, alert limits and (with a truth) errors, m; `None` where the epoch had none.
#[derive(Debug, Clone, Copy, PartialEq)]
struct GnssPoint {
    t: f64,
    hpl: Option<f32>,
    vpl: Option<f32>,
    hal: f32,
    val: Option<f32>,
    hpe: Option<f32>,
    vpe: Option<f32>,
}

impl GnssPoint {
    fn of(g: &GnssSnapshot) -> Self {
        let o = &g.outputs;
        let f = |x: Option<f64>| x.map(|v| v as f32);
        GnssPoint {
            t: g.t,
            hpl: f(o.hpl),
            vpl: f(o.vpl),
            hal: o.hal as f32,
            val: f(o.val),
            hpe: f(o.hpe),
            vpe: f(o.vpe),
        }
    }

    fn json(&self) -> serde_json::Value {
        let f = |x: Option<f32>| x.map(f64::from);
        serde_json::json!({
            "t": self.t,
            "hpl": f(self.hpl),
            "vpl": f(self.vpl),
            "hal": f64::from(self.hal),
            "val": f(self.val),
            "hpe": f(self.hpe),
            "vpe": f(self.vpe),
        })
    }
}

/// One monitor at one sample.
#[derive(Debug, Clone, PartialEq)]
struct MonitorPoint {
    /// In the order of the layout's tests; `None` before the test first ran.
    tests: Vec<Option<TestPoint>>,
    /// Protection level, alert limit, availability.
    integrity: Option<(f32, f32, Availability)>,
    track: Option<Track>,
    /// `gnss` monitors: the latest pseudorange epoch's levels and errors (without its
    /// satellites, which only the latest `stats` carry).
    gnss: Option<GnssPoint>,
}

#[derive(Debug, Clone, PartialEq)]
struct Sample {
    t: f64,
    monitors: Vec<MonitorPoint>,
}

/// The history of one session.
#[derive(Debug, Clone)]
pub struct History {
    capacity: usize,
    /// Monitor names and their test names, in the statistics' (sorted) order.
    layout: Vec<(String, Vec<TestName>)>,
    samples: VecDeque<Sample>,
    next_t: Option<f64>,
}

/// What `GET …/history` answers.
#[derive(Debug, Serialize)]
pub struct HistoryView {
    /// Seconds of epoch time between samples.
    pub period_s: f64,
    /// Samples at or after `since`, oldest first.
    pub samples: Vec<serde_json::Value>,
}

impl History {
    /// An empty history keeping `capacity` samples for the monitors and tests of `stats`.
    pub fn new(capacity: usize, stats: &SessionStats) -> Self {
        let layout = stats
            .monitors
            .iter()
            .map(|(name, m)| (name.clone(), m.tests.keys().cloned().collect()))
            .collect();
        History {
            capacity,
            layout,
            samples: VecDeque::new(),
            next_t: None,
        }
    }

    /// Forgets every sample (a new stream).
    pub fn clear(&mut self) {
        self.samples.clear();
        self.next_t = None;
    }

    /// Takes a sample of `stats` at epoch time `t` when a period has passed since the
    /// last one (time going back restarts the history).
    pub fn offer(&mut self, t: f64, stats: &SessionStats) {
        if self.capacity == 0 {
            return;
        }
        if let Some(last) = self.samples.back()
            && t < last.t
        {
            self.clear();
        }
        if self.next_t.is_some_and(|next| t < next) {
            return;
        }
        self.next_t = Some((t / PERIOD_S).floor() * PERIOD_S + PERIOD_S);
        let monitors = self
            .layout
            .iter()
            .map(|(name, tests)| {
                let m = stats.monitors.get(name);
                MonitorPoint {
                    tests: tests
                        .iter()
                        .map(|test| {
                            let ts = m?.tests.get(test)?;
                            Some(TestPoint {
                                last: ts.last? as f32,
                                threshold: ts.threshold as f32,
                                state: ts.state,
                            })
                        })
                        .collect(),
                    integrity: m
                        .and_then(|m| m.integrity.as_ref())
                        .map(|i| (i.protection_level as f32, i.alert_limit as f32, i.state)),
                    track: m.and_then(|m| m.track),
                    gnss: m.and_then(|m| m.gnss.as_ref()).map(GnssPoint::of),
                }
            })
            .collect();
        self.samples.push_back(Sample { t, monitors });
        if self.samples.len() > self.capacity {
            self.samples.pop_front();
        }
    }

    /// Samples at or after `since` (all with `None`).
    pub fn view(&self, since: Option<f64>) -> HistoryView {
        let samples = self
            .samples
            .iter()
            .filter(|s| since.is_none_or(|since| s.t >= since))
            .map(|s| self.sample_json(s))
            .collect();
        HistoryView {
            period_s: PERIOD_S,
            samples,
        }
    }

    fn sample_json(&self, s: &Sample) -> serde_json::Value {
        let mut monitors = serde_json::Map::new();
        for ((name, tests), point) in self.layout.iter().zip(&s.monitors) {
            let mut t = serde_json::Map::new();
            for (test, p) in tests.iter().zip(&point.tests) {
                if let Some(p) = p {
                    t.insert(
                        test.to_string(),
                        serde_json::json!({
                            "last": f64::from(p.last),
                            "threshold": f64::from(p.threshold),
                            "state": p.state,
                        }),
                    );
                }
            }
            let mut m = serde_json::Map::new();
            m.insert("tests".into(), t.into());
            if let Some((pl, al, state)) = point.integrity {
                m.insert(
                    "integrity".into(),
                    serde_json::json!({
                        "protection_level": f64::from(pl),
                        "alert_limit": f64::from(al),
                        "state": state,
                    }),
                );
            }
            if let Some(track) = &point.track {
                m.insert(
                    "track".into(),
                    serde_json::to_value(track).unwrap_or_default(),
                );
            }
            if let Some(g) = &point.gnss {
                m.insert("gnss".into(), g.json());
            }
            monitors.insert(name.clone(), m.into());
        }
        serde_json::json!({"t": s.t, "monitors": monitors})
    }

    /// Samples held.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// True when no sample is held.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::monitor::MonitorKind;
    use crate::session::stats::{MonitorStats, TestStats};
    use std::collections::BTreeMap;

    fn stats(last: f64) -> SessionStats {
        let mut test = TestStats::new(1, 9.5);
        test.last = Some(last);
        SessionStats {
            session: "s".into(),
            connected: true,
            frames: 0,
            epochs: 0,
            frame_errors: 0,
            last_t: None,
            last_frame_at_ms: None,
            published_at_ms: 0,
            epochs_per_s: 0.0,
            monitors: BTreeMap::from([(
                "m".to_owned(),
                MonitorStats {
                    kind: MonitorKind::Linear,
                    epochs: 0,
                    worst_test_ratio: None,
                    tests: BTreeMap::from([(TestName::from("residual"), test)]),
                    track: None,
                    alignment: None,
                    gnss: None,
                    integrity: None,
                },
            )]),
        }
    }

    #[test]
    fn one_sample_per_second_of_epoch_time_bounded_and_restarted() {
        let mut h = History::new(5, &stats(0.0));
        // 10 Hz epochs over 8 s: samples at t = 0, 1, …, 7; the last 5 are kept.
        for k in 0..80 {
            let t = k as f64 * 0.1;
            h.offer(t, &stats(t));
        }
        assert_eq!(h.len(), 5);
        let v = h.view(None);
        let ts: Vec<f64> = v.samples.iter().map(|s| s["t"].as_f64().unwrap()).collect();
        assert_eq!(ts.len(), 5);
        assert!(
            (ts[0] - 3.0).abs() < 1e-9 && (ts[4] - 7.0).abs() < 1e-9,
            "{ts:?}"
        );
        assert_eq!(
            v.samples[4]["monitors"]["m"]["tests"]["residual"]["state"],
            "healthy"
        );
        assert!(
            (v.samples[4]["monitors"]["m"]["tests"]["residual"]["last"]
                .as_f64()
                .unwrap()
                - 7.0)
                .abs()
                < 1e-6
        );
        assert_eq!(h.view(Some(6.0)).samples.len(), 2);
        // Time going back (a new stream) restarts it.
        h.offer(0.5, &stats(0.5));
        assert_eq!(h.len(), 1);
    }

    #[test]
    fn a_gnss_monitors_levels_and_errors_are_sampled_without_its_satellites() {
        use crate::monitor::gnss::GnssOutputs;
        use crate::session::stats::GnssSnapshot;
        use std::sync::Arc;
        let with_gnss = |t: f64, hpe: Option<f64>| {
            let mut s = stats(t);
            let mut o = GnssOutputs::without_solution(40.0, None, Vec::new());
            o.hpl = Some(12.5);
            o.vpl = Some(20.25);
            o.hpe = hpe;
            let m = s.monitors.get_mut("m").unwrap();
            m.gnss = Some(GnssSnapshot {
                t: t - 0.5,
                outputs: Arc::new(o),
            });
            s
        };
        let mut h = History::new(10, &stats(0.0));
        h.offer(1.0, &with_gnss(1.0, Some(3.5)));
        h.offer(2.0, &with_gnss(2.0, None));
        h.offer(3.0, &stats(3.0));
        let v = h.view(None);
        let g = &v.samples[0]["monitors"]["m"]["gnss"];
        assert_eq!(
            *g,
            serde_json::json!({"t": 0.5, "hpl": 12.5, "vpl": 20.25, "hal": 40.0, "val": null, "hpe": 3.5, "vpe": null}),
        );
        assert_eq!(
            v.samples[1]["monitors"]["m"]["gnss"]["hpe"],
            serde_json::Value::Null
        );
        assert_eq!(v.samples[1]["monitors"]["m"]["gnss"]["t"], 1.5);
        // A monitor without a gnss snapshot has no `gnss` member.
        assert!(v.samples[2]["monitors"]["m"].get("gnss").is_none());
    }

    #[test]
    fn a_history_of_zero_keeps_nothing() {
        let mut h = History::new(0, &stats(0.0));
        h.offer(1.0, &stats(1.0));
        assert!(h.is_empty());
    }
}
