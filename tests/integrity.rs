//! Integrity and alarms through the real server (docs/methods.md §M23, §M24): a federated session
//! opens `converging` with its protection level above the alert limit and raises no alarm;
//! a GNSS fault present from the start is a warning while the filter converges and an
//! alarm the moment it has converged; the drift and stuck tests raise their own alarms
//! (`gnss.drift` on a slow GNSS drift, `residual.stuck` on a frozen measurement), stored
//! in the alarm log with their test names; and the experiments, scoring the same
//! scenario through the session core, log the same entries as the server.
//!
//! The ship runs at a 1 Hz INS rate (as in tests/federated.rs) so a debug build streams
//! a few hundred seconds quickly.

mod common;

use common::{Socket, client, create_session, get_text, http, ingest, recv, send, ship_1hz, start};
use navguard::service::session::spec::monitor_spec;
use navguard::service::wire::{MonitorSpecWire, epoch_to_wire};
use navguard::service::{Limits, Server};
use navguard_sim::{Channel, Fault, FaultKind, Scenario};
use serde_json::{Value, json};

/// A session `id` with one federated monitor `nav` (the scenario's config with `extra`
/// merged in), counters, p_fa 1e-3, echoing results.
fn federated_session(id: &str, scenario: &Scenario, extra: Value) -> Value {
    let mut config = scenario.default_monitor_config();
    for (k, v) in extra.as_object().unwrap() {
        config[k] = v.clone();
    }
    json!({"id": id, "echo": true, "monitors": [{
        "name": "nav", "type": "federated", "config": config,
        "policy": {"kind": "counters", "n1": 10, "n2": 5}, "p_fa": 1e-3
    }]})
}

/// Streams `frames` in batches of 10 and returns, in arrival order, every message the
/// ingest socket sent up to the last `result`: the results and the events between them.
async fn stream_all(socket: &mut Socket, frames: &[Value]) -> (Vec<Value>, Vec<Value>) {
    for chunk in frames.chunks(10) {
        send(socket, &Value::Array(chunk.to_vec())).await;
    }
    let (mut results, mut events) = (Vec::new(), Vec::new());
    while results.len() < frames.len() {
        let message = recv(socket).await;
        assert_ne!(message["type"], "error", "{message}");
        if message["type"] == "result" {
            results.push(message);
        } else {
            events.push(message);
        }
    }
    (results, events)
}

fn frames(scenario: &Scenario) -> Vec<Value> {
    scenario
        .epochs
        .iter()
        .map(|e| serde_json::from_str(&epoch_to_wire(&e.epoch).unwrap()).unwrap())
        .collect()
}

/// The session's stored alarm log (alarms and warnings), oldest first.
async fn alarm_log(server: &Server, session: &str) -> Vec<Value> {
    let page: Value = client()
        .get(format!(
            "{}/api/v1/alarms?session={session}&limit=1000",
            http(server)
        ))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let mut log = page["alarms"].as_array().unwrap().clone();
    log.sort_by_key(|a| a["id"].as_i64().unwrap());
    log
}

/// A 100 m step on the GNSS north position over `[start_s, end_s)`.
fn gnss_step(start_s: f64, end_s: f64) -> Fault {
    Fault {
        aid: navguard_core::epoch::Aid::Gnss,
        channel: Channel::Position,
        component: 0,
        kind: FaultKind::Step { value: 100.0 },
        start_s,
        end_s: Some(end_s),
    }
}

fn of_type<'a>(events: &'a [Value], kind: &str) -> Vec<&'a Value> {
    events.iter().filter(|e| e["type"] == kind).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_federated_session_opens_converging_without_an_alarm_and_then_is_available() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("i.db"), None, Limits::default()).await;
    let scenario = ship_1hz(11, Vec::new(), 240.0);
    create_session(
        &client(),
        &server,
        &federated_session("conv", &scenario, json!({})),
    )
    .await;
    let mut socket = ingest(&server, "conv").await;
    let (results, events) = stream_all(&mut socket, &frames(&scenario)).await;

    // At t = 0 the HPL from P0 is above the HAL: the filter converging, not a fault.
    let first = &results[0]["monitors"]["nav"]["integrity"];
    assert_eq!(first["state"], "converging", "{first}");
    assert!(
        first["protection_level"].as_f64().unwrap() > first["alert_limit"].as_f64().unwrap(),
        "{first}"
    );
    // One change, converging → available, at the first epoch whose HPL is within the HAL.
    let changes = of_type(&events, "availability");
    assert_eq!(changes.len(), 1, "{changes:?}");
    let change = changes[0];
    assert_eq!(
        (&change["from"], &change["to"]),
        (&json!("converging"), &json!("available"))
    );
    let at = results
        .iter()
        .position(|r| r["monitors"]["nav"]["integrity"]["state"] == "available")
        .unwrap();
    assert_eq!(change["t"], results[at]["t"]);
    assert!(
        change["protection_level"].as_f64().unwrap() <= change["alert_limit"].as_f64().unwrap()
    );
    assert!(
        results[..at]
            .iter()
            .all(|r| r["monitors"]["nav"]["integrity"]["state"] == "converging")
    );
    // No alarm on either channel, none stored.
    assert!(of_type(&events, "alarm").is_empty(), "{events:?}");
    let log = alarm_log(&server, "conv").await;
    assert!(
        log.iter().all(|a| a["severity"] != "alarm"),
        "fault-free alarms: {log:?}"
    );
    // The stats keep the timeline: the convergence stretch, then available now.
    let stats: Value = client()
        .get(format!("{}/api/v1/sessions/conv/stats", http(&server)))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let integrity = &stats["monitors"]["nav"]["integrity"];
    assert_eq!(integrity["state"], "available", "{integrity}");
    let timeline = integrity["timeline"].as_array().unwrap();
    assert_eq!(timeline[0]["state"], "converging", "{integrity}");
    assert_eq!(
        timeline.last().unwrap()["state"],
        "available",
        "{integrity}"
    );
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_gnss_fault_from_the_start_warns_while_converging_and_alarms_once_converged() {
    // A 100 m east offset on every GNSS fix from t = 0 and a 30 s convergence cap: GNSS is
    // excluded within seconds, and without it the HPL may never come within the HAL.
    let fault = Fault {
        aid: navguard_core::epoch::Aid::Gnss,
        channel: Channel::Position,
        component: 0,
        kind: FaultKind::Step { value: 100.0 },
        start_s: 0.0,
        end_s: None,
    };
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("i.db"), None, Limits::default()).await;
    let scenario = ship_1hz(12, vec![fault], 60.0);
    create_session(
        &client(),
        &server,
        &federated_session("start", &scenario, json!({"converge_max_s": 30.0})),
    )
    .await;
    let mut socket = ingest(&server, "start").await;
    let (_, events) = stream_all(&mut socket, &frames(&scenario)).await;

    let changes = of_type(&events, "availability");
    let converged = changes
        .iter()
        .find(|c| c["from"] == "converging")
        .expect("the monitor converges (or its cap passes)");
    let t_conv = converged["t"].as_f64().unwrap();
    assert!(t_conv <= 31.0, "{converged}");
    // Before it: the GNSS tests' changes are warnings, however far they went.
    let states = of_type(&events, "state");
    let early: Vec<_> = states
        .iter()
        .filter(|s| s["t"].as_f64().unwrap() < t_conv)
        .collect();
    assert!(
        early
            .iter()
            .any(|s| s["test"] == "gnss" && s["to"] == "isolated"),
        "GNSS isolated while converging: {states:?}"
    );
    assert!(
        early.iter().all(|s| s["severity"] == "warning"),
        "{early:?}"
    );
    // At convergence: one alarm per test left isolated, `gnss` among them, at that epoch.
    let alarms = of_type(&events, "alarm");
    assert!(!alarms.is_empty(), "{events:?}");
    assert!(alarms.iter().any(|a| a["test"] == "gnss"), "{alarms:?}");
    for a in &alarms {
        assert_eq!(a["t"].as_f64().unwrap(), t_conv, "{a}");
        assert!(a["test"].as_str().unwrap().starts_with("gnss"), "{a}");
        assert_eq!(a["state"], "isolated", "{a}");
    }
    // Stored the same way: warnings before, the alarms at convergence.
    let log = alarm_log(&server, "start").await;
    let stored: Vec<_> = log.iter().filter(|a| a["severity"] == "alarm").collect();
    assert_eq!(stored.len(), alarms.len(), "{log:?}");
    assert!(
        log.iter()
            .filter(|a| a["t"].as_f64().unwrap() < t_conv)
            .all(|a| a["severity"] == "warning"),
        "{log:?}"
    );
    server.shutdown().await;
}

/// Onset of the drift, s.
const ONSET: f64 = 600.0;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn gnss_drift_alarms_on_a_slow_gnss_drift_through_the_server() {
    // 1 m/s north-east from 600 s (as tests/federated.rs does in-process): the drift test
    // warns within about 20 m and excludes GNSS well before the per-epoch χ² test.
    let faults = navguard_sim::experiment::ramp::ramp_faults(1.0, ONSET);
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("i.db"), None, Limits::default()).await;
    let scenario = ship_1hz(6, faults, ONSET + 80.0);
    create_session(
        &client(),
        &server,
        &federated_session("ramp", &scenario, json!({})),
    )
    .await;
    let mut socket = ingest(&server, "ramp").await;
    let (results, events) = stream_all(&mut socket, &frames(&scenario)).await;

    let states = of_type(&events, "state");
    let first = |test: &str| {
        states
            .iter()
            .find(|s| s["test"] == test && s["from"] == "healthy")
            .map(|s| s["t"].as_f64().unwrap() - ONSET)
    };
    let warned = first("gnss.drift").expect("gnss.drift flags the drift");
    assert!(
        warned <= 25.0,
        "gnss.drift flagged {warned} s (m) into the drift"
    );
    assert!(first("gnss").is_none_or(|c| c >= warned), "{states:?}");
    let alarms = of_type(&events, "alarm");
    assert!(
        alarms.iter().all(|a| a["t"].as_f64().unwrap() >= ONSET
            && a["test"].as_str().unwrap().starts_with("gnss")),
        "{alarms:?}"
    );
    let drift = alarms
        .iter()
        .find(|a| a["test"] == "gnss.drift")
        .unwrap_or_else(|| panic!("no gnss.drift alarm: {alarms:?}"));
    let after = drift["t"].as_f64().unwrap() - ONSET;
    assert!(
        after <= 40.0,
        "gnss.drift alarm {after} s (m) into the drift"
    );
    assert_eq!(drift["dof"], 2, "{drift}");
    assert!(drift["test_ratio"].as_f64().unwrap() > 1.0, "{drift}");
    // The results carry the test beside the χ² test, and the log stores the alarm.
    let tests = &results.last().unwrap()["monitors"]["nav"]["tests"];
    assert!(tests.get("gnss.drift").is_some(), "{tests}");
    let log = alarm_log(&server, "ramp").await;
    assert!(
        log.iter()
            .any(|a| a["test"] == "gnss.drift" && a["severity"] == "alarm"),
        "{log:?}"
    );
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn residual_stuck_alarms_on_a_frozen_measurement_through_the_server() {
    // A slow 1-D random walk seen with σ = 1, frozen from measurement 300.
    let mut g = common::Gauss::new(21);
    let mut truth = 0.0;
    let mut z: Vec<f64> = (0..400)
        .map(|_| {
            truth += 0.01 * g.normal();
            truth + g.normal()
        })
        .collect();
    let held = z[299];
    for v in &mut z[300..] {
        *v = held;
    }
    let config = json!({
        "f": [[1.0]], "h": [[1.0]], "q": [[1e-4]], "r": [[1.0]], "x0": [0.0], "p0": [[1.0]],
        "stuck": {}
    });
    let body = json!({"id": "stuck", "echo": true, "monitors": [{
        "name": "cv", "type": "linear", "config": config,
        "policy": {"kind": "classic"}, "p_fa": 1e-3
    }]});
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("i.db"), None, Limits::default()).await;
    create_session(&client(), &server, &body).await;
    let mut socket = ingest(&server, "stuck").await;
    let (results, events) = stream_all(&mut socket, &common::epochs(&z, 0)).await;

    let alarms = of_type(&events, "alarm");
    let stuck = alarms
        .iter()
        .find(|a| a["test"] == "residual.stuck")
        .unwrap_or_else(|| panic!("no residual.stuck alarm: {alarms:?}"));
    // The first repeat is measurement 301; k = 8 repeated differences flag it.
    let t = stuck["t"].as_f64().unwrap();
    assert!((300.0..=310.0).contains(&t), "{stuck}");
    assert_eq!(stuck["dof"], 1, "{stuck}");
    // Nothing before the freeze (p_fa 1e-6 on the stuck test).
    assert!(
        alarms
            .iter()
            .all(|a| a["test"] != "residual.stuck" || a["t"].as_f64().unwrap() >= 300.0),
        "{alarms:?}"
    );
    let last = &results.last().unwrap()["monitors"]["cv"]["tests"];
    assert!(last.get("residual.stuck").is_some(), "{last}");
    server.shutdown().await;
}

/// Every message the ingest socket sends up to the `results`-th `result` since the
/// stream began (`seen` of them already read), in arrival order.
async fn messages_until(socket: &mut Socket, seen: &mut usize, results: usize) -> Vec<Value> {
    let mut out = Vec::new();
    while *seen < results {
        let message = recv(socket).await;
        assert_ne!(message["type"], "error", "{message}");
        if message["type"] == "result" {
            *seen += 1;
        }
        out.push(message);
    }
    out
}

/// What differs between two sessions fed the same stream is taken out: their ids, the
/// alarm log's ids and the wall-clock times.
fn without_identity(mut v: Value) -> Value {
    if let Some(o) = v.as_object_mut() {
        for key in ["session", "id", "log_id", "raised_at_ms"] {
            o.remove(key);
        }
        for x in o.values_mut() {
            *x = without_identity(x.take());
        }
    }
    v
}

async fn counter(server: &Server, name: &str) -> u64 {
    let text = get_text(&format!("{}/metrics", http(server))).await;
    text.lines()
        .find_map(|l| l.strip_prefix(name)?.trim().parse().ok())
        .unwrap_or_else(|| panic!("no {name} in {text}"))
}

/// Frames queued at a session (sent back to back) have their first slice stepped on the
/// compute pool while the frame before is committed (docs/architecture.md §A2 step 3).
/// The results, state changes, alarms, availability changes and the alarm log are those
/// of the same frames sent one at a time, each after the results of the one before.
// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn queued_frames_are_stepped_ahead_with_the_messages_of_one_frame_at_a_time() {
    // A GNSS offset from the start, standing when the monitor converges (30 s cap), whose
    // alarm is raised then; and a GNSS jump well after
    // convergence: warnings, an alarm, the return to healthy.
    let scenario = ship_1hz(
        13,
        vec![gnss_step(0.0, 60.0), gnss_step(300.0, 360.0)],
        700.0,
    );
    // The first frame ends on the epoch that ends convergence (t = 30 s), so that epoch
    // is committed while the next frame steps ahead.
    let frames = frames(&scenario);
    assert_eq!(frames[30]["t"], 30.0);
    let batches: Vec<Value> = std::iter::once(&frames[..31])
        .chain(frames[31..].chunks(100))
        .map(|c| Value::Array(c.to_vec()))
        .collect();
    let epochs = scenario.epochs.len();
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("i.db"), None, Limits::default()).await;
    for id in ["ahead", "serial"] {
        create_session(
            &client(),
            &server,
            &federated_session(id, &scenario, json!({"converge_max_s": 30.0})),
        )
        .await;
    }

    let mut socket = ingest(&server, "ahead").await;
    for batch in &batches {
        send(&mut socket, batch).await;
    }
    let ahead = messages_until(&mut socket, &mut 0, epochs).await;
    let stepped_ahead = counter(&server, "navguard_frames_prestepped_total").await;
    // The second frame may be stepped while the first one's commit ends convergence: the
    // standing alarm is read from the committed statistics, not from the monitors.
    assert!(
        stepped_ahead >= batches.len() as u64 / 2,
        "{stepped_ahead} of {} frames stepped ahead",
        batches.len()
    );

    let mut socket = ingest(&server, "serial").await;
    let (mut serial, mut seen, mut sent) = (Vec::new(), 0, 0);
    for batch in &batches {
        send(&mut socket, batch).await;
        sent += batch.as_array().unwrap().len();
        serial.extend(messages_until(&mut socket, &mut seen, sent).await);
    }
    assert_eq!(
        counter(&server, "navguard_frames_prestepped_total").await,
        stepped_ahead,
        "a frame sent after the results of the one before is never stepped ahead"
    );

    for kind in ["alarm", "state", "availability"] {
        assert!(!of_type(&ahead, kind).is_empty(), "no {kind} message");
    }
    // The standing alarm raised at convergence, at the end of the converging stretch.
    let converged = of_type(&ahead, "availability")[0]["t"].as_f64().unwrap();
    assert!(
        of_type(&ahead, "alarm")
            .iter()
            .any(|a| a["test"] == "gnss" && a["t"].as_f64() == Some(converged)),
        "{ahead:?}"
    );
    assert_eq!(ahead.len(), serial.len());
    for (a, s) in ahead.into_iter().zip(serial) {
        assert_eq!(without_identity(a), without_identity(s));
    }
    let (log_ahead, log_serial) = (
        alarm_log(&server, "ahead").await,
        alarm_log(&server, "serial").await,
    );
    assert!(!log_ahead.is_empty());
    assert_eq!(
        log_ahead
            .into_iter()
            .map(without_identity)
            .collect::<Vec<_>>(),
        log_serial
            .into_iter()
            .map(without_identity)
            .collect::<Vec<_>>()
    );
    server.shutdown().await;
}

/// The experiments score the server's own rule: a scenario streamed through the server,
/// and the same scenario run by the experiment code (`run_monitor`, through the session
/// core), log the same entries — test, state, epoch time and severity — in the same
/// order: warnings while converging, the standing alarm raised at convergence, the later
/// fault's warnings and alarms.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_experiments_log_the_alarms_and_warnings_the_server_logs() {
    let scenario = ship_1hz(
        13,
        vec![gnss_step(0.0, 60.0), gnss_step(300.0, 360.0)],
        700.0,
    );
    let session = federated_session("agree", &scenario, json!({"converge_max_s": 30.0}));
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("a.db"), None, Limits::default()).await;
    create_session(&client(), &server, &session).await;
    let mut socket = ingest(&server, "agree").await;
    stream_all(&mut socket, &frames(&scenario)).await;
    let served: Vec<(String, String, f64, String)> = alarm_log(&server, "agree")
        .await
        .iter()
        .map(|a| {
            let text = |k: &str| a[k].as_str().unwrap().to_owned();
            (
                text("test"),
                text("state"),
                a["t"].as_f64().unwrap(),
                text("severity"),
            )
        })
        .collect();
    server.shutdown().await;

    let wire: MonitorSpecWire = serde_json::from_value(session["monitors"][0].clone()).unwrap();
    let spec = monitor_spec(&wire).unwrap();
    let run = navguard_sim::experiment::run_monitor(&scenario, &spec).unwrap();
    let scored: Vec<(String, String, f64, String)> = run
        .entries
        .iter()
        .map(|e| {
            let state = serde_json::to_value(e.state)
                .unwrap()
                .as_str()
                .unwrap()
                .to_owned();
            (e.test.clone(), state, e.t, e.severity.as_str().to_owned())
        })
        .collect();
    assert_eq!(served, scored);
    // Not trivially equal: warnings while converging, the standing alarm at convergence
    // (a warning for the same test before it), and the later jump's alarm.
    let count = |severity: &str| served.iter().filter(|e| e.3 == severity).count();
    assert!(count("warning") >= 2 && count("alarm") >= 2, "{served:?}");
    let standing = served
        .iter()
        .position(|e| e.0 == "gnss" && e.1 == "isolated" && e.3 == "alarm")
        .unwrap();
    assert!(
        served[..standing]
            .iter()
            .any(|e| e.0 == "gnss" && e.1 == "isolated" && e.3 == "warning")
    );
    assert!(
        served
            .iter()
            .any(|e| e.3 == "alarm" && e.2 >= 300.0 && e.2 < 360.0)
    );
}
