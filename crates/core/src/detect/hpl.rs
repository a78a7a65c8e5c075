//! Horizontal protection level (docs/methods.md §M7, seed 000 §2.3): sits beside the χ² tests
//! in the detector layer. The federated monitor hands it the fused covariance and, per
//! aid, the horizontal rows of the gain and the innovation covariance its test used; the
//! HPL is then compared with the alert limit (HAL) as a test of its own.
//!
//! `HPL = sqrt(HPL₁² + HPL₂²)` (seed 000 eq. 19):
//! - `HPL₁ = k_md σ_h` (eq. 20). `σ_h` is the square root of the **largest eigenvalue** of
//!   the 2 × 2 horizontal (east, north) block of `P`: the semi-major axis of the error
//!   ellipse, so the bound holds along every horizontal direction (the trace form
//!   `sqrt(P_ee + P_nn)` would be up to √2 larger for a circular ellipse, and too small
//!   for none; the eigenvalue form is the tight conservative one). `k_md` is the
//!   **two-sided** normal quantile `Φ⁻¹(1 − P_MD/2)`: the error along that axis leaves
//!   `±HPL₁` with probability `P_MD` (3.2905 for the default `P_MD = 1e-3`).
//! - `HPL₂ = max_i slope_i sqrt(λ_det)` (eq. 21) with `slope_i = ‖K_h e_i‖ / sqrt((S⁻¹)_ii)`:
//!   a bias `b` on measurement component `i` moves the horizontal solution by `‖K_h e_i‖ b`
//!   and the test statistic's non-centrality by `b² (S⁻¹)_ii`, so the largest horizontal
//!   error that still escapes detection with probability `P_MD` is
//!   `slope_i sqrt(λ_det)`, where `λ_det` is the non-centrality at which
//!   `F_{χ²(dof, λ)}(T_D) = P_MD` (docs/methods.md §M1). `λ_det` depends only on `(dof, T_D, P_MD)`;
//!   [`DetectionNoncentrality`] caches it.

use nalgebra::{Matrix2, SMatrix, SVector};
use statrs::distribution::{ContinuousCDF, Normal};

use super::chi2::{self, Chi2Error};

/// Most `(dof, T_D)` pairs a [`DetectionNoncentrality`] keeps.
const MAX_CACHED: usize = 32;

/// Default missed-detection requirement (docs/methods.md §M7).
pub const DEFAULT_P_MD: f64 = 1e-3;

/// Why a protection level could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HplError {
    /// `P_MD` outside (0, 1).
    #[error("p_md must be in (0, 1), got {0}")]
    InvalidPMd(f64),
    /// The innovation covariance has no Cholesky factor.
    #[error("innovation covariance S is not positive definite")]
    NotPositiveDefinite,
    /// The χ² machinery refused the (dof, threshold, P_MD) triple.
    #[error(transparent)]
    Chi2(#[from] Chi2Error),
}

/// `k_md = Φ⁻¹(1 − P_MD/2)`, the two-sided standard normal quantile of the missed-detection
/// requirement.
pub fn k_md(p_md: f64) -> Result<f64, HplError> {
    if !(p_md > 0.0 && p_md < 1.0) {
        return Err(HplError::InvalidPMd(p_md));
    }
    Ok(Normal::standard().inverse_cdf(1.0 - p_md / 2.0))
}

/// `σ_h = sqrt(λ_max)` of the symmetric 2 × 2 horizontal covariance block
/// `[[a, b], [b, d]]`: `λ_max = (a + d)/2 + sqrt(((a − d)/2)² + b²)`.
pub fn sigma_h(p_h: &Matrix2<f64>) -> f64 {
    let (a, d) = (p_h[(0, 0)], p_h[(1, 1)]);
    let b = 0.5 * (p_h[(0, 1)] + p_h[(1, 0)]);
    let half = 0.5 * (a - d);
    let lambda_max = 0.5 * (a + d) + (half * half + b * b).sqrt();
    lambda_max.max(0.0).sqrt()
}

/// `max_i ‖K_h e_i‖ / sqrt((S⁻¹)_ii)` over the `M` components of one measurement: the
/// horizontal error per unit of `sqrt(λ)` of the worst-observable bias (metres).
pub fn slope_max<const M: usize>(
    k_h: &SMatrix<f64, 2, M>,
    s: &SMatrix<f64, M, M>,
) -> Result<f64, HplError> {
    let chol = s.cholesky().ok_or(HplError::NotPositiveDefinite)?;
    slope_max_with(k_h, &chol.inverse().diagonal())
}

/// [`slope_max`] given the diagonal of `S⁻¹` (for a caller that already factored `S`).
pub fn slope_max_with<const M: usize>(
    k_h: &SMatrix<f64, 2, M>,
    s_inv_diagonal: &SVector<f64, M>,
) -> Result<f64, HplError> {
    let mut worst = 0.0_f64;
    for i in 0..M {
        let d = s_inv_diagonal[i];
        if d <= 0.0 || !d.is_finite() {
            return Err(HplError::NotPositiveDefinite);
        }
        worst = worst.max(k_h.column(i).norm() / d.sqrt());
    }
    Ok(worst)
}

/// `sqrt(HPL₁² + HPL₂²)` (seed 000 eq. 19).
pub fn combine(hpl1: f64, hpl2: f64) -> f64 {
    hpl1.hypot(hpl2)
}

/// `λ_det(dof, T_D)` at one `P_MD`, computed once per `(dof, T_D)` pair and then reused
/// (a monitor has a handful of pairs; thresholds change only on a live spec change).
#[derive(Debug, Clone, PartialEq)]
pub struct DetectionNoncentrality {
    p_md: f64,
    entries: Vec<(u32, f64, f64)>,
}

impl DetectionNoncentrality {
    /// An empty cache for missed-detection probability `p_md`.
    pub fn new(p_md: f64) -> Result<Self, HplError> {
        if !(p_md > 0.0 && p_md < 1.0) {
            return Err(HplError::InvalidPMd(p_md));
        }
        Ok(DetectionNoncentrality {
            p_md,
            entries: Vec::new(),
        })
    }

    /// The missed-detection probability.
    pub fn p_md(&self) -> f64 {
        self.p_md
    }

    /// The cached value for `(dof, threshold)`, if computed before.
    pub fn cached(&self, dof: u32, threshold: f64) -> Option<f64> {
        self.entries
            .iter()
            .find(|&&(d, t, _)| d == dof && t == threshold)
            .map(|&(_, _, l)| l)
    }

    /// `λ_det` for `(dof, threshold)`: from the cache, or computed with
    /// [`chi2::noncentrality_for_missed_detection`] and remembered.
    pub fn get(&mut self, dof: u32, threshold: f64) -> Result<f64, HplError> {
        if let Some(l) = self.cached(dof, threshold) {
            return Ok(l);
        }
        let l = chi2::noncentrality_for_missed_detection(dof, threshold, self.p_md)?;
        // Live threshold changes add pairs; keep the cache small (a monitor has a handful).
        if self.entries.len() >= MAX_CACHED {
            self.entries.clear();
        }
        self.entries.push((dof, threshold, l));
        Ok(l)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::{Matrix3, SMatrix};

    #[test]
    fn k_md_is_the_two_sided_normal_quantile() {
        // Φ⁻¹(0.9995) = √2 erfinv(0.999) = 3.290526731491895 (mpmath 1.3, 30 digits).
        assert_relative_eq!(
            k_md(1e-3).unwrap(),
            3.290_526_731_491_895,
            max_relative = 1e-9
        );
        // Φ⁻¹(0.975) = 1.959963984540054.
        assert_relative_eq!(
            k_md(0.05).unwrap(),
            1.959_963_984_540_054,
            max_relative = 1e-9
        );
        assert_eq!(k_md(0.0), Err(HplError::InvalidPMd(0.0)));
    }

    #[test]
    fn sigma_h_is_the_semi_major_axis() {
        // [[4, 0], [0, 1]] → 2; a rotated ellipse [[5, 2], [2, 2]] has eigenvalues 6 and 1.
        assert_relative_eq!(sigma_h(&Matrix2::new(4.0, 0.0, 0.0, 1.0)), 2.0);
        assert_relative_eq!(
            sigma_h(&Matrix2::new(5.0, 2.0, 2.0, 2.0)),
            6f64.sqrt(),
            max_relative = 1e-15
        );
        // A circle of variance 9: σ_h = 3 (the trace form would give √18).
        assert_relative_eq!(sigma_h(&Matrix2::new(9.0, 0.0, 0.0, 9.0)), 3.0);
    }

    #[test]
    fn slope_of_a_diagonal_case_is_gain_times_sigma() {
        // K_h = [[0.5, 0, 0], [0, 0.2, 0]], S = diag(4, 9, 1): (S⁻¹)_ii = 1/4, 1/9, 1;
        // slopes 0.5·2 = 1, 0.2·3 = 0.6, 0 → max 1.
        let k_h = SMatrix::<f64, 2, 3>::new(0.5, 0.0, 0.0, 0.0, 0.2, 0.0);
        let s = Matrix3::from_diagonal(&nalgebra::Vector3::new(4.0, 9.0, 1.0));
        assert_relative_eq!(slope_max(&k_h, &s).unwrap(), 1.0, max_relative = 1e-15);
    }

    #[test]
    fn slope_with_correlated_innovations_uses_the_inverse_diagonal() {
        // S = [[2, 1], [1, 2]] → S⁻¹ = [[2, −1], [−1, 2]]/3, (S⁻¹)_ii = 2/3.
        // K_h = [[3, 0], [4, 1]]: ‖K_h e₁‖ = 5, ‖K_h e₂‖ = 1 → slope max 5/sqrt(2/3).
        let k_h = Matrix2::new(3.0, 0.0, 4.0, 1.0);
        let s = Matrix2::new(2.0, 1.0, 1.0, 2.0);
        assert_relative_eq!(
            slope_max(&k_h, &s).unwrap(),
            5.0 / (2.0f64 / 3.0).sqrt(),
            max_relative = 1e-14
        );
        let bad = Matrix2::new(1.0, 2.0, 2.0, 1.0);
        assert_eq!(slope_max(&k_h, &bad), Err(HplError::NotPositiveDefinite));
    }

    #[test]
    fn hand_computed_protection_level() {
        // P_h = diag(4, 1) m² → σ_h = 2 m, HPL₁ = 3.2905·2 = 6.5811 m.
        // One 2-dim aid with slope 1 m at T_D = 13.8155 (χ²(2), p_fa 1e-3) and P_MD 1e-3:
        // λ_det = 44.993802188406 (mpmath 1.3, 30 digits: findroot on the Poisson-weighted
        // series Σ_j e^{−λ/2} (λ/2)^j / j! · P(1 + j, T_D/2) − 1e-3), so HPL₂ = 6.7077 m and
        // HPL = sqrt(6.5811² + 44.9938) = 9.397024362587 m.
        let hpl1 = k_md(1e-3).unwrap() * sigma_h(&Matrix2::new(4.0, 0.0, 0.0, 1.0));
        assert_relative_eq!(hpl1, 6.581_053_462_983_79, max_relative = 1e-9);
        let mut cache = DetectionNoncentrality::new(1e-3).unwrap();
        let t_d = chi2::threshold(2, 1e-3).unwrap();
        let l = cache.get(2, t_d).unwrap();
        assert_relative_eq!(
            chi2::missed_detection(2, t_d, l).unwrap(),
            1e-3,
            max_relative = 1e-9
        );
        assert_relative_eq!(l, 44.993_802_188_406, max_relative = 1e-9);
        assert_eq!(cache.cached(2, t_d), Some(l));
        let hpl = combine(hpl1, 1.0 * l.sqrt());
        assert_relative_eq!(hpl, (hpl1 * hpl1 + l).sqrt(), max_relative = 1e-15);
        assert_relative_eq!(hpl, 9.397_024_362_587, max_relative = 1e-9);
    }
}
