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

use std::hint::black_box;
use std::path::Path;
use std::time::{Duration, Instant};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::Vector3;
use navguard_core::epoch::Epoch;
use navguard_core::monitor::{self, NoModels};
use navguard_formats::imu_csv::{self, ImuCsvLayout};
use navguard_formats::{rtklib_pos, timetag};
use navguard_sim::experiment::drive::{self, DriveData, DriveParams};

/// The drive as the experiment reads it.
fn read_drive() -> DriveData {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/drive");
    let samples = imu_csv::read_imu_csv(&dir.join("imu_1934.csv"), &ImuCsvLayout::default())
        .expect("the drive's IMU CSV");
    let tag = timetag::read_tag(&dir.join("imu_1934.csv.tag")).expect("its time tag");
    let imu = imu_csv::to_epochs_tagged(&samples, &tag, -0.125);
    let reference = rtklib_pos::read_pos(&dir.join("gnss_1934_sf.pos"))
        .expect("the drive's RTK solution")
        .iter()
        .map(|f| drive::RefFix {
            t: f.t,
            lla: f.lla,
            vel: Vector3::from(f.vel.unwrap_or_default()),
        })
        .collect();
    DriveData { imu, reference }
}

fn bench(c: &mut Criterion) {
    let data = read_drive();
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
