//! χ² core of the detect layer: detection thresholds, false-alarm and
//! missed-detection probabilities of the chi-square residual test (seed 000,
//! eq. 18).
//!
//! With `dof` degrees of freedom the test alarms when the statistic exceeds
//! `T_D = F⁻¹_{χ²(dof)}(1 − p_fa)`; under a fault of non-centrality λ it stays
//! silent with probability `P_MD = F_{χ²(dof, λ)}(T_D)`.
//!
//! # Numerical method
//!
//! Notation: `a = dof/2`, `y = x/2`, `μ = λ/2`, `P(b, y)` / `Q(b, y)` the
//! regularized lower / upper incomplete gamma functions and
//! `d_b(y) = y^b e^{-y} / Γ(b+1)`, so that `P(b+1) = P(b) − d_b` and
//! `Q(b+1) = Q(b) + d_b` (A&S 6.5.21).
//!
//! * Central χ²: `P` by its power series (A&S 6.5.29) when `y < b + 1`, `Q` by
//!   its continued fraction (A&S 6.5.31, modified Lentz) otherwise; the small
//!   one is always computed directly, in logarithms, and the other one as its
//!   complement. The prefactor `d_b(y)` uses Loader's saddle-point form
//!   (`stirlerr` + `bd0`), which keeps full relative accuracy for large `b, y`.
//! * Non-central χ² (Johnson, Kotz & Balakrishnan, *Continuous Univariate
//!   Distributions* vol. 2, ch. 29):
//!   `F = Σ_j w_j P(a+j, y)` and `1 − F = Σ_j w_j Q(a+j, y)` with Poisson
//!   weights `w_j = e^{-μ} μ^j / j!`. Each series is summed outward from its
//!   largest term in both directions, with terms carried relative to that term
//!   so that nothing underflows while the answer is representable. The ratio
//!   of consecutive terms decreases monotonically away from the peak (both the
//!   Poisson ratio and `P(b+1)/P(b)`, `Q(b+1)/Q(b)` are monotone in `b`), so
//!   once it is `r < 1` the rest of the sweep is bounded by `t·r/(1 − r)`;
//!   a sweep stops when that bound is below `1e-15` of the partial sum.
//! * The thresholds and the inverse in λ are safeguarded root finders on the
//!   logarithm of the small tail, so tiny probabilities keep full relative
//!   accuracy.

use libm::erfc;
use statrs::function::erf::erfc_inv;
use statrs::function::gamma::ln_gamma;

/// Errors of the χ² routines; every function validates its inputs and returns
/// one of these instead of panicking or producing NaN.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Chi2Error {
    /// dof must be >= 1
    #[error("dof must be a positive integer, got {0}")]
    InvalidDof(u32),
    /// A probability argument was not in the open interval (0, 1), or was NaN.
    #[error("probability must lie strictly between 0 and 1, got {0}")]
    InvalidProbability(f64),
    /// A threshold / evaluation point was negative, NaN or infinite (or zero
    /// where a positive threshold is required).
    #[error("threshold must be finite and positive, got {0}")]
    InvalidThreshold(f64),
    /// The non-centrality was negative, NaN, infinite or above the supported
    /// maximum of `1e8`.
    #[error("non-centrality must be finite and non-negative, got {0}")]
    InvalidNoncentrality(f64),
    /// No non-centrality in `[0, max]` yields the requested missed-detection
    /// probability.
    #[error("no non-centrality in [0, {max}] gives P_MD = {p_md} at threshold {threshold}")]
    Unreachable {
        /// The requested missed-detection probability.
        p_md: f64,
        /// The detection threshold it was requested at.
        threshold: f64,
        /// The largest non-centrality searched.
        max: f64,
    },
}

/// Largest supported non-centrality. The series need O(√λ) terms and the
/// start values O(√λ) iterations, so this keeps one evaluation in the
/// millisecond range; P_MD of practical interest needs λ of at most a few
/// thousand.
const MAX_NONCENTRALITY: f64 = 1e8;
/// Relative bound on the truncated remainder of each non-central sweep.
const SERIES_TOL: f64 = 1e-15;
/// Iteration cap of the central series / continued fraction (only reached for
/// `b` far beyond anything valid inputs produce; it guarantees termination).
const MAX_ITER: u32 = 10_000_000;
/// Term cap of a non-central sweep (same purpose).
const MAX_TERMS: u64 = 100_000_000;
/// `ln √(2π)`.
const LN_SQRT_2PI: f64 = 0.918_938_533_204_672_8;
/// A tail whose Chernoff bound is below `e^{-750}` rounds to 0 in f64.
const LN_UNDERFLOW: f64 = -750.0;

/// χ² detection threshold `T_D = F⁻¹_{χ²(dof)}(1 − p_fa)`.
///
/// The survival function is inverted directly (never `1 − p_fa` for small
/// `p_fa`), so thresholds for `p_fa` down to ~1e-300 are accurate to about
/// 1e-15 relative.
///
/// # Errors
/// [`Chi2Error::InvalidDof`] for `dof == 0`, [`Chi2Error::InvalidProbability`]
/// unless `0 < p_fa < 1`.
pub fn threshold(dof: u32, p_fa: f64) -> Result<f64, Chi2Error> {
    check_dof(dof)?;
    check_probability(p_fa)?;
    // Closed forms (every detector's χ²(1) and χ²(2) equivalent takes one per epoch):
    // χ²(2) is 2·Exp(1), Q(1, y) = e^{−y}; χ²(1) is Z², Q(½, y) = erfc(√y). `ln` and
    // `erfc_inv` keep full relative accuracy over (0, 1), down to subnormal p_fa.
    match dof {
        1 => return Ok(2.0 * erfc_inv(p_fa).powi(2)),
        2 => return Ok(-2.0 * p_fa.ln()),
        _ => {}
    }
    let a = f64::from(dof) / 2.0;
    // Small dof (every drift test's χ²(3) equivalent, one per epoch): the tails from the
    // finite sums of `finite_tails`, several times cheaper than `inc_gamma`'s series and
    // continued fraction.
    let y = if p_fa < 0.5 {
        upper_quantile_with(a, p_fa, |y| match finite_tails(dof, y) {
            Some((q, density)) => (q.ln(), density / q),
            _ => upper_tail_slope(a, y),
        })
    } else {
        // 1 − p_fa is exact here (Sterbenz), so the lower tail is the
        // well-conditioned one to invert. `1 − Q` is used only where `P ≥ 0.1`, so it
        // loses at most a few bits; below, the series.
        lower_quantile_with(a, 1.0 - p_fa, |y| match finite_tails(dof, y) {
            Some((q, density)) if q <= 0.9 => {
                let p = 1.0 - q;
                (p.ln(), density * y / p)
            }
            _ => lower_tail_slope(a, y),
        })
    };
    Ok(2.0 * y)
}

/// False-alarm probability of a threshold: the central χ² survival function
/// `1 − F_{χ²(dof)}(threshold)`, with full relative accuracy in the tail.
///
/// # Errors
/// [`Chi2Error::InvalidDof`] for `dof == 0`, [`Chi2Error::InvalidThreshold`]
/// unless `threshold` is finite and `> 0`.
pub fn false_alarm_probability(dof: u32, threshold: f64) -> Result<f64, Chi2Error> {
    check_dof(dof)?;
    check_threshold(threshold)?;
    Ok(inc_gamma(f64::from(dof) / 2.0, threshold / 2.0).ln_q.exp())
}

/// Non-central χ² CDF `F_{χ²(dof, λ)}(x)`; `λ = 0` gives the central χ².
///
/// Relative accuracy is ~1e-13 or better in both tails (values down to the
/// f64 underflow limit), for λ up to `1e8`.
///
/// # Errors
/// [`Chi2Error::InvalidDof`] for `dof == 0`, [`Chi2Error::InvalidThreshold`]
/// unless `x` is finite and `>= 0` (`x = 0` gives 0),
/// [`Chi2Error::InvalidNoncentrality`] unless `0 <= lambda <= 1e8`.
pub fn noncentral_cdf(x: f64, dof: u32, lambda: f64) -> Result<f64, Chi2Error> {
    check_dof(dof)?;
    check_point(x)?;
    check_noncentrality(lambda)?;
    Ok(noncentral_tail(x, dof, lambda, Tail::Lower))
}

/// Non-central χ² survival function `1 − F_{χ²(dof, λ)}(x)`, summed directly
/// from central survival functions so that upper-tail values near 0 keep full
/// relative accuracy.
///
/// # Errors
/// As [`noncentral_cdf`] (`x = 0` gives 1).
pub fn noncentral_sf(x: f64, dof: u32, lambda: f64) -> Result<f64, Chi2Error> {
    check_dof(dof)?;
    check_point(x)?;
    check_noncentrality(lambda)?;
    Ok(noncentral_tail(x, dof, lambda, Tail::Upper))
}

/// Missed-detection probability `P_MD = F_{χ²(dof, λ)}(threshold)` of a fault
/// with non-centrality `lambda` (seed 000, eq. 18).
///
/// # Errors
/// As [`noncentral_cdf`], except that the threshold must be `> 0`.
pub fn missed_detection(dof: u32, threshold: f64, lambda: f64) -> Result<f64, Chi2Error> {
    check_dof(dof)?;
    check_threshold(threshold)?;
    check_noncentrality(lambda)?;
    Ok(noncentral_tail(threshold, dof, lambda, Tail::Lower))
}

/// The non-centrality λ at which the missed-detection probability at
/// `threshold` equals `p_md`, to ~1e-15 relative.
///
/// `P_MD` decreases strictly in λ from the central CDF at λ = 0, so a solution
/// exists iff `p_md <= F_{χ²(dof)}(threshold)`. Equality returns `Ok(0.0)`; a
/// larger `p_md` (a fault-free test already misses less often than asked) is
/// reported as [`Chi2Error::Unreachable`] rather than silently clamped, as it
/// signals inconsistent integrity parameters. So is a `p_md` that would need
/// λ above `1e8`.
///
/// # Errors
/// [`Chi2Error::InvalidDof`], [`Chi2Error::InvalidThreshold`] (`threshold`
/// must be finite and `> 0`), [`Chi2Error::InvalidProbability`] unless
/// `0 < p_md < 1`, and [`Chi2Error::Unreachable`] as above.
pub fn noncentrality_for_missed_detection(
    dof: u32,
    threshold: f64,
    p_md: f64,
) -> Result<f64, Chi2Error> {
    check_dof(dof)?;
    check_threshold(threshold)?;
    check_probability(p_md)?;
    let unreachable = Chi2Error::Unreachable {
        p_md,
        threshold,
        max: MAX_NONCENTRALITY,
    };
    // Root of the decreasing h(λ) = ln P_MD(λ) − ln p_md. Working with the
    // logarithm makes h nearly linear in λ in the tail and keeps the relative
    // accuracy for tiny p_md. ln 0 is clamped to a finite value below any
    // ln p_md (> −745) so the root finder only ever sees finite numbers.
    let ln_p = p_md.ln();
    let h = |lambda: f64| {
        noncentral_tail(threshold, dof, lambda, Tail::Lower)
            .ln()
            .max(-800.0)
            - ln_p
    };
    let h0 = h(0.0);
    if h0 < 0.0 {
        return Err(unreachable);
    }
    if h0 == 0.0 {
        return Ok(0.0);
    }
    // Bracket: F_{χ²(d,λ)}(T) ≈ Φ(√T − √λ) for large λ, so start a little
    // beyond (√T + √(2|ln p|))² and grow geometrically.
    let (mut lo, mut h_lo) = (0.0, h0);
    let mut hi = (threshold.sqrt() + (-2.0 * ln_p).sqrt() + 1.0).powi(2);
    let mut h_hi;
    loop {
        hi = hi.min(MAX_NONCENTRALITY);
        h_hi = h(hi);
        if h_hi <= 0.0 {
            break;
        }
        if hi >= MAX_NONCENTRALITY {
            return Err(unreachable);
        }
        (lo, h_lo) = (hi, h_hi);
        hi *= 4.0;
    }
    if h_hi == 0.0 {
        return Ok(hi);
    }
    Ok(brent(h, lo, hi, h_lo, h_hi))
}

// ---------------------------------------------------------------------------
// Input validation

fn check_dof(dof: u32) -> Result<(), Chi2Error> {
    if dof == 0 {
        return Err(Chi2Error::InvalidDof(dof));
    }
    Ok(())
}

fn check_probability(p: f64) -> Result<(), Chi2Error> {
    if p > 0.0 && p < 1.0 {
        Ok(())
    } else {
        Err(Chi2Error::InvalidProbability(p))
    }
}

/// Evaluation point of a CDF / SF: finite and `>= 0`.
fn check_point(x: f64) -> Result<(), Chi2Error> {
    if x.is_finite() && x >= 0.0 {
        Ok(())
    } else {
        Err(Chi2Error::InvalidThreshold(x))
    }
}

/// Detection threshold: finite and `> 0`.
fn check_threshold(t: f64) -> Result<(), Chi2Error> {
    if t.is_finite() && t > 0.0 {
        Ok(())
    } else {
        Err(Chi2Error::InvalidThreshold(t))
    }
}

fn check_noncentrality(lambda: f64) -> Result<(), Chi2Error> {
    if (0.0..=MAX_NONCENTRALITY).contains(&lambda) {
        Ok(())
    } else {
        Err(Chi2Error::InvalidNoncentrality(lambda))
    }
}

// ---------------------------------------------------------------------------
// Central χ²: the regularized incomplete gamma functions in logarithms

/// `stirlerr(n) = ln Γ(n+1) − (n + ½) ln n + n − ln √(2π)` at n = 0.5, 1, …, 15
/// (computed with mpmath at 40 digits).
const STIRLERR_HALVES: [f64; 30] = [
    0.15342640972002736,
    0.08106146679532726,
    0.05481412105191765,
    0.0413406959554093,
    0.03316287351993629,
    0.02767792568499834,
    0.023746163656297496,
    0.020790672103765093,
    0.018488450532673187,
    0.016644691189821193,
    0.015134973221917378,
    0.013876128823070748,
    0.012810465242920227,
    0.01189670994589177,
    0.011104559758206917,
    0.010411265261972096,
    0.009799416126158804,
    0.009255462182712733,
    0.008768700134139386,
    0.00833056343336287,
    0.00793411456431402,
    0.007573675487951841,
    0.007244554301320383,
    0.00694284010720953,
    0.006665247032707682,
    0.006408994188004207,
    0.006171712263039458,
    0.0059513701127588475,
    0.0057462165130101155,
    0.005554733551962801,
];

/// Error of Stirling's formula for `ln Γ(n+1)` (Loader 2000): a table at
/// half-integers up to 15 (all the module needs, as `dof` is an integer), the
/// asymptotic series above.
fn stirlerr(n: f64) -> f64 {
    const S0: f64 = 1.0 / 12.0;
    const S1: f64 = 1.0 / 360.0;
    const S2: f64 = 1.0 / 1260.0;
    const S3: f64 = 1.0 / 1680.0;
    const S4: f64 = 1.0 / 1188.0;
    if n <= 15.0 {
        let twice = 2.0 * n;
        if twice >= 1.0 && twice.fract() == 0.0 {
            return STIRLERR_HALVES[twice as usize - 1];
        }
        return ln_gamma(n + 1.0) - (n + 0.5) * n.ln() + n - LN_SQRT_2PI;
    }
    let nn = n * n;
    if n > 500.0 {
        (S0 - S1 / nn) / n
    } else if n > 80.0 {
        (S0 - (S1 - S2 / nn) / nn) / n
    } else if n > 35.0 {
        (S0 - (S1 - (S2 - S3 / nn) / nn) / nn) / n
    } else {
        (S0 - (S1 - (S2 - (S3 - S4 / nn) / nn) / nn) / nn) / n
    }
}

/// `x ln(x/m) + m − x >= 0` without cancellation when `x ≈ m` (Loader 2000).
fn bd0(x: f64, m: f64) -> f64 {
    if (x - m).abs() < 0.1 * (x + m) {
        let v = (x - m) / (x + m);
        let v2 = v * v;
        let mut s = (x - m) * v;
        let mut ej = 2.0 * x * v;
        for j in 1..1000 {
            ej *= v2;
            let s1 = s + ej / f64::from(2 * j + 1);
            if s1 == s {
                break;
            }
            s = s1;
        }
        s
    } else {
        // x/m over- or underflows for subnormal x: then the logs are far
        // apart and their difference is accurate.
        let r = x / m;
        let ln_r = if r.is_normal() {
            r.ln()
        } else {
            x.ln() - m.ln()
        };
        x * ln_r + m - x
    }
}

/// `ln d_b(y) = ln(y^b e^{-y} / Γ(b+1))`, the Poisson(y) log-probability of
/// `b` extended to real `b >= 0`; also the Poisson weights (`b = j`, `y = μ`).
fn ln_poisson_term(b: f64, y: f64) -> f64 {
    if b == 0.0 {
        -y
    } else if y == 0.0 {
        f64::NEG_INFINITY
    } else {
        -stirlerr(b) - bd0(b, y) - LN_SQRT_2PI - 0.5 * b.ln()
    }
}

/// Logarithms of `P(b, y)`, `Q(b, y)` and `d_b(y)`.
#[derive(Debug, Clone, Copy)]
struct IncGamma {
    ln_p: f64,
    ln_q: f64,
    ln_d: f64,
}

/// Regularized incomplete gamma functions for `b > 0`, finite `y > 0`.
fn inc_gamma(b: f64, y: f64) -> IncGamma {
    let ln_d = ln_poisson_term(b, y);
    if y < b + 1.0 {
        // P = d_b Σ_{n>=0} y^n / ((b+1)…(b+n)); terms shrink since y < b+1.
        let (mut term, mut sum, mut n) = (1.0_f64, 1.0_f64, 1.0);
        for _ in 0..MAX_ITER {
            term *= y / (b + n);
            sum += term;
            if term <= sum * f64::EPSILON * 0.5 {
                break;
            }
            n += 1.0;
        }
        let ln_p = ln_d + sum.ln();
        IncGamma {
            ln_p,
            ln_q: (-ln_p.exp()).ln_1p(), // Q >= Q(½, 3/2) ≈ 0.08: no cancellation
            ln_d,
        }
    } else {
        // Q = b d_b / (y+1−b − 1(1−b)/(y+3−b − 2(2−b)/(y+5−b − …))), Lentz.
        const TINY: f64 = 1e-300;
        let mut den = y + 1.0 - b;
        let mut c = 1.0 / TINY;
        let mut d = 1.0 / den;
        let mut h = d;
        for i in 1..MAX_ITER {
            let i = f64::from(i);
            let an = -i * (i - b);
            den += 2.0;
            d = an * d + den;
            if d.abs() < TINY {
                d = TINY;
            }
            c = den + an / c;
            if c.abs() < TINY {
                c = TINY;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() <= f64::EPSILON {
                break;
            }
        }
        let ln_q = ln_d + (b * h).ln();
        IncGamma {
            ln_p: (-ln_q.exp()).ln_1p(), // P >= 0.5 here
            ln_q,
            ln_d,
        }
    }
}

/// [`upper_quantile_with`] on [`inc_gamma`] alone (the reference the closed forms are
/// tested against).
#[cfg(test)]
fn upper_quantile(a: f64, p: f64) -> f64 {
    upper_quantile_with(a, p, |y| upper_tail_slope(a, y))
}

/// Largest dof whose thresholds use [`finite_tails`].
const FINITE_SUM_MAX_DOF: u32 = 12;

/// `(Q(dof/2, y), ρ(y))`, the χ²(dof) survival function at `2y` and the Gamma(dof/2, 1)
/// density at `y`, for `1 ≤ dof ≤` [`FINITE_SUM_MAX_DOF`] and `0 < y ≤ 700` (`None`
/// otherwise: past 700 `e^{−y}` nears underflow), from the finite sums — of positive
/// terms, so to a few ulp:
/// - even `dof = 2m`: `Q = e^{−y} Σ_{k<m} y^k/k!`, `ρ = e^{−y} y^{m−1}/(m−1)!`;
/// - odd `dof = 2m+1`: `Q = erfc(√y) + e^{−y} Σ_{k=1}^{m} y^{k−½}/Γ(k+½)`,
///   `ρ = e^{−y} y^{m−½}/Γ(m+½)` (for `m = 0`, `ρ = e^{−y}/√(π y)`).
///
/// The sums have `dof/2` terms, so they are for small dof only.
fn finite_tails(dof: u32, y: f64) -> Option<(f64, f64)> {
    if dof > FINITE_SUM_MAX_DOF || !(y > 0.0 && y <= 700.0) {
        return None;
    }
    let m = dof / 2;
    let e = (-y).exp();
    if dof % 2 == 0 {
        let (mut term, mut sum) = (1.0, 1.0);
        for k in 1..m {
            term *= y / f64::from(k);
            sum += term;
        }
        Some((e * sum, e * term))
    } else {
        let root = y.sqrt();
        if m == 0 {
            return Some((erfc(root), e / (root * std::f64::consts::PI.sqrt())));
        }
        // y^{½}/Γ(3/2), then y^{k+½}/Γ(k+3/2) = previous · y/(k+½).
        let mut term = root * std::f64::consts::FRAC_2_SQRT_PI;
        let mut sum = term;
        for k in 1..m {
            term *= y / (f64::from(k) + 0.5);
            sum += term;
        }
        Some((erfc(root) + e * sum, e * term))
    }
}

/// `(ln Q(a, y), ρ(y)/Q(a, y))` from [`inc_gamma`]: what [`upper_quantile_with`] steps on.
fn upper_tail_slope(a: f64, y: f64) -> (f64, f64) {
    let g = inc_gamma(a, y);
    // ρ/Q = a d_a(y) / (y Q)
    (g.ln_q, (g.ln_d - g.ln_q).exp() * a / y)
}

/// `(ln P(a, y), y ρ(y)/P(a, y))` from [`inc_gamma`]: what [`lower_quantile_with`] steps on.
fn lower_tail_slope(a: f64, y: f64) -> (f64, f64) {
    let g = inc_gamma(a, y);
    // y ρ/P = a d_a(y) / P
    (g.ln_p, (g.ln_d - g.ln_p).exp() * a)
}

/// `y` with `Q(a, y) = p` for `p < 0.5`: Halley on `ln p − ln Q(a, y)`, which
/// is close to linear in `y` in the tail, from the Wilson–Hilferty start,
/// falling back to bisection / doubling whenever a step leaves the bracket;
/// `tail(y)` gives `ln Q` and the slope `d/dy (−ln Q) = ρ/Q` (ρ the Gamma(a, 1) density).
fn upper_quantile_with(a: f64, p: f64, tail: impl Fn(f64) -> (f64, f64)) -> f64 {
    let ln_p = p.ln();
    let dof = 2.0 * a;
    let z = std::f64::consts::SQRT_2 * erfc_inv(2.0 * p);
    let t = 2.0 / (9.0 * dof);
    let wh = dof * (1.0 - t + z * t.sqrt()).powi(3) / 2.0;
    let mut y = if wh.is_finite() && wh > 0.0 { wh } else { a };
    let (mut lo, mut hi) = (0.0_f64, f64::INFINITY);
    for _ in 0..200 {
        let (ln_q, slope) = tail(y);
        let f = ln_p - ln_q; // increasing in y, with slope d/dy (−ln Q) = ρ/Q
        if f == 0.0 {
            break;
        }
        if f < 0.0 {
            lo = y;
        } else {
            hi = y;
        }
        // Halley: f'' / f' = (a − 1)/y − 1 + ρ/Q (ρ' = ρ ((a − 1)/y − 1), Q' = −ρ).
        let (correction, halley) = halley_step(f / slope, (a - 1.0) / y - 1.0 + slope);
        let mut next = y - correction;
        let inside = next > lo && next < hi;
        if !inside {
            next = if hi.is_finite() {
                0.5 * (lo + hi)
            } else {
                2.0 * y
            };
        }
        let step = (next - y).abs();
        // A Halley step that moves ln Q by δ leaves an error in ln Q of order δ³: below
        // `CONVERGED_STEP` that is under the last bit, so no further evaluation is needed.
        let done = step <= 4.0 * f64::EPSILON * y
            || (halley && inside && step * slope <= CONVERGED_STEP)
            || next == lo
            || next == hi;
        y = next;
        if done {
            break;
        }
    }
    y
}

/// The change of the log-tail by a Halley step below which the quantile inversions stop
/// without evaluating the tail again: what the step leaves, of the order of that change
/// cubed (1e-21), is far below an ulp of the result.
const CONVERGED_STEP: f64 = 1e-7;

/// Halley's correction from the Newton correction `t = f/f'` and `c = f''/f'`:
/// `(t / (1 − t c / 2), true)`, or `(t, false)` (Newton's) when the denominator is not
/// comfortably positive (far from the root, where Newton and the bracket are safer).
fn halley_step(t: f64, c: f64) -> (f64, bool) {
    let denominator = 1.0 - 0.5 * t * c;
    if denominator > 0.5 && denominator < 2.0 {
        (t / denominator, true)
    } else {
        (t, false)
    }
}

/// [`lower_quantile_with`] on [`inc_gamma`] alone.
#[cfg(test)]
fn lower_quantile(a: f64, q: f64) -> f64 {
    lower_quantile_with(a, q, |y| lower_tail_slope(a, y))
}

/// `y` with `P(a, y) = q` for `q <= 0.5`: Halley in `u = ln y`, where
/// `ln P ≈ a u − ln Γ(a+1)` is close to linear, inside the bracket
/// `P(a, y) <= y^a/Γ(a+1)` (left) and median < a (right); `tail(y)` gives `ln P` and
/// the slope `d ln P / d ln y = y ρ/P`.
fn lower_quantile_with(a: f64, q: f64, tail: impl Fn(f64) -> (f64, f64)) -> f64 {
    let ln_q = q.ln();
    let mut lo = (ln_q + ln_gamma(a + 1.0)) / a - 1.0;
    let mut hi = (a + 1.0).ln();
    let mut u = (lo + 1.0).min(0.5 * (lo + hi));
    for _ in 0..200 {
        let y = u.exp();
        let (ln_p, slope) = tail(y);
        let f = ln_p - ln_q; // increasing in u, with slope d ln P / du = y ρ/P
        if f == 0.0 {
            break;
        }
        if f < 0.0 {
            lo = u;
        } else {
            hi = u;
        }
        // Halley in u: with w = y ρ/P, d²(ln P)/du² = w (a − y − w).
        let (correction, halley) = halley_step(f / slope, a - y - slope);
        let mut next = u - correction;
        let inside = next > lo && next < hi;
        if !inside {
            next = 0.5 * (lo + hi);
        }
        let step = (next - u).abs();
        let done = step <= 2.0 * f64::EPSILON
            || (halley && inside && step * slope <= CONVERGED_STEP)
            || next == lo
            || next == hi;
        u = next;
        if done {
            break;
        }
    }
    u.exp()
}

// ---------------------------------------------------------------------------
// Non-central χ²

/// Which Poisson mixture to sum: of central CDFs (`P`) or of central SFs (`Q`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Tail {
    Lower,
    Upper,
}

/// `ln` of the Chernoff bound `min_t e^{-t x} E[e^{t X}]`, `X ~ χ²(d, λ)`:
/// bounds the upper tail for `x` above the mean `d + λ`, the lower tail below
/// it. The optimal `s = 1/(1 − 2t)` solves `λ s² + d s = x`.
fn ln_chernoff_bound(x: f64, d: f64, lambda: f64) -> f64 {
    let root = d.hypot(2.0 * lambda.sqrt() * x.sqrt()); // √(d² + 4λx)
    let x_over_s = 0.5 * (d + root);
    let s = x / x_over_s;
    0.5 * (x_over_s - x) + 0.5 * d * (x.ln() - x_over_s.ln()) + 0.5 * lambda * (s - 1.0)
}

/// `F(x)` (`Lower`) or `1 − F(x)` (`Upper`) of `χ²(dof, λ)`, inputs validated: the
/// cases with a closed answer here, otherwise the Poisson mixture of central tails
/// summed by [`PoissonMixture`].
fn noncentral_tail(x: f64, dof: u32, lambda: f64, tail: Tail) -> f64 {
    let lower = tail == Tail::Lower;
    if x == 0.0 {
        return if lower { 0.0 } else { 1.0 };
    }
    let d = f64::from(dof);
    let (a, y, mu) = (0.5 * d, 0.5 * x, 0.5 * lambda);
    if x < f64::MIN_POSITIVE {
        // Subnormal x, where y may even round to 0: only the j = 0 term
        // e^{-μ} y^a / Γ(a+1) matters, the rest being relatively O(μx).
        let ln_f = -mu + a * (x.ln() - std::f64::consts::LN_2) - ln_gamma(a + 1.0);
        return if lower { ln_f.exp() } else { 1.0 };
    }
    if lambda == 0.0 {
        let g = inc_gamma(a, y);
        return if lower { g.ln_p } else { g.ln_q }.exp();
    }
    // A tail whose Chernoff bound underflows is exactly 0 (and the other 1) in
    // f64. This also caps how far the sweeps below can wander.
    if ln_chernoff_bound(x, d, lambda) < LN_UNDERFLOW {
        return if (x < d + lambda) == lower { 0.0 } else { 1.0 };
    }

    let mixture = PoissonMixture::new(a, y, mu, lower);
    let mut sum = 1.0;
    mixture.sweep_forward(&mut sum);
    mixture.sweep_backward(&mut sum);
    let value = (mixture.scale + sum.ln()).exp();
    if value.is_nan() {
        // Unreachable for validated inputs; never hand NaN to callers.
        return if (x < d + lambda) == lower { 0.0 } else { 1.0 };
    }
    value.clamp(0.0, 1.0)
}

/// The series `Σ_j w_j G(a+j, y)` of [`noncentral_tail`]: Poisson weights
/// `w_j = e^{-μ} μ^j / j!` times central tails `G = P` (`lower`) or `Q`. Every term
/// is carried relative to the start term's, so that none overflows or underflows;
/// the start term itself counts 1 in the sum the sweeps add to.
struct PoissonMixture {
    /// Half the degrees of freedom.
    a: f64,
    /// Half the argument `x`.
    y: f64,
    /// Half the non-centrality `λ`.
    mu: f64,
    /// Summing `P` (the CDF) rather than `Q` (the SF).
    lower: bool,
    /// Index of the start term.
    s: u64,
    /// `ln` of the start term `w_s G_s`: the scale of every relative quantity.
    scale: f64,
    /// `ln G_s`.
    ln_g_start: f64,
    /// `d_{a+s}(y)` relative to `G_s`.
    d_start: f64,
    /// `G(b+1) = G(b) + sign·d_b`.
    sign: f64,
}

impl PoissonMixture {
    fn new(a: f64, y: f64, mu: f64, lower: bool) -> Self {
        // Start at (about) the largest term, so that the terms relative to it
        // neither overflow nor underflow. w_j d_{a+j-1}(y) peaks where
        // (j+1)(j+a) = μy; P(a+j, y) decreases and Q(a+j, y) increases in j, so
        // the P-series peaks at or below min(that, Poisson mode) and the Q-series
        // near or above max(that, Poisson mode). Any start gives the same sum.
        let k_peak = (0.5 * ((a - 1.0).hypot(2.0 * mu.sqrt() * y.sqrt()) - (a + 1.0))).max(0.0);
        let k_mode = mu.floor();
        let start = if lower {
            k_peak.min(k_mode)
        } else {
            k_peak.max(k_mode)
        }
        .floor();

        // All quantities are carried relative to the start term's Poisson weight
        // and central probability G_s = P or Q(a+s, y); `scale` is their ln.
        let g_start = inc_gamma(a + start, y);
        let ln_g_start = if lower { g_start.ln_p } else { g_start.ln_q };
        Self {
            a,
            y,
            mu,
            lower,
            s: start as u64,
            scale: ln_poisson_term(start, mu) + ln_g_start,
            ln_g_start,
            d_start: (g_start.ln_d - ln_g_start).exp(),
            sign: if lower { -1.0 } else { 1.0 },
        }
    }

    /// G at b = a + j, and d_b, computed directly (relative to G_s).
    fn direct(&self, j: u64) -> (f64, f64) {
        let g = inc_gamma(self.a + j as f64, self.y);
        let ln_g = if self.lower { g.ln_p } else { g.ln_q };
        (
            (ln_g - self.ln_g_start).exp(),
            (g.ln_d - self.ln_g_start).exp(),
        )
    }

    /// Forward sweep j = s+1, s+2, … The recurrence is stable for Q (sum of
    /// positive terms); for P it subtracts, so whenever P has fallen by 8×
    /// since it was last computed directly it is recomputed: every value then
    /// carries at most ~8n ulp of error.
    fn sweep_forward(&self, sum: &mut f64) {
        let (a, y, mu, s) = (self.a, self.y, self.mu, self.s);
        let (mut w, mut g, mut dj, mut prev, mut anchor) = (1.0, 1.0, self.d_start, 1.0, 1.0);
        let mut j = s;
        while j - s < MAX_TERMS {
            let b = a + j as f64;
            g += self.sign * dj;
            dj *= y / (b + 1.0);
            j += 1;
            w *= mu / j as f64;
            if self.lower && g < 0.125 * anchor {
                (g, dj) = self.direct(j);
                anchor = g;
            }
            let t = w * g;
            *sum += t;
            if remainder_negligible(t, prev, *sum) {
                break;
            }
            prev = t;
        }
    }

    /// Backward sweep j = s−1, …, 0: stable for P, re-anchored for Q.
    fn sweep_backward(&self, sum: &mut f64) {
        let (a, y, mu, s) = (self.a, self.y, self.mu, self.s);
        let (mut w, mut g, mut dj, mut prev, mut anchor) = (1.0, 1.0, self.d_start, 1.0, 1.0);
        let mut j = s;
        while j > 0 && s - j < MAX_TERMS {
            j -= 1;
            let b = a + j as f64;
            dj *= (b + 1.0) / y;
            g -= self.sign * dj;
            w *= (j + 1) as f64 / mu;
            if !self.lower && g < 0.125 * anchor {
                (g, dj) = self.direct(j);
                anchor = g;
            }
            let t = w * g;
            *sum += t;
            if remainder_negligible(t, prev, *sum) {
                break;
            }
            prev = t;
        }
    }
}

/// Stopping rule of a sweep, given the newest term `t`, the one before it and
/// the partial sum. Term ratios only decrease away from the peak, so with
/// `r = t/prev < 1` the unsummed rest is at most `t r / (1 − r)`.
///
/// Monotonicity: the Poisson ratio is `μ/(j+1)`; with `S(b) = Σ_n y^n /
/// ((b+1)…(b+n))`, decreasing in `b`, `P(b−1)/P(b) = 1 + (b/y)/S(b)` increases
/// in `b`; and `Q(b+1)/Q(b) = 1 + y / (b E[(1 + U/y)^{b−1}])`, `U ~ Exp(1)`,
/// decreases in `b`. So the ratio `t_{j+1}/t_j` of either series decreases in
/// `j` (the terms are unimodal) and every later ratio is at most `r`.
fn remainder_negligible(t: f64, prev: f64, sum: f64) -> bool {
    if t.is_nan() || t <= 0.0 {
        // Zero (the terms have underflowed relative to the peak) or NaN.
        return true;
    }
    let r = t / prev;
    r < 1.0 && t * r / (1.0 - r) <= SERIES_TOL * sum
}

/// Brent–Dekker root finder on a bracket `[a, b]` with `f(a)`, `f(b)` of
/// opposite signs (Brent 1973, ch. 4); converges to ~4 ulp of the root.
fn brent(f: impl Fn(f64) -> f64, mut a: f64, mut b: f64, mut fa: f64, mut fb: f64) -> f64 {
    let (mut c, mut fc) = (a, fa);
    let mut d = b - a;
    let mut e = d;
    for _ in 0..300 {
        if (fb > 0.0) == (fc > 0.0) {
            (c, fc) = (a, fa);
            d = b - a;
            e = d;
        }
        if fc.abs() < fb.abs() {
            (a, b, c) = (b, c, b);
            (fa, fb, fc) = (fb, fc, fb);
        }
        let tol = 2.0 * f64::EPSILON * b.abs() + f64::MIN_POSITIVE;
        let m = 0.5 * (c - b);
        if m.abs() <= tol || fb == 0.0 {
            return b;
        }
        if e.abs() >= tol && fa.abs() > fb.abs() {
            // Inverse quadratic interpolation (secant if only two points).
            let s = fb / fa;
            let (mut p, mut q) = if a == c {
                (2.0 * m * s, 1.0 - s)
            } else {
                let (qa, r) = (fa / fc, fb / fc);
                (
                    s * (2.0 * m * qa * (qa - r) - (b - a) * (r - 1.0)),
                    (qa - 1.0) * (r - 1.0) * (s - 1.0),
                )
            };
            if p > 0.0 {
                q = -q;
            }
            p = p.abs();
            if 2.0 * p < (3.0 * m * q - (tol * q).abs()).min((e * q).abs()) {
                e = d;
                d = p / q;
            } else {
                d = m;
                e = m;
            }
        } else {
            d = m;
            e = m;
        }
        (a, fa) = (b, fb);
        b += if d.abs() > tol { d } else { tol.copysign(m) };
        fb = f(b);
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn rel_err(got: f64, want: f64) -> f64 {
        if want == 0.0 {
            got.abs()
        } else {
            ((got - want) / want).abs()
        }
    }

    /// Seed 000, Table 1: T_D for dof 1..=6, to 4 decimals.
    #[rustfmt::skip]
    const SEED000_TABLE1: [(f64, [&str; 6]); 2] = [
        (0.002, ["9.5495", "12.4292", "14.7955", "16.9238", "18.9074", "20.7912"]),
        (1e-5, ["19.5114", "23.0259", "25.9017", "28.4733", "30.8562", "33.1071"]),
    ];

    #[test]
    fn threshold_matches_seed000_table1() {
        for (p_fa, expected) in SEED000_TABLE1 {
            for (dof, want) in (1..=6).zip(expected) {
                let t = threshold(dof, p_fa).unwrap();
                assert_eq!(format!("{t:.4}"), want, "dof {dof}, p_fa {p_fa}");
            }
        }
    }

    /// Central χ² quantiles from mpmath (50 digits, then rounded to f64):
    /// `2 * findroot(lambda y: log(gammainc(dof/2, y, inf, regularized=True)) - log(p), y0)`
    /// with `y0` from 200 bisection steps. `(dof, p_fa, T_D)`.
    #[rustfmt::skip]
    const THRESHOLD_REFERENCE: [(u32, f64, f64); 42] = [
        (1, 0.9, 0.015790774093431225),
        (1, 0.5, 0.4549364231195728),
        (1, 0.002, 9.549535706083244),
        (1, 1e-05, 19.51142096465757),
        (1, 1e-12, 50.844127911818155),
        (1, 1e-30, 132.79989270501423),
        (2, 0.9, 0.2107210313156526),
        (2, 0.5, 1.3862943611198906),
        (2, 0.002, 12.429216196844383),
        (2, 1e-05, 23.025850929940457),
        (2, 1e-12, 55.262042231857095),
        (2, 1e-30, 138.15510557964274),
        (3, 0.9, 0.5843743741551832),
        (3, 0.5, 2.365973884375338),
        (3, 0.002, 14.79551705455239),
        (3, 1e-05, 25.901749745662052),
        (3, 1e-12, 58.919755683202155),
        (3, 1e-30, 142.67798622346095),
        (5, 0.9, 1.610307986962323),
        (5, 0.5, 4.351460191095527),
        (5, 0.002, 18.90737737986124),
        (5, 1e-05, 30.856189940435904),
        (5, 1e-12, 65.23863621336784),
        (5, 1e-30, 150.58968413567666),
        (8, 0.9, 3.4895391256498227),
        (8, 0.5, 7.344121497701792),
        (8, 0.002, 24.352081352360617),
        (8, 1e-05, 37.331593644422206),
        (8, 1e-12, 73.4660190661635),
        (8, 1e-30, 160.9752026765824),
        (12, 0.9, 6.303796059584323),
        (12, 0.5, 11.34032237742414),
        (12, 0.002, 30.956960530151903),
        (12, 1e-05, 45.076146524160144),
        (12, 1e-12, 83.21940615745052),
        (12, 1e-30, 173.3172862038903),
        (30, 0.9, 20.599234614585345),
        (30, 0.5, 29.336031516661585),
        (30, 0.002, 57.16743305991452),
        (30, 1e-05, 75.02343243887015),
        (30, 1e-12, 120.05203472501219),
        (30, 1e-30, 219.60569393387303),
    ];

    #[test]
    fn threshold_matches_mpmath_quantiles_to_2e_15_relative() {
        // Measured worst case: 8.8e-16 (4 ulp). The table is exact to half an ulp
        // (re-checked against mpmath at 50 digits).
        for (dof, p_fa, want) in THRESHOLD_REFERENCE {
            let got = threshold(dof, p_fa).unwrap();
            assert!(
                rel_err(got, want) <= 2e-15,
                "dof {dof} p_fa {p_fa}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn the_closed_forms_equal_the_general_inversion() {
        // dof 1 and 2 invert in closed form, 3..=12 by Newton on the finite sums.
        for p_fa in [
            0.999_999, 0.95, 0.9, 0.7, 0.5, 0.3, 0.1, 1e-3, 1e-7, 1e-12, 1e-50, 1e-200, 1e-300,
        ] {
            for dof in 1..=FINITE_SUM_MAX_DOF + 1 {
                let a = f64::from(dof) / 2.0;
                let general = 2.0
                    * if p_fa < 0.5 {
                        upper_quantile(a, p_fa)
                    } else {
                        lower_quantile(a, 1.0 - p_fa)
                    };
                let got = threshold(dof, p_fa).unwrap();
                assert!(
                    rel_err(got, general) <= 1e-14,
                    "dof {dof} p_fa {p_fa}: {got} vs {general}"
                );
            }
        }
    }

    #[test]
    fn the_finite_sums_equal_the_series_and_continued_fraction() {
        for dof in 1..=FINITE_SUM_MAX_DOF {
            let a = f64::from(dof) / 2.0;
            for y in [
                1e-6, 1e-3, 0.1, 0.5, 1.0, 2.4, 3.0, 7.5, 20.0, 80.0, 300.0, 700.0,
            ] {
                let (q, density) = finite_tails(dof, y).unwrap();
                let g = inc_gamma(a, y);
                // ρ = a d_a(y) / y
                let want_density = g.ln_d.exp() * a / y;
                // The reference comes through `exp(ln Q)`, whose relative error is the
                // absolute error of `ln Q` (≈ ε |ln Q|, 1.6e-13 at y = 700).
                let tol = 1e-14 + 2.0 * f64::EPSILON * g.ln_q.abs();
                assert!(
                    rel_err(q, g.ln_q.exp()) <= tol,
                    "dof {dof} y {y}: Q {q} vs {}",
                    g.ln_q.exp()
                );
                assert!(
                    rel_err(density, want_density) <= 1e-13 + tol,
                    "dof {dof} y {y}: ρ {density} vs {want_density}"
                );
            }
        }
        assert_eq!(finite_tails(3, 700.5), None);
        assert_eq!(finite_tails(3, 0.0), None);
    }

    #[test]
    fn threshold_inverts_the_false_alarm_probability_down_to_subnormal_p_fa() {
        for dof in [1, 2, 3, 7, 12, 40, 1000] {
            for p_fa in [
                0.999_999, 0.9, 0.5, 0.1, 1e-3, 1e-7, 1e-12, 1e-50, 1e-300, 5e-324,
            ] {
                let t = threshold(dof, p_fa).unwrap();
                let back = false_alarm_probability(dof, t).unwrap();
                // 5e-324 has a single bit of precision; elsewhere ask for 1e-13, or
                // |ln p_fa|·ε·2 in the far tail: there d(ln p)/dT ≈ −1/2 and T ≈ 2 |ln p|,
                // so half an ulp of T alone moves p by |ln p|·ε/2 relative, and the
                // survival function's own ln Q carries |ln p|·ε (measured worst case
                // 1.4e-13 at dof 12, p 1e-300, against a bound of 3.1e-13).
                let tol = if p_fa < 1e-307 {
                    0.5
                } else {
                    1e-13_f64.max(2.0 * f64::EPSILON * p_fa.ln().abs())
                };
                assert!(
                    rel_err(back, p_fa) <= tol,
                    "dof {dof} p_fa {p_fa}: T {t} -> {back}"
                );
            }
        }
    }

    #[test]
    fn false_alarm_probability_matches_the_even_dof_closed_form() {
        // For dof = 2n, Q(n, y) = e^{-y} Σ_{k<n} y^k / k!: a sum of positive
        // terms, accurate to a few ulp, and independent of the series above.
        for n in 1..=6_u32 {
            for y in [1e-3, 0.5, 1.0, 3.0, 10.0, 40.0, 150.0, 350.0] {
                let (mut term, mut sum) = (1.0_f64, 1.0_f64);
                for k in 1..n {
                    term *= y / f64::from(k);
                    sum += term;
                }
                let want = (-y).exp() * sum;
                let got = false_alarm_probability(2 * n, 2.0 * y).unwrap();
                assert!(
                    rel_err(got, want) <= 1e-13,
                    "dof {} y {y}: {got} vs {want}",
                    2 * n
                );
            }
        }
    }

    /// Non-central χ² CDF and SF from mpmath, `(dof, λ, x, F(x), 1 − F(x))`,
    /// each evaluated independently at 50 digits and rounded to f64:
    ///
    /// ```python
    /// from mpmath import mp, mpf, gammainc, exp, log, loggamma, sqrt, inf
    /// mp.dps = 50
    /// def ncx2(x, k, lam, upper):
    ///     x, lam = mpf(x), mpf(lam); a, y, mu = mpf(k) / 2, x / 2, lam / 2
    ///     G = (lambda b: gammainc(b, y, inf, regularized=True)) if upper \
    ///         else (lambda b: gammainc(b, 0, y, regularized=True))
    ///     if lam == 0:
    ///         return G(a)
    ///     total, j, peak = mpf(0), 0, max(mu, sqrt(mu * y))
    ///     while True:
    ///         t = exp(-mu + j * log(mu) - loggamma(j + 1)) * G(a + j)
    ///         total += t
    ///         if j > peak + 10 and t <= mpf(10) ** -55 * total:
    ///             return total
    ///         j += 1
    /// ```
    ///
    /// For each (dof, λ), `x` is where F = 1e-30, 1e-8, 0.5 and 1 − F = 1e-8,
    /// 1e-30 (found at low precision, then rounded to 6 digits); the last block
    /// adds extreme tails, subnormal x and larger λ.
    #[rustfmt::skip]
    const NCX2_REFERENCE: &[(u32, f64, f64, f64, f64)] = &[
        (1, 0.0, 1.5708e-60, 1.000001169216815e-30, 1.0),
        (1, 0.0, 1.5708e-16, 1.0000011692168149e-08, 0.9999999899999883),
        (1, 0.0, 0.454938, 0.5000007429245972, 0.4999992570754028),
        (1, 0.0, 32.8413, 0.9999999900002399, 9.999760086628145e-09),
        (1, 0.0, 132.8, 1.0, 9.999459558620698e-31),
        (2, 0.0, 2e-30, 1e-30, 1.0),
        (2, 0.0, 2e-08, 9.999999950000001e-09, 0.9999999900000001),
        (2, 0.0, 1.38635, 0.5000139095265488, 0.49998609047345116),
        (2, 0.0, 36.8414, 0.9999999900001926, 9.999807441377619e-09),
        (2, 0.0, 138.155, 1.0, 1.0000527912147772e-30),
        (3, 0.0, 2.41799e-20, 1.0000012834901149e-30, 1.0),
        (3, 0.0, 1.12233e-05, 9.999958604590042e-09, 0.9999999900000414),
        (3, 0.0, 2.36612, 0.5000274686830222, 0.49997253131697783),
        (3, 0.0, 40.1295, 0.9999999899975639, 1.0002436098505424e-08),
        (3, 0.0, 142.677, 1.0, 1.0004898229839827e-30),
        (12, 0.0, 5.98762e-05, 1.000004069155917e-30, 1.0),
        (12, 0.0, 0.283599, 9.999949992560962e-09, 0.99999999000005),
        (12, 0.0, 11.3404, 0.5000065348123605, 0.49999346518763954),
        (12, 0.0, 61.9342, 0.9999999899998652, 1.000013485675216e-08),
        (12, 0.0, 173.317, 1.0, 1.0001349529825283e-30),
        (1, 0.5, 2.59462e-60, 1.0009291139356282e-30, 1.0),
        (1, 0.5, 2.58981e-16, 1.0000009043292709e-08, 0.999999989999991),
        (1, 0.5, 0.732178, 0.5000003478980279, 0.49999965210197206),
        (1, 0.5, 39.931, 0.9999999899983615, 1.0001638517726573e-08),
        (1, 0.5, 148.136, 1.0, 1.0002094175878541e-30),
        (4, 0.5, 3.20503e-15, 1.0000013597275682e-30, 1.0),
        (4, 0.5, 0.000320518, 1.0000014765015255e-08, 0.9999999899999852),
        (4, 0.5, 3.78713, 0.5000306085629799, 0.4999693914370202),
        (4, 0.5, 47.2576, 0.9999999899999488, 1.0000051211666289e-08),
        (4, 0.5, 157.147, 1.0, 9.997824156683045e-31),
        (5, 0.5, 3.57347e-12, 1.00000122753225e-30, 1.0),
        (5, 0.5, 0.00225537, 1.0000111730988202e-08, 0.9999999899998883),
        (5, 0.5, 4.79442, 0.5000272220985421, 0.4999727779014579),
        (5, 0.5, 49.5617, 0.9999999900000428, 9.99995722650446e-09),
        (5, 0.5, 160.061, 1.0, 1.0009769823310915e-30),
        (12, 0.5, 6.24237e-05, 9.999995741214784e-31, 1.0),
        (12, 0.5, 0.29566, 9.99996598932063e-09, 0.999999990000034),
        (12, 0.5, 11.8147, 0.5000075166012962, 0.49999248339870384),
        (12, 0.5, 64.3594, 0.9999999900000127, 9.999987287873237e-09),
        (12, 0.5, 179.412, 1.0, 9.998175447779173e-31),
        (1, 1.0, 4.27347e-60, 1.0004218080874331e-30, 1.0),
        (1, 1.0, 4.26987e-16, 1.0000003382614321e-08, 0.9999999899999966),
        (1, 1.0, 1.10588, 0.5004757211537598, 0.4995242788462401),
        (1, 1.0, 43.7186, 0.9999999900001594, 9.999840631334388e-09),
        (1, 1.0, 155.352, 1.0, 9.999589654125886e-31),
        (6, 1.0, 4.29335e-10, 1.000000930922797e-30, 1.0),
        (6, 1.0, 0.00925939, 1.0002351141497938e-08, 0.9999999899976488),
        (6, 1.0, 6.26081, 0.5000196133929102, 0.49998038660708977),
        (6, 1.0, 54.5959, 0.9999999899990046, 1.0000995419803804e-08),
        (6, 1.0, 168.882, 1.0, 1.0000727800582868e-30),
        (7, 1.0, 1.24771e-08, 1.000003028055886e-30, 1.0),
        (7, 1.0, 0.0241449, 9.99994859957812e-09, 0.9999999900000514),
        (7, 1.0, 7.26901, 0.5000098915917591, 0.49999010840824093),
        (7, 1.0, 56.6606, 0.9999999900001396, 9.999860391999541e-09),
        (7, 1.0, 171.509, 1.0, 1.0001621751782969e-30),
        (12, 1.0, 6.50797e-05, 1.0000056154376599e-30, 1.0),
        (12, 1.0, 0.308222, 9.999944750620604e-09, 0.9999999900000552),
        (12, 1.0, 12.2921, 0.5000023333842187, 0.4999976666157812),
        (12, 1.0, 66.5526, 0.9999999899998819, 1.000011803436573e-08),
        (12, 1.0, 184.287, 1.0, 9.999387062663908e-31),
        (1, 5.0, 2.33015e-58, 9.99760090726081e-31, 1.0),
        (1, 5.0, 2.33018e-14, 9.997665265148195e-09, 0.9999999900023347),
        (1, 5.0, 4.99996, 0.4999925594744139, 0.5000074405255861),
        (1, 5.0, 61.5922, 0.9999999900000349, 9.99996504503318e-09),
        (1, 5.0, 187.692, 1.0, 1.0002272533228578e-30),
        (8, 5.0, 2.61527e-07, 9.999969648356562e-31, 1.0),
        (8, 5.0, 0.0829639, 1.00015347358038e-08, 0.9999999899984653),
        (8, 5.0, 12.1412, 0.49969017699505786, 0.5003098230049421),
        (8, 5.0, 73.7497, 0.9999999899997466, 1.0000253370476901e-08),
        (8, 5.0, 202.73, 1.0, 1.0004094185210783e-30),
        (9, 5.0, 1.8097e-06, 1.0000035553916922e-30, 1.0),
        (9, 5.0, 0.140921, 9.99996845854757e-09, 0.9999999900000316),
        (9, 5.0, 13.1623, 0.5003912790735535, 0.4996087209264465),
        (9, 5.0, 75.4489, 0.9999999899997623, 1.0000237778728599e-08),
        (9, 5.0, 204.848, 1.0, 9.997998441558084e-31),
        (12, 5.0, 9.08259e-05, 9.999993635222372e-31, 1.0),
        (12, 5.0, 0.429203, 9.999937010054617e-09, 0.999999990000063),
        (12, 5.0, 16.1821, 0.5000005421416285, 0.4999994578583715),
        (12, 5.0, 80.4953, 0.999999989998553, 1.0001447025288534e-08),
        (12, 5.0, 211.152, 1.0, 9.997963478319597e-31),
        (1, 10.0, 3.45807e-56, 9.997341836643848e-31, 1.0),
        (1, 10.0, 3.45991e-12, 1.0000001219338775e-08, 0.9999999899999987),
        (1, 10.0, 10.0, 0.4999999998730186, 0.5000000001269814),
        (1, 10.0, 76.988, 0.9999999900000979, 9.999902142244445e-09),
        (1, 10.0, 213.929, 1.0, 9.998896072463922e-31),
        (10, 10.0, 1.41632e-05, 1.0000076116169046e-30, 1.0),
        (10, 10.0, 0.35592, 1.0003756062794774e-08, 0.999999989996244),
        (10, 10.0, 19.1074, 0.5000008018622144, 0.4999991981377856),
        (10, 10.0, 91.2254, 0.999999989995646, 1.0004354008632303e-08),
        (10, 10.0, 231.388, 1.0, 9.99995796966015e-31),
        (11, 10.0, 4.8801e-05, 1.0000007155803694e-30, 1.0),
        (11, 10.0, 0.489925, 1.000002377800573e-08, 0.9999999899999762),
        (11, 10.0, 20.1151, 0.4999992728068211, 0.5000007271931789),
        (11, 10.0, 92.7831, 0.9999999899943077, 1.0005692224539919e-08),
        (11, 10.0, 233.306, 1.0, 9.998410864942357e-31),
        (12, 10.0, 0.000137773, 9.999897250680374e-31, 1.0),
        (12, 10.0, 0.64481, 9.999993969934273e-09, 0.9999999900000061),
        (12, 10.0, 21.1224, 0.5000040182449875, 0.4999959817550125),
        (12, 10.0, 94.3363, 0.999999989992879, 1.0007121015787442e-08),
        (12, 10.0, 235.219, 1.0, 9.999514223203028e-31),
        (1, 50.0, 8.14412e-39, 1.0000002210296156e-30, 1.0),
        (1, 50.0, 2.12863, 9.995143017891904e-09, 0.999999990004857),
        (1, 50.0, 50.0077, 0.5002172046168788, 0.49978279538312126),
        (1, 50.0, 160.859, 0.9999999899971724, 1.0002827611052751e-08),
        (1, 50.0, 343.55, 1.0, 9.998922008630829e-31),
        (2, 50.0, 1.4401e-19, 1.0000013979967343e-30, 1.0),
        (2, 50.0, 2.55114, 9.996760800859556e-09, 0.9999999900032392),
        (2, 50.0, 51.0177, 0.5004030477942352, 0.4995969522057649),
        (2, 50.0, 162.181, 0.9999999899962534, 1.0003746583515824e-08),
        (2, 50.0, 345.109, 1.0, 1.000035013982663e-30),
        (3, 50.0, 4.185e-13, 9.999998910387733e-31, 1.0),
        (3, 50.0, 2.98423, 9.998499704192332e-09, 0.9999999900015003),
        (3, 50.0, 52.0066, 0.4999996073503132, 0.5000003926496869),
        (3, 50.0, 163.502, 0.9999999899951032, 1.0004896831059055e-08),
        (3, 50.0, 346.667, 1.0, 1.0001701243138036e-30),
        (12, 50.0, 0.00385863, 9.999935489976096e-31, 1.0),
        (12, 50.0, 7.24815, 9.999666791022417e-09, 0.9999999900003332),
        (12, 50.0, 61.0335, 0.5000030764949657, 0.4999969235050343),
        (12, 50.0, 175.358, 0.999999989999136, 1.0000863986377766e-08),
        (12, 50.0, 360.647, 1.0, 1.0003222150739053e-30),
        (1, 100.0, 4.22248e-17, 9.99999463306454e-31, 1.0),
        (1, 100.0, 19.2544, 9.999123491893108e-09, 0.9999999900008765),
        (1, 100.0, 100.0, 0.5, 0.5),
        (1, 100.0, 243.734, 0.9999999899989209, 1.0001079054871832e-08),
        (1, 100.0, 460.704, 1.0, 1.0000957410992838e-30),
        (4, 100.0, 0.000203495, 1.0000005879430872e-30, 1.0),
        (4, 100.0, 21.202, 9.997986599260775e-09, 0.9999999900020135),
        (4, 100.0, 103.005, 0.5000008827514841, 0.4999991172485158),
        (4, 100.0, 247.454, 0.9999999899992021, 1.0000797857008307e-08),
        (4, 100.0, 464.995, 1.0, 1.0001523568350418e-30),
        (5, 100.0, 0.00156207, 9.9993813059968e-31, 1.0),
        (5, 100.0, 21.8548, 9.997581717921345e-09, 0.9999999900024182),
        (5, 100.0, 104.007, 0.5000084023511959, 0.4999915976488041),
        (5, 100.0, 248.693, 0.9999999899988656, 1.0001134414552927e-08),
        (5, 100.0, 466.425, 1.0, 9.999989871012887e-31),
        (12, 100.0, 0.223002, 9.99987629708476e-31, 1.0),
        (12, 100.0, 26.4726, 1.0001698674197971e-08, 0.9999999899983013),
        (12, 100.0, 111.018, 0.5000101801836915, 0.4999898198163085),
        (12, 100.0, 257.356, 0.9999999899975784, 1.0002421585376222e-08),
        (12, 100.0, 476.417, 1.0, 1.0001280212631698e-30),
        (1, 200.0, 7.17228, 1.0000039209155136e-30, 1.0),
        (1, 200.0, 72.7632, 1.0000025298680478e-08, 0.9999999899999747),
        (1, 200.0, 199.985, 0.49978842494898096, 0.500211575051019),
        (1, 200.0, 390.226, 0.9999999900001121, 9.99988792339269e-09),
        (1, 200.0, 655.675, 1.0, 1.0001005767785783e-30),
        (6, 200.0, 9.16373, 9.990928149478353e-31, 1.0),
        (6, 200.0, 76.6182, 1.0006112018576236e-08, 0.999999989993888),
        (6, 200.0, 204.997, 0.4999000904056939, 0.5000999095943062),
        (6, 200.0, 396.109, 0.9999999899994079, 1.0000592080611792e-08),
        (6, 200.0, 662.306, 1.0, 9.999725052709133e-31),
        (7, 200.0, 9.57134, 9.992444073008186e-31, 1.0),
        (7, 200.0, 77.3884, 1.0000123704254402e-08, 0.9999999899998763),
        (7, 200.0, 206.0, 0.49993082895668467, 0.5000691710433153),
        (7, 200.0, 397.286, 0.9999999900005406, 9.999459316241508e-09),
        (7, 200.0, 663.631, 1.0, 1.0000676636187702e-30),
        (12, 200.0, 11.6511, 9.997609116663857e-31, 1.0),
        (12, 200.0, 81.2552, 1.0000873936118778e-08, 0.9999999899991261),
        (12, 200.0, 211.012, 0.5000424775937162, 0.4999575224062837),
        (12, 200.0, 403.164, 0.9999999899994273, 1.0000572701598484e-08),
        (12, 200.0, 670.255, 1.0, 1.0000267934701992e-30),
        // extreme tails and larger λ
        (1, 200.0, 1.13505e-113, 9.999985440105714e-101, 1.0),
        (1, 200.0, 1.13505e-213, 9.999985440105713e-151, 1.0),
        (1, 200.0, 1254.26, 1.0, 1.0011918600650409e-100),
        (1, 200.0, 2620.34, 1.0, 9.990823832924066e-301),
        (4, 1000.0, 408.751, 9.998835360817774e-31, 1.0),
        (4, 1000.0, 2.45829, 1.000002037110867e-200, 1.0),
        (4, 1000.0, 1859.95, 1.0, 1.0014251471851166e-30),
        (4, 1000.0, 3826.86, 1.0, 1.0011867260617184e-200),
        (12, 5000.0, 3786.14, 9.99638881715193e-21, 1.0),
        (12, 5000.0, 6407.37, 1.0, 1.0002759659279234e-20),
        (2, 0.001, 2.00268e-250, 1.0008394551466413e-250, 1.0),
        (2, 0.001, 1151.83, 1.0, 1.000753630401255e-250),
        (7, 50.0, 1849.45, 1.0, 9.983354415722218e-281),
        (9, 300.0, 2.39034, 9.999818471506198e-61, 1.0),
        (9, 300.0, 1147.85, 1.0, 9.988896272373529e-61),
        (1, 0.0, 1e-310, 7.978845608028641e-156, 1.0),
        (1, 3.0, 5e-324, 3.957224298181506e-163, 1.0),
        (2, 0.5, 1e-300, 3.894003915357024e-301, 1.0),
        (3, 20.0, 2e-200, 3.415222328772495e-305, 1.0),
    ];

    #[test]
    fn noncentral_cdf_and_sf_match_mpmath_to_1e_13_relative() {
        // The table is exact to 1 ulp at the f64 x shown (re-checked with the
        // mpmath code above); the measured worst case is 9.1e-14.
        for &(dof, lambda, x, cdf, sf) in NCX2_REFERENCE {
            let got_cdf = noncentral_cdf(x, dof, lambda).unwrap();
            let got_sf = noncentral_sf(x, dof, lambda).unwrap();
            let (e_cdf, e_sf) = (rel_err(got_cdf, cdf), rel_err(got_sf, sf));
            assert!(
                e_cdf <= 1e-13,
                "CDF dof {dof} λ {lambda} x {x}: {got_cdf:e} vs {cdf:e}"
            );
            assert!(
                e_sf <= 1e-13,
                "SF dof {dof} λ {lambda} x {x}: {got_sf:e} vs {sf:e}"
            );
        }
    }

    #[test]
    fn zero_noncentrality_is_the_central_distribution() {
        for dof in [1, 2, 5, 12] {
            for x in [1e-8, 0.3, 4.0, 25.0, 90.0] {
                let central_sf = false_alarm_probability(dof, x).unwrap();
                assert_eq!(noncentral_sf(x, dof, 0.0).unwrap(), central_sf);
                let cdf = noncentral_cdf(x, dof, 0.0).unwrap();
                assert!((cdf + central_sf - 1.0).abs() <= 1e-15);
                // and the series joins it continuously
                let near = noncentral_cdf(x, dof, 1e-12).unwrap();
                assert!(rel_err(near, cdf) <= 1e-11, "dof {dof} x {x}");
            }
        }
    }

    #[test]
    fn cdf_at_zero_is_zero_and_sf_is_one() {
        assert_eq!(noncentral_cdf(0.0, 3, 7.0), Ok(0.0));
        assert_eq!(noncentral_sf(0.0, 3, 7.0), Ok(1.0));
        assert_eq!(noncentral_cdf(0.0, 1, 0.0), Ok(0.0));
    }

    #[test]
    fn missed_detection_is_the_cdf_at_the_threshold() {
        let t = threshold(4, 1e-5).unwrap();
        assert_eq!(missed_detection(4, t, 30.0), noncentral_cdf(t, 4, 30.0));
    }

    /// λ with `F_{χ²(dof, λ)}(T) = P_MD`, from mpmath at 50 digits (the `ncx2`
    /// above, `findroot` on `log(ncx2(T, dof, lam, False)) - log(p_md)` after
    /// 120 bisection steps). `(dof, T, P_MD, λ)`; T and P_MD are the decimals
    /// shown.
    #[rustfmt::skip]
    const NONCENTRALITY_REFERENCE: [(u32, f64, f64, f64); 8] = [
        (1, 9.5495, 0.001, 38.19807141213311),
        (1, 9.5495, 1e-07, 68.71687315213977),
        (1, 19.5114, 0.001, 56.36110500780536),
        (3, 14.7955, 0.001, 45.44746054462154),
        (4, 16.9238, 1e-05, 65.97692424282411),
        (6, 20.7912, 0.5, 15.744005771448716),
        (6, 33.1071, 1e-09, 131.07013212745053),
        (12, 40.0, 0.9, 15.623512240843905),
    ];

    #[test]
    fn noncentrality_for_missed_detection_matches_mpmath() {
        for (dof, t, p_md, want) in NONCENTRALITY_REFERENCE {
            // Measured worst case 3.4e-16.
            let got = noncentrality_for_missed_detection(dof, t, p_md).unwrap();
            assert!(
                rel_err(got, want) <= 1e-15,
                "dof {dof} T {t} P_MD {p_md}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn noncentrality_for_missed_detection_round_trips() {
        for dof in [1, 2, 3, 6, 12, 30] {
            for p_fa in [0.1, 2e-3, 1e-5, 1e-9] {
                let t = threshold(dof, p_fa).unwrap();
                for p_md in [0.5, 1e-3, 1e-7, 1e-12, 1e-100] {
                    let lambda = noncentrality_for_missed_detection(dof, t, p_md).unwrap();
                    let back = missed_detection(dof, t, lambda).unwrap();
                    // Measured worst case 6.8e-14.
                    assert!(
                        rel_err(back, p_md) <= 1e-13,
                        "dof {dof} T {t}: {p_md} -> {back}"
                    );
                }
            }
        }
    }

    #[test]
    fn unreachable_missed_detection_is_an_error_and_the_boundary_is_zero() {
        let t = threshold(2, 1e-3).unwrap();
        let p0 = noncentral_cdf(t, 2, 0.0).unwrap(); // = 1 − 1e-3
        // Already met without any fault: no λ >= 0 gives a larger P_MD.
        assert_eq!(
            noncentrality_for_missed_detection(2, t, 0.9995),
            Err(Chi2Error::Unreachable {
                p_md: 0.9995,
                threshold: t,
                max: MAX_NONCENTRALITY
            })
        );
        assert_eq!(noncentrality_for_missed_detection(2, t, p0), Ok(0.0));
        // Would need λ ≈ 1e12, beyond the supported range.
        assert!(matches!(
            noncentrality_for_missed_detection(2, 1e12, 1e-3),
            Err(Chi2Error::Unreachable { .. })
        ));
    }

    #[test]
    fn every_error_variant_is_returned_for_its_bad_input() {
        use Chi2Error::*;
        assert_eq!(threshold(0, 0.01), Err(InvalidDof(0)));
        assert_eq!(false_alarm_probability(0, 3.0), Err(InvalidDof(0)));
        assert_eq!(noncentral_cdf(1.0, 0, 1.0), Err(InvalidDof(0)));
        assert_eq!(noncentral_sf(1.0, 0, 1.0), Err(InvalidDof(0)));
        assert_eq!(missed_detection(0, 1.0, 1.0), Err(InvalidDof(0)));
        assert_eq!(
            noncentrality_for_missed_detection(0, 1.0, 0.1),
            Err(InvalidDof(0))
        );

        for p in [0.0, 1.0, -0.5, 1.5, f64::INFINITY] {
            assert_eq!(threshold(2, p), Err(InvalidProbability(p)));
            assert_eq!(
                noncentrality_for_missed_detection(2, 10.0, p),
                Err(InvalidProbability(p))
            );
        }
        assert!(matches!(threshold(2, f64::NAN), Err(InvalidProbability(p)) if p.is_nan()));

        for t in [-1.0, f64::INFINITY, f64::NEG_INFINITY] {
            assert_eq!(noncentral_cdf(t, 2, 1.0), Err(InvalidThreshold(t)));
            assert_eq!(noncentral_sf(t, 2, 1.0), Err(InvalidThreshold(t)));
            assert_eq!(false_alarm_probability(2, t), Err(InvalidThreshold(t)));
        }
        // A detection threshold must be strictly positive.
        assert_eq!(false_alarm_probability(2, 0.0), Err(InvalidThreshold(0.0)));
        assert_eq!(missed_detection(2, 0.0, 1.0), Err(InvalidThreshold(0.0)));
        assert_eq!(
            noncentrality_for_missed_detection(2, 0.0, 0.1),
            Err(InvalidThreshold(0.0))
        );
        assert!(matches!(noncentral_cdf(f64::NAN, 2, 1.0), Err(InvalidThreshold(x)) if x.is_nan()));

        for l in [-1e-300, -3.0, f64::INFINITY, 2.0 * MAX_NONCENTRALITY] {
            assert_eq!(noncentral_cdf(1.0, 2, l), Err(InvalidNoncentrality(l)));
            assert_eq!(noncentral_sf(1.0, 2, l), Err(InvalidNoncentrality(l)));
            assert_eq!(missed_detection(2, 1.0, l), Err(InvalidNoncentrality(l)));
        }
        assert!(
            matches!(missed_detection(2, 1.0, f64::NAN), Err(InvalidNoncentrality(l)) if l.is_nan())
        );

        assert!(matches!(
            noncentrality_for_missed_detection(1, 3.0, 0.99),
            Err(Unreachable { .. })
        ));
    }

    /// Probabilities spread evenly over decades.
    fn log_uniform(lo_exp: f64, hi_exp: f64) -> impl Strategy<Value = f64> {
        (lo_exp..hi_exp).prop_map(|e| 10f64.powf(e))
    }

    /// A point of χ²(dof, λ), increasing in `u`: `10^u` times the mean below
    /// it (the lower tail spans decades), `u` standard deviations above it.
    fn point(dof: u32, lambda: f64, u: f64) -> f64 {
        let mean = f64::from(dof) + lambda;
        if u < 0.0 {
            mean * 10f64.powf(u)
        } else {
            mean + u * (2.0 * (mean + lambda)).sqrt()
        }
    }

    proptest! {
        #[test]
        fn thresholds_grow_as_the_false_alarm_probability_shrinks(
            dof in 1u32..=60,
            p1 in log_uniform(-300.0, -1e-3),
            p2 in log_uniform(-300.0, -1e-3),
        ) {
            prop_assume!(p1 != p2);
            let (small, large) = if p1 < p2 { (p1, p2) } else { (p2, p1) };
            prop_assert!(threshold(dof, small).unwrap() > threshold(dof, large).unwrap());
        }

        #[test]
        fn cdf_plus_sf_is_one(dof in 1u32..=60, lambda in 0.0..1500.0, u in -40.0..40.0) {
            let x = point(dof, lambda, u);
            let cdf = noncentral_cdf(x, dof, lambda).unwrap();
            let sf = noncentral_sf(x, dof, lambda).unwrap();
            prop_assert!((cdf + sf - 1.0).abs() <= 1e-12, "x {}: {} + {}", x, cdf, sf);
        }

        #[test]
        fn cdf_increases_in_x(
            dof in 1u32..=60,
            lambda in 0.0..1500.0,
            u in -40.0..40.0,
            du in 0.0..3.0,
        ) {
            let (x1, x2) = (point(dof, lambda, u), point(dof, lambda, u + du));
            let f1 = noncentral_cdf(x1, dof, lambda).unwrap();
            let f2 = noncentral_cdf(x2, dof, lambda).unwrap();
            prop_assert!(f1 <= f2 * (1.0 + 1e-13), "F({}) = {} > F({}) = {}", x1, f1, x2, f2);
            let s1 = noncentral_sf(x1, dof, lambda).unwrap();
            let s2 = noncentral_sf(x2, dof, lambda).unwrap();
            prop_assert!(s2 <= s1 * (1.0 + 1e-13), "SF({}) = {} < SF({}) = {}", x1, s1, x2, s2);
        }

        #[test]
        fn cdf_decreases_in_lambda(
            dof in 1u32..=60,
            l1 in 0.0..1500.0,
            dl in 0.0..20.0,
            u in -40.0..40.0,
        ) {
            let x = point(dof, l1 + 0.5 * dl, u);
            let f1 = noncentral_cdf(x, dof, l1).unwrap();
            let f2 = noncentral_cdf(x, dof, l1 + dl).unwrap();
            prop_assert!(f2 <= f1 * (1.0 + 1e-13), "x {}: {} > {}", x, f2, f1);
        }

        #[test]
        fn inverse_in_lambda_round_trips(
            dof in 1u32..=30,
            p_fa in log_uniform(-12.0, -1.0),
            p_md in log_uniform(-30.0, -0.5),
        ) {
            let t = threshold(dof, p_fa).unwrap();
            let lambda = noncentrality_for_missed_detection(dof, t, p_md).unwrap();
            let back = missed_detection(dof, t, lambda).unwrap();
            prop_assert!(rel_err(back, p_md) <= 1e-9, "{} -> {} -> {}", p_md, lambda, back);
        }

        #[test]
        fn never_panics_and_answers_are_probabilities(
            dof in prop_oneof![0u32..=3, 1u32..=100, any::<u32>()],
            x in prop_oneof![any::<f64>(), 0.0..1e4],
            lambda in prop_oneof![any::<f64>(), 0.0..1e4, 0.0..1e6],
            p in prop_oneof![any::<f64>(), 0.0..1.0],
        ) {
            let probability =
                |r: Result<f64, Chi2Error>| r.map_or(true, |v| (0.0..=1.0).contains(&v));
            prop_assert!(probability(noncentral_cdf(x, dof, lambda)));
            prop_assert!(probability(noncentral_sf(x, dof, lambda)));
            prop_assert!(probability(missed_detection(dof, x, lambda)));
            prop_assert!(probability(false_alarm_probability(dof, x)));
            prop_assert!(threshold(dof, p).map_or(true, |t| t.is_finite() && t >= 0.0));
            let lambda = noncentrality_for_missed_detection(dof, x, p);
            prop_assert!(lambda.map_or(true, |l| (0.0..=MAX_NONCENTRALITY).contains(&l)));
        }
    }
}
