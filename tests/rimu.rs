//! The `rimu` monitor end to end through `monitor::build` (docs/methods.md §M15, seed 002): a small
//! C-SVC trained in-test on simulated wavelet-packet windows isolates each gyro's bias
//! fault in steady flight; 5- and 6-gyro sets work; manoeuvres do not trip the parity
//! test; a model of the wrong kind or dimension is refused naming `model`.

use std::collections::HashMap;
use std::sync::Arc;

use nalgebra::DMatrix;
use navguard_core::detect::parity::SKEW;
use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::epoch::Epoch;
use navguard_core::learn::{self, AnyModel, Dataset, ModelKind, ModelParams, NoProgress};
use navguard_core::monitor::{self, BuildError, MonitorKind, MonitorSpec, Outputs};
use navguard_sim::experiment::seed002::{self, Seed002Params};
use navguard_sim::rimu::{GyroFaultKind, RimuSimParams};
use serde_json::{Value, json};

/// A reduced version of the paper's training set (400 + 288 windows).
fn small_classifier() -> HashMap<String, Arc<AnyModel>> {
    let params = Seed002Params {
        n_normal: 60,
        n_fault: 48,
        ..Seed002Params::default()
    };
    let (model, summary) = seed002::train_classifier(&params).expect("training");
    assert!(summary.test_accuracy > 0.95, "{summary:?}");
    [("svc".to_owned(), model)].into()
}

fn spec(config: Value) -> MonitorSpec {
    MonitorSpec {
        kind: MonitorKind::Rimu,
        config: navguard_core::monitor::MonitorConfig::parse(MonitorKind::Rimu, &config).unwrap(),
        policy: PolicyConfig::Classic,
        threshold: ThresholdSpec::Threshold(seed002::T_D),
    }
}

#[test]
fn steady_flight_isolates_each_gyros_bias_fault() {
    let models = small_classifier();
    let spec = spec(json!({"model": "svc"}));
    for gyro in 0..4 {
        for kind in [GyroFaultKind::Bias(5.0), GyroFaultKind::Bias(6.0)] {
            let sim = RimuSimParams::steady(11 + gyro as u64, Some((gyro, kind)));
            let out = seed002::run_case(&sim, &spec, &models).unwrap();
            let detected = out.detected_at.expect("detected");
            assert!(detected - 25.0 < 1.0, "gyro {gyro} {kind:?}: {detected}");
            let (t, isolated) = out.isolated.clone().expect("isolated");
            assert_eq!(isolated, vec![gyro], "{kind:?}");
            assert!(t >= detected && t - 25.0 < 1.0, "isolated at {t}");
            // Before the onset: no alarm (T_D = 39.81 at dof 6 is p_fa ≈ 1e-6).
            assert!(
                out.trace
                    .iter()
                    .all(|&(t, h, _)| t >= 25.0 || h.as_str() == "healthy")
            );
            // The last second's ω error is the noise of the remaining three gyros
            // (RMS 2.65σ or 1.73σ), not the fault's 5–6σ.
            let tail = &out.omega_sq[out.omega_sq.len() - 100..];
            let rms = (tail.iter().sum::<f64>() / tail.len() as f64).sqrt();
            assert!(
                rms < 3.5 * navguard_core::monitor::rimu::default_sigma(),
                "gyro {gyro}: {rms}"
            );
        }
    }
}

#[test]
fn parity_alone_detects_but_cannot_isolate_with_four_gyros() {
    let sim = RimuSimParams::steady(3, Some((1, GyroFaultKind::Bias(6.0))));
    let out = seed002::run_case(&sim, &spec(json!({})), &monitor::NoModels).unwrap();
    assert!(out.detected_at.is_some());
    assert!(out.isolated.is_none());
}

#[test]
fn a_climb_without_fault_leaves_the_parity_test_quiet() {
    // VH = 0: the manoeuvre's rates cancel in the parity residual.
    let sim = RimuSimParams::manoeuvring(5, None);
    let out = seed002::run_case(&sim, &spec(json!({})), &monitor::NoModels).unwrap();
    assert!(out.trace.iter().all(|&(_, h, _)| h.as_str() == "healthy"));
    assert!(out.trace.iter().map(|x| x.2).fold(0.0, f64::max) < seed002::T_D);
}

fn five_gyros() -> Vec<Vec<f64>> {
    // A cone of five at the skew angle (cos = 1/√3) around z.
    let s = (1.0 - SKEW * SKEW).sqrt();
    (0..5)
        .map(|i| {
            let a = 2.0 * std::f64::consts::PI * i as f64 / 5.0;
            vec![s * a.cos(), s * a.sin(), SKEW]
        })
        .collect()
}

fn six_gyros() -> Vec<Vec<f64>> {
    // Normals of a dodecahedron's faces: the classic six-gyro skewed set.
    let (a, b) = (0.525_731_112_119_133_6, 0.850_650_808_352_039_9);
    vec![
        vec![a, 0.0, b],
        vec![-a, 0.0, b],
        vec![b, a, 0.0],
        vec![b, -a, 0.0],
        vec![0.0, b, a],
        vec![0.0, b, -a],
    ]
}

#[test]
fn five_and_six_gyro_sets_detect_and_isolate_through_monitor_build() {
    let models = small_classifier();
    for (rows, bad) in [(five_gyros(), 3), (six_gyros(), 4)] {
        let m = rows.len();
        let h = DMatrix::from_fn(m, 3, |i, j| rows[i][j]);
        let config = json!({"h": rows, "sigma": navguard_core::monitor::rimu::default_sigma(), "model": "svc"});
        let spec = spec(config);
        let built = monitor::build(&spec, &models).unwrap();
        assert_eq!(built.tests().slots()[0].dof, 6 * (m as u32 - 3));
        let sim = RimuSimParams {
            h,
            ..RimuSimParams::steady(21, Some((bad, GyroFaultKind::Bias(6.0))))
        };
        let out = seed002::run_case(&sim, &spec, &models).unwrap();
        assert!(out.detected_at.is_some(), "m = {m}");
        assert_eq!(out.isolated.map(|x| x.1), Some(vec![bad]), "m = {m}");
        // A wrong-length epoch is refused before stepping.
        let e = Epoch {
            gyros: Some(vec![0.0; 4]),
            ..Default::default()
        };
        assert!(built.check_epoch("gyros", &e).is_err());
        // The parity vector has p = m − 3 elements.
        let mut fresh = monitor::build(&spec, &models).unwrap();
        let report = fresh
            .step(&Epoch {
                gyros: Some(vec![0.0; m]),
                ..Default::default()
            })
            .unwrap();
        let Outputs::Rimu { parity, omega, .. } = report.outputs else {
            panic!("rimu outputs")
        };
        assert_eq!(parity.map(|p| p.len()), Some(m - 3));
        assert_eq!(omega, Some([0.0; 3]));
    }
}

#[test]
fn a_model_of_the_wrong_kind_or_dimension_is_refused_naming_model() {
    let x: Vec<Vec<f64>> = (0..20).map(|i| vec![i as f64, 1.0, 0.0, 2.0]).collect();
    let y: Vec<f64> = (0..20).map(|i| if i < 10 { -1.0 } else { 1.0 }).collect();
    let params = ModelParams::from_json(ModelKind::Svm, &json!({"kernel": "linear"})).unwrap();
    let trained = learn::train(
        &params,
        None,
        &Dataset::new(&x, Some(&y)).unwrap(),
        &NoProgress,
    )
    .unwrap();
    let models: HashMap<String, Arc<AnyModel>> =
        [("four".to_owned(), Arc::new(trained.model))].into();
    for config in [json!({"model": "four"}), json!({"model": "missing"})] {
        match monitor::build(&spec(config), &models) {
            Err(BuildError::Config(e)) => assert_eq!(e.field, "model"),
            Err(BuildError::ModelNotFound { field, .. }) => assert_eq!(field, "model"),
            Err(other) => panic!("{other}"),
            Ok(_) => panic!("built"),
        }
    }
    // Level 2 gives 4 features: the same model now fits.
    let ok = json!({"model": "four", "wavelet": {"level": 2}, "feature_window": 96});
    assert!(monitor::build(&spec(ok), &models).is_ok());
}
