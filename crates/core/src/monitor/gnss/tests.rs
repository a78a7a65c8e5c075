//! Tests of the `gnss` monitor on synthetic two-constellation skies (seeded noise): the
//! `raim` test's dof and threshold, exclusion and per-satellite health under counters,
//! protection levels bounding the error, errors against the truth, checkpoints and the
//! config's refusals.

use rand::SeedableRng;
use rand::rngs::StdRng;

use super::*;
use crate::detect::{Health, chi2};
use crate::epoch::{Constellation, GnssRawBlock, SatObs};
use crate::geo::Lla;
use crate::gnss::testdata::{add_noise, random_sky, synthetic};
use crate::monitor::{Availability, MonitorConfig, MonitorSpec, NoModels};

fn truth() -> Lla {
    Lla {
        lat: 0.66,
        lon: -2.13,
        h: 25.0,
    }
}

/// Ten satellites, GPS and Galileo alternating, σ 1 m, receiver clocks 30 km apart by
/// 12 m.
fn sky() -> Vec<SatObs> {
    let clock = |c| {
        if c == Constellation::Gps {
            3.0e4
        } else {
            3.0e4 - 12.0
        }
    };
    synthetic(&truth(), &random_sky(11, 10), clock, |_| 1.0)
}

fn epoch(t: f64, rng: &mut StdRng, bias: Option<(usize, f64)>) -> Epoch {
    let mut sats = sky();
    add_noise(&mut sats, rng);
    if let Some((i, b)) = bias {
        sats[i].pr += b;
    }
    let Lla { lat, lon, h } = truth();
    Epoch {
        t,
        gnss_raw: Some(GnssRawBlock {
            sats,
            truth: Some([lat, lon, h]),
        }),
        ..Epoch::default()
    }
}

fn monitor(config: serde_json::Value, policy: PolicyConfig) -> Box<dyn Monitor> {
    let spec = MonitorSpec {
        kind: MonitorKind::Gnss,
        config: MonitorConfig::parse(MonitorKind::Gnss, &config).unwrap(),
        policy,
        threshold: ThresholdSpec::PFa(1e-3),
    };
    crate::monitor::build(&spec, &NoModels).unwrap()
}

fn outputs(r: &MonitorReport) -> &GnssOutputs {
    match &r.outputs {
        Outputs::Gnss(o) => o,
        other => panic!("not gnss outputs: {other:?}"),
    }
}

fn health_of(r: &MonitorReport, id: &str) -> Health {
    outputs(r)
        .satellites
        .iter()
        .find(|s| s.id == id)
        .unwrap()
        .health
}

#[test]
fn fault_free_epochs_run_the_raim_test_at_the_dof_of_the_fix() {
    let mut m = monitor(
        serde_json::json!({"elevation_mask_deg": 0}),
        PolicyConfig::Classic,
    );
    let mut rng = StdRng::seed_from_u64(1);
    let mut exceed = 0;
    for k in 0..200 {
        let r = m.step(&epoch(k as f64, &mut rng, None)).unwrap();
        let test = &r.tests[0];
        // 10 satellites − 3 position − 2 clocks.
        assert_eq!(test.statistic.dof, 5);
        assert!((test.statistic.threshold - chi2::threshold(5, 1e-3).unwrap()).abs() < 1e-9);
        exceed += usize::from(test.statistic.exceeds());
        let o = outputs(&r);
        assert!(o.hpe.unwrap() < 10.0 && o.vpe.unwrap() < 15.0, "{o:?}");
        assert_eq!(o.clocks.len(), 2);
        assert!((o.clocks["G"] - o.clocks["E"] - 12.0).abs() < 10.0);
        assert_eq!(r.integrity.unwrap().state, Availability::Available);
    }
    // p_fa 1e-3: 0.2 exceedances expected in 200 epochs.
    assert!(exceed <= 2, "{exceed} exceedances");
}

#[test]
fn a_step_on_one_satellite_is_excluded_isolated_and_readmitted_once_clean() {
    let mut m = monitor(
        serde_json::json!({"elevation_mask_deg": 0, "fde": {"method": "greedy"}}),
        PolicyConfig::Counters { n1: 3, n2: 1 },
    );
    let mut rng = StdRng::seed_from_u64(2);
    let id = sky()[3].id.to_string();
    let mut trace = Vec::new();
    for k in 0..14 {
        let bias = (4..8).contains(&k).then_some((3, 60.0));
        let r = m.step(&epoch(k as f64, &mut rng, bias)).unwrap();
        let o = outputs(&r);
        let used = o.satellites.iter().find(|s| s.id == id).unwrap().used;
        trace.push((health_of(&r, &id), used, r.tests[0].statistic.exceeds()));
        // Whatever happens to the satellite, the final fix stays on the truth.
        assert!(o.hpe.unwrap() < 10.0, "epoch {k}: {o:?}");
        if k == 4 {
            assert_eq!(o.excluded, vec![id.clone()]);
        }
    }
    use Health::*;
    let healths: Vec<Health> = trace.iter().map(|t| t.0).collect();
    // Epoch 4: detected (the raim test exceeds) and excluded: suspect. Epoch 5: left
    // out, still biased: isolated (t3 = 2 > N2 = 1). Epochs 6, 7 biased: isolated.
    // From epoch 8 clean: N1 = 3 clean epochs (t2's timeout) clear t1: healthy at 10.
    assert_eq!(
        healths,
        [
            Healthy, Healthy, Healthy, Healthy, Suspect, Isolated, Isolated, Isolated, Isolated,
            Isolated, Healthy, Healthy, Healthy, Healthy
        ]
    );
    let used: Vec<bool> = trace.iter().map(|t| t.1).collect();
    assert_eq!(used[..4], [true; 4]);
    assert_eq!(used[4..11], [false; 7], "out while flagged");
    assert_eq!(used[11..], [true; 3], "re-admitted after it recovered");
    let raim: Vec<bool> = trace.iter().map(|t| t.2).collect();
    assert!(raim[4], "the step is detected on its first epoch");
    assert!(
        !raim[5..].iter().any(|&x| x),
        "{raim:?}: the fix without it passes"
    );
}

#[test]
fn protection_levels_bound_the_fault_free_error_by_either_method() {
    for protection in ["slope", "araim"] {
        let mut m = monitor(
            serde_json::json!({"elevation_mask_deg": 0, "protection": protection}),
            PolicyConfig::Classic,
        );
        let mut rng = StdRng::seed_from_u64(3);
        for k in 0..300 {
            let r = m.step(&epoch(k as f64, &mut rng, None)).unwrap();
            let o = outputs(&r);
            let (hpl, vpl) = (o.hpl.unwrap(), o.vpl.unwrap());
            assert!(
                hpl.is_finite() && hpl > 0.0 && vpl > 0.0,
                "{protection}: {o:?}"
            );
            assert!(
                o.hpe.unwrap() <= hpl && o.vpe.unwrap() <= vpl,
                "{protection}: {o:?}"
            );
            assert_eq!(r.integrity.unwrap().protection_level, hpl);
        }
    }
}

#[test]
fn a_tight_vertical_limit_makes_integrity_unavailable_never_a_test() {
    let mut m = monitor(
        serde_json::json!({"elevation_mask_deg": 0, "val_m": 0.5}),
        PolicyConfig::Classic,
    );
    let r = m
        .step(&epoch(0.0, &mut StdRng::seed_from_u64(4), None))
        .unwrap();
    assert_eq!(r.integrity.unwrap().state, Availability::Unavailable);
    assert_eq!(r.tests.len(), 1);
}

#[test]
fn too_few_satellites_give_no_fix_no_test_and_no_availability() {
    let mut m = monitor(serde_json::json!({}), PolicyConfig::Classic);
    let mut e = epoch(0.0, &mut StdRng::seed_from_u64(5), None);
    e.gnss_raw.as_mut().unwrap().sats.truncate(4);
    let r = m.step(&e).unwrap();
    assert!(r.tests.is_empty());
    let integrity = r.integrity.unwrap();
    assert_eq!(integrity.state, Availability::Unavailable);
    // No level to report: NaN, which goes out as null (as while an imu monitor aligns).
    assert!(integrity.protection_level.is_nan());
    let o = outputs(&r);
    assert!(o.position.is_none() && o.hpl.is_none());
    assert_eq!(o.satellites.len(), 4);
}

#[test]
fn epochs_without_pseudoranges_repeat_the_last_outputs() {
    let mut m = monitor(serde_json::json!({}), PolicyConfig::Classic);
    let first = m
        .step(&epoch(0.0, &mut StdRng::seed_from_u64(6), None))
        .unwrap();
    let r = m
        .step(&Epoch {
            t: 0.5,
            ..Epoch::default()
        })
        .unwrap();
    assert!(r.tests.is_empty() && r.integrity.is_none());
    assert_eq!(r.outputs, first.outputs);
}

#[test]
fn a_restored_checkpoint_carries_on_exactly() {
    let policy = PolicyConfig::Counters { n1: 5, n2: 1 };
    let config = serde_json::json!({"elevation_mask_deg": 0});
    let mut a = monitor(config.clone(), policy);
    let mut rng = StdRng::seed_from_u64(7);
    let epochs: Vec<Epoch> = (0..12)
        .map(|k| epoch(k as f64, &mut rng, (3..9).contains(&k).then_some((1, 80.0))))
        .collect();
    for e in &epochs[..5] {
        a.step(e).unwrap();
    }
    let mut b = monitor(config, policy);
    b.restore(&a.checkpoint().unwrap()).unwrap();
    for e in &epochs[5..] {
        let (ra, rb) = (a.step(e).unwrap(), b.step(e).unwrap());
        assert_eq!(ra.outputs, rb.outputs);
        assert_eq!(ra.tests, rb.tests);
    }
    let other = monitor(serde_json::json!({}), PolicyConfig::Classic)
        .checkpoint()
        .unwrap();
    let mut tacan_bytes = other.clone();
    tacan_bytes[crate::monitor::checkpoint::HEADER - 1] = 5;
    assert!(b.restore(&tacan_bytes).is_err());
}

#[test]
fn configs_are_refused_naming_the_field() {
    let field = |config: serde_json::Value| {
        MonitorConfig::parse(MonitorKind::Gnss, &config)
            .and_then(|c| match c {
                MonitorConfig::Gnss(w) => GnssConfig::try_from(w).map(|_| ()),
                _ => unreachable!(),
            })
            .unwrap_err()
            .field
    };
    use serde_json::json;
    assert_eq!(
        field(json!({"elevation_mask_deg": 75})),
        "elevation_mask_deg"
    );
    assert_eq!(field(json!({"sigma": {"scale": 0}})), "sigma.scale");
    assert_eq!(field(json!({"sigma": {"model": "snr"}})), "sigma.model");
    assert_eq!(
        field(json!({"fde": {"max_exclusions": 11}})),
        "fde.max_exclusions"
    );
    assert_eq!(field(json!({"hal_m": -1})), "hal_m");
    assert_eq!(field(json!({"ism": {"sigma_ura_m": 0}})), "ism.sigma_ura_m");
    assert_eq!(field(json!({"araim": {"p_sat": 2}})), "araim.p_sat");
    assert_eq!(field(json!({"mask": 5})), "mask");
}

#[test]
fn calibration_proposes_the_sigma_scale_the_data_need() {
    // The data's noise is 2.5 × the σ the satellites report.
    let mut rng = StdRng::seed_from_u64(8);
    let epochs: Vec<Epoch> = (0..400)
        .map(|k| {
            let mut e = epoch(k as f64, &mut rng, None);
            let b = e.gnss_raw.as_mut().unwrap();
            for (s, clean) in b.sats.iter_mut().zip(sky()) {
                s.pr = clean.pr + 2.5 * (s.pr - clean.pr);
            }
            e
        })
        .collect();
    let mut m = monitor(
        serde_json::json!({"elevation_mask_deg": 0}),
        PolicyConfig::Classic,
    );
    let lines =
        crate::monitor::calibrate::calibrate_monitor(m.as_mut(), &epochs, 0.01, 0.95).unwrap();
    let k = lines[0].noise_scale.unwrap();
    assert!((k - 2.5).abs() < 0.1, "σ scale {k}");
}
