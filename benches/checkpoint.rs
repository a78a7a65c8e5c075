//! Criterion bench: a monitor's checkpoint and its restore (`Monitor::checkpoint`,
//! `Monitor::restore`), what a session pays to move to another node.
//!
//! - `checkpoint/federated_ship`: the `federated` monitor (GNSS, DVL, CNS; drift and stuck
//!   tests at their defaults; counters) after 120 s of seed 004's ship at 10 Hz;
//! - `checkpoint/linear_cv`: the `linear` monitor on the 2-state constant-velocity model
//!   (position measured; no guards) after 200 epochs;
//! - `checkpoint/linear_cv_guarded`: the same model with the residual's drift (windows 5
//!   and 20) and stuck tests.
//!
//! Each is benched as `save` (checkpoint) and `restore` (into a monitor built afresh from
//! the same spec). The checkpoint's size is printed and recorded as the bench's
//! throughput in bytes.
//!
//! Run: `cargo bench --bench checkpoint`

// criterion_group! defines a public function it cannot document.
#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::epoch::Epoch;
use navguard_core::monitor::{self, MonitorConfig, MonitorKind, MonitorSpec, NoModels};
use navguard_sim::scenario::ship_with;

/// A federated monitor for the ship and the ship's first 120 s (1200 INS epochs).
fn ship() -> (MonitorSpec, Vec<Epoch>) {
    let scenario = ship_with(4, Vec::new(), 120.0).expect("ship scenario");
    let spec = MonitorSpec {
        kind: MonitorKind::Federated,
        config: MonitorConfig::Federated(scenario.monitor_config()),
        policy: PolicyConfig::counters_default(),
        threshold: ThresholdSpec::PFa(1e-3),
    };
    let epochs = scenario.epochs.into_iter().map(|e| e.epoch).collect();
    (spec, epochs)
}

/// The 2-state constant-velocity model (σ = 1 on position), guarded or not, and 200
/// epochs of a target at 0.5 per epoch with a deterministic wiggle.
fn linear_cv(guards: bool) -> (MonitorSpec, Vec<Epoch>) {
    let mut config = serde_json::json!({
        "f": [[1.0, 1.0], [0.0, 1.0]],
        "h": [[1.0, 0.0]],
        "q": [[0.25, 0.5], [0.5, 1.0]],
        "r": [[1.0]],
        "x0": [0.0, 0.0],
        "p0": [[10.0, 0.0], [0.0, 10.0]]
    });
    if guards {
        config["drift"] = serde_json::json!({"windows": [5, 20]});
        config["stuck"] = serde_json::json!({});
    }
    let spec = MonitorSpec {
        kind: MonitorKind::Linear,
        config: MonitorConfig::parse(MonitorKind::Linear, &config).expect("linear config"),
        policy: PolicyConfig::counters_default(),
        threshold: ThresholdSpec::PFa(1e-3),
    };
    let epochs = (0..200)
        .map(|k| Epoch {
            t: f64::from(k),
            z: Some(vec![0.5 * f64::from(k) + 0.7 * (f64::from(k) * 1.3).sin()]),
            ..Default::default()
        })
        .collect();
    (spec, epochs)
}

fn bench_one(c: &mut Criterion, name: &str, spec: &MonitorSpec, epochs: &[Epoch]) {
    let mut m = monitor::build(spec, &NoModels).expect("monitor");
    for e in epochs {
        m.step(e).expect("step");
    }
    let bytes = m.checkpoint().expect("checkpoint");
    println!("checkpoint/{name}: {} bytes", bytes.len());
    let mut fresh = monitor::build(spec, &NoModels).expect("monitor");
    fresh.restore(&bytes).expect("restore");
    assert_eq!(fresh.checkpoint().expect("checkpoint"), bytes);
    let mut group = c.benchmark_group("checkpoint");
    group.throughput(Throughput::Bytes(bytes.len() as u64));
    group.bench_function(format!("{name}/save"), |b| {
        b.iter(|| black_box(m.checkpoint().expect("checkpoint")))
    });
    group.bench_function(format!("{name}/restore"), |b| {
        b.iter(|| fresh.restore(black_box(&bytes)).expect("restore"))
    });
    group.finish();
}

fn bench(c: &mut Criterion) {
    let (spec, epochs) = ship();
    bench_one(c, "federated_ship", &spec, &epochs);
    let (spec, epochs) = linear_cv(false);
    bench_one(c, "linear_cv", &spec, &epochs);
    let (spec, epochs) = linear_cv(true);
    bench_one(c, "linear_cv_guarded", &spec, &epochs);
}

criterion_group!(benches, bench);
criterion_main!(benches);
