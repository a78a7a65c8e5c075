//! Unit tests of the federated monitor: config defaults and refusals, the tests it runs,
//! the fault-free ship, seed 004's GNSS jump, integrity, gaps and failed steps.

use super::*;
use crate::epoch::{CnsBlock, GnssBlock, InsBlock};
use crate::filter::federated::ins_transition;
use crate::filter::ins::{ATT, ErrorVector, ImuErrors};
use nalgebra::{Rotation3, SVector};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use serde_json::{Value, json};

fn all_aids() -> Value {
    json!({"aids": ["gnss", "dvl", "cns"]})
}

fn monitor(config: Value, policy: PolicyConfig, spec: ThresholdSpec) -> FederatedMonitor {
    FederatedMonitor::new(FederatedConfig::from_json(&config).unwrap(), policy, spec).unwrap()
}

#[test]
fn every_field_but_aids_defaults_to_seed_004() {
    let c = FederatedConfig::from_json(&all_aids()).unwrap();
    assert_eq!(c.aids, vec![Aid::Gnss, Aid::Dvl, Aid::Cns]);
    assert_eq!((c.gnss_pos_sigma_m, c.gnss_vel_sigma_mps), (10.0, 0.1));
    assert_eq!((c.dvl_vel_sigma_mps, c.cns_pos_sigma_m), (0.1, 450.0));
    assert_eq!(c.imu, ImuErrors::default());
    assert_eq!(c.init_att_sigma_arcsec, [5.0, 5.0, 30.0]);
    assert_eq!((c.init_pos_sigma_m, c.init_vel_sigma_mps), (10.0, 0.1));
    assert_eq!(c.beta, vec![1.0 / 3.0; 3]);
    assert_eq!((c.hal_m, c.p_md), (DEFAULT_HAL_M, 1e-3));
    let p0 = c.initial_estimate().p;
    let arcsec = (1.0f64 / 3600.0).to_radians();
    assert!((p0[(ATT + 2, ATT + 2)].sqrt() - 30.0 * arcsec).abs() < 1e-18);
    assert_eq!(p0[(POS, POS)], 100.0);
    let c = FederatedConfig::from_json(&json!({
        "aids": ["cns", "gnss"],
        "gnss": {"pos_sigma_m": 3},
        "beta": {"gnss": 0.75, "cns": 0.25},
        "imu": {"gyro_bias_dph": 0.01},
        "init": {"att_sigma_arcsec": [10, 10, 60]},
        "hal_m": 40,
        "p_md": 1e-4
    }))
    .unwrap();
    assert_eq!(c.aids, vec![Aid::Cns, Aid::Gnss]);
    assert_eq!(c.beta, vec![0.25, 0.75], "β follows the order of aids");
    assert_eq!(
        (c.gnss_pos_sigma_m, c.imu.gyro_bias_dph, c.hal_m),
        (3.0, 0.01, 40.0)
    );
}

#[test]
fn invalid_configs_are_refused_naming_the_field() {
    let cases = [
        (json!({}), "aids"),
        (json!({"aids": []}), "aids"),
        (json!({"aids": ["gnss", "radar"]}), "aids[1]"),
        (json!({"aids": ["gnss", "gnss"]}), "aids[1]"),
        (
            json!({"aids": ["gnss"], "gnss": {"pos_sigma_m": -1}}),
            "gnss.pos_sigma_m",
        ),
        (
            json!({"aids": ["gnss"], "gnss": {"pos_sigma": 1}}),
            "gnss.pos_sigma",
        ),
        (
            json!({"aids": ["gnss"], "dvl": {"vel_sigma_mps": 1}}),
            "dvl",
        ),
        (
            json!({"aids": ["dvl"], "dvl": {"vel_sigma_mps": "x"}}),
            "dvl.vel_sigma_mps",
        ),
        (
            json!({"aids": ["cns"], "imu": {"arw_deg_rthr": 0}}),
            "imu.arw_deg_rthr",
        ),
        (
            json!({"aids": ["cns"], "init": {"att_sigma_arcsec": [1, 2]}}),
            "init.att_sigma_arcsec",
        ),
        (
            json!({"aids": ["cns"], "init": {"att_sigma_arcsec": [1, 2, 0]}}),
            "init.att_sigma_arcsec[2]",
        ),
        (
            json!({"aids": ["gnss", "cns"], "beta": {"gnss": 0.5, "cns": 0.6}}),
            "beta",
        ),
        (
            json!({"aids": ["gnss", "cns"], "beta": {"gnss": 0.5}}),
            "beta",
        ),
        (
            json!({"aids": ["gnss"], "beta": {"gnss": 0.5, "dvl": 0.5}}),
            "beta.dvl",
        ),
        (json!({"aids": ["gnss"], "beta": {"gnss": 2}}), "beta.gnss"),
        (json!({"aids": ["gnss"], "hal_m": 0}), "hal_m"),
        (json!({"aids": ["gnss"], "p_md": 1}), "p_md"),
        (json!({"aids": ["gnss"], "extra": 1}), "extra"),
    ];
    for (config, field) in cases {
        let e = FederatedConfig::from_json(&config).unwrap_err();
        assert_eq!(e.field, field, "{config}: {e}");
    }
    let spec = MonitorSpecForTest::build(json!({"aids": ["gnss"], "hal_m": -3}));
    assert_eq!(
        spec.err().map(|e| e.to_string()).unwrap_or_default(),
        "config.hal_m: must be a finite number > 0"
    );
}

#[test]
fn guard_and_convergence_fields_are_refused_by_monitor_build_naming_the_exact_path() {
    let cases = [
        (
            json!({"gnss": {"drift": {"windows": []}}}),
            "gnss.drift.windows",
        ),
        (
            json!({"gnss": {"drift": {"windows": [0]}}}),
            "gnss.drift.windows[0]",
        ),
        (
            json!({"gnss": {"drift": {"windows": [5, 1001]}}}),
            "gnss.drift.windows[1]",
        ),
        (
            json!({"gnss": {"drift": {"windows": [5, 5]}}}),
            "gnss.drift.windows[1]",
        ),
        (json!({"gnss": {"drift": {"p_fa": 0}}}), "gnss.drift.p_fa"),
        (
            json!({"gnss": {"drift": {"threshold": -1}}}),
            "gnss.drift.threshold",
        ),
        (
            json!({"gnss": {"drift": {"p_fa": 0.1, "threshold": 9}}}),
            "gnss.drift",
        ),
        (
            json!({"gnss": {"drift": {"scales": [5]}}}),
            "gnss.drift.scales",
        ),
        (
            json!({"gnss": {"drift": {"windows": "10"}}}),
            "gnss.drift.windows",
        ),
        (json!({"gnss": {"stuck": {"k": 1}}}), "gnss.stuck.k"),
        (json!({"gnss": {"stuck": {"p_fa": 1}}}), "gnss.stuck.p_fa"),
        (
            json!({"gnss": {"stuck": {"threshold": 0}}}),
            "gnss.stuck.threshold",
        ),
        (
            json!({"gnss": {"stuck": {"p_fa": 1e-6, "threshold": 24}}}),
            "gnss.stuck",
        ),
        (
            json!({"gnss": {"stuck": {"enabled": "yes"}}}),
            "gnss.stuck.enabled",
        ),
        (
            json!({"dvl": {"drift": {"windows": [0]}}}),
            "dvl.drift.windows[0]",
        ),
        (json!({"dvl": {"stuck": {"k": 5000}}}), "dvl.stuck.k"),
        (json!({"cns": {"drift": {"p_fa": -1}}}), "cns.drift.p_fa"),
        (
            json!({"cns": {"stuck": {"threshold": 0}}}),
            "cns.stuck.threshold",
        ),
        (json!({"converge_max_s": 0}), "converge_max_s"),
        (json!({"converge_max_s": -5}), "converge_max_s"),
        (json!({"converge_max_s": "long"}), "converge_max_s"),
    ];
    for (extra, field) in cases {
        let mut config = all_aids();
        for (k, v) in extra.as_object().unwrap() {
            config[k] = v.clone();
        }
        match MonitorSpecForTest::build(config) {
            Err(crate::monitor::BuildError::Config(e)) => {
                assert_eq!(e.field, field, "{extra}: {e}")
            }
            Err(e) => panic!("{extra}: {e}"),
            Ok(_) => panic!("{extra} accepted"),
        }
    }
}

#[test]
fn a_config_stored_before_the_guards_loads_with_their_defaults() {
    // A session spec written before drift, stuck and converge_max_s existed.
    let old = json!({"aids": ["gnss", "dvl", "cns"], "gnss": {"pos_sigma_m": 10, "vel_sigma_mps": 0.1},
                     "dvl": {"vel_sigma_mps": 0.1}, "cns": {"pos_sigma_m": 450}, "hal_m": 25, "p_md": 0.001});
    let c = FederatedConfig::from_json(&old).unwrap();
    assert_eq!(c.converge_max_s, DEFAULT_CONVERGE_MAX_S);
    let on = |i: usize| (c.guards[i].drift.is_some(), c.guards[i].stuck.is_some());
    assert_eq!(
        [on(0), on(1), on(2)],
        [
            (GNSS_DRIFT_DEFAULT_ON, STUCK_DEFAULT_ON),
            (DVL_DRIFT_DEFAULT_ON, STUCK_DEFAULT_ON),
            (CNS_DRIFT_DEFAULT_ON, STUCK_DEFAULT_ON)
        ]
    );
    assert!(MonitorSpecForTest::build(old.clone()).is_ok());
    // The typed wire form round-trips without inventing blocks.
    let wire: FederatedConfigWire = serde_json::from_value(old).unwrap();
    let back = serde_json::to_value(&wire).unwrap();
    assert!(back["gnss"].get("drift").is_none(), "{back}");
    assert_eq!(back["converge_max_s"], json!(DEFAULT_CONVERGE_MAX_S));
}

/// `monitor::build` as the REST layer calls it.
struct MonitorSpecForTest;

impl MonitorSpecForTest {
    fn build(config: Value) -> Result<Box<dyn Monitor>, crate::monitor::BuildError> {
        crate::monitor::build(
            &crate::monitor::MonitorSpec {
                kind: MonitorKind::Federated,
                config: crate::monitor::MonitorConfig::parse(MonitorKind::Federated, &config)?,
                policy: PolicyConfig::counters_default(),
                threshold: ThresholdSpec::Threshold(20.0),
            },
            &crate::monitor::NoModels,
        )
    }
}

#[test]
fn one_test_per_configured_aid_then_the_guards_and_no_hpl_test() {
    let m = monitor(
        json!({"aids": ["dvl", "gnss"], "hal_m": 55}),
        PolicyConfig::counters_default(),
        ThresholdSpec::PFa(0.002),
    );
    let slots = m.tests().slots();
    let names: Vec<_> = slots.iter().map(|s| (&*s.name, s.dof)).collect();
    // The defaults: gnss.drift (horizontal, dof 2) and dvl.drift on, every aid's stuck
    // test on.
    assert_eq!(
        names,
        vec![
            ("dvl", 3),
            ("gnss", 6),
            ("dvl.drift", 3),
            ("dvl.stuck", 1),
            ("gnss.drift", 2),
            ("gnss.stuck", 1)
        ]
    );
    assert!((slots[1].threshold_for(3).unwrap() - 14.7955).abs() < 1e-4);
    // The drift tests follow the monitor's spec (χ²(3), χ²(2) at 0.002), the stuck tests
    // keep their own (χ²(1) at 1e-6); all follow the monitor's policy.
    assert!((slots[2].threshold - 14.7955).abs() < 1e-4);
    assert!((slots[4].threshold - 12.4292).abs() < 1e-4);
    assert!((slots[3].threshold - 23.9281).abs() < 1e-3);
    assert_eq!(slots[5].policy.config(), PolicyConfig::counters_default());
    assert!(
        m.tests().index_of("hpl").is_none(),
        "HPL is integrity, not a test"
    );
    assert!(MonitorSpecForTest::build(all_aids()).is_ok());
    // Each block can be turned on, off or tuned in its aid's section.
    let m = monitor(
        json!({"aids": ["gnss", "dvl", "cns"],
               "gnss": {"drift": {"enabled": false}, "stuck": {"k": 12, "threshold": 40}},
               "dvl": {"drift": {"windows": [5, 30], "p_fa": 1e-4}, "stuck": {"enabled": false}},
               "cns": {"drift": {}}}),
        PolicyConfig::Classic,
        ThresholdSpec::PFa(1e-3),
    );
    let slots = m.tests().slots();
    let names: Vec<_> = slots.iter().map(|s| &*s.name).collect();
    assert_eq!(
        names,
        [
            "gnss",
            "dvl",
            "cns",
            "gnss.stuck",
            "dvl.drift",
            "cns.drift",
            "cns.stuck"
        ]
    );
    assert_eq!(slots[3].threshold, 40.0);
    assert!((slots[4].threshold - chi2_threshold(3, 1e-4)).abs() < 1e-9);
    assert!((slots[5].threshold - chi2_threshold(2, 1e-3)).abs() < 1e-9);
}

fn chi2_threshold(dof: u32, p_fa: f64) -> f64 {
    crate::detect::chi2::threshold(dof, p_fa).unwrap()
}

/// A ship at 30° N sailing north-east at 5 m/s, with an INS whose error follows the
/// monitor's own model (seeded), and noisy aids.
struct Ship {
    rng: StdRng,
    t: f64,
    dt: f64,
    truth: Lla,
    vel: Vector3<f64>,
    c_bn: nalgebra::Matrix3<f64>,
    error: ErrorVector,
    imu: ImuErrors,
}

impl Ship {
    fn new(seed: u64, dt: f64) -> Self {
        let mut rng = StdRng::seed_from_u64(seed);
        let p0 = FederatedConfig::from_json(&all_aids())
            .unwrap()
            .initial_estimate()
            .p;
        let error =
            ErrorVector::from_fn(|i, _| p0[(i, i)].sqrt() * rng.sample::<f64, _>(StandardNormal));
        let v = 5.0 * std::f64::consts::FRAC_1_SQRT_2;
        Ship {
            rng,
            t: 0.0,
            dt,
            truth: Lla {
                lat: 30f64.to_radians(),
                lon: 120f64.to_radians(),
                h: 0.0,
            },
            vel: Vector3::new(v, v, 0.0),
            c_bn: geo::dcm_body_to_nav(0.0, 0.0, 45f64.to_radians()),
            error,
            imu: ImuErrors::default(),
        }
    }

    fn gauss(&mut self) -> f64 {
        self.rng.sample(StandardNormal)
    }

    fn ins(&self) -> InsBlock {
        let dp = Vector3::new(self.error[POS], self.error[POS + 1], self.error[POS + 2]);
        let phi = Vector3::new(self.error[ATT], self.error[ATT + 1], self.error[ATT + 2]);
        let c = Rotation3::new(-phi).into_inner() * self.c_bn;
        let p = geo::apply_offset(&self.truth, &dp);
        let v = self.vel + Vector3::new(self.error[VEL], self.error[VEL + 1], self.error[VEL + 2]);
        InsBlock {
            lat: p.lat,
            lon: p.lon,
            h: p.h,
            vel: [v.x, v.y, v.z],
            att: geo::euler_from_dcm(&c),
            f_b: None,
        }
    }

    /// The next epoch: truth and INS error advance, every aid reports.
    fn next(&mut self, gnss_offset: Vector3<f64>) -> Epoch {
        self.t += self.dt;
        self.truth = geo::apply_offset(&self.truth, &(self.vel * self.dt));
        let nav = NavSolution::from_ins(&self.ins());
        let trans = ins_transition(&nav, &self.imu, self.dt).unwrap();
        let g = crate::filter::ins::noise_input(&nav);
        let w = SVector::<f64, 6>::from_fn(|i, _| {
            let psd = if i < 3 {
                self.imu.gyro_noise_psd()
            } else {
                self.imu.accel_noise_psd()
            };
            (psd * self.dt).sqrt() * self.rng.sample::<f64, _>(StandardNormal)
        });
        self.error = trans.f * self.error + g * w;
        let noise = Vector3::new(self.gauss(), self.gauss(), self.gauss()) * 10.0 + gnss_offset;
        let fix = geo::apply_offset(&self.truth, &noise);
        let gv = self.vel + Vector3::new(self.gauss(), self.gauss(), self.gauss()) * 0.1;
        let dvl = self.c_bn.transpose() * self.vel
            + Vector3::new(self.gauss(), self.gauss(), self.gauss()) * 0.1;
        let cns_noise = Vector3::new(self.gauss() * 450.0, self.gauss() * 450.0, 0.0);
        let cns = geo::apply_offset(&self.truth, &cns_noise);
        Epoch {
            t: self.t,
            ins: Some(self.ins()),
            gnss: Some(GnssBlock {
                lat: fix.lat,
                lon: fix.lon,
                h: fix.h,
                vel: Some([gv.x, gv.y, gv.z]),
                pos_sigma: None,
                vel_sigma: None,
            }),
            dvl_vel_b: Some([dvl.x, dvl.y, dvl.z]),
            cns: Some(CnsBlock {
                lat: cns.lat,
                lon: cns.lon,
            }),
            ..Default::default()
        }
    }
}

fn outputs(r: &MonitorReport) -> (FederatedSolution, f64, Vec<&'static str>) {
    match &r.outputs {
        Outputs::Federated {
            solution: Some(s),
            hpl: Some(h),
            isolated,
            alignment: None,
        } => (*s, *h, isolated.clone()),
        other => panic!("unexpected outputs {other:?}"),
    }
}

#[test]
fn fault_free_ship_is_consistent_quiet_and_inside_its_protection_level() {
    // 1,500 s at 1 Hz, every aid every epoch, counters policy at p_fa 1e-3 per test.
    let mut ship = Ship::new(21, 1.0);
    let mut m = monitor(
        all_aids(),
        PolicyConfig::counters_default(),
        ThresholdSpec::PFa(1e-3),
    );
    let epochs = 1500;
    let mut sums = [0.0; 3];
    let mut exceed = [0usize; 3];
    let mut worst_ratio: f64 = 0.0;
    let mut max_hpl: f64 = 0.0;
    for k in 0..epochs {
        let e = ship.next(Vector3::zeros());
        let r = m.step(&e).unwrap();
        let (sol, hpl, isolated) = outputs(&r);
        assert!(isolated.is_empty(), "epoch {k}: {isolated:?}");
        for o in r.tests.iter().filter(|o| o.index < 3) {
            sums[o.index] += o.statistic.value;
            exceed[o.index] += usize::from(o.statistic.exceeds());
        }
        // Drift and stuck tests beside them: no isolation fault-free.
        assert!(
            r.tests
                .iter()
                .all(|o| o.decision.health != Health::Isolated),
            "epoch {k}"
        );
        let integrity = r.integrity.unwrap();
        assert_eq!(integrity.protection_level, hpl);
        if k >= 10 {
            assert_eq!(
                integrity.state,
                crate::monitor::Availability::Available,
                "epoch {k}"
            );
        }
        if k >= 10 {
            worst_ratio = worst_ratio.max(horizontal_error_m(&sol, &ship.truth) / hpl);
            max_hpl = max_hpl.max(hpl);
        }
    }
    let k = f64::from(epochs);
    for (i, dof) in [6.0, 3.0, 2.0].into_iter().enumerate() {
        // Local filters carry P_g/β_i, so their NIS is at most χ²(m)'s mean, never above.
        let mean = sums[i] / k;
        assert!(
            mean < dof + 4.0 * (2.0 * dof / k).sqrt(),
            "test {i}: mean λ {mean}"
        );
        assert!(
            mean > 0.3 * dof,
            "test {i}: mean λ {mean} is implausibly small"
        );
        // Exceedances of a 1e-3 threshold: at most a handful in 1,500 (binomial, 1e-6 tail).
        assert!(exceed[i] <= 8, "test {i}: {} exceedances", exceed[i]);
    }
    assert!(
        worst_ratio < 1.0,
        "horizontal error reached {worst_ratio} × HPL"
    );
    assert!(max_hpl < DEFAULT_HAL_M, "HPL {max_hpl} m");
    assert_consistency_fed_with_nu(&m);
}

/// The corrected position's horizontal distance from the truth, m.
fn horizontal_error_m(sol: &FederatedSolution, truth: &Lla) -> f64 {
    let fixed = Lla {
        lat: sol.lat.to_radians(),
        lon: sol.lon.to_radians(),
        h: sol.h,
    };
    geo::local_offset(&fixed, truth).xy().norm()
}

/// Every aid's χ² test fed its consistency diagnostics with ν (‖ν‖² = λ): healthy epochs
/// only, the NIS mean a little below the dof (the local priors carry P_g/β).
fn assert_consistency_fed_with_nu(m: &FederatedMonitor) {
    for (i, dof) in [6.0, 3.0, 2.0].into_iter().enumerate() {
        let mut c = m.tests().slots()[i].consistency.clone();
        let summary = c.summary().unwrap();
        assert!(summary.samples >= 30, "test {i}: {summary:?}");
        assert!(
            summary.nis_mean > 0.3 * dof && summary.nis_mean < 2.0 * dof,
            "test {i}: {summary:?}"
        );
    }
}

#[test]
fn gnss_jump_is_suspect_then_isolated_then_readmitted_after_it_ends() {
    // Seed 004's fault: 0.02′ of latitude and longitude (≈ 37 m and 32 m) for 120 s.
    let mut ship = Ship::new(22, 1.0);
    let mut m = monitor(
        all_aids(),
        PolicyConfig::counters_default(),
        ThresholdSpec::Threshold(20.0),
    );
    let jump = Vector3::new(32.1, 36.9, 0.0);
    let (onset, end) = (300, 420);
    let mut health = Vec::new();
    for k in 0..600 {
        let offset = if (onset..end).contains(&k) {
            jump
        } else {
            Vector3::zeros()
        };
        let r = m.step(&ship.next(offset)).unwrap();
        let gnss = r.tests.iter().find(|o| &*o.name == "gnss").unwrap();
        health.push(gnss.decision.health);
        // The aid is left out of fusion when any of its tests is isolated.
        let aid = r
            .tests
            .iter()
            .filter(|o| o.name.starts_with("gnss"))
            .map(|o| o.decision.health)
            .fold(Health::Healthy, crate::monitor::guards::worse);
        let (_, _, isolated) = outputs(&r);
        assert_eq!(isolated.contains(&"gnss"), aid == Health::Isolated);
    }
    assert!(health[..onset].iter().all(|&h| h == Health::Healthy));
    let suspect = (onset..).find(|&k| health[k] != Health::Healthy).unwrap();
    // Out of updating within 2 GNSS epochs of onset; isolated after N2 + 1 = 6
    // exceedances, allowing one quiet epoch between them. (The jump is only ≈ 2.6 σ of the
    // 10 m GNSS per axis: λ ≈ 25 against T_D = 20, so single epochs can pass.)
    assert!(suspect <= onset + 2, "suspect at {suspect}");
    let isolated = (onset..).find(|&k| health[k] == Health::Isolated).unwrap();
    assert!(isolated <= suspect + 5 + 1, "isolated at {isolated}");
    let back = (isolated..)
        .find(|&k| health[k] == Health::Healthy)
        .unwrap();
    assert!(
        back >= end,
        "readmitted at {back}, before the fault ended at {end}"
    );
    assert!(back <= end + 12, "readmitted only at {back}");
    // Fault-free again: an occasional exceedance (p_fa of χ²(6) at 20 is 0.28 %) may make
    // it suspect, never isolated.
    assert!(health[back..].iter().all(|&h| h != Health::Isolated));
}

#[test]
fn integrity_converges_from_p0_then_is_available_and_an_unreachable_limit_is_unavailable() {
    use crate::monitor::Availability::{Available, Converging, Unavailable};
    // Default HAL 25 m: HPL from P₀ (10 m per axis) is above it at t = 0, which is
    // convergence, not a fault: no test raises anything.
    let mut ship = Ship::new(23, 1.0);
    let mut m = monitor(
        all_aids(),
        PolicyConfig::counters_default(),
        ThresholdSpec::PFa(1e-3),
    );
    let mut states = Vec::new();
    for _ in 0..60 {
        let r = m.step(&ship.next(Vector3::zeros())).unwrap();
        let (_, hpl, _) = outputs(&r);
        let i = r.integrity.unwrap();
        assert_eq!((i.protection_level, i.alert_limit), (hpl, DEFAULT_HAL_M));
        assert!(r.tests.iter().all(|o| o.decision.health == Health::Healthy));
        states.push(i.state);
    }
    assert_eq!(states[0], Converging);
    let first = states.iter().position(|&s| s == Available).unwrap();
    assert!(states[..first].iter().all(|&s| s == Converging));
    assert!(
        states[first..].iter().all(|&s| s == Available),
        "{states:?}"
    );
    // A reset (new stream) converges again.
    m.reset();
    let r = m.step(&ship.next(Vector3::zeros())).unwrap();
    assert_eq!(r.integrity.unwrap().state, Converging);
    // A 5 m limit is never reached: converging for converge_max_s, then unavailable.
    let mut m = monitor(
        json!({"aids": ["gnss", "dvl", "cns"], "hal_m": 5, "converge_max_s": 20}),
        PolicyConfig::counters_default(),
        ThresholdSpec::PFa(1e-3),
    );
    let states: Vec<_> = (0..30)
        .map(|_| {
            m.step(&ship.next(Vector3::zeros()))
                .unwrap()
                .integrity
                .unwrap()
                .state
        })
        .collect();
    assert!(states[..20].iter().all(|&s| s == Converging), "{states:?}");
    assert!(states[20..].iter().all(|&s| s == Unavailable), "{states:?}");
    // Epochs without INS report none.
    let e = Epoch {
        ins: None,
        ..ship.next(Vector3::zeros())
    };
    assert_eq!(m.step(&e).unwrap().integrity, None);
}

#[test]
fn a_slow_gnss_drift_is_caught_by_its_drift_test_which_stops_the_update() {
    // 1 m/s north-east from 400 s: the windowed mean of the whitened position innovation
    // crosses its threshold while the per-epoch χ² is still quiet; the combined decision
    // then stops GNSS updating (suspect: predict only).
    let mut ship = Ship::new(28, 1.0);
    let mut m = monitor(
        all_aids(),
        PolicyConfig::counters_default(),
        ThresholdSpec::PFa(1e-3),
    );
    let onset = 400;
    let (mut drift_first, mut chi2_first) = (None, None);
    for k in 0..onset + 120 {
        let d = if k >= onset {
            f64::from(k - onset)
        } else {
            0.0
        };
        let r = m
            .step(&ship.next(Vector3::new(d, d, 0.0) * std::f64::consts::FRAC_1_SQRT_2))
            .unwrap();
        let health = |name: &str| {
            r.tests
                .iter()
                .find(|o| &*o.name == name)
                .map(|o| o.decision.health)
        };
        if k < onset {
            continue;
        }
        if drift_first.is_none() && health("gnss.drift").is_some_and(|h| h != Health::Healthy) {
            drift_first = Some(k - onset);
            // The local filter is not updated this epoch.
            let aid = r.tests.iter().find(|o| &*o.name == "gnss.drift").unwrap();
            assert!(!aid.decision.update);
        }
        if chi2_first.is_none() && health("gnss").is_some_and(|h| h != Health::Healthy) {
            chi2_first = Some(k - onset);
        }
    }
    let drift = drift_first.expect("the drift test fires");
    assert!(drift <= 40, "drift flagged after {drift} s");
    assert!(
        chi2_first.is_none_or(|c| c >= drift),
        "{chi2_first:?} vs {drift}"
    );
    assert_eq!(
        outputs(&m.step(&ship.next(Vector3::new(90.0, 90.0, 0.0))).unwrap()).2,
        vec!["gnss"]
    );
}

#[test]
fn under_traditional_an_excluded_gnss_filter_still_updates_and_is_readmitted_without_reset() {
    let mut ship = Ship::new(29, 1.0);
    let mut m = monitor(
        json!({"aids": ["gnss", "dvl", "cns"], "gnss": {"drift": {"enabled": false}}}),
        PolicyConfig::Traditional,
        ThresholdSpec::Threshold(20.0),
    );
    for _ in 0..300 {
        m.step(&ship.next(Vector3::zeros())).unwrap();
    }
    // A 100 m jump: far above the threshold.
    let r = m.step(&ship.next(Vector3::new(100.0, 0.0, 0.0))).unwrap();
    let gnss = &r.tests[0];
    assert_eq!(&*gnss.name, "gnss");
    assert_eq!(gnss.decision.health, Health::Isolated);
    assert!(gnss.decision.update && !gnss.decision.fuse);
    assert_eq!(outputs(&r).2, vec!["gnss"]);
    // The GNSS local filter has its own estimate, pulled by the faulty fix (z = INS − GNSS
    // moves 100 m west, and so does its INS position error estimate); the master, fused
    // without it, is not.
    let own = m.filter().state().own[0]
        .clone()
        .expect("left out of fusion");
    let master = m.filter().master();
    assert!(
        master.x[POS] - own.x[POS] > 1.0,
        "{} vs {}",
        own.x[POS],
        master.x[POS]
    );
    // The next quiet epoch readmits it as it is (no reset).
    let r = m.step(&ship.next(Vector3::zeros())).unwrap();
    assert_eq!(r.tests[0].decision.health, Health::Healthy);
    assert!(!r.tests[0].decision.reset);
}

#[test]
fn epochs_without_ins_are_ignored_and_gnss_without_velocity_has_dof_3() {
    let mut ship = Ship::new(24, 0.1);
    let mut m = monitor(
        all_aids(),
        PolicyConfig::counters_default(),
        ThresholdSpec::PFa(0.002),
    );
    let mut e = ship.next(Vector3::zeros());
    let aid_only = Epoch {
        ins: None,
        ..e.clone()
    };
    let r = m.step(&aid_only).unwrap();
    assert!(r.tests.is_empty());
    assert_eq!(
        r.outputs,
        Outputs::Federated {
            solution: None,
            hpl: None,
            isolated: vec![],
            alignment: None,
        }
    );
    assert!(m.check_epoch("fed", &aid_only).is_ok());
    if let Some(g) = &mut e.gnss {
        g.vel = None;
    }
    e.dvl_vel_b = None;
    let r = m.step(&e).unwrap();
    let names: Vec<_> = r
        .tests
        .iter()
        .map(|o| (&*o.name, o.statistic.dof))
        .collect();
    // The drift and stuck tests warm up: nothing from them on the first epochs.
    assert_eq!(names, vec![("gnss", 3), ("cns", 2)]);
    assert!((r.tests[0].statistic.threshold - 14.7955).abs() < 1e-4);
    let state = m.filter().state().clone();
    let r = m.step(&aid_only).unwrap();
    assert!(r.tests.is_empty());
    assert_eq!(m.filter().state(), &state);
    let (sol, hpl, _) = outputs(&r);
    assert!(sol.lat > 29.9 && hpl > 0.0, "the last outputs are repeated");
}

#[test]
fn a_failed_step_leaves_the_monitor_untouched() {
    let mut ship = Ship::new(25, 1.0);
    let mut m = monitor(
        all_aids(),
        PolicyConfig::counters_default(),
        ThresholdSpec::Threshold(20.0),
    );
    for _ in 0..5 {
        m.step(&ship.next(Vector3::zeros())).unwrap();
    }
    let state = m.filter().state().clone();
    let policies: Vec<_> = m.tests().slots().iter().map(|s| s.policy.clone()).collect();
    let outputs_before = m.outputs.clone();
    // An absurd INS velocity overflows the prediction.
    let mut bad = ship.next(Vector3::zeros());
    if let Some(ins) = &mut bad.ins {
        ins.vel = [1e300, 0.0, 0.0];
    }
    assert!(m.step(&bad).is_err());
    assert_eq!(m.filter().state(), &state);
    let after: Vec<_> = m.tests().slots().iter().map(|s| s.policy.clone()).collect();
    assert_eq!(after, policies);
    assert_eq!(m.outputs, outputs_before);
    // And it goes on from where it was.
    assert!(m.step(&ship.next(Vector3::zeros())).is_ok());
}

#[test]
fn a_long_gap_restarts_the_filter_and_a_repeated_instant_predicts_nothing() {
    let mut ship = Ship::new(26, 1.0);
    let mut m = monitor(
        json!({"aids": ["gnss"]}),
        PolicyConfig::Classic,
        ThresholdSpec::PFa(0.002),
    );
    for _ in 0..20 {
        m.step(&ship.next(Vector3::zeros())).unwrap();
    }
    let converged = m.filter().master().p;
    let mut e = ship.next(Vector3::zeros());
    e.gnss = None;
    e.dvl_vel_b = None;
    e.cns = None;
    let same = Epoch {
        t: e.t - 1.0,
        ..e.clone()
    };
    // The same instant again (dt = 0): no prediction, nothing to update.
    let t_last = m.last_t.unwrap();
    m.step(&Epoch { t: t_last, ..same }).unwrap();
    assert_eq!(m.filter().master().p, converged);
    e.t += MAX_GAP_S + 10.0;
    m.step(&e).unwrap();
    let p0 = m.config().initial_estimate().p;
    assert_eq!(m.filter().master().p, p0);
}

#[test]
fn outputs_serialise_in_wire_units() {
    let mut ship = Ship::new(27, 1.0);
    let mut m = monitor(
        all_aids(),
        PolicyConfig::counters_default(),
        ThresholdSpec::Threshold(20.0),
    );
    let r = m.step(&ship.next(Vector3::zeros())).unwrap();
    let v = serde_json::to_value(&r.outputs).unwrap();
    let lat = v["solution"]["lat"].as_f64().unwrap();
    assert!((lat - 30.0).abs() < 0.01, "degrees on the wire: {v}");
    assert_eq!(v["solution"]["vel"].as_array().unwrap().len(), 3);
    assert!(v["hpl"].as_f64().unwrap() > 0.0);
    assert_eq!(v["isolated"], json!([]));
    m.reset();
    assert_eq!(m.filter().master(), &m.config().initial_estimate());
    assert!(m.last_t.is_none());
}
