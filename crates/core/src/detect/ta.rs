//! The T_a statistic of seed 000 eqs. 14–16, made precise in docs/methods.md §M14: a
//! variance-weighted mean of the last `n` prediction residuals of a channel, tested
//! against χ²(dim). Sits between a predictor (the `channel` monitor's LS-SVM, which
//! yields the residuals `r_k = y_k − ŷ_k`) and the decision policy.
//!
//! - **Variance** (eq. 16): the successive-difference estimate
//!   `V_k = (1 − 1/(k−1)) V_{k−1} + (r_k − r_{k−1})(r_k − r_{k−1})ᵀ / (2(k−1))`,
//!   i.e. the running mean of `d dᵀ / 2` over the differences seen so far (a slow ramp
//!   adds only its squared rate to it, unlike a plain variance). `k − 1` counts the
//!   differences actually used: V is **frozen** while the channel is not healthy (the
//!   caller says so in [`TaStatistic::commit`]), and a difference is only formed
//!   between two healthy residuals, so a fault can neither inflate V directly nor
//!   through the jump back to normal.
//! - **Statistic** (eqs. 14–15): over the last `n` residuals,
//!   `V_a = (Σ V_j⁻¹)⁻¹`, `r_a = V_a Σ V_j⁻¹ r_j`, `T_a = r_aᵀ V_a⁻¹ r_a`,
//!   which is `sᵀ V_a s` with `s = Σ V_j⁻¹ r_j`, computed by Cholesky of `Σ V_j⁻¹`.
//!   With white residuals of variance V it is `n · r̄ᵀ V⁻¹ r̄ ~ χ²(dim)`.
//! - **Which V weighs r_j**: the variance known *before* r_j arrived (`V_{j−1}`), as a
//!   Kalman innovation test uses the prior S: this keeps r_j out of its own weight, so a
//!   fault's first residual is judged against the healthy variance. The paper's
//!   indexing (V_k beside r_k) would let the first faulty residual raise its own V.
//! - **Warm-up**: the statistic is `None` until V has been estimated from at least
//!   `min_differences` differences and the window holds `n` residuals weighed by it.
//!
//! Default `n` (seed 000): [`DEFAULT_N`] = 10. The paper does not state its window. A
//! window of `n` shrinks the detectable mean shift by √n, but a fault stays in the window
//! for `n` epochs after it ends: the time in false alarm after the fault grows with n.
//! On seed 000's `ads-gnss` channel (≈ 2.3 m residual noise, p_fa = 0.002) n = 10 flags
//! the paper's 1 m/s ramp after 6 s on average (10 s at most over 200 runs) and leaves
//! a mean tail of ≈ 10 s after the fault, against the ≈ 20 s the paper reports for its
//! plain LS-SVM (`navguard experiment seed000`).

use std::collections::VecDeque;

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Seed 000's window: residuals summed into T_a (see the module doc for the choice).
pub const DEFAULT_N: usize = 10;

/// Default number of successive differences V must have seen before T_a is reported.
pub const DEFAULT_MIN_DIFFERENCES: usize = 10;

/// Why a residual could not be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TaError {
    /// The residual does not have the statistic's dimension.
    #[error("residual has {got} components, the statistic expects {want}")]
    Dimension {
        /// Components received.
        got: usize,
        /// Components expected.
        want: usize,
    },
    /// A component is NaN or infinite.
    #[error("residual has a non-finite component")]
    NonFinite,
    /// V (or Σ V_j⁻¹) has no Cholesky factor: the channel's residuals have no spread in
    /// some direction, so the statistic is undefined.
    #[error("residual variance V is singular (Cholesky failed)")]
    Singular,
}

/// Parameters of T_a.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TaParams {
    /// Residual dimension (1 for a scalar channel).
    pub dim: usize,
    /// Residuals in the window (≥ 1).
    pub n: usize,
    /// Successive differences V needs before the statistic is reported (≥ 1).
    pub min_differences: usize,
}

impl TaParams {
    /// Seed 000's defaults for a residual of `dim` components.
    pub fn new(dim: usize) -> Self {
        TaParams {
            dim,
            n: DEFAULT_N,
            min_differences: DEFAULT_MIN_DIFFERENCES.max(dim + 1),
        }
    }
}

/// One window entry: `V_j⁻¹` and `V_j⁻¹ r_j`, or only `r_j` during warm-up.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Entry {
    weighted: Option<(DMatrix<f64>, DVector<f64>)>,
}

/// The running T_a of one channel (serde: a monitor checkpoint saves it whole, parameters
/// included, and [`TaStatistic::restored`] checks it).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TaStatistic {
    params: TaParams,
    /// V over the differences used so far (zero before the first).
    v: DMatrix<f64>,
    /// V⁻¹, once V is past warm-up and positive definite.
    v_inv: Option<DMatrix<f64>>,
    /// Differences used (k − 1 of eq. 16).
    differences: usize,
    /// The previous residual, if it was healthy (a difference needs two healthy ones).
    last_healthy: Option<DVector<f64>>,
    window: VecDeque<Entry>,
}

impl TaStatistic {
    /// A fresh statistic. `n`, `dim` and `min_differences` must be ≥ 1 (the channel
    /// monitor validates them first; zero values are raised to 1 here).
    pub fn new(params: TaParams) -> Self {
        let params = TaParams {
            dim: params.dim.max(1),
            n: params.n.max(1),
            min_differences: params.min_differences.max(1),
        };
        TaStatistic {
            v: DMatrix::zeros(params.dim, params.dim),
            v_inv: None,
            differences: 0,
            last_healthy: None,
            window: VecDeque::with_capacity(params.n),
            params,
        }
    }

    /// The parameters.
    pub fn params(&self) -> TaParams {
        self.params
    }

    /// The current residual variance V (zero before the first difference).
    pub fn variance(&self) -> &DMatrix<f64> {
        &self.v
    }

    /// Successive differences V has used.
    pub fn differences(&self) -> usize {
        self.differences
    }

    /// Back to the state of [`TaStatistic::new`].
    pub fn reset(&mut self) {
        *self = TaStatistic::new(self.params);
    }

    /// `saved` (read from a checkpoint) as the running state of this statistic: the same
    /// parameters, every matrix and vector of its dimension, no more than `n` residuals;
    /// with the capacity [`TaStatistic::new`] reserves. The reason otherwise.
    pub fn restored(&self, mut saved: TaStatistic) -> Result<TaStatistic, String> {
        let p = self.params;
        if saved.params != p {
            return Err(format!(
                "T_a over {} residuals in {} dimensions, the channel's is over {} in {}",
                saved.params.n, saved.params.dim, p.n, p.dim
            ));
        }
        let d = p.dim;
        let square = |m: &DMatrix<f64>| m.shape() == (d, d);
        let fits = square(&saved.v)
            && saved.v_inv.as_ref().is_none_or(square)
            && saved.last_healthy.as_ref().is_none_or(|r| r.len() == d)
            && saved.window.len() <= p.n
            && saved.window.iter().all(|e| {
                e.weighted
                    .as_ref()
                    .is_none_or(|(vi, vir)| square(vi) && vir.len() == d)
            });
        if !fits {
            return Err("T_a state does not fit its parameters".into());
        }
        saved.window.reserve(p.n.saturating_sub(saved.window.len()));
        Ok(saved)
    }

    fn check(&self, r: &[f64]) -> Result<DVector<f64>, TaError> {
        if r.len() != self.params.dim {
            return Err(TaError::Dimension {
                got: r.len(),
                want: self.params.dim,
            });
        }
        if r.iter().any(|v| !v.is_finite()) {
            return Err(TaError::NonFinite);
        }
        Ok(DVector::from_column_slice(r))
    }

    /// The entry `r` would make with the current V (weights `V⁻¹`, `V⁻¹ r`).
    fn entry(&self, r: &DVector<f64>) -> Entry {
        Entry {
            weighted: self.v_inv.as_ref().map(|vi| (vi.clone(), vi * r)),
        }
    }

    /// T_a over the window with `r` appended as its newest residual, without changing
    /// anything. `Ok(None)` during warm-up; `Err(Singular)` if Σ V_j⁻¹ has no Cholesky
    /// factor.
    pub fn evaluate(&self, r: &[f64]) -> Result<Option<f64>, TaError> {
        let r = self.check(r)?;
        if let (true, None) = (self.differences >= self.params.min_differences, &self.v_inv) {
            return Err(TaError::Singular);
        }
        let newest = self.entry(&r);
        let skip = usize::from(self.window.len() >= self.params.n);
        if self.window.len() + 1 - skip < self.params.n {
            return Ok(None);
        }
        let dim = self.params.dim;
        let mut info = DMatrix::<f64>::zeros(dim, dim);
        let mut s = DVector::<f64>::zeros(dim);
        for e in self
            .window
            .iter()
            .skip(skip)
            .chain(std::iter::once(&newest))
        {
            let Some((vi, vir)) = &e.weighted else {
                return Ok(None);
            };
            info += vi;
            s += vir;
        }
        // eqs. 14–15: T_a = r_aᵀ V_a⁻¹ r_a with V_a = info⁻¹, r_a = V_a s, so T_a = sᵀ info⁻¹ s.
        let chol = info.cholesky().ok_or(TaError::Singular)?;
        let t = s.dot(&chol.solve(&s));
        if t.is_finite() {
            Ok(Some(t.max(0.0)))
        } else {
            Err(TaError::Singular)
        }
    }

    /// Appends `r` to the window (weighed by the V known before it) and, when the
    /// channel's decision for this epoch is `healthy`, updates V with the difference to
    /// the previous healthy residual (eq. 16). Otherwise V stays frozen.
    pub fn commit(&mut self, r: &[f64], healthy: bool) -> Result<(), TaError> {
        let r = self.check(r)?;
        let entry = self.entry(&r);
        if self.window.len() >= self.params.n {
            self.window.pop_front();
        }
        self.window.push_back(entry);
        if !healthy {
            self.last_healthy = None;
            return Ok(());
        }
        if let Some(prev) = self.last_healthy.take() {
            // eq. 16 with k − 1 = the number of differences used, this one included.
            let d = &r - prev;
            self.differences += 1;
            let k1 = self.differences as f64;
            self.v = &self.v * (1.0 - 1.0 / k1) + (&d * d.transpose()) / (2.0 * k1);
            self.v_inv = if self.differences >= self.params.min_differences {
                self.v.clone().cholesky().map(|c| c.inverse())
            } else {
                None
            };
        }
        self.last_healthy = Some(r);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::chi2;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, StandardNormal};

    /// Feeds `epochs` white residuals `L z` (z standard normal) and returns T_a at every
    /// `n`-th epoch after warm-up (non-overlapping windows, so the values are independent).
    fn white_run(dim: usize, l: &DMatrix<f64>, epochs: usize, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut ta = TaStatistic::new(TaParams::new(dim));
        let n = ta.params().n;
        let mut out = Vec::new();
        for k in 0..epochs {
            let z = DVector::from_fn(dim, |_, _| StandardNormal.sample(&mut rng));
            let r = l * z;
            let t = ta.evaluate(r.as_slice()).unwrap();
            if let Some(t) = t.filter(|_| k >= 200 && k % n == 0) {
                out.push(t);
            }
            ta.commit(r.as_slice(), true).unwrap();
        }
        out
    }

    /// Asserts that the share of `values` above the χ²(dof) threshold for each p_fa
    /// lies within 4 binomial standard deviations of p_fa.
    fn assert_chi2_tails(values: &[f64], dof: u32) {
        let m = values.len() as f64;
        for p in [0.05, 0.01, 0.5] {
            let t = chi2::threshold(dof, p).unwrap();
            let frac = values.iter().filter(|&&v| v > t).count() as f64 / m;
            let sd = (p * (1.0 - p) / m).sqrt();
            assert!(
                (frac - p).abs() < 4.0 * sd,
                "dof {dof}: {frac} above the {p} quantile {t} (±{sd})"
            );
        }
    }

    #[test]
    fn scalar_ta_under_no_fault_follows_chi2_with_one_dof() {
        let l = DMatrix::from_element(1, 1, 3.0);
        let values = white_run(1, &l, 60_000, 7);
        assert!(values.len() > 5_000);
        assert_chi2_tails(&values, 1);
    }

    #[test]
    fn vector_ta_with_correlated_residuals_follows_chi2_with_dim_dof() {
        // Residual covariance L Lᵀ = [[4, 1.2], [1.2, 1]]: correlated, unequal scales.
        let l = DMatrix::from_row_slice(2, 2, &[2.0, 0.0, 0.6, 0.8]);
        let values = white_run(2, &l, 60_000, 11);
        assert_chi2_tails(&values, 2);
    }

    #[test]
    fn successive_difference_variance_matches_the_recursion_by_hand() {
        let mut ta = TaStatistic::new(TaParams {
            dim: 1,
            n: 2,
            min_differences: 1,
        });
        // Differences 2, −4: V_2 = 4/2 = 2, V_3 = (1 − 1/2)·2 + 16/4 = 5.
        for r in [1.0, 3.0, -1.0] {
            ta.commit(&[r], true).unwrap();
        }
        assert!((ta.variance()[(0, 0)] - 5.0).abs() < 1e-12);
        // Window [3 (warm-up, unweighed), −1 (weighed by V = 2)]; appending 4 (by 5) drops 3:
        // s = −1/2 + 4/5 = 0.3, info = 1/2 + 1/5 = 0.7, T_a = 0.09 / 0.7.
        let t = ta.evaluate(&[4.0]).unwrap().unwrap();
        assert!((t - 0.09 / 0.7).abs() < 1e-12, "{t}");
    }

    #[test]
    fn variance_is_frozen_while_unhealthy_and_across_the_return() {
        let mut ta = TaStatistic::new(TaParams {
            dim: 1,
            n: 3,
            min_differences: 1,
        });
        for r in [0.0, 1.0, 0.0, 1.0] {
            ta.commit(&[r], true).unwrap();
        }
        let v = ta.variance()[(0, 0)];
        assert!((v - 0.5).abs() < 1e-12);
        ta.commit(&[100.0], false).unwrap();
        // Back to healthy: no difference with the faulty residual is formed.
        ta.commit(&[0.5], true).unwrap();
        assert_eq!(ta.variance()[(0, 0)], v);
        assert_eq!(ta.differences(), 3);
        // The faulty residual is still in the window and drives T_a up.
        assert!(ta.evaluate(&[0.0]).unwrap().unwrap() > 1000.0);
    }

    #[test]
    fn warm_up_and_bad_input_give_none_or_errors_not_panics() {
        let mut ta = TaStatistic::new(TaParams::new(2));
        assert_eq!(ta.evaluate(&[0.0, 0.0]).unwrap(), None);
        assert!(matches!(
            ta.evaluate(&[1.0]),
            Err(TaError::Dimension { got: 1, want: 2 })
        ));
        assert_eq!(ta.evaluate(&[f64::NAN, 0.0]), Err(TaError::NonFinite));
        // A component that never moves: V is singular once warm-up is over.
        for k in 0..40 {
            ta.commit(&[k as f64 % 2.0, 5.0], true).unwrap();
        }
        assert_eq!(ta.evaluate(&[0.0, 5.0]), Err(TaError::Singular));
        ta.reset();
        assert_eq!(ta.differences(), 0);
    }
}
