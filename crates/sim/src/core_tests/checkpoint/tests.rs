//! Unit tests of monitor checkpoints, part 1: for each kind, a monitor restored mid-fault
//! from another's checkpoint steps exactly as one that never stopped (reports and final
//! checkpoints bit for bit), on seeded scenarios; and every f64 survives the format.

use std::collections::HashMap;
use std::sync::Arc;

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use serde_json::{Value, json};

use super::*;
use navguard_core::detect::{Health, PolicyConfig, ThresholdSpec};
use navguard_core::epoch::{Aid, Epoch};
use navguard_core::learn::{AnyModel, Dataset, ModelKind, ModelParams, NoProgress, train};
use navguard_core::monitor::rimu::{GyroClassifier, RimuConfig, RimuMonitor};
use navguard_core::monitor::{
    ModelSource, Monitor, MonitorConfig, MonitorReport, MonitorSpec, NoModels, Outputs, build,
};

/// Steps `m` through `epochs`, keeping every report.
pub(super) fn run(m: &mut dyn Monitor, epochs: &[Epoch]) -> Vec<MonitorReport> {
    epochs
        .iter()
        .enumerate()
        .map(|(k, e)| m.step(e).unwrap_or_else(|err| panic!("epoch {k}: {err}")))
        .collect()
}

/// Exact equality of two runs: `PartialEq` (as the service compares), and the `Debug` text,
/// which tells `-0.0` from `0.0` and every other pair of distinct f64 but NaNs.
fn assert_same_reports(got: &[MonitorReport], want: &[MonitorReport]) {
    assert_eq!(got.len(), want.len());
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert_eq!(g, w, "epoch {k} after the checkpoint");
        assert_eq!(
            format!("{g:?}"),
            format!("{w:?}"),
            "epoch {k} after the checkpoint"
        );
    }
}

/// Whether some test of `m` is suspect or isolated now.
fn some_test_unhealthy(m: &dyn Monitor) -> bool {
    m.tests()
        .slots()
        .iter()
        .any(|s| s.policy.health() != Health::Healthy)
}

/// The resume check: A steps every epoch; B steps the first `n1` and is checkpointed (mid
/// fault: some test suspect or isolated); C is built afresh from the same spec, restores
/// B's bytes and steps the rest. C's reports equal A's over the rest, bit for bit, and so
/// do their checkpoints at the end. A fresh monitor that is not restored reports otherwise
/// over the rest, so the state carried is what makes them equal. Returns B's checkpoint.
pub(super) fn assert_resumes_exactly(
    build: &dyn Fn() -> Box<dyn Monitor>,
    epochs: &[Epoch],
    n1: usize,
) -> Vec<u8> {
    let (first, rest) = epochs.split_at(n1);
    let mut a = build();
    run(a.as_mut(), first);
    let want = run(a.as_mut(), rest);

    let mut b = build();
    run(b.as_mut(), first);
    assert!(
        some_test_unhealthy(b.as_ref()),
        "the checkpoint is taken mid-fault"
    );
    let bytes = b.checkpoint().unwrap();
    assert_eq!(
        b.checkpoint().unwrap(),
        bytes,
        "checkpointing changes nothing"
    );

    let mut c = build();
    c.restore(&bytes).unwrap();
    assert_eq!(c.checkpoint().unwrap(), bytes, "restored as saved");
    let got = run(c.as_mut(), rest);
    assert_same_reports(&got, &want);
    assert_eq!(c.checkpoint().unwrap(), a.checkpoint().unwrap());

    let mut fresh = build();
    assert_ne!(
        run(fresh.as_mut(), rest),
        want,
        "a monitor without the state reports otherwise"
    );
    bytes
}

fn spec(
    kind: MonitorKind,
    config: Value,
    policy: PolicyConfig,
    threshold: ThresholdSpec,
) -> MonitorSpec {
    MonitorSpec {
        kind,
        config: MonitorConfig::parse(kind, &config).unwrap(),
        policy,
        threshold,
    }
}

/// seed 004's counters.
fn counters() -> PolicyConfig {
    PolicyConfig::counters_default()
}

/// The 2-state constant-velocity model (position measured, σ = 1), with the residual's
/// drift and stuck tests when `guards`.
fn cv_config(guards: bool) -> Value {
    let mut c = json!({
        "f": [[1.0, 1.0], [0.0, 1.0]],
        "h": [[1.0, 0.0]],
        "q": [[0.25, 0.5], [0.5, 1.0]],
        "r": [[1.0]],
        "x0": [0.0, 0.0],
        "p0": [[10.0, 0.0], [0.0, 10.0]]
    });
    if guards {
        c["drift"] = json!({"windows": [5, 20]});
        c["stuck"] = json!({});
    }
    c
}

/// A linear monitor on [`cv_config`] under counters at p_fa 1e-3.
pub(super) fn cv_monitor(guards: bool) -> Box<dyn Monitor> {
    let s = spec(
        MonitorKind::Linear,
        cv_config(guards),
        counters(),
        ThresholdSpec::PFa(1e-3),
    );
    build(&s, &NoModels).unwrap()
}

/// `len` epochs of a target moving at 0.5 per epoch seen with σ = 1 (seeded), every
/// seventh without `z`, and a step of `step` on `[at, at + 30)`.
pub(super) fn cv_epochs(len: usize, at: usize, step: f64, seed: u64) -> Vec<Epoch> {
    let mut rng = StdRng::seed_from_u64(seed);
    (0..len)
        .map(|k| {
            let noise: f64 = rng.sample(StandardNormal);
            let fault = if (at..at + 30).contains(&k) {
                step
            } else {
                0.0
            };
            Epoch {
                t: k as f64,
                z: (k % 7 != 3).then(|| vec![0.5 * k as f64 + noise + fault]),
                ..Default::default()
            }
        })
        .collect()
}

#[test]
fn a_linear_monitor_restored_mid_fault_steps_as_one_that_never_stopped() {
    let epochs = cv_epochs(300, 150, 30.0, 1);
    let bytes = assert_resumes_exactly(&|| cv_monitor(true), &epochs, 155);
    assert_eq!(checkpoint_kind(&bytes), Ok(MonitorKind::Linear));
}

#[test]
fn thresholds_and_policies_are_the_checkpoints() {
    let mut b = cv_monitor(false);
    b.tests_mut()
        .set_spec(ThresholdSpec::Threshold(4.0))
        .unwrap();
    b.tests_mut()
        .set_policy(PolicyConfig::Counters { n1: 3, n2: 2 });
    run(b.as_mut(), &cv_epochs(40, 20, 8.0, 2));
    let mut c = cv_monitor(false);
    c.restore(&b.checkpoint().unwrap()).unwrap();
    let slot = &c.tests().slots()[0];
    assert_eq!(slot.threshold, 4.0);
    assert_eq!(c.tests().spec(), ThresholdSpec::Threshold(4.0));
    assert_eq!(slot.policy, b.tests().slots()[0].policy);
    assert_eq!(c.tests().policy(), PolicyConfig::Counters { n1: 3, n2: 2 });
}

/// The ship of seed 004 (10 Hz INS, GNSS, DVL, CNS) for 150 s with an 80 m GNSS jump east
/// on [80, 120) s.
pub(super) fn ship_epochs() -> (crate::Scenario, Vec<Epoch>) {
    use crate::{Channel, Fault, FaultKind};
    let faults = vec![Fault {
        aid: Aid::Gnss,
        channel: Channel::Position,
        component: 0,
        kind: FaultKind::Step { value: 80.0 },
        start_s: 80.0,
        end_s: Some(120.0),
    }];
    let scenario = crate::scenario::ship_with(5, faults, 150.0).unwrap();
    let epochs = scenario.epochs.iter().map(|e| e.epoch.clone()).collect();
    (scenario, epochs)
}

/// A federated monitor for the ship (its config from the scenario, drift and stuck tests
/// at their defaults) under counters at p_fa 1e-3.
pub(super) fn ship_monitor(scenario: &crate::Scenario) -> Box<dyn Monitor> {
    let s = MonitorSpec {
        kind: MonitorKind::Federated,
        config: MonitorConfig::Federated(scenario.monitor_config()),
        policy: counters(),
        threshold: ThresholdSpec::PFa(1e-3),
    };
    build(&s, &NoModels).unwrap()
}

#[test]
fn a_federated_monitor_restored_mid_fault_steps_as_one_that_never_stopped() {
    let (scenario, epochs) = ship_epochs();
    // t = 85 s: the GNSS test has seen five epochs of the jump.
    let n1 = epochs.iter().position(|e| e.t >= 85.0).unwrap();
    let build = || ship_monitor(&scenario);
    let bytes = assert_resumes_exactly(&build, &epochs, n1);
    // The checkpoint of the GNSS test's health: the isolated aid is saved with it.
    let mut c = build();
    c.restore(&bytes).unwrap();
    let gnss = c.tests().index_of("gnss").unwrap();
    assert_ne!(c.tests().slots()[gnss].policy.health(), Health::Healthy);
}

/// A sinusoid with white noise of σ = 0.05 (seeded), plus `step` on `[at, at + 40)`.
fn signal(len: usize, at: usize, step: f64, seed: u64) -> Vec<f64> {
    let mut rng = StdRng::seed_from_u64(seed);
    (0..len)
        .map(|k| {
            let noise: f64 = rng.sample(StandardNormal);
            let s = (2.0 * std::f64::consts::PI * k as f64 / 25.0).sin() + 0.05 * noise;
            if (at..at.saturating_add(40)).contains(&k) {
                s + step
            } else {
                s
            }
        })
        .collect()
}

/// An LS-SVM trained on a clean sinusoid embedded with m = 5.
fn channel_model() -> Arc<AnyModel> {
    let (x, y) = navguard_core::monitor::channel::embed_series(&signal(300, usize::MAX, 0.0, 3), 5);
    let data = Dataset::new(&x, Some(&y)).unwrap();
    let params =
        ModelParams::from_json(ModelKind::LsSvm, &json!({"gamma": 10.0, "sigma2": 5.0})).unwrap();
    Arc::new(train(&params, None, &data, &NoProgress).unwrap().model)
}

/// Two channels: `s` on an online LS-SVM with the outlier filter, the batch-means T_a and
/// the stuck and drift tests; `t` on a stored model with seed 000's successive-difference
/// T_a and the stuck and drift tests.
pub(super) fn channel_config(online_window: usize) -> Value {
    json!({"channels": [
        {"name": "s", "predictor": {"online": {"window": online_window, "gamma": 30.0, "sigma2": 9.0}},
         "outlier_filter": {"c": 3}, "stuck": {"k": 6}, "drift": {"windows": [30]}, "guard": 5},
        {"name": "t", "predictor": {"model": "m"}, "variance": "successive_difference",
         "drift": true}
    ]})
}

pub(super) fn channel_monitor(models: &dyn ModelSource, online_window: usize) -> Box<dyn Monitor> {
    let s = spec(
        MonitorKind::Channel,
        channel_config(online_window),
        counters(),
        ThresholdSpec::PFa(1e-4),
    );
    build(&s, models).unwrap()
}

pub(super) fn channel_models() -> HashMap<String, Arc<AnyModel>> {
    HashMap::from([("m".to_owned(), channel_model())])
}

/// Both channels of [`channel_config`], a step of 1 on each from 250 (every fifth epoch
/// without `t`).
pub(super) fn channel_epochs() -> Vec<Epoch> {
    let (s, t) = (signal(400, 250, 1.0, 4), signal(400, 250, 1.0, 5));
    (0..400)
        .map(|k| {
            let mut channels = vec![("s".to_owned(), vec![s[k]])];
            if k % 5 != 2 {
                channels.push(("t".to_owned(), vec![t[k]]));
            }
            Epoch {
                t: k as f64,
                channels: Some(channels),
                ..Default::default()
            }
        })
        .collect()
}

#[test]
fn a_channel_monitor_restored_mid_fault_steps_as_one_that_never_stopped() {
    let models = channel_models();
    let epochs = channel_epochs();
    assert_resumes_exactly(&|| channel_monitor(&models, 50), &epochs, 262);
}

pub(super) fn rimu_monitor() -> Box<dyn Monitor> {
    // A stand-in for the C-SVC (as in the rimu tests): fault when the lowest wavelet band
    // holds most of the energy.
    let classifier: GyroClassifier = Arc::new(|phi: &[f64]| phi[0] - 0.5);
    let config = RimuConfig::from_json(&json!({})).unwrap();
    Box::new(
        RimuMonitor::new(
            config,
            Some(classifier),
            counters(),
            ThresholdSpec::Threshold(39.81),
        )
        .unwrap(),
    )
}

/// Seed 002's steady flight, 22–28 s at 100 Hz, with a 6σ bias on gyro 1 from 25 s.
pub(super) fn rimu_epochs() -> Vec<Epoch> {
    use crate::rimu::{GyroFaultKind, RimuSimParams, simulate};
    let params = RimuSimParams::steady(7, Some((1, GyroFaultKind::Bias(6.0))));
    simulate(&params)
        .unwrap()
        .samples
        .iter()
        .map(|s| Epoch {
            t: s.t,
            gyros: Some(s.gyros.clone()),
            ..Default::default()
        })
        .collect()
}

#[test]
fn a_rimu_monitor_restored_mid_fault_steps_as_one_that_never_stopped() {
    let epochs = rimu_epochs();
    // The bias starts at 25 s: checkpoint 20 epochs after gyro 1 is isolated.
    let reports = run(rimu_monitor().as_mut(), &epochs);
    let isolated_at = reports
        .iter()
        .position(|r| matches!(&r.outputs, Outputs::Rimu { isolated, .. } if isolated == &[1]))
        .expect("gyro 1 is isolated");
    assert!(epochs[isolated_at].t >= 25.0);
    assert_resumes_exactly(&rimu_monitor, &epochs, isolated_at + 20);
}

/// The reduced seed 003 training set of the tacan tests: 100 clean 4 s flights.
fn tacan_model() -> Arc<AnyModel> {
    use crate::experiment::seed003::{Seed003Params, train_model};
    use navguard_core::features::tacan::TacanFeatureParams;
    let p = Seed003Params {
        noise_vars_m2: vec![20.0],
        train_flights: 100,
        train_duration_s: 4.0,
        train_samples: 3_000,
        ins_tau_s: 10.0,
        features: TacanFeatureParams {
            window: 10,
            crest: false,
        },
        ..Seed003Params::default()
    };
    Arc::new(train_model(&p, 20.0).unwrap().model)
}

/// A tacan monitor's spec and model (counters), and a clean 20 s flight with a 200 m jump
/// on samples 400–402 and every 50th epoch without the range (ignored by the monitor).
pub(super) fn tacan_case() -> (MonitorSpec, HashMap<String, Arc<AnyModel>>, Vec<Epoch>) {
    use crate::tacan::{TacanFlightParams, default_station, simulate_flight};
    let models = HashMap::from([("m".to_owned(), tacan_model())]);
    let station = default_station();
    let config = json!({
        "station": {"lat": station.lat.to_degrees(), "lon": station.lon.to_degrees(), "h": station.h},
        "model": "m"
    });
    let s = spec(
        MonitorKind::Tacan,
        config,
        counters(),
        ThresholdSpec::default(),
    );
    let mut flight = simulate_flight(&TacanFlightParams {
        seed: 12,
        duration_s: 20.0,
        jumps: 0,
        ins_tau_s: 10.0,
        ..TacanFlightParams::default()
    })
    .unwrap();
    for k in 400..403 {
        let r = flight.epochs[k].tacan_range_m.unwrap();
        flight.epochs[k].tacan_range_m = Some(r + 200.0);
    }
    for e in flight.epochs.iter_mut().step_by(50) {
        e.tacan_range_m = None;
    }
    (s, models, flight.epochs)
}

#[test]
fn a_tacan_monitor_restored_mid_fault_steps_as_one_that_never_stopped() {
    let (s, models, epochs) = tacan_case();
    assert_resumes_exactly(&|| build(&s, &models).unwrap(), &epochs, 405);
}
