//! Integration tests against the real server on port 0, a temporary SQLite
//! file and a real WebSocket client (docs/architecture.md §A2).

mod common;

use std::time::Duration;

use common::*;
use navguard::service::{self, Limits, ServiceConfig};
use serde_json::{Value, json};
use statrs::distribution::{Binomial, DiscreteCDF};

/// Polls the session's stats until it has processed `epochs` epochs.
async fn wait_for_epochs(server: &service::Server, session: &str, epochs: u64) -> Value {
    for _ in 0..500 {
        let (status, stats) =
            get_json(&format!("{}/api/v1/sessions/{session}/stats", http(server))).await;
        assert_eq!(status, 200, "{stats}");
        if stats["epochs"].as_u64() == Some(epochs) {
            return stats;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    panic!("session {session} never reached {epochs} epochs");
}

async fn stream(socket: &mut Socket, frames: &[Value], batch: usize) {
    for chunk in frames.chunks(batch) {
        send(socket, &Value::Array(chunk.to_vec())).await;
    }
}

const MODEL: CvModel = CvModel {
    q: 0.01,
    sigma: 1.0,
    p0: 10.0,
};

/// 10σ on measurements 1000..1010.
fn step_fault(k: usize) -> f64 {
    if (1000..1010).contains(&k) { 10.0 } else { 0.0 }
}

// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_measurement_step_alarms_on_both_sockets_is_logged_and_survives_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("navguard.db");
    let server = start(&db, None, Limits::default()).await;
    let body = cv_session(
        "veh1",
        &MODEL,
        json!({"kind": "classic"}),
        json!({"p_fa": 1e-5}),
        false,
    );
    create_session(&client(), &server, &body).await;
    let mut events = connect(&format!("{}/api/v1/sessions/veh1/events", ws(&server))).await;
    let mut ingest_socket = ingest(&server, "veh1").await;

    let z = MODEL.measurements(2000, 7, step_fault);
    stream(&mut ingest_socket, &epochs(&z, 0), 100).await;

    let (alarm, _) = recv_until(&mut ingest_socket, |v| v["type"] == "alarm").await;
    assert_eq!(alarm["t"], 1000.0, "{alarm}");
    assert_eq!(alarm["state"], "isolated");
    assert_eq!(
        (
            alarm["session"].as_str(),
            alarm["monitor"].as_str(),
            alarm["test"].as_str()
        ),
        (Some("veh1"), Some("cv"), Some("residual"))
    );
    assert!(alarm["statistic"].as_f64().unwrap() > alarm["threshold"].as_f64().unwrap());
    assert!(
        (alarm["threshold"].as_f64().unwrap() - 19.5114).abs() < 1e-4,
        "χ²(1) at p_fa 1e-5"
    );
    assert!(
        alarm["id"].as_i64().unwrap() > 0,
        "committed before broadcast"
    );

    let (event_alarm, before) = recv_until(&mut events, |v| v["type"] == "alarm").await;
    assert_eq!(event_alarm, alarm);
    assert!(
        before
            .iter()
            .any(|v| v["type"] == "state" && v["to"] == "isolated" && v["t"] == 1000.0)
    );

    let stats = wait_for_epochs(&server, "veh1", 2000).await;
    let residual = &stats["monitors"]["cv"]["tests"]["residual"];
    assert_eq!(residual["state"], "healthy");

    let (status, log) = get_json(&format!("{}/api/v1/alarms?session=veh1", http(&server))).await;
    assert_eq!(status, 200);
    let logged = log["alarms"].as_array().unwrap();
    assert_eq!(
        logged.len() as u64,
        residual["alarms"].as_u64().unwrap(),
        "every alarm is logged: {log}"
    );
    // Newest first; the oldest is the step's onset. At p_fa 1e-5 this seed has
    // no false alarm: every alarm belongs to the fault or its classic-policy
    // aftermath (the filter absorbs the step's tail once P has grown, and is
    // then rejected again when the step ends).
    let oldest = logged.last().unwrap();
    assert_eq!(oldest["id"], alarm["id"]);
    for a in logged {
        let t = a["t"].as_f64().unwrap();
        assert!(
            (1000.0..1050.0).contains(&t),
            "alarm outside the fault's reach: {a}"
        );
        let cleared = a["cleared_t"]
            .as_f64()
            .expect("every alarm is cleared by the end");
        assert!(cleared > t && cleared < 1100.0, "{a}");
    }

    drop(ingest_socket);
    drop(events);
    server.shutdown().await;

    let server = start(&db, None, Limits::default()).await;
    let (_, log) = get_json(&format!(
        "{}/api/v1/alarms?session=veh1&monitor=cv",
        http(&server)
    ))
    .await;
    assert_eq!(
        log["alarms"].as_array().unwrap().len(),
        logged.len(),
        "the whole log survives"
    );
    assert_eq!(log["alarms"].as_array().unwrap().last().unwrap(), oldest);
    let (status, session) = get_json(&format!("{}/api/v1/sessions/veh1", http(&server))).await;
    assert_eq!(status, 200, "the session is restored");
    assert_eq!(session["monitors"][0]["p_fa"], 1e-5);
    server.shutdown().await;
}

// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn counters_policy_goes_suspect_then_isolated_and_recovers_after_the_step() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("n.db"), None, Limits::default()).await;
    let policy = json!({"kind": "counters", "n1": 10, "n2": 3});
    create_session(
        &client(),
        &server,
        &cv_session("veh2", &MODEL, policy.clone(), json!({"p_fa": 1e-5}), false),
    )
    .await;
    let mut socket = ingest(&server, "veh2").await;
    // 30σ on measurements 1000..1010: large enough to exceed through the whole step
    // although P grows while the suspect filter only predicts.
    let z = MODEL.measurements(2000, 7, |k| 3.0 * step_fault(k));
    stream(&mut socket, &epochs(&z, 0), 250).await;
    let mut changes = Vec::new();
    let mut severities = Vec::new();
    while changes.len() < 3 {
        let (v, _) = recv_until(&mut socket, |v| v["type"] == "state").await;
        changes.push((
            v["from"].as_str().unwrap().to_owned(),
            v["to"].as_str().unwrap().to_owned(),
            v["t"].as_f64().unwrap(),
        ));
        severities.push(v["severity"].clone());
    }
    // The default alarm level: entering suspect is a warning, isolated the alarm, and
    // the return to healthy has no severity.
    assert_eq!(
        severities,
        vec![json!("warning"), json!("alarm"), Value::Null]
    );
    assert_eq!(
        (changes[0].0.as_str(), changes[0].1.as_str(), changes[0].2),
        ("healthy", "suspect", 1000.0)
    );
    // seed 004 §2: isolated once t3 > N2, i.e. at the fourth consecutive exceedance.
    assert_eq!(
        (changes[1].0.as_str(), changes[1].1.as_str(), changes[1].2),
        ("suspect", "isolated", 1003.0)
    );
    assert_eq!(
        (changes[2].0.as_str(), changes[2].1.as_str()),
        ("isolated", "healthy")
    );
    assert!(
        (1010.0..=1030.0).contains(&changes[2].2),
        "healthy again after the step ends: {changes:?}"
    );
    let stats = wait_for_epochs(&server, "veh2", 2000).await;
    let residual = &stats["monitors"]["cv"]["tests"]["residual"];
    assert_eq!(
        (&residual["alarms"], &residual["warnings"]),
        (&json!(1), &json!(1)),
        "isolated is the alarm, suspect a warning: {residual}"
    );
    assert_eq!(
        residual["last_alarm_delay_s"], 3.0,
        "isolated 3 s after the first exceedance"
    );
    assert_eq!(residual["state"], "healthy");
    // Both are in the log, told apart by severity and filterable.
    let (_, log) = get_json(&format!("{}/api/v1/alarms?session=veh2", http(&server))).await;
    let got: Vec<(&str, &str)> = log["alarms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| {
            (
                a["state"].as_str().unwrap(),
                a["severity"].as_str().unwrap(),
            )
        })
        .collect();
    assert_eq!(got, vec![("isolated", "alarm"), ("suspect", "warning")]);
    let (_, log) = get_json(&format!(
        "{}/api/v1/alarms?session=veh2&severity=warning",
        http(&server)
    ))
    .await;
    assert_eq!(log["alarms"].as_array().unwrap().len(), 1);
    let (status, _) = get_json(&format!("{}/api/v1/alarms?severity=loud", http(&server))).await;
    assert_eq!(status, 400);

    // A session that asks for alarms on suspect gets today's meaning.
    let mut body = cv_session("veh3", &MODEL, policy, json!({"p_fa": 1e-5}), false);
    body["alarm_level"] = json!("suspect");
    create_session(&client(), &server, &body).await;
    let mut socket = ingest(&server, "veh3").await;
    stream(&mut socket, &epochs(&z, 0), 250).await;
    let stats = wait_for_epochs(&server, "veh3", 2000).await;
    let residual = &stats["monitors"]["cv"]["tests"]["residual"];
    assert_eq!(
        (&residual["alarms"], &residual["warnings"]),
        (&json!(2), &json!(0))
    );
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fault_free_exceedances_are_consistent_with_p_fa() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("p.db"), None, Limits::default()).await;
    let p_fa = 0.002;
    let n = 20_000u64;
    create_session(
        &client(),
        &server,
        &cv_session(
            "calm",
            &MODEL,
            json!({"kind": "classic"}),
            json!({"p_fa": p_fa}),
            false,
        ),
    )
    .await;
    let mut socket = ingest(&server, "calm").await;
    let z = MODEL.measurements(n as usize, 2024, |_| 0.0);
    let frames = epochs(&z, 0);
    // Drain the socket while streaming so state/alarm messages never back up.
    let drain = tokio::spawn(async move {
        stream(&mut socket, &frames, 500).await;
        socket
    });
    let stats = wait_for_epochs(&server, "calm", n).await;
    drop(drain.await.unwrap());
    let exceedances = stats["monitors"]["cv"]["tests"]["residual"]["exceedances"]
        .as_u64()
        .unwrap();
    // Two-sided binomial interval with total tail probability 1e-6.
    let binomial = Binomial::new(p_fa, n).unwrap();
    let lo = (0..n).find(|&k| binomial.cdf(k) > 0.5e-6).unwrap();
    let hi = (0..n).find(|&k| binomial.cdf(k) >= 1.0 - 0.5e-6).unwrap();
    assert!(
        (lo..=hi).contains(&exceedances),
        "{exceedances} exceedances outside [{lo}, {hi}] for p_fa {p_fa} over {n} epochs"
    );
    server.shutdown().await;
}

// ------------------------------------------------------------ echo and λ

type M = Vec<Vec<f64>>;

fn mul(a: &M, b: &M) -> M {
    (0..a.len())
        .map(|i| {
            (0..b[0].len())
                .map(|j| (0..b.len()).map(|k| a[i][k] * b[k][j]).sum())
                .collect()
        })
        .collect()
}

fn tr(a: &M) -> M {
    (0..a[0].len())
        .map(|j| (0..a.len()).map(|i| a[i][j]).collect())
        .collect()
}

fn add(a: &M, b: &M) -> M {
    a.iter()
        .zip(b)
        .map(|(r, s)| r.iter().zip(s).map(|(x, y)| x + y).collect())
        .collect()
}

fn inv2(s: &M) -> M {
    let det = s[0][0] * s[1][1] - s[0][1] * s[1][0];
    vec![
        vec![s[1][1] / det, -s[0][1] / det],
        vec![-s[1][0] / det, s[0][0] / det],
    ]
}

// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn echoed_lambda_equals_r_s_inverse_r_from_an_independent_filter() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("e.db"), None, Limits::default()).await;
    // 2-D constant velocity, positions measured with correlated noise.
    let q = 0.05;
    let qb = [[q / 3.0, q / 2.0], [q / 2.0, q]];
    let f: M = vec![
        vec![1.0, 1.0, 0.0, 0.0],
        vec![0.0, 1.0, 0.0, 0.0],
        vec![0.0, 0.0, 1.0, 1.0],
        vec![0.0, 0.0, 0.0, 1.0],
    ];
    let qm: M = vec![
        vec![qb[0][0], qb[0][1], 0.0, 0.0],
        vec![qb[1][0], qb[1][1], 0.0, 0.0],
        vec![0.0, 0.0, qb[0][0], qb[0][1]],
        vec![0.0, 0.0, qb[1][0], qb[1][1]],
    ];
    let h: M = vec![vec![1.0, 0.0, 0.0, 0.0], vec![0.0, 0.0, 1.0, 0.0]];
    let r: M = vec![vec![1.0, 0.3], vec![0.3, 2.0]];
    let p0: M = (0..4)
        .map(|i| (0..4).map(|j| if i == j { 5.0 } else { 0.0 }).collect())
        .collect();
    let threshold = 9.0;
    let body = json!({"id": "echo", "echo": true, "monitors": [{
        "name": "track", "type": "linear", "threshold": threshold, "policy": {"kind": "classic"},
        "config": {"f": f, "h": h, "q": qm, "r": r, "x0": [0.0, 1.0, 0.0, -1.0], "p0": p0}
    }]});
    create_session(&client(), &server, &body).await;
    let mut socket = ingest(&server, "echo").await;

    let mut g = Gauss::new(99);
    let n = 300;
    let frames: Vec<Value> = (0..n)
        .map(|k| {
            let t = k as f64;
            if k % 37 == 5 {
                return json!({"t": t}); // predict-only epoch
            }
            let bias = if (150..160).contains(&k) { 8.0 } else { 0.0 };
            json!({"t": t, "z": [t + g.normal() + bias, -t + 1.4 * g.normal()]})
        })
        .collect();
    stream(&mut socket, &frames, 50).await;

    // The test's own filter (standard form, explicit 2×2 inverse).
    let mut x: M = vec![vec![0.0], vec![1.0], vec![0.0], vec![-1.0]];
    let mut p = p0.clone();
    let mut rejected = 0;
    for frame in &frames {
        let (result, _) = recv_until(&mut socket, |v| v["type"] == "result").await;
        assert_eq!(result["t"], frame["t"]);
        x = mul(&f, &x);
        p = add(&mul(&mul(&f, &p), &tr(&f)), &qm);
        let out = &result["monitors"]["track"];
        let Some(z) = frame["z"].as_array() else {
            assert!(
                out["tests"].as_object().unwrap().is_empty(),
                "no test without z"
            );
            assert!(out["innovation"].is_null());
            continue;
        };
        let hx = mul(&h, &x);
        let innov = [
            z[0].as_f64().unwrap() - hx[0][0],
            z[1].as_f64().unwrap() - hx[1][0],
        ];
        let returned: Vec<f64> = out["innovation"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        for i in 0..2 {
            assert!(
                (returned[i] - innov[i]).abs() <= 1e-9 * (1.0 + innov[i].abs()),
                "innovation {returned:?} vs {innov:?}"
            );
        }
        let s = add(&mul(&mul(&h, &p), &tr(&h)), &r);
        let si = inv2(&s);
        let rv: M = vec![vec![returned[0]], vec![returned[1]]];
        let lambda = mul(&mul(&tr(&rv), &si), &rv)[0][0];
        let test = &out["tests"]["residual"];
        let server_lambda = test["statistic"].as_f64().unwrap();
        assert!(
            (server_lambda - lambda).abs() <= 1e-9 * lambda.max(1e-12),
            "λ {server_lambda} vs {lambda} at {}",
            frame["t"]
        );
        assert_eq!(test["threshold"], threshold);
        assert_eq!(test["dof"], 2);
        assert!((test["test_ratio"].as_f64().unwrap() - server_lambda / threshold).abs() < 1e-12);
        if lambda > threshold {
            assert_eq!(test["state"], "isolated");
            rejected += 1;
            continue; // classic: rejected, no update
        }
        assert_eq!(test["state"], "healthy");
        let k = mul(&mul(&p, &tr(&h)), &si);
        let inn: M = vec![vec![innov[0]], vec![innov[1]]];
        x = add(&x, &mul(&k, &inn));
        let kh = mul(&k, &h);
        let i_kh: M = (0..4)
            .map(|i| {
                (0..4)
                    .map(|j| if i == j { 1.0 } else { 0.0 } - kh[i][j])
                    .collect()
            })
            .collect();
        p = mul(&i_kh, &p);
        let state: Vec<f64> = out["x"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        for i in 0..4 {
            assert!(
                (state[i] - x[i][0]).abs() < 1e-8 * (1.0 + x[i][0].abs()),
                "x {state:?} vs {x:?}"
            );
        }
    }
    assert!(
        rejected >= 5,
        "the 8σ bias must be rejected at least at its start: {rejected}"
    );
    server.shutdown().await;
}

// ------------------------------------------------------------ bad input

// Over 80 lines: a table of cases checked one after another.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_bad_frame_gets_an_error_event_and_leaves_the_session_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let limits = Limits {
        max_frame_bytes: 4096,
        max_batch_epochs: 50,
        ..Limits::default()
    };
    let server = start(&dir.path().join("b.db"), None, limits).await;
    for id in ["bad", "ref"] {
        create_session(
            &client(),
            &server,
            &cv_session(
                id,
                &MODEL,
                json!({"kind": "counters"}),
                json!({"p_fa": 0.01}),
                true,
            ),
        )
        .await;
    }
    let mut bad = ingest(&server, "bad").await;
    let mut reference = ingest(&server, "ref").await;
    let z = MODEL.measurements(40, 3, |_| 0.0);
    let good = epochs(&z, 0);
    for frame in &good[..10] {
        send(&mut bad, frame).await;
        send(&mut reference, frame).await;
    }
    for socket in [&mut bad, &mut reference] {
        for k in 0..10 {
            let (result, _) = recv_until(socket, |v| v["type"] == "result").await;
            assert_eq!(result["t"], k as f64);
        }
    }
    let oversize = Value::Array(
        (0..200)
            .map(|k| json!({"t": 500.0 + k as f64, "z": [0.123456789]}))
            .collect(),
    )
    .to_string();
    let too_many =
        Value::Array((0..60).map(|k| json!({"t": 500.0 + k as f64})).collect()).to_string();
    let cases: Vec<(&str, String)> = vec![
        ("malformed_json", r#"{"t": 500, "z": [1.0,"#.to_owned()),
        ("non_finite", r#"{"t": 500, "z": [NaN]}"#.to_owned()),
        ("non_finite", r#"{"t": 500, "z": [1e999]}"#.to_owned()),
        ("time_backwards", r#"{"t": 3, "z": [1.0]}"#.to_owned()),
        (
            "time_backwards",
            r#"[{"t": 500, "z": [1.0]}, {"t": 499.5, "z": [1.0]}]"#.to_owned(),
        ),
        ("wrong_length", r#"{"t": 500, "z": [1.0, 2.0]}"#.to_owned()),
        (
            "wrong_length",
            r#"[{"t": 500, "z": [1.0]}, {"t": 501, "z": []}]"#.to_owned(),
        ),
        (
            "unknown_input",
            r#"{"t": 500, "z": [1.0], "lidar": [3]}"#.to_owned(),
        ),
        (
            "unknown_input",
            r#"{"t": 500, "z": [1.0], "u": [1.0]}"#.to_owned(),
        ),
        ("frame_too_large", oversize),
        ("batch_too_large", too_many),
        ("invalid_epoch", r#"{"z": [1.0]}"#.to_owned()),
        // Parses, fits, but overflows λ: refused by the filter, nothing committed.
        ("numerical", r#"{"t": 500, "z": [1e300]}"#.to_owned()),
    ];
    for (i, (code, text)) in cases.iter().enumerate() {
        send_text(&mut bad, text).await;
        let (error, before) = recv_until(&mut bad, |v| v["type"] == "error").await;
        assert!(
            before.iter().all(|v| v["type"] != "result"),
            "case {i} produced a result"
        );
        assert_eq!(error["code"], *code, "case {i}: {text:.80} -> {error}");
        assert!(!error["message"].as_str().unwrap().is_empty());
        // The next good frame is processed normally on the same socket, with
        // exactly the result of the session that never saw a bad frame.
        let frame = &good[10 + i];
        send(&mut bad, frame).await;
        send(&mut reference, frame).await;
        let (a, _) = recv_until(&mut bad, |v| v["type"] == "result").await;
        let (b, _) = recv_until(&mut reference, |v| v["type"] == "result").await;
        assert_eq!(a["t"], frame["t"], "case {i}");
        assert_eq!(a, b, "case {i}: state untouched");
    }
    // Binary frames that are not UTF-8 are refused too.
    {
        use futures_util::SinkExt;
        bad.send(tokio_tungstenite::tungstenite::Message::Binary(
            vec![0xff, 0xfe].into(),
        ))
        .await
        .unwrap();
        let (error, _) = recv_until(&mut bad, |v| v["type"] == "error").await;
        assert_eq!(error["code"], "malformed_json");
    }
    let n = (10 + cases.len()) as u64;
    let stats_bad = wait_for_epochs(&server, "bad", n).await;
    let stats_ref = wait_for_epochs(&server, "ref", n).await;
    assert_eq!(
        stats_bad["monitors"], stats_ref["monitors"],
        "identical statistics"
    );
    // Frames that parse but do not fit the session are counted by it; the rest
    // are refused at the edge before reaching it.
    assert_eq!(stats_bad["frame_errors"], 5);
    assert_eq!(stats_ref["frame_errors"], 0);
    server.shutdown().await;
}

// ------------------------------------------------------------ REST

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn token_is_required_on_api_routes_and_sockets_and_bodies_are_limited() {
    let dir = tempfile::tempdir().unwrap();
    let limits = Limits {
        max_body_bytes: 2048,
        ..Limits::default()
    };
    let server = start(&dir.path().join("a.db"), Some("s3cret"), limits).await;
    let base = http(&server);
    let c = client();
    let resp = c
        .get(format!("{base}/api/v1/sessions"))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 401);
    let body: Value = resp.json().await.unwrap();
    assert_eq!(body["error"]["code"], "unauthorized");
    let resp = c
        .get(format!("{base}/api/v1/sessions"))
        .bearer_auth("wrong")
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 401);
    let resp = c
        .get(format!("{base}/api/v1/sessions"))
        .bearer_auth("s3cret")
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 200);
    assert_eq!(
        c.get(format!("{base}/healthz"))
            .send()
            .await
            .unwrap()
            .status(),
        200,
        "health is public"
    );

    let body = cv_session("tok", &MODEL, json!({"kind": "classic"}), json!({}), false);
    let resp = c
        .post(format!("{base}/api/v1/sessions"))
        .bearer_auth("s3cret")
        .json(&body)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 201);

    // Sockets: refused without the token, accepted with `?token=` or the subprotocol.
    let url = format!("{}/api/v1/sessions/tok/events", ws(&server));
    assert!(tokio_tungstenite::connect_async(&url).await.is_err());
    let mut socket = connect(&format!("{url}?token=s3cret")).await;
    assert_eq!(recv(&mut socket).await["type"], "stats");
    use tokio_tungstenite::tungstenite::client::IntoClientRequest;
    let mut request = url.as_str().into_client_request().unwrap();
    request.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        "navguard, bearer.s3cret".parse().unwrap(),
    );
    let (mut socket, response) = tokio_tungstenite::connect_async(request).await.unwrap();
    assert_eq!(response.headers()["sec-websocket-protocol"], "navguard");
    assert_eq!(recv(&mut socket).await["type"], "stats");

    // Bodies over the limit: 413 with a JSON error.
    let big = json!({"id": "big", "monitors": [{"name": "x".repeat(4000), "type": "linear"}]});
    let resp = c
        .post(format!("{base}/api/v1/sessions"))
        .bearer_auth("s3cret")
        .json(&big)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 413);
    let body: Value = resp.json().await.unwrap();
    assert_eq!(body["error"]["code"], "too_large");
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn open_address_without_a_token_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let config = ServiceConfig::new("0.0.0.0:0".parse().unwrap(), dir.path().join("o.db"));
    let err = service::start(config).await.unwrap_err();
    assert!(
        matches!(err, service::StartError::OpenWithoutToken(_)),
        "{err}"
    );
}

// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn threshold_and_policy_changes_apply_live_and_persist() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("t.db");
    let server = start(&db, None, Limits::default()).await;
    let base = http(&server);
    let c = client();
    create_session(
        &c,
        &server,
        &cv_session(
            "live",
            &MODEL,
            json!({"kind": "classic"}),
            json!({"p_fa": 0.002}),
            true,
        ),
    )
    .await;
    let url = format!("{base}/api/v1/sessions/live/monitors/cv/threshold");
    let (status, view) = get_json(&url).await;
    assert_eq!(status, 200);
    assert_eq!(view["p_fa"], 0.002);
    assert!((view["tests"]["residual"]["threshold"].as_f64().unwrap() - 9.5495).abs() < 1e-4);

    let mut socket = ingest(&server, "live").await;
    send(&mut socket, &json!({"t": 0, "z": [0.5]})).await;
    let (r, _) = recv_until(&mut socket, |v| v["type"] == "result").await;
    assert!(
        (r["monitors"]["cv"]["tests"]["residual"]["threshold"]
            .as_f64()
            .unwrap()
            - 9.5495)
            .abs()
            < 1e-4
    );

    let put = json!({"threshold": 13.0, "policy": {"kind": "counters", "n1": 4, "n2": 2}});
    let resp = c.put(&url).json(&put).send().await.unwrap();
    assert_eq!(resp.status(), 200);
    let view: Value = resp.json().await.unwrap();
    assert_eq!(view["threshold"], 13.0);
    assert!(view["p_fa"].is_null());
    assert_eq!(
        view["policy"],
        json!({"kind": "counters", "n1": 4, "n2": 2})
    );
    assert_eq!(view["tests"]["residual"]["threshold"], 13.0);
    // χ²(1) survival at 13.
    assert!((view["tests"]["residual"]["p_fa"].as_f64().unwrap() - 3.1153e-4).abs() < 1e-7);

    // Applied to the live stream at once.
    send(&mut socket, &json!({"t": 1, "z": [100.0]})).await;
    let (r, _) = recv_until(&mut socket, |v| v["type"] == "result").await;
    let test = &r["monitors"]["cv"]["tests"]["residual"];
    assert_eq!(test["threshold"], 13.0);
    assert_eq!(test["state"], "suspect", "the counters policy is in force");

    // Bad changes: 422 / 404 and nothing changes.
    for (body, status) in [
        (json!({"threshold": 13.0, "p_fa": 0.01}), 422),
        (json!({"p_fa": 1.5}), 422),
        (json!({"threshold": -1}), 422),
        (json!({"policy": {"kind": "counters", "n1": 0}}), 422),
        (json!({"policy": {"kind": "vote"}}), 422),
        (json!({}), 422),
        (json!({"p_fa": "high"}), 422),
    ] {
        let resp = c.put(&url).json(&body).send().await.unwrap();
        assert_eq!(resp.status(), status, "{body}");
        let err: Value = resp.json().await.unwrap();
        assert!(err["error"]["message"].as_str().is_some());
    }
    let resp = c
        .put(&url)
        .header("content-type", "application/json")
        .body("{")
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 400);
    let resp = c
        .put(format!(
            "{base}/api/v1/sessions/live/monitors/nope/threshold"
        ))
        .json(&put)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 404);
    let resp = c
        .put(format!("{base}/api/v1/sessions/nope/monitors/cv/threshold"))
        .json(&put)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 404);
    let (_, view) = get_json(&url).await;
    assert_eq!(view["threshold"], 13.0);

    drop(socket);
    server.shutdown().await;
    let server = start(&db, None, Limits::default()).await;
    let (_, view) = get_json(&format!(
        "{}/api/v1/sessions/live/monitors/cv/threshold",
        http(&server)
    ))
    .await;
    assert_eq!(view["threshold"], 13.0, "persisted across a restart");
    assert_eq!(view["policy"]["kind"], "counters");
    server.shutdown().await;
}

/// Every monitor's 422 names the exact path of the bad field inside its `config`: a value
/// of the wrong type, an unknown key and an out-of-range value each.
// Over 80 lines: a table of cases checked one after another.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_monitor_names_the_field_path_of_a_bad_config() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("s.db"), None, Limits::default()).await;
    let base = http(&server);
    let c = client();
    let linear = MODEL.config();
    // Sets (or adds) the value at a JSON pointer.
    let with = |mut base: Value, pointer: &str, v: Value| {
        let (parent, key) = pointer.rsplit_once('/').unwrap();
        match base.pointer_mut(parent).unwrap() {
            Value::Array(a) => a[key.parse::<usize>().unwrap()] = v,
            other => other[key] = v,
        }
        base
    };
    let add = |mut base: Value, key: &str, v: Value| {
        base[key] = v;
        base
    };
    let channel = json!({"channels": [{"name": "s", "predictor":
        {"online": {"window": 50, "gamma": 30.0, "sigma2": 9.0, "refresh": 1000}}}]});
    let station = json!({"lat": 34.25, "lon": 108.95, "h": 400.0});
    let tacan = json!({"station": station, "model": "m-0"});
    let cases = [
        (
            "linear",
            with(linear.clone(), "/q/1/0", json!("x")),
            "q[1][0]",
        ),
        ("linear", add(linear.clone(), "extra", json!(1)), "extra"),
        ("linear", with(linear.clone(), "/r/0/0", json!(-1.0)), "r"),
        (
            "federated",
            json!({"aids": ["gnss"], "gnss": {"pos_sigma_m": "x"}}),
            "gnss.pos_sigma_m",
        ),
        (
            "federated",
            json!({"aids": ["gnss"], "gnss": {"pos_sigma": 1}}),
            "gnss.pos_sigma",
        ),
        ("federated", json!({"aids": ["gnss"], "p_md": 1}), "p_md"),
        (
            "channel",
            with(channel.clone(), "/channels/0/dim", json!("two")),
            "channels[0].dim",
        ),
        (
            "channel",
            with(
                channel.clone(),
                "/channels/0/predictor/online/window",
                json!(true),
            ),
            "channels[0].predictor.online.window",
        ),
        ("channel", add(channel.clone(), "extra", json!(1)), "extra"),
        (
            "channel",
            with(channel.clone(), "/channels/0/embedding", json!(0)),
            "channels[0].embedding",
        ),
        ("rimu", json!({"h": [[1, 0, "x"]]}), "h[0][2]"),
        ("rimu", json!({"windw": 3}), "windw"),
        ("rimu", json!({"fss_window": 0}), "fss_window"),
        (
            "tacan",
            with(tacan.clone(), "/station/lon", json!("x")),
            "station.lon",
        ),
        ("tacan", add(tacan.clone(), "windw", json!(10)), "windw"),
        ("tacan", add(tacan.clone(), "window", json!(1)), "window"),
    ];
    for (kind, config, field) in cases {
        let body = json!({"monitors": [{"name": "m", "type": kind, "config": config}]});
        let resp = c
            .post(format!("{base}/api/v1/sessions"))
            .json(&body)
            .send()
            .await
            .unwrap();
        let status = resp.status().as_u16();
        let err = resp.json::<Value>().await.unwrap();
        assert_eq!(
            (status, err["error"]["field"].as_str()),
            (422, Some(format!("monitors[0].config.{field}").as_str())),
            "{kind}: {config} -> {err}"
        );
    }
    server.shutdown().await;
}

// Over 80 lines: a table of cases checked one after another.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sessions_are_validated_listed_and_deleted() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(
        &dir.path().join("s.db"),
        None,
        Limits {
            max_monitors_per_session: 2,
            ..Limits::default()
        },
    )
    .await;
    let base = http(&server);
    let c = client();
    let post = async |body: Value| {
        let resp = c
            .post(format!("{base}/api/v1/sessions"))
            .json(&body)
            .send()
            .await
            .unwrap();
        (resp.status().as_u16(), resp.json::<Value>().await.unwrap())
    };
    let mut bad_q = MODEL.config();
    bad_q["q"] = json!([[1.0, 0.5], [0.4, 1.0]]);
    let (status, err) =
        post(json!({"monitors": [{"name": "cv", "type": "linear", "config": bad_q}]})).await;
    assert_eq!(status, 422);
    assert_eq!(err["error"]["field"], "monitors[0].config.q");
    assert!(
        err["error"]["message"]
            .as_str()
            .unwrap()
            .contains("symmetric")
    );
    // A monitor naming a model the server does not have is refused at creation.
    let (status, err) = post(json!({"monitors": [{"name": "g", "type": "rimu",
        "config": {"model": "m-0123456789abcdef"}}]}))
    .await;
    assert_eq!(
        (status, err["error"]["field"].as_str()),
        (422, Some("monitors[0].config.model"))
    );
    let (status, _) = post(json!({"monitors": [{"name": "cv", "type": "kalman"}]})).await;
    assert_eq!(status, 422);
    let (status, _) = post(json!({"id": "has space", "monitors": [{"name": "cv", "type": "linear", "config": MODEL.config()}]})).await;
    assert_eq!(status, 422);
    let (status, err) = post(json!({"monitors": []})).await;
    assert_eq!(
        (status, err["error"]["field"].as_str()),
        (422, Some("monitors"))
    );
    let m = json!({"name": "cv", "type": "linear", "config": MODEL.config()});
    let (status, _) = post(json!({"monitors": [m, m, m]})).await;
    assert_eq!(status, 413);
    let (status, err) = post(json!({"monitors": [m, m]})).await;
    assert_eq!(
        (status, err["error"]["field"].as_str()),
        (422, Some("monitors[1].name"))
    );
    let (status, _) = post(json!({"monitors": [m], "policy": "x"})).await;
    assert_eq!(status, 422, "unknown fields are refused");

    let (status, created) = post(json!({"monitors": [m]})).await;
    assert_eq!(status, 201);
    let id = created["id"].as_str().unwrap().to_owned();
    assert_eq!(created["monitors"][0]["tests"]["residual"]["dof"], 1);
    let (status, _) = post(json!({"id": id, "monitors": [m]})).await;
    assert_eq!(status, 409);
    let (_, list) = get_json(&format!("{base}/api/v1/sessions")).await;
    assert_eq!(list["sessions"].as_array().unwrap().len(), 1);
    let resp = c
        .delete(format!("{base}/api/v1/sessions/{id}"))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 204);
    let (status, err) = get_json(&format!("{base}/api/v1/sessions/{id}")).await;
    assert_eq!(
        (status, err["error"]["code"].as_str()),
        (404, Some("not_found"))
    );
    let resp = c
        .delete(format!("{base}/api/v1/sessions/{id}"))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 404);
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn chi2_health_metrics_and_unknown_routes_answer_in_json() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("c.db"), None, Limits::default()).await;
    let base = http(&server);
    let (status, v) = get_json(&format!("{base}/api/v1/chi2/threshold?dof=6&p_fa=0.00001")).await;
    assert_eq!(status, 200);
    assert!((v["threshold"].as_f64().unwrap() - 33.1071).abs() < 1e-4);
    let (status, v) = get_json(&format!(
        "{base}/api/v1/chi2/missed-detection?dof=2&p_fa=0.002&p_md=0.001"
    ))
    .await;
    assert_eq!(status, 200, "{v}");
    let lambda = v["noncentrality"].as_f64().unwrap();
    let (_, back) = get_json(&format!(
        "{base}/api/v1/chi2/missed-detection?dof=2&p_fa=0.002&noncentrality={lambda}"
    ))
    .await;
    assert!(
        (back["p_md"].as_f64().unwrap() - 0.001).abs() < 1e-9,
        "{back}"
    );
    for bad in ["dof=0&p_fa=0.1", "dof=2&p_fa=1.5", "dof=2&p_fa=0"] {
        let (status, v) = get_json(&format!("{base}/api/v1/chi2/threshold?{bad}")).await;
        assert_eq!(status, 422, "{bad}: {v}");
    }
    let (status, v) = get_json(&format!("{base}/api/v1/chi2/threshold?dof=two&p_fa=0.1")).await;
    assert_eq!(
        (status, v["error"]["code"].as_str()),
        (400, Some("bad_request"))
    );
    let (status, _) = get_json(&format!(
        "{base}/api/v1/chi2/missed-detection?dof=2&threshold=10"
    ))
    .await;
    assert_eq!(status, 422);
    let (status, v) = get_json(&format!("{base}/api/v1/alarms?limit=0")).await;
    assert_eq!((status, v["error"]["field"].as_str()), (422, Some("limit")));

    let (status, v) = get_json(&format!("{base}/healthz")).await;
    assert_eq!((status, v["status"].as_str()), (200, Some("ok")));
    let text = get_text(&format!("{base}/metrics")).await;
    for metric in [
        "navguard_frames_total",
        "navguard_epochs_total",
        "navguard_alarms_total",
        "navguard_sessions",
        "navguard_frame_latency_seconds_bucket",
    ] {
        assert!(text.contains(metric), "{metric} missing from /metrics");
    }
    let (status, v) = get_json(&format!("{base}/api/v1/nothing")).await;
    assert_eq!(
        (status, v["error"]["code"].as_str()),
        (404, Some("not_found"))
    );
    let resp = client()
        .patch(format!("{base}/api/v1/sessions"))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 405);
    let html = client()
        .get(format!("{base}/"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(html.contains("navguard"));
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_new_stream_resets_the_filters_and_closes_what_the_old_one_left_open() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("r.db"), None, Limits::default()).await;
    let base = http(&server);
    let policy = json!({"kind": "counters", "n1": 10, "n2": 1});
    create_session(
        &client(),
        &server,
        &cv_session("re", &MODEL, policy, json!({"p_fa": 1e-5}), true),
    )
    .await;
    let mut events = connect(&format!("{}/api/v1/sessions/re/events", ws(&server))).await;
    let mut socket = ingest(&server, "re").await;
    // A second ingest stream while one is attached: 409.
    let second =
        tokio_tungstenite::connect_async(format!("{}/api/v1/sessions/re/ingest", ws(&server)))
            .await;
    assert!(second.is_err(), "only one ingest stream at a time");
    let z = MODEL.measurements(60, 5, |k| if k >= 50 { 30.0 } else { 0.0 });
    stream(&mut socket, &epochs(&z, 0), 60).await;
    let (last, _) = recv_until(&mut socket, |v| v["type"] == "result" && v["t"] == 59.0).await;
    assert_eq!(
        last["monitors"]["cv"]["tests"]["residual"]["state"],
        "isolated"
    );
    drop(socket);

    // Reconnect: filters start afresh (t may restart), the test is announced
    // healthy, and the open alarms are closed in the log.
    let mut socket = reingest(&server, "re").await;
    let (change, _) = recv_until(&mut events, |v| {
        v["type"] == "state" && v["to"] == "healthy"
    })
    .await;
    assert_eq!(
        (change["from"].as_str(), change["t"].as_f64()),
        (Some("isolated"), Some(59.0))
    );
    let (_, log) = get_json(&format!("{base}/api/v1/alarms?session=re")).await;
    let alarms = log["alarms"].as_array().unwrap();
    assert_eq!(alarms.len(), 2, "suspect then isolated: {log}");
    assert!(alarms.iter().all(|a| a["cleared_t"] == 59.0), "{log}");
    send(&mut socket, &json!({"t": 0.0, "z": [z[0]]})).await;
    let (first, _) = recv_until(&mut socket, |v| v["type"] == "result").await;
    // Same first result as the first stream had: the prior is x0, P0 again.
    let x = first["monitors"]["cv"]["x"].as_array().unwrap();
    let gain = (MODEL.p0 * 2.0 + MODEL.q / 3.0) / (MODEL.p0 * 2.0 + MODEL.q / 3.0 + 1.0);
    assert!(
        (x[0].as_f64().unwrap() - gain * z[0]).abs() < 1e-12,
        "{first}"
    );
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn socket_routes_answer_plain_requests_with_json_errors() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("u.db"), None, Limits::default()).await;
    let base = http(&server);
    create_session(
        &client(),
        &server,
        &cv_session("up", &MODEL, json!({"kind": "classic"}), json!({}), false),
    )
    .await;
    let resp = client()
        .get(format!("{base}/api/v1/sessions/up/ingest"))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 426);
    assert_eq!(resp.headers()["upgrade"], "websocket");
    let body: Value = resp.json().await.unwrap();
    assert_eq!(body["error"]["code"], "upgrade_required");
    let (status, body) = get_json(&format!("{base}/api/v1/sessions/none/events")).await;
    assert_eq!(
        (status, body["error"]["code"].as_str()),
        (404, Some("not_found"))
    );
    let resp = client()
        .delete(format!("{base}/api/v1/alarms"))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 405);
    assert_eq!(resp.headers()["allow"], "GET");
    let resp = client()
        .post(format!("{base}/api/v1/sessions/up"))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.headers()["allow"], "GET, DELETE");
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_slow_subscriber_gets_every_alarm_and_stats_stay_decimated() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("v.db"), None, Limits::default()).await;
    // An outlier on every tenth measurement: under the classic policy each is
    // rejected (an alarm) and the next epoch is healthy again.
    create_session(
        &client(),
        &server,
        &cv_session(
            "many",
            &MODEL,
            json!({"kind": "classic"}),
            json!({"p_fa": 1e-5}),
            false,
        ),
    )
    .await;
    let mut slow = connect(&format!("{}/api/v1/sessions/many/events", ws(&server))).await;
    let mut socket = ingest(&server, "many").await;
    let z = MODEL.measurements(3000, 11, |k| if k % 10 == 9 { 50.0 } else { 0.0 });
    let frames = epochs(&z, 0);
    let started = std::time::Instant::now();
    let writer = tokio::spawn(async move {
        for chunk in frames.chunks(30) {
            send(&mut socket, &Value::Array(chunk.to_vec())).await;
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        socket
    });
    let stats = wait_for_epochs(&server, "many", 3000).await;
    let elapsed = started.elapsed().as_secs_f64();
    drop(writer.await.unwrap());
    let alarms = stats["monitors"]["cv"]["tests"]["residual"]["alarms"]
        .as_u64()
        .unwrap();
    assert_eq!(alarms, 300, "one alarm per outlier: {stats}");
    // Only now does the subscriber read: every alarm is still there, in order.
    let mut seen = Vec::new();
    let mut stats_messages = 0;
    while (seen.len() as u64) < alarms {
        let v = recv(&mut slow).await;
        match v["type"].as_str() {
            Some("alarm") => seen.push(v["id"].as_i64().unwrap()),
            Some("stats") => stats_messages += 1,
            _ => {}
        }
    }
    assert!(
        seen.windows(2).all(|w| w[0] < w[1]),
        "alarms arrive in order, none twice"
    );
    let (_, log) = get_json(&format!(
        "{}/api/v1/alarms?session=many&limit=1000",
        http(&server)
    ))
    .await;
    let mut logged: Vec<i64> = log["alarms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["id"].as_i64().unwrap())
        .collect();
    logged.reverse();
    assert_eq!(seen, logged, "the subscriber saw exactly the logged alarms");
    // Stats are decimated to at most 20 per second (plus the immediate first one).
    let bound = (20.0 * (elapsed + started.elapsed().as_secs_f64())).ceil() as u64 + 2;
    assert!(
        stats_messages <= bound,
        "{stats_messages} stats messages, at most {bound} allowed"
    );
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_last_frame_of_a_burst_reaches_observers_while_the_stream_stays_open() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("t.db"), None, Limits::default()).await;
    create_session(
        &client(),
        &server,
        &cv_session(
            "burst",
            &MODEL,
            json!({"kind": "classic"}),
            json!({"p_fa": 0.002}),
            false,
        ),
    )
    .await;
    let mut events = connect(&format!("{}/api/v1/sessions/burst/events", ws(&server))).await;
    let mut socket = ingest(&server, "burst").await;
    // Two frames well inside one 50 ms publication period: the second one's
    // statistics are held back by the rate limit and must still be published,
    // although no further frame arrives and the ingest socket stays open.
    let z = MODEL.measurements(20, 3, |_| 0.0);
    let frames = epochs(&z, 0);
    send(&mut socket, &Value::Array(frames[..10].to_vec())).await;
    send(&mut socket, &Value::Array(frames[10..].to_vec())).await;
    let (stats, _) = recv_until(&mut events, |v| {
        v["type"] == "stats" && v["epochs"].as_u64() == Some(20)
    })
    .await;
    assert_eq!(stats["monitors"]["cv"]["epochs"], 20, "{stats}");
    drop(socket);
}

/// A short federated stream with echo: the `track` of the stats is the last INS
/// epoch's corrected solution (as the last echoed `result` carries it) and the
/// INS position as sent; an epoch without `ins` leaves it where it was.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn federated_stats_track_is_the_last_echoed_solution_and_ins_position() {
    use navguard::service::wire::epoch_to_wire;
    use navguard_sim::scenario::ship_with;

    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("t.db"), None, Limits::default()).await;
    let scenario = ship_with(3, vec![], 3.0).unwrap();
    let body = json!({"id": "fed", "echo": true, "monitors": [{
        "name": "nav", "type": "federated",
        "config": scenario.default_monitor_config(),
        "policy": {"kind": "classic"}, "p_fa": 1e-3
    }]});
    create_session(&client(), &server, &body).await;

    // Before any epoch: no track.
    let (_, stats) = get_json(&format!("{}/api/v1/sessions/fed/stats", http(&server))).await;
    assert!(stats["monitors"]["nav"].get("track").is_none(), "{stats}");

    let mut frames: Vec<Value> = scenario
        .epochs
        .iter()
        .map(|e| serde_json::from_str(&epoch_to_wire(&e.epoch).unwrap()).unwrap())
        .collect();
    let last_ins = frames.last().unwrap().clone();
    let last_ins_t = last_ins["t"].as_f64().unwrap();
    // A trailing epoch without `ins`: the monitor repeats its solution, the track stays.
    frames.push(json!({"t": last_ins_t + 0.05}));
    let n = frames.len();

    let mut socket = ingest(&server, "fed").await;
    stream(&mut socket, &frames, 7).await;
    let mut results = Vec::new();
    while results.len() < n {
        let message = recv(&mut socket).await;
        assert_ne!(message["type"], "error", "{message}");
        if message["type"] == "result" {
            results.push(message);
        }
    }
    let stats = wait_for_epochs(&server, "fed", n as u64).await;
    let track = &stats["monitors"]["nav"]["track"];
    assert_eq!(track["t"], json!(last_ins_t), "{track}");

    // The last `result` repeats the last INS epoch's solution.
    let solution = &results[n - 1]["monitors"]["nav"]["solution"];
    assert_eq!(solution, &results[n - 2]["monitors"]["nav"]["solution"]);
    for k in ["lat", "lon", "h"] {
        assert_eq!(
            track["solution"][k], solution[k],
            "{k}: {track} vs {solution}"
        );
    }
    // The raw INS position is the one sent (degrees on the wire, round-tripped through radians).
    for k in ["lat", "lon", "h"] {
        let (got, sent) = (
            track["ins"][k].as_f64().unwrap(),
            last_ins["ins"][k].as_f64().unwrap(),
        );
        assert!(
            (got - sent).abs() <= 1e-9 * sent.abs().max(1.0),
            "{k}: {got} vs {sent}"
        );
    }
    // The correction is small but real.
    let dlat = track["solution"]["lat"].as_f64().unwrap() - track["ins"]["lat"].as_f64().unwrap();
    assert!(dlat.abs() < 1e-3, "{track}");

    // The events socket's `stats` carries the same track.
    let mut events = connect(&format!("{}/api/v1/sessions/fed/events", ws(&server))).await;
    let first = recv(&mut events).await;
    assert_eq!(first["type"], "stats");
    assert_eq!(&first["monitors"]["nav"]["track"], track);
    server.shutdown().await;
}

/// Per-test thresholds and the alarm level, set at creation and by `PUT`, are in force
/// at once, checked as a whole before anything changes, and survive a restart.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn per_test_thresholds_and_the_alarm_level_apply_live_and_persist() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("pt.db");
    let server = start(&db, None, Limits::default()).await;
    let base = http(&server);
    let c = client();
    let mut body = cv_session(
        "pt",
        &MODEL,
        json!({"kind": "counters", "n1": 10, "n2": 5}),
        json!({"p_fa": 0.002}),
        true,
    );
    body["monitors"][0]["thresholds"] = json!({"residual": {"threshold": 30.0}});
    create_session(&c, &server, &body).await;
    let url = format!("{base}/api/v1/sessions/pt/monitors/cv/threshold");
    let (_, view) = get_json(&url).await;
    assert_eq!(view["tests"]["residual"]["threshold"], 30.0);
    assert_eq!(view["tests"]["residual"]["own"], true);
    assert_eq!(view["alarm_level"], "isolated");
    // A monitor-wide change leaves the test's own threshold alone.
    let resp = c
        .put(&url)
        .json(&json!({"p_fa": 1e-5}))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 200);
    let view: Value = resp.json().await.unwrap();
    assert_eq!(view["tests"]["residual"]["threshold"], 30.0);
    // Back to the monitor's, and alarms on suspect.
    let resp = c
        .put(&url)
        .json(&json!({"tests": {"residual": null}, "alarm_level": "suspect"}))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 200);
    let view: Value = resp.json().await.unwrap();
    assert!((view["tests"]["residual"]["threshold"].as_f64().unwrap() - 19.5114).abs() < 1e-4);
    assert_eq!(view["tests"]["residual"]["own"], false);
    assert_eq!(view["alarm_level"], "suspect");
    // Refused as a whole, naming the field; nothing changes.
    for (put, field) in [
        (json!({"tests": {"nope": {"p_fa": 0.01}}}), "tests.nope"),
        (json!({"tests": {"residual": {}}}), "tests.residual"),
        (
            json!({"p_fa": 0.01, "tests": {"residual": {"p_fa": 2.0}}}),
            "tests.residual",
        ),
    ] {
        let resp = c.put(&url).json(&put).send().await.unwrap();
        assert_eq!(resp.status(), 422, "{put}");
        let err: Value = resp.json().await.unwrap();
        assert_eq!(err["error"]["field"], field, "{err}");
    }
    let (_, view) = get_json(&url).await;
    assert_eq!(
        view["p_fa"], 1e-5,
        "the refused p_fa change was not applied"
    );
    // A session whose thresholds name an unknown test is refused at creation.
    let mut bad = cv_session("pt2", &MODEL, json!({"kind": "classic"}), json!({}), false);
    bad["monitors"][0]["thresholds"] = json!({"gnss": {"threshold": 3.0}});
    let resp = c
        .post(format!("{base}/api/v1/sessions"))
        .json(&bad)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 422);
    let err: Value = resp.json().await.unwrap();
    assert_eq!(err["error"]["field"], "monitors[0].thresholds.gnss");

    let resp = c
        .put(&url)
        .json(&json!({"tests": {"residual": {"threshold": 25.0}}}))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 200);
    server.shutdown().await;
    let server = start(&db, None, Limits::default()).await;
    let (_, view) = get_json(&format!(
        "{}/api/v1/sessions/pt/monitors/cv/threshold",
        http(&server)
    ))
    .await;
    assert_eq!(view["tests"]["residual"]["threshold"], 25.0, "persisted");
    assert_eq!(view["alarm_level"], "suspect", "persisted");
    let (_, session) = get_json(&format!("{}/api/v1/sessions/pt", http(&server))).await;
    assert_eq!(
        session["monitors"][0]["thresholds"],
        json!({"residual": {"threshold": 25.0}})
    );
    server.shutdown().await;
}

/// A model whose R is four times too small is named `overconfident` in the stats and
/// counted in `/metrics`; a well-tuned one is `ok`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn consistency_diagnostics_name_a_mis_tuned_model() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("c.db"), None, Limits::default()).await;
    let c = client();
    let tuned = CvModel {
        q: MODEL.q,
        sigma: MODEL.sigma,
        p0: MODEL.p0,
    };
    let optimistic = CvModel {
        q: MODEL.q,
        sigma: MODEL.sigma / 2.0,
        p0: MODEL.p0,
    };
    // Both see the same measurements, drawn with the true σ; a raw threshold far away
    // keeps every epoch healthy.
    let z = MODEL.measurements(400, 11, |_| 0.0);
    for (id, model) in [("tuned", &tuned), ("optimistic", &optimistic)] {
        let body = cv_session(
            id,
            model,
            json!({"kind": "classic"}),
            json!({"threshold": 1e6}),
            false,
        );
        create_session(&c, &server, &body).await;
        let mut socket = ingest(&server, id).await;
        stream(&mut socket, &epochs(&z, 0), 100).await;
    }
    let flag = |stats: &Value| stats["monitors"]["cv"]["tests"]["residual"]["consistency"].clone();
    let tuned = flag(&wait_for_epochs(&server, "tuned", 400).await);
    let optimistic = flag(&wait_for_epochs(&server, "optimistic", 400).await);
    assert_eq!(tuned["flag"], "ok", "{tuned}");
    assert_eq!(tuned["samples"], 100);
    assert_eq!(optimistic["flag"], "overconfident", "{optimistic}");
    assert!(
        optimistic["nis_mean"].as_f64().unwrap() > optimistic["nis_bounds"][1].as_f64().unwrap()
    );
    // /metrics reads the published statistics (≤ 20 a second): wait for the last ones of
    // both sessions.
    let mut text = String::new();
    for _ in 0..250 {
        text = get_text(&format!("{}/metrics", http(&server))).await;
        if text.contains("navguard_tests_by_consistency{flag=\"ok\"} 1")
            && text.contains("navguard_tests_by_consistency{flag=\"overconfident\"} 1")
        {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    assert!(
        text.contains("navguard_tests_by_consistency{flag=\"ok\"} 1"),
        "{text}"
    );
    assert!(
        text.contains("navguard_tests_by_consistency{flag=\"overconfident\"} 1"),
        "{text}"
    );
    server.shutdown().await;
}

/// `resume` on a single node (docs/deployment.md, Failover): a bad value is a 400 JSON
/// error before any upgrade; `resume=true` on a session with no stream yet starts afresh
/// (`resumed` null); after a stream, it carries on from the last epoch, nothing reset.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_ingest_stream_resumes_where_the_previous_one_left_off() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("r.db"), None, Limits::default()).await;
    create_session(
        &client(),
        &server,
        &cv_session("rs", &MODEL, json!({"kind": "classic"}), json!({}), false),
    )
    .await;
    let (status, body) = get_json(&format!(
        "{}/api/v1/sessions/rs/ingest?resume=maybe",
        http(&server)
    ))
    .await;
    assert_eq!(
        (status, body["error"]["code"].as_str()),
        (400, Some("bad_request"))
    );
    let url = format!("{}/api/v1/sessions/rs/ingest?resume=true", ws(&server));
    let mut socket = connect(&url).await;
    let ready = recv(&mut socket).await;
    assert_eq!(
        (ready["type"].as_str(), &ready["resumed"]),
        (Some("ready"), &Value::Null)
    );
    let z = MODEL.measurements(20, 7, |_| 0.0);
    send(&mut socket, &Value::from(epochs(&z, 0))).await;
    wait_for_epochs(&server, "rs", 20).await;
    drop(socket);
    // The server sees the old stream's close asynchronously (409 until then).
    let mut socket = None;
    for _ in 0..250 {
        if let Ok((s, _)) = tokio_tungstenite::connect_async(&url).await {
            socket = Some(s);
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let mut socket = socket.expect("the stream reattaches within 5 s");
    let ready = recv(&mut socket).await;
    assert_eq!(
        ready["resumed"],
        json!({"t": 19.0, "epochs": 20}),
        "{ready}"
    );
    // Time goes on from 19: an epoch before it is refused, as within one stream.
    send(&mut socket, &json!({"t": 5.0, "z": [0.0]})).await;
    let refused = recv(&mut socket).await;
    assert_eq!(refused["code"], "time_backwards", "{refused}");
    server.shutdown().await;
}
