//! Reliability of a session's writes: a frame refused by one monitor still commits and
//! announces what the others did with it; threshold, policy and delete changes are
//! stored in the order they were acknowledged (checked across restarts); a heavy session
//! cannot stall the runtime or another session.

mod common;

use std::collections::BTreeMap;

use common::*;
use navguard::service::Limits;
use serde_json::{Value, json};

/// A 1-D random walk seen directly, with measurement variance `r`.
fn walk(name: &str, r: f64) -> Value {
    json!({
        "name": name, "type": "linear",
        "config": {"f": [[1.0]], "h": [[1.0]], "q": [[1.0]], "r": [[r]], "x0": [0.0], "p0": [[1.0]]},
        "policy": {"kind": "counters", "n1": 10, "n2": 5},
        "threshold": 20.0
    })
}

/// The frames: z = 0 three times, 1e152 five times, 1e200, 1e152 three times.
/// With r = 1e300 the first monitor's λ stays finite throughout (1e4, then 1e100); with
/// r = 1 the second monitor's λ overflows at 1e200 and that epoch fails for it alone.
fn issue_zs() -> Vec<f64> {
    let mut z = vec![0.0; 3];
    z.extend([1e152; 5]);
    z.push(1e200);
    z.extend([1e152; 3]);
    z
}

/// Every `state` and `alarm` message on the socket until `epochs` results and the
/// expected errors have arrived.
async fn drain(socket: &mut Socket, results: usize, errors: usize) -> Vec<Value> {
    let mut seen = Vec::new();
    let (mut r, mut e) = (0, 0);
    while r < results || e < errors {
        let v = recv(socket).await;
        match v["type"].as_str() {
            Some("result") => r += 1,
            Some("error") => e += 1,
            _ => {}
        }
        seen.push(v);
    }
    seen
}

/// Each test's `state` messages chain (`from` = the previous `to`, from healthy), and
/// the alarms the stats count equal those stored.
async fn assert_consistent(server: &navguard::service::Server, id: &str, messages: &[Value]) {
    let mut last: BTreeMap<(String, String), String> = BTreeMap::new();
    for m in messages.iter().filter(|m| m["type"] == "state") {
        let key = (
            m["monitor"].as_str().unwrap().to_owned(),
            m["test"].as_str().unwrap().to_owned(),
        );
        let prev = last.get(&key).cloned().unwrap_or_else(|| "healthy".into());
        assert_eq!(m["from"].as_str().unwrap(), prev, "{m} after {prev}");
        last.insert(key, m["to"].as_str().unwrap().to_owned());
    }
    let (_, stats) = get_json(&format!("{}/api/v1/sessions/{id}/stats", http(server))).await;
    let (_, log) = get_json(&format!(
        "{}/api/v1/alarms?session={id}&severity=alarm&limit=1000",
        http(server)
    ))
    .await;
    let stored = log["alarms"].as_array().unwrap();
    for (monitor, m) in stats["monitors"].as_object().unwrap() {
        for (test, t) in m["tests"].as_object().unwrap() {
            let n = stored
                .iter()
                .filter(|a| a["monitor"] == monitor.as_str() && a["test"] == test.as_str())
                .count();
            assert_eq!(
                t["alarms"].as_u64().unwrap() as usize,
                n,
                "{monitor}/{test}: {t}"
            );
            if let Some(to) = last.get(&(monitor.clone(), test.clone())) {
                assert_eq!(
                    t["state"].as_str().unwrap(),
                    to,
                    "{monitor}/{test}: stats state"
                );
            }
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_epoch_refused_by_one_monitor_commits_and_announces_what_the_others_did() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("a.db"), None, Limits::default()).await;
    for (id, batched) in [("one-by-one", false), ("batched", true)] {
        let body =
            json!({"id": id, "echo": true, "monitors": [walk("wide", 1e300), walk("narrow", 1.0)]});
        create_session(&client(), &server, &body).await;
        let mut socket = ingest(&server, id).await;
        let frames: Vec<Value> = issue_zs()
            .iter()
            .enumerate()
            .map(|(k, z)| json!({"t": k as f64, "z": [z]}))
            .collect();
        let messages = if batched {
            // One frame: epochs 0..=8 are taken (epoch 8 by `wide` only), then the
            // frame stops; the last three epochs come as a second frame.
            send(&mut socket, &Value::Array(frames[..9].to_vec())).await;
            let mut m = drain(&mut socket, 9, 1).await;
            send(&mut socket, &Value::Array(frames[9..].to_vec())).await;
            m.extend(drain(&mut socket, 3, 0).await);
            m
        } else {
            let mut m = Vec::new();
            for (k, f) in frames.iter().enumerate() {
                send(&mut socket, f).await;
                m.extend(drain(&mut socket, 1, usize::from(k == 8)).await);
            }
            m
        };
        // `wide` reaches isolated on epoch 8, the one `narrow` could not process: the
        // change is announced and stored, with its alarm.
        let wide: Vec<(&str, &str, f64)> = messages
            .iter()
            .filter(|m| m["type"] == "state" && m["monitor"] == "wide")
            .map(|m| {
                (
                    m["from"].as_str().unwrap(),
                    m["to"].as_str().unwrap(),
                    m["t"].as_f64().unwrap(),
                )
            })
            .collect();
        assert_eq!(
            wide,
            vec![("healthy", "suspect", 3.0), ("suspect", "isolated", 8.0)],
            "{id}"
        );
        let error = messages.iter().find(|m| m["type"] == "error").unwrap();
        assert_eq!(error["code"], "numerical");
        assert_eq!(error["index"], if batched { 8 } else { 0 });
        assert!(
            error["message"].as_str().unwrap().contains("'narrow'"),
            "{error}"
        );
        // The epoch's result carries the monitor that took it, not the one that failed.
        let result8 = messages
            .iter()
            .find(|m| m["type"] == "result" && m["t"] == 8.0)
            .unwrap();
        assert!(
            result8["monitors"].get("wide").is_some()
                && result8["monitors"].get("narrow").is_none()
        );
        assert_consistent(&server, id, &messages).await;
        let (_, stats) = get_json(&format!("{}/api/v1/sessions/{id}/stats", http(&server))).await;
        assert_eq!(stats["monitors"]["wide"]["epochs"], 12);
        assert_eq!(
            stats["monitors"]["narrow"]["epochs"], 11,
            "narrow missed epoch 8"
        );
    }
    server.shutdown().await;
}

// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_changes_are_stored_in_the_order_acknowledged_across_restarts() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("r.db");
    let server = start(&db, None, Limits::default()).await;
    let base = http(&server);
    let c = client();
    // (a) 8 concurrent PUTs on different monitors of one session, 10 sessions.
    let names: Vec<String> = (0..8).map(|i| format!("m{i}")).collect();
    for s in 0..10 {
        let monitors: Vec<Value> = names.iter().map(|n| walk(n, 1.0)).collect();
        create_session(
            &c,
            &server,
            &json!({"id": format!("a{s}"), "monitors": monitors}),
        )
        .await;
    }
    let mut puts = Vec::new();
    for s in 0..10 {
        for (i, n) in names.iter().enumerate() {
            let url = format!("{base}/api/v1/sessions/a{s}/monitors/{n}/threshold");
            let c = c.clone();
            puts.push(tokio::spawn(async move {
                c.put(url)
                    .json(&json!({"threshold": 30.0 + i as f64}))
                    .send()
                    .await
                    .unwrap()
                    .status()
            }));
        }
    }
    // (b) 10 concurrent PUTs on one monitor, 10 sessions: what is in force at the end.
    for s in 0..10 {
        create_session(
            &c,
            &server,
            &json!({"id": format!("b{s}"), "monitors": [walk("m", 1.0)]}),
        )
        .await;
    }
    for s in 0..10 {
        for k in 0..10 {
            let url = format!("{base}/api/v1/sessions/b{s}/monitors/m/threshold");
            let c = c.clone();
            puts.push(tokio::spawn(async move {
                c.put(url)
                    .json(&json!({"threshold": 40.0 + k as f64}))
                    .send()
                    .await
                    .unwrap()
                    .status()
            }));
        }
    }
    for p in puts {
        assert_eq!(p.await.unwrap(), 200);
    }
    let mut in_force = BTreeMap::new();
    for s in 0..10 {
        let (_, view) =
            get_json(&format!("{base}/api/v1/sessions/b{s}/monitors/m/threshold")).await;
        in_force.insert(s, view["threshold"].as_f64().unwrap());
    }
    // (c) DELETE racing a PUT, 20 sessions: a 204 is final.
    for s in 0..20 {
        create_session(
            &c,
            &server,
            &json!({"id": format!("c{s}"), "monitors": [walk("m", 1.0)]}),
        )
        .await;
    }
    let mut races = Vec::new();
    for s in 0..20 {
        let (c1, c2) = (c.clone(), c.clone());
        let put = format!("{base}/api/v1/sessions/c{s}/monitors/m/threshold");
        let del = format!("{base}/api/v1/sessions/c{s}");
        races.push(tokio::spawn(async move {
            let (p, d) = tokio::join!(
                async move {
                    c1.put(put)
                        .json(&json!({"threshold": 50.0}))
                        .send()
                        .await
                        .unwrap()
                        .status()
                },
                async move { c2.delete(del).send().await.unwrap().status() }
            );
            (s, p.as_u16(), d.as_u16())
        }));
    }
    let mut deleted = Vec::new();
    for r in races {
        let (s, put, del) = r.await.unwrap();
        assert!(matches!(put, 200 | 404), "PUT {put}");
        assert_eq!(del, 204);
        deleted.push(s);
    }

    server.shutdown().await;
    let server = start(&db, None, Limits::default()).await;
    let base = http(&server);
    for s in 0..10 {
        for (i, n) in names.iter().enumerate() {
            let (_, view) = get_json(&format!(
                "{base}/api/v1/sessions/a{s}/monitors/{n}/threshold"
            ))
            .await;
            assert_eq!(
                view["threshold"],
                30.0 + i as f64,
                "a{s}/{n} lost its change"
            );
        }
        let (_, view) =
            get_json(&format!("{base}/api/v1/sessions/b{s}/monitors/m/threshold")).await;
        assert_eq!(
            view["threshold"].as_f64().unwrap(),
            in_force[&s],
            "b{s}: stored ≠ in force"
        );
    }
    for s in deleted {
        let (status, _) = get_json(&format!("{base}/api/v1/sessions/c{s}")).await;
        assert_eq!(status, 404, "c{s} came back after a 204 DELETE");
    }
    server.shutdown().await;
}

/// A linear model of `n` states, all measured: each epoch costs O(n³).
fn heavy(n: usize) -> Value {
    let eye = |scale: f64| -> Vec<Vec<f64>> {
        (0..n)
            .map(|i| (0..n).map(|j| if i == j { scale } else { 0.0 }).collect())
            .collect()
    };
    json!({"id": "heavy", "echo": true, "monitors": [{
        "name": "big", "type": "linear",
        "config": {"f": eye(1.0), "h": eye(1.0), "q": eye(0.01), "r": eye(1.0),
                   "x0": vec![0.0; n], "p0": eye(1.0)},
    }]})
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_heavy_session_neither_stalls_the_runtime_nor_another_session() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("h.db"), None, Limits::default()).await;
    let c = client();
    // Over the dimension limit: refused before anything is built, naming the field.
    let resp = c
        .post(format!("{}/api/v1/sessions", http(&server)))
        .json(&heavy(129))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 413);
    let err: Value = resp.json().await.unwrap();
    assert!(
        err["error"]["message"]
            .as_str()
            .is_some_and(|m| m.contains("monitors[0].config.f")),
        "{err}"
    );

    // As many heavy sessions as the runtime has worker threads (two, as in the probe).
    let n = 128;
    let mut second = heavy(n);
    second["id"] = json!("heavy2");
    create_session(&c, &server, &heavy(n)).await;
    create_session(&c, &server, &second).await;
    create_session(
        &c,
        &server,
        &json!({"id": "light", "echo": true, "monitors": [walk("w", 1.0)]}),
    )
    .await;
    let mut heavy_socket = ingest(&server, "heavy").await;
    let mut heavy2_socket = ingest(&server, "heavy2").await;
    let mut light_socket = ingest(&server, "light").await;
    // The heavy sessions get batches that take many compute slices.
    let z: Vec<f64> = vec![0.5; n];
    let batch: Vec<Value> = (0..40).map(|k| json!({"t": k as f64, "z": z})).collect();
    send(&mut heavy2_socket, &Value::Array(batch.clone())).await;
    send(&mut heavy_socket, &Value::Array(batch)).await;
    // Wait until it is being processed (its first result arrived), then, while it
    // runs, the other session does 20 round trips and /healthz answers 10 times.
    let first = recv(&mut heavy_socket).await;
    assert_eq!(first["type"], "result");
    let mut light_done = 0;
    for k in 0..20 {
        send(&mut light_socket, &json!({"t": k as f64, "z": [0.0]})).await;
        let r = recv(&mut light_socket).await;
        assert_eq!(r["type"], "result");
        light_done += 1;
        if k % 2 == 0 {
            let (status, _) = get_json(&format!("{}/healthz", http(&server))).await;
            assert_eq!(status, 200);
        }
    }
    // Ordering, not timing: all of that finished while the heavy batch was still
    // being stepped (its last result had not been sent yet).
    let (_, stats) = get_json(&format!("{}/api/v1/sessions/heavy/stats", http(&server))).await;
    assert!(
        stats["epochs"].as_u64().unwrap() < 40,
        "the heavy batch had finished before the light session's round trips: {}",
        stats["epochs"]
    );
    assert_eq!(light_done, 20);
    let mut results = 1;
    while results < 40 {
        if recv(&mut heavy_socket).await["type"] == "result" {
            results += 1;
        }
    }
    server.shutdown().await;
}
