//! Snedecor's F law of the drift and stuck tests ([`super::window`], [`super::stuck`]):
//! its tails through the regularised incomplete beta function, with `ln B(d1/2, d2/2)`
//! computed once per law. Those tests evaluate the same law every epoch once their
//! references are full, and a fresh `ln B` (three `ln Γ`) was a third of each tail's cost.
//!
//! `I_x(a, b)` is the continued fraction of DLMF 8.17.22, evaluated by its fundamental
//! recurrences (no division per term) on `I_x(a, b)` when `x < (a + 1)/(a + b + 2)` (where
//! it converges fast) and as `1 − I_{1−x}(b, a)` otherwise; `1 − x` is passed in, formed
//! from the F statistic without cancellation, rather than rounded from `x`.

use statrs::function::gamma::ln_gamma;

/// Terms of the continued fraction before it is taken as converged: about
/// `√max(a, b)` are needed, so this covers any dof a test can be configured with.
const MAX_TERMS: u32 = 100_000;

/// The law `F(d1, d2)` with `ln B(d1/2, d2/2)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FLaw {
    d1: f64,
    d2: f64,
    /// `ln B(d1/2, d2/2)`; not needed (NaN) when `d1 = 2`, whose tails are closed forms.
    ln_beta: f64,
}

impl FLaw {
    /// `F(d1, d2)` for `d1, d2 > 0`.
    pub fn new(d1: f64, d2: f64) -> Self {
        let ln_beta = if d1 == 2.0 {
            f64::NAN
        } else {
            let (a, b) = (d1 / 2.0, d2 / 2.0);
            ln_gamma(a) + ln_gamma(b) - ln_gamma(a + b)
        };
        FLaw { d1, d2, ln_beta }
    }

    /// `cached` when it is `F(d1, d2)`, else a new law.
    pub fn reuse(cached: Option<FLaw>, d1: f64, d2: f64) -> Self {
        match cached {
            Some(law) if law.d1 == d1 && law.d2 == d2 => law,
            _ => FLaw::new(d1, d2),
        }
    }

    /// Upper-tail probability at `x`: `I_w(d2/2, d1/2)` with `w = d2/(d1 x + d2)`
    /// (no `1 − cdf` cancellation in the far tail).
    pub fn upper_tail(&self, x: f64) -> f64 {
        if x <= 0.0 {
            return 1.0;
        }
        if !x.is_finite() {
            return 0.0;
        }
        let (d1, d2) = (self.d1, self.d2);
        if d1 == 2.0 {
            // I_w(b, 1) = w^b: the tail is (1 + 2x/d2)^(−d2/2) (the drift tests of
            // two-component aids take one every epoch).
            return (-0.5 * d2 * (2.0 * x / d2).ln_1p()).exp();
        }
        let s = d1 * x + d2;
        beta_reg(d2 / 2.0, d1 / 2.0, d2 / s, d1 * x / s, self.ln_beta)
    }

    /// Lower-tail probability at `x`: `I_v(d1/2, d2/2)` with `v = d1 x/(d1 x + d2)`.
    pub fn lower_tail(&self, x: f64) -> f64 {
        if x <= 0.0 {
            return 0.0;
        }
        if !x.is_finite() {
            return 1.0;
        }
        let (d1, d2) = (self.d1, self.d2);
        if d1 == 2.0 {
            // I_v(1, b) = 1 − (1 − v)^b, as an expm1.
            return -(-0.5 * d2 * (2.0 * x / d2).ln_1p()).exp_m1();
        }
        let s = d1 * x + d2;
        beta_reg(d1 / 2.0, d2 / 2.0, d1 * x / s, d2 / s, self.ln_beta)
    }
}

/// `I_x(a, b)` for `a, b > 0`, `x ∈ [0, 1]` with `y = 1 − x` and `ln_beta = ln B(a, b)`.
fn beta_reg(a: f64, b: f64, x: f64, y: f64, ln_beta: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if y <= 0.0 {
        return 1.0;
    }
    // x^a y^b / B(a, b)
    let front = (a * x.ln() + b * y.ln() - ln_beta).exp();
    if x < (a + 1.0) / (a + b + 2.0) {
        front * continued_fraction(a, b, x) / a
    } else {
        1.0 - front * continued_fraction(b, a, y) / b
    }
}

/// `1/(1 + d₁/(1 + d₂/(1 + …)))` of DLMF 8.17.22, with
/// `d_{2m} = m(b − m)x / ((a + 2m − 1)(a + 2m))` and
/// `d_{2m+1} = −(a + m)(a + b + m)x / ((a + 2m)(a + 2m + 1))`.
///
/// Evaluated by the fundamental recurrences `A_n = β_n A_{n−1} + α_n A_{n−2}` (and `B_n`
/// alike) of the equivalent fraction with `β_n = a + n`, `α_1 = −(a + b)x`,
/// `α_{2m} = m(b − m)x`, `α_{2m+1} = −(a + m)(a + b + m)x` (`d_n` multiplied through by
/// `(a + n − 1)(a + n)`, `d_1` by `a + 1`): the value is `B_n / A_n`. That needs no division
/// per term, where Lentz's method needs six in one dependency chain; division latency was
/// most of the stuck test's cost. `A` and `B` grow like `n!`, so both are scaled down by an
/// exact power of two when they pass `2⁴⁰⁰` (the products of the check cannot overflow).
/// The fraction has converged when two successive convergents agree to `ε`
/// (`|A_n B_{n−1} − A_{n−1} B_n| ≤ ε |A_{n−1} B_n|`), checked after each odd term as
/// Lentz's method checks it.
fn continued_fraction(a: f64, b: f64, x: f64) -> f64 {
    /// Where the recurrences are rescaled, and by how much (both exact).
    const BIG: f64 = 2.582_249_878_086_908_6e120; // 2^400
    const SMALL: f64 = 3.872_591_914_849_318e-121; // 2^-400
    // One term: (A_{n−2}, A_{n−1}, B_{n−2}, B_{n−1}) → (A_{n−1}, A_n, B_{n−1}, B_n).
    let term = |[a0, a1, b0, b1]: [f64; 4], alpha: f64, beta: f64| {
        [a1, beta * a1 + alpha * a0, b1, beta * b1 + alpha * b0]
    };
    // From A_{−1} = 1, A_0 = 1, B_{−1} = 0, B_0 = 1.
    let mut r = term([1.0, 1.0, 0.0, 1.0], -(a + b) * x, a + 1.0);
    for m in 1..=MAX_TERMS {
        let m = f64::from(m);
        let m2 = 2.0 * m;
        r = term(r, m * (b - m) * x, a + m2);
        r = term(r, -(a + m) * (a + b + m) * x, a + m2 + 1.0);
        let [a0, a1, b0, b1] = r;
        if a1.abs() > BIG || b1.abs() > BIG {
            r = r.map(|v| v * SMALL);
        }
        if (a1 * b0 - a0 * b1).abs() <= f64::EPSILON * (a0 * b1).abs() {
            break;
        }
    }
    let [_, a1, _, b1] = r;
    b1 / a1
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rel_err(got: f64, want: f64) -> f64 {
        ((got - want) / want).abs()
    }

    #[test]
    fn the_tails_match_scipy() {
        // scipy.stats.f.sf(4.0, 1, 20), f.sf(40.0, 2, 9), f.cdf(0.01, 5, 300),
        // f.sf(3.5, 3, 12), f.cdf(0.2, 16.5, 998.5).
        let cases = [
            (
                FLaw::new(1.0, 20.0).upper_tail(4.0),
                0.059_265_535_446_570_44,
            ),
            (
                FLaw::new(2.0, 9.0).upper_tail(40.0),
                3.325_341_578_437_592e-5,
            ),
            (
                FLaw::new(5.0, 300.0).lower_tail(0.01),
                2.956_656_579_812_494_3e-5,
            ),
        ];
        for (got, want) in cases {
            assert!(rel_err(got, want) < 1e-12, "{got} vs {want}");
        }
    }

    #[test]
    fn the_stuck_tests_laws_match_mpmath_near_their_mean() {
        // The stuck test's laws near their mean, just below the continued fraction's switch
        // point (where it converges slowest): mpmath.betainc(d1/2, d2/2, 0, d1 x/(d1 x + d2))
        // at 40 digits. What limits the agreement is `ln B(a, b)` = ln Γ(a) + ln Γ(b) −
        // ln Γ(a + b), whose terms near 2,600 cancel to about −40 (2e-12 relative at
        // F(16.7, 999), x = 0.6).
        let cases = [
            (16.7, 999.0, 0.6, 0.108_464_702_048_365_61),
            (16.7, 999.0, 1.0, 0.544_910_321_150_695_4),
            (5.6, 333.4, 0.9, 0.510_194_337_613_847),
            (33.4, 2997.0, 1.0, 0.532_012_500_118_239_5),
            (11.1, 1498.5, 0.95, 0.508_662_625_542_573_7),
        ];
        for (d1, d2, x, want) in cases {
            let got = FLaw::new(d1, d2).lower_tail(x);
            assert!(
                rel_err(got, want) < 1e-11,
                "F({d1}, {d2}) cdf({x}): {got} vs {want}"
            );
        }
    }

    #[test]
    fn the_tails_equal_statrs_incomplete_beta_and_sum_to_one() {
        // statrs' I_x(a, b) from the same continued fraction with a fresh ln B and 1 − x
        // rounded from x: equal to 1e-12 wherever the value is not a cancellation.
        for (d1, d2) in [
            (1.0, 5.0),
            (2.0, 9.0),
            (3.0, 8.0),
            (3.0, 48.0),
            (6.0, 145.0),
            (16.7, 999.0),
            (5.6, 333.4),
        ] {
            let law = FLaw::new(d1, d2);
            for x in [1e-4, 0.01, 0.2, 0.5, 0.9, 1.0, 1.3, 2.0, 4.0, 10.0, 60.0] {
                let (up, low) = (law.upper_tail(x), law.lower_tail(x));
                let s = d1 * x + d2;
                let want_up = statrs::function::beta::beta_reg(d2 / 2.0, d1 / 2.0, d2 / s);
                let want_low = statrs::function::beta::beta_reg(d1 / 2.0, d2 / 2.0, d1 * x / s);
                assert!(
                    rel_err(up, want_up) < 1e-12,
                    "F({d1}, {d2}) sf({x}): {up} vs {want_up}"
                );
                assert!(
                    rel_err(low, want_low) < 1e-12,
                    "F({d1}, {d2}) cdf({x}): {low} vs {want_low}"
                );
                assert!(
                    (up + low - 1.0).abs() < 4.0 * f64::EPSILON,
                    "F({d1}, {d2}) at {x}: {up} + {low} - 1 = {:e}",
                    up + low - 1.0
                );
            }
            assert_eq!(law.upper_tail(0.0), 1.0);
            assert_eq!(law.lower_tail(0.0), 0.0);
            assert_eq!(law.upper_tail(f64::INFINITY), 0.0);
            assert_eq!(law.lower_tail(f64::INFINITY), 1.0);
        }
    }

    #[test]
    fn a_cached_law_is_reused_only_for_its_own_dofs() {
        let law = FLaw::new(3.0, 40.0);
        assert_eq!(FLaw::reuse(Some(law), 3.0, 40.0), law);
        let other = FLaw::reuse(Some(law), 3.0, 41.0);
        assert_eq!(other, FLaw::new(3.0, 41.0));
        assert_eq!(FLaw::reuse(None, 3.0, 40.0), law);
    }
}
