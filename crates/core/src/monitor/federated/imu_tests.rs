//! Unit tests of the federated monitor with `input: imu`: config refusals, the alignment
//! sequence, the closed loop on a synthetic drive (the truth is the mechanization of exact
//! increments, the monitor gets them with gyro biases and noisy GNSS), the receiver's σ,
//! and a checkpoint taken mid-drive.

use super::*;
use crate::epoch::ImuBlock;
use crate::filter::ins::ATT;
use crate::strapdown::{Increments, Strapdown};
use nalgebra::Matrix3;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use serde_json::{Value, json};

/// 100 Hz.
const DT: f64 = 0.01;
/// Static seconds, then accelerating, then cruising.
const STATIC_S: f64 = 10.0;
const ACCEL_END_S: f64 = 20.0;
const END_S: f64 = 80.0;
const HEADING_DEG: f64 = 30.0;
/// The gyro biases the monitor's IMU has, rad/s (body).
const GYRO_BIAS: [f64; 3] = [0.0008, -0.0005, 0.0015];

fn config(extra: Value) -> Value {
    let mut c = json!({
        "aids": ["gnss"],
        "input": "imu",
        "gnss": {"pos_sigma_m": 0.5, "vel_sigma_mps": 0.05},
        "imu": {"gyro_bias_dph": 30.0, "accel_bias_ug": 5000.0,
                "arw_deg_rthr": 0.3, "vrw_mps_rthr": 0.1},
        "strapdown": {"align": {"static_s": 5}}
    });
    if let (Some(c), Some(extra)) = (c.as_object_mut(), extra.as_object()) {
        for (k, v) in extra {
            c.insert(k.clone(), v.clone());
        }
    }
    c
}

fn monitor(config: Value) -> FederatedMonitor {
    FederatedMonitor::new(
        FederatedConfig::from_json(&config).unwrap(),
        PolicyConfig::counters_default(),
        ThresholdSpec::PFa(1e-3),
    )
    .unwrap()
}

/// One step of the synthetic drive: the epoch the monitor gets and the truth after it.
struct DriveEpoch {
    epoch: Epoch,
    truth: Lla,
    truth_vel: Vector3<f64>,
}

/// Body rates (specific force, angular rate) of the drive at `t`: the Earth rate seen by
/// a body at heading 30°, level, plus a forward acceleration of 1 m/s² while accelerating.
fn true_rates(t: f64, c_bn: &Matrix3<f64>, lat: f64, h: f64) -> (Vector3<f64>, Vector3<f64>) {
    let a = if (STATIC_S..ACCEL_END_S).contains(&t) {
        1.0
    } else {
        0.0
    };
    let f_n =
        c_bn * Vector3::new(0.0, a, 0.0) + Vector3::new(0.0, 0.0, geo::normal_gravity(lat, h));
    let w_n = geo::earth_rate_enu(lat);
    (c_bn.transpose() * f_n, c_bn.transpose() * w_n)
}

/// The drive at 100 Hz with a 1 Hz GNSS fix (σ 0.5 m, 0.05 m/s, seeded), and the truth:
/// the mechanization of the exact increments (so the truth is consistent with them).
fn drive(seed: u64) -> Vec<DriveEpoch> {
    let start = Lla {
        lat: 40f64.to_radians(),
        lon: -105f64.to_radians(),
        h: 1600.0,
    };
    let c0 = geo::dcm_body_to_nav(0.0, 0.0, HEADING_DEG.to_radians());
    let mut truth = Strapdown::new(start, Vector3::zeros(), c0);
    let mut rng = StdRng::seed_from_u64(seed);
    let (pos_noise, vel_noise) = (
        Normal::new(0.0, 0.5).unwrap(),
        Normal::new(0.0, 0.05).unwrap(),
    );
    let mut out = Vec::new();
    let n = (END_S / DT).round() as usize;
    for k in 0..=n {
        let t = k as f64 * DT;
        let p = truth.lla();
        let (f, w) = true_rates(t, &truth.c_bn(), p.lat, p.h);
        if k > 0 {
            truth.step(&Increments {
                dtheta: (w * DT).into(),
                dv: (f * DT).into(),
                dt: DT,
            });
        }
        let (p, v) = (truth.lla(), truth.vel());
        let gnss = (k % 100 == 0).then(|| {
            let d = Vector3::from_fn(|_, _| pos_noise.sample(&mut rng));
            let fix = geo::apply_offset(&p, &d);
            GnssBlock {
                lat: fix.lat,
                lon: fix.lon,
                h: fix.h,
                vel: Some((v + Vector3::from_fn(|_, _| vel_noise.sample(&mut rng))).into()),
                pos_sigma: None,
                vel_sigma: None,
            }
        });
        let biased = w + Vector3::from(GYRO_BIAS);
        out.push(DriveEpoch {
            epoch: Epoch {
                t,
                gnss,
                imu: Some(ImuBlock {
                    accel: f.into(),
                    gyro: biased.into(),
                    dt: None,
                }),
                ..Epoch::default()
            },
            truth: p,
            truth_vel: v,
        });
    }
    out
}

fn alignment(r: &MonitorReport) -> Option<Alignment> {
    match &r.outputs {
        Outputs::Federated { alignment, .. } => *alignment,
        _ => None,
    }
}

fn solution(r: &MonitorReport) -> Option<FederatedSolution> {
    match &r.outputs {
        Outputs::Federated { solution, .. } => *solution,
        _ => None,
    }
}

#[test]
fn imu_configs_are_checked_naming_the_field() {
    let c = FederatedConfig::from_json(&config(json!({}))).unwrap();
    let s = c.strapdown.as_ref().unwrap();
    assert_eq!(s.section.align.static_s, 5.0);
    assert_eq!(s.c_sb, Matrix3::identity());
    // The alignment's attitude σ replaces init's arcseconds.
    let p0 = c.initial_estimate().p;
    assert!((p0[(ATT + 2, ATT + 2)].sqrt() - 5f64.to_radians()).abs() < 1e-15);
    // The axis swap of an IMU mounted (back, right, up): yaw 90°.
    let c = FederatedConfig::from_json(&config(json!({"strapdown": {"mounting_deg": [0, 0, 90]}})))
        .unwrap();
    let c_sb = c.strapdown.unwrap().c_sb;
    let back = Vector3::new(1.0, 0.0, 0.0);
    assert!(
        (c_sb * back - Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-15,
        "sensor x is backward"
    );
    for (cfg, field) in [
        (
            json!({"strapdown": {"max_gap_s": 0}}),
            "strapdown.max_gap_s",
        ),
        (
            json!({"strapdown": {"align": {"att_sigma_deg": [1, 1, 0]}}}),
            "strapdown.align.att_sigma_deg",
        ),
        (
            json!({"strapdown": {"gnss_lever_arm_m": [0, 500, 0]}}),
            "strapdown.gnss_lever_arm_m",
        ),
        (json!({"imu": {"bias_tau_s": -1}}), "imu.bias_tau_s"),
        (json!({"input": "ins"}), "strapdown"),
    ] {
        let err = FederatedConfig::from_json(&config(cfg)).unwrap_err();
        assert_eq!(err.field, field, "{err:?}");
    }
}

#[test]
fn the_drive_aligns_then_the_closed_loop_tracks_the_truth_and_finds_the_gyro_biases() {
    for seed in [1, 2, 3] {
        let mut m = monitor(config(json!({})));
        let mut states = Vec::new();
        let mut worst_after = 0.0f64;
        for e in drive(seed) {
            let r = m.step(&e.epoch).unwrap();
            let a = alignment(&r).unwrap();
            if states.last() != Some(&a) {
                states.push(a);
            }
            if a != Alignment::Aligned {
                assert!(r.tests.is_empty(), "no test runs while aligning");
                assert_eq!(r.integrity.unwrap().state, Availability::Converging);
                continue;
            }
            let s = solution(&r).unwrap();
            let got = Lla {
                lat: s.lat.to_radians(),
                lon: s.lon.to_radians(),
                h: s.h,
            };
            let err = geo::local_offset(&e.truth, &got);
            if e.epoch.t > ACCEL_END_S + 10.0 {
                worst_after = worst_after.max(err.xy().norm());
                let dv = Vector3::from(s.vel) - e.truth_vel;
                assert!(
                    dv.norm() < 0.2,
                    "seed {seed} t {}: velocity error {dv}",
                    e.epoch.t
                );
            }
        }
        assert_eq!(
            states,
            vec![Alignment::Levelling, Alignment::Heading, Alignment::Aligned],
            "seed {seed}"
        );
        assert!(
            worst_after < 1.0,
            "seed {seed}: horizontal error up to {worst_after} m"
        );
        let (gyro, _) = m.front.as_ref().unwrap().biases();
        for i in 0..3 {
            // The static mean finds them (to the Earth rate's horizontal part, 1e-5 rad/s);
            // the filter, trading heading error against the vertical gyro's bias within
            // their σ (30 °/h = 1.5e-4 rad/s), keeps them.
            assert!(
                (gyro[i] - GYRO_BIAS[i]).abs() < 1.5e-4,
                "seed {seed}: gyro bias {i} estimated {} rad/s, true {}",
                gyro[i],
                GYRO_BIAS[i]
            );
        }
    }
}

#[test]
fn a_given_heading_aligns_once_levelled_and_a_gap_restarts_alignment() {
    let mut m = monitor(config(
        json!({"strapdown": {"align": {"static_s": 5, "heading_deg": 30}}}),
    ));
    let epochs = drive(4);
    let mut aligned_at = None;
    for e in &epochs[..800] {
        let r = m.step(&e.epoch).unwrap();
        if aligned_at.is_none() && alignment(&r) == Some(Alignment::Aligned) {
            aligned_at = Some(e.epoch.t);
        }
    }
    // 5 s of static data after the first fix at t = 0 (the first sample only starts time).
    let t = aligned_at.unwrap();
    assert!((5.0..5.05).contains(&t), "aligned at {t} s");
    // A two-second hole in the IMU stream: back to levelling, no tests; the gyro bias
    // estimates (the static mean found them) are kept.
    let before = m.front.as_ref().unwrap().biases();
    assert!((before.0[2] - GYRO_BIAS[2]).abs() < 1.5e-4, "{before:?}");
    let mut late = epochs[1000].epoch.clone();
    late.t = epochs[799].epoch.t + 2.0;
    let r = m.step(&late).unwrap();
    assert_eq!(alignment(&r), Some(Alignment::Levelling));
    assert!(r.tests.is_empty());
    assert_eq!(m.front.as_ref().unwrap().biases(), before);
}

#[test]
fn a_fix_with_its_own_sigma_is_weighed_by_it() {
    // Same drive, the fixes claim σ 0.05 m while they carry 0.5 m: the GNSS test's mean
    // statistic is its dof (6) with the configured σ, and several times that with the
    // claimed one (the filter follows the fixes closer, so less than (0.5/0.05)²).
    let mut plain = monitor(config(json!({})));
    let mut tight = monitor(config(json!({})));
    let (mut sum_plain, mut sum_tight, mut n) = (0.0, 0.0, 0);
    for e in drive(5) {
        let mut claimed = e.epoch.clone();
        if let Some(g) = &mut claimed.gnss {
            g.pos_sigma = Some([0.05; 3]);
        }
        let a = plain.step(&e.epoch).unwrap();
        let b = tight.step(&claimed).unwrap();
        n += a.tests.iter().filter(|o| &*o.name == "gnss").count();
        sum_plain += a
            .tests
            .iter()
            .filter(|o| &*o.name == "gnss")
            .map(|o| o.statistic.value)
            .sum::<f64>();
        sum_tight += b
            .tests
            .iter()
            .filter(|o| &*o.name == "gnss")
            .map(|o| o.statistic.value)
            .sum::<f64>();
    }
    let (mean_plain, mean_tight) = (sum_plain / n as f64, sum_tight / n as f64);
    assert!(
        (4.5..7.5).contains(&mean_plain),
        "mean λ {mean_plain} over {n} tests"
    );
    assert!(
        mean_tight > 4.0 * mean_plain,
        "{mean_tight} vs {mean_plain}"
    );
}

#[test]
fn a_checkpoint_mid_drive_resumes_bit_for_bit() {
    let epochs = drive(6);
    let mut a = monitor(config(json!({})));
    for e in &epochs[..2500] {
        a.step(&e.epoch).unwrap();
    }
    let bytes = a.checkpoint().unwrap();
    let mut b = monitor(config(json!({})));
    b.restore(&bytes).unwrap();
    for e in &epochs[2500..3500] {
        let (ra, rb) = (a.step(&e.epoch).unwrap(), b.step(&e.epoch).unwrap());
        assert_eq!(ra, rb, "t = {}", e.epoch.t);
    }
    // An ins monitor refuses an imu checkpoint.
    let mut ins = FederatedMonitor::new(
        FederatedConfig::from_json(&json!({"aids": ["gnss"]})).unwrap(),
        PolicyConfig::counters_default(),
        ThresholdSpec::PFa(1e-3),
    )
    .unwrap();
    assert!(matches!(
        ins.restore(&bytes),
        Err(CheckpointError::Mismatch(_))
    ));
}
