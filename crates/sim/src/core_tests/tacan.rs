//! The unit tests of `navguard_core::monitor::tacan` that run the simulator (moved out of
//! the core: navguard-sim depends on navguard-core, not the reverse).

use std::collections::HashMap;

use serde_json::{Value, json};

use crate::experiment::seed003::{Seed003Params, train_model};
use crate::tacan::{TacanFlightParams, default_station, simulate_flight};
use navguard_core::detect::Health;
use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::features::tacan::TacanFeatureParams;
use navguard_core::learn::{AnyModel, Standardizer};
use navguard_core::monitor::tacan::*;
use navguard_core::monitor::{BuildError, MonitorKind, Outputs};
use navguard_core::monitor::{MonitorConfig, MonitorSpec, NoModels};
use std::sync::Arc;

fn config(model: &str) -> Value {
    let s = default_station();
    json!({
        "station": {"lat": s.lat.to_degrees(), "lon": s.lon.to_degrees(), "h": s.h},
        "model": model
    })
}

fn spec(config: Value, policy: PolicyConfig) -> MonitorSpec {
    MonitorSpec {
        kind: MonitorKind::Tacan,
        config: MonitorConfig::parse(MonitorKind::Tacan, &config).unwrap(),
        policy,
        threshold: ThresholdSpec::default(),
    }
}

fn field(e: BuildError) -> String {
    match e {
        BuildError::Config(c) => c.field,
        BuildError::ModelNotFound { field, .. } => field,
        other => panic!("{other:?}"),
    }
}

/// The reduced seed 003 training set of `tests/tacan.rs` (100 clean 4 s flights at
/// 20 m², INS error correlation time 10 s), with the experiment's default model.
fn small_model(crest: bool) -> Arc<AnyModel> {
    let p = Seed003Params {
        noise_vars_m2: vec![20.0],
        train_flights: 100,
        train_duration_s: 4.0,
        train_samples: 3_000,
        ins_tau_s: 10.0,
        features: TacanFeatureParams { window: 10, crest },
        ..Seed003Params::default()
    };
    Arc::new(train_model(&p, 20.0).unwrap().model)
}

/// A clean 20 s test flight unlike any training flight.
fn flight() -> crate::tacan::TacanFlight {
    simulate_flight(&TacanFlightParams {
        seed: 12,
        duration_s: 20.0,
        jumps: 0,
        ins_tau_s: 10.0,
        ..TacanFlightParams::default()
    })
    .unwrap()
}

#[test]
fn defaults_are_the_papers_window_without_crest() {
    let c = TacanConfig::from_json(&config("m-1")).unwrap();
    assert_eq!(c.features, TacanFeatureParams::default());
    assert_eq!((c.model.as_str(), c.max_gap_s), ("m-1", DEFAULT_MAX_GAP_S));
    assert!((c.station.lat - default_station().lat).abs() < 1e-15);
}

#[test]
fn invalid_configs_are_refused_naming_the_field() {
    let station = json!({"lat": 34.0, "lon": 108.0, "h": 400.0});
    let cases = [
        (json!({"model": "m"}), "station"),
        (json!({"station": 3, "model": "m"}), "station"),
        (
            json!({"station": {"lat": 95.0, "lon": 0.0, "h": 0.0}, "model": "m"}),
            "station.lat",
        ),
        (
            json!({"station": {"lat": 0.0, "lon": "x", "h": 0.0}, "model": "m"}),
            "station.lon",
        ),
        (
            json!({"station": {"lat": 0.0, "lon": 0.0}, "model": "m"}),
            "station",
        ),
        (
            json!({"station": {"lat": 0.0, "lon": 0.0, "h": 0.0, "x": 1}, "model": "m"}),
            "station.x",
        ),
        (json!({"station": station}), "model"),
        (json!({"station": station, "model": 7}), "model"),
        (
            json!({"station": station, "model": "m", "window": 1}),
            "window",
        ),
        (
            json!({"station": station, "model": "m", "window": 2.5}),
            "window",
        ),
        (
            json!({"station": station, "model": "m", "crest": "yes"}),
            "crest",
        ),
        (
            json!({"station": station, "model": "m", "max_gap_s": 0}),
            "max_gap_s",
        ),
        (
            json!({"station": station, "model": "m", "windw": 10}),
            "windw",
        ),
    ];
    for (c, want) in cases {
        let e = TacanConfig::from_json(&c).unwrap_err();
        assert_eq!(e.field, want, "{c}");
    }
    let e = navguard_core::monitor::build(&spec(config("m-404"), PolicyConfig::Classic), &NoModels)
        .map(|_| ())
        .unwrap_err();
    assert_eq!(field(e), "model");
}

#[test]
fn a_model_of_the_wrong_dimension_is_refused() {
    let models = HashMap::from([("m".to_owned(), small_model(false))]);
    // The right one: ρ, scale and the standardiser are read from the model.
    let m = TacanMonitor::new(
        TacanConfig::from_json(&config("m")).unwrap(),
        models["m"].clone(),
        PolicyConfig::Classic,
        ThresholdSpec::default(),
    )
    .unwrap();
    assert!(m.decision_scale().is_some_and(|s| s > 0.0));
    assert_eq!(m.standardizer().map(Standardizer::dim), Some(3));
    let mut c = config("m");
    c["crest"] = json!(true);
    let e = navguard_core::monitor::build(&spec(c, PolicyConfig::Classic), &models)
        .map(|_| ())
        .unwrap_err();
    assert_eq!(field(e), "model");
}

#[test]
fn a_clean_stream_stays_healthy_and_a_200_m_jump_is_flagged() {
    let models = HashMap::from([("m".to_owned(), small_model(false))]);
    let mut monitor =
        navguard_core::monitor::build(&spec(config("m"), PolicyConfig::Classic), &models).unwrap();
    let mut f = flight();
    // A 200 m jump on 3 samples from sample 400.
    for k in 400..403 {
        let r = f.epochs[k].tacan_range_m.unwrap();
        f.epochs[k].tacan_range_m = Some(r + 200.0);
    }
    let mut clean_flags = 0;
    let mut clean = 0;
    for (k, e) in f.epochs.iter().enumerate() {
        let report = monitor.step(e).unwrap();
        if k < 9 {
            assert!(report.tests.is_empty(), "no test before the window is full");
            assert_eq!(report.outputs, empty());
            continue;
        }
        let o = &report.tests[0];
        assert_eq!((&*o.name, o.statistic.dof), ("range", 3));
        let Outputs::Tacan {
            features: Some(x),
            decision: Some(g),
        } = &report.outputs
        else {
            panic!("no outputs at {k}");
        };
        assert_eq!(x.len(), 3);
        // The test fails exactly when the point is outside the boundary.
        assert_eq!(o.statistic.exceeds(), *g < 0.0);
        let holds_jump = (400..412).contains(&k);
        if holds_jump {
            assert_eq!(o.decision.health, Health::Isolated, "jump window at {k}");
            assert!(o.statistic.test_ratio() > 1.0);
        } else {
            clean += 1;
            clean_flags += usize::from(o.decision.health != Health::Healthy);
        }
    }
    assert_eq!(clean, 491 - 12);
    assert!(clean_flags <= clean / 100, "{clean_flags} of {clean}");
    assert_eq!(
        monitor.tests().slots()[0].policy.health(),
        Health::Healthy,
        "healthy again at the end"
    );
    monitor.reset();
    assert!(monitor.step(&f.epochs[0]).unwrap().tests.is_empty());
}

#[test]
fn a_gap_restarts_the_window_and_epochs_without_both_blocks_are_ignored() {
    let models = HashMap::from([("m".to_owned(), small_model(false))]);
    let mut monitor =
        navguard_core::monitor::build(&spec(config("m"), PolicyConfig::Classic), &models).unwrap();
    let f = simulate_flight(&TacanFlightParams {
        seed: 13,
        duration_s: 2.0,
        jumps: 0,
        ..TacanFlightParams::default()
    })
    .unwrap();
    for e in &f.epochs[..10] {
        monitor.step(e).unwrap();
    }
    let mut no_tacan = f.epochs[10].clone();
    no_tacan.tacan_range_m = None;
    let r = monitor.step(&no_tacan).unwrap();
    assert!(r.tests.is_empty());
    assert!(matches!(
        r.outputs,
        Outputs::Tacan {
            decision: Some(_),
            ..
        }
    ));
    // 2 s later: the window starts afresh and needs 10 epochs again.
    let mut late = f.epochs[11].clone();
    late.t += 2.0;
    assert!(monitor.step(&late).unwrap().tests.is_empty());
}

/// The outputs of a step that ran no test (`tacan::empty`, private to the core).
fn empty() -> Outputs {
    Outputs::Tacan {
        features: None,
        decision: None,
    }
}
