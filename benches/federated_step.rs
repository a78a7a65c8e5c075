//! Criterion bench: one epoch of the federated INS/GNSS/DVL/CNS filter (docs/performance.md target:
//! ≥ 200,000 epochs/s on one core) — INS plus all three aids on every epoch (GNSS with
//! velocity: 6 + 3 + 2 measurements), the counters policy, 15 error states. A ship at 30° N
//! sails north-east at 5 m/s; the INS runs at 10 Hz. Epochs are built in memory as the bench
//! runs (a few arithmetic operations each), so the figure is the monitor's own cost.
//!
//! - `federated_monitor/step_ins_gnss_dvl_cns`: the whole `federated` monitor step (aid
//!   models, the filter, the policies, the HPL, the corrected solution, the report);
//! - `federated_filter/step_ins_gnss_dvl_cns`: the filter step alone (transition, tests,
//!   fusion), decisions always healthy;
//! - `federated_monitor/step_ship_seed004`: the whole monitor on the simulated ship as
//!   `loadgen` streams it (INS every epoch, GNSS and DVL at 1 Hz, CNS at 0.1 Hz), the
//!   epochs simulated before the bench; the stream restarts on a fresh monitor every
//!   20,000 epochs (not timed).
//!
//! Run: `cargo bench --bench federated_step`
//!
//! Instruction counts (docs/performance.md): with `NAVGUARD_BENCH_STEPS=all:N` (or `ship:N`)
//! the binary skips criterion and steps the all-aids monitor (or the ship stream) exactly `N`
//! times, so that callgrind's count per step is repeatable:
//! `NAVGUARD_BENCH_STEPS=all:11000 valgrind --tool=callgrind target/release/deps/federated_step-*`,
//! then the inclusive count of `<FederatedMonitor as Monitor>::step` divided by `N`. With
//! `all:N:print` (or `ship:N:print`) it prints every step's report with `{:?}` (floats in
//! their shortest round-trip form, so equal lines are equal bits): two builds' outputs can
//! be compared with `cmp`.

// criterion_group! defines a public function it cannot document.
#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group};
use nalgebra::Vector3;
use navguard_core::detect::{Decision, Health, PolicyConfig, ThresholdSpec};
use navguard_core::epoch::{Aid, Epoch};
use navguard_core::epoch::{CnsBlock, GnssBlock, InsBlock};
use navguard_core::filter::aiding;
use navguard_core::filter::federated::{FederatedFilter, Observation, equal_betas, ins_transition};
use navguard_core::filter::ins::{ImuErrors, NavSolution};
use navguard_core::geo::{self, Lla};
use navguard_core::monitor::Monitor;
use navguard_core::monitor::federated::{FederatedConfig, FederatedConfigWire, FederatedMonitor};
use navguard_sim as sim;

const DT: f64 = 0.1;

/// The ship's epoch `k`: an error-free INS and aids off by a few centimetres.
fn epoch(start: &Lla, k: u64) -> Epoch {
    let t = k as f64 * DT;
    let v = 5.0 * std::f64::consts::FRAC_1_SQRT_2;
    let vel = [v, v, 0.0];
    let at = geo::apply_offset(start, &Vector3::new(v * t, v * t, 0.0));
    let wiggle = 0.05 * ((k % 7) as f64 - 3.0);
    let fix = geo::apply_offset(&at, &Vector3::new(wiggle, -wiggle, 0.5 * wiggle));
    let yaw = 45f64.to_radians();
    Epoch {
        t,
        ins: Some(InsBlock {
            lat: at.lat,
            lon: at.lon,
            h: at.h,
            vel,
            att: [0.0, 0.0, yaw],
            f_b: None,
        }),
        gnss: Some(GnssBlock {
            lat: fix.lat,
            lon: fix.lon,
            h: fix.h,
            vel: Some([v + 0.01 * wiggle, v, 0.0]),
            pos_sigma: None,
            vel_sigma: None,
        }),
        dvl_vel_b: Some([0.01 * wiggle, 5.0, 0.0]),
        cns: Some(CnsBlock {
            lat: fix.lat,
            lon: fix.lon,
        }),
        ..Default::default()
    }
}

/// Where the all-aids ship starts.
fn start() -> Lla {
    Lla {
        lat: 30f64.to_radians(),
        lon: 120f64.to_radians(),
        h: 0.0,
    }
}

/// The all-aids monitor's configuration.
fn all_aids() -> FederatedConfig {
    FederatedConfig::try_from(FederatedConfigWire::new(vec![
        Aid::Gnss,
        Aid::Dvl,
        Aid::Cns,
    ]))
    .expect("config")
}

/// A fresh monitor on `config` under the counters policy.
fn monitor_on(config: &FederatedConfig) -> FederatedMonitor {
    FederatedMonitor::new(
        config.clone(),
        PolicyConfig::counters_default(),
        ThresholdSpec::Threshold(20.0),
    )
    .expect("monitor")
}

/// The simulated ship stream of seed 004 (20,000 epochs) and its monitor configuration.
fn ship_stream() -> (sim::Scenario, FederatedConfig) {
    let ship = sim::ship_with(4, Vec::new(), 1999.9).expect("ship scenario");
    let config = FederatedConfig::try_from(ship.monitor_config()).expect("config");
    (ship, config)
}

/// `NAVGUARD_BENCH_STEPS=all:N` or `ship:N`: `N` monitor steps, nothing else timed or
/// printed (the module doc's instruction counts); `…:print` prints each report. The ship
/// stream restarts on a fresh monitor after its 20,000 epochs, as its bench does.
fn count_steps(spec: &str) {
    let parts: Vec<&str> = spec.split(':').collect();
    let parsed = match parts[..] {
        [which @ ("all" | "ship"), n] => n.parse::<usize>().ok().map(|n| (which, n, false)),
        [which @ ("all" | "ship"), n, "print"] => n.parse().ok().map(|n| (which, n, true)),
        _ => None,
    };
    let Some((which, n, print)) = parsed else {
        panic!("NAVGUARD_BENCH_STEPS is all:N or ship:N, optionally :print, not {spec:?}");
    };
    let step = |monitor: &mut FederatedMonitor, e: &Epoch| {
        let report = monitor.step(black_box(e)).expect("step");
        if print {
            println!("{report:?}");
        }
        black_box(report);
    };
    if which == "all" {
        let (start, config) = (start(), all_aids());
        let mut monitor = monitor_on(&config);
        for k in 1..=n as u64 {
            step(&mut monitor, &epoch(&start, k));
        }
    } else {
        let (ship, config) = ship_stream();
        let mut monitor = monitor_on(&config);
        for (i, e) in ship.epochs.iter().cycle().take(n).enumerate() {
            if i > 0 && i % ship.epochs.len() == 0 {
                monitor = monitor_on(&config);
            }
            step(&mut monitor, &e.epoch);
        }
    }
}

/// Every benchmark of this file, in the order they run (the ids are what
/// docs/performance.md quotes: `federated_monitor/…`, `federated_filter/…`).
fn bench(c: &mut Criterion) {
    let start = start();
    let config = all_aids();
    bench_monitor_all_aids(c, &start, &config);
    bench_filter_all_aids(c, &start, &config);
    bench_monitor_ship(c);
}

/// `federated_monitor/step_ins_gnss_dvl_cns`: the monitor on synthetic epochs that
/// carry every aid.
fn bench_monitor_all_aids(c: &mut Criterion, start: &Lla, config: &FederatedConfig) {
    let mut monitor = monitor_on(config);
    let mut k = 0;
    let mut group = c.benchmark_group("federated_monitor");
    group.throughput(Throughput::Elements(1));
    group.bench_function("step_ins_gnss_dvl_cns", |b| {
        b.iter(|| {
            k += 1;
            let e = epoch(start, k);
            black_box(monitor.step(black_box(&e)).expect("step"))
        })
    });
    group.finish();
}

/// `federated_filter/step_ins_gnss_dvl_cns`: the federated filter alone on the same
/// epochs, every aid healthy (the monitor's cost without its tests).
fn bench_filter_all_aids(c: &mut Criterion, start: &Lla, config: &FederatedConfig) {
    let mut filter =
        FederatedFilter::new(&equal_betas(3), config.initial_estimate()).expect("filter");
    let imu = ImuErrors::default();
    let healthy = Decision {
        health: Health::Healthy,
        update: true,
        fuse: true,
        reset: false,
    };
    let mut k = 0;
    let mut group = c.benchmark_group("federated_filter");
    group.throughput(Throughput::Elements(1));
    group.bench_function("step_ins_gnss_dvl_cns", |b| {
        b.iter(|| {
            k += 1;
            let e = epoch(start, k);
            let (Some(ins), Some(g), Some(d), Some(cns)) = (&e.ins, &e.gnss, e.dvl_vel_b, &e.cns)
            else {
                unreachable!("every bench epoch carries all blocks")
            };
            let nav = NavSolution::from_ins(ins);
            let fix = Lla {
                lat: g.lat,
                lon: g.lon,
                h: g.h,
            };
            let vel = Vector3::from(g.vel.unwrap_or_default());
            let obs: [Option<Observation>; 3] = [
                Some(aiding::gnss_velocity_position(&nav, &fix, &vel, 10.0, 0.1).into()),
                Some(aiding::dvl_velocity(&nav, &Vector3::from(d), 0.1).into()),
                Some(aiding::cns_position(&nav, cns.lat, cns.lon, 450.0).into()),
            ];
            let trans = ins_transition(&nav, &imu, DT).expect("transition");
            black_box(filter.step(&trans, &obs, |_, _| healthy).expect("step"));
            filter.commit();
        })
    });
    group.finish();
}

/// `federated_monitor/step_ship_seed004`: the monitor on seed 004's ship stream,
/// restarted at the end of the stream.
fn bench_monitor_ship(c: &mut Criterion) {
    let mut group = c.benchmark_group("federated_monitor");
    group.throughput(Throughput::Elements(1));
    let (ship, ship_config) = ship_stream();
    let ship_monitor = || monitor_on(&ship_config);
    let (mut monitor, mut next) = (ship_monitor(), 0);
    group.bench_function("step_ship_seed004", |b| {
        b.iter_custom(|iters| {
            let mut timed = std::time::Duration::ZERO;
            let mut left = iters as usize;
            while left > 0 {
                if next == ship.epochs.len() {
                    (monitor, next) = (ship_monitor(), 0);
                }
                let n = left.min(ship.epochs.len() - next);
                let start = std::time::Instant::now();
                for e in &ship.epochs[next..next + n] {
                    black_box(monitor.step(black_box(&e.epoch)).expect("step"));
                }
                timed += start.elapsed();
                (next, left) = (next + n, left - n);
            }
            timed
        })
    });
    group.finish();
}

criterion_group!(benches, bench);

/// `criterion_main!`, unless `NAVGUARD_BENCH_STEPS` asks for a fixed number of steps.
fn main() {
    if let Ok(spec) = std::env::var("NAVGUARD_BENCH_STEPS") {
        count_steps(&spec);
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
