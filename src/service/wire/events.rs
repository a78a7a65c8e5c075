//! Outbound events: the `result`, `state`, `alarm` and `error` messages the server sends.

use std::collections::BTreeMap;

use serde::Serialize;
use serde_json::ser::{CompactFormatter, Formatter};

use super::ingest::{FrameError, FrameErrorCode};
use navguard_core::monitor::federated::FederatedSolution;
use navguard_core::monitor::{MonitorReport, Outputs, TestOutcome};

// ------------------------------------------------------------- server messages

/// Room for one `result` frame: a federated monitor's is about 800 bytes.
pub const RESULT_FRAME_BYTES: usize = 1024;

/// Appends one epoch's `result` frame to `out`: its time and each reporting monitor's
/// result by name (a monitor that failed on the epoch is left out by the caller). The
/// session actor writes a frame's results into one buffer and sends each as a slice of it.
///
/// The frame is `{"type":"result","t":…,"monitors":{NAME:{"tests":{TEST:{"statistic",
/// "threshold","dof","test_ratio","state"},…},"integrity":{"state","protection_level",
/// "alert_limit"}?,…outputs}}}`: monitors and tests in name order (a name given twice
/// keeps its last entry), numbers as serde_json writes them (shortest round trip,
/// non-finite as `null`). The fixed keys are written as they are, and only names go
/// through JSON escaping; a federated monitor's outputs are written the same way, and
/// other monitors' outputs are serialised by serde and spliced in.
/// Byte for byte what serde writes for the same frame (tested against it below), in
/// less time (`cargo bench --bench wire`: 58.6 µs for 100 ship results through serde,
/// 33–38 µs now); most of what remains is formatting the numbers.
pub fn write_result_frame<'a>(
    out: &mut Vec<u8>,
    t: f64,
    monitors: impl IntoIterator<Item = (&'a str, &'a MonitorReport)>,
) {
    let mut monitors: Vec<(&str, &MonitorReport)> = monitors.into_iter().collect();
    // Stable: of two entries with one name, the later stays last and is the one kept.
    monitors.sort_by(|a, b| a.0.cmp(b.0));
    out.extend_from_slice(br#"{"type":"result","t":"#);
    write_f64(out, t);
    out.extend_from_slice(br#","monitors":{"#);
    let mut first = true;
    for (k, &(name, report)) in monitors.iter().enumerate() {
        if monitors.get(k + 1).is_some_and(|next| next.0 == name) {
            continue;
        }
        if !first {
            out.push(b',');
        }
        first = false;
        write_str(out, name);
        out.extend_from_slice(br#":{"tests":{"#);
        write_tests(out, &report.tests);
        out.push(b'}');
        if let Some(i) = &report.integrity {
            out.extend_from_slice(br#","integrity":{"state":""#);
            out.extend_from_slice(i.state.as_str().as_bytes());
            out.extend_from_slice(br#"","protection_level":"#);
            write_f64(out, i.protection_level);
            out.extend_from_slice(br#","alert_limit":"#);
            write_f64(out, i.alert_limit);
            out.push(b'}');
        }
        write_outputs(out, &report.outputs);
        out.push(b'}');
    }
    out.extend_from_slice(b"}}");
}

/// The tests of one report as a JSON object's members, by name; a report that lists
/// them in name order (every monitor does) is written as it stands.
fn write_tests(out: &mut Vec<u8>, tests: &[TestOutcome]) {
    if tests.windows(2).all(|w| w[0].name < w[1].name) {
        for (k, o) in tests.iter().enumerate() {
            write_test(out, k == 0, o);
        }
    } else {
        let sorted: BTreeMap<&str, &TestOutcome> = tests.iter().map(|o| (&*o.name, o)).collect();
        for (k, o) in sorted.into_values().enumerate() {
            write_test(out, k == 0, o);
        }
    }
}

fn write_test(out: &mut Vec<u8>, first: bool, o: &TestOutcome) {
    if !first {
        out.push(b',');
    }
    let s = &o.statistic;
    write_str(out, &o.name);
    out.extend_from_slice(br#":{"statistic":"#);
    write_f64(out, s.value);
    out.extend_from_slice(br#","threshold":"#);
    write_f64(out, s.threshold);
    out.extend_from_slice(br#","dof":"#);
    let _ = CompactFormatter.write_u32(out, s.dof);
    out.extend_from_slice(br#","test_ratio":"#);
    write_f64(out, s.test_ratio());
    out.extend_from_slice(br#","state":""#);
    out.extend_from_slice(o.decision.health.as_str().as_bytes());
    out.extend_from_slice(br#""}"#);
}

/// The outputs' members after the monitor's others: the federated monitor's written here
/// in serde's field order; others as serde writes them as an object, whose braces are
/// taken off (an empty one leaves nothing).
fn write_outputs(out: &mut Vec<u8>, outputs: &Outputs) {
    // The hand-written path covers a client-INS monitor; with `input: imu` (an alignment
    // state, an attitude) serde writes the outputs.
    if let Outputs::Federated {
        solution,
        hpl,
        isolated,
        alignment: None,
    } = outputs
    {
        if solution.is_none_or(|s| s.att.is_none()) {
            write_federated_outputs(out, solution.as_ref(), *hpl, isolated);
            return;
        }
    }
    let at = out.len();
    // Numbers, strings, sequences and maps with string keys serialise without error.
    let _ = serde_json::to_writer(&mut *out, outputs);
    if out.len() <= at + 2 {
        out.truncate(at);
    } else {
        out[at] = b',';
        out.pop();
    }
}

/// The federated monitor's outputs, the most common, written as serde writes them (its
/// field order) without it.
fn write_federated_outputs(
    out: &mut Vec<u8>,
    solution: Option<&FederatedSolution>,
    hpl: Option<f64>,
    isolated: &[&str],
) {
    out.extend_from_slice(br#","solution":"#);
    match solution {
        Some(s) => {
            out.extend_from_slice(br#"{"lat":"#);
            write_f64(out, s.lat);
            out.extend_from_slice(br#","lon":"#);
            write_f64(out, s.lon);
            out.extend_from_slice(br#","h":"#);
            write_f64(out, s.h);
            out.extend_from_slice(br#","vel":"#);
            write_array(out, &s.vel, |out, &v| write_f64(out, v));
            out.push(b'}');
        }
        None => out.extend_from_slice(b"null"),
    }
    out.extend_from_slice(br#","hpl":"#);
    // `None` is `null`, as a non-finite number is.
    write_f64(out, hpl.unwrap_or(f64::NAN));
    out.extend_from_slice(br#","isolated":"#);
    write_array(out, isolated, |out, name| write_str(out, name));
}

/// A JSON array of `items`, each written by `each`.
fn write_array<T>(out: &mut Vec<u8>, items: &[T], mut each: impl FnMut(&mut Vec<u8>, &T)) {
    out.push(b'[');
    for (k, item) in items.iter().enumerate() {
        if k > 0 {
            out.push(b',');
        }
        each(out, item);
    }
    out.push(b']');
}

/// A number as serde_json writes an `f64`: shortest round trip, non-finite as `null`.
fn write_f64(out: &mut Vec<u8>, v: f64) {
    if v.is_finite() {
        let _ = CompactFormatter.write_f64(out, v);
    } else {
        out.extend_from_slice(b"null");
    }
}

/// A JSON string, escaped.
fn write_str(out: &mut Vec<u8>, s: &str) {
    // Writing a string into a Vec cannot fail.
    let _ = serde_json::to_writer(&mut *out, s);
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

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;
    use std::sync::Arc;

    use serde::ser::SerializeMap;
    use serde::{Serialize, Serializer};

    use super::*;
    use navguard_core::detect::{Decision, Health, Statistic};
    use navguard_core::monitor::Availability;
    use navguard_core::monitor::Integrity;
    use navguard_core::monitor::gnss::GnssOutputs;
    use navguard_core::monitor::gnss::outputs::{Dops, GnssPosition, SatOutput};

    // The `result` frame as serde writes it from types: the form the hand-written writer
    // replaced, kept as its reference.

    #[derive(Serialize)]
    struct TestResultWire {
        statistic: f64,
        threshold: f64,
        dof: u32,
        test_ratio: f64,
        state: Health,
    }

    #[derive(Serialize)]
    struct IntegrityWire {
        state: Availability,
        protection_level: f64,
        alert_limit: f64,
    }

    struct TestsWire<'a>(&'a [TestOutcome]);

    impl Serialize for TestsWire<'_> {
        fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
            let sorted: BTreeMap<&str, &TestOutcome> =
                self.0.iter().map(|o| (&*o.name, o)).collect();
            let mut map = serializer.serialize_map(Some(sorted.len()))?;
            for (name, o) in sorted {
                let s = &o.statistic;
                let result = TestResultWire {
                    statistic: s.value,
                    threshold: s.threshold,
                    dof: s.dof,
                    test_ratio: s.test_ratio(),
                    state: o.decision.health,
                };
                map.serialize_entry(name, &result)?;
            }
            map.end()
        }
    }

    #[derive(Serialize)]
    struct MonitorResultWire<'a> {
        tests: TestsWire<'a>,
        #[serde(skip_serializing_if = "Option::is_none")]
        integrity: Option<IntegrityWire>,
        #[serde(flatten)]
        outputs: &'a Outputs,
    }

    #[derive(Serialize)]
    struct ResultFrame<'a> {
        #[serde(rename = "type")]
        kind: &'static str,
        t: f64,
        monitors: BTreeMap<&'a str, MonitorResultWire<'a>>,
    }

    fn by_serde(t: f64, monitors: &[(&str, &MonitorReport)]) -> String {
        let monitors = monitors
            .iter()
            .map(|&(name, r)| {
                let integrity = r.integrity.map(|i| IntegrityWire {
                    state: i.state,
                    protection_level: i.protection_level,
                    alert_limit: i.alert_limit,
                });
                let wire = MonitorResultWire {
                    tests: TestsWire(&r.tests),
                    integrity,
                    outputs: &r.outputs,
                };
                (name, wire)
            })
            .collect();
        let frame = ResultFrame {
            kind: "result",
            t,
            monitors,
        };
        serde_json::to_string(&frame).unwrap()
    }

    fn outcome(name: &str, value: f64, threshold: f64, dof: u32, health: Health) -> TestOutcome {
        TestOutcome {
            index: 0,
            name: Arc::from(name),
            statistic: Statistic {
                value,
                threshold,
                dof,
            },
            decision: Decision {
                health,
                update: true,
                fuse: true,
                reset: false,
            },
            previous: Health::Healthy,
        }
    }

    /// Reports of every monitor kind, with awkward numbers and names. Over 80 lines: one
    /// fixture, read as a table of cases.
    fn reports() -> Vec<(&'static str, MonitorReport)> {
        let tests = vec![
            outcome("cns", 1.25e-7, 11.345, 2, Health::Healthy),
            outcome("dvl", 0.1 + 0.2, 16.27, 3, Health::Suspect),
            outcome("gnss", 1e300, 22.457744484825326, 6, Health::Isolated),
            outcome("hpl", f64::NAN, f64::INFINITY, 1, Health::Healthy),
        ];
        let federated = MonitorReport {
            tests: tests.clone(),
            outputs: Outputs::Federated {
                solution: Some(FederatedSolution {
                    lat: 30.123456789012345,
                    lon: -120.5,
                    h: -0.0,
                    vel: [1.0, -2.5e-12, f64::NEG_INFINITY],
                    att: None,
                }),
                hpl: Some(24.531182482419574),
                isolated: vec!["gnss"],
                alignment: None,
            },
            integrity: Some(Integrity {
                state: Availability::Converging,
                protection_level: 32.95314407244513,
                alert_limit: 25.0,
            }),
        };
        // Tests out of order, one name twice (the later entry is kept).
        let mut unsorted = tests.clone();
        unsorted.reverse();
        unsorted.push(outcome("dvl", 2.0, 16.27, 3, Health::Healthy));
        let linear = MonitorReport {
            tests: unsorted,
            outputs: Outputs::Linear {
                innovation: None,
                x: vec![1.0, 2.0, 3.5, -4.0],
            },
            integrity: None,
        };
        let channel = MonitorReport {
            tests: vec![outcome("a\"b\\c\u{7}é", 3.0, 9.0, 1, Health::Healthy)],
            outputs: Outputs::Channel {
                prediction: [(Arc::from("a\"b\\c\u{7}é"), vec![0.5])].into(),
                residual: BTreeMap::new(),
            },
            integrity: None,
        };
        let rimu = MonitorReport {
            tests: Vec::new(),
            outputs: Outputs::Rimu {
                parity: Some(vec![0.1, 0.2]),
                flagged: vec![1],
                isolated: Vec::new(),
                omega: Some([0.0, 1e-5, 3.0]),
            },
            integrity: None,
        };
        let tacan = MonitorReport {
            tests: vec![outcome("range", 0.0, 0.0, 0, Health::Healthy)],
            outputs: Outputs::Tacan {
                features: None,
                decision: None,
            },
            integrity: Some(Integrity {
                state: Availability::Unavailable,
                protection_level: f64::NAN,
                alert_limit: 40.0,
            }),
        };
        // A fix with awkward numbers, a satellite without geometry, one excluded.
        let gnss = MonitorReport {
            tests: vec![outcome(
                "raim",
                1007.299425159751,
                34.09130098231032,
                14,
                Health::Suspect,
            )],
            outputs: Outputs::Gnss(Arc::new(GnssOutputs {
                position: Some(GnssPosition {
                    lat: 37.692237073777186,
                    lon: -122.08845157993579,
                    h: -0.0,
                }),
                clocks: [("E".to_owned(), 20.31900463431), ("G".to_owned(), -1e-300)].into(),
                dop: Some(Dops {
                    gdop: 1.5,
                    pdop: 0.1 + 0.2,
                    hdop: 1e21,
                    vdop: f64::NAN,
                }),
                hpl: Some(47.953212863695065),
                vpl: Some(f64::INFINITY),
                hal: 40.0,
                val: None,
                hpe: Some(2.8742980158685474),
                vpe: None,
                satellites: vec![
                    SatOutput {
                        id: "G10".to_owned(),
                        el: Some(63.8000764993965),
                        az: Some(19.6345796646986),
                        residual: Some(199.9788277524254),
                        w: Some(18.2806918485177),
                        used: false,
                        health: Health::Suspect,
                    },
                    SatOutput {
                        id: "R24".to_owned(),
                        el: None,
                        az: None,
                        residual: None,
                        w: None,
                        used: true,
                        health: Health::Healthy,
                    },
                ],
                excluded: vec!["G10".to_owned()],
            })),
            integrity: Some(Integrity {
                state: Availability::Unavailable,
                protection_level: 47.953212863695065,
                alert_limit: 40.0,
            }),
        };
        // Before the first fix: no position, no satellites.
        let gnss_bare = MonitorReport {
            tests: Vec::new(),
            outputs: Outputs::Gnss(Arc::new(GnssOutputs::without_solution(
                40.0,
                Some(50.0),
                Vec::new(),
            ))),
            integrity: None,
        };
        // Before the first INS epoch, and with two aids isolated.
        let federated_bare = MonitorReport {
            tests: Vec::new(),
            outputs: Outputs::Federated {
                solution: None,
                hpl: None,
                isolated: vec!["dvl", "gnss"],
                alignment: None,
            },
            integrity: None,
        };
        // A mechanized solution (`input: imu`): attitude and alignment state.
        let federated_imu = MonitorReport {
            tests: Vec::new(),
            outputs: Outputs::Federated {
                solution: Some(FederatedSolution {
                    lat: 40.0966268,
                    lon: -105.1474483,
                    h: 1601.25,
                    vel: [0.5, 3.0, -0.01],
                    att: Some([1.5, -6.75, 359.5]),
                }),
                hpl: Some(3.5),
                isolated: Vec::new(),
                alignment: Some(navguard_core::monitor::federated::Alignment::Aligned),
            },
            integrity: None,
        };
        vec![
            ("nav", federated),
            ("nav0", federated_bare),
            ("strap", federated_imu),
            ("lin", linear),
            ("ch \u{1F680}", channel),
            ("gyros", rimu),
            ("tacan", tacan),
            ("gnss", gnss),
            ("gnss0", gnss_bare),
        ]
    }

    fn by_hand(t: f64, monitors: &[(&str, &MonitorReport)]) -> String {
        let mut out = Vec::new();
        write_result_frame(&mut out, t, monitors.iter().copied());
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn the_result_frame_is_what_serde_writes_byte_for_byte() {
        let reports = reports();
        let all: Vec<(&str, &MonitorReport)> = reports.iter().map(|(n, r)| (*n, r)).collect();
        for (t, monitors) in [
            (0.0, vec![all[0]]),
            (12.3, all.clone()),
            (-1e-9, all.iter().rev().copied().collect()),
            // A monitor named twice: the later entry is kept, as a map keeps it.
            (f64::NAN, vec![all[0], all[1], ("nav", all[2].1)]),
            (1e21, Vec::new()),
        ] {
            let hand = by_hand(t, &monitors);
            assert_eq!(hand, by_serde(t, &monitors));
            serde_json::from_str::<serde_json::Value>(&hand).expect("valid JSON");
        }
    }

    #[test]
    fn a_gnss_report_is_written_flat_beside_its_tests() {
        let reports = reports();
        let gnss: Vec<(&str, &MonitorReport)> = reports
            .iter()
            .filter(|(n, _)| n.starts_with("gnss"))
            .map(|(n, r)| (*n, r))
            .collect();
        let frame: serde_json::Value = serde_json::from_str(&by_hand(5.0, &gnss)).unwrap();
        let m = &frame["monitors"]["gnss"];
        let keys: Vec<&str> = m.as_object().unwrap().keys().map(String::as_str).collect();
        assert_eq!(
            keys,
            [
                "clocks",
                "dop",
                "excluded",
                "hal",
                "hpe",
                "hpl",
                "integrity",
                "position",
                "satellites",
                "tests",
                "val",
                "vpe",
                "vpl"
            ]
        );
        assert_eq!(m["tests"]["raim"]["dof"], 14);
        assert_eq!(m["tests"]["raim"]["state"], "suspect");
        assert_eq!(m["position"]["lat"], 37.692237073777186);
        assert_eq!(m["clocks"]["G"], -1e-300);
        assert_eq!(m["dop"]["vdop"], serde_json::Value::Null, "non-finite");
        assert_eq!(m["vpl"], serde_json::Value::Null, "non-finite");
        assert_eq!(
            (&m["val"], &m["vpe"]),
            (&serde_json::Value::Null, &serde_json::Value::Null)
        );
        assert_eq!(m["excluded"], serde_json::json!(["G10"]));
        assert_eq!(
            m["satellites"][0],
            serde_json::json!({"id": "G10", "el": 63.8000764993965, "az": 19.6345796646986,
                "residual": 199.9788277524254, "w": 18.2806918485177, "used": false,
                "health": "suspect"})
        );
        assert_eq!(m["satellites"][1]["el"], serde_json::Value::Null);
        assert_eq!(m["integrity"]["state"], "unavailable");
        let bare = &frame["monitors"]["gnss0"];
        assert_eq!(bare["position"], serde_json::Value::Null);
        assert_eq!(bare["val"], 50.0);
        assert_eq!(bare["satellites"], serde_json::json!([]));
        assert_eq!(bare["clocks"], serde_json::json!({}));
        assert!(bare.get("integrity").is_none());
    }

    #[test]
    fn a_federated_report_of_the_ship_is_written_as_serde_writes_it() {
        let scenario = navguard_sim::ship_with(4, Vec::new(), 30.0).unwrap();
        let spec = navguard_core::monitor::MonitorSpec {
            kind: navguard_core::monitor::MonitorKind::Federated,
            config: navguard_core::monitor::MonitorConfig::Federated(scenario.monitor_config()),
            policy: navguard_core::detect::PolicyConfig::Counters { n1: 10, n2: 5 },
            threshold: navguard_core::detect::ThresholdSpec::PFa(1e-3),
        };
        let mut monitor =
            navguard_core::monitor::build(&spec, &navguard_core::monitor::NoModels).unwrap();
        for e in &scenario.epochs {
            let report = monitor.step(&e.epoch).unwrap();
            let monitors = [("federated", &report)];
            assert_eq!(
                by_hand(e.epoch.t, &monitors),
                by_serde(e.epoch.t, &monitors)
            );
        }
    }
}
