//! Tests of the PL solver ([`super::pl::solve`]) against two references written here:
//! halving the whole left-hand side on the same bracket (the solver without its term
//! skipping, which must give the same PL to the bit), and an independent root to 1e-9 m
//! (plain halving from a bracket found by doubling), over seeded random term sets and
//! seeded random skies.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::pl::{PlTerm, lhs, q_inv, solve};
use super::{AraimModel, AraimParams, AraimSat};
use crate::epoch::{Constellation, SatId};

/// The solver without term skipping: halving of the whole sum on [B15]'s bracket.
fn halving_of_the_whole_sum(terms: &[PlTerm], rhs: f64, tol: f64) -> f64 {
    if rhs <= 0.0 || terms.is_empty() {
        return f64::INFINITY;
    }
    let n = terms.len() as f64;
    let (mut lo, mut hi) = (0.0_f64, 0.0_f64);
    for t in terms {
        if t.coef > rhs {
            lo = lo.max(t.offset + q_inv(rhs / t.coef) * t.sigma);
        }
        let share = rhs / (n * t.coef);
        let k_hi = if share < 1.0 {
            q_inv(share).max(0.0)
        } else {
            0.0
        };
        hi = hi.max(t.offset + k_hi * t.sigma);
    }
    if lo >= hi {
        return hi;
    }
    while hi - lo > tol {
        let mid = 0.5 * (lo + hi);
        if lhs(terms, mid) > rhs {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// The root of `lhs(L) = rhs` to 1e-9 m, from a bracket of its own: the upper end
/// doubled from 1 m until the sum is below `rhs`, the lower end −1e4 m.
fn root(terms: &[PlTerm], rhs: f64) -> f64 {
    let mut hi = 1.0;
    while lhs(terms, hi) > rhs {
        hi *= 2.0;
    }
    let mut lo = -1e4;
    assert!(lhs(terms, lo) > rhs);
    while hi - lo > 1e-9 {
        let mid = 0.5 * (lo + hi);
        if lhs(terms, mid) > rhs {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// A fault-free term and 1 to 80 fault modes shaped like an epoch's: priors of single
/// satellites, constellations and their products, offsets `K_fa σ_ss + b` and σ at least
/// the fault-free one.
fn random_terms(rng: &mut StdRng) -> Vec<PlTerm> {
    let sigma0 = rng.random_range(0.3..4.0);
    let mut terms = vec![PlTerm {
        coef: 2.0,
        offset: rng.random_range(0.0..2.0),
        sigma: sigma0,
    }];
    let priors = [1e-5, 1e-4, 1e-8, 2e-5, 1e-9, 1e-10, 3e-4];
    for _ in 0..rng.random_range(1..80) {
        let sigma = sigma0 * rng.random_range(1.0..3.0);
        let sigma_ss = (sigma * sigma - sigma0 * sigma0).sqrt();
        terms.push(PlTerm {
            coef: priors[rng.random_range(0..priors.len())],
            offset: rng.random_range(4.5..6.0) * sigma_ss + rng.random_range(0.0..3.0),
            sigma,
        });
    }
    terms
}

#[test]
fn skipping_terms_gives_the_pl_of_halving_the_whole_sum_to_the_bit() {
    let mut rng = StdRng::seed_from_u64(28);
    for case in 0..3000 {
        let terms = random_terms(&mut rng);
        let rhs = [9.8e-8, 1e-9, 1e-5, 1e-7][case % 4] * rng.random_range(0.5..1.0);
        let tol = [5e-2, 1e-3, 1e-6][case % 3];
        let pl = solve(&terms, rhs, tol);
        let want = halving_of_the_whole_sum(&terms, rhs, tol);
        assert_eq!(pl.to_bits(), want.to_bits(), "case {case}: {pl} vs {want}");
    }
}

#[test]
fn the_pl_lies_within_tol_above_an_independent_root() {
    let mut rng = StdRng::seed_from_u64(2015);
    for case in 0..2000 {
        let terms = random_terms(&mut rng);
        let rhs = [9.8e-8, 1e-9, 1e-5][case % 3];
        let tol = 5e-2;
        let pl = solve(&terms, rhs, tol);
        let r = root(&terms, rhs);
        assert!(
            pl >= r - 1e-9 && pl < r + tol + 1e-9,
            "case {case}: PL {pl}, root {r}"
        );
        assert!(lhs(&terms, pl) <= rhs, "case {case}: the conservative side");
    }
}

/// `n` satellites at random azimuths and elevations (5° to 90°), alternating GPS and
/// Galileo, with random σ_URA, b_nom and local σ.
fn random_sky(rng: &mut StdRng, n: usize) -> Vec<AraimSat> {
    (0..n)
        .map(|i| {
            let az = rng.random_range(0.0..std::f64::consts::TAU);
            let el: f64 = rng.random_range(5f64.to_radians()..std::f64::consts::FRAC_PI_2);
            let (constellation, clock) = if i % 2 == 0 {
                (Constellation::Gps, 0)
            } else {
                (Constellation::Galileo, 1)
            };
            AraimSat {
                id: SatId {
                    constellation,
                    prn: (i + 1) as u8,
                },
                los_enu: [el.cos() * az.sin(), el.cos() * az.cos(), el.sin()],
                clock,
                sigma_ura: rng.random_range(0.5..1.5),
                sigma_ure: rng.random_range(0.3..1.0),
                b_nom: rng.random_range(0.0..1.0),
                el,
                sigma_local: Some(rng.random_range(0.3..3.0)),
            }
        })
        .collect()
}

#[test]
fn a_fitted_models_pls_lie_within_tol_above_an_independent_root() {
    let mut rng = StdRng::seed_from_u64(20_150_101);
    let params = AraimParams::default();
    let mut checked = 0;
    for _ in 0..60 {
        let n = rng.random_range(10..=32);
        let sats = random_sky(&mut rng, n);
        let Ok(model) = AraimModel::fit(&sats, &params) else {
            continue;
        };
        let scale = 1.0 - model.p_not_monitored() / (params.p_hmi_vert + params.p_hmi_hor);
        let axes = [
            (2, model.vpl(), params.p_hmi_vert),
            (0, model.hpl_en()[0], params.p_hmi_hor / 2.0),
            (1, model.hpl_en()[1], params.p_hmi_hor / 2.0),
        ];
        for (q, pl, budget) in axes {
            // The PL equation, built here from the model's accessors.
            let mut terms = vec![PlTerm {
                coef: 2.0,
                offset: model.bias(0)[q],
                sigma: model.sigma(0)[q],
            }];
            for (k, m) in model.modes().iter().enumerate() {
                terms.push(PlTerm {
                    coef: m.p_fault,
                    offset: model.threshold(k + 1)[q] + model.bias(k + 1)[q],
                    sigma: model.sigma(k + 1)[q],
                });
            }
            let r = root(&terms, budget * scale);
            assert!(
                pl >= r - 1e-9 && pl < r + params.tol_pl + 1e-9,
                "{n} satellites, axis {q}: PL {pl}, root {r}"
            );
            checked += 1;
        }
    }
    assert!(checked >= 150, "{checked} levels checked");
}
