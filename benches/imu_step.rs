//! Criterion bench: one 100 Hz epoch of a `federated` monitor on raw IMU (`input: imu`):
//! the strapdown front end and mechanization, the federated step about it (prediction
//! every epoch, the GNSS update and tests on the 1 Hz epochs) and the closed-loop
//! feedback. The stream is the real car drive (tests/data/drive/) with its 1 Hz degraded
//! GNSS, as `navguard experiment drive` builds it, after alignment (docs/performance.md,
//! "Raw IMU sessions").
//!
//! Run: `cargo bench --bench imu_step`

// criterion_group! defines a public function it cannot document.
#![allow(missing_docs)]

#[path = "../tests/common/drive.rs"]
mod drive_data;

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use navguard_core::epoch::Epoch;
use navguard_core::monitor::{self, NoModels};
use navguard_sim::experiment::drive::{self, DriveParams};

fn bench(c: &mut Criterion) {
    let data = drive_data::read_drive();
    let params = DriveParams {
        outages: Vec::new(),
        ..DriveParams::default()
    };
    let epochs: Vec<Epoch> = drive::free_epochs(&data, &params, 1, &|e| Ok(e)).expect("epochs");
    let spec = drive::monitor_spec(&params).expect("the drive's spec");
    let mut m = monitor::build(&spec, &NoModels).expect("the drive's monitor");
    // Past alignment (the car moves off at ~36 s, the heading comes at ~40 s).
    let start = 5_000;
    for e in &epochs[..start] {
        m.step(e).expect("a step");
    }
    let aligned = m.checkpoint().expect("a checkpoint");
    let stream = &epochs[start..];
    let mut g = c.benchmark_group("imu_monitor");
    g.throughput(Throughput::Elements(1));
    g.bench_function("step_100hz_drive", |b| {
        let mut k = 0;
        b.iter_custom(|iters| {
            let mut busy = Duration::ZERO;
            for _ in 0..iters {
                if k == stream.len() {
                    m.restore(&aligned).expect("restore");
                    k = 0;
                }
                let started = Instant::now();
                black_box(m.step(black_box(&stream[k])).expect("a step"));
                busy += started.elapsed();
                k += 1;
            }
            busy
        });
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
