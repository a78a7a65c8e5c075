//! Model REST end to end on a real server (port 0, temporary SQLite file):
//! training round trips for every kind with predictions equal to the same model
//! trained in-process, progress while training, every refusal with the field it
//! names, cancellation, restart, a session that uses a stored model, and ingest
//! that keeps flowing while a large model trains. No assertion on time: the
//! large job is cancelled, never awaited.

mod common;

use std::time::Duration;

use common::*;
use navguard::service::{Limits, Server};
use navguard_core::learn::{self, Dataset, ModelKind, ModelParams, NoProgress, Prediction};
use reqwest::StatusCode;
use serde_json::{Value, json};

async fn post(server: &Server, path: &str, body: &Value) -> (StatusCode, Value) {
    let resp = client()
        .post(format!("{}{path}", http(server)))
        .json(body)
        .send()
        .await
        .unwrap();
    let status = resp.status();
    let text = resp.text().await.unwrap();
    (status, serde_json::from_str(&text).unwrap_or(Value::Null))
}

async fn get(server: &Server, path: &str) -> (StatusCode, Value) {
    let resp = client()
        .get(format!("{}{path}", http(server)))
        .send()
        .await
        .unwrap();
    let status = resp.status();
    (status, resp.json().await.unwrap_or(Value::Null))
}

async fn delete(server: &Server, path: &str) -> StatusCode {
    client()
        .delete(format!("{}{path}", http(server)))
        .send()
        .await
        .unwrap()
        .status()
}

/// POSTs a training request, asserts 202 + Location, returns the id.
async fn train(server: &Server, body: &Value) -> String {
    let resp = client()
        .post(format!("{}/api/v1/models", http(server)))
        .json(body)
        .send()
        .await
        .unwrap();
    let status = resp.status();
    let location = resp
        .headers()
        .get("location")
        .map(|v| v.to_str().unwrap().to_owned());
    let record: Value = resp.json().await.unwrap();
    assert_eq!(status, 202, "{record}");
    let id = record["id"].as_str().unwrap().to_owned();
    assert_eq!(location, Some(format!("/api/v1/models/{id}")));
    assert_eq!(record["status"], "training");
    assert!(record["finished_ms"].is_null());
    check_progress(&record);
    id
}

/// A training record's progress has the documented shape.
fn check_progress(record: &Value) {
    let p = &record["progress"];
    let fraction = p["fraction"].as_f64().expect("progress.fraction");
    assert!((0.0..=1.0).contains(&fraction), "{record}");
    assert!(p["stage"].is_string(), "{record}");
}

/// Polls until the model leaves `training`; returns the final record and every
/// record seen while training.
/// Waits until job `id` holds a training slot (its stage is no longer `queued`), so a
/// job submitted next is certain to queue behind it.
async fn wait_running(server: &Server, id: &str) {
    for _ in 0..6000 {
        let (_, record) = get(server, &format!("/api/v1/models/{id}")).await;
        if record["status"] != "training" || record["progress"]["stage"] != "queued" {
            return;
        }
        tokio::time::sleep(std::time::Duration::from_millis(5)).await;
    }
    panic!("job {id} never left the queue");
}

async fn wait(server: &Server, id: &str) -> (Value, Vec<Value>) {
    let mut seen = Vec::new();
    for _ in 0..6000 {
        let (status, record) = get(server, &format!("/api/v1/models/{id}")).await;
        assert_eq!(status, 200, "{record}");
        if record["status"] != "training" {
            return (record, seen);
        }
        check_progress(&record);
        seen.push(record);
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    panic!("model {id} still training after 60 s");
}

async fn predict(server: &Server, id: &str, x: &[Vec<f64>]) -> (StatusCode, Value) {
    post(
        server,
        &format!("/api/v1/models/{id}/predict"),
        &json!({"x": x}),
    )
    .await
}

/// The same model trained in-process.
fn in_process(
    kind: ModelKind,
    params: &Value,
    x: &[Vec<f64>],
    y: Option<&[f64]>,
) -> learn::AnyModel {
    let params = ModelParams::from_json(kind, params).unwrap();
    let data = Dataset::new(x, y).unwrap();
    learn::train(&params, None, &data, &NoProgress)
        .unwrap()
        .model
}

fn in_process_prediction(model: &learn::AnyModel, x: &[Vec<f64>]) -> Value {
    let p: Prediction = model.predict(&Dataset::new(x, None).unwrap()).unwrap();
    serde_json::to_value(p).unwrap()
}

/// Two predictions agree to 1e-12 (relative): the REST model trained on the
/// numbers after a JSON round trip, which may move an input by one ulp.
fn assert_close(got: &Value, want: &Value) {
    let flat = |v: &Value| -> Vec<f64> {
        ["y", "decision"]
            .iter()
            .filter_map(|k| v[*k].as_array())
            .flatten()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let (g, w) = (flat(got), flat(want));
    assert!(!w.is_empty() && g.len() == w.len(), "{got} vs {want}");
    for (a, b) in g.iter().zip(&w) {
        assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0), "{got} vs {want}");
    }
    assert_eq!(got["label"], want["label"]);
}

fn sine(n: usize) -> (Vec<Vec<f64>>, Vec<f64>) {
    let x: Vec<Vec<f64>> = (0..n).map(|i| vec![i as f64 * 6.0 / n as f64]).collect();
    let y = x.iter().map(|v| v[0].sin()).collect();
    (x, y)
}

async fn serve(dir: &tempfile::TempDir, limits: Limits) -> Server {
    start(&dir.path().join("models.db"), None, limits).await
}

// ------------------------------------------------------------ round trips

// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_kind_trains_over_rest_and_predicts_like_the_same_model_in_process() {
    let dir = tempfile::tempdir().unwrap();
    let server = serve(&dir, Limits::default()).await;
    let (x, y) = sine(40);
    let queries = vec![vec![0.25], vec![1.0], vec![2.5], vec![4.75]];

    // lssvm, RBF: the REST model is bit-for-bit the in-process one.
    let params = json!({"gamma": 100.0, "sigma2": 0.5});
    let id = train(
        &server,
        &json!({"kind": "lssvm", "name": "sine", "params": params, "data": {"x": x, "y": y}}),
    )
    .await;
    let (record, _) = wait(&server, &id).await;
    assert_eq!(record["status"], "ready", "{record}");
    assert_eq!(
        (record["n"].as_u64(), record["dim"].as_u64()),
        (Some(40), Some(1))
    );
    assert_eq!(record["name"], "sine");
    assert_eq!(record["metrics"]["n"], 40);
    assert!(
        record["metrics"]["train_rmse"].as_f64().unwrap() < 0.05,
        "{record}"
    );
    assert!(record["finished_ms"].as_i64() >= record["created_ms"].as_i64());
    assert!(record.get("progress").is_none() && record.get("error").is_none());
    let (status, got) = predict(&server, &id, &queries).await;
    assert_eq!(status, 200, "{got}");
    let model = in_process(ModelKind::LsSvm, &params, &x, Some(&y));
    assert_close(&got, &in_process_prediction(&model, &queries));
    for (q, v) in queries.iter().zip(got["y"].as_array().unwrap()) {
        assert!(
            (v.as_f64().unwrap() - q[0].sin()).abs() < 0.05,
            "sin({}) ≈ {v}",
            q[0]
        );
    }

    // lssvm, linear kernel, γ large: ridge regression with a vanishing penalty
    // reproduces the line y = 2x + 1 exactly (closed form).
    let xl: Vec<Vec<f64>> = (0..10).map(|i| vec![i as f64]).collect();
    let yl: Vec<f64> = xl.iter().map(|v| 2.0 * v[0] + 1.0).collect();
    let id = train(
        &server,
        &json!({"kind": "lssvm", "params": {"kernel": "linear", "gamma": 1e9},
                "data": {"x": xl, "y": yl}}),
    )
    .await;
    assert_eq!(wait(&server, &id).await.0["status"], "ready");
    let (_, got) = predict(&server, &id, &[vec![20.0], vec![-3.0]]).await;
    let got: Vec<f64> = serde_json::from_value(got["y"].clone()).unwrap();
    assert!(
        (got[0] - 41.0).abs() < 1e-5 && (got[1] + 5.0).abs() < 1e-5,
        "{got:?}"
    );

    // svm: two separable clusters; labels ±1 and decisions as in-process.
    let xs: Vec<Vec<f64>> = (0..20)
        .map(|i| {
            let s = if i < 10 { -1.0 } else { 1.0 };
            vec![s * 2.0 + 0.1 * (i % 5) as f64, 0.2 * (i % 3) as f64]
        })
        .collect();
    let ys: Vec<f64> = (0..20).map(|i| if i < 10 { -1.0 } else { 1.0 }).collect();
    let svm_params = json!({"C": 10.0});
    let id = train(
        &server,
        &json!({"kind": "svm", "params": svm_params, "data": {"x": xs, "y": ys}}),
    )
    .await;
    assert_eq!(wait(&server, &id).await.0["status"], "ready");
    let q = vec![vec![-2.0, 0.0], vec![2.0, 0.0]];
    let (_, got) = predict(&server, &id, &q).await;
    assert_eq!(got["label"], json!([-1, 1]), "{got}");
    let model = in_process(ModelKind::Svm, &svm_params, &xs, Some(&ys));
    assert_close(&got, &in_process_prediction(&model, &q));

    // ocsvm: x alone; decisions as in-process, the far point outside.
    let xo: Vec<Vec<f64>> = (0..30)
        .map(|i| vec![(i as f64 * 0.7).sin(), (i as f64 * 1.3).cos()])
        .collect();
    let oc_params = json!({"nu": 0.1});
    let id = train(
        &server,
        &json!({"kind": "ocsvm", "params": oc_params, "data": {"x": xo}}),
    )
    .await;
    let (record, _) = wait(&server, &id).await;
    assert_eq!(record["status"], "ready", "{record}");
    let q = vec![vec![0.0, 0.0], vec![40.0, -40.0]];
    let (_, got) = predict(&server, &id, &q).await;
    assert_eq!(got["label"][1], -1, "{got}");
    let model = in_process(ModelKind::OcSvm, &oc_params, &xo, None);
    assert_close(&got, &in_process_prediction(&model, &q));

    // lw-lssvm: a local fit per query, as in-process; the record echoes `reg`
    // (the regularisation's wire name) for the old spelling `gamma` too.
    let lw_params = json!({"reg": 50.0, "sigma2": 0.5, "k": 12});
    let id = train(
        &server,
        &json!({"kind": "lw-lssvm", "params": lw_params, "data": {"x": x, "y": y}}),
    )
    .await;
    let (record, _) = wait(&server, &id).await;
    assert_eq!(record["status"], "ready", "{record}");
    assert_eq!(record["params"]["reg"], 50.0, "{record}");
    assert_eq!(record["params"]["k"], 12, "{record}");
    let (status, got) = predict(&server, &id, &queries).await;
    assert_eq!(status, 200, "{got}");
    let model = in_process(ModelKind::LwLsSvm, &lw_params, &x, Some(&y));
    assert_close(&got, &in_process_prediction(&model, &queries));
    let old_spelling = json!({"gamma": 50.0, "sigma2": 0.5, "k": 12});
    let same = in_process(ModelKind::LwLsSvm, &old_spelling, &x, Some(&y));
    assert_eq!(same, model);

    // Newest first.
    let (_, list) = get(&server, "/api/v1/models").await;
    let kinds: Vec<&str> = list["models"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["kind"].as_str().unwrap())
        .collect();
    assert_eq!(kinds, ["lw-lssvm", "ocsvm", "svm", "lssvm", "lssvm"]);
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cross_validation_job_shows_its_progress_then_its_choice() {
    let dir = tempfile::tempdir().unwrap();
    let server = serve(&dir, Limits::default()).await;
    // A job holding the single training slot keeps the CV job visibly `training`
    // (stage `queued`) until it is deleted: no race with a fast machine.
    let blocker = train(&server, &large_job()).await;
    wait_running(&server, &blocker).await;
    let (x, y) = sine(120);
    let id = train(
        &server,
        &json!({"kind": "lssvm", "params": {"gamma": "auto", "sigma2": "auto"},
                "cv": {"folds": 3, "seed": 7, "grid": 5},
                "data": {"x": x, "y": y}}),
    )
    .await;
    let (_, queued) = get(&server, &format!("/api/v1/models/{id}")).await;
    assert_eq!(queued["status"], "training");
    assert_eq!(
        queued["progress"],
        json!({"fraction": 0.0, "stage": "queued"})
    );
    assert_eq!(
        delete(&server, &format!("/api/v1/models/{blocker}")).await,
        204
    );
    let (record, seen) = wait(&server, &id).await;
    assert_eq!(record["status"], "ready", "{record}");
    // Every record seen while training had a fraction in [0, 1] and a stage
    // (checked in `wait`), and the fraction never went back.
    let fractions: Vec<f64> = seen
        .iter()
        .map(|r| r["progress"]["fraction"].as_f64().unwrap())
        .collect();
    assert!(fractions.windows(2).all(|w| w[0] <= w[1]), "{fractions:?}");
    let cv = &record["metrics"]["cv"];
    assert_eq!(cv["folds"], 3, "{record}");
    assert!(cv["error"].as_f64().unwrap() < 0.01, "{record}");
    // The record shows the values CV chose, not "auto".
    assert_eq!(record["params"]["reg"], cv["reg"]);
    assert_eq!(record["params"]["sigma2"], cv["sigma2"]);
    server.shutdown().await;
}

// ------------------------------------------------------------ refusals

// Over 80 lines: a table of cases checked one after another.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_training_requests_and_unknown_ids_get_clear_4xx() {
    let dir = tempfile::tempdir().unwrap();
    let limits = Limits {
        max_training_samples: 50,
        max_lssvm_samples: 30,
        ..Limits::default()
    };
    let server = serve(&dir, limits).await;
    let good = json!({"kind": "lssvm", "params": {"gamma": 10, "sigma2": 1},
                      "data": {"x": [[0.0], [1.0], [2.0]], "y": [0.0, 1.0, 4.0]}});
    let with = |path: &str, v: Value| {
        let mut b = good.clone();
        match b.pointer_mut(path) {
            Some(slot) => *slot = v,
            None => {
                let (parent, key) = path.rsplit_once('/').unwrap();
                b.pointer_mut(parent).unwrap()[key] = v;
            }
        }
        b
    };
    let many: Vec<Vec<f64>> = (0..40).map(|i| vec![i as f64]).collect();
    let many_y: Vec<f64> = (0..40).map(f64::from).collect();
    let cases = [
        ("empty", with("/data/x", json!([])), "data.x"),
        (
            "ragged",
            with("/data/x", json!([[0.0], [1.0, 1.0], [2.0]])),
            "data.x[1]",
        ),
        (
            "null",
            with("/data/x", json!([[0.0], [1.0], [null]])),
            "data.x[2][0]",
        ),
        ("length", with("/data/y", json!([0.0, 1.0])), "data.y"),
        ("no y", with("/data", json!({"x": [[0.0]]})), "data.y"),
        ("gamma", with("/params/gamma", json!(-1.0)), "params.gamma"),
        (
            "unknown param",
            with("/params/gama", json!(1.0)),
            "params.gama",
        ),
        ("kind", with("/kind", json!("random-forest")), "kind"),
        ("no kind", json!({"data": {"x": [[0.0]]}}), "kind"),
        ("folds", with("/cv", json!({"folds": 1})), "cv.folds"),
        ("folds > n", with("/cv", json!({"folds": 4})), "cv.folds"),
        ("cv field", with("/cv", json!({"flods": 3})), "cv.flods"),
        ("extra", with("/colour", json!("red")), "colour"),
        (
            "ocsvm y",
            json!({"kind": "ocsvm", "data": {"x": [[0.0]], "y": [1.0]}}),
            "data.y",
        ),
        (
            "svm labels",
            json!({"kind": "svm", "data": {"x": [[0.0], [1.0]], "y": [1.0, 2.0]}}),
            "data.y[1]",
        ),
    ];
    for (what, body, field) in cases {
        let (status, answer) = post(&server, "/api/v1/models", &body).await;
        assert_eq!(status, 422, "{what}: {answer}");
        assert_eq!(answer["error"]["code"], "invalid", "{what}");
        assert_eq!(answer["error"]["field"], field, "{what}: {answer}");
    }
    // Python's json.dumps writes NaN for a non-finite float: 422, not 400.
    let resp = client()
        .post(format!("{}/api/v1/models", http(&server)))
        .header("content-type", "application/json")
        .body(r#"{"kind": "lssvm", "data": {"x": [[0.0], [NaN]], "y": [1, 2]}}"#)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 422);
    // Over the limits: 413.
    let too_many: Vec<Vec<f64>> = (0..51).map(|i| vec![i as f64]).collect();
    let (status, _) = post(
        &server,
        "/api/v1/models",
        &json!({"kind": "ocsvm", "data": {"x": too_many}}),
    )
    .await;
    assert_eq!(status, 413);
    let (status, answer) = post(
        &server,
        "/api/v1/models",
        &json!({"kind": "lssvm", "data": {"x": many, "y": many_y}}),
    )
    .await;
    assert_eq!(status, 413, "{answer}");
    // Nothing refused was stored.
    let (_, list) = get(&server, "/api/v1/models").await;
    assert_eq!(list["models"], json!([]));

    // Unknown ids: 404 everywhere.
    let unknown = "/api/v1/models/m-0123456789abcdef";
    assert_eq!(get(&server, unknown).await.0, 404);
    assert_eq!(delete(&server, unknown).await, 404);
    let (status, answer) = predict(&server, "m-0123456789abcdef", &[vec![1.0]]).await;
    assert_eq!(
        (status, &answer["error"]["code"]),
        (StatusCode::NOT_FOUND, &json!("not_found"))
    );

    // A ready model refuses inputs of the wrong dimension or non-finite ones.
    let id = train(&server, &good).await;
    assert_eq!(wait(&server, &id).await.0["status"], "ready");
    let (status, answer) = predict(&server, &id, &[vec![1.0, 2.0]]).await;
    assert_eq!(
        (status.as_u16(), &answer["error"]["field"]),
        (422, &json!("x"))
    );
    let (status, answer) = post(
        &server,
        &format!("/api/v1/models/{id}/predict"),
        &json!({"x": [[1.0], [null]]}),
    )
    .await;
    assert_eq!(
        (status.as_u16(), &answer["error"]["field"]),
        (422, &json!("x[1][0]"))
    );
    let (status, _) = post(&server, &format!("/api/v1/models/{id}/predict"), &json!({})).await;
    assert_eq!(status, 422);

    // A model whose training fails says why, and refuses to predict (409).
    let failing = json!({"kind": "lssvm", "params": {"gamma": 10, "sigma2": 1},
                         "data": {"x": [[1.0], [1.0], [1.0]], "y": [0.0, 1.0, 2.0]}});
    let id = train(&server, &failing).await;
    let (record, _) = wait(&server, &id).await;
    if record["status"] == "failed" {
        assert!(
            record["error"].as_str().is_some_and(|e| !e.is_empty()),
            "{record}"
        );
        assert!(record.get("metrics").is_none());
        let (status, answer) = predict(&server, &id, &[vec![1.0]]).await;
        assert_eq!(
            (status.as_u16(), &answer["error"]["code"]),
            (409, &json!("conflict"))
        );
    }
    server.shutdown().await;
}

// ------------------------------------------------------------ jobs and ingest

/// A job long enough to still be running after a short stream: LS-SVM with a
/// full cross-validation grid on a few hundred samples (tens of seconds in
/// debug builds; it is cancelled, never awaited).
fn large_job() -> Value {
    let (x, y) = sine(400);
    json!({"kind": "lssvm", "name": "large", "params": {"gamma": "auto", "sigma2": "auto"},
           "cv": {"folds": 10, "grid": 20}, "data": {"x": x, "y": y}})
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn training_never_blocks_ingest_and_delete_cancels_the_job() {
    let dir = tempfile::tempdir().unwrap();
    let server = serve(&dir, Limits::default()).await;
    let large = train(&server, &large_job()).await;
    wait_running(&server, &large).await;
    // A second job waits for the single training slot.
    let (x, y) = sine(20);
    let small =
        json!({"kind": "lssvm", "params": {"gamma": 10, "sigma2": 1}, "data": {"x": x, "y": y}});
    let queued = train(&server, &small).await;
    let (_, record) = get(&server, &format!("/api/v1/models/{queued}")).await;
    assert_eq!(record["progress"]["stage"], "queued", "{record}");

    // Meanwhile a session processes a stream: every epoch gets its result.
    let model = CvModel {
        q: 0.01,
        sigma: 1.0,
        p0: 10.0,
    };
    let body = cv_session(
        "ingest",
        &model,
        json!({"kind": "classic"}),
        json!({}),
        true,
    );
    create_session(&client(), &server, &body).await;
    let mut socket = ingest(&server, "ingest").await;
    let z = model.measurements(400, 11, |_| 0.0);
    let frames = epochs(&z, 0);
    let mut results = 0;
    for batch in frames.chunks(50) {
        send(&mut socket, &json!(batch)).await;
        for _ in 0..batch.len() {
            let (message, _) = recv_until(&mut socket, |m| m["type"] == "result").await;
            assert!(message["monitors"]["cv"]["tests"].is_object(), "{message}");
            results += 1;
        }
    }
    assert_eq!(results, 400);
    let (_, stats) = get(&server, "/api/v1/sessions/ingest/stats").await;
    assert_eq!(stats["epochs"], 400, "{stats}");

    // The large model is still training: ingest did not wait for it.
    let (_, record) = get(&server, &format!("/api/v1/models/{large}")).await;
    assert_eq!(record["status"], "training", "{record}");
    check_progress(&record);

    // DELETE cancels it: gone at once, and its slot passes to the queued job.
    assert_eq!(
        delete(&server, &format!("/api/v1/models/{large}")).await,
        204
    );
    assert_eq!(
        get(&server, &format!("/api/v1/models/{large}")).await.0,
        404
    );
    let (record, _) = wait(&server, &queued).await;
    assert_eq!(record["status"], "ready", "{record}");
    let (_, list) = get(&server, "/api/v1/models").await;
    assert_eq!(list["models"].as_array().unwrap().len(), 1);
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn models_survive_a_restart_and_interrupted_jobs_fail_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let (x, y) = sine(30);
    let queries = vec![vec![0.5], vec![3.0]];
    let (ready, interrupted, before) = {
        let server = serve(&dir, Limits::default()).await;
        let id = train(
            &server,
            &json!({"kind": "lssvm", "name": "kept", "params": {"gamma": 50, "sigma2": 0.5},
                    "data": {"x": x, "y": y}}),
        )
        .await;
        assert_eq!(wait(&server, &id).await.0["status"], "ready");
        let (_, before) = predict(&server, &id, &queries).await;
        let interrupted = train(&server, &large_job()).await;
        server.shutdown().await;
        (id, interrupted, before)
    };
    let server = serve(&dir, Limits::default()).await;
    let (_, record) = get(&server, &format!("/api/v1/models/{ready}")).await;
    assert_eq!(
        (&record["status"], &record["name"]),
        (&json!("ready"), &json!("kept"))
    );
    assert!(record["metrics"]["train_rmse"].is_number(), "{record}");
    let (status, after) = predict(&server, &ready, &queries).await;
    assert_eq!(status, 200);
    assert_eq!(after, before);
    let (_, record) = get(&server, &format!("/api/v1/models/{interrupted}")).await;
    assert_eq!(record["status"], "failed", "{record}");
    assert_eq!(record["error"], "server restarted during training");
    // A failed model can be deleted, and stays deleted across a restart.
    assert_eq!(
        delete(&server, &format!("/api/v1/models/{interrupted}")).await,
        204
    );
    server.shutdown().await;
    let server = serve(&dir, Limits::default()).await;
    let (_, list) = get(&server, "/api/v1/models").await;
    let ids: Vec<&str> = list["models"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["id"].as_str().unwrap())
        .collect();
    assert_eq!(ids, [ready.as_str()]);
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_session_builds_its_monitor_from_a_stored_model_and_keeps_it_after_delete() {
    let dir = tempfile::tempdir().unwrap();
    let server = serve(&dir, Limits::default()).await;
    // Three TACAN window features (mean, variance, shape factor) of normal windows.
    let x: Vec<Vec<f64>> = (0..40)
        .map(|i| {
            let t = i as f64;
            vec![
                0.5 + 0.1 * (t * 0.7).sin(),
                4.0 + 0.5 * (t * 1.1).cos(),
                1.2 + 0.02 * (t * 0.3).sin(),
            ]
        })
        .collect();
    let id = train(
        &server,
        &json!({"kind": "ocsvm", "params": {"nu": 0.1}, "data": {"x": x}}),
    )
    .await;
    assert_eq!(wait(&server, &id).await.0["status"], "ready");
    let station = json!({"lat": 34.0, "lon": 108.0, "h": 500.0});
    let session = |sid: &str, model: &str| {
        json!({"id": sid, "monitors": [{"name": "tacan", "type": "tacan",
               "config": {"station": station, "model": model}}]})
    };
    let (status, answer) = post(
        &server,
        "/api/v1/sessions",
        &session("t0", "m-ffffffffffffffff"),
    )
    .await;
    assert_eq!(status, 422, "{answer}");
    assert_eq!(answer["error"]["field"], "monitors[0].config.model");
    let (status, answer) = post(&server, "/api/v1/sessions", &session("t1", &id)).await;
    assert_eq!(status, 201, "{answer}");
    // Deleting the model leaves the live session running with its copy.
    assert_eq!(delete(&server, &format!("/api/v1/models/{id}")).await, 204);
    assert_eq!(get(&server, "/api/v1/sessions/t1").await.0, 200);
    let (status, _) = post(&server, "/api/v1/sessions", &session("t2", &id)).await;
    assert_eq!(status, 422);
    server.shutdown().await;
    // After a restart the session cannot be rebuilt; the server starts without it.
    let server = serve(&dir, Limits::default()).await;
    assert_eq!(get(&server, "/api/v1/sessions/t1").await.0, 404);
    assert_eq!(get(&server, "/healthz").await.0, 200);
    server.shutdown().await;
}

// ------------------------------------------------------------ features

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn features_are_computed_over_rest_and_bad_requests_name_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let server = serve(&dir, Limits::default()).await;
    // Haar, level 1, absolute energies of [1..8]: approximation (a+b)/√2 and
    // detail (a−b)/√2 per pair; energies Σ (a+b)²/2 = (9+49+121+225)/2 = 202
    // and Σ (a−b)²/2 = 4 · 1/2 = 2 (their sum is Σ i² = 204, Parseval).
    let signal: Vec<f64> = (1..=8).map(f64::from).collect();
    let (status, got) = post(
        &server,
        "/api/v1/features",
        &json!({"kind": "wavelet-packet", "signal": signal, "wavelet": "db1", "level": 1, "normalize": false}),
    )
    .await;
    assert_eq!(status, 200, "{got}");
    let e: Vec<Vec<f64>> = serde_json::from_value(got["features"].clone()).unwrap();
    assert_eq!(e.len(), 1);
    assert!(
        (e[0][0] - 202.0).abs() < 1e-9 && (e[0][1] - 2.0).abs() < 1e-9,
        "{e:?}"
    );
    // The same through the library.
    let params =
        serde_json::from_value(json!({"wavelet": "db1", "level": 1, "normalize": false})).unwrap();
    assert_eq!(
        e[0],
        navguard_core::features::wavelet::packet_energies(&signal, &params).unwrap()
    );

    let ins: Vec<f64> = (0..12).map(|i| 1000.0 + i as f64).collect();
    let tacan: Vec<f64> = ins
        .iter()
        .enumerate()
        .map(|(i, r)| r + (i % 3) as f64)
        .collect();
    let (status, got) = post(
        &server,
        "/api/v1/features",
        &json!({"kind": "tacan-window", "ins_range_m": ins, "tacan_range_m": tacan, "window": 4, "crest": false}),
    )
    .await;
    assert_eq!(status, 200, "{got}");
    let params = serde_json::from_value(json!({"window": 4, "crest": false})).unwrap();
    let want = navguard_core::features::tacan::series_features(&ins, &tacan, &params).unwrap();
    assert_eq!(want.len(), 9);
    assert_eq!(got["features"], json!(want));

    let cases = [
        (json!({"kind": "fft", "signal": [1.0]}), "kind"),
        (json!({"signal": [1.0]}), "kind"),
        (
            json!({"kind": "wavelet-packet", "signal": [1.0, null]}),
            "signal[1]",
        ),
        (
            json!({"kind": "wavelet-packet", "wavelet": "db1", "level": 1}),
            "signal",
        ),
        (
            json!({"kind": "wavelet-packet", "signal": [1.0, 2.0], "wavelet": "db9"}),
            "wavelet",
        ),
        (
            json!({"kind": "tacan-window", "ins_range_m": [1.0, 2.0, 3.0]}),
            "tacan_range_m",
        ),
        (
            json!({"kind": "tacan-window", "ins_range_m": [1.0], "tacan_range_m": [1.0], "colour": 1}),
            "colour",
        ),
    ];
    for (body, field) in cases {
        let (status, answer) = post(&server, "/api/v1/features", &body).await;
        assert_eq!(status, 422, "{body}: {answer}");
        assert_eq!(answer["error"]["field"], field, "{body}: {answer}");
    }
    server.shutdown().await;
}
