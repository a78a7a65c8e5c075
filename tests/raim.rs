//! The RAIM experiment on real data (`navguard experiment raim`, docs/experiments.md):
//! the geodetic receiver's hour of RINEX and the GSDC 2023 phone epochs, read with the
//! converter's readers, fault-free and with seeded faults, checked against what the
//! experiment's documentation states: the σ scale the data need, every fault-free
//! epoch bounded by its HPL, a 50 m step on one satellite detected and excluded on its
//! first epoch, no misleading information under single-satellite faults, and what
//! monitoring pairs of faults changes for two simultaneous ones.

use std::path::{Path, PathBuf};

use navguard_formats::gsdc::{Band, y2023};
use navguard_formats::rinex::convert::{RinexParams, convert};
use navguard_formats::rinex::{nav::read_nav, obs::read_obs};
use navguard_sim::experiment::raim::{self, Dataset, Fault, FaultKind, RaimParams};

fn data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/gnss")
}

fn geonet() -> Dataset {
    let dir = data().join("rtklib");
    let obs = read_obs(&dir.join("07590920.05o")).unwrap();
    let nav = read_nav(&dir.join("07590920.05n")).unwrap();
    let params = RinexParams {
        iono_free: true,
        truth_approx_position: true,
    };
    Dataset {
        name: "geonet".into(),
        epochs: convert(&obs, &nav, "07590920.05o", params).unwrap().epochs,
        sigma: serde_json::json!({"model": "elevation"}),
    }
}

fn gsdc2023() -> Dataset {
    let dir = data().join("gsdc");
    let truth = y2023::read_truth(&dir.join("gsdc2023_pixel7pro_ground_truth.csv")).unwrap();
    let file = dir.join("gsdc2023_pixel7pro_device_gnss.csv");
    Dataset {
        name: "gsdc2023".into(),
        epochs: y2023::read(&file, Band::L1, Some(&truth)).unwrap(),
        sigma: serde_json::json!({"model": "given"}),
    }
}

fn params() -> RaimParams {
    let step = |m, satellites| Fault {
        kind: FaultKind::Step(m),
        satellites,
    };
    RaimParams {
        seed: 7,
        draws: 40,
        faults: vec![
            step(50.0, 1),
            step(100.0, 1),
            Fault {
                kind: FaultKind::Ramp(1.0),
                satellites: 1,
            },
        ],
        ..RaimParams::default()
    }
}

#[test]
fn on_the_geodetic_receiver_a_50_m_step_is_detected_and_excluded_on_its_first_epoch() {
    let r = raim::run(&[geonet()], &params()).unwrap();
    let d = &r.datasets[0];
    assert_eq!(d.epochs, 120);
    // RTKLIB's elevation model (a = b = 0.3 m) understates the iono-free code noise.
    assert!(
        (1.3..1.9).contains(&d.sigma_scale),
        "σ scale {}",
        d.sigma_scale
    );
    for (method, f) in &d.fault_free {
        assert_eq!(f.bounded, f.epochs, "{method}: every fault-free HPE ≤ HPL");
        assert!(
            f.exceedances <= 1,
            "{method}: {} false alarms",
            f.exceedances
        );
        assert_eq!(f.exclusions, 0, "{method}");
    }
    for method in ["rtklib", "greedy"] {
        let f = &d.faulted["step 50 m"][method];
        let tested = f.draws - f.skipped;
        assert!(tested >= 30, "{method}: {tested} draws with 6 satellites");
        assert_eq!(
            f.detected_first, tested,
            "{method}: detected on the first epoch"
        );
        assert!(
            f.excluded_first as f64 >= 0.95 * tested as f64,
            "{method}: excluded first {} of {tested}",
            f.excluded_first
        );
    }
    for (case, by_method) in &d.faulted {
        for (method, f) in by_method {
            assert_eq!(
                (f.mi, f.hmi),
                (0, 0),
                "{case} {method}: misleading information"
            );
        }
    }
}

#[test]
fn on_the_phone_every_fault_free_epoch_is_bounded_and_faults_mislead_nowhere() {
    let r = raim::run(&[gsdc2023()], &params()).unwrap();
    let d = &r.datasets[0];
    assert_eq!(d.epochs, 5);
    for f in d.fault_free.values() {
        assert_eq!(f.bounded, f.epochs);
        // Within a few metres of the truth, as docs/experiments.md reports.
        assert!(f.hpe[2] < 6.0, "HPE max {}", f.hpe[2]);
    }
    // The phone's σ reach 10–20 m on some satellites, where a step of 100 m hides in the
    // weights: docs/experiments.md reports 82 % over 100 draws.
    let (big, small) = (
        &d.faulted["step 100 m"]["greedy"],
        &d.faulted["step 50 m"]["greedy"],
    );
    assert!(
        big.detected_first * 10 >= 7 * (big.draws - big.skipped),
        "{big:?}"
    );
    assert!(big.detected_first >= small.detected_first);
    for by_method in d.faulted.values() {
        for f in by_method.values() {
            assert_eq!(f.mi, 0);
        }
    }
}

#[test]
fn with_pairs_monitored_two_simultaneous_faults_are_excluded_and_never_hazardous() {
    let p = RaimParams {
        seed: 11,
        draws: 40,
        faults: vec![Fault {
            kind: FaultKind::Step(50.0),
            satellites: 2,
        }],
        methods: vec!["solution_separation", raim::PAIRS],
        ..RaimParams::default()
    };
    let r = raim::run(&[geonet()], &p).unwrap();
    let d = &r.datasets[0];
    let by = &d.faulted["step 50 m ×2"];
    let (single, pairs) = (&by["solution_separation"], &by[raim::PAIRS]);
    let tested = pairs.draws - pairs.skipped;
    let brief = |f: &raim::Faulted| {
        format!(
            "excluded first {} of {}, MI {} and HMI {} of {} epochs",
            f.excluded_first,
            f.draws - f.skipped,
            f.mi,
            f.hmi,
            f.epochs
        )
    };
    println!(
        "single-fault modes: {}; pairs monitored: {}",
        brief(single),
        brief(pairs)
    );
    // Under the ADD's threat model pairs are not modes: one exclusion never removes both
    // (docs/experiments.md: 0 % on the first epoch, MI on 2–4.5 % of faulted epochs).
    assert_eq!(single.excluded_first, 0);
    assert!(single.mi * 100 > single.epochs, "{}", brief(single));
    // With pairs monitored (P_sat 1e-4): both out on the first epoch in 20–44 % of draws
    // (by seed), no HMI, and MI under 1 % of faulted epochs.
    assert!(pairs.excluded_first * 10 >= tested, "{}", brief(pairs));
    assert_eq!(pairs.hmi, 0);
    assert!(pairs.mi * 100 < pairs.epochs, "{}", brief(pairs));
    assert!(pairs.mi < single.mi, "{}", brief(pairs));
    // The price: the pair subsets' geometry keeps the HPL above the HAL more often.
    let avail = |m: &str| d.fault_free[m].available;
    assert!(avail(raim::PAIRS) * 2 < avail("solution_separation"));
}
