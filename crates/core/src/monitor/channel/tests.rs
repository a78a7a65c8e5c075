//! Unit tests of the `channel` monitor: config refusals (one per field, with its exact
//! path), the main, stuck and drift tests, learning only from healthy data.
use std::collections::HashMap;

use super::*;
use crate::detect::{PolicyConfig, ThresholdSpec};
use crate::learn::{Dataset, ModelKind, ModelParams, NoProgress, train};
use crate::monitor::ConfigError;
use crate::monitor::MonitorSpec;
use crate::monitor::NoModels;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use serde_json::{Value, json};

fn spec(config: Value) -> MonitorSpec {
    MonitorSpec {
        kind: MonitorKind::Channel,
        config: crate::monitor::MonitorConfig::parse(MonitorKind::Channel, &config).unwrap(),
        policy: PolicyConfig::Classic,
        threshold: ThresholdSpec::PFa(1e-5),
    }
}

fn config_error(config: Value, models: &dyn ModelSource) -> ConfigError {
    let parsed = match crate::monitor::MonitorConfig::parse(MonitorKind::Channel, &config) {
        Ok(p) => p,
        Err(e) => return e,
    };
    let spec = MonitorSpec {
        config: parsed,
        ..spec(json!({"channels": []}))
    };
    match crate::monitor::build(&spec, models) {
        Err(BuildError::Config(e)) => e,
        Err(BuildError::ModelNotFound { field, id }) => {
            ConfigError::new(field, format!("no stored model '{id}'"))
        }
        Err(other) => panic!("expected a config error, got {other:?}"),
        Ok(_) => panic!("expected a config error, got a monitor"),
    }
}

/// A sinusoid with white noise of σ = 0.05, plus `step` from sample `at` on.
fn signal(len: usize, at: usize, step: f64, seed: u64) -> Vec<f64> {
    let mut rng = StdRng::seed_from_u64(seed);
    let noise = Normal::new(0.0, 0.05).unwrap();
    (0..len)
        .map(|k| {
            let s = (2.0 * std::f64::consts::PI * k as f64 / 25.0).sin() + noise.sample(&mut rng);
            if k >= at { s + step } else { s }
        })
        .collect()
}

fn epoch(k: usize, name: &str, v: Vec<f64>) -> Epoch {
    Epoch {
        t: k as f64,
        channels: Some(vec![(name.to_owned(), v)]),
        ..Default::default()
    }
}

/// Runs the series through the monitor; returns the k of every non-healthy epoch.
fn alarms(monitor: &mut dyn Monitor, series: &[f64]) -> Vec<usize> {
    let mut out = Vec::new();
    for (k, &y) in series.iter().enumerate() {
        let report = monitor.step(&epoch(k, "s", vec![y])).unwrap();
        if report
            .tests
            .iter()
            .any(|t| t.decision.health != Health::Healthy)
        {
            out.push(k);
        }
    }
    out
}

fn online_config() -> Value {
    json!({"channels": [{"name": "s", "predictor":
        {"online": {"window": 50, "gamma": 30.0, "sigma2": 9.0, "refresh": 1000}}}]})
}

#[test]
fn config_errors_name_the_field() {
    let e = config_error(json!({}), &NoModels);
    assert!(e.reason.contains("channels"), "{e}");
    let e = config_error(json!({"channels": []}), &NoModels);
    assert_eq!(e.field, "channels");
    let e = config_error(
        json!({"channels": [{"name": "a", "embedding": 0, "predictor": {"model": "x"}}]}),
        &NoModels,
    );
    assert_eq!(e.field, "channels[0].embedding");
    let e = config_error(
        json!({"channels": [{"name": "a", "predictor": {"model": "nope"}}]}),
        &NoModels,
    );
    assert_eq!(e.field, "channels[0].predictor.model");
    assert!(e.reason.contains("nope"), "{e}");
    let e = config_error(
        json!({"channels": [{"name": "a", "dim": 2, "predictor": {"model": "x"}}]}),
        &NoModels,
    );
    assert_eq!(e.field, "channels[0].predictor.model");
    assert!(e.reason.contains("one model per component"), "{e}");
    let e = config_error(
        json!({"channels": [{"name": "a", "predictor": {"kalman": 1}}]}),
        &NoModels,
    );
    assert_eq!(e.field, "channels[0].predictor");
    let mut c = online_config();
    let first = c["channels"][0].clone();
    c["channels"].as_array_mut().unwrap().push(first);
    let e = config_error(c, &NoModels);
    assert_eq!(e.field, "channels[1].name");
    let mut c = online_config();
    c["channels"][0]["outlier_filter"] = json!({"c": -1.0});
    assert_eq!(
        config_error(c, &NoModels).field,
        "channels[0].outlier_filter.c"
    );
    let mut c = online_config();
    c["channels"][0]["n"] = json!(0);
    assert_eq!(config_error(c, &NoModels).field, "channels[0].n");
    let mut c = online_config();
    c["channels"][0]["extra"] = json!(0);
    let e = config_error(c, &NoModels);
    assert!(e.field.starts_with("channels[0]."), "{e}");
    assert!(e.reason.contains("unknown field"), "{e}");
}

#[test]
fn stored_model_of_the_wrong_dimension_is_refused() {
    let (x, y) = embed_series(&signal(120, usize::MAX, 0.0, 1), 3);
    let data = Dataset::new(&x, Some(&y)).unwrap();
    let params =
        ModelParams::from_json(ModelKind::LsSvm, &json!({"gamma": 10.0, "sigma2": 5.0})).unwrap();
    let model = train(&params, None, &data, &NoProgress).unwrap().model;
    let models: HashMap<String, Arc<AnyModel>> =
        HashMap::from([("m3".to_owned(), Arc::new(model))]);
    let e = config_error(
        json!({"channels": [{"name": "s", "embedding": 5, "predictor": {"model": "m3"}}]}),
        &models,
    );
    assert_eq!(e.field, "channels[0].predictor.model");
    assert!(e.reason.contains("takes 3 inputs"), "{e}");
}

#[test]
fn embedding_pairs_the_last_m_values_with_the_next() {
    let (x, y) = embed_series(&[1.0, 2.0, 3.0, 4.0], 2);
    assert_eq!(x, vec![vec![1.0, 2.0], vec![2.0, 3.0]]);
    assert_eq!(y, vec![3.0, 4.0]);
    assert!(embed_series(&[1.0], 2).0.is_empty());
}

#[test]
fn clean_sinusoid_on_an_online_predictor_stays_healthy() {
    let mut m = crate::monitor::build(&spec(online_config()), &NoModels).unwrap();
    let series = signal(500, usize::MAX, 0.0, 2);
    assert_eq!(alarms(m.as_mut(), &series), Vec::<usize>::new());
}

#[test]
fn step_fault_on_an_online_predictor_is_detected_at_once() {
    let mut m = crate::monitor::build(&spec(online_config()), &NoModels).unwrap();
    let series = signal(500, 400, 1.0, 2);
    let a = alarms(m.as_mut(), &series);
    assert!(
        a.first().is_some_and(|&k| (400..=402).contains(&k)),
        "{a:?}"
    );
    // The window does not learn the faulty values: the fault stays flagged until the
    // freeze has lasted `max_freeze` (20) epochs.
    assert!((400..420).all(|k| a.contains(&k)), "{a:?}");
}

#[test]
fn stored_model_predictor_detects_a_step_and_not_the_clean_signal() {
    let train_series = signal(300, usize::MAX, 0.0, 3);
    let (x, y) = embed_series(&train_series, 5);
    let data = Dataset::new(&x, Some(&y)).unwrap();
    // Both stored kinds, with the raw residual and over its predictive σ.
    for kind in [ModelKind::LsSvm, ModelKind::LwLsSvm] {
        let params = ModelParams::from_json(kind, &json!({"gamma": 10.0, "sigma2": 5.0})).unwrap();
        let model = train(&params, None, &data, &NoProgress).unwrap().model;
        let models: HashMap<String, Arc<AnyModel>> =
            HashMap::from([("m".to_owned(), Arc::new(model))]);
        for scale in ["raw", "predictive"] {
            let config = json!({"channels": [{"name": "s", "residual_scale": scale,
                "predictor": {"model": "m"}}]});
            let mut m = crate::monitor::build(&spec(config.clone()), &models).unwrap();
            let clean = alarms(m.as_mut(), &signal(400, usize::MAX, 0.0, 4));
            assert!(clean.is_empty(), "{kind:?} {scale}: {clean:?}");
            let mut m = crate::monitor::build(&spec(config), &models).unwrap();
            let a = alarms(m.as_mut(), &signal(400, 300, 1.0, 4));
            let at_once = a.first().is_some_and(|&k| (300..303).contains(&k));
            assert!(at_once, "{kind:?} {scale}: {a:?}");
        }
    }
}

#[test]
fn vector_channel_predicts_each_component_and_checks_its_length() {
    let config = json!({"channels": [{"name": "v", "dim": 2, "embedding": 3, "predictor":
        {"online": {"window": 30, "gamma": 30.0, "sigma2": 9.0}}}]});
    let mut m = crate::monitor::build(&spec(config), &NoModels).unwrap();
    assert_eq!(m.tests().slots()[0].dof, 2);
    let a = signal(60, usize::MAX, 0.0, 5);
    let b = signal(60, usize::MAX, 0.0, 6);
    let mut last = None;
    for k in 0..60 {
        let e = Epoch {
            t: k as f64,
            channels: Some(vec![("v".to_owned(), vec![a[k], 2.0 * b[k]])]),
            ..Default::default()
        };
        m.check_epoch("mon", &e).unwrap();
        last = Some(m.step(&e).unwrap());
    }
    let Some(MonitorReport {
        outputs: Outputs::Channel {
            prediction,
            residual,
        },
        ..
    }) = last
    else {
        panic!("channel outputs")
    };
    assert_eq!(prediction["v"].len(), 2);
    assert_eq!(residual["v"].len(), 2);
    let bad = epoch(60, "v", vec![1.0]);
    assert!(matches!(
        m.check_epoch("mon", &bad),
        Err(EpochError::WrongLength {
            got: 1,
            want: 2,
            ..
        })
    ));
}

#[test]
fn reset_restarts_predictor_and_test() {
    let mut m = crate::monitor::build(&spec(online_config()), &NoModels).unwrap();
    let series = signal(300, 250, 5.0, 7);
    assert!(!alarms(m.as_mut(), &series).is_empty());
    m.reset();
    assert_eq!(m.tests().slots()[0].policy.health(), Health::Healthy);
    let report = m.step(&epoch(0, "s", vec![0.0])).unwrap();
    assert_eq!(
        report.outputs,
        Outputs::Channel {
            prediction: BTreeMap::new(),
            residual: BTreeMap::new()
        },
        "no prediction before the history is refilled"
    );
    // Other names in the epoch are ignored.
    assert!(
        m.step(&epoch(1, "other", vec![1.0, 2.0]))
            .unwrap()
            .tests
            .is_empty()
    );
}

/// The online config with `field` set to `value` on channel 0.
fn online_with(field: &str, value: Value) -> Value {
    let mut c = online_config();
    c["channels"][0][field] = value;
    c
}

/// The test names of the monitor built from `config`, in bank order.
fn test_names(config: Value) -> Vec<String> {
    let m = crate::monitor::build(&spec(config), &NoModels).unwrap();
    m.tests()
        .slots()
        .iter()
        .map(|s| s.name.to_string())
        .collect()
}

#[test]
fn every_new_field_is_refused_at_its_exact_path() {
    let cases = [
        ("variance", json!("plain"), "channels[0].variance"),
        ("min_blocks", json!(1), "channels[0].min_blocks"),
        ("max_blocks", json!(5), "channels[0].max_blocks"),
        ("max_blocks", json!(20_000), "channels[0].max_blocks"),
        ("n", json!(1_000_000), "channels[0].n"),
        ("stuck", json!({"k": 1}), "channels[0].stuck.k"),
        ("stuck", json!({"k": "eight"}), "channels[0].stuck.k"),
        ("stuck", json!({"p_fa": 0.0}), "channels[0].stuck.p_fa"),
        ("stuck", json!({"p_fa": 1.5}), "channels[0].stuck.p_fa"),
        ("stuck", json!({"kk": 3}), "channels[0].stuck"),
        ("stuck", json!("yes"), "channels[0].stuck"),
        ("drift", json!({"windows": []}), "channels[0].drift.windows"),
        (
            "drift",
            json!({"windows": [30, 1]}),
            "channels[0].drift.windows[1]",
        ),
        (
            "drift",
            json!({"windows": [30, 5000]}),
            "channels[0].drift.windows[1]",
        ),
        ("drift", json!({"window": 30}), "channels[0].drift"),
        ("drift", json!(3), "channels[0].drift"),
        ("guard", json!(1_000_000), "channels[0].guard"),
        ("guard", json!(-1), "channels[0].guard"),
        ("max_freeze", json!(1_000_000), "channels[0].max_freeze"),
        ("max_freeze", json!("long"), "channels[0].max_freeze"),
    ];
    for (field, value, path) in cases {
        let e = config_error(online_with(field, value.clone()), &NoModels);
        assert!(e.field.starts_with(path), "{field} = {value}: {e}");
    }
    // Batch-means block counts do not go with the successive-difference variance.
    let mut c = online_with("variance", json!("successive_difference"));
    c["channels"][0]["min_blocks"] = json!(20);
    assert_eq!(config_error(c, &NoModels).field, "channels[0].min_blocks");
    // A channel named like another channel's stuck test clashes with it.
    let mut c = online_config();
    let mut second = c["channels"][0].clone();
    second["name"] = json!("s.stuck");
    c["channels"].as_array_mut().unwrap().push(second);
    let e = config_error(c, &NoModels);
    assert_eq!(e.field, "channels[1].name", "{e}");
}

#[test]
fn a_config_stored_before_the_new_fields_loads_with_the_calibrated_test_and_a_stuck_test() {
    // As written by an earlier release: `n` and `min_differences`, nothing newer.
    let old = json!({"channels": [{"name": "s", "n": 10, "min_differences": 30,
        "predictor": {"online": {"window": 50, "gamma": 30.0, "sigma2": 9.0}}}]});
    assert_eq!(test_names(old.clone()), ["s", "s.stuck"]);
    let mut m = crate::monitor::build(&spec(old), &NoModels).unwrap();
    assert!(alarms(m.as_mut(), &signal(300, usize::MAX, 0.0, 8)).is_empty());
    let mut on = online_with("drift", json!(true));
    on["channels"][0]["stuck"] = json!(false);
    assert_eq!(test_names(on), ["s", "s.drift"]);
    let stuck = test_names(online_with("stuck", json!({"k": 4})));
    assert_eq!(stuck, ["s", "s.stuck"]);
    // The stuck test keeps its own p_fa (1e-6 → χ²(1) 23.93) under the monitor's 1e-5.
    let m = crate::monitor::build(&spec(online_config()), &NoModels).unwrap();
    assert!((m.tests().slots()[1].threshold - 23.928).abs() < 1e-3);
    assert!((m.tests().slots()[0].threshold - 19.511).abs() < 1e-3);
}

#[test]
fn a_frozen_channel_is_flagged_by_its_stuck_test_within_k_samples() {
    let mut m = crate::monitor::build(&spec(online_config()), &NoModels).unwrap();
    let mut series = signal(400, usize::MAX, 0.0, 9);
    let held = series[300];
    for v in &mut series[300..] {
        *v = held;
    }
    let stuck = 1;
    let mut first = None;
    for (k, &y) in series.iter().enumerate() {
        let report = m.step(&epoch(k, "s", vec![y])).unwrap();
        let flagged = report
            .tests
            .iter()
            .any(|t| t.index == stuck && t.decision.health != Health::Healthy);
        if flagged && first.is_none() {
            first = Some(k);
        }
    }
    // The 8th repeated difference (k = 308) at the latest.
    assert!(first.is_some_and(|k| (300..=308).contains(&k)), "{first:?}");
}

#[test]
fn the_successive_difference_variance_is_still_available() {
    let config = online_with("variance", json!("successive_difference"));
    let mut m = crate::monitor::build(&spec(config.clone()), &NoModels).unwrap();
    assert!(alarms(m.as_mut(), &signal(400, usize::MAX, 0.0, 10)).is_empty());
    let mut m = crate::monitor::build(&spec(config), &NoModels).unwrap();
    let a = alarms(m.as_mut(), &signal(400, 300, 1.0, 10));
    assert!(a.first().is_some_and(|&k| (300..303).contains(&k)), "{a:?}");
}

#[test]
fn the_main_test_feeds_its_consistency_diagnostics_with_the_normalised_residual() {
    let mut m = crate::monitor::build(&spec(online_config()), &NoModels).unwrap();
    alarms(m.as_mut(), &signal(400, usize::MAX, 0.0, 11));
    let summary = m.tests().slots()[0].consistency.clone().summary().unwrap();
    assert!(summary.samples > 50, "{summary:?}");
    // Normalised by its own healthy second moment: a NIS mean near 1.
    assert!((0.5..2.0).contains(&summary.nis_mean), "{summary:?}");
    assert!(m.tests().slots()[1].consistency.clone().summary().is_none());
}

#[test]
fn a_drift_test_reports_under_its_own_name_and_flags_a_slow_ramp() {
    let config = json!({"channels": [{"name": "s", "drift": {"windows": [20]},
        "predictor": {"online": {"window": 50, "gamma": 30.0, "sigma2": 9.0}}}]});
    let mut m = crate::monitor::build(&spec(config), &NoModels).unwrap();
    let mut series = signal(900, usize::MAX, 0.0, 12);
    for (k, v) in series.iter_mut().enumerate().skip(700) {
        *v += 0.002 * (k - 700) as f64;
    }
    let (mut ran, mut flagged_clear) = (0, 0);
    for (k, &y) in series.iter().enumerate() {
        let report = m.step(&epoch(k, "s", vec![y])).unwrap();
        for t in report.tests.iter().filter(|t| &*t.name == "s.drift") {
            ran += 1;
            assert_eq!(t.statistic.dof, 1);
            if k < 700 && t.decision.health != Health::Healthy {
                flagged_clear += 1;
            }
        }
    }
    assert!(ran > 100, "{ran}");
    assert_eq!(flagged_clear, 0);
}

#[test]
fn nothing_is_learned_while_flagged_nor_during_the_guard_and_a_long_freeze_relearns() {
    let config = |guard: usize, max_freeze: usize| {
        let c = online_with("guard", json!(guard));
        let mut c = c;
        c["channels"][0]["max_freeze"] = json!(max_freeze);
        let crate::monitor::MonitorConfig::Channel(wire) = spec(c).config else {
            panic!("a channel config")
        };
        let config = ChannelMonitorConfig::from_wire(&wire, &NoModels).unwrap();
        ChannelMonitor::new(config, PolicyConfig::Classic, ThresholdSpec::PFa(1e-5)).unwrap()
    };
    let series = signal(400, usize::MAX, 0.0, 13);
    // A single 20σ spike at k = 300 is flagged by the window of 1 (and the window of 10
    // for a few epochs after): no sample is learned then, nor for 3 epochs after.
    let mut m = config(3, 0);
    let mut learned = Vec::new();
    for (k, &y) in series.iter().enumerate() {
        let y = if k == 300 { y + 1.0 } else { y };
        m.step(&epoch(k, "s", vec![y])).unwrap();
        // `frozen` is reset by every epoch that teaches.
        if (295..330).contains(&k) {
            learned.push((k, m.channels[0].frozen == 0));
        }
    }
    let first_frozen = learned.iter().find(|(_, l)| !l).map(|&(k, _)| k);
    assert_eq!(first_frozen, Some(300), "{learned:?}");
    let frozen_run = learned.iter().filter(|(_, l)| !l).count();
    assert!(
        frozen_run >= 4,
        "flagged epoch(s) plus a guard of 3: {learned:?}"
    );
    assert!(learned.last().unwrap().1, "learning again by k = 329");
    // A step that stays flagged: frozen for good with max_freeze 0, relearned after 20
    // epochs otherwise (so the flag then clears).
    let stepped = signal(500, 300, 1.0, 14);
    let run = |max_freeze| {
        let mut m = config(0, max_freeze);
        let a = alarms(&mut m, &stepped);
        a.iter().filter(|&&k| k >= 300).count()
    };
    let (forever, relearned) = (run(0), run(20));
    assert!(forever > 190, "{forever}");
    assert!(relearned < forever, "{relearned} vs {forever}");
}
