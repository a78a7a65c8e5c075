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

/// Solves `lhs(L) = rhs` by halving the bracket until it is at most `tol` wide and
/// returns its upper end (so `lhs(PL) ≤ rhs`: the conservative side). The bracket is
/// Blanch et al. 2015's: no term may exceed `rhs` (lower bound), and all terms at most
/// `rhs / n` suffice (upper bound). `rhs ≤ 0` (the unmonitored modes use up the whole
/// budget) gives an infinite PL. (Regula falsi on `ln lhs` was tried: it moves one end
/// close to the root but seldom narrows the bracket below `tol`, and was no faster.)
pub fn solve(terms: &[PlTerm], rhs: f64, tol: f64) -> f64 {
    if rhs <= 0.0 || terms.is_empty() {
        return f64::INFINITY;
    }
    let (mut lo, mut hi) = bracket(terms, rhs);
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

/// Blanch et al. 2015's bracket of the PL: `Q⁻¹` is taken once per distinct coefficient
/// (the fault modes share a few: 2, P_sat, P_const and their products).
fn bracket(terms: &[PlTerm], rhs: f64) -> (f64, f64) {
    let n = terms.len() as f64;
    let mut seen: Vec<(f64, f64, f64)> = Vec::with_capacity(4);
    let (mut lo, mut hi) = (0.0_f64, 0.0_f64);
    for t in terms {
        let (k_lo, k_hi) = match seen.iter().find(|s| s.0 == t.coef) {
            Some(&(_, a, b)) => (a, b),
            None => {
                let k_lo = if t.coef > rhs {
                    q_inv(rhs / t.coef)
                } else {
                    f64::NEG_INFINITY
                };
                let share = rhs / (n * t.coef);
                let k_hi = if share < 1.0 {
                    q_inv(share).max(0.0)
                } else {
                    0.0
                };
                seen.push((t.coef, k_lo, k_hi));
                (k_lo, k_hi)
            }
        };
        if k_lo.is_finite() {
            lo = lo.max(t.offset + k_lo * t.sigma);
        }
        hi = hi.max(t.offset + k_hi * t.sigma);
    }
    (lo, hi)
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
