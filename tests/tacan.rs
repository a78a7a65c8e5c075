//! The seed 003 case end to end at reduced sizes (debug-mode friendly): simulated
//! TACAN flights, window features, a one-class SVM trained on clean flights, and the
//! `tacan` monitor scoring test flights with random jumps; and build errors.

use std::collections::HashMap;
use std::sync::Arc;

use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::features::tacan::TacanFeatureParams;
use navguard_core::learn::AnyModel;
use navguard_core::monitor::{self, BuildError, MonitorKind, MonitorSpec};
use navguard_sim::experiment::seed003::{self, Seed003Params, train_model};
use serde_json::json;

/// Seed 003 at reduced sizes: 10 training flights of 30 s (subsampled to 1,500 windows),
/// 2 test flights of 60 s with 20 jumps each (the paper's 200 per 10 min is one per 3 s;
/// here one per 3 s too).
fn reduced(noise: f64) -> Seed003Params {
    Seed003Params {
        noise_vars_m2: vec![noise],
        train_flights: 100,
        train_duration_s: 4.0,
        test_flights: 2,
        test_duration_s: 60.0,
        jumps: 20,
        train_samples: 3_000,
        // The INS error's correlation time shrinks with the flights (300 s → 10 s) so
        // 30 s training flights see as many INS error values as 20 min ones would.
        ins_tau_s: 10.0,
        ..Seed003Params::default()
    }
}

#[test]
fn seed_003_reaches_99_percent_mean_detection_at_noise_variance_20() {
    let result = seed003::run(reduced(20.0)).unwrap();
    let level = &result.levels[0];
    assert_eq!(level.flights.len(), 2);
    assert_eq!((level.train_n, level.train_total), (2_275, 9_100));
    let p = level.mean_detection();
    assert!(p >= 0.99, "mean detection probability {p}");
    let pooled = level.pooled();
    assert_eq!(pooled.jumps, 40);
    assert_eq!(pooled.jumps_detected, 40, "every jump is caught");
    // The boundary keeps about ν = 0.2 % of the clean training windows outside. On
    // flights it has not seen, this reduced training set (100 × 4 s) flags 2.1 % of the
    // clean windows; the full-size run (10 × 20 min, release) flags 0.18 %.
    let far = pooled.false_alarm_rate();
    assert!(far < 0.05, "{far}");
    assert!(pooled.accuracy() > 0.95);
    let text = seed003::render(&result);
    assert!(text.contains("P > 99 %, lowest flight 97.97 %"));
    assert_eq!(seed003::plots(&result).len(), 3);
}

fn spec(config: serde_json::Value) -> MonitorSpec {
    MonitorSpec {
        kind: MonitorKind::Tacan,
        config: navguard_core::monitor::MonitorConfig::parse(MonitorKind::Tacan, &config).unwrap(),
        policy: PolicyConfig::Classic,
        threshold: ThresholdSpec::default(),
    }
}

fn config_field(e: BuildError) -> String {
    match e {
        BuildError::Config(c) => c.field,
        BuildError::ModelNotFound { field, .. } => field,
        other => panic!("{other:?}"),
    }
}

#[test]
fn bad_tacan_configs_get_a_build_error_naming_the_field() {
    let p = Seed003Params {
        train_flights: 1,
        train_duration_s: 20.0,
        train_samples: 300,
        ..reduced(20.0)
    };
    let model = train_model(&p, 20.0).unwrap().model;
    let models: HashMap<String, Arc<AnyModel>> =
        HashMap::from([("oc".to_owned(), Arc::new(model))]);
    let station = json!({"lat": 34.25, "lon": 108.95, "h": 400.0});
    let ok = monitor::build(&spec(json!({"station": station, "model": "oc"})), &models);
    assert!(ok.is_ok());
    let cases = [
        (json!({"model": "oc"}), "station"),
        (
            json!({"station": {"lat": 34.0, "lon": 200.0, "h": 0.0}, "model": "oc"}),
            "station.lon",
        ),
        (json!({"station": station, "model": "nope"}), "model"),
        // A 3-feature model cannot serve the 4 features of crest = true.
        (
            json!({"station": station, "model": "oc", "crest": true}),
            "model",
        ),
        (
            json!({"station": station, "model": "oc", "window": 0}),
            "window",
        ),
    ];
    for (c, want) in cases {
        let e = monitor::build(&spec(c.clone()), &models)
            .map(|_| ())
            .unwrap_err();
        assert_eq!(config_field(e), want, "{c}");
    }
    assert_eq!(TacanFeatureParams::default().dim(), 3);
}
