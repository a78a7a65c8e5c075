//! `kill -9` in the middle of alarms: the real binary as a child
//! process streams three recording sessions whose faults keep raising alarms; it is
//! killed five times at random moments (seeded) and restarted on the same database.
//! Every alarm announced on a socket must be in the log exactly once, the database must
//! open cleanly each time, and each recording must be a prefix of what was sent.

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::process::Stdio;
use std::time::Duration;

use common::*;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde_json::{Value, json};
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::{Child, Command};

const SESSIONS: [&str; 3] = ["k1", "k2", "k3"];
const KILLS: usize = 5;

/// The real binary on a free port; returns it and its base URL once it listens.
async fn spawn(db: &std::path::Path) -> (Child, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_navguard"))
        .args(["serve", "--bind", "127.0.0.1:0", "--db"])
        .arg(db)
        .env("RUST_LOG", "navguard=warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .kill_on_drop(true)
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let mut lines = BufReader::new(stdout).lines();
    let line = tokio::time::timeout(Duration::from_secs(30), lines.next_line())
        .await
        .expect("the server starts within 30 s (the database opened)")
        .unwrap()
        .unwrap();
    // "navguard listening on http://127.0.0.1:PORT (store: …)"
    let url = line
        .split_whitespace()
        .find(|w| w.starts_with("http://"))
        .unwrap()
        .to_owned();
    // Keep draining stdout so the child never blocks on a full pipe.
    tokio::spawn(async move { while let Ok(Some(_)) = lines.next_line().await {} });
    (child, url)
}

fn spec(id: &str) -> Value {
    json!({"id": id, "echo": true, "record": true, "monitors": [{
        "name": "w", "type": "linear",
        "config": {"f": [[1.0]], "h": [[1.0]], "q": [[1e-4]], "r": [[1.0]], "x0": [0.0], "p0": [[1.0]]},
        "policy": {"kind": "counters", "n1": 5, "n2": 2},
        "threshold": 20.0
    }]})
}

/// Epoch `k` of a session: noise, and a 30σ step on 20 of every 60 epochs (an alarm
/// each time, isolated after three exceedances).
fn epoch(g: &mut Gauss, k: u64) -> String {
    let fault = if k % 60 >= 40 { 30.0 } else { 0.0 };
    format!("{{\"t\": {k}, \"z\": [{}]}}", g.normal() + fault)
}

// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_announced_alarm_survives_five_kills_exactly_once() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("kill.db");
    let mut rng = StdRng::seed_from_u64(2026);
    let mut gauss: Vec<Gauss> = (0..3).map(|i| Gauss::new(100 + i)).collect();
    let mut t = [0u64; 3];
    // Per session and connection (cycle), the epochs sent, in order (to check the
    // recording, whose streams are the connections in order).
    let mut sent: BTreeMap<(String, usize), Vec<String>> = BTreeMap::new();
    let mut announced: BTreeMap<i64, Value> = BTreeMap::new();
    let (mut child, mut base) = spawn(&db).await;
    let client = reqwest::Client::new();
    for id in SESSIONS {
        let resp = client
            .post(format!("{base}/api/v1/sessions"))
            .json(&spec(id))
            .send()
            .await
            .unwrap();
        assert_eq!(resp.status(), 201);
    }
    for cycle in 0..=KILLS {
        let ws = base.replacen("http://", "ws://", 1);
        let mut sockets = Vec::new();
        for id in SESSIONS {
            let url = format!("{ws}/api/v1/sessions/{id}/ingest");
            let mut socket = None;
            for _ in 0..250 {
                if let Ok((mut s, _)) = tokio_tungstenite::connect_async(&url).await {
                    let ready = recv(&mut s).await;
                    assert_eq!(ready["type"], "ready");
                    socket = Some(s);
                    break;
                }
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
            sockets.push(socket.expect("ingest reconnects after a restart"));
        }
        // Stream until a random moment (the last cycle runs to its end and shuts down).
        let frames = if cycle < KILLS {
            rng.random_range(30..150)
        } else {
            120
        };
        'stream: for n in 0..frames {
            for (i, socket) in sockets.iter_mut().enumerate() {
                let text = epoch(&mut gauss[i], t[i]);
                t[i] += 1;
                send_text(socket, &text).await;
                sent.entry((SESSIONS[i].to_owned(), cycle))
                    .or_default()
                    .push(text);
                if cycle < KILLS && n == frames - 1 && i == 1 {
                    // Mid-cycle: kill -9 with frames in flight on some sockets.
                    break 'stream;
                }
                loop {
                    let v = recv(socket).await;
                    if v["type"] == "alarm" {
                        announced.insert(v["id"].as_i64().unwrap(), v.clone());
                    }
                    if v["type"] == "result" {
                        break;
                    }
                }
            }
        }
        if cycle < KILLS {
            child.start_kill().unwrap();
            child.wait().await.unwrap();
            drop(sockets);
            let (c, b) = spawn(&db).await;
            child = c;
            base = b;
        } else {
            drop(sockets);
        }
    }

    // Every announced alarm is in the log once, with what was announced.
    let mut log = BTreeMap::new();
    let mut before: Option<i64> = None;
    loop {
        let url = match before {
            Some(b) => format!("{base}/api/v1/alarms?severity=alarm&limit=1000&before={b}"),
            None => format!("{base}/api/v1/alarms?severity=alarm&limit=1000"),
        };
        let page: Value = client.get(url).send().await.unwrap().json().await.unwrap();
        for a in page["alarms"].as_array().unwrap() {
            assert!(
                log.insert(a["id"].as_i64().unwrap(), a.clone()).is_none(),
                "duplicate id"
            );
        }
        match page["next_before"].as_i64() {
            Some(b) => before = Some(b),
            None => break,
        }
    }
    assert!(
        announced.len() >= 10,
        "the faults raised alarms: {}",
        announced.len()
    );
    for (id, a) in &announced {
        let stored = log
            .get(id)
            .unwrap_or_else(|| panic!("announced alarm {id} not in the log"));
        for key in [
            "session",
            "monitor",
            "test",
            "state",
            "t",
            "statistic",
            "threshold",
            "severity",
        ] {
            assert_eq!(stored[key], a[key], "alarm {id}: {key}");
        }
    }
    let keys: BTreeSet<(String, String, String)> = log
        .values()
        .map(|a| {
            (
                a["session"].as_str().unwrap().to_owned(),
                a["t"].to_string(),
                a["raised_at_ms"].to_string(),
            )
        })
        .collect();
    assert_eq!(keys.len(), log.len(), "no alarm stored twice");

    // Each recorded stream is a prefix of what was sent on its connection.
    for id in SESSIONS {
        let index: Value = client
            .get(format!(
                "{base}/api/v1/sessions/{id}/recording?format=index"
            ))
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        let streams: Vec<u64> = index["streams"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["stream"].as_u64().unwrap())
            .collect();
        assert_eq!(
            streams.len(),
            KILLS + 1,
            "{id}: one recorded stream per connection: {index}"
        );
        for (cycle, stream) in streams.iter().enumerate() {
            let epochs = &sent[&(id.to_owned(), cycle)];
            let text = get_text(&format!(
                "{base}/api/v1/sessions/{id}/recording?stream={stream}"
            ))
            .await;
            let recorded: Vec<&str> = text.lines().collect();
            assert!(recorded.len() <= epochs.len(), "{id}/{cycle}");
            assert!(!recorded.is_empty(), "{id}/{cycle}: nothing recorded");
            for (r, s) in recorded.iter().zip(epochs) {
                assert_eq!(
                    r, s,
                    "{id}/{cycle}: the recording is a prefix of what was sent"
                );
            }
        }
    }

    // A clean shutdown (SIGINT), then the database's own integrity check.
    let pid = child.id().unwrap();
    let _ = Command::new("kill")
        .args(["-INT", &pid.to_string()])
        .status()
        .await;
    let _ = tokio::time::timeout(Duration::from_secs(20), child.wait()).await;
    let pool = sqlx::SqlitePool::connect(&format!("sqlite://{}", db.display()))
        .await
        .unwrap();
    let check: String = sqlx::query_scalar("PRAGMA integrity_check")
        .fetch_one(&pool)
        .await
        .unwrap();
    assert_eq!(check, "ok");
}
