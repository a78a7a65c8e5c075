//! Tests of ARAIM: the covariance, a closed-form separation, the PL equation, monotonicity,
//! a seeded Monte Carlo of the false-alert rate, and exclusion of a 50 m bias, on a real
//! GSDC 2023 geometry (Pixel 7 Pro, GPS + Galileo) and on symmetric synthetic geometries.

use nalgebra::DMatrix;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};
use statrs::distribution::{ContinuousCDF, Normal};

use super::*;
use crate::geo::frames::ecef_to_enu_rotation;
use crate::geo::wgs84::{Lla, lla_to_ecef};

const GSDC: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../tests/data/gnss/gsdc/gsdc2023_pixel7pro_device_gnss.csv"
);

/// ISM values for the tests: σ_URA 1 m, σ_URE 2/3 m, b_nom 0.75 m.
fn sat(id: SatId, los: [f64; 3], clock: usize) -> AraimSat {
    let el = los[2].clamp(-1.0, 1.0).asin();
    AraimSat {
        id,
        los_enu: los,
        clock,
        sigma_ura: 1.0,
        sigma_ure: 2.0 / 3.0,
        b_nom: 0.75,
        el,
        sigma_local: None,
    }
}

/// The first epoch of the GSDC 2023 Pixel 7 Pro file, satellites above 5°, one row per
/// satellite, only the constellations in `keep` (clock column in `keep` order).
fn gsdc_geometry(keep: &[Constellation]) -> Vec<AraimSat> {
    let text = std::fs::read_to_string(GSDC).expect("GSDC file");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (ct, sv, sig, t) = (
        col("ConstellationType"),
        col("Svid"),
        col("SignalType"),
        col("utcTimeMillis"),
    );
    let (px, py, pz) = (
        col("SvPositionXEcefMeters"),
        col("SvPositionYEcefMeters"),
        col("SvPositionZEcefMeters"),
    );
    let truth = Lla {
        lat: 37.692231_f64.to_radians(),
        lon: (-122.0884199_f64).to_radians(),
        h: 20.9736,
    };
    let r0 = lla_to_ecef(&truth);
    let rot = ecef_to_enu_rotation(truth.lat, truth.lon);
    let mut out: Vec<AraimSat> = Vec::new();
    let mut first_t = None;
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        if f.len() < header.len() || f[sig].is_empty() || !line.starts_with("Raw") {
            continue;
        }
        if *first_t.get_or_insert(f[t]) != f[t] {
            break;
        }
        let c = match f[ct] {
            "1" => Constellation::Gps,
            "3" => Constellation::Glonass,
            "6" => Constellation::Galileo,
            _ => continue,
        };
        let Some(clock) = keep.iter().position(|&k| k == c) else {
            continue;
        };
        let id = SatId {
            constellation: c,
            prn: f[sv].parse().unwrap(),
        };
        if out.iter().any(|s| s.id == id) {
            continue;
        }
        let p = nalgebra::Vector3::new(
            f[px].parse().unwrap(),
            f[py].parse().unwrap(),
            f[pz].parse().unwrap(),
        );
        let u = rot * (p - r0).normalize();
        if u[2] < 5f64.to_radians().sin() {
            continue;
        }
        out.push(sat(id, [u[0], u[1], u[2]], clock));
    }
    out
}

fn gps(prn: u8) -> SatId {
    SatId {
        constellation: Constellation::Gps,
        prn,
    }
}

/// A zenith satellite and two rings (n1 at elevation el1, n2 at el2, evenly spaced in
/// azimuth), one constellation.
fn symmetric(n1: usize, el1: f64, n2: usize, el2: f64) -> Vec<AraimSat> {
    let mut v = vec![sat(gps(1), [0.0, 0.0, 1.0], 0)];
    for (ring, (n, el)) in [(n1, el1), (n2, el2)].into_iter().enumerate() {
        for j in 0..n {
            let az = 2.0 * std::f64::consts::PI * (j as f64 + 0.5 * ring as f64) / n as f64;
            let los = [el.cos() * az.sin(), el.cos() * az.cos(), el.sin()];
            v.push(sat(gps((2 + v.len()) as u8), los, 0));
        }
    }
    v
}

fn var_int(s: &AraimSat) -> f64 {
    s.sigma_ura.powi(2) + sigma_tropo(s.el).powi(2) + sigma_user_airborne(s.el, true).powi(2)
}

fn var_acc(s: &AraimSat) -> f64 {
    s.sigma_ure.powi(2) + sigma_tropo(s.el).powi(2) + sigma_user_airborne(s.el, true).powi(2)
}

#[test]
fn all_in_view_sigma_equals_the_wls_covariance_diagonal() {
    let sats = gsdc_geometry(&[Constellation::Gps]);
    assert!(sats.len() >= 7, "{} GPS satellites", sats.len());
    let model = AraimModel::fit(&sats, &AraimParams::default()).unwrap();
    // (Gᵀ W G)⁻¹ built here from scratch.
    let g = DMatrix::from_fn(
        sats.len(),
        4,
        |r, c| if c < 3 { -sats[r].los_enu[c] } else { 1.0 },
    );
    let w = DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
        sats.len(),
        sats.iter().map(|s| 1.0 / var_int(s)),
    ));
    let p = (g.transpose() * &w * &g).try_inverse().unwrap();
    for q in 0..3 {
        approx::assert_relative_eq!(model.sigma(0)[q], p[(q, q)].sqrt(), max_relative = 1e-12);
    }
    // One constellation: no constellation mode; GPS's P_const is unmonitorable.
    assert!(
        model
            .modes()
            .iter()
            .all(|m| m.excluded_mask.count_ones() < sats.len() as u32 - 3)
    );
    assert!(model.p_not_monitored() >= 1e-8);
}

#[test]
fn separation_of_a_biased_zenith_satellite_matches_its_closed_form() {
    let (n1, el1, n2, el2) = (6, 15f64.to_radians(), 5, 50f64.to_radians());
    let mut sats = symmetric(n1, el1, n2, el2);
    // Equal σ everywhere (σ_local 0), so the gain has a closed form.
    for s in &mut sats {
        s.sigma_local = Some(0.0);
    }
    let model = AraimModel::fit(&sats, &AraimParams::default()).unwrap();
    let k = model
        .modes()
        .iter()
        .position(|m| m.excluded_mask == 1)
        .expect("zenith mode");
    let b = 10.0;
    let mut y = vec![0.0; sats.len()];
    y[0] = b;
    let t = model.test(&y).unwrap();
    // With equal weights GᵀG has, in (up, clock), a = 1 + n1 s1² + n2 s2², c = −(1 + n1 s1
    // + n2 s2), d = 1 + n1 + n2, and east/north decouple by symmetry. The zenith row is
    // (u, clk) = (−1, 1), so S_0(up, zenith) = (−d − c)/(ad − c²); the subset without it
    // sees no bias, so the separation is |S_0(up, zenith)| b and 0 in east and north.
    let (s1, s2) = (el1.sin(), el2.sin());
    let (nf1, nf2) = (n1 as f64, n2 as f64);
    let a = 1.0 + nf1 * s1 * s1 + nf2 * s2 * s2;
    let c = -(1.0 + nf1 * s1 + nf2 * s2);
    let d = 1.0 + nf1 + nf2;
    let s_up = (-d - c) / (a * d - c * c);
    approx::assert_relative_eq!(t.separations[k][2], s_up.abs() * b, max_relative = 1e-10);
    assert!(t.separations[k][0].abs() < 1e-10 && t.separations[k][1].abs() < 1e-10);
    assert!(
        t.x0_enu[2] < 0.0,
        "a long zenith range pulls the solution down"
    );
}

#[test]
fn sigma_ss_squared_is_the_variance_difference_when_c_acc_equals_c_int() {
    let mut sats = gsdc_geometry(&[Constellation::Gps, Constellation::Galileo]);
    for s in &mut sats {
        s.sigma_ure = s.sigma_ura;
    }
    let model = AraimModel::fit(&sats, &AraimParams::default()).unwrap();
    for k in 1..=model.modes().len() {
        for q in 0..3 {
            let want = (model.sigma(k)[q].powi(2) - model.sigma(0)[q].powi(2)).sqrt();
            approx::assert_relative_eq!(model.sigma_ss(k)[q], want, max_relative = 1e-7);
        }
    }
}

#[test]
fn constellation_modes_drop_their_clock_and_stay_solvable() {
    let sats = gsdc_geometry(&[Constellation::Gps, Constellation::Galileo]);
    let n_gal = sats
        .iter()
        .filter(|s| s.id.constellation == Constellation::Galileo)
        .count();
    let model = AraimModel::fit(&sats, &AraimParams::default()).unwrap();
    let k = (0..model.modes().len())
        .find(|&k| {
            model.excluded(k).len() == n_gal
                && model
                    .excluded(k)
                    .iter()
                    .all(|id| id.constellation == Constellation::Galileo)
        })
        .expect("a Galileo constellation mode");
    // The GPS-only solution, computed here with a single clock.
    let gps_sats: Vec<&AraimSat> = sats
        .iter()
        .filter(|s| s.id.constellation == Constellation::Gps)
        .collect();
    let g = DMatrix::from_fn(gps_sats.len(), 4, |r, c| {
        if c < 3 { -gps_sats[r].los_enu[c] } else { 1.0 }
    });
    let w = DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
        gps_sats.len(),
        gps_sats.iter().map(|s| 1.0 / var_int(s)),
    ));
    let p = (g.transpose() * &w * &g).try_inverse().unwrap();
    approx::assert_relative_eq!(
        model.sigma(k + 1)[2],
        p[(2, 2)].sqrt(),
        max_relative = 1e-10
    );
    assert!(model.vpl().is_finite() && model.hpl().is_finite());
}

#[test]
fn the_pl_equation_holds_at_the_returned_pl() {
    let sats = gsdc_geometry(&[Constellation::Gps, Constellation::Galileo]);
    let params = AraimParams {
        tol_pl: 1e-7,
        ..AraimParams::default()
    };
    let model = AraimModel::fit(&sats, &params).unwrap();
    let normal = Normal::standard();
    // Left-hand side of the ADD PL equation, computed here with statrs' survival function.
    let lhs = |q: usize, l: f64| {
        let mut s = 2.0 * normal.sf((l - model.bias(0)[q]) / model.sigma(0)[q]);
        for (k, m) in model.modes().iter().enumerate() {
            s += m.p_fault
                * normal
                    .sf((l - model.threshold(k + 1)[q] - model.bias(k + 1)[q])
                        / model.sigma(k + 1)[q]);
        }
        s
    };
    let scale = 1.0 - model.p_not_monitored() / (params.p_hmi_vert + params.p_hmi_hor);
    let cases = [
        (2, model.vpl(), params.p_hmi_vert),
        (0, model.hpl_en()[0], params.p_hmi_hor / 2.0),
        (1, model.hpl_en()[1], params.p_hmi_hor / 2.0),
    ];
    for (q, pl, budget) in cases {
        let rhs = budget * scale;
        approx::assert_relative_eq!(lhs(q, pl), rhs, max_relative = 1e-5);
        assert!(
            lhs(q, pl) <= rhs * (1.0 + 1e-9),
            "the returned end is the conservative one"
        );
    }
    approx::assert_relative_eq!(model.hpl(), model.hpl_en()[0].hypot(model.hpl_en()[1]));
}

#[test]
fn pls_grow_with_sigma_ura_and_with_nominal_bias() {
    let base = gsdc_geometry(&[Constellation::Gps, Constellation::Galileo]);
    let p = AraimParams::default();
    let m0 = AraimModel::fit(&base, &p).unwrap();
    let scaled = |f: &dyn Fn(&mut AraimSat)| {
        let mut s = base.clone();
        s.iter_mut().for_each(f);
        AraimModel::fit(&s, &p).unwrap()
    };
    let ura = scaled(&|s| s.sigma_ura *= 1.5);
    let bnom = scaled(&|s| s.b_nom += 1.0);
    for m in [&ura, &bnom] {
        assert!(m.vpl() > m0.vpl() + 0.1, "{} vs {}", m.vpl(), m0.vpl());
        assert!(m.hpl() > m0.hpl() + 0.1, "{} vs {}", m.hpl(), m0.hpl());
    }
}

#[test]
fn adding_a_satellite_does_not_raise_the_vpl() {
    let all = gsdc_geometry(&[Constellation::Gps, Constellation::Galileo]);
    let p = AraimParams::default();
    let vpl_all = AraimModel::fit(&all, &p).unwrap().vpl();
    // Drop each GPS satellite in turn (GPS keeps ≥ 2 so the clock stays).
    for i in (0..all.len()).filter(|&i| all[i].id.constellation == Constellation::Gps) {
        let mut less = all.clone();
        less.remove(i);
        let vpl_less = AraimModel::fit(&less, &p).unwrap().vpl();
        assert!(
            vpl_all <= vpl_less + p.tol_pl,
            "{}: {vpl_all} > {vpl_less}",
            all[i].id
        );
    }
}

#[test]
fn fault_free_false_alert_rate_is_within_the_allocation() {
    let sats = gsdc_geometry(&[Constellation::Gps, Constellation::Galileo]);
    let p = AraimParams {
        p_fa_vert: 1e-2,
        p_fa_hor: 1e-2,
        ..AraimParams::default()
    };
    let model = AraimModel::fit(&sats, &p).unwrap();
    let sd: Vec<f64> = sats.iter().map(|s| var_acc(s).sqrt()).collect();
    let mut rng = StdRng::seed_from_u64(20150101);
    let draws = 40_000;
    let mut alerts = 0;
    let mut y = vec![0.0; sats.len()];
    for _ in 0..draws {
        for (v, s) in y.iter_mut().zip(&sd) {
            let z: f64 = StandardNormal.sample(&mut rng);
            *v = s * z;
        }
        if !model.test(&y).unwrap().passed() {
            alerts += 1;
        }
    }
    let rate = alerts as f64 / draws as f64;
    eprintln!(
        "ARAIM SS false-alert rate {rate} ({alerts}/{draws}), allocated {}",
        p.p_fa_vert + p.p_fa_hor
    );
    assert!(rate <= p.p_fa_vert + p.p_fa_hor, "{rate}");
    assert!(alerts > 0, "the test must be able to fire at this p_fa");
}

#[test]
fn a_50_m_bias_is_detected_and_its_satellite_excluded() {
    let sats = gsdc_geometry(&[Constellation::Gps, Constellation::Galileo]);
    let p = AraimParams::default();
    let mut rng = StdRng::seed_from_u64(7);
    for faulty in [0, sats.len() - 1] {
        let mut y: Vec<f64> = sats
            .iter()
            .map(|s| {
                let z: f64 = StandardNormal.sample(&mut rng);
                var_acc(s).sqrt() * z
            })
            .collect();
        y[faulty] += 50.0;
        let out = solution_separation_fde(&sats, &y, &p).unwrap();
        assert!(
            !out.detection.passed(),
            "50 m on {} not detected",
            sats[faulty].id
        );
        assert_eq!(out.excluded, vec![sats[faulty].id]);
        assert!(!out.unresolved);
        assert_eq!(out.model.ids().len(), sats.len() - 1);
        // And without the bias, nothing is detected.
        y[faulty] -= 50.0;
        let clean = solution_separation_fde(&sats, &y, &p).unwrap();
        assert!(clean.detection.passed() && clean.excluded.is_empty());
    }
}

#[test]
fn params_check_refuses_a_budget_that_does_not_add_up() {
    let p = AraimParams {
        p_hmi_hor: 1e-8,
        ..AraimParams::default()
    };
    assert!(matches!(
        p.check(),
        Err(AraimError::Param { name: "p_hmi", .. })
    ));
    assert!(AraimParams::default().check().is_ok());
}

/// Rough timing of one epoch (fit with PLs + test) on 30 satellites, 2 constellations:
/// `cargo test -p navguard-core --release araim_timing -- --ignored --nocapture`.
#[test]
#[ignore]
fn araim_timing() {
    // GSDC GPS + Galileo geometry, padded to 30 with mirrored copies of the satellites.
    let mut sats = gsdc_geometry(&[Constellation::Gps, Constellation::Galileo]);
    let base = sats.clone();
    for s in base.iter().cycle().take(30usize.saturating_sub(base.len())) {
        let mut t = *s;
        t.los_enu = [-s.los_enu[0], s.los_enu[1], s.los_enu[2]];
        t.id.prn += 40;
        sats.push(t);
    }
    let y = vec![0.1; sats.len()];
    for (label, p) in [
        ("default (GPS P_const 1e-8)", AraimParams::default()),
        (
            "P_const 1e-4 both",
            AraimParams {
                p_const: [1e-4; 7],
                ..AraimParams::default()
            },
        ),
    ] {
        let reps = 2000;
        let start = std::time::Instant::now();
        let mut acc = 0.0;
        for _ in 0..reps {
            let m = AraimModel::fit(&sats, &p).unwrap();
            acc += m.vpl() + m.test(&y).unwrap().max_ratio;
        }
        let m = AraimModel::fit(&sats, &p).unwrap();
        eprintln!(
            "{label}: {} sats, {} modes (order {}), {:.1} µs/epoch, VPL {:.2} HPL {:.2} σ_acc {:.2} EMT {:.2} p_nm {:.2e} ({acc:.0})",
            sats.len(),
            m.modes().len(),
            m.max_fault_order(),
            start.elapsed().as_secs_f64() * 1e6 / reps as f64,
            m.vpl(),
            m.hpl(),
            m.sigma_acc(),
            m.emt(),
            m.p_not_monitored()
        );
    }
}

#[test]
fn the_rank_one_downdate_equals_refactorising_each_single_satellite_subset() {
    let sats = gsdc_geometry(&[Constellation::Gps, Constellation::Galileo]);
    let nominal = subsets::Nominal::new(&sats).unwrap();
    let n0 = nominal.normal();
    let inverse = n0.cholesky().unwrap().inverse();
    let mut compared = 0;
    for i in 0..sats.len() {
        let mask = 1u64 << i;
        if nominal.clocks_of(mask) != nominal.clocks_of(0) {
            continue;
        }
        let (a, sa) = nominal
            .downdate(&inverse, i)
            .expect("a redundant satellite");
        let (b, sb) = nominal.subset(&n0, mask).unwrap();
        for (x, y) in a.iter().zip(b.iter()) {
            assert!((x - y).abs() <= 1e-9 * y.abs().max(1e-3), "{x} vs {y}");
        }
        for q in 0..3 {
            assert!((sa[q] - sb[q]).abs() <= 1e-9 * sb[q]);
        }
        compared += 1;
    }
    assert!(compared >= 10, "{compared} subsets compared");
}
