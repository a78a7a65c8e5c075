//! The cluster end to end (docs/deployment.md): `deploy/cluster.sh` starts Postgres, NATS,
//! three nodes and HAProxy on loopback ports; 30 sessions stream through the load balancer
//! with faults that raise alarms; one node is `kill -9`ed and another drained. Checked:
//! every session of the killed node resumes on another node within lease + 2 s and from
//! where its checkpoint says; the alarm log holds exactly the entries an uninterrupted
//! monitor raises over the same epochs, each once; an events socket on one node sees the
//! alarms of sessions the others own; a threshold `PUT` sent to a node that does not own
//! the session reaches the live session; draining a node moves its sessions without an
//! alarm lost, and its clients, connected through the load balancer, are told `moved` and
//! closed cleanly before the load balancer marks the node down. A client's Close is
//! answered through the load balancer on both sockets; after NATS is restarted by hand,
//! `deploy/cluster.sh status` reports it and `stop` stops it.
//!
//! The cluster runs secured as `deploy/cluster.sh` sets it up: NATS with TLS and a
//! password, a cluster key, Postgres with TLS (`sslmode=verify-full`) and scram-sha-256,
//! HAProxy's TLS frontend. NATS refuses a client without a login, Postgres one without TLS
//! or without the password. A client holding the nodes' NATS login but not the cluster key
//! publishes forged alarms and a forged end of session on the events subjects: no events
//! socket delivers them (nor closes on them), while every genuine alarm still arrives, and
//! the node counts them in `navguard_bus_rejected_total`.
//!
//! Needs Debian's `postgresql`, `nats-server`, `haproxy` and `openssl`: without them the test says
//! how to run it and passes, unless `NAVGUARD_CLUSTER_TEST=1` (set by `.ci/run`), which
//! makes a missing engine a failure.

mod common;

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use common::{CvModel, Socket, cv_session, get_json};
use futures_util::{SinkExt, StreamExt};
use navguard_core::detect::{Health, PolicyConfig, ThresholdSpec};
use navguard_core::epoch::Epoch;
use navguard_core::monitor::{MonitorConfig, MonitorKind, MonitorSpec, NoModels};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::protocol::CloseFrame;
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;

const SESSIONS: usize = 30;
const LEASE_MS: u64 = 3000;
/// Epochs per phase: before the kill, between the kill and the drain, after the drain.
const PHASE: usize = 150;
/// Epochs per frame.
const BATCH: usize = 10;

fn engines_missing() -> Vec<&'static str> {
    let mut missing = Vec::new();
    let on_path = |b: &str| {
        Command::new("sh")
            .args(["-c", &format!("command -v {b}")])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if !on_path("nats-server") {
        missing.push("nats-server");
    }
    if !on_path("openssl") {
        missing.push("openssl");
    }
    if !on_path("haproxy") && !Path::new("/usr/sbin/haproxy").exists() {
        missing.push("haproxy");
    }
    let initdb = std::fs::read_dir("/usr/lib/postgresql")
        .map(|d| d.flatten().any(|v| v.path().join("bin/initdb").exists()))
        .unwrap_or(false);
    if !initdb {
        missing.push("postgresql");
    }
    missing
}

/// The running cluster: its directory and the URLs from `cluster.env`.
struct Cluster {
    dir: tempfile::TempDir,
    env: HashMap<String, String>,
}

impl Cluster {
    /// Runs `deploy/cluster.sh` on this cluster: its exit status and output.
    fn run_script(&self, args: &[&str]) -> (Option<i32>, String) {
        let out = Command::new(repo().join("deploy/cluster.sh"))
            .args(args)
            .args(["--dir", self.dir.path().to_str().unwrap()])
            .output()
            .expect("deploy/cluster.sh runs");
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        (out.status.code(), text)
    }

    /// Runs `deploy/cluster.sh` on this cluster, which must succeed: its output.
    fn script(&self, args: &[&str]) -> String {
        let (code, text) = self.run_script(args);
        assert_eq!(code, Some(0), "cluster.sh {args:?} failed:\n{text}");
        text
    }

    fn url(&self, key: &str) -> String {
        self.env[key].clone()
    }

    fn node_url(&self, node: &str) -> String {
        self.url(&format!("{}_URL", node.to_uppercase()))
    }

    fn logs(&self) -> String {
        let mut out = String::new();
        for k in 1..=3 {
            let path = self.dir.path().join(format!("node{k}.log"));
            let text = std::fs::read_to_string(&path).unwrap_or_default();
            let tail: Vec<&str> = text.lines().rev().take(40).collect();
            out.push_str(&format!("--- node{k}.log (last lines)\n"));
            for line in tail.into_iter().rev() {
                out.push_str(line);
                out.push('\n');
            }
        }
        out
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = Command::new(repo().join("deploy/cluster.sh"))
            .args(["stop", "--dir", self.dir.path().to_str().unwrap()])
            .output();
    }
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn start_cluster() -> Cluster {
    let dir = tempfile::tempdir().unwrap();
    // A port base of our own: 20000 + 100·(pid mod 120), so every port the script
    // uses (base to base + 20s) stays below Linux's ephemeral range (32768 up):
    // there, a node's own client socket to Postgres or NATS can take the load
    // balancer's port before HAProxy binds it (seen in CI: 37300 in use).
    let base = 20_000 + 100 * (std::process::id() % 120);
    let mut cluster = Cluster {
        dir,
        env: HashMap::new(),
    };
    let base = base.to_string();
    let lease = LEASE_MS.to_string();
    cluster.script(&[
        "start",
        "--port-base",
        &base,
        "--bin",
        env!("CARGO_BIN_EXE_navguard"),
        "--lease-ms",
        &lease,
    ]);
    let env = std::fs::read_to_string(cluster.dir.path().join("cluster.env")).unwrap();
    cluster.env = env
        .lines()
        .filter_map(|l| l.split_once('='))
        .map(|(k, v)| (k.to_owned(), v.trim_matches(['"', '\'']).to_owned()))
        .collect();
    cluster
}

/// What an uninterrupted monitor does over `z`: the log entries it raises (epoch
/// index, state, severity), in order, and its residual test's epochs, mean and max.
struct Reference {
    entries: Vec<(usize, Health, &'static str)>,
    epochs: u64,
    mean: f64,
    max: f64,
}

fn reference(model: &CvModel, z: &[f64]) -> Reference {
    let spec = MonitorSpec {
        kind: MonitorKind::Linear,
        config: MonitorConfig::parse(MonitorKind::Linear, &model.config()).unwrap(),
        policy: PolicyConfig::Classic,
        threshold: ThresholdSpec::default(),
    };
    let mut m = navguard_core::monitor::build(&spec, &NoModels).unwrap();
    let mut out = Vec::new();
    let (mut epochs, mut sum, mut max) = (0u64, 0.0, f64::NEG_INFINITY);
    for (k, z) in z.iter().enumerate() {
        let epoch = Epoch {
            t: k as f64,
            z: Some(vec![*z]),
            ..Default::default()
        };
        for outcome in m.step(&epoch).unwrap().tests {
            if &*outcome.name == "residual" {
                epochs += 1;
                sum += outcome.statistic.value;
                max = max.max(outcome.statistic.value);
            }
            let to = outcome.decision.health;
            if outcome.previous != to {
                match to {
                    Health::Isolated => out.push((k, to, "alarm")),
                    Health::Suspect => out.push((k, to, "warning")),
                    Health::Healthy => {}
                }
            }
        }
    }
    Reference {
        entries: out,
        epochs,
        mean: sum / epochs as f64,
        max,
    }
}

/// One session's client: its measurements, where it has got to, its socket.
struct Client {
    id: String,
    z: Vec<f64>,
    /// Epochs the server has answered (`result`s received).
    done: usize,
    socket: Option<Socket>,
    node: String,
}

async fn open_ingest(lb_ws: &str, id: &str) -> Result<(Socket, Value), String> {
    let url = format!("{lb_ws}/api/v1/sessions/{id}/ingest?resume=true");
    let mut request = url.into_client_request().unwrap();
    request
        .headers_mut()
        .insert("sec-websocket-protocol", "navguard".parse().unwrap());
    let (mut socket, _) = tokio_tungstenite::connect_async(request)
        .await
        .map_err(|e| e.to_string())?;
    loop {
        match tokio::time::timeout(Duration::from_secs(10), socket.next()).await {
            Ok(Some(Ok(Message::Text(t)))) => {
                let v: Value = serde_json::from_str(&t).unwrap();
                if v["type"] == "ready" {
                    return Ok((socket, v));
                }
            }
            Ok(Some(Ok(_))) => continue,
            other => return Err(format!("no ready: {other:?}")),
        }
    }
}

/// Connects (through the load balancer, resuming), retrying as a client would until
/// `deadline`; returns the time it took and sets `done` from the `ready`'s resume point.
async fn connect(lb_ws: &str, c: &mut Client, deadline: Duration) -> Duration {
    let start = Instant::now();
    loop {
        match open_ingest(lb_ws, &c.id).await {
            Ok((socket, ready)) => {
                c.socket = Some(socket);
                c.node = ready["node"].as_str().unwrap_or("").to_owned();
                let from = match ready["resumed"]["t"].as_f64() {
                    Some(t) => t as usize + 1,
                    None => 0,
                };
                if from < c.done {
                    eprintln!(
                        "{}: resumed at epoch {from} on {}, resending {} epochs",
                        c.id,
                        c.node,
                        c.done - from
                    );
                }
                c.done = from;
                return start.elapsed();
            }
            Err(e) => {
                assert!(
                    start.elapsed() < deadline,
                    "{}: no ingest socket within {deadline:?}: {e}",
                    c.id
                );
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
    }
}

/// Streams `c`'s epochs up to `until` in frames of `BATCH`, each frame answered (echo)
/// before the next; stops early (false) when the socket closes.
async fn stream(c: &mut Client, until: usize) -> bool {
    while c.done < until {
        let Some(socket) = c.socket.as_mut() else {
            return false;
        };
        let end = (c.done + BATCH).min(until);
        let frame: Vec<Value> = (c.done..end)
            .map(|k| json!({"t": k as f64, "z": [c.z[k]]}))
            .collect();
        if socket
            .send(Message::Text(Value::from(frame).to_string().into()))
            .await
            .is_err()
        {
            c.socket = None;
            return false;
        }
        let mut answered = c.done;
        while answered < end {
            match tokio::time::timeout(Duration::from_secs(10), socket.next()).await {
                Ok(Some(Ok(Message::Text(t)))) => {
                    let v: Value = serde_json::from_str(&t).unwrap();
                    match v["type"].as_str() {
                        Some("result") => answered = v["t"].as_f64().unwrap() as usize + 1,
                        Some("error") => panic!("{}: {v}", c.id),
                        _ => {}
                    }
                }
                Ok(Some(Ok(Message::Close(_)))) | Ok(None) | Ok(Some(Err(_))) => {
                    c.socket = None;
                    return false;
                }
                Ok(Some(Ok(_))) => {}
                Err(_) => panic!("{}: no result within 10 s", c.id),
            }
        }
        c.done = end;
    }
    true
}

/// Streams every client to `until`, reconnecting (resume) any whose socket closes; the
/// reconnection times.
async fn stream_all(lb_ws: &str, clients: &mut [Client], until: usize) -> Vec<Duration> {
    let tasks: Vec<_> = clients
        .iter_mut()
        .map(|c| async move {
            let mut reconnects = Vec::new();
            loop {
                if c.socket.is_none() {
                    reconnects.push(connect(lb_ws, c, Duration::from_secs(20)).await);
                }
                if stream(c, until).await {
                    return reconnects;
                }
            }
        })
        .collect();
    futures_util::future::join_all(tasks)
        .await
        .into_iter()
        .flatten()
        .collect()
}

/// The alarm log of `session` as (epoch, state, severity), oldest first, read until it
/// holds at least `expected` entries or 20 s have passed.
async fn alarm_log(lb: &str, session: &str, expected: usize) -> Vec<(usize, String, String)> {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let log: Value = get_json(&format!("{lb}/api/v1/alarms?session={session}&limit=1000"))
            .await
            .1;
        let mut got: Vec<(usize, String, String)> = log["alarms"]
            .as_array()
            .unwrap()
            .iter()
            .map(|a| {
                (
                    a["t"].as_f64().unwrap() as usize,
                    a["state"].as_str().unwrap().to_owned(),
                    a["severity"].as_str().unwrap().to_owned(),
                )
            })
            .collect();
        got.reverse();
        if got.len() >= expected || Instant::now() >= deadline {
            return got;
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// Reads `socket` until it is idle for `quiet`, returning the alarm ids seen.
async fn alarms_seen(sockets: &mut [Socket], quiet: Duration) -> Vec<i64> {
    let mut ids = Vec::new();
    for socket in sockets {
        while let Ok(Some(Ok(msg))) = tokio::time::timeout(quiet, socket.next()).await {
            if let Message::Text(t) = msg {
                let v: Value = serde_json::from_str(&t).unwrap();
                if v["type"] == "alarm" {
                    ids.push(v["id"].as_i64().unwrap());
                }
            }
        }
    }
    ids
}

/// How a socket ended: the text messages it received, the server's Close frame (code and
/// reason; `None` when the connection ended without one, which a client reports as 1006)
/// and whether the connection then ended cleanly rather than with an error.
#[derive(Debug)]
struct Ending {
    texts: Vec<Value>,
    close: Option<(u16, String)>,
    clean: bool,
}

/// Reads `socket` until the connection ends (at most 30 s).
async fn until_closed(mut socket: Socket) -> Ending {
    let mut ending = Ending {
        texts: Vec::new(),
        close: None,
        clean: false,
    };
    let read = async {
        loop {
            match socket.next().await {
                Some(Ok(Message::Text(t))) => ending.texts.push(serde_json::from_str(&t).unwrap()),
                Some(Ok(Message::Close(frame))) => {
                    ending.close = frame.map(|f| (u16::from(f.code), f.reason.to_string()));
                }
                Some(Ok(_)) => {}
                Some(Err(_)) => return,
                None => {
                    ending.clean = true;
                    return;
                }
            }
        }
    };
    let ended = tokio::time::timeout(Duration::from_secs(30), read).await;
    assert!(
        ended.is_ok(),
        "the socket did not end within 30 s: {ending:?}"
    );
    ending
}

/// Closes `socket` with 1000 as a client does when it is done, and reads how it ends.
async fn close_as_client(mut socket: Socket) -> Ending {
    let frame = CloseFrame {
        code: CloseCode::Normal,
        reason: "done".into(),
    };
    socket
        .close(Some(frame))
        .await
        .expect("the Close frame is sent");
    until_closed(socket).await
}

/// An events socket through the load balancer, after its first `stats`; and the node
/// that took it (HAProxy's `X-Navguard-Node`).
async fn open_events(lb_ws: &str, id: &str) -> (Socket, String) {
    let (mut socket, response) =
        tokio_tungstenite::connect_async(format!("{lb_ws}/api/v1/sessions/{id}/events"))
            .await
            .unwrap();
    let node = response.headers()["x-navguard-node"]
        .to_str()
        .unwrap()
        .to_owned();
    match tokio::time::timeout(Duration::from_secs(10), socket.next()).await {
        Ok(Some(Ok(Message::Text(t)))) => {
            let v: Value = serde_json::from_str(&t).unwrap();
            assert_eq!(v["type"], "stats", "{v}");
        }
        other => panic!("{id}: no first stats on the events socket: {other:?}"),
    }
    (socket, node)
}

/// An id no genuine alarm has (the log's ids count up from 1).
const FORGED_ID: i64 = 987_654_321;

/// Publishes on NATS what an outsider with the nodes' NATS login (but without the cluster
/// key) could: for each session, an `alarm` with epoch 1 and seq 1 and 2 and no MAC, the
/// same with a made-up MAC, and an end-of-session message; the number of messages sent.
async fn forge_events(cluster: &Cluster, sessions: &[String]) -> u64 {
    let anonymous = async_nats::ConnectOptions::new()
        .add_root_certificates(PathBuf::from(cluster.url("TLS_CA")))
        .require_tls(true)
        .connect(cluster.url("NATS_URL"))
        .await;
    assert!(anonymous.is_err(), "NATS refuses a client without a login");
    let password =
        std::fs::read_to_string(cluster.url("NATS_PASSWORD_FILE")).expect("the NATS password");
    let nats = async_nats::ConnectOptions::new()
        .user_and_password(cluster.url("NATS_USER"), password.trim().to_owned())
        .add_root_certificates(PathBuf::from(cluster.url("TLS_CA")))
        .require_tls(true)
        .connect(cluster.url("NATS_URL"))
        .await
        .expect("the outsider reaches NATS with the nodes' login");
    let mut sent = 0;
    for id in sessions {
        let subject = format!("navguard.events.{id}");
        for (seq, mac) in [(1, None), (2, None), (3, Some("00".repeat(32)))] {
            let mut headers = async_nats::HeaderMap::new();
            headers.insert("Navguard-Epoch", "1");
            headers.insert("Navguard-Seq", seq.to_string().as_str());
            if let Some(mac) = &mac {
                headers.insert("Navguard-Sender", "node1");
                headers.insert("Navguard-Mac", mac.as_str());
            }
            let alarm = json!({"type": "alarm", "id": FORGED_ID, "session": id,
                "severity": "alarm", "state": "isolated", "t": 1.0});
            nats.publish_with_headers(subject.clone(), headers, alarm.to_string().into())
                .await
                .unwrap();
            sent += 1;
        }
        let mut end = async_nats::HeaderMap::new();
        end.insert("Navguard-End", "deleted");
        nats.publish_with_headers(subject, end, "{}".into())
            .await
            .unwrap();
        sent += 1;
    }
    nats.flush().await.unwrap();
    sent
}

/// The cluster's Postgres takes the nodes' URL (TLS, verify-full, a password), and
/// refuses the same login without TLS, and the same user without the password.
async fn postgres_needs_tls_and_the_password(url: &str) {
    use sqlx::Connection;
    assert!(
        url.contains("sslmode=verify-full") && url.contains("sslrootcert="),
        "the nodes' store URL asks for verified TLS"
    );
    sqlx::PgConnection::connect(url)
        .await
        .expect("the nodes' URL logs in")
        .close()
        .await
        .unwrap();
    let plain = url.replace("sslmode=verify-full", "sslmode=disable");
    assert!(
        sqlx::PgConnection::connect(&plain).await.is_err(),
        "a login without TLS is refused"
    );
    let (user, rest) = url.split_once(':').unwrap().1.split_once('@').unwrap();
    let user = user.split_once(':').map_or(user, |(u, _)| u);
    let no_password = format!("postgres:{user}@{rest}");
    assert!(
        sqlx::PgConnection::connect(&no_password).await.is_err(),
        "a login without the password is refused"
    );
}

/// A counter's value in a node's `/metrics`.
async fn metric(node_url: &str, name: &str) -> u64 {
    let text = reqwest::get(format!("{node_url}/metrics"))
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    text.lines()
        .find_map(|l| l.strip_prefix(name)?.trim().parse().ok())
        .unwrap_or_else(|| panic!("no {name} in {node_url}/metrics"))
}

/// A nats-server this test started; killed (by its pid) on drop if still running.
struct HandStarted(std::process::Child);

impl Drop for HandStarted {
    fn drop(&mut self) {
        if self.0.try_wait().ok().flatten().is_none() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

/// The port of a `scheme://host:port` URL.
fn port_of(url: &str) -> u16 {
    url.rsplit(':')
        .next()
        .unwrap()
        .trim_end_matches('/')
        .parse()
        .unwrap()
}

// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cluster_survives_a_killed_node_and_a_drain_without_losing_or_repeating_an_alarm() {
    let missing = engines_missing();
    if !missing.is_empty() {
        let required = std::env::var("NAVGUARD_CLUSTER_TEST").is_ok_and(|v| v == "1");
        let message = format!(
            "cluster test skipped: {} not installed (Debian: apt-get install postgresql nats-server haproxy openssl; .ci/run installs them and sets NAVGUARD_CLUSTER_TEST=1)",
            missing.join(", ")
        );
        assert!(!required, "{message}");
        eprintln!("{message}");
        return;
    }
    let cluster = start_cluster();
    postgres_needs_tls_and_the_password(&cluster.url("PG_URL")).await;
    let lb = cluster.url("LB_URL");
    let lb_ws = lb.replace("http://", "ws://");
    let http = reqwest::Client::new();
    let model = CvModel {
        q: 0.01,
        sigma: 1.0,
        p0: 1.0,
    };
    // Each phase has a fault (a 30-sigma step for 8 epochs) near its end, so alarms are
    // raised right before the kill and the drain, likely after the last checkpoint.
    let faulty = |k: usize| {
        let in_phase = k % PHASE;
        if (PHASE - 30..PHASE - 22).contains(&in_phase) {
            30.0
        } else {
            0.0
        }
    };
    let mut clients = Vec::new();
    let mut expected = BTreeMap::new();
    for s in 0..SESSIONS {
        let id = format!("c{s:02}");
        let z = model.measurements(3 * PHASE, 1000 + s as u64, faulty);
        expected.insert(id.clone(), reference(&model, &z));
        let body = cv_session(&id, &model, json!({"kind": "classic"}), json!({}), true);
        let resp = http
            .post(format!("{lb}/api/v1/sessions"))
            .json(&body)
            .send()
            .await
            .unwrap();
        assert_eq!(resp.status(), 201, "{}", resp.text().await.unwrap());
        clients.push(Client {
            id,
            z,
            done: 0,
            socket: None,
            node: String::new(),
        });
    }
    for c in &mut clients {
        connect(&lb_ws, c, Duration::from_secs(20)).await;
    }
    let owners = |clients: &[Client]| -> BTreeMap<String, Vec<String>> {
        let mut by_node: BTreeMap<String, Vec<String>> = BTreeMap::new();
        for c in clients {
            by_node
                .entry(c.node.clone())
                .or_default()
                .push(c.id.clone());
        }
        by_node
    };
    let placed = owners(&clients);
    assert_eq!(
        placed.len(),
        3,
        "the load balancer spreads 30 sessions over the 3 nodes: {placed:?}"
    );
    // An events socket on node1 for every session the other nodes own.
    let node1_ws = cluster.node_url("node1").replace("http://", "ws://");
    let watched: Vec<String> = clients
        .iter()
        .filter(|c| c.node != "node1")
        .map(|c| c.id.clone())
        .collect();
    let mut observers = Vec::new();
    for id in &watched {
        let (socket, _) =
            tokio_tungstenite::connect_async(format!("{node1_ws}/api/v1/sessions/{id}/events"))
                .await
                .unwrap();
        observers.push(socket);
    }
    // Forged events on every watched session's subject, once node1 subscribed (its first
    // `stats` follows the subscription): dropped.
    for (socket, id) in observers.iter_mut().zip(&watched) {
        match tokio::time::timeout(Duration::from_secs(10), socket.next()).await {
            Ok(Some(Ok(Message::Text(t)))) => assert!(t.contains("\"stats\""), "{id}: {t}"),
            other => panic!("{id}: no first stats on node1's events socket: {other:?}"),
        }
    }
    let forged = forge_events(&cluster, &watched).await;
    let deadline = Instant::now() + Duration::from_secs(5);
    while metric(&cluster.node_url("node1"), "navguard_bus_rejected_total").await < forged {
        assert!(
            Instant::now() < deadline,
            "node1 did not count the {forged} forged messages within 5 s"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }

    // Phase 1, then kill -9 the node with the most sessions at once.
    let reconnects = stream_all(&lb_ws, &mut clients, PHASE).await;
    assert!(reconnects.is_empty(), "nobody reconnects before the kill");
    let (victim, victims) = placed
        .iter()
        .filter(|(n, _)| *n != "node1")
        .max_by_key(|(_, v)| v.len())
        .map(|(n, v)| (n.clone(), v.clone()))
        .unwrap();
    let k = victim.trim_start_matches("node");
    cluster.script(&["kill", k]);
    let killed_at = Instant::now();

    // Phase 2: the victim's clients find their sessions on another node.
    let reconnects = stream_all(&lb_ws, &mut clients, 2 * PHASE).await;
    assert_eq!(
        reconnects.len(),
        victims.len(),
        "each session of {victim} reconnects once: {reconnects:?}\n{}",
        cluster.logs()
    );
    let limit = Duration::from_millis(LEASE_MS) + Duration::from_secs(2);
    let worst = reconnects.iter().max().unwrap();
    eprintln!(
        "resume after kill -9 of {victim} ({} sessions): worst {worst:?}, all {reconnects:?}; {:?} since the kill",
        victims.len(),
        killed_at.elapsed()
    );
    assert!(
        *worst <= limit,
        "a session resumed after {worst:?} (limit {limit:?})"
    );
    for c in clients.iter().filter(|c| victims.contains(&c.id)) {
        assert_ne!(c.node, victim, "{} resumed on a live node", c.id);
    }

    // A PUT sent to a node that does not own the session reaches the live session.
    let target = clients.iter().find(|c| c.node != "node1").unwrap();
    let (target_id, target_node) = (target.id.clone(), target.node.clone());
    let resp = http
        .put(format!(
            "{}/api/v1/sessions/{target_id}/monitors/cv/threshold",
            cluster.node_url("node1")
        ))
        .header("x-navguard-reason", "raised after a false alarm — café")
        .json(&json!({"p_fa": 0.0005}))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 200, "{}", resp.text().await.unwrap());
    // The owner wrote the audit entry once, with the reason and the caller's address that
    // travelled with the forwarded request.
    let audit: Value = get_json(&format!(
        "{}/api/v1/audit?session={target_id}",
        cluster.node_url(&target_node)
    ))
    .await
    .1;
    let puts: Vec<&Value> = audit["entries"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["method"] == "PUT")
        .collect();
    assert_eq!(puts.len(), 1, "{audit}");
    assert_eq!(
        puts[0]["reason"], "raised after a false alarm — café",
        "{audit}"
    );
    assert!(
        puts[0]["forwarded_for"]
            .as_str()
            .is_some_and(|f| f.ends_with("127.0.0.1")),
        "{audit}"
    );
    let owner_view: Value = get_json(&format!(
        "{}/api/v1/sessions/{target_id}/monitors/cv/threshold",
        cluster.node_url(&target_node)
    ))
    .await
    .1;
    assert_eq!(owner_view["p_fa"], 0.0005, "{owner_view}");
    let threshold = owner_view["tests"]["residual"]["threshold"]
        .as_f64()
        .unwrap();
    let live: Value = get_json(&format!(
        "{}/api/v1/sessions/{target_id}/stats",
        cluster.node_url(&target_node)
    ))
    .await
    .1;
    assert_eq!(
        live["monitors"]["cv"]["tests"]["residual"]["threshold"].as_f64(),
        Some(threshold),
        "{live}"
    );
    // The target's reference from here on uses the new threshold: recompute its tail.
    // (The rest of the check compares entries up to the PUT for it.)
    let put_at = clients.iter().find(|c| c.id == target_id).unwrap().done;

    // Drain one of the nodes still running (not node1, which holds the observers).
    let drained = ["node2", "node3"]
        .into_iter()
        .find(|n| *n != victim)
        .unwrap()
        .to_owned();
    let moving: Vec<String> = clients
        .iter()
        .filter(|c| c.node == drained)
        .map(|c| c.id.clone())
        .collect();
    // Every client of the drained node is connected through the load balancer, and is read
    // while the node drains: the node hands its session over while the load balancer still
    // relays the socket, so the client is told `moved`, with the last epoch the session
    // took, and the socket closes cleanly with 1000. An events socket the load balancer
    // sent to the drained node is closed cleanly with 1001.
    let readers: Vec<_> = clients
        .iter_mut()
        .filter(|c| c.node == drained)
        .map(|c| {
            let socket = c.socket.take().expect("connected before the drain");
            let (id, last_t) = (c.id.clone(), c.done as f64 - 1.0);
            tokio::spawn(async move { (id, last_t, until_closed(socket).await) })
        })
        .collect();
    let (observer, observed_on) = open_events(&lb_ws, &moving[0]).await;
    assert_eq!(
        observed_on, drained,
        "{} hashes to the drained node",
        moving[0]
    );
    let observer = tokio::spawn(until_closed(observer));
    let out = tokio::task::block_in_place(|| {
        cluster.script(&["drain", drained.trim_start_matches("node")])
    });
    eprintln!(
        "drain of {drained} ({} sessions): {}",
        moving.len(),
        out.trim()
    );
    for reader in readers {
        let (id, last_t, ending) = reader.await.unwrap();
        let moved = ending.texts.iter().find(|v| v["type"] == "moved");
        let moved = moved.unwrap_or_else(|| {
            panic!(
                "{id}: no `moved` through the load balancer: {ending:?}\n{}",
                cluster.logs()
            )
        });
        assert_eq!(moved["session"], id.as_str(), "{moved}");
        assert_eq!(moved["resume"]["t"].as_f64(), Some(last_t), "{id}: {moved}");
        assert_eq!(
            (ending.close.clone(), ending.clean),
            (Some((1000, "stream detached".to_owned())), true),
            "{id}: how the drained node's ingest socket ended: {ending:?}"
        );
    }
    let ending = observer.await.unwrap();
    assert_eq!(
        (ending.close.as_ref().map(|c| c.0), ending.clean),
        (Some(1001), true),
        "the events socket on the drained node: {ending:?}"
    );
    let reconnects = stream_all(&lb_ws, &mut clients, 3 * PHASE).await;
    assert_eq!(
        reconnects.len(),
        moving.len(),
        "each session of the drained node reconnects once\n{}",
        cluster.logs()
    );
    for c in clients.iter().filter(|c| moving.contains(&c.id)) {
        assert_eq!(c.node, "node1", "{} moved to the last node", c.id);
    }

    // The log holds exactly the reference entries, each once. A client's last `result`
    // frame does not wait for the alarm writes of its epochs (an alarm reaches the log
    // before its event, not before the epoch's result), so a loaded machine may still be
    // committing the last ones: the log is read until it holds as many entries as the
    // reference, for at most 20 s, and then compared.
    for c in &clients {
        let want: Vec<(usize, String, String)> = expected[&c.id]
            .entries
            .iter()
            .map(|(k, h, s)| (*k, h.as_str().to_owned(), (*s).to_owned()))
            .collect();
        // The PUT's target decides differently after it: only its earlier entries count.
        let settled = if c.id == target_id {
            want.iter().filter(|e| e.0 < put_at).count()
        } else {
            want.len()
        };
        let got = alarm_log(&lb, &c.id, settled).await;
        if c.id == target_id {
            // After the PUT the threshold is higher: compare what came before it.
            let before = |v: &Vec<(usize, String, String)>| -> Vec<(usize, String, String)> {
                v.iter().filter(|e| e.0 < put_at).cloned().collect()
            };
            assert_eq!(
                before(&got),
                before(&want),
                "{}: entries before the PUT",
                c.id
            );
        } else {
            assert_eq!(
                got,
                want,
                "{}: the log against an uninterrupted monitor\n{}",
                c.id,
                cluster.logs()
            );
        }
        // The statistics carried across the failover and the drain too (the PUT's
        // target decides, and so filters, differently after its threshold change).
        if c.id == target_id {
            continue;
        }
        let stats: Value = get_json(&format!("{lb}/api/v1/sessions/{}/stats", c.id))
            .await
            .1;
        let residual = &stats["monitors"]["cv"]["tests"]["residual"];
        let r = &expected[&c.id];
        assert_eq!(
            residual["epochs"].as_u64(),
            Some(r.epochs),
            "{}: {residual}",
            c.id
        );
        assert_eq!(
            residual["max"].as_f64(),
            Some(r.max),
            "{}: {residual}",
            c.id
        );
        let mean = residual["mean"].as_f64().unwrap();
        assert!(
            (mean - r.mean).abs() <= 1e-12 * r.mean.abs(),
            "{}: mean {mean} against {} uninterrupted",
            c.id,
            r.mean
        );
        assert!(
            want.iter().filter(|e| e.2 == "alarm").count() >= 3,
            "{}: the scenario raises an alarm in every phase",
            c.id
        );
    }

    // node1's observers saw the alarms of the sessions the other nodes owned, and none of
    // the forged ones (nor closed on the forged end).
    let seen = alarms_seen(&mut observers, Duration::from_millis(500)).await;
    assert!(
        !seen.contains(&FORGED_ID),
        "a forged alarm reached an events socket"
    );
    for id in &watched {
        let log: Value = get_json(&format!(
            "{lb}/api/v1/alarms?session={id}&severity=alarm&limit=1000"
        ))
        .await
        .1;
        for a in log["alarms"].as_array().unwrap() {
            let aid = a["id"].as_i64().unwrap();
            assert!(
                seen.contains(&aid),
                "{id}: alarm {aid} not seen on node1's events socket"
            );
        }
    }

    // Deleting a session (through the load balancer, on whichever node owns it) ends its
    // events socket on node1 as a local one ends: close 1008.
    let resp = http
        .delete(format!("{lb}/api/v1/sessions/{}", watched[0]))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 204);
    let closed = tokio::time::timeout(Duration::from_secs(5), async {
        while let Some(Ok(msg)) = observers[0].next().await {
            if let Message::Close(frame) = msg {
                return frame.map(|f| u16::from(f.code));
            }
        }
        None
    })
    .await
    .expect("the observer of a deleted session is closed within 5 s");
    assert_eq!(closed, Some(1008));

    // A client that closes with 1000 through the load balancer gets its Close answered
    // with 1000 and a clean end, on the ingest socket and on the events socket.
    let client = clients.iter_mut().find(|c| c.id != watched[0]).unwrap();
    let ending = close_as_client(client.socket.take().expect("still connected")).await;
    assert_eq!(
        (ending.close.map(|c| c.0), ending.clean),
        (Some(1000), true),
        "{}: the ingest socket closed by its client",
        client.id
    );
    let (events, _) = open_events(&lb_ws, &client.id).await;
    let ending = close_as_client(events).await;
    assert_eq!(
        (ending.close.map(|c| c.0), ending.clean),
        (Some(1000), true),
        "the events socket closed by its client"
    );

    // NATS restarted by hand: `status` reports the new process and `stop` stops it.
    let pid_file = cluster.dir.path().join("run/nats.pid");
    let old_pid = std::fs::read_to_string(&pid_file)
        .unwrap()
        .trim()
        .to_owned();
    // HAProxy's TLS frontend answers with the test CA's certificate for 127.0.0.1.
    let tls_health = Command::new("curl")
        .args(["-sS", "-o", "/dev/null", "-w", "%{http_code}", "--cacert"])
        .arg(cluster.url("TLS_CA"))
        .arg(format!("{}/healthz", cluster.url("LB_TLS_URL")))
        .output()
        .unwrap();
    assert_eq!(
        String::from_utf8_lossy(&tls_health.stdout),
        "200",
        "GET /healthz over TLS through HAProxy: {}",
        String::from_utf8_lossy(&tls_health.stderr)
    );

    let killed = Command::new("kill").arg(&old_pid).status().unwrap();
    assert!(killed.success(), "kill {old_pid}");
    let nats_port = port_of(&cluster.url("NATS_URL"));
    let monitor = cluster.url("NATS_MONITOR_URL");
    let deadline = Instant::now() + Duration::from_secs(10);
    while tokio::net::TcpStream::connect(("127.0.0.1", nats_port))
        .await
        .is_ok()
    {
        assert!(
            Instant::now() < deadline,
            "NATS (pid {old_pid}) still listens 10 s after SIGTERM"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let log = std::fs::File::create(cluster.dir.path().join("nats-by-hand.log")).unwrap();
    let mut nats = HandStarted(
        Command::new("nats-server")
            .args(["-c", &cluster.url("NATS_CONF")])
            .args(["-a", "127.0.0.1", "-p", &nats_port.to_string()])
            .args(["-m", &port_of(&monitor).to_string(), "-n", "navguard-nats"])
            .stdout(log.try_clone().unwrap())
            .stderr(log)
            .spawn()
            .expect("nats-server starts"),
    );
    let new_pid = nats.0.id();
    let deadline = Instant::now() + Duration::from_secs(10);
    while http_status(&format!("{monitor}/healthz")).await != Some(200) {
        assert!(
            Instant::now() < deadline,
            "the restarted NATS is not up within 10 s"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let (_, status) = cluster.run_script(&["status"]);
    let line = status
        .lines()
        .find(|l| l.starts_with("nats "))
        .unwrap_or_else(|| panic!("no nats line in:\n{status}"));
    let words: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(
        words[..4],
        ["nats", "up", "pid", new_pid.to_string().as_str()],
        "status after NATS was restarted by hand:\n{status}"
    );
    let out = tokio::task::block_in_place(|| cluster.script(&["stop"]));
    let deadline = Instant::now() + Duration::from_secs(10);
    while nats.0.try_wait().unwrap().is_none() {
        assert!(
            Instant::now() < deadline,
            "stop left the NATS restarted by hand (pid {new_pid}) running:\n{out}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// The status of a GET, or `None` when nothing answers.
async fn http_status(url: &str) -> Option<u16> {
    reqwest::get(url).await.ok().map(|r| r.status().as_u16())
}
