//! The unit tests of `navguard_core::monitor::rimu` that run the simulator (moved out of
//! the core: navguard-sim depends on navguard-core, not the reverse).

use crate::rimu::{GyroFaultKind, RimuSimParams, simulate};
use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::epoch::Epoch;
use navguard_core::monitor::rimu::*;
use navguard_core::monitor::{
    BuildError, EpochError, Monitor, MonitorKind, MonitorReport, Outputs,
};
use navguard_core::monitor::{MonitorSpec, NoModels};
use serde_json::json;
use std::sync::Arc;

fn spec(config: serde_json::Value) -> MonitorSpec {
    MonitorSpec {
        kind: MonitorKind::Rimu,
        config: navguard_core::monitor::MonitorConfig::parse(MonitorKind::Rimu, &config).unwrap(),
        policy: PolicyConfig::Classic,
        threshold: ThresholdSpec::Threshold(39.81),
    }
}

/// A stand-in for the C-SVC: fault when the lowest band holds most of the energy
/// (white noise spreads it evenly, 1/8 per band; a bias or drift piles it into `aaa`).
fn low_band_classifier() -> GyroClassifier {
    Arc::new(|phi: &[f64]| phi[0] - 0.5)
}

fn run(
    monitor: &mut RimuMonitor,
    fault: Option<(usize, GyroFaultKind)>,
) -> Vec<(f64, MonitorReport)> {
    let sim = simulate(&RimuSimParams::steady(7, fault)).unwrap();
    sim.samples
        .iter()
        .map(|s| {
            let e = Epoch {
                t: s.t,
                gyros: Some(s.gyros.clone()),
                ..Default::default()
            };
            (s.t, monitor.step(&e).unwrap())
        })
        .collect()
}

fn monitor(config: serde_json::Value, classifier: Option<GyroClassifier>) -> RimuMonitor {
    let s = spec(config);
    let navguard_core::monitor::MonitorConfig::Rimu(wire) = s.config else {
        unreachable!("a rimu spec")
    };
    RimuMonitor::new(
        RimuConfig::try_from(wire).unwrap(),
        classifier,
        s.policy,
        s.threshold,
    )
    .unwrap()
}

#[test]
fn defaults_are_seed_002s_four_gyros_with_a_six_epoch_window() {
    let c = RimuConfig::from_json(&json!({})).unwrap();
    assert_eq!(c.parity.gyros(), 4);
    assert_eq!((c.fss_window, c.feature_window, c.t_i), (6, 96, 0.1));
    let m = monitor(json!({}), None);
    assert_eq!(&*m.tests().slots()[0].name, "parity");
    assert_eq!(m.tests().slots()[0].dof, 6);
}

#[test]
fn bad_configs_are_refused_naming_the_field() {
    let field = |v: serde_json::Value| RimuConfig::from_json(&v).unwrap_err().field;
    assert_eq!(field(json!({"h": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]})), "h");
    assert_eq!(field(json!({"h": [[1, 0], [0, 1, 0]]})), "h[0]");
    assert_eq!(field(json!({"sigma": [1e-3, 1e-3]})), "sigma");
    assert_eq!(field(json!({"sigma": [1e-3, 0.0, 1e-3, 1e-3]})), "sigma[1]");
    assert_eq!(field(json!({"fss_window": 0})), "fss_window");
    assert_eq!(field(json!({"feature_window": 100})), "feature_window");
    assert_eq!(field(json!({"wavelet": {"level": 0}})), "wavelet.level");
    assert_eq!(field(json!({"windw": 3})), "windw");
    let e = navguard_core::monitor::build(&spec(json!({"model": "m-0"})), &NoModels)
        .err()
        .unwrap();
    assert!(
        matches!(&e, BuildError::ModelNotFound { field, id } if field == "model" && id == "m-0"),
        "{e}"
    );
}

#[test]
fn wrong_number_of_gyros_is_refused_before_stepping() {
    let m = monitor(json!({}), None);
    let e = Epoch {
        gyros: Some(vec![0.0; 5]),
        ..Default::default()
    };
    assert!(matches!(
        m.check_epoch("imu", &e),
        Err(EpochError::WrongLength {
            got: 5,
            want: 4,
            ..
        })
    ));
}

#[test]
fn a_bias_is_detected_and_without_a_classifier_not_isolated() {
    let mut m = monitor(json!({}), None);
    let reports = run(&mut m, Some((0, GyroFaultKind::Bias(6.0))));
    let alarm = |from: f64, to: f64| {
        reports
            .iter()
            .any(|(t, r)| *t >= from && *t < to && r.tests.iter().any(|o| o.statistic.exceeds()))
    };
    assert!(!alarm(22.0, 25.0), "no false alarm before the fault");
    assert!(alarm(25.0, 26.0), "detected within a second");
    let Outputs::Rimu {
        isolated, parity, ..
    } = &reports.last().unwrap().1.outputs
    else {
        panic!()
    };
    assert!(isolated.is_empty());
    assert_eq!(parity.as_ref().map(Vec::len), Some(1));
}

#[test]
fn each_gyros_bias_is_isolated_and_omega_stays_clean() {
    for gyro in 0..4 {
        let mut m = monitor(json!({}), Some(low_band_classifier()));
        let reports = run(&mut m, Some((gyro, GyroFaultKind::Bias(6.0))));
        let Outputs::Rimu {
            isolated, omega, ..
        } = &reports.last().unwrap().1.outputs
        else {
            panic!()
        };
        assert_eq!(isolated, &vec![gyro], "gyro {gyro}");
        // With the faulty gyro out, ω's error is noise only: a few σ at most
        // (a 6σ bias left in would put ≥ 1.5σ on the affected axes).
        let w = omega.unwrap();
        let s = default_sigma();
        let truth = crate::rimu::Flight::Steady.omega(27.99);
        for k in 0..3 {
            assert!((w[k] - truth[k]).abs() < 4.0 * s, "gyro {gyro}: {w:?}");
        }
    }
}

#[test]
fn reset_forgets_the_isolation_and_the_window() {
    let mut m = monitor(json!({}), Some(low_band_classifier()));
    run(&mut m, Some((2, GyroFaultKind::Bias(6.0))));
    m.reset();
    let r = m
        .step(&Epoch {
            gyros: Some(vec![0.0; 4]),
            ..Default::default()
        })
        .unwrap();
    assert!(r.tests.is_empty(), "window restarts empty");
    assert!(matches!(r.outputs, Outputs::Rimu { ref isolated, .. } if isolated.is_empty()));
}
