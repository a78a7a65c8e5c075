//! The ARAIM protection-level equation and its half-interval solver (Blanch et al. 2015,
//! Appendix "Computation of the protection levels"; ADD "Protection levels"): for one
//! axis q, the PL is the L that satisfies
//!
//! `2 Q((L − b_q⁽⁰⁾)/σ_q⁽⁰⁾) + Σ_k p_fault,k Q((L − T_k,q − b_q⁽ᵏ⁾)/σ_q⁽ᵏ⁾) = P_HMI,q (1 − P_not_monitored/(P_HMI,VERT + P_HMI,HOR))`
//!
//! with `P_HMI,q = P_HMI,VERT` for the vertical and `P_HMI,HOR / 2` for each horizontal axis.

use statrs::distribution::{ContinuousCDF, Normal};

/// One term `coef · Q((L − offset)/sigma)` of the PL equation's left-hand side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlTerm {
    /// 2 for the fault-free term, `p_fault,k` for fault mode k.
    pub coef: f64,
    /// `b_q⁽⁰⁾` for the fault-free term, `T_k,q + b_q⁽ᵏ⁾` for fault mode k, m.
    pub offset: f64,
    /// `σ_q⁽ᵏ⁾`, m.
    pub sigma: f64,
}

/// Upper tail of the standard normal, `Q(x) = erfc(x/√2)/2` (libm's erfc keeps the tail
/// accurate down to 1e-300).
pub fn q(x: f64) -> f64 {
    0.5 * libm::erfc(x * std::f64::consts::FRAC_1_SQRT_2)
}

/// `Q⁻¹(p)`: the x with `Q(x) = p`, for p in (0, 1).
pub fn q_inv(p: f64) -> f64 {
    -Normal::standard().inverse_cdf(p)
}

/// The left-hand side `Σ coef · Q((L − offset)/σ)` at `l`.
pub fn lhs(terms: &[PlTerm], l: f64) -> f64 {
    terms
        .iter()
        .map(|t| t.coef * q((l - t.offset) / t.sigma))
        .sum()
}

/// What a term may hold at most, once it is left out of the halving: at most
/// `SKIP_SHARE · rhs / n` each, so all of them together at most `SKIP_SHARE · rhs`.
const SKIP_SHARE: f64 = 1e-3;

/// Relative margin of the kept-terms comparisons over the rounding of a sum of positive
/// terms (a few ulps per term): within it the whole left-hand side decides.
const SUM_MARGIN: f64 = 1e-9;

/// Solves `lhs(L) = rhs` by halving the bracket until it is at most `tol` wide and
/// returns its upper end (so `lhs(PL) ≤ rhs`: the conservative side). The bracket is
/// Blanch et al. 2015's: no term may exceed `rhs` (lower bound), and all terms at most
/// `rhs / n` suffice (upper bound). `rhs ≤ 0` (the unmonitored modes use up the whole
/// budget) gives an infinite PL.
///
/// Every halving point is at or above the bracket's lower end `lo`, where `Q` of each
/// term is largest; a term whose argument there is past `Q⁻¹(SKIP_SHARE · rhs /
/// (n coef))` stays below that share wherever the halving looks, so it is bounded once
/// (the sum of those bounds, `dropped`) and not evaluated again. A midpoint is then
/// decided by the kept terms alone when `kept > rhs` or `kept + dropped < rhs` (each by
/// [`SUM_MARGIN`]), and by the whole sum otherwise: every decision, and so the PL, is
/// the one plain halving of the whole sum makes. (Regula falsi on `ln lhs` was tried: it
/// moves one end close to the root but seldom narrows the bracket below `tol`, and was
/// no faster.)
pub fn solve(terms: &[PlTerm], rhs: f64, tol: f64) -> f64 {
    if rhs <= 0.0 || terms.is_empty() {
        return f64::INFINITY;
    }
    let bracket = Bracket::new(terms, rhs);
    let (mut lo, mut hi) = (bracket.lo, bracket.hi);
    if lo >= hi {
        return hi;
    }
    let mut kept: Vec<PlTerm> = Vec::with_capacity(terms.len());
    let mut dropped = 0.0;
    for t in terms {
        match bracket.of(t.coef) {
            Some(k) if (lo - t.offset) / t.sigma >= k.skip => dropped += k.skip_bound,
            _ => kept.push(*t),
        }
    }
    while hi - lo > tol {
        let mid = 0.5 * (lo + hi);
        let part = lhs(&kept, mid);
        let above = if part > rhs * (1.0 + SUM_MARGIN) {
            true
        } else if (part + dropped) * (1.0 + SUM_MARGIN) <= rhs {
            false
        } else {
            lhs(terms, mid) > rhs
        };
        if above {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// The quantiles of one coefficient: the bracket's (`Q⁻¹(rhs / coef)` and
/// `Q⁻¹(rhs / (n coef))`) and the skipping threshold with its bound.
#[derive(Debug, Clone, Copy)]
struct Quantiles {
    /// `Q⁻¹(rhs / coef)`, −∞ when `coef ≤ rhs` (the term alone never reaches `rhs`).
    lower: f64,
    /// `max(Q⁻¹(rhs / (n coef)), 0)`.
    upper: f64,
    /// `Q⁻¹(SKIP_SHARE · rhs / (n coef))`, −∞ when the term can never exceed that.
    skip: f64,
    /// `coef · Q(skip)`: the most a skipped term holds.
    skip_bound: f64,
}

/// Blanch et al. 2015's bracket of the PL, and the quantiles it took: `Q⁻¹` is taken once
/// per distinct coefficient (the fault modes share a few: 2, P_sat, P_const and their
/// products).
struct Bracket {
    /// No term may exceed `rhs` alone.
    lo: f64,
    /// Every term at most `rhs / n`.
    hi: f64,
    /// Each distinct coefficient and its quantiles.
    seen: Vec<(f64, Quantiles)>,
}

impl Bracket {
    fn new(terms: &[PlTerm], rhs: f64) -> Self {
        let n = terms.len() as f64;
        let mut b = Bracket {
            lo: 0.0,
            hi: 0.0,
            seen: Vec::with_capacity(4),
        };
        for t in terms {
            let k = match b.seen.iter().find(|s| s.0 == t.coef) {
                Some(&(_, k)) => k,
                None => {
                    let k = Quantiles::of(t.coef, rhs, n);
                    b.seen.push((t.coef, k));
                    k
                }
            };
            if k.lower.is_finite() {
                b.lo = b.lo.max(t.offset + k.lower * t.sigma);
            }
            b.hi = b.hi.max(t.offset + k.upper * t.sigma);
        }
        b
    }

    /// The quantiles of a coefficient of the terms the bracket was built on (`None` for
    /// a NaN coefficient, which never compares equal).
    fn of(&self, coef: f64) -> Option<Quantiles> {
        self.seen.iter().find(|s| s.0 == coef).map(|s| s.1)
    }
}

impl Quantiles {
    fn of(coef: f64, rhs: f64, n: f64) -> Self {
        let lower = if coef > rhs {
            q_inv(rhs / coef)
        } else {
            f64::NEG_INFINITY
        };
        let share = rhs / (n * coef);
        let upper = if share < 1.0 {
            q_inv(share).max(0.0)
        } else {
            0.0
        };
        let small = SKIP_SHARE * share;
        let (skip, skip_bound) = if small < 1.0 {
            let k = q_inv(small);
            (k, coef * q(k))
        } else {
            (f64::NEG_INFINITY, coef)
        };
        Quantiles {
            lower,
            upper,
            skip,
            skip_bound,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_single_fault_free_term_gives_the_two_sided_quantile() {
        // 2 Q(L/σ) = 1e-7 ⇒ L = σ · Q⁻¹(5e-8) = 5.3267 σ.
        let t = [PlTerm {
            coef: 2.0,
            offset: 0.0,
            sigma: 1.5,
        }];
        let l = solve(&t, 1e-7, 1e-9);
        assert!((l - 1.5 * q_inv(5e-8)).abs() < 1e-8, "{l}");
        assert!((q_inv(5e-8) - 5.326_723_886).abs() < 1e-6);
    }
}

#[cfg(test)]
mod solver_tests {
    use super::*;

    #[test]
    fn the_solver_lands_within_tol_above_the_root_on_many_terms() {
        // A fault-free term and 30 modes of varied offsets and σ, as a 30-satellite epoch.
        let mut terms = vec![PlTerm {
            coef: 2.0,
            offset: 0.3,
            sigma: 1.1,
        }];
        for k in 0..30 {
            let k = f64::from(k);
            terms.push(PlTerm {
                coef: 1e-5,
                offset: 4.0 + 0.37 * k,
                sigma: 1.2 + 0.05 * k,
            });
        }
        for rhs in [9.8e-8, 1e-9, 1e-5] {
            let l = solve(&terms, rhs, 0.05);
            assert!(lhs(&terms, l) <= rhs, "conservative side at {rhs}");
            assert!(
                lhs(&terms, l - 0.05) > rhs,
                "within tol of the root at {rhs}"
            );
        }
    }
}
