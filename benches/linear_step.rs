//! Criterion bench: one step of the `linear` monitor (4 states, 2 measurements,
//! classic policy): predict, innovation, χ² test, Joseph update.
//!
//! Run: `cargo bench --bench linear_step`

// criterion_group! defines a public function it cannot document.
#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::epoch::Epoch;
use navguard_core::monitor::Monitor;
use navguard_core::monitor::linear::{LinearConfig, LinearConfigWire, LinearMonitor};

/// The benched model: 2-D constant velocity, 1 s steps, seeing x and y with
/// correlated noise; typed, so a renamed config field fails to compile.
fn model() -> LinearConfigWire {
    let q = 0.05;
    let (a, b) = (q / 3.0, q / 2.0);
    LinearConfigWire {
        f: vec![
            vec![1.0, 1.0, 0.0, 0.0],
            vec![0.0, 1.0, 0.0, 0.0],
            vec![0.0, 0.0, 1.0, 1.0],
            vec![0.0, 0.0, 0.0, 1.0],
        ],
        h: vec![vec![1.0, 0.0, 0.0, 0.0], vec![0.0, 0.0, 1.0, 0.0]],
        q: vec![
            vec![a, b, 0.0, 0.0],
            vec![b, q, 0.0, 0.0],
            vec![0.0, 0.0, a, b],
            vec![0.0, 0.0, b, q],
        ],
        r: vec![vec![1.0, 0.3], vec![0.3, 2.0]],
        x0: vec![0.0, 1.0, 0.0, -1.0],
        p0: vec![
            vec![5.0, 0.0, 0.0, 0.0],
            vec![0.0, 5.0, 0.0, 0.0],
            vec![0.0, 0.0, 5.0, 0.0],
            vec![0.0, 0.0, 0.0, 5.0],
        ],
        b: None,
        drift: None,
        stuck: None,
    }
}

fn bench(c: &mut Criterion) {
    let config = LinearConfig::try_from(model()).expect("valid model");
    let mut monitor = LinearMonitor::new(config, PolicyConfig::Classic, ThresholdSpec::PFa(0.002))
        .expect("monitor");
    let mut k = 0.0;
    let mut group = c.benchmark_group("linear_monitor");
    group.throughput(Throughput::Elements(1));
    group.bench_function("step_4_states_2_measurements", |bench| {
        bench.iter(|| {
            k += 1.0;
            let epoch = Epoch {
                t: k,
                z: Some(vec![k + 0.3, -k - 0.2]),
                ..Default::default()
            };
            black_box(monitor.step(black_box(&epoch)).expect("step"))
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
