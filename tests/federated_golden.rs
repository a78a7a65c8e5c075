//! Golden run of the federated monitor on the simulated ship: the optimised
//! federated step must give the results of the straightforward one, to 1e-9
//! relative. Two runs, blessed from that straightforward step (commit c9c17be):
//!
//! - the 10 Hz ship (aids at their own rates between INS epochs) under counters, with a
//!   GNSS position jump on [150, 210) s and a DVL velocity step from 300 s: suspect,
//!   isolated, reset from the master and readmitted, the drift and stuck tests live;
//! - the 1 Hz ship of seed 004's position jump on [1080, 1200) s under the classic policy,
//!   whose filters rejoin with an estimate of their own (independent-estimate fusion).
//!
//! Each run records, every `every` epochs, the fused state `x_g`, the diagonal and first
//! row of `P_g`, every test's statistic and threshold, the corrected solution and the HPL;
//! and, for every epoch, each test's health (as run-length transitions). States are
//! compared on their own scale: `|a − g| ≤ 1e-9·max(|g|, σ_i)` for `x`, and
//! `|a − g| ≤ 1e-9·σ_i σ_j` for `P`; statistics `|a − g| ≤ 1e-9·max(|g|, 1)`
//! (a statistic below 1 is far from any threshold). Health must match exactly.
//!
//! Re-bless (only when a change of results is intended and explained):
//! `NAVGUARD_BLESS=1 cargo test --release --test federated_golden`.

mod common;

use std::collections::BTreeMap;

use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::monitor::federated::{FederatedConfig, FederatedMonitor};
use navguard_core::monitor::{Monitor, Outputs};
use navguard_sim::{self as sim, Channel, Fault, FaultKind, Scenario};
use serde::{Deserialize, Serialize};

use common::ship_1hz;

const TOL: f64 = 1e-9;

/// One sampled epoch.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Sample {
    k: usize,
    x: Vec<f64>,
    p_diag: Vec<f64>,
    p_row0: Vec<f64>,
    /// Test name → (statistic, threshold).
    tests: BTreeMap<String, (f64, f64)>,
    /// lat, lon (degrees), h, vel ENU.
    solution: Option<[f64; 6]>,
    hpl: Option<f64>,
}

/// One run's record.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Record {
    epochs: usize,
    samples: Vec<Sample>,
    /// Test name → (epoch, health) at each change of health.
    health: BTreeMap<String, Vec<(usize, String)>>,
}

#[derive(Debug, Serialize, Deserialize)]
struct Golden {
    ship_10hz_counters: Record,
    ship_1hz_classic: Record,
}

fn record(scenario: &Scenario, policy: PolicyConfig, every: usize) -> Record {
    let config = FederatedConfig::from_json(&scenario.default_monitor_config()).unwrap();
    let mut m = FederatedMonitor::new(config, policy, ThresholdSpec::Threshold(20.0)).unwrap();
    let mut samples = Vec::new();
    let mut health: BTreeMap<String, Vec<(usize, String)>> = BTreeMap::new();
    for (k, e) in scenario.epochs.iter().enumerate() {
        let report = m.step(&e.epoch).unwrap();
        for t in &report.tests {
            let h = format!("{:?}", t.decision.health);
            let changes = health.entry(t.name.to_string()).or_default();
            if changes.last().is_none_or(|(_, last)| *last != h) {
                changes.push((k, h));
            }
        }
        if k % every != 0 {
            continue;
        }
        let master = m.filter().master();
        let Outputs::Federated { solution, hpl, .. } = &report.outputs else {
            panic!("a federated monitor reports federated outputs");
        };
        samples.push(Sample {
            k,
            x: master.x.iter().copied().collect(),
            p_diag: (0..15).map(|i| master.p[(i, i)]).collect(),
            p_row0: (0..15).map(|j| master.p[(0, j)]).collect(),
            tests: report
                .tests
                .iter()
                .map(|t| {
                    (
                        t.name.to_string(),
                        (t.statistic.value, t.statistic.threshold),
                    )
                })
                .collect(),
            solution: solution.map(|s| [s.lat, s.lon, s.h, s.vel[0], s.vel[1], s.vel[2]]),
            hpl: *hpl,
        });
    }
    Record {
        epochs: scenario.epochs.len(),
        samples,
        health,
    }
}

fn runs() -> Golden {
    let gnss = |component, value| Fault {
        aid: navguard_core::epoch::Aid::Gnss,
        channel: Channel::Position,
        component,
        kind: FaultKind::Step { value },
        start_s: 150.0,
        end_s: Some(210.0),
    };
    let dvl = Fault {
        aid: navguard_core::epoch::Aid::Dvl,
        channel: Channel::Velocity,
        component: 0,
        kind: FaultKind::Step { value: 0.6 },
        start_s: 300.0,
        end_s: None,
    };
    let ten_hz = sim::ship_with(5, vec![gnss(0, 30.0), gnss(1, -25.0), dvl], 400.0).unwrap();
    let jump: Vec<Fault> = sim::ship_faults()
        .into_iter()
        .filter(|f| f.channel == Channel::Position)
        .collect();
    let one_hz = ship_1hz(2, jump, 1300.0);
    Golden {
        ship_10hz_counters: record(&ten_hz, PolicyConfig::Counters { n1: 10, n2: 5 }, 40),
        ship_1hz_classic: record(&one_hz, PolicyConfig::Classic, 20),
    }
}

fn path() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/federated_ship.json")
}

fn close(what: &str, got: f64, want: f64, scale: f64) {
    let ok = (got - want).abs() <= TOL * scale || got == want;
    assert!(
        ok,
        "{what}: {got:e} against the golden {want:e} (scale {scale:e})"
    );
}

fn compare(name: &str, got: &Record, want: &Record) {
    assert_eq!(got.epochs, want.epochs, "{name}: epochs");
    assert_eq!(got.health, want.health, "{name}: health transitions");
    assert_eq!(got.samples.len(), want.samples.len(), "{name}: samples");
    for (g, w) in got.samples.iter().zip(&want.samples) {
        let at = |what: &str| format!("{name} epoch {} {what}", w.k);
        assert_eq!(g.k, w.k);
        let sigma: Vec<f64> = w.p_diag.iter().map(|v| v.sqrt()).collect();
        for i in 0..15 {
            close(
                &at(&format!("x[{i}]")),
                g.x[i],
                w.x[i],
                w.x[i].abs().max(sigma[i]),
            );
            close(
                &at(&format!("P[{i},{i}]")),
                g.p_diag[i],
                w.p_diag[i],
                w.p_diag[i],
            );
            close(
                &at(&format!("P[0,{i}]")),
                g.p_row0[i],
                w.p_row0[i],
                sigma[0] * sigma[i],
            );
        }
        assert_eq!(
            g.tests.keys().collect::<Vec<_>>(),
            w.tests.keys().collect::<Vec<_>>(),
            "{}",
            at("tests that ran")
        );
        for (test, (value, threshold)) in &w.tests {
            let (gv, gt) = g.tests[test];
            close(&at(test), gv, *value, value.abs().max(1.0));
            close(
                &at(&format!("{test} threshold")),
                gt,
                *threshold,
                threshold.abs(),
            );
        }
        match (g.solution, w.solution) {
            (Some(gs), Some(ws)) => {
                // Relative to the value: for lat/lon in degrees, 1e-9 of 30° is 3 mm.
                for c in 0..6 {
                    close(
                        &at(&format!("solution[{c}]")),
                        gs[c],
                        ws[c],
                        ws[c].abs().max(1.0),
                    );
                }
            }
            (g, w) => assert_eq!(g.is_some(), w.is_some(), "{}", at("solution")),
        }
        match (g.hpl, w.hpl) {
            (Some(gh), Some(wh)) => close(&at("hpl"), gh, wh, wh.abs()),
            (g, w) => assert_eq!(g.is_some(), w.is_some(), "{}", at("hpl")),
        }
    }
}

#[test]
fn the_federated_monitor_reproduces_its_golden_run_to_1e_9() {
    let got = runs();
    if std::env::var_os("NAVGUARD_BLESS").is_some() {
        std::fs::create_dir_all(path().parent().unwrap()).unwrap();
        std::fs::write(path(), serde_json::to_string(&got).unwrap()).unwrap();
        return;
    }
    let text = std::fs::read_to_string(path()).expect("the golden file");
    let want: Golden = serde_json::from_str(&text).unwrap();
    // The run must exercise what the golden is for: isolation and return in both runs.
    for (name, rec) in [
        ("10 Hz", &want.ship_10hz_counters),
        ("1 Hz", &want.ship_1hz_classic),
    ] {
        let isolated = rec
            .health
            .values()
            .flatten()
            .filter(|(_, h)| h == "Isolated")
            .count();
        assert!(isolated > 0, "{name}: no test was ever isolated");
    }
    compare("10 Hz", &got.ship_10hz_counters, &want.ship_10hz_counters);
    compare("1 Hz", &got.ship_1hz_classic, &want.ship_1hz_classic);
}
