//! Predictive variance of the LS-SVM family (docs/methods.md §M9a), beside `lssvm_solve`:
//! the LS-SVM read as a Gaussian process with an unregularised bias (Van Gestel et al.
//! 2002; Suykens et al. 2002, ch. 4). With `H = Ω + I/γ` over the training inputs,
//! `k_x` the kernel column of a query `x`, `η = H⁻¹1` and `c = 1ᵀη`, the model term is
//!
//! `m(x) = K(x, x) − k_xᵀ H⁻¹ k_x + (1 − ηᵀk_x)² / c`,
//!
//! the last term being the bias's contribution (a flat prior on `b`, which is what the
//! LS-SVM's unpenalised `b` and its block elimination in `two_solve` amount to). The
//! prediction's variance in original units is `σ_e² (1 + γ m(x))`: the weight prior's
//! variance is `σ_e²·γ` because γ is the ratio of the prior precision of the weights to
//! the noise precision. `m(x)` is dimensionless (kernel units), so standardised training
//! units need no conversion. Pure maths: no state beyond the factor.

use nalgebra::DMatrix;

use super::lssvm_solve as solve;
use super::{Kernel, LearnError};

/// The Cholesky factor of `H` over a training set and `w = L⁻¹1`, answering the model
/// term of any query in O(N²) (one forward substitution).
#[derive(Debug, Clone, PartialEq)]
pub struct ModelTerm {
    /// Training inputs, row-major, in the units the kernel sees.
    rows: Vec<f64>,
    /// Input dimension.
    dim: usize,
    /// The kernel the model was fitted with.
    kernel: Kernel,
    /// `L` with `L Lᵀ = Ω + I/γ`, lower triangle.
    l: DMatrix<f64>,
    /// `w = L⁻¹1`, so `ηᵀk = wᵀ(L⁻¹k)` and `c = ‖w‖²`.
    w: Vec<f64>,
    /// `c = 1ᵀH⁻¹1`.
    c: f64,
}

impl ModelTerm {
    /// Factorises `Ω + I/γ` over `rows` (`dim` values each): O(N³), once per model.
    pub fn new(rows: Vec<f64>, dim: usize, kernel: Kernel, gamma: f64) -> Result<Self, LearnError> {
        let mut l = solve::regularised_kernel(&rows, dim, &kernel, gamma);
        solve::cholesky(&mut l)?;
        let mut w = vec![1.0; l.nrows()];
        solve::forward_solve(&l, &mut w);
        let c = solve::dot(&w, &w);
        Ok(ModelTerm {
            rows,
            dim,
            kernel,
            l,
            w,
            c,
        })
    }

    /// The factor `L` (`L Lᵀ = Ω + I/γ`), for a caller that also solves for `(α, b)`.
    pub(crate) fn factor(&self) -> &DMatrix<f64> {
        &self.l
    }

    /// The training inputs it was built on.
    pub(crate) fn rows(&self) -> &[f64] {
        &self.rows
    }

    /// `m(z)` for a query `z` in the training units (module doc).
    pub fn at(&self, z: &[f64]) -> f64 {
        let mut v: Vec<f64> = self
            .rows
            .chunks_exact(self.dim)
            .map(|xi| self.kernel.eval(xi, z))
            .collect();
        solve::forward_solve(&self.l, &mut v);
        let a = solve::dot(&self.w, &v);
        let kxx = self.kernel.eval(z, z);
        (kxx - solve::dot(&v, &v) + (1.0 - a) * (1.0 - a) / self.c).max(0.0)
    }
}

/// The prediction's variance `σ_e² (1 + γ m)` in the units of `noise2` (module doc).
pub fn predictive_variance(noise2: f64, gamma: f64, model_term: f64) -> f64 {
    noise2 * (1.0 + gamma * model_term)
}

/// A robust noise variance from residuals: `(1.4826 · MAD)²`, the normal-consistent
/// median absolute deviation about the median (Hampel 1974), so a few faulty residuals
/// do not inflate it. `None` for fewer than two residuals.
pub fn robust_noise_variance(residuals: &[f64]) -> Option<f64> {
    if residuals.len() < 2 {
        return None;
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        let n = v.len();
        if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        }
    };
    let mut r = residuals.to_vec();
    let mid = median(&mut r);
    let mut dev: Vec<f64> = residuals.iter().map(|v| (v - mid).abs()).collect();
    Some((1.4826 * median(&mut dev)).powi(2))
}

/// The reference the predictors' variances are tested against: the GP posterior
/// variance with a flat prior on the bias, by one dense LU solve of the bordered
/// system `A = [[0, 1ᵀ], [1, Ω + I/γ]]`: `m(x) = K(x, x) − vᵀ A⁻¹ v` with `v = [1; k_x]`
/// (Rasmussen & Williams 2006, eq. 2.42, with the basis `h(x) = 1`). Independent of the
/// Cholesky path above.
#[cfg(test)]
pub(crate) fn bordered_reference(
    rows: &[f64],
    dim: usize,
    kernel: Kernel,
    gamma: f64,
    z: &[f64],
) -> f64 {
    let xs: Vec<&[f64]> = rows.chunks_exact(dim).collect();
    let n = xs.len();
    let a = DMatrix::from_fn(n + 1, n + 1, |i, j| match (i, j) {
        (0, 0) => 0.0,
        (0, _) | (_, 0) => 1.0,
        _ => kernel.eval(xs[i - 1], xs[j - 1]) + if i == j { 1.0 / gamma } else { 0.0 },
    });
    let v = nalgebra::DVector::from_fn(n + 1, |i, _| {
        if i == 0 {
            1.0
        } else {
            kernel.eval(xs[i - 1], z)
        }
    });
    let sol = a.lu().solve(&v).expect("bordered system is regular");
    kernel.eval(z, z) - v.dot(&sol)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng, rngs::StdRng};

    #[test]
    fn the_model_term_equals_the_bordered_gp_posterior() {
        let mut rng = StdRng::seed_from_u64(37);
        let (n, dim) = (60, 3);
        let rows: Vec<f64> = (0..n * dim)
            .map(|_| rng.random::<f64>() * 4.0 - 2.0)
            .collect();
        for (kernel, gamma) in [
            (Kernel::Rbf { sigma2: 1.5 }, 30.0),
            (Kernel::Rbf { sigma2: 0.3 }, 1000.0),
            (Kernel::Linear, 5.0),
        ] {
            let term = ModelTerm::new(rows.clone(), dim, kernel, gamma).unwrap();
            for q in 0..20 {
                // Queries on training points, near them and far out.
                let z: Vec<f64> = if q < 5 {
                    rows[q * dim..(q + 1) * dim].to_vec()
                } else {
                    (0..dim)
                        .map(|_| rng.random::<f64>() * 3.0 * q as f64 / 5.0)
                        .collect()
                };
                let reference = bordered_reference(&rows, dim, kernel, gamma, &z);
                let got = term.at(&z);
                assert!(
                    (got - reference).abs() <= 1e-9 * reference.abs(),
                    "{kernel:?} γ {gamma} query {q}: {got:e} vs {reference:e}"
                );
            }
        }
    }

    #[test]
    fn far_from_the_data_the_rbf_term_is_the_prior_plus_the_bias_uncertainty() {
        // k_x = 0: m = K(x, x) + 1/c with c = 1ᵀH⁻¹1.
        let rows = [0.0, 0.5, 1.0];
        let kernel = Kernel::Rbf { sigma2: 0.1 };
        let term = ModelTerm::new(rows.to_vec(), 1, kernel, 10.0).unwrap();
        let h = DMatrix::from_fn(3, 3, |i, j| {
            kernel.eval(&[rows[i]], &[rows[j]]) + if i == j { 0.1 } else { 0.0 }
        });
        let c = h.try_inverse().unwrap().sum();
        let m = term.at(&[1e3]);
        assert!((m - (1.0 + 1.0 / c)).abs() < 1e-12 * m);
        assert_eq!(predictive_variance(2.0, 10.0, 0.5), 12.0);
    }

    #[test]
    fn the_robust_noise_ignores_a_few_outliers() {
        // −1, 0, 1 in equal numbers: median 0, MAD 1; ten huge values leave both.
        let mut r: Vec<f64> = (0..201).map(|i| (i % 3) as f64 - 1.0).collect();
        assert!((robust_noise_variance(&r).unwrap() - 1.4826f64.powi(2)).abs() < 1e-12);
        r.extend([1e6; 10]);
        assert!((robust_noise_variance(&r).unwrap() - 1.4826f64.powi(2)).abs() < 1e-12);
        assert_eq!(robust_noise_variance(&[1.0]), None);
    }
}
