//! Kernels, with LS-SVMlab's convention (DESIGN §3.5): RBF
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
}
