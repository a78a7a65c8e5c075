//! Tests of [`super::raim`]: the χ² test's distribution, FDE on synthetic and real
//! (GSDC 2023) geometry, and the slope protection level at the detection boundary.

use nalgebra::Vector3;
use rand::SeedableRng;
use rand::rngs::StdRng;

use super::raim::{FdeMethod, FdeParams, SatStatus, chi2_test, fde, slope_protection_levels};
use super::testdata::{self, add_noise, errors, random_sky, synthetic};
use super::wls::{SigmaModel, WlsParams, solve};
use crate::epoch::{Constellation, SatObs};
use crate::geo::{Lla, ecef_to_lla, lla_to_ecef};

fn params() -> WlsParams {
    WlsParams {
        sigma_model: SigmaModel::Given { fallback_m: 1.0 },
        elevation_mask_rad: -std::f64::consts::FRAC_PI_2,
        ..WlsParams::default()
    }
}

fn truth() -> Lla {
    Lla {
        lat: 0.66,
        lon: -2.13,
        h: 25.0,
    }
}

fn clock(c: Constellation) -> f64 {
    if c == Constellation::Gps {
        3.0e4
    } else {
        3.0e4 - 12.0
    }
}

/// Two-constellation synthetic sky, 10 satellites, σ from 0.8 to 2.6 m.
fn synthetic_sky(seed: u64) -> Vec<SatObs> {
    synthetic(&truth(), &random_sky(seed, 10), clock, |i| {
        0.8 + 0.2 * i as f64
    })
}

/// The GSDC 2023 first epoch's satellites seen from its truth, simulated pseudoranges
/// with σ = 1.5 m (the phone's own σ reach 10+ m on GLONASS, where a 50 m step is only
/// a few σ and rightly goes unnoticed on weak satellites).
fn real_geometry() -> Vec<SatObs> {
    let e = &testdata::gsdc2023()[0];
    let rx = lla_to_ecef(&testdata::gsdc2023_truth());
    e.obs
        .iter()
        .map(|o| {
            let s = testdata::reference_rotate(&Vector3::from(o.pos), &rx);
            SatObs {
                pr: (s - rx).norm() + clock(o.id.constellation),
                clk: 0.0,
                iono: Some(0.0),
                tropo: Some(0.0),
                sigma: Some(1.5),
                ..o.clone()
            }
        })
        .collect()
}

#[test]
fn wssr_follows_chi2_of_dof_in_a_seeded_monte_carlo() {
    let clean = synthetic_sky(11);
    let mut rng = StdRng::seed_from_u64(2024);
    let draws = 2000;
    let mut sum = 0.0;
    let mut dof = 0;
    for _ in 0..draws {
        let mut obs = clean.clone();
        add_noise(&mut obs, &mut rng);
        let sol = solve(&obs, &params()).unwrap();
        sum += sol.wssr;
        dof = sol.dof;
    }
    let mean = sum / f64::from(draws);
    assert_eq!(dof, 10 - 5);
    // Standard error of the mean: sqrt(2·dof/draws) = 0.07, 1.4 % of dof.
    assert!(
        (mean / f64::from(dof) - 1.0).abs() < 0.05,
        "mean WSSR {mean}, dof {dof}"
    );
}

const METHODS: [FdeMethod; 3] = [
    FdeMethod::Rtklib,
    FdeMethod::Greedy,
    FdeMethod::SolutionSeparation,
];

fn step_is_detected_and_excluded(clean: &[SatObs], what: &str) {
    for method in METHODS {
        for faulty in [0, clean.len() / 2, clean.len() - 1] {
            let mut obs = clean.to_vec();
            add_noise(&mut obs, &mut StdRng::seed_from_u64(faulty as u64));
            obs[faulty].pr += 50.0;
            let p = FdeParams {
                method,
                max_exclusions: 2,
                ..FdeParams::default()
            };
            let out = fde(&obs, &params(), &p).unwrap();
            assert_eq!(out.detected, Some(true), "{what} {method:?} sat {faulty}");
            assert_eq!(
                out.excluded,
                vec![obs[faulty].id],
                "{what} {method:?} sat {faulty}"
            );
            assert_eq!(out.status[faulty].1, SatStatus::Excluded);
            assert!(out.test.unwrap().passed);
            let (h, _) = errors(
                &out.solution.ecef,
                &ecef_to_lla(&lla_to_ecef(&truth_of(what))),
            );
            assert!(h < 10.0, "{what} {method:?}: {h} m after exclusion");
        }
    }
}

fn truth_of(what: &str) -> Lla {
    if what == "real" {
        testdata::gsdc2023_truth()
    } else {
        truth()
    }
}

#[test]
fn a_50_m_step_on_one_satellite_is_detected_and_excluded_on_synthetic_geometry() {
    step_is_detected_and_excluded(&synthetic_sky(5), "synthetic");
}

#[test]
fn a_50_m_step_on_one_satellite_is_detected_and_excluded_on_gsdc_2023_geometry() {
    step_is_detected_and_excluded(&real_geometry(), "real");
}

#[test]
fn fault_free_draws_rarely_exclude() {
    let clean = real_geometry();
    let mut rng = StdRng::seed_from_u64(77);
    for method in METHODS {
        let mut exclusions = 0;
        for _ in 0..200 {
            let mut obs = clean.clone();
            add_noise(&mut obs, &mut rng);
            let p = FdeParams {
                method,
                ..FdeParams::default()
            };
            exclusions += fde(&obs, &params(), &p).unwrap().excluded.len();
        }
        // P_FA = 1e-3 per test: 0.2 expected in 200 draws.
        assert!(
            exclusions <= 3,
            "{method:?}: {exclusions} exclusions in 200 draws"
        );
    }
}

#[test]
fn the_chi2_test_reports_statistic_dof_and_threshold() {
    let mut obs = synthetic_sky(3);
    add_noise(&mut obs, &mut StdRng::seed_from_u64(3));
    let sol = solve(&obs, &params()).unwrap();
    let t = chi2_test(&sol, 1e-3).unwrap();
    assert_eq!((t.wssr, t.dof), (sol.wssr, 5));
    assert!((t.threshold - 20.515).abs() < 1e-3, "{}", t.threshold);
    assert!(chi2_test(&sol, 1.5).is_err());
}

#[test]
fn slope_hpl_bounds_the_horizontal_error_of_the_worst_bias_at_detection() {
    let (p_fa, p_md) = (1e-3, 1e-2);
    let clean = synthetic_sky(9);
    let sol = solve(&clean, &params()).unwrap();
    let pl = slope_protection_levels(&sol, p_fa, p_md).unwrap();
    assert!(pl.hpl_m.is_finite() && pl.vpl_m.is_finite());
    // Noise-free: the bias giving λ = λ_det on satellite i moves the fix by exactly
    // slope_H,i·sqrt(λ_det) ≤ HPL, with equality on the worst satellite.
    let mut worst = (0, 0.0);
    for (j, s) in sol.sats.iter().enumerate() {
        let b = pl.lambda_det.sqrt() * s.sigma_m / s.redundancy.sqrt();
        let mut obs = clean.clone();
        obs[s.index].pr += b;
        let faulty = solve(&obs, &params()).unwrap();
        assert!(
            (faulty.wssr / pl.lambda_det - 1.0).abs() < 1e-4,
            "{} vs {}",
            faulty.wssr,
            pl.lambda_det
        );
        let (h, _) = errors(&faulty.ecef, &truth());
        let slope = pl.slopes[j].horizontal * pl.lambda_det.sqrt();
        assert!((h - slope).abs() < 1e-4 * slope.max(1.0), "{h} vs {slope}");
        assert!(h <= pl.hpl_m * (1.0 + 1e-6));
        if h > worst.1 {
            worst = (s.index, h);
        }
    }
    assert!((worst.1 / pl.hpl_m - 1.0).abs() < 1e-4);
    // With noise: undetected and beyond the HPL at most about P_MD of the time.
    let b = {
        let s = sol.sats.iter().find(|s| s.index == worst.0).unwrap();
        pl.lambda_det.sqrt() * s.sigma_m / s.redundancy.sqrt()
    };
    let mut rng = StdRng::seed_from_u64(31);
    let (draws, mut misleading) = (2000, 0);
    for _ in 0..draws {
        let mut obs = clean.clone();
        add_noise(&mut obs, &mut rng);
        obs[worst.0].pr += b;
        let s = solve(&obs, &params()).unwrap();
        let (h, _) = errors(&s.ecef, &truth());
        if s.wssr <= pl.threshold && h > pl.hpl_m {
            misleading += 1;
        }
    }
    let bound = p_md + 3.0 * (p_md / f64::from(draws)).sqrt();
    assert!(
        f64::from(misleading) / f64::from(draws) <= bound,
        "{misleading} of {draws}"
    );
}

#[test]
fn a_satellite_alone_in_its_constellation_has_no_slope_its_clock_absorbs_its_bias() {
    let mut sky = random_sky(8, 7);
    for s in &mut sky {
        s.0 = Constellation::Gps;
    }
    sky.push((Constellation::Glonass, 2.0, 0.7));
    let obs = synthetic(&truth(), &sky, clock, |_| 1.0);
    let sol = solve(&obs, &params()).unwrap();
    let pl = slope_protection_levels(&sol, 1e-3, 1e-3).unwrap();
    let alone = &pl.slopes[7];
    assert_eq!((alone.horizontal, alone.vertical), (0.0, 0.0));
    assert!(
        pl.slopes[..7]
            .iter()
            .all(|s| s.horizontal.is_finite() && s.horizontal > 0.0)
    );
    // The levels are those of the GPS satellites, and a bias on the lone satellite
    // indeed leaves the position where it was.
    let gps_only = solve(&obs[..7], &params()).unwrap();
    let gps_pl = slope_protection_levels(&gps_only, 1e-3, 1e-3).unwrap();
    assert!(
        (pl.hpl_m - gps_pl.hpl_m).abs() < 1e-6 * gps_pl.hpl_m,
        "{} vs {}",
        pl.hpl_m,
        gps_pl.hpl_m
    );
    let mut biased = obs.clone();
    biased[7].pr += 500.0;
    let moved = solve(&biased, &params()).unwrap();
    assert!((moved.ecef - sol.ecef).norm() < 1e-6);
}
