//! `navguard calibrate` on simulated data with a known answer (docs/methods.md §M25),
//! and its `--out` bodies applied to a live session by `PUT`.

mod common;

use common::*;
use navguard::service::Limits;
use serde_json::{Value, json};

/// A random walk measured with noise σ = √2 while the model says σ = 1: λ ~ 2 χ²(1),
/// so the threshold for a rate of 1e-3 is ≈ 2 × 10.83.
fn mis_scaled_data(
    dir: &std::path::Path,
    epochs: usize,
) -> (std::path::PathBuf, std::path::PathBuf) {
    let mut g = Gauss::new(21);
    let lines: Vec<String> = (0..epochs)
        .map(|k| json!({"t": k as f64, "z": [2f64.sqrt() * g.normal()]}).to_string())
        .collect();
    let data = dir.join("walk.jsonl");
    std::fs::write(&data, lines.join("\n") + "\n").unwrap();
    let spec = json!({"id": "walk", "monitors": [{
        "name": "w", "type": "linear", "policy": {"kind": "counters"},
        "config": {"f": [[1.0]], "h": [[1.0]], "q": [[1e-8]], "r": [[1.0]], "x0": [0.0], "p0": [[1e-8]]}
    }]});
    let spec_file = dir.join("walk.session.json");
    std::fs::write(&spec_file, spec.to_string()).unwrap();
    (data, spec_file)
}

fn calibrate(args: &[&std::ffi::OsStr]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_navguard"))
        .arg("calibrate")
        .args(args)
        .output()
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn calibrate_proposes_the_known_threshold_and_its_body_applies_by_put() {
    let dir = tempfile::tempdir().unwrap();
    let (data, spec) = mis_scaled_data(dir.path(), 50_000);
    let out = dir.path().join("put.json");
    let run = calibrate(&[
        data.as_os_str(),
        "--session-spec".as_ref(),
        spec.as_os_str(),
        "--far".as_ref(),
        "1e-3".as_ref(),
        "--json".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let report: Value = serde_json::from_slice(&run.stdout).unwrap();
    // The main test only, calibrated on the first half and checked on the second.
    let tests = report[0]["tests"].as_array().unwrap();
    assert_eq!(tests.len(), 1, "{report}");
    let test = &tests[0];
    assert_eq!(
        (test["test"].as_str(), test["epochs"].as_u64()),
        (Some("residual"), Some(25_000))
    );
    assert_eq!(test["holdout_epochs"], 25_000, "{test}");
    assert!(test["holdout_rate"].as_f64().unwrap() <= 2e-3, "{test}");
    let threshold = test["threshold"].as_f64().unwrap();
    // The 17th-largest of 25,000 statistics: its rate is Beta(17, 24984), 6.8e-4 ± 1.7e-4,
    // so the threshold lies about 2 × 11.5, and above 2 × 13.5 with probability < 1e-4.
    assert!(
        (20.5..27.0).contains(&threshold),
        "{threshold} vs 2 × 10.83"
    );
    // The χ² threshold it replaces fails ≈ 2 % of these epochs, 20× the rate asked.
    assert!(
        (test["chi2_rate"].as_f64().unwrap() - 0.02).abs() < 0.003,
        "{test}"
    );

    // The body is a PUT body for the monitor, and the server takes it.
    let bodies: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let body = &bodies["w"];
    let server = start(&dir.path().join("c.db"), None, Limits::default()).await;
    let spec_body: Value = serde_json::from_str(&std::fs::read_to_string(&spec).unwrap()).unwrap();
    create_session(&client(), &server, &spec_body).await;
    let resp = client()
        .put(format!(
            "{}/api/v1/sessions/walk/monitors/w/threshold",
            http(&server)
        ))
        .json(body)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 200);
    let view: Value = resp.json().await.unwrap();
    let applied = view["tests"]["residual"]["threshold"].as_f64().unwrap();
    assert!(
        (applied - threshold).abs() < 1e-9 * threshold,
        "{applied} vs {threshold}"
    );
    assert_eq!(view["tests"]["residual"]["own"], true);
    server.shutdown().await;
}

#[test]
fn calibrate_refuses_data_too_short_for_the_rate_and_says_how_much_it_needs() {
    let dir = tempfile::tempdir().unwrap();
    let (data, spec) = mis_scaled_data(dir.path(), 2_000);
    let run = calibrate(&[
        data.as_os_str(),
        "--session-spec".as_ref(),
        spec.as_os_str(),
        "--far".as_ref(),
        "1e-4".as_ref(),
    ]);
    assert!(!run.status.success());
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        stdout.contains("refused: too short: 2000 epochs, the rate asked needs at least 59912"),
        "{stdout}"
    );
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("no test could be calibrated"), "{stderr}");
    // A bad file is named with its line.
    std::fs::write(&data, "{\"t\": 0, \"z\": [1]}\n{\"t\": 1, \"z\": [oops]}\n").unwrap();
    let run = calibrate(&[
        data.as_os_str(),
        "--session-spec".as_ref(),
        spec.as_os_str(),
    ]);
    assert!(!run.status.success());
    assert!(String::from_utf8_lossy(&run.stderr).contains("walk.jsonl:2"));
}
