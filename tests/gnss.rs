//! The `gnss` monitor end to end on a real server: the five GSDC 2023 Pixel 7 Pro epochs
//! (tests/data/gnss/) streamed over the ingest socket, their `result` frames (fix,
//! clocks, protection levels, satellites, the `raim` test and its dof) and the
//! statistics' `gnss` snapshot; satellites the edge refuses, each with its stable
//! code, on a session that goes on; a bad config's 422 naming its field; and a +200 m
//! pseudorange fault on one GPS satellite, announced as a `raim` state change and
//! left out of the fix.

mod common;

use std::time::Duration;

use common::*;
use navguard::service::{Limits, Server};
use serde_json::{Value, json};

/// The GSDC 2023 Pixel 7 Pro epochs as ingest frames, one per line, with truth.
const GSDC_2023: &str = include_str!("data/gnss/gsdc2023_pixel7pro.jsonl");

/// The phone's true position (static): latitude, longitude in degrees, ellipsoidal
/// height in m (tests/data/gnss/README.md).
const TRUTH: (f64, f64, f64) = (37.692231, -122.0884199, 20.9736);

/// The GPS satellite given a pseudorange fault (63.8° elevation in the first epoch).
const FAULTY: &str = "G10";

fn frames() -> Vec<Value> {
    GSDC_2023
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| serde_json::from_str(l).expect("a JSON frame per line"))
        .collect()
}

/// A session with one `gnss` monitor named `gnss` and `echo` on; `extra` adds fields
/// to the monitor (policy, alarm level).
fn session(id: &str, config: Value, extra: Value) -> Value {
    let mut monitor = json!({"name": "gnss", "type": "gnss", "config": config});
    for (k, v) in extra.as_object().expect("an object") {
        monitor[k] = v.clone();
    }
    json!({"id": id, "echo": true, "monitors": [monitor]})
}

fn config() -> Value {
    json!({
        "elevation_mask_deg": 10.0,
        "sigma": {"model": "given"},
        "fde": {"method": "greedy", "max_exclusions": 1},
        "protection": "araim",
        "hal_m": 40.0
    })
}

/// Horizontal distance, m, between a reported position and the truth (local flat
/// Earth: the two are metres apart).
fn horizontal_error(position: &Value) -> f64 {
    let (lat, lon) = (
        position["lat"].as_f64().unwrap(),
        position["lon"].as_f64().unwrap(),
    );
    const R: f64 = 6_371_000.0;
    let north = (lat - TRUTH.0).to_radians() * R;
    let east = (lon - TRUTH.1).to_radians() * R * TRUTH.0.to_radians().cos();
    north.hypot(east)
}

/// Sends each frame on its own and collects its `result`: the results in order and
/// every other message seen meanwhile.
async fn stream(socket: &mut Socket, frames: &[Value]) -> (Vec<Value>, Vec<Value>) {
    let mut results = Vec::new();
    let mut others = Vec::new();
    for frame in frames {
        send(socket, frame).await;
        let (result, before) = recv_until(socket, |v| v["type"] == "result").await;
        assert!(
            before.iter().all(|v| v["type"] != "error"),
            "t = {}: {before:?}",
            frame["t"]
        );
        assert_eq!(result["t"], frame["t"]);
        results.push(result);
        others.extend(before);
    }
    (results, others)
}

/// Polls the session's stats until it has processed `epochs` epochs.
async fn stats_after(server: &Server, session: &str, epochs: u64) -> Value {
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

fn satellite<'a>(outputs: &'a Value, id: &str) -> &'a Value {
    outputs["satellites"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["id"] == id)
        .unwrap_or_else(|| panic!("{id} in {outputs}"))
}

fn used(outputs: &Value) -> usize {
    outputs["satellites"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|s| s["used"] == true)
        .count()
}

// Over 80 lines: one scenario in the order it happens.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn gsdc_2023_epochs_fix_within_10_m_with_a_raim_test_and_a_stats_snapshot() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("g.db"), None, Limits::default()).await;
    create_session(&client(), &server, &session("pixel", config(), json!({}))).await;
    let mut socket = ingest(&server, "pixel").await;
    let frames = frames();
    assert_eq!(frames.len(), 5);
    let (results, _) = stream(&mut socket, &frames).await;

    for (frame, result) in frames.iter().zip(&results) {
        let m = &result["monitors"]["gnss"];
        let t = &frame["t"];
        let error = horizontal_error(&m["position"]);
        assert!(error < 10.0, "t = {t}: {error} m from the truth: {m}");
        let hpe = m["hpe"].as_f64().expect("an hpe against the truth");
        assert!(
            hpe < 10.0 && (hpe - error).abs() < 0.5,
            "t = {t}: {hpe} vs {error}"
        );
        assert!(
            (m["position"]["h"].as_f64().unwrap() - TRUTH.2).abs() < 50.0,
            "{m}"
        );
        assert!(m["vpe"].as_f64().is_some(), "{m}");
        // Non-finite numbers are written as null: a number is finite.
        let (hpl, vpl) = (m["hpl"].as_f64(), m["vpl"].as_f64());
        assert!(hpl.is_some_and(|x| x > 0.0), "t = {t}: {m}");
        assert!(vpl.is_some_and(|x| x > 0.0), "t = {t}: {m}");
        assert_eq!(m["hal"], 40.0);
        assert_eq!(m["val"], Value::Null);
        for k in ["gdop", "pdop", "hdop", "vdop"] {
            assert!(m["dop"][k].as_f64().is_some_and(|x| x > 0.0), "{k}: {m}");
        }
        let clocks = m["clocks"].as_object().unwrap();
        let letters: Vec<&str> = clocks.keys().map(String::as_str).collect();
        assert_eq!(letters, ["E", "G", "R"], "t = {t}");
        assert!(clocks.values().all(|c| c.as_f64().is_some()), "{m}");
        let sats = m["satellites"].as_array().unwrap();
        assert_eq!(
            sats.len(),
            frame["gnss_raw"]["sats"].as_array().unwrap().len()
        );
        let n_used = used(m);
        assert!(n_used >= 15, "t = {t}: {n_used} satellites used: {m}");
        for s in sats {
            assert!(
                ["healthy", "suspect", "isolated"].contains(&s["health"].as_str().unwrap()),
                "{s}"
            );
            if s["used"] == true {
                for k in ["el", "az", "residual", "w"] {
                    assert!(s[k].as_f64().is_some(), "{k}: {s}");
                }
                assert!(s["el"].as_f64().unwrap() >= 10.0, "under the mask: {s}");
            }
        }
        assert!(m["excluded"].is_array(), "{m}");
        let tests = m["tests"].as_object().unwrap();
        assert_eq!(tests.keys().collect::<Vec<_>>(), ["raim"], "t = {t}");
        let raim = &tests["raim"];
        assert_eq!(
            raim["dof"].as_u64(),
            Some((n_used - 3 - clocks.len()) as u64),
            "t = {t}: the dof follows the satellites: {m}"
        );
        assert!(
            raim["statistic"].as_f64().is_some_and(|x| x >= 0.0),
            "{raim}"
        );
        assert!(
            raim["threshold"].as_f64().is_some_and(|x| x > 0.0),
            "{raim}"
        );
        let integrity = &m["integrity"];
        assert_eq!(integrity["protection_level"].as_f64(), hpl, "{m}");
        assert_eq!(integrity["alert_limit"], 40.0);
        assert!(
            ["available", "unavailable"].contains(&integrity["state"].as_str().unwrap()),
            "{integrity}"
        );
    }

    let stats = stats_after(&server, "pixel", 5).await;
    let monitor = &stats["monitors"]["gnss"];
    assert_eq!(monitor["type"], "gnss");
    assert_eq!(monitor["epochs"], 5);
    assert!(monitor["tests"]["raim"].is_object(), "{monitor}");
    let snapshot = &monitor["gnss"];
    assert_eq!(snapshot["t"], frames[4]["t"], "the latest epoch");
    let last = &results[4]["monitors"]["gnss"];
    assert_eq!(snapshot["satellites"], last["satellites"], "{snapshot}");
    assert_eq!(snapshot["position"], last["position"]);
    assert_eq!(snapshot["hpl"], last["hpl"]);
    assert_eq!(snapshot["satellites"].as_array().unwrap().len(), 21);
    assert!(monitor["integrity"].is_object(), "{monitor}");
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn refused_satellites_get_their_codes_and_the_session_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("g.db"), None, Limits::default()).await;
    create_session(&client(), &server, &session("bad", config(), json!({}))).await;
    let mut socket = ingest(&server, "bad").await;
    let frames = frames();
    stream(&mut socket, &frames[..1]).await;

    let mut unknown = frames[1].clone();
    unknown["gnss_raw"]["sats"][0]["id"] = json!("X05");
    let mut duplicate = frames[1].clone();
    let mut list = duplicate["gnss_raw"]["sats"].as_array().unwrap().clone();
    list.push(list[3].clone());
    duplicate["gnss_raw"]["sats"] = Value::Array(list);
    let mut km = frames[1].clone();
    let pos: Vec<f64> = km["gnss_raw"]["sats"][2]["pos"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap() / 1e3)
        .collect();
    km["gnss_raw"]["sats"][2]["pos"] = json!(pos);
    let cases = [
        (unknown, "unknown_constellation", "X05"),
        (duplicate, "duplicate_satellite", "appears twice"),
        (km, "satellite_position", "ECEF metres"),
    ];
    for (i, (frame, code, says)) in cases.into_iter().enumerate() {
        send(&mut socket, &frame).await;
        let (error, before) = recv_until(&mut socket, |v| v["type"] == "error").await;
        assert!(before.iter().all(|v| v["type"] != "result"), "{before:?}");
        assert_eq!(error["code"], code, "{error}");
        let message = error["message"].as_str().unwrap();
        assert!(message.contains(says), "{message}");
        // The session goes on: the next good epoch gets its result.
        let (results, _) = stream(&mut socket, &frames[1 + i..2 + i]).await;
        let m = &results[0]["monitors"]["gnss"];
        assert!(horizontal_error(&m["position"]) < 10.0, "{m}");
        assert!(m["tests"]["raim"].is_object(), "{m}");
    }
    let stats = stats_after(&server, "bad", 4).await;
    assert_eq!(stats["monitors"]["gnss"]["epochs"], 4);
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bad_gnss_config_is_a_422_naming_its_field() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("g.db"), None, Limits::default()).await;
    let base = http(&server);
    let c = client();
    let cases = [
        (json!({"elevation_mask_deg": 95}), "elevation_mask_deg"),
        (json!({"elevation_mask_deg": "high"}), "elevation_mask_deg"),
        (json!({"elevation_mask": 5}), "elevation_mask"),
        (json!({"sigma": {"scale": 0}}), "sigma.scale"),
        (
            json!({"sigma": {"model": "elevation", "a_m": -1}}),
            "sigma.a_m",
        ),
        (json!({"fde": {"max_exclusions": 11}}), "fde.max_exclusions"),
        (json!({"hal_m": 0}), "hal_m"),
        (json!({"val_m": -5}), "val_m"),
        (json!({"p_md": 0.9}), "p_md"),
        (json!({"ism": {"sigma_ura_m": 0}}), "ism.sigma_ura_m"),
        (json!({"araim": {"p_hmi": 2}}), "araim.p_hmi"),
    ];
    for (config, field) in cases {
        let body = json!({"monitors": [{"name": "g", "type": "gnss", "config": config}]});
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
            "{config} -> {err}"
        );
    }
    // Every field has a default: an empty config is a monitor.
    let body = json!({"monitors": [{"name": "g", "type": "gnss", "config": {}}]});
    let resp = c
        .post(format!("{base}/api/v1/sessions"))
        .json(&body)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 201);
    server.shutdown().await;
}

// Over 80 lines: one scenario in the order it happens.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_200_m_pseudorange_fault_changes_the_raim_state_and_leaves_the_satellite_out() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("g.db"), None, Limits::default()).await;
    let extra =
        json!({"policy": {"kind": "counters", "n1": 10, "n2": 1}, "alarm_level": "suspect"});
    create_session(&client(), &server, &session("fault", config(), extra)).await;
    let mut events = connect(&format!("{}/api/v1/sessions/fault/events", ws(&server))).await;
    let mut socket = ingest(&server, "fault").await;
    let mut frames = frames();
    for frame in &mut frames[2..] {
        let sat = frame["gnss_raw"]["sats"]
            .as_array_mut()
            .unwrap()
            .iter_mut()
            .find(|s| s["id"] == FAULTY)
            .unwrap();
        sat["pr"] = json!(sat["pr"].as_f64().unwrap() + 200.0);
    }
    let (results, others) = stream(&mut socket, &frames).await;

    // Clean epochs: the satellite is used and nothing is excluded.
    for r in &results[..2] {
        let m = &r["monitors"]["gnss"];
        assert_eq!(satellite(m, FAULTY)["used"], true, "{m}");
        assert_eq!(m["excluded"], json!([]), "{m}");
    }
    // Faulty epochs: the satellite is excluded or left out, and the fix stays good.
    for r in &results[2..] {
        let m = &r["monitors"]["gnss"];
        let excluded = m["excluded"].as_array().unwrap().contains(&json!(FAULTY));
        let out = satellite(m, FAULTY)["used"] == false;
        assert!(excluded || out, "t = {}: {m}", r["t"]);
        assert!(horizontal_error(&m["position"]) < 10.0, "{m}");
        let residual = satellite(m, FAULTY)["residual"].as_f64().unwrap();
        assert!(residual > 100.0, "its residual shows the fault: {m}");
    }
    // The first faulty epoch fails the all-in-view test and excludes the satellite.
    let first = &results[2]["monitors"]["gnss"];
    assert_eq!(first["excluded"], json!([FAULTY]), "{first}");
    let raim = &first["tests"]["raim"];
    assert!(raim["test_ratio"].as_f64().unwrap() > 1.0, "{raim}");
    assert_eq!(satellite(first, FAULTY)["health"], "suspect", "{first}");
    // The all-in-view test holds the satellite; the fix after exclusion does not.
    let clocks = first["clocks"].as_object().unwrap().len();
    assert_eq!(
        raim["dof"].as_u64(),
        Some((used(first) + 1 - 3 - clocks) as u64),
        "{first}"
    );
    // Next epochs: the satellite, suspect, is left out of the all-in-view fix, whose
    // test passes; tested against the others' fix it still exceeds and is isolated.
    for r in &results[3..] {
        let m = &r["monitors"]["gnss"];
        assert_eq!(m["excluded"], json!([]), "{m}");
        assert_eq!(m["tests"]["raim"]["state"], "healthy", "{m}");
        assert_eq!(
            m["tests"]["raim"]["dof"].as_u64(),
            Some((used(m) - 3 - clocks) as u64),
            "{m}"
        );
        assert_eq!(satellite(m, FAULTY)["health"], "isolated", "{m}");
    }

    // The raim test's state change is announced on both sockets.
    let is_raim_change = |v: &Value| {
        v["type"] == "state"
            && v["monitor"] == "gnss"
            && v["test"] == "raim"
            && v["from"] == "healthy"
    };
    let change = others
        .iter()
        .find(|v| is_raim_change(v))
        .unwrap_or_else(|| panic!("a raim state change in {others:?}"));
    assert_eq!(change["t"], frames[2]["t"], "{change}");
    assert_eq!(change["to"], "suspect", "{change}");
    assert_eq!(change["session"], "fault");
    let (on_events, _) = recv_until(&mut events, is_raim_change).await;
    assert_eq!(&on_events, change);
    assert!(
        others
            .iter()
            .any(|v| v["type"] == "alarm" && v["test"] == "raim"),
        "alarm level suspect: {others:?}"
    );
    let stats = stats_after(&server, "fault", 5).await;
    let raim_stats = &stats["monitors"]["gnss"]["tests"]["raim"];
    assert_eq!(raim_stats["exceedances"], 1, "{raim_stats}");
    server.shutdown().await;
}
