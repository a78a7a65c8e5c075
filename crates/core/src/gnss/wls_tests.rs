//! Tests of [`super::wls`] against the independent reference of [`super::testdata`], the
//! GSDC truths and Google's WLS, and closed-form DOPs.

use nalgebra::{DMatrix, Vector3};
use rand::SeedableRng;
use rand::rngs::StdRng;

use super::testdata::{self, errors, random_sky, reference_wls, synthetic};
use super::wls::{SigmaModel, WlsError, WlsParams, dops, solve};
use crate::epoch::Constellation;
use crate::geo::{Lla, lla_to_ecef};

/// The phones' own σ, no mask (the reference has none).
fn given_no_mask() -> WlsParams {
    WlsParams {
        sigma_model: SigmaModel::Given { fallback_m: 10.0 },
        elevation_mask_rad: -std::f64::consts::FRAC_PI_2,
        ..WlsParams::default()
    }
}

fn assert_matches_reference(obs: &[crate::epoch::SatObs], what: &str) {
    let sol = solve(obs, &given_no_mask()).unwrap();
    let (pos, clocks) = reference_wls(obs, 1.0);
    let d = (sol.ecef - pos).norm();
    assert!(d < 1e-6, "{what}: WLS differs from the reference by {d} m");
    for (c, clk) in clocks {
        let ours = sol.clock(c).unwrap();
        assert!(
            (ours - clk).abs() < 1e-6,
            "{what}: clock {c:?} {ours} vs {clk}"
        );
    }
}

#[test]
fn wls_matches_the_independent_reference_on_gsdc_2023_epochs() {
    let epochs = testdata::gsdc2023();
    assert_eq!(epochs.len(), 5);
    for e in &epochs {
        assert_eq!(e.obs.len(), 21);
        assert_matches_reference(&e.obs, &format!("GSDC 2023 {}", e.millis));
    }
}

#[test]
fn wls_matches_the_independent_reference_on_gsdc_2021_epochs() {
    let epochs = testdata::gsdc2021();
    assert_eq!(epochs.len(), 6);
    for e in &epochs {
        assert!(e.obs.len() >= 12, "{} satellites", e.obs.len());
        assert_matches_reference(&e.obs, &format!("GSDC 2021 {}", e.millis));
    }
}

#[test]
fn wls_matches_the_independent_reference_on_seeded_two_constellation_geometries() {
    let truth = Lla {
        lat: 0.9,
        lon: 2.1,
        h: 300.0,
    };
    for seed in 0..10 {
        let dirs = random_sky(seed, 9);
        let clock = |c| {
            if c == Constellation::Gps {
                1.2e5
            } else {
                1.2e5 + 37.0
            }
        };
        let mut obs = synthetic(&truth, &dirs, clock, |i| 1.0 + 0.2 * i as f64);
        testdata::add_noise(&mut obs, &mut StdRng::seed_from_u64(100 + seed));
        assert_matches_reference(&obs, &format!("seed {seed}"));
        let sol = solve(&obs, &given_no_mask()).unwrap();
        assert_eq!(sol.dof, 9 - 5);
        let gal_minus_gps =
            sol.clock(Constellation::Galileo).unwrap() - sol.clock(Constellation::Gps).unwrap();
        assert!((gal_minus_gps - 37.0).abs() < 10.0, "{gal_minus_gps}");
    }
}

#[test]
fn gsdc_2023_fix_is_within_a_few_metres_of_truth_and_of_googles_wls() {
    let truth = testdata::gsdc2023_truth();
    for e in testdata::gsdc2023() {
        let sol = solve(&e.obs, &given_no_mask()).unwrap();
        let (h, v) = errors(&sol.ecef, &truth);
        let google = e.google_wls.unwrap();
        let (gh, _) = errors(&google, &truth);
        let to_google = (sol.ecef - google).norm();
        let (to_google_h, _) = errors(&google, &sol.lla);
        println!(
            "GSDC 2023 {}: horizontal {h:.2} m, vertical {v:.2} m (Google's WLS horizontal \
             {gh:.2} m), ours − Google's {to_google:.2} m ({to_google_h:.2} m horizontally), {} iterations from the centre",
            e.millis, sol.iterations
        );
        assert!(h < 5.0, "horizontal error {h} m");
        assert!(v < 15.0, "vertical error {v} m");
        // Google's baseline fix is not ours: it also uses the L5/E5a signals and its own
        // weights; the two differ mostly in height.
        assert!(
            to_google < 15.0 && to_google_h < 6.0,
            "{to_google} m from Google's WLS"
        );
    }
}

#[test]
fn gsdc_2021_fixes_are_within_metres_of_the_corrected_truth() {
    for e in testdata::gsdc2021() {
        let truth = testdata::gsdc2021_truth(e.millis);
        let sol = solve(&e.obs, &given_no_mask()).unwrap();
        let (h, v) = errors(&sol.ecef, &truth);
        println!(
            "GSDC 2021 {}: horizontal {h:.2} m, vertical {v:.2} m",
            e.millis
        );
        assert!(h < 10.0 && v < 20.0, "horizontal {h} m, vertical {v} m");
    }
}

#[test]
fn the_elevation_mask_drops_low_satellites_after_the_first_fix() {
    let e = &testdata::gsdc2023()[0];
    let unmasked = solve(&e.obs, &given_no_mask()).unwrap();
    let mask = 20f64.to_radians();
    let low: Vec<_> = unmasked
        .sats
        .iter()
        .filter(|s| s.az_el.el < mask)
        .map(|s| s.id)
        .collect();
    assert!(!low.is_empty(), "the test needs satellites below 20°");
    let masked = solve(
        &e.obs,
        &WlsParams {
            elevation_mask_rad: mask,
            ..given_no_mask()
        },
    )
    .unwrap();
    assert_eq!(masked.masked, low);
    assert_eq!(masked.sats.len() + low.len(), e.obs.len());
}

#[test]
fn dops_match_the_closed_form_of_four_zenith_and_three_equally_spaced_satellites() {
    // Rows [−e_enu, 1]: four at zenith, three at az 0°, 120°, 240°, elevation θ. Then
    // GᵀG = diag-blocks: EE = NN = 1.5 cos²θ, and the (up, clock) block
    // [[4 + 3 sin²θ, −(4 + 3 sin θ)], [−(4 + 3 sin θ), 7]] with determinant 12 (1 − sin θ)².
    let theta = 30f64.to_radians();
    let (s, c) = theta.sin_cos();
    let mut dirs = vec![(0.0, std::f64::consts::FRAC_PI_2); 4];
    dirs.extend([0.0_f64, 120.0, 240.0].map(|a| (a.to_radians(), theta)));
    let g = DMatrix::from_fn(7, 4, |i, j| {
        let (az, el) = dirs[i];
        let e = [az.sin() * el.cos(), az.cos() * el.cos(), el.sin()];
        if j < 3 { -e[j] } else { 1.0 }
    });
    let det = 12.0 * (1.0 - s).powi(2);
    let (q_en, q_u, q_t) = (1.0 / (1.5 * c * c), 7.0 / det, (4.0 + 3.0 * s * s) / det);
    let expected = [
        (2.0 * q_en + q_u + q_t).sqrt(),
        (2.0 * q_en + q_u).sqrt(),
        (2.0 * q_en).sqrt(),
        q_u.sqrt(),
    ];
    let d = dops(&g);
    let got = [d.gdop, d.pdop, d.hdop, d.vdop];
    for (g, e) in got.iter().zip(expected) {
        assert!((g - e).abs() < 1e-9, "{got:?} vs {expected:?}");
    }
    // The same through a full fix on satellites placed in those directions.
    let truth = Lla {
        lat: 0.6,
        lon: -2.0,
        h: 10.0,
    };
    let sky: Vec<_> = dirs
        .iter()
        .map(|&(az, el)| (Constellation::Gps, az, el))
        .collect();
    let obs = synthetic(&truth, &sky, |_| 0.0, |_| 1.0);
    let sol = solve(&obs, &given_no_mask()).unwrap();
    assert!((sol.dops.pdop - expected[1]).abs() < 1e-6, "{:?}", sol.dops);
    assert!((sol.dops.hdop - expected[2]).abs() < 1e-6, "{:?}", sol.dops);
}

#[test]
fn a_fix_from_the_earths_centre_converges_and_equals_one_from_near_the_truth() {
    let e = &testdata::gsdc2023()[2];
    let from_centre = solve(&e.obs, &given_no_mask()).unwrap();
    let near = WlsParams {
        initial_ecef: Some(
            lla_to_ecef(&testdata::gsdc2023_truth()) + Vector3::new(50.0, -30.0, 20.0),
        ),
        ..given_no_mask()
    };
    let from_near = solve(&e.obs, &near).unwrap();
    assert!(from_centre.iterations <= 10 && from_near.iterations < from_centre.iterations);
    assert!((from_centre.ecef - from_near.ecef).norm() < 1e-5);
}

#[test]
fn residuals_w_tests_and_wssr_are_consistent() {
    let e = &testdata::gsdc2023()[0];
    let sol = solve(&e.obs, &given_no_mask()).unwrap();
    let wssr: f64 = sol
        .sats
        .iter()
        .map(|s| (s.residual_m / s.sigma_m).powi(2))
        .sum();
    assert!((wssr - sol.wssr).abs() < 1e-9 * wssr.max(1.0));
    // Σ redundancy numbers = dof (the trace of the residual projector).
    let r: f64 = sol.sats.iter().map(|s| s.redundancy).sum();
    assert!((r - f64::from(sol.dof)).abs() < 1e-6, "{r} vs {}", sol.dof);
    // Weighted residuals are orthogonal to the columns of G (normal equations).
    for col in 0..sol.geometry_enu.ncols() {
        let dot: f64 = sol
            .sats
            .iter()
            .enumerate()
            .map(|(j, s)| sol.geometry_enu[(j, col)] * s.residual_m / s.sigma_m.powi(2))
            .sum();
        assert!(dot.abs() < 1e-3, "column {col}: {dot}");
    }
}

#[test]
fn a_single_satellite_constellation_gets_a_clock_and_no_redundancy() {
    let truth = Lla {
        lat: 0.7,
        lon: 0.2,
        h: 0.0,
    };
    let mut sky = random_sky(7, 7);
    for s in &mut sky {
        s.0 = Constellation::Gps;
    }
    sky.push((Constellation::Glonass, 1.0, 0.8));
    let obs = synthetic(&truth, &sky, |_| 10.0, |_| 1.0);
    let sol = solve(&obs, &given_no_mask()).unwrap();
    assert_eq!(sol.clocks.len(), 2);
    assert_eq!(sol.dof, 8 - 5);
    let glo = sol
        .sats
        .iter()
        .find(|s| s.id.constellation == Constellation::Glonass)
        .unwrap();
    assert!(glo.redundancy < 1e-9 && glo.normalised == 0.0);
}

#[test]
fn too_few_satellites_and_degenerate_geometry_are_errors() {
    let truth = Lla {
        lat: 0.7,
        lon: 0.2,
        h: 0.0,
    };
    let sky = random_sky(3, 4);
    let obs = synthetic(&truth, &sky, |_| 0.0, |_| 1.0);
    assert!(matches!(
        solve(&obs, &given_no_mask()),
        Err(WlsError::TooFewSatellites { have: 4, need: 5 })
    ));
    let same: Vec<_> = (0..6).map(|_| (Constellation::Gps, 0.3, 0.9)).collect();
    let obs = synthetic(&truth, &same, |_| 0.0, |_| 1.0);
    let err = solve(&obs, &given_no_mask()).unwrap_err();
    assert!(
        matches!(err, WlsError::SingularGeometry | WlsError::NonFinite),
        "{err:?}"
    );
    let mut bad = synthetic(&truth, &random_sky(4, 6), |_| 0.0, |_| 1.0);
    bad[2].pr = f64::NAN;
    assert!(solve(&bad, &given_no_mask()).is_err());
}
