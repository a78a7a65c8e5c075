//! Criterion bench: one epoch of the `gnss` monitor with 30 satellites of two
//! constellations (GPS and Galileo, 15 each), σ 1.5 m, fault-free: WLS, the `raim`
//! test, fault exclusion and ARAIM protection levels; and the same with the slope
//! levels, and with solution-separation exclusion. Also the whole monitor's rate over
//! a stream of such epochs (docs/performance.md, "GNSS epoch").
//!
//! Run: `cargo bench --bench gnss_step`; for instruction counts, a fixed number of steps
//! under callgrind: `GNSS_STEP_COUNT=200 GNSS_STEP_CASE=step_30_sats_greedy_araim
//! valgrind --tool=callgrind <the bench binary>` (see [`fixed_count`]).

// criterion_group! defines a public function it cannot document.
#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group};
use nalgebra::Vector3;
use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::epoch::{Constellation, Epoch, GnssRawBlock, SatId, SatObs};
use navguard_core::geo::{Lla, ecef_to_enu_rotation, lla_to_ecef};
use navguard_core::gnss::correct::{OMEGA_E, SPEED_OF_LIGHT, rotate_frame_z, sagnac_rotate};
use navguard_core::monitor::{self, Monitor, MonitorConfig, MonitorKind, MonitorSpec, NoModels};

const ORBIT_RADIUS_M: f64 = 26_560_000.0;

/// A satellite at azimuth `az`, elevation `el` (rad) from `rx`, on the orbit sphere,
/// expressed in the transmit-time frame so the monitor's Sagnac rotation recovers it.
fn satellite(rx: &Vector3<f64>, at: &Lla, az: f64, el: f64) -> Vector3<f64> {
    let enu = Vector3::new(az.sin() * el.cos(), az.cos() * el.cos(), el.sin());
    let dir = ecef_to_enu_rotation(at.lat, at.lon).transpose() * enu;
    let b = rx.dot(&dir);
    let c = rx.norm_squared() - ORBIT_RADIUS_M * ORBIT_RADIUS_M;
    let s_rx = rx + dir * (-b + (b * b - c).sqrt());
    let mut s_tx = rotate_frame_z(&s_rx, -OMEGA_E * (s_rx - rx).norm() / SPEED_OF_LIGHT);
    // Two fixed-point rounds: the rotation of s_tx must land on s_rx.
    for _ in 0..2 {
        s_tx += s_rx - sagnac_rotate(&s_tx, rx);
    }
    s_tx
}

/// 30 satellites, alternating GPS and Galileo, spread in azimuth and elevation, with a
/// small deterministic noise on each pseudorange (epoch `k` varies it).
fn epoch(k: u64) -> Epoch {
    let at = Lla {
        lat: 0.66,
        lon: -2.13,
        h: 25.0,
    };
    let rx = lla_to_ecef(&at);
    let sats = (0..30)
        .map(|i| {
            let constellation = if i % 2 == 0 {
                Constellation::Gps
            } else {
                Constellation::Galileo
            };
            let az = (i as f64 * 137.5f64).to_radians();
            let el = (12.0 + (i as f64 * 29.0) % 75.0).to_radians();
            let s = satellite(&rx, &at, az, el);
            let noise = (((k * 31 + i as u64 * 17) % 23) as f64 - 11.0) * 0.2;
            let clock = if i % 2 == 0 { 3.0e4 } else { 3.0e4 - 12.0 };
            SatObs {
                id: SatId {
                    constellation,
                    prn: (i / 2 + 1) as u8,
                },
                pr: (sagnac_rotate(&s, &rx) - rx).norm() + clock + noise,
                pos: [s.x, s.y, s.z],
                clk: 0.0,
                iono: Some(0.0),
                tropo: Some(0.0),
                sigma: Some(1.5),
                cn0: None,
                el: None,
                az: None,
            }
        })
        .collect();
    Epoch {
        t: k as f64,
        gnss_raw: Some(GnssRawBlock { sats, truth: None }),
        ..Epoch::default()
    }
}

fn monitor_for(config: serde_json::Value) -> Box<dyn Monitor> {
    let spec = MonitorSpec {
        kind: MonitorKind::Gnss,
        config: MonitorConfig::parse(MonitorKind::Gnss, &config).expect("config"),
        policy: PolicyConfig::Classic,
        threshold: ThresholdSpec::PFa(1e-3),
    };
    monitor::build(&spec, &NoModels).expect("monitor")
}

/// The monitor configurations benched, by name.
fn cases() -> [(&'static str, serde_json::Value); 3] {
    [
        ("step_30_sats_greedy_araim", serde_json::json!({})),
        (
            "step_30_sats_greedy_slope",
            serde_json::json!({"protection": "slope"}),
        ),
        (
            "step_30_sats_solution_separation_araim",
            serde_json::json!({"fde": {"method": "solution_separation"}}),
        ),
    ]
}

fn bench(c: &mut Criterion) {
    let epochs: Vec<Epoch> = (0..64).map(epoch).collect();
    let mut group = c.benchmark_group("gnss_monitor");
    group.throughput(Throughput::Elements(1));
    for (name, config) in cases() {
        let mut m = monitor_for(config);
        let first = m.step(&epochs[0]).expect("step");
        assert_eq!(first.tests.len(), 1, "the raim test runs");
        let mut k = 0;
        group.bench_function(name, |bench| {
            bench.iter(|| {
                k = (k + 1) % epochs.len();
                black_box(m.step(black_box(&epochs[k])).expect("step"))
            })
        });
    }
    group.finish();
}

/// A fixed amount of work instead of criterion's timed runs, for instruction counts:
/// with `GNSS_STEP_COUNT=n` (and `GNSS_STEP_CASE=<name>` to pick one case) each case's
/// monitor takes its first epoch and then `n` more steps, as in the bench; the count at
/// `n = 0` is the set-up to subtract.
fn fixed_count(n: usize, only: Option<&str>) {
    let epochs: Vec<Epoch> = (0..64).map(epoch).collect();
    for (name, config) in cases() {
        if only.is_some_and(|o| o != name) {
            continue;
        }
        let mut m = monitor_for(config);
        m.step(&epochs[0]).expect("step");
        for k in 1..=n {
            black_box(m.step(black_box(&epochs[k % epochs.len()])).expect("step"));
        }
    }
}

criterion_group!(benches, bench);

fn main() {
    if let Some(n) = std::env::var("GNSS_STEP_COUNT")
        .ok()
        .and_then(|v| v.parse().ok())
    {
        fixed_count(n, std::env::var("GNSS_STEP_CASE").ok().as_deref());
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
