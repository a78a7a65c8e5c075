//! The flight recorder (docs/architecture.md §A12): a recording session's frames and the
//! messages they caused are stored, streamed back in the replay format, and
//! `navguard replay` of them into a fresh session reproduces every result and alarm bit
//! for bit; retention keeps the newest frames within the limits; the 1 Hz history
//! serves the past of the charts.

mod common;

use common::*;
use navguard::service::store::Retention;
use navguard::service::{Limits, ServiceConfig};
use serde_json::{Value, json};

const MODEL: CvModel = CvModel {
    q: 0.01,
    sigma: 1.0,
    p0: 10.0,
};

/// The frames a client sends: 600 epochs with a 30σ step on 300..310, as single epochs
/// and batches, with the spellings a client may use (long decimals, exponents, spaces,
/// a line break inside a batch).
fn client_frames() -> Vec<String> {
    let z = MODEL.measurements(600, 5, |k| if (300..310).contains(&k) { 30.0 } else { 0.0 });
    let epoch = |k: usize| format!("{{\"t\": {}, \"z\": [{:.17e}]}}", k as f64 * 0.1, z[k]);
    let mut frames = Vec::new();
    let mut k = 0;
    while k < z.len() {
        if k % 7 == 0 && k + 5 <= z.len() {
            let batch: Vec<String> = (k..k + 5).map(epoch).collect();
            frames.push(format!(
                "[{},\n {}]",
                batch[..2].join(","),
                batch[2..].join(" , ")
            ));
            k += 5;
        } else {
            frames.push(epoch(k));
            k += 1;
        }
    }
    frames
}

fn spec(id: &str, record: bool) -> Value {
    let mut body = cv_session(
        id,
        &MODEL,
        json!({"kind": "counters", "n1": 10, "n2": 3}),
        json!({"p_fa": 1e-5}),
        true,
    );
    body["record"] = json!(record);
    body
}

/// Messages that depend on the session or the wall clock, not on the data.
fn without_identity(mut v: Value) -> Value {
    if let Some(o) = v.as_object_mut() {
        for key in ["id", "log_id", "session", "raised_at_ms"] {
            o.remove(key);
        }
    }
    v
}

// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_replayed_recording_reproduces_every_result_and_alarm_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("r.db"), None, Limits::default()).await;
    let base = http(&server);
    create_session(&client(), &server, &spec("orig", true)).await;
    let mut socket = ingest(&server, "orig").await;
    let frames = client_frames();
    let mut original = Vec::new();
    for f in &frames {
        send_text(&mut socket, f).await;
    }
    let mut results = 0;
    while results < 600 {
        let v = recv(&mut socket).await;
        if v["type"] == "result" {
            results += 1;
        }
        if matches!(v["type"].as_str(), Some("result" | "state" | "alarm")) {
            original.push(v);
        }
    }
    assert!(
        original.iter().any(|m| m["type"] == "alarm"),
        "the step raised an alarm"
    );

    // The recording: one epoch per line, each as sent.
    let resp = client()
        .get(format!("{base}/api/v1/sessions/orig/recording"))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 200);
    assert!(
        resp.headers()[reqwest::header::CONTENT_DISPOSITION]
            .to_str()
            .unwrap()
            .starts_with("attachment; filename=\"recording-orig-")
    );
    let text = resp.text().await.unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 600);
    // frames[0] is a batch of epochs 0..5; frames[1] is epoch 5 alone.
    assert_eq!(lines[5], frames[1], "a single epoch is kept byte for byte");
    let file = dir.path().join("orig.jsonl");
    std::fs::write(&file, &text).unwrap();

    // The events it caused, with their epoch index.
    let events = get_text(&format!(
        "{base}/api/v1/sessions/orig/recording?format=events"
    ))
    .await;
    let events: Vec<Value> = events
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let announced: Vec<&Value> = original.iter().filter(|m| m["type"] != "result").collect();
    assert_eq!(events.len(), announced.len());
    for (e, m) in events.iter().zip(&announced) {
        assert_eq!(&e["message"], *m);
        let t = m["t"].as_f64().unwrap();
        assert_eq!(
            e["epoch_index"].as_f64().unwrap(),
            (t * 10.0).round(),
            "{e}"
        );
    }

    // Replayed into a fresh session with the same spec by the real CLI.
    let spec_file = dir.path().join("copy.json");
    std::fs::write(&spec_file, spec("copy", false).to_string()).unwrap();
    let messages = dir.path().join("copy.messages");
    let status = tokio::process::Command::new(env!("CARGO_BIN_EXE_navguard"))
        .arg("replay")
        .arg(&file)
        .args([
            "--url",
            &ws(&server),
            "--session",
            "copy",
            "--quiet",
            "--batch",
            "37",
        ])
        .arg("--session-spec")
        .arg(&spec_file)
        .arg("--messages")
        .arg(&messages)
        .stdout(std::process::Stdio::null())
        .status()
        .await
        .unwrap();
    assert!(status.success());
    let replayed: Vec<Value> = std::fs::read_to_string(&messages)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let results = |m: &[Value]| -> Vec<String> {
        m.iter()
            .filter(|v| v["type"] == "result")
            .map(|v| v.to_string())
            .collect()
    };
    assert_eq!(
        results(&replayed),
        results(&original),
        "every result, bit for bit"
    );
    let announced = |m: &[Value]| -> Vec<Value> {
        m.iter()
            .filter(|v| v["type"] != "result")
            .cloned()
            .map(without_identity)
            .collect()
    };
    assert_eq!(
        announced(&replayed),
        announced(&original),
        "every state change and alarm"
    );
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn retention_keeps_the_newest_frames_and_an_unknown_recording_is_404() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = ServiceConfig::new(
        "127.0.0.1:0".parse().unwrap(),
        common::store_for(&dir.path().join("k.db")).await,
    );
    config.record_default = true;
    config.retention = Retention {
        session_bytes: 4_000,
        total_bytes: 6_000,
        max_age_ms: 3_600_000,
    };
    let server = navguard::service::start(config).await.unwrap();
    let base = http(&server);
    for id in ["a", "b", "c"] {
        // Recording by the server default (no "record" field).
        let mut body = spec(id, false);
        body.as_object_mut().unwrap().remove("record");
        create_session(&client(), &server, &body).await;
        let mut socket = ingest(&server, id).await;
        for k in 0..200 {
            send_text(&mut socket, &format!("{{\"t\": {k}, \"z\": [0.5]}}")).await;
        }
        let mut n = 0;
        while n < 200 {
            if recv(&mut socket).await["type"] == "result" {
                n += 1;
            }
        }
    }
    let mut total = 0;
    for id in ["a", "b", "c"] {
        let (status, index) = {
            let resp = reqwest::get(format!(
                "{base}/api/v1/sessions/{id}/recording?format=index"
            ))
            .await
            .unwrap();
            (resp.status(), resp.json::<Value>().await.unwrap())
        };
        assert_eq!(status, 200);
        let bytes: u64 = index["streams"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["bytes"].as_u64().unwrap())
            .sum();
        assert!(bytes <= 4_000, "{id}: {bytes} bytes kept");
        total += bytes;
        if bytes > 0 {
            // What is kept is the newest: the last epoch sent is there.
            let text = reqwest::get(format!("{base}/api/v1/sessions/{id}/recording"))
                .await
                .unwrap()
                .text()
                .await
                .unwrap();
            assert_eq!(text.lines().last().unwrap(), "{\"t\": 199, \"z\": [0.5]}");
        }
    }
    assert!(total <= 6_000, "{total} bytes in all");
    // The oldest session's frames went first when the total was over.
    let resp = reqwest::get(format!("{base}/api/v1/sessions/nobody/recording"))
        .await
        .unwrap();
    assert_eq!(resp.status(), 404);
    let resp = reqwest::get(format!("{base}/api/v1/sessions/a/recording?stream=9"))
        .await
        .unwrap();
    assert_eq!(resp.status(), 404);
    let resp = reqwest::get(format!("{base}/api/v1/sessions/a/recording?format=video"))
        .await
        .unwrap();
    assert_eq!(resp.status(), 400);
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_history_serves_one_sample_per_second_of_the_current_stream() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("h.db"), None, Limits::default()).await;
    create_session(&client(), &server, &spec("h", false)).await;
    let mut socket = ingest(&server, "h").await;
    // 600 epochs at 10 Hz: 60 s of epoch time.
    for f in client_frames() {
        send_text(&mut socket, &f).await;
    }
    let mut n = 0;
    while n < 600 {
        if recv(&mut socket).await["type"] == "result" {
            n += 1;
        }
    }
    let (_, h) = {
        let r = reqwest::get(format!("{}/api/v1/sessions/h/history", http(&server)))
            .await
            .unwrap();
        (r.status(), r.json::<Value>().await.unwrap())
    };
    let samples = h["samples"].as_array().unwrap();
    assert_eq!(samples.len(), 60, "one per second of epoch time");
    assert_eq!(h["period_s"], 1.0);
    let at_30 = samples
        .iter()
        .find(|s| s["t"].as_f64().unwrap() >= 30.0)
        .unwrap();
    let residual = &at_30["monitors"]["cv"]["tests"]["residual"];
    assert_eq!(
        residual["state"], "suspect",
        "the step on epochs 300..310 is in the past: {at_30}"
    );
    let (_, since) = {
        let r = reqwest::get(format!(
            "{}/api/v1/sessions/h/history?since=50",
            http(&server)
        ))
        .await
        .unwrap();
        (r.status(), r.json::<Value>().await.unwrap())
    };
    assert_eq!(since["samples"].as_array().unwrap().len(), 10);
    let r = reqwest::get(format!(
        "{}/api/v1/sessions/h/history?since=x",
        http(&server)
    ))
    .await
    .unwrap();
    assert_eq!(r.status(), 400);
    server.shutdown().await;
}

/// `navguard calibrate` over REST, on the session's own recording: a random walk
/// measured with noise √2 × what the model states gets ≈ 2 × χ²₁ at the rate asked.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn calibration_over_rest_uses_the_sessions_recording() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("c.db"), None, Limits::default()).await;
    let base = http(&server);
    let body = json!({"id": "cal", "record": true, "monitors": [{
        "name": "w", "type": "linear", "policy": {"kind": "counters"},
        "config": {"f": [[1.0]], "h": [[1.0]], "q": [[1e-8]], "r": [[1.0]], "x0": [0.0], "p0": [[1e-8]]}
    }]});
    create_session(&client(), &server, &body).await;
    let resp = reqwest::get(format!("{base}/api/v1/sessions/cal/calibration?far=1e-3"))
        .await
        .unwrap();
    assert_eq!(resp.status(), 404, "no recording yet");
    let mut socket = ingest(&server, "cal").await;
    let mut g = Gauss::new(3);
    let frames: Vec<Value> = (0..20_000)
        .map(|k| json!({"t": k as f64, "z": [2f64.sqrt() * g.normal()]}))
        .collect();
    for chunk in frames.chunks(500) {
        send(&mut socket, &Value::Array(chunk.to_vec())).await;
    }
    // The last epoch is in once the stats count it.
    for _ in 0..500 {
        let s: Value = reqwest::get(format!("{base}/api/v1/sessions/cal/stats"))
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        if s["epochs"] == 20_000 {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    let v: Value = reqwest::get(format!("{base}/api/v1/sessions/cal/calibration?far=1e-3"))
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(v["epochs"], 20_000, "{v}");
    let test = &v["monitors"]["w"]["tests"][0];
    let threshold = test["threshold"].as_f64().unwrap();
    assert!(
        (20.0..26.0).contains(&threshold),
        "{threshold} vs 2 × 10.83: {v}"
    );
    // Its PUT body applies as it is.
    let resp = client()
        .put(format!("{base}/api/v1/sessions/cal/monitors/w/threshold"))
        .json(&v["monitors"]["w"]["put"])
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 200);
    let resp = reqwest::get(format!("{base}/api/v1/sessions/cal/calibration?far=2"))
        .await
        .unwrap();
    assert_eq!(resp.status(), 422);
    let resp = reqwest::get(format!("{base}/api/v1/sessions/cal/calibration?far=1e-6"))
        .await
        .unwrap();
    let v: Value = resp.json().await.unwrap();
    assert!(
        v["monitors"]["w"]["tests"][0]["refused"]
            .as_str()
            .unwrap()
            .contains("needs at least")
    );
    // Calibrated on the first half, measured on the second; a test nobody has is refused.
    assert_eq!(test["holdout_epochs"], 10_000, "{test}");
    assert!(test["holdout_rate"].as_f64().unwrap() <= 2e-3, "{test}");
    let resp = reqwest::get(format!(
        "{base}/api/v1/sessions/cal/calibration?far=1e-3&tests=residual,nope"
    ))
    .await
    .unwrap();
    assert_eq!(resp.status(), 422);
    let v: Value = resp.json().await.unwrap();
    assert!(v.to_string().contains("'nope'"), "{v}");
    server.shutdown().await;
}
