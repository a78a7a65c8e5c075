//! Kernels, with LS-SVMlab's convention (docs/methods.md §M8): RBF
//! `K(x, y) = exp(−‖x − y‖² / σ²)` with parameter `sigma2` (scikit-learn's
//! `gamma` is `1 / sigma2`), and the linear kernel `K(x, y) = xᵀy`.

use serde::{Deserialize, Serialize};

use super::LearnError;

/// A kernel function.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Kernel {
    /// `exp(−‖x − y‖² / sigma2)`.
    Rbf {
        /// Width σ² (> 0), in squared input units (standardised units by default).
        sigma2: f64,
    },
    /// `xᵀy`.
    Linear,
}

/// The kernel family a `params` body names (`"kernel"`), shared by `lssvm` and `svm`
/// (`lw-lssvm` and `ocsvm` are RBF only). Its width comes from the params' `sigma2`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum KernelKind {
    /// `exp(−‖x − y‖² / sigma2)` (the default).
    #[default]
    Rbf,
    /// `xᵀy` (no width).
    Linear,
}

impl KernelKind {
    /// The kernel of this family with RBF width `sigma2` (ignored by the linear kernel).
    pub fn with_width(self, sigma2: f64) -> Kernel {
        match self {
            KernelKind::Rbf => Kernel::Rbf { sigma2 },
            KernelKind::Linear => Kernel::Linear,
        }
    }
}

impl Kernel {
    /// Checks the parameters; `field` prefixes the error path (e.g. `sigma2`).
    pub fn check(&self) -> Result<(), LearnError> {
        match *self {
            Kernel::Rbf { sigma2 } if !(sigma2.is_finite() && sigma2 > 0.0) => Err(
                LearnError::params("sigma2", "must be a finite number greater than 0"),
            ),
            _ => Ok(()),
        }
    }

    /// `K(a, b)`. `a` and `b` have the same length.
    #[inline]
    pub fn eval(&self, a: &[f64], b: &[f64]) -> f64 {
        debug_assert_eq!(a.len(), b.len());
        match *self {
            Kernel::Rbf { sigma2 } => {
                let d2: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
                (-d2 / sigma2).exp()
            }
            Kernel::Linear => a.iter().zip(b).map(|(x, y)| x * y).sum(),
        }
    }

    /// `K(a, b)` from the squared distance and dot product, when the caller has them
    /// (SMO's cached row norms).
    #[inline]
    pub fn eval_parts(&self, dist2: f64, dot: f64) -> f64 {
        match *self {
            Kernel::Rbf { sigma2 } => (-dist2 / sigma2).exp(),
            Kernel::Linear => dot,
        }
    }
}

/// `eˣ` for `x ≤ 0` (the RBF kernel's range), branch-free so loops over it vectorise:
/// `x = k·ln2 + r` with `|r| ≤ ln2/2`, `eʳ` by its degree-13 Taylor polynomial
/// (truncation `< 5e-18` relative), times `2ᵏ` built from the exponent bits. Within a
/// few ulp of `f64::exp`. Shared by every kernel-matrix loop (LS-SVM
/// systems, the online window, SMO's kernel rows); arguments below −700 give `≈ 1e-304` instead of less.
#[inline(always)]
pub fn exp_nonpos(x: f64) -> f64 {
    const LOG2E: f64 = std::f64::consts::LOG2_E;
    // fdlibm's split of ln 2: the high part has trailing zero bits so k·LN2_HI is exact.
    const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
    const SHIFT: f64 = 6_755_399_441_055_744.0; // 1.5·2⁵²: adding it rounds to an integer
    let x = x.clamp(-700.0, 0.0);
    let kf = (x * LOG2E + SHIFT) - SHIFT;
    let r = (x - kf * LN2_HI) - kf * LN2_LO;
    // Horner on 1/i! coefficients, highest first.
    let mut p = 1.0 / 6_227_020_800.0;
    for c in [
        1.0 / 479_001_600.0,
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ] {
        p = p * r + c;
    }
    let scale = f64::from_bits(((kf as i64 + 1023) as u64) << 52);
    p * scale
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn rbf_uses_the_ls_svmlab_width_convention() {
        let k = Kernel::Rbf { sigma2: 2.0 };
        // ‖(1,2) − (2,4)‖² = 5, so K = exp(−5/2).
        assert_relative_eq!(k.eval(&[1.0, 2.0], &[2.0, 4.0]), (-2.5f64).exp());
        assert_eq!(k.eval(&[1.0, 2.0], &[1.0, 2.0]), 1.0);
    }

    #[test]
    fn linear_is_the_dot_product() {
        assert_eq!(Kernel::Linear.eval(&[1.0, 2.0], &[3.0, -4.0]), -5.0);
    }

    #[test]
    fn non_positive_width_is_refused() {
        assert!(Kernel::Rbf { sigma2: 0.0 }.check().is_err());
        assert!(Kernel::Rbf { sigma2: f64::NAN }.check().is_err());
        assert!(Kernel::Rbf { sigma2: 1e-3 }.check().is_ok());
    }

    #[test]
    fn fast_exp_agrees_with_the_library_exp_over_the_rbf_range() {
        let mut worst = 0.0f64;
        for i in 0..100_000 {
            let x = -(i as f64) * 7.3e-4 - 1e-9 * (i % 7) as f64;
            let (a, b) = (exp_nonpos(x), x.exp());
            worst = worst.max((a - b).abs() / b);
        }
        assert!(worst < 4e-16, "worst relative error {worst:e}");
        assert_eq!(exp_nonpos(0.0), 1.0);
        assert!(exp_nonpos(-1e6) < 1e-300);
    }
}
