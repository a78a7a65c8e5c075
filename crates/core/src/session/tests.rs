//! The session core's rules, on a scripted monitor whose epochs say what it reports:
//! `z[k]` is test k's statistic (NaN: the test does not run), `u = [state, pl, al]` its
//! integrity (state 0 converging, 1 available, 2 unavailable), and `gyros` present makes
//! the step fail numerically.

use super::*;
use crate::detect::{PolicyConfig, ThresholdSpec};
use crate::filter::kalman::FilterError;
use crate::monitor::{Availability, CheckpointError, Integrity, Outputs, TestBank};
use Health::{Healthy as H, Isolated as I, Suspect as S};
use rand::{Rng, SeedableRng};

/// A monitor that reports what its epochs say (see the module's documentation).
struct Scripted {
    bank: TestBank,
    steps: u64,
}

impl Scripted {
    fn boxed(tests: &[(&str, u32)], threshold: f64, policy: PolicyConfig) -> Box<dyn Monitor> {
        let spec = ThresholdSpec::Threshold(threshold);
        Box::new(Scripted {
            bank: TestBank::new(tests, spec, policy).unwrap(),
            steps: 0,
        })
    }
}

impl Monitor for Scripted {
    fn kind(&self) -> MonitorKind {
        MonitorKind::Linear
    }
    fn tests(&self) -> &TestBank {
        &self.bank
    }
    fn tests_mut(&mut self) -> &mut TestBank {
        &mut self.bank
    }
    fn check_epoch(&self, _: &str, _: &Epoch) -> Result<(), EpochError> {
        Ok(())
    }
    fn step(&mut self, epoch: &Epoch) -> Result<MonitorReport, StepError> {
        if epoch.gyros.is_some() {
            return Err(StepError::Filter(FilterError::NotPositiveDefinite));
        }
        self.steps += 1;
        let values = epoch.z.clone().unwrap_or_default();
        let tests = values
            .iter()
            .enumerate()
            .take(self.bank.slots().len())
            .filter(|(_, v)| !v.is_nan())
            .map(|(k, &v)| self.bank.evaluate(k, v))
            .collect();
        let integrity = epoch.u.as_ref().map(|u| Integrity {
            state: [
                Availability::Converging,
                Availability::Available,
                Availability::Unavailable,
            ][u[0] as usize],
            protection_level: u[1],
            alert_limit: u[2],
        });
        let outputs = Outputs::Linear {
            innovation: None,
            x: vec![self.steps as f64],
        };
        Ok(MonitorReport {
            tests,
            outputs,
            integrity,
        })
    }
    fn reset(&mut self) {
        self.bank.reset();
        self.steps = 0;
    }
    fn checkpoint(&self) -> Result<Vec<u8>, CheckpointError> {
        rmp_serde::to_vec_named(&(self.steps, &self.bank))
            .map_err(|e| CheckpointError::Encode(e.to_string()))
    }
    fn restore(&mut self, bytes: &[u8]) -> Result<(), CheckpointError> {
        let (steps, saved): (u64, TestBank) =
            rmp_serde::from_slice(bytes).map_err(|e| CheckpointError::Decode(e.to_string()))?;
        self.bank = self
            .bank
            .restored(saved)
            .map_err(CheckpointError::Mismatch)?;
        self.steps = steps;
        Ok(())
    }
}

const COUNTERS: PolicyConfig = PolicyConfig::Counters { n1: 3, n2: 2 };

fn seat(name: &str, monitor: Box<dyn Monitor>, alarm_level: AlarmLevel) -> Seat {
    Seat {
        name: name.into(),
        monitor,
        alarm_level,
    }
}

/// One test `r` (dof 1, threshold 10) under counters N1 = 3, N2 = 2.
fn one(level: AlarmLevel) -> SessionCore {
    let m = Scripted::boxed(&[("r", 1)], 10.0, COUNTERS);
    SessionCore::new("s", vec![seat("m", m, level)], 60)
}

fn epoch(t: f64, z: &[f64], integrity: Option<u8>) -> Epoch {
    Epoch {
        t,
        z: Some(z.to_vec()),
        u: integrity.map(|s| vec![f64::from(s), 10.0 + f64::from(s), 25.0]),
        ..Epoch::default()
    }
}

/// Steps and commits one epoch; its effects.
fn run(core: &mut SessionCore, e: &Epoch) -> Vec<Effect> {
    let (reports, _) = core.step(e);
    let mut effects = Vec::new();
    if reports.iter().any(Option::is_some) {
        core.commit(e, &reports, &mut effects);
    }
    effects
}

/// Each effect as (kind, monitor, test or availability, to-state, severity).
fn brief(effects: &[Effect]) -> Vec<(&'static str, String, String, String, Option<Severity>)> {
    effects
        .iter()
        .map(|e| match e {
            Effect::State { change, entry } => {
                assert_eq!(entry.as_ref().map(|x| x.severity), change.severity);
                let to = format!("{:?}", change.to);
                (
                    "state",
                    change.monitor.clone(),
                    change.test.clone(),
                    to,
                    change.severity,
                )
            }
            Effect::Availability(a) => {
                let to = a.to.as_str().to_owned();
                ("availability", a.monitor.clone(), String::new(), to, None)
            }
            Effect::Standing(x) => {
                let to = format!("{:?}", x.state);
                (
                    "standing",
                    x.monitor.clone(),
                    x.test.clone(),
                    to,
                    Some(x.severity),
                )
            }
        })
        .collect()
}

fn state(
    test: &str,
    to: Health,
    severity: Option<Severity>,
) -> (&'static str, String, String, String, Option<Severity>) {
    (
        "state",
        "m".into(),
        test.into(),
        format!("{to:?}"),
        severity,
    )
}

/// Monitor `m`'s availability change to `to`, as [`brief`] shows it.
fn availability(to: &str) -> (&'static str, String, String, String, Option<Severity>) {
    ("availability", "m".into(), String::new(), to.into(), None)
}

/// Test `r`'s standing alarm in isolated, as [`brief`] shows it.
fn standing_r() -> (&'static str, String, String, String, Option<Severity>) {
    (
        "standing",
        "m".into(),
        "r".into(),
        "Isolated".into(),
        Some(Severity::Alarm),
    )
}

#[test]
fn under_the_default_level_suspect_is_a_warning_isolated_an_alarm_and_healthy_clears() {
    let mut core = one(AlarmLevel::Isolated);
    let mut seen = Vec::new();
    // 20 > 10 exceeds: suspect at once, isolated at the third exceedance (t3 > N2 = 2),
    // healthy once three clean epochs have counted t1 down to 0.
    for (k, v) in [1.0, 20.0, 20.0, 20.0, 1.0, 1.0, 1.0].iter().enumerate() {
        seen.extend(brief(&run(&mut core, &epoch(k as f64, &[*v], None))));
    }
    assert_eq!(
        seen,
        vec![
            state("r", S, Some(Severity::Warning)),
            state("r", I, Some(Severity::Alarm)),
            state("r", H, None),
        ]
    );
    let r = &core.stats().monitors["m"].tests["r"];
    assert_eq!((r.alarms, r.warnings), (1, 1));
    assert_eq!(core.stats().alarms(), 1);
    assert_eq!(core.stream_epochs(), 7);
    assert_eq!(core.last_t(), Some(6.0));
}

#[test]
fn under_the_suspect_level_entering_suspect_is_an_alarm() {
    let mut core = one(AlarmLevel::Suspect);
    let effects = run(&mut core, &epoch(0.0, &[20.0], None));
    assert_eq!(brief(&effects), vec![state("r", S, Some(Severity::Alarm))]);
}

#[test]
fn the_log_entry_carries_the_statistic_threshold_dof_and_the_episode_delay() {
    let mut core = one(AlarmLevel::Isolated);
    run(&mut core, &epoch(0.0, &[1.0], None));
    run(&mut core, &epoch(1.0, &[20.0], None));
    run(&mut core, &epoch(2.5, &[30.0], None));
    let effects = run(&mut core, &epoch(4.0, &[40.0], None));
    let Some(entry) = effects[0].entry() else {
        panic!("no entry in {effects:?}");
    };
    assert_eq!(
        (entry.statistic, entry.threshold, entry.dof),
        (40.0, 10.0, 1)
    );
    assert_eq!(entry.test_ratio, 4.0);
    // From the episode's first exceedance at t = 1 to the alarm at t = 4.
    assert_eq!(entry.delay_s, 3.0);
    assert_eq!(
        (entry.id, entry.raised_at_ms, entry.cleared_t),
        (0, 0, None)
    );
    assert_eq!((entry.session.as_str(), entry.monitor.as_str()), ("s", "m"));
}

#[test]
fn while_converging_every_change_is_a_warning_and_convergence_raises_the_standing_alarm() {
    let mut core = one(AlarmLevel::Isolated);
    let mut seen = Vec::new();
    for k in 0..4 {
        seen.extend(brief(&run(&mut core, &epoch(k as f64, &[20.0], Some(0)))));
    }
    assert_eq!(
        seen,
        vec![
            state("r", S, Some(Severity::Warning)),
            state("r", I, Some(Severity::Warning)),
        ]
    );
    let effects = run(&mut core, &epoch(4.0, &[20.0], Some(1)));
    assert_eq!(
        brief(&effects),
        vec![availability("available"), standing_r(),]
    );
    let Effect::Standing(entry) = &effects[1] else {
        unreachable!()
    };
    assert_eq!((entry.t, entry.statistic, entry.delay_s), (4.0, 20.0, 4.0));
    let r = &core.stats().monitors["m"].tests["r"];
    assert_eq!((r.alarms, r.warnings), (1, 2));
}

#[test]
fn a_change_on_the_epoch_that_converges_is_a_warning_then_raised_as_an_alarm() {
    let mut core = one(AlarmLevel::Isolated);
    for k in 0..2 {
        run(&mut core, &epoch(k as f64, &[20.0], Some(0)));
    }
    // The third exceedance isolates on the very epoch the monitor converges.
    let effects = run(&mut core, &epoch(2.0, &[20.0], Some(1)));
    assert_eq!(
        brief(&effects),
        vec![
            state("r", I, Some(Severity::Warning)),
            availability("available"),
            standing_r(),
        ]
    );
}

#[test]
fn a_suspect_test_at_convergence_stands_in_an_alarm_only_under_the_suspect_level() {
    for (level, standing) in [(AlarmLevel::Isolated, 0), (AlarmLevel::Suspect, 1)] {
        let mut core = one(level);
        run(&mut core, &epoch(0.0, &[20.0], Some(0)));
        run(&mut core, &epoch(1.0, &[20.0], Some(0)));
        // Still suspect (t1 = 1) when it converges.
        let effects = run(&mut core, &epoch(2.0, &[1.0], Some(1)));
        assert_eq!(core.stats().monitors["m"].tests["r"].state, S);
        let raised = effects
            .iter()
            .filter(|e| matches!(e, Effect::Standing(_)))
            .count();
        assert_eq!(raised, standing, "{level:?}");
    }
}

#[test]
fn a_first_integrity_epoch_already_available_is_a_change_from_converging() {
    let mut core = one(AlarmLevel::Isolated);
    let effects = run(&mut core, &epoch(0.0, &[1.0], Some(1)));
    let Effect::Availability(a) = &effects[0] else {
        panic!("{effects:?}");
    };
    assert_eq!(
        (a.from, a.to),
        (Availability::Converging, Availability::Available)
    );
    assert_eq!((a.protection_level, a.alert_limit), (11.0, 25.0));
    assert_eq!(effects.len(), 1, "nothing was held back: {effects:?}");
    // Not converging: a change after it is loud at once.
    let effects = run(&mut core, &epoch(1.0, &[20.0], Some(1)));
    assert_eq!(
        brief(&effects),
        vec![state("r", S, Some(Severity::Warning))]
    );
    assert_eq!(
        core.roster()[0].rule.availability,
        Some(Availability::Available)
    );
}

#[test]
fn unavailable_is_an_availability_change_never_an_alarm_and_raises_nothing_standing() {
    let mut core = one(AlarmLevel::Isolated);
    for k in 0..3 {
        run(&mut core, &epoch(k as f64, &[20.0], Some(1)));
    }
    let effects = run(&mut core, &epoch(3.0, &[20.0], Some(2)));
    assert_eq!(brief(&effects), vec![availability("unavailable")]);
}

#[test]
fn two_monitors_changing_on_one_epoch_come_in_session_order_then_availabilities() {
    let a = Scripted::boxed(&[("x", 1), ("y", 1)], 10.0, PolicyConfig::Classic);
    let b = Scripted::boxed(&[("x", 1)], 10.0, PolicyConfig::Classic);
    let seats = vec![
        seat("b", a, AlarmLevel::Isolated),
        seat("a", b, AlarmLevel::Isolated),
    ];
    let mut core = SessionCore::new("s", seats, 60);
    let effects = run(&mut core, &epoch(0.0, &[20.0, 30.0], Some(1)));
    let order: Vec<(String, String)> = brief(&effects)
        .into_iter()
        .map(|(kind, monitor, test, ..)| (monitor, format!("{kind}:{test}")))
        .collect();
    assert_eq!(
        order,
        vec![
            ("b".into(), "state:x".into()),
            ("b".into(), "state:y".into()),
            ("a".into(), "state:x".into()),
            ("b".into(), "availability:".into()),
            ("a".into(), "availability:".into()),
        ]
    );
    // Classic: isolated at once, an alarm (the first integrity epoch is not converging),
    // and not raised a second time as standing.
    assert!(
        effects[..3]
            .iter()
            .all(|e| e.entry().unwrap().severity == Severity::Alarm)
    );
}

#[test]
fn a_monitor_that_fails_numerically_changes_nothing_and_the_others_commit() {
    let a = Scripted::boxed(&[("r", 1)], 10.0, PolicyConfig::Classic);
    let b = Scripted::boxed(&[("r", 1)], 10.0, PolicyConfig::Classic);
    let seats = vec![
        seat("a", a, AlarmLevel::Isolated),
        seat("b", b, AlarmLevel::Isolated),
    ];
    let mut core = SessionCore::new("s", seats, 60);
    // Both monitors read the same script; fail the first by stepping it alone.
    let mut bad = epoch(0.0, &[20.0], None);
    bad.gyros = Some(vec![]);
    let mut engines = core.take_engines();
    let (first, failure) = step_epoch(&mut engines[..1], &bad);
    let (second, _) = step_epoch(&mut engines[1..], &epoch(0.0, &[20.0], None));
    core.put_engines(engines);
    assert!(matches!(failure, Some((0, StepError::Filter(_)))));
    let reports = vec![first[0].clone(), second[0].clone()];
    let mut effects = Vec::new();
    core.commit(&epoch(0.0, &[20.0], None), &reports, &mut effects);
    let monitors: Vec<String> = brief(&effects).into_iter().map(|b| b.1).collect();
    assert_eq!(monitors, vec!["b".to_owned()]);
    assert_eq!(core.stats().monitors["a"].epochs, 0);
    assert_eq!(core.stats().monitors["b"].epochs, 1);
    assert_eq!(core.engines()[0].tests().slots()[0].policy.health(), H);
}

#[test]
fn step_slice_stops_at_the_first_failure_with_the_others_stepped() {
    let a = Scripted::boxed(&[("r", 1)], 10.0, PolicyConfig::Classic);
    let b = Scripted::boxed(&[("r", 1)], 10.0, PolicyConfig::Classic);
    let mut bad = epoch(1.0, &[1.0], None);
    bad.gyros = Some(vec![]);
    let epochs = vec![epoch(0.0, &[1.0], None), bad, epoch(2.0, &[1.0], None)];
    let slice = step_slice(vec![a, b], epochs, 0, Duration::from_secs(60));
    assert_eq!(slice.stepped.len(), 2);
    assert!(matches!(slice.failure, Some((1, 0, _))));
    assert!(slice.stepped[1].iter().all(Option::is_none));
    assert_eq!(slice.epochs.len(), 3);
}

#[test]
fn the_rule_on_a_trace_gives_the_entries_the_core_writes() {
    // A seeded walk of statistics through one counters test: the scorecards' rule and the
    // core agree entry for entry.
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    for level in [AlarmLevel::Isolated, AlarmLevel::Suspect] {
        let mut core = one(level);
        let (mut trace, mut logged) = (Vec::new(), Vec::new());
        for k in 0..2000 {
            let v = if rng.random::<f64>() < 0.3 { 20.0 } else { 1.0 };
            let t = k as f64 * 0.5;
            for e in run(&mut core, &epoch(t, &[v], None)) {
                if let Some(x) = e.entry() {
                    logged.push((x.t, x.state, x.severity));
                }
            }
            trace.push((t, core.stats().monitors["m"].tests["r"].state));
        }
        assert!(logged.len() > 100, "{}", logged.len());
        assert_eq!(rule::trace_entries(&trace, level), logged);
    }
}

#[test]
fn a_threshold_change_applies_all_or_nothing_and_undoes() {
    let mut core = one(AlarmLevel::Isolated);
    let bad = ThresholdUpdate {
        p_fa: Some(0.01),
        threshold: None,
        policy: None,
        alarm_level: Some(AlarmLevel::Suspect),
        tests: Some([("nope".to_owned(), None)].into()),
    };
    let refused = core.apply_threshold(0, &bad).unwrap_err();
    assert_eq!(refused.field.as_deref(), Some("tests.nope"));
    assert_eq!(
        refused.reason,
        "no test 'nope' in this monitor; its tests are r"
    );
    assert_eq!(core.threshold_view(0).alarm_level, AlarmLevel::Isolated);
    assert_eq!(core.threshold_view(0).tests["r"].threshold, 10.0);

    let good = ThresholdUpdate { tests: None, ..bad };
    let undo = core.apply_threshold(0, &good).unwrap();
    let view = core.threshold_view(0);
    // χ²(1) at p_fa 0.01: 6.634896601021214.
    assert!((view.tests["r"].threshold - 6.634_896_601_021_214).abs() < 1e-9);
    assert_eq!(view.alarm_level, AlarmLevel::Suspect);
    assert_eq!(
        core.stats().monitors["m"].tests["r"].threshold,
        view.tests["r"].threshold
    );
    // 8 now exceeds, and suspect is an alarm.
    let effects = run(&mut core, &epoch(0.0, &[8.0], None));
    assert_eq!(brief(&effects), vec![state("r", S, Some(Severity::Alarm))]);

    core.undo_threshold(undo);
    assert_eq!(core.threshold_view(0).tests["r"].threshold, 10.0);
    assert_eq!(core.threshold_view(0).alarm_level, AlarmLevel::Isolated);
    assert_eq!(core.stats().monitors["m"].tests["r"].threshold, 10.0);
}

#[test]
fn an_empty_threshold_change_is_refused_as_a_whole() {
    let mut core = one(AlarmLevel::Isolated);
    let empty = ThresholdUpdate {
        p_fa: None,
        threshold: None,
        policy: None,
        alarm_level: None,
        tests: None,
    };
    assert_eq!(core.apply_threshold(0, &empty).unwrap_err().field, None);
}

#[test]
fn a_restart_returns_the_unhealthy_tests_and_starts_converging_again() {
    let mut core = one(AlarmLevel::Isolated);
    for k in 0..3 {
        run(&mut core, &epoch(k as f64, &[20.0], Some(1)));
    }
    let returned = core.restart();
    assert_eq!(
        returned,
        vec![Returned {
            monitor: "m".into(),
            test: "r".into(),
            from: I,
            t: Some(2.0),
        }]
    );
    assert_eq!((core.last_t(), core.stream_epochs()), (None, 0));
    assert_eq!(core.stats().monitors["m"].tests["r"].state, H);
    assert!(core.stats().monitors["m"].integrity.is_none());
    assert!(core.history().is_empty());
    // The new stream converges again: its first change is a warning.
    run(&mut core, &epoch(10.0, &[1.0], Some(0)));
    let effects = run(&mut core, &epoch(11.0, &[20.0], Some(0)));
    assert_eq!(
        brief(&effects),
        vec![state("r", S, Some(Severity::Warning))]
    );
    assert!(core.restart().is_empty() || core.stats().monitors["m"].tests["r"].state == H);
}

#[test]
fn a_restored_checkpoint_carries_on_as_the_session_would_have_with_the_stored_thresholds() {
    let script: Vec<Epoch> = (0..40)
        .map(|k| {
            let v = if (10..16).contains(&k) || (25..27).contains(&k) {
                20.0
            } else {
                1.0
            };
            epoch(k as f64, &[v], Some(u8::from(k >= 5)))
        })
        .collect();
    let mut straight = one(AlarmLevel::Isolated);
    let mut resumed = one(AlarmLevel::Isolated);
    let mut expected = Vec::new();
    for e in &script {
        expected.push(run(&mut straight, e));
    }
    for e in &script[..20] {
        run(&mut resumed, e);
    }
    let bytes = resumed.checkpoint(77).unwrap();
    let mut fresh = one(AlarmLevel::Isolated);
    assert_eq!(fresh.restore(&bytes), Ok(77));
    assert_eq!(fresh.stream_epochs(), 20);
    assert_eq!(fresh.last_t(), Some(19.0));
    for (k, e) in script.iter().enumerate().skip(20) {
        assert_eq!(run(&mut fresh, e), expected[k], "epoch {k}");
    }
    assert_eq!(fresh.stats().monitors, straight.stats().monitors);

    // A threshold changed in the stored spec after the checkpoint is not undone.
    let m = Scripted::boxed(&[("r", 1)], 50.0, COUNTERS);
    let mut changed = SessionCore::new("s", vec![seat("m", m, AlarmLevel::Isolated)], 60);
    changed.restore(&bytes).unwrap();
    assert_eq!(changed.threshold_view(0).tests["r"].threshold, 50.0);
    assert_eq!(changed.stats().monitors["m"].tests["r"].threshold, 50.0);
}

#[test]
fn a_checkpoint_of_other_monitors_is_refused_and_changes_nothing() {
    let mut core = one(AlarmLevel::Isolated);
    run(&mut core, &epoch(0.0, &[20.0], None));
    let bytes = core.checkpoint(1).unwrap();
    let m = Scripted::boxed(&[("r", 1)], 10.0, COUNTERS);
    let mut other = SessionCore::new("s", vec![seat("other", m, AlarmLevel::Isolated)], 60);
    let refused = other.restore(&bytes).unwrap_err();
    assert!(refused.contains("checkpoint monitors"), "{refused}");
    assert_eq!(other.stream_epochs(), 0);
    assert_eq!(other.restore(b"not a checkpoint").map_err(|_| ()), Err(()));
}

#[test]
fn frames_going_back_in_time_are_refused_before_anything_changes() {
    let core = one(AlarmLevel::Isolated);
    let refusal = core
        .check_frame(&[epoch(4.0, &[1.0], None)], Some(5.0))
        .unwrap_err();
    assert_eq!(refusal.to_string(), "t = 4 goes back from 5");
    assert!(
        core.check_frame(&[epoch(5.0, &[1.0], None)], Some(5.0))
            .is_ok()
    );
}

#[test]
fn the_history_samples_once_a_second_of_epoch_time() {
    let mut core = one(AlarmLevel::Isolated);
    for k in 0..50 {
        run(&mut core, &epoch(k as f64 * 0.1, &[1.0], None));
    }
    // t = 0 … 4.9 s: samples at 0, 1, 2, 3, 4.
    assert_eq!(core.history().len(), 5);
}

/// A federated monitor on raw IMU, still, with a fix every 100th epoch: the stats carry
/// its alignment state from the first IMU epoch, before any track; with a configured
/// heading it aligns once levelled and the track carries the state too.
#[test]
fn the_stats_carry_a_raw_imu_monitors_alignment_before_and_with_its_track() {
    use crate::epoch::{GnssBlock, ImuBlock};
    use crate::monitor::federated::Alignment;
    let monitor = |align: serde_json::Value| {
        let config = serde_json::json!({"aids": ["gnss"], "input": "imu",
            "strapdown": {"align": align}});
        let spec = crate::monitor::MonitorSpec {
            kind: MonitorKind::Federated,
            config: crate::monitor::MonitorConfig::parse(MonitorKind::Federated, &config).unwrap(),
            policy: PolicyConfig::counters_default(),
            threshold: ThresholdSpec::PFa(1e-3),
        };
        crate::monitor::build(&spec, &crate::monitor::NoModels).unwrap()
    };
    let seats = vec![
        Seat {
            name: "level".into(),
            monitor: monitor(serde_json::json!({"static_s": 2})),
            alarm_level: AlarmLevel::default(),
        },
        Seat {
            name: "heading".into(),
            monitor: monitor(serde_json::json!({"static_s": 2, "heading_deg": 30})),
            alarm_level: AlarmLevel::default(),
        },
    ];
    let mut core = SessionCore::new("imu", seats, 0);
    let mut effects = Vec::new();
    for k in 0..400 {
        let epoch = Epoch {
            t: k as f64 * 0.01,
            imu: Some(ImuBlock {
                accel: [0.0, 0.0, crate::geo::normal_gravity(0.7, 1600.0)],
                gyro: [0.0; 3],
                dt: None,
            }),
            gnss: (k % 100 == 0).then(|| GnssBlock {
                lat: 0.7,
                lon: -1.8,
                h: 1600.0,
                vel: Some([0.0; 3]),
                ..GnssBlock::default()
            }),
            ..Epoch::default()
        };
        let (reports, failure) = core.step(&epoch);
        assert!(failure.is_none());
        core.commit(&epoch, &reports, &mut effects);
    }
    let stats = core.stats();
    let level = &stats.monitors["level"];
    assert_eq!(level.alignment, Some(Alignment::Levelling));
    assert!(level.track.is_none(), "no solution while levelling");
    let heading = &stats.monitors["heading"];
    assert_eq!(heading.alignment, Some(Alignment::Aligned));
    assert_eq!(heading.track.unwrap().alignment, Some(Alignment::Aligned));
}
