//! Criterion bench: the wire's two CPU paths on the simulated ship (seed 004, 10 Hz INS
//! with GNSS, DVL and CNS), without a socket.
//!
//! - `wire/parse_frame/batch_N`: one ingest frame of N epochs (the JSON lines `loadgen`
//!   sends) parsed and validated into `Epoch`s, as the socket task does per frame.
//! - `wire/result_frame/batch_100`: the `result` frames of 100 federated-monitor reports
//!   written, each into a `String` of its own.
//! - `wire/result_frames_one_buffer/batch_100`: the same frames written one after another
//!   into one buffer and split off it, as the session actor does for a frame's epochs
//!   when the session echoes.
//!
//! Throughput is in epochs. Run: `cargo bench --bench wire`

// criterion_group! defines a public function it cannot document.
#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use navguard::service::wire::{
    RESULT_FRAME_BYTES, epoch_to_wire, parse_frame, result_frame, write_result_frame,
};
use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::monitor::federated::{FederatedConfig, FederatedMonitor};
use navguard_core::monitor::{Monitor, MonitorReport};
use navguard_sim as sim;

/// The largest batch the server accepts by default is 1,000; the bench frames are smaller.
const MAX_BATCH: usize = 1000;

fn bench(c: &mut Criterion) {
    let scenario = sim::ship_with(4, Vec::new(), 99.9).expect("ship scenario");
    let lines: Vec<String> = scenario
        .epochs
        .iter()
        .map(|e| epoch_to_wire(&e.epoch).expect("wire line"))
        .collect();
    assert_eq!(lines.len(), 1000, "100 s at 10 Hz");

    let mut group = c.benchmark_group("wire");
    for batch in [1, 10, 100, 1000] {
        let frame = if batch == 1 {
            lines[0].clone()
        } else {
            format!("[{}]", lines[..batch].join(","))
        };
        assert_eq!(parse_frame(&frame, MAX_BATCH).expect("frame").len(), batch);
        group.throughput(Throughput::Elements(batch as u64));
        group.bench_function(format!("parse_frame/batch_{batch}"), |b| {
            b.iter(|| parse_frame(black_box(&frame), MAX_BATCH).expect("frame"))
        });
    }

    let config = FederatedConfig::try_from(scenario.monitor_config()).expect("config");
    let mut monitor = FederatedMonitor::new(
        config,
        PolicyConfig::counters_default(),
        ThresholdSpec::Threshold(20.0),
    )
    .expect("monitor");
    let reports: Vec<(f64, MonitorReport)> = scenario.epochs[..100]
        .iter()
        .map(|e| (e.epoch.t, monitor.step(&e.epoch).expect("step")))
        .collect();
    group.throughput(Throughput::Elements(reports.len() as u64));
    group.bench_function("result_frame/batch_100", |b| {
        b.iter(|| {
            for (t, report) in &reports {
                black_box(result_frame(*t, [("federated", report)]));
            }
        })
    });
    group.bench_function("result_frames_one_buffer/batch_100", |b| {
        b.iter(|| {
            let mut buffer = bytes::BytesMut::with_capacity(reports.len() * RESULT_FRAME_BYTES);
            let mut scratch = Vec::with_capacity(RESULT_FRAME_BYTES);
            for (t, report) in &reports {
                scratch.clear();
                write_result_frame(&mut scratch, *t, [("federated", report)]);
                buffer.extend_from_slice(&scratch);
                black_box(buffer.split().freeze());
            }
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
