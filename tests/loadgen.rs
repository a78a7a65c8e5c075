//! Backpressure and fairness (docs/performance.md): a client that sends
//! faster than its session is processed (and does not read its results) slows
//! only its own socket; another session's epochs keep being answered, each in
//! order; once the flooding client reads again, every one of its epochs is
//! processed and answered in order, without an error.
//!
//! The server runs in-process and the test drives it with tokio-tungstenite
//! directly rather than through `navguard loadgen`: the load generator lives in
//! the binary (its engine measures, it does not assert per epoch), and the
//! shared target directory's `navguard` binary may be another build. Small
//! numbers, correctness only: no assertion depends on time except generous
//! timeouts that turn a deadlock into a failure. The last test runs the real
//! `navguard loadgen --ramp` (`CARGO_BIN_EXE_navguard`, this build) against the server.

use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use navguard::service::wire::{CreateSession, MonitorSpecWire};
use navguard::service::{self, ServiceConfig};
use navguard_core::detect::PolicyConfig;
use navguard_core::monitor::MonitorKind;
use navguard_core::monitor::linear::LinearConfigWire;
use serde_json::Value;
use tokio::net::{TcpSocket, TcpStream};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

mod common;

type Socket = WebSocketStream<MaybeTlsStream<TcpStream>>;

/// Epochs per frame of the flooding client.
const FLOOD_BATCH: usize = 100;
/// Frames the flooding client sends back to back.
const FLOOD_FRAMES: usize = 400;
/// Single-epoch frames of the well-behaved session.
const STEADY_FRAMES: usize = 40;
/// Longest wait for anything: a deadlock fails the test instead of hanging it.
const PATIENCE: Duration = Duration::from_secs(60);

/// The session body, built through the service's own wire type.
fn linear_session(id: &str) -> CreateSession {
    CreateSession {
        id: Some(id.to_owned()),
        monitors: vec![MonitorSpecWire {
            name: "track".into(),
            kind: MonitorKind::Linear,
            config: linear_config(),
            policy: PolicyConfig::Classic,
            p_fa: None,
            threshold: None,
            alarm_level: None,
            tests: Default::default(),
        }],
        echo: true,
        alarm_level: None,
        record: None,
    }
}

/// A 2-D constant-velocity model at 10 Hz seeing x and y, built through the
/// monitor's own config type so that a renamed field fails to compile.
fn linear_config() -> Value {
    let q = 0.005;
    let (a, b) = (q * 0.01 / 3.0, q * 0.1 / 2.0);
    let p0 = 5.0;
    let config = LinearConfigWire {
        f: vec![
            vec![1.0, 0.1, 0.0, 0.0],
            vec![0.0, 1.0, 0.0, 0.0],
            vec![0.0, 0.0, 1.0, 0.1],
            vec![0.0, 0.0, 0.0, 1.0],
        ],
        h: vec![vec![1.0, 0.0, 0.0, 0.0], vec![0.0, 0.0, 1.0, 0.0]],
        q: vec![
            vec![a, b, 0.0, 0.0],
            vec![b, q, 0.0, 0.0],
            vec![0.0, 0.0, a, b],
            vec![0.0, 0.0, b, q],
        ],
        r: vec![vec![1.0, 0.0], vec![0.0, 1.0]],
        x0: vec![0.0, 1.0, 0.0, -1.0],
        p0: vec![
            vec![p0, 0.0, 0.0, 0.0],
            vec![0.0, p0, 0.0, 0.0],
            vec![0.0, 0.0, p0, 0.0],
            vec![0.0, 0.0, 0.0, p0],
        ],
        b: None,
        drift: None,
        stuck: None,
    };
    serde_json::to_value(config).unwrap()
}

/// Epoch `k` of a target moving at (1, −1) m/s, seen without noise at 10 Hz.
fn epoch(k: usize) -> String {
    let t = k as f64 * 0.1;
    format!(r#"{{"t":{t},"z":[{t},{}]}}"#, -t)
}

fn t_of(k: usize) -> f64 {
    k as f64 * 0.1
}

/// Opens a session's ingest socket; `small_receive_buffer` shrinks the
/// client's TCP receive buffer so that unread results back up quickly.
async fn connect(addr: std::net::SocketAddr, id: &str, small_receive_buffer: bool) -> Socket {
    let tcp = TcpSocket::new_v4().unwrap();
    if small_receive_buffer {
        tcp.set_recv_buffer_size(4096).unwrap();
    }
    let stream = tcp.connect(addr).await.unwrap();
    let url = format!("ws://{addr}/api/v1/sessions/{id}/ingest");
    let (mut socket, _) = tokio_tungstenite::client_async(url, MaybeTlsStream::Plain(stream))
        .await
        .unwrap();
    let ready = next_json(&mut socket).await;
    assert_eq!(ready["type"], "ready", "{ready}");
    socket
}

async fn next_json(socket: &mut Socket) -> Value {
    loop {
        let message = tokio::time::timeout(PATIENCE, socket.next())
            .await
            .expect("the server answered")
            .expect("the socket is open")
            .expect("no socket error");
        if let Message::Text(text) = message {
            return serde_json::from_str(&text).unwrap();
        }
    }
}

async fn processed_epochs(http: &reqwest::Client, addr: std::net::SocketAddr, id: &str) -> u64 {
    let stats: Value = http
        .get(format!("http://{addr}/api/v1/sessions/{id}/stats"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    stats["epochs"].as_u64().unwrap()
}

/// Reads results until `count` epochs are answered; asserts that they come in
/// order starting at epoch `from`, and that nothing else but `result` arrives.
async fn expect_results<S>(stream: &mut S, from: usize, count: usize)
where
    S: StreamExt<Item = Result<Message, tokio_tungstenite::tungstenite::Error>> + Unpin,
{
    let mut k = from;
    while k < from + count {
        let message = tokio::time::timeout(PATIENCE, stream.next())
            .await
            .expect("results keep coming")
            .expect("the socket is open")
            .expect("no socket error");
        let Message::Text(text) = message else {
            continue;
        };
        let v: Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["type"], "result", "epoch {k}: {v}");
        let t = v["t"].as_f64().unwrap();
        assert!((t - t_of(k)).abs() < 1e-9, "epoch {k}: result for t = {t}");
        assert!(v["monitors"]["track"]["tests"]["residual"].is_object());
        k += 1;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flooding_session_slows_only_its_own_socket_and_every_epoch_is_answered_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let server = service::start(ServiceConfig::new(
        "127.0.0.1:0".parse().unwrap(),
        dir.path().join("loadgen.db"),
    ))
    .await
    .unwrap();
    let addr = server.addr;
    let http = reqwest::Client::new();
    for id in ["flood", "steady"] {
        let status = http
            .post(format!("http://{addr}/api/v1/sessions"))
            .json(&linear_session(id))
            .send()
            .await
            .unwrap()
            .status();
        assert_eq!(status, 201);
    }

    // The flooder writes every frame back to back and reads nothing yet.
    let flood = connect(addr, "flood", true).await;
    let (mut flood_sink, mut flood_stream) = flood.split();
    let writer = tokio::spawn(async move {
        for f in 0..FLOOD_FRAMES {
            let frame: Vec<String> = (f * FLOOD_BATCH..(f + 1) * FLOOD_BATCH)
                .map(epoch)
                .collect();
            let text = format!("[{}]", frame.join(","));
            flood_sink.send(Message::Text(text.into())).await.unwrap();
        }
        flood_sink
    });

    // Its session stalls: results it cannot deliver stop its actor, and its
    // socket stops being read. Wait until its count stops moving.
    let total = (FLOOD_FRAMES * FLOOD_BATCH) as u64;
    let mut last = u64::MAX;
    let stalled = loop {
        tokio::time::sleep(Duration::from_millis(300)).await;
        let now = processed_epochs(&http, addr, "flood").await;
        if now == last {
            break now;
        }
        last = now;
    };
    assert!(
        stalled < total,
        "the flooding session processed all {total} epochs without its results being read"
    );
    // (Whether the client's own writes block too depends on how much the
    // kernel's socket buffers hold; the session's actor has stopped either way.)

    // Meanwhile another session is answered, epoch by epoch, in order.
    let mut steady = connect(addr, "steady", false).await;
    for k in 0..STEADY_FRAMES {
        steady.send(Message::Text(epoch(k).into())).await.unwrap();
        expect_results(&mut steady, k, 1).await;
    }
    assert_eq!(
        processed_epochs(&http, addr, "steady").await,
        STEADY_FRAMES as u64
    );

    // The flooder reads again: every epoch it sent is processed and answered
    // in order, with no error.
    expect_results(&mut flood_stream, 0, total as usize).await;
    let flood_sink = tokio::time::timeout(PATIENCE, writer)
        .await
        .expect("the flooding client finished writing")
        .unwrap();
    assert_eq!(processed_epochs(&http, addr, "flood").await, total);
    let mut flood = flood_sink.reunite(flood_stream).unwrap();
    flood.close(None).await.unwrap();
    steady.close(None).await.unwrap();
    server.shutdown().await;
}

/// `navguard loadgen --ramp` end to end against a real server: with a limit no
/// run can reach, the ramp must take every step up to `--ramp-max`, answer every
/// epoch of every step in order, report memory and CPU, draw its curve, and
/// leave no session behind. Nothing here depends on how fast the machine is.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_ramp_streams_every_step_to_its_maximum_and_draws_the_curve() {
    let dir = tempfile::tempdir().unwrap();
    let server = service::start(ServiceConfig::new(
        "127.0.0.1:0".parse().unwrap(),
        dir.path().join("ramp.db"),
    ))
    .await
    .unwrap();
    let svg = dir.path().join("ramp.svg");
    let output = tokio::process::Command::new(env!("CARGO_BIN_EXE_navguard"))
        .arg("loadgen")
        .args(["--url", &format!("ws://{}", server.addr)])
        .args(["--monitor", "linear", "--sessions", "2", "--ramp", "3"])
        .args(["--ramp-max", "5", "--ramp-p99-ms", "600000"])
        .args(["--duration", "1", "--settle", "0", "--json", "--svg"])
        .arg(&svg)
        .output()
        .await
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "loadgen failed: {stderr}");
    let report: Value = serde_json::from_slice(&output.stdout).unwrap();
    let steps = report["steps"].as_array().unwrap();
    let sessions: Vec<u64> = steps
        .iter()
        .map(|s| s["sessions"].as_u64().unwrap())
        .collect();
    // 2, then 2 + 3 = 5, which is the maximum.
    assert_eq!(sessions, [2, 5]);
    for step in steps {
        let n = step["sessions"].as_u64().unwrap();
        assert_eq!(step["within_limit"], true, "{step}");
        assert_eq!(step["results"], step["epochs_sent"], "{step}");
        assert_eq!(step["unanswered_frames"], 0, "{step}");
        assert_eq!(step["out_of_order"], 0, "{step}");
        // 10 Hz for 1 s: at most the pass's 11 single-epoch frames per session
        // (fewer if the machine delays the send clock), at least one.
        let sent = step["epochs_sent"].as_u64().unwrap();
        assert!((n..=11 * n).contains(&sent), "{n} sessions sent {sent}");
        assert_eq!(step["passes"], n, "{step}");
        assert_eq!(step["frame_latency"]["count"], step["frames_sent"]);
        assert!(step["loaded_bytes_per_session"].is_number(), "{step}");
        assert!(
            step["cpu"]["server_cores"].as_f64().unwrap() > 0.0,
            "{step}"
        );
    }
    assert_eq!(report["largest_within_limit"], 5);
    assert_eq!(report["stopped"], "reached --ramp-max 5 within the limit");
    let drawn = std::fs::read_to_string(&svg).unwrap();
    assert!(drawn.starts_with("<svg") && drawn.contains("p99 limit 600000 ms"));
    let (_, body) = common::get_json(&format!("http://{}/api/v1/sessions", server.addr)).await;
    assert_eq!(body["sessions"].as_array().map(Vec::len), Some(0), "{body}");
    server.shutdown().await;
}

/// `navguard loadgen --input imu` end to end: two raw-IMU sessions at 10 frames of 10
/// epochs a second, every epoch answered in order and no error. Nothing depends on time.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_raw_imu_run_answers_every_epoch_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let server = service::start(ServiceConfig::new(
        "127.0.0.1:0".parse().unwrap(),
        dir.path().join("imu.db"),
    ))
    .await
    .unwrap();
    let output = tokio::process::Command::new(env!("CARGO_BIN_EXE_navguard"))
        .arg("loadgen")
        .args(["--url", &format!("ws://{}", server.addr)])
        .args([
            "--input",
            "imu",
            "--sessions",
            "2",
            "--rate",
            "10",
            "--batch",
            "10",
        ])
        .args(["--duration", "1", "--settle", "0", "--json"])
        .output()
        .await
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "loadgen failed: {stderr}");
    let report: Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(report["monitor"], "federated/imu", "{report}");
    assert_eq!(report["batch"], 10);
    let sent = report["epochs_sent"].as_u64().unwrap();
    // 10 frames of 10 epochs a second for 1 s: at most 11 frames a session.
    assert!((10..=220).contains(&sent), "sent {sent}");
    assert_eq!(sent % 10, 0, "whole frames of 10: {sent}");
    assert_eq!(report["results"], sent, "{report}");
    assert_eq!(report["out_of_order"], 0, "{report}");
    assert_eq!(report["unanswered_frames"], 0, "{report}");
    assert_eq!(report["errors"], serde_json::json!({}), "{report}");
    let (_, body) = common::get_json(&format!("http://{}/api/v1/sessions", server.addr)).await;
    assert_eq!(body["sessions"].as_array().map(Vec::len), Some(0), "{body}");
    server.shutdown().await;
}
