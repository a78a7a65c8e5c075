//! Unit tests of monitor checkpoints, part 2: checkpoints that do not fit the monitor are
//! refused with `Mismatch` and change nothing; bytes that are not a checkpoint (truncated,
//! another version, garbage, a corrupted byte) are refused or, where they still decode to
//! a state that fits, never make a later step panic.

use proptest::prelude::*;
use proptest::test_runner::RngSeed;
use serde_json::json;

use super::tests::{
    channel_epochs, channel_models, channel_monitor, cv_epochs, cv_monitor, rimu_epochs,
    rimu_monitor, run, ship_epochs, ship_monitor, tacan_case,
};
use super::*;
use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::epoch::Epoch;
use navguard_core::monitor::{Monitor, MonitorConfig, MonitorSpec, NoModels, build};

/// A linear monitor with a 3-state constant-acceleration model (position measured).
fn ca_monitor() -> Box<dyn Monitor> {
    let config = json!({
        "f": [[1.0, 1.0, 0.5], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]],
        "h": [[1.0, 0.0, 0.0]],
        "q": [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]],
        "r": [[1.0]],
        "x0": [0.0, 0.0, 0.0],
        "p0": [[10.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 10.0]]
    });
    let spec = MonitorSpec {
        kind: MonitorKind::Linear,
        config: MonitorConfig::parse(MonitorKind::Linear, &config).unwrap(),
        policy: PolicyConfig::counters_default(),
        threshold: ThresholdSpec::PFa(1e-3),
    };
    build(&spec, &NoModels).unwrap()
}

/// A linear checkpoint mid-run (guards on).
fn linear_bytes() -> Vec<u8> {
    let mut m = cv_monitor(true);
    run(m.as_mut(), &cv_epochs(155, 150, 30.0, 1));
    m.checkpoint().unwrap()
}

fn is_mismatch(r: Result<(), CheckpointError>) -> bool {
    matches!(r, Err(CheckpointError::Mismatch(_)))
}

#[test]
fn a_linear_checkpoint_is_refused_by_a_federated_monitor() {
    let config = json!({"aids": ["gnss", "dvl", "cns"]});
    let spec = MonitorSpec {
        kind: MonitorKind::Federated,
        config: MonitorConfig::parse(MonitorKind::Federated, &config).unwrap(),
        policy: PolicyConfig::counters_default(),
        threshold: ThresholdSpec::PFa(1e-3),
    };
    let mut m = build(&spec, &NoModels).unwrap();
    let before = m.checkpoint().unwrap();
    let e = m.restore(&linear_bytes()).unwrap_err();
    assert_eq!(
        e,
        CheckpointError::Mismatch("a linear checkpoint, the monitor is federated".into())
    );
    assert_eq!(m.checkpoint().unwrap(), before);
}

#[test]
fn a_two_state_checkpoint_is_refused_by_a_three_state_monitor_which_then_steps_as_before() {
    let epochs = cv_epochs(120, 40, 8.0, 3);
    let (first, rest) = epochs.split_at(50);
    let (mut m, mut twin) = (ca_monitor(), ca_monitor());
    run(m.as_mut(), first);
    run(twin.as_mut(), first);
    let mut two_state = cv_monitor(false);
    run(two_state.as_mut(), first);
    let e = m.restore(&two_state.checkpoint().unwrap()).unwrap_err();
    assert!(
        matches!(&e, CheckpointError::Mismatch(r) if r.contains("2-state")),
        "{e}"
    );
    assert_eq!(m.checkpoint().unwrap(), twin.checkpoint().unwrap());
    assert_eq!(run(m.as_mut(), rest), run(twin.as_mut(), rest));
    assert_eq!(m.checkpoint().unwrap(), twin.checkpoint().unwrap());
}

#[test]
fn checkpoints_with_other_tests_channels_or_windows_are_refused() {
    // The same model with and without the residual's guards: other tests.
    let mut plain = cv_monitor(false);
    assert!(is_mismatch(plain.restore(&linear_bytes())));
    let mut guarded = cv_monitor(true);
    assert!(is_mismatch(guarded.restore(&plain.checkpoint().unwrap())));
    // A channel monitor whose online window is 30 samples, not 50.
    let models = channel_models();
    let mut m50 = channel_monitor(&models, 50);
    run(m50.as_mut(), &channel_epochs()[..120]);
    let mut m30 = channel_monitor(&models, 30);
    let before = m30.checkpoint().unwrap();
    let e = m30.restore(&m50.checkpoint().unwrap()).unwrap_err();
    assert!(
        matches!(&e, CheckpointError::Mismatch(r) if r.contains("channel 's'")),
        "{e}"
    );
    assert_eq!(m30.checkpoint().unwrap(), before);
    // One channel where the monitor has two.
    let one = json!({"channels": [{"name": "s", "predictor":
        {"online": {"window": 50, "gamma": 30.0, "sigma2": 9.0}}}]});
    let spec = MonitorSpec {
        kind: MonitorKind::Channel,
        config: MonitorConfig::parse(MonitorKind::Channel, &one).unwrap(),
        policy: PolicyConfig::counters_default(),
        threshold: ThresholdSpec::PFa(1e-4),
    };
    let single = build(&spec, &NoModels).unwrap();
    let e = m50.restore(&single.checkpoint().unwrap()).unwrap_err();
    assert_eq!(
        e,
        CheckpointError::Mismatch("1 channels, the monitor has 2".into())
    );
}

#[test]
fn truncated_checkpoints_and_other_versions_are_refused_and_change_nothing() {
    let bytes = linear_bytes();
    let mut m = cv_monitor(true);
    run(m.as_mut(), &cv_epochs(30, 10, 8.0, 4));
    let before = m.checkpoint().unwrap();
    for len in 0..bytes.len() {
        let e = m.restore(&bytes[..len]).unwrap_err();
        assert!(matches!(e, CheckpointError::Decode(_)), "{len} bytes: {e}");
    }
    let mut longer = bytes.clone();
    longer.push(0xc0);
    assert!(matches!(
        m.restore(&longer),
        Err(CheckpointError::Decode(_))
    ));
    let mut older = bytes.clone();
    older[4] = FORMAT_VERSION.wrapping_sub(1);
    let e = m.restore(&older).unwrap_err();
    assert!(
        matches!(&e, CheckpointError::Decode(r) if r.contains("version")),
        "{e}"
    );
    assert_eq!(m.checkpoint().unwrap(), before);
    m.restore(&bytes).unwrap();
}

#[test]
fn a_truncated_federated_or_channel_checkpoint_is_refused() {
    let (scenario, epochs) = {
        let s = crate::scenario::ship_with(6, Vec::new(), 20.0).unwrap();
        let e: Vec<_> = s.epochs.iter().map(|e| e.epoch.clone()).collect();
        (s, e)
    };
    let mut fed = ship_monitor(&scenario);
    run(fed.as_mut(), &epochs);
    let models = channel_models();
    let mut ch = channel_monitor(&models, 50);
    run(ch.as_mut(), &channel_epochs()[..200]);
    for m in [&mut fed, &mut ch] {
        let bytes = m.checkpoint().unwrap();
        // Every 7th length, and the last bytes one by one.
        let lens = (0..bytes.len())
            .step_by(7)
            .chain(bytes.len() - 40..bytes.len());
        for len in lens {
            assert!(
                matches!(m.restore(&bytes[..len]), Err(CheckpointError::Decode(_))),
                "{len} of {} bytes",
                bytes.len()
            );
        }
        m.restore(&bytes).unwrap();
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 256,
        rng_seed: RngSeed::Fixed(0x636b_7074),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn random_bytes_are_refused_without_a_panic(
        bytes in proptest::collection::vec(any::<u8>(), 0..400),
        with_header in any::<bool>(),
    ) {
        let mut input = if with_header { b"NGCP\x01\x01".to_vec() } else { Vec::new() };
        input.extend_from_slice(&bytes);
        let mut m = cv_monitor(true);
        let before = m.checkpoint().unwrap();
        prop_assert!(m.restore(&input).is_err());
        prop_assert_eq!(m.checkpoint().unwrap(), before);
    }

    #[test]
    fn a_corrupted_byte_is_refused_or_fits_and_never_makes_a_step_panic(
        at in any::<proptest::sample::Index>(),
        value in any::<u8>(),
        which in any::<proptest::sample::Index>(),
    ) {
        let cases = fixture();
        let case = &cases[which.index(cases.len())];
        let mut m = (case.build)();
        let mut bytes = case.bytes.clone();
        let i = at.index(bytes.len());
        bytes[i] = value;
        let before = m.checkpoint().unwrap();
        if m.restore(&bytes).is_err() {
            prop_assert_eq!(m.checkpoint().unwrap(), before);
        }
        // Whatever was restored fits the monitor: steps may fail numerically, never panic.
        for e in &case.epochs {
            let _ = m.step(e);
        }
    }
}

/// One kind's mid-run checkpoint, how to build a fresh monitor of it, and the epochs that
/// follow the checkpoint.
struct Case {
    build: Box<dyn Fn() -> Box<dyn Monitor> + Send + Sync>,
    bytes: Vec<u8>,
    epochs: Vec<Epoch>,
}

impl Case {
    /// Runs a fresh monitor through `epochs[..n1]`, checkpoints it, keeps the next 60.
    fn new(
        build: Box<dyn Fn() -> Box<dyn Monitor> + Send + Sync>,
        epochs: &[Epoch],
        n1: usize,
    ) -> Self {
        let mut m = build();
        run(m.as_mut(), &epochs[..n1]);
        Case {
            bytes: m.checkpoint().unwrap(),
            epochs: epochs[n1..(n1 + 60).min(epochs.len())].to_vec(),
            build,
        }
    }
}

/// A mid-run case of every kind, made once for all proptest cases.
fn fixture() -> &'static [Case] {
    static FIXTURE: std::sync::OnceLock<Vec<Case>> = std::sync::OnceLock::new();
    FIXTURE.get_or_init(|| {
        let channel_models = channel_models();
        let (scenario, ship) = ship_epochs();
        let ship_n1 = ship.iter().position(|e| e.t >= 85.0).unwrap();
        let (tacan_spec, tacan_models, tacan) = tacan_case();
        vec![
            Case::new(
                Box::new(|| cv_monitor(true)),
                &cv_epochs(220, 150, 30.0, 5),
                155,
            ),
            Case::new(Box::new(move || ship_monitor(&scenario)), &ship, ship_n1),
            Case::new(
                Box::new(move || channel_monitor(&channel_models, 50)),
                &channel_epochs(),
                262,
            ),
            Case::new(Box::new(rimu_monitor), &rimu_epochs(), 330),
            Case::new(
                Box::new(move || build(&tacan_spec, &tacan_models).unwrap()),
                &tacan,
                405,
            ),
        ]
    })
}
