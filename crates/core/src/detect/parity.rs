//! Parity space of a redundant gyro set (docs/methods.md §M15, seed 002 §2.1): the parity
//! matrix `V` whose rows span the left null space of the mounting matrix `H`
//! (`VH = 0`, `VVᵀ = I`), the parity residual `r = V v`, the windowed χ² of the
//! fixed-sample-size (FSS/GLT) test over the last `l'` residuals, and ω by weighted
//! least squares over the healthy gyros. Sits between the gyro samples of an epoch
//! and the `parity` test of `monitor::rimu`.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Why a parity space cannot be built or used; `field` names the input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {reason}")]
pub struct ParityError {
    /// The offending input, e.g. `h`, `sigma[2]`.
    pub field: String,
    /// Why it was refused.
    pub reason: String,
}

impl ParityError {
    fn new(field: impl Into<String>, reason: impl Into<String>) -> Self {
        ParityError {
            field: field.into(),
            reason: reason.into(),
        }
    }
}

/// 1/√3: the direction cosines of the skewed gyro of the default set.
pub const SKEW: f64 = 0.577_350_269_189_625_8;

/// The default mounting matrix (seed 002 Fig. 1): three orthogonal gyros on x, y, z and
/// one skewed at equal angles to all three, `[1/√3, 1/√3, 1/√3]`.
pub fn default_h() -> DMatrix<f64> {
    DMatrix::from_row_slice(
        4,
        3,
        &[
            1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, SKEW, SKEW, SKEW,
        ],
    )
}

/// Eigenvalues of the projector above this are taken as 1 (its spectrum is {0, 1}).
const PROJECTOR_TOL: f64 = 0.5;

/// The parity space of a mounting matrix `H` (m × 3, m > 3, rank 3).
#[derive(Debug, Clone, PartialEq)]
pub struct ParitySpace {
    h: DMatrix<f64>,
    v: DMatrix<f64>,
}

impl ParitySpace {
    /// Builds `V` (p × m, p = m − 3) from `H`. `V`'s rows are the unit eigenvectors of
    /// the projector `I − H(HᵀH)⁻¹Hᵀ` onto the left null space, each signed so its
    /// first non-zero element is positive (for the default `H` this makes
    /// `r ∝ v₁ + v₂ + v₃ − √3·v₄`, seed 002 eq. 6).
    pub fn new(h: DMatrix<f64>) -> Result<Self, ParityError> {
        let m = h.nrows();
        if h.ncols() != 3 {
            return Err(ParityError::new(
                "h",
                format!("rows must have 3 elements (x, y, z), got {}", h.ncols()),
            ));
        }
        if m <= 3 {
            return Err(ParityError::new(
                "h",
                format!("needs more than 3 gyros for a parity space, got {m}"),
            ));
        }
        if h.iter().any(|v| !v.is_finite()) {
            return Err(ParityError::new("h", "must be finite"));
        }
        for i in 0..m {
            if h.row(i).norm() < 1e-9 {
                return Err(ParityError::new(format!("h[{i}]"), "is a zero axis"));
            }
        }
        let hth = h.transpose() * &h;
        let eig = hth.clone().symmetric_eigenvalues();
        let (lo, hi) = (eig.min(), eig.max());
        // NaN-safe: a NaN eigenvalue is refused too.
        if lo.is_nan() || lo <= 1e-9 * hi {
            return Err(ParityError::new(
                "h",
                "the gyro axes do not span 3-D space (HᵀH is singular)",
            ));
        }
        let inv = hth
            .try_inverse()
            .ok_or_else(|| ParityError::new("h", "HᵀH is singular"))?;
        let projector = DMatrix::identity(m, m) - &h * inv * h.transpose();
        let sym = (&projector + projector.transpose()) * 0.5;
        let eigen = sym.symmetric_eigen();
        let mut rows: Vec<Vec<f64>> = (0..m)
            .filter(|&k| eigen.eigenvalues[k] > PROJECTOR_TOL)
            .map(|k| eigen.eigenvectors.column(k).iter().copied().collect())
            .collect();
        if rows.len() != m - 3 {
            return Err(ParityError::new(
                "h",
                "parity space has the wrong dimension",
            ));
        }
        for row in &mut rows {
            let first = row.iter().copied().find(|v| v.abs() > 1e-9).unwrap_or(1.0);
            if first < 0.0 {
                row.iter_mut().for_each(|v| *v = -*v);
            }
        }
        let p = rows.len();
        let v = DMatrix::from_fn(p, m, |i, j| rows[i][j]);
        Ok(ParitySpace { h, v })
    }

    /// The default four-gyro set's parity space.
    pub fn default_four() -> Self {
        // The default H has full rank; building it cannot fail.
        Self::new(default_h()).unwrap_or_else(|_| unreachable!("default H is valid"))
    }

    /// Number of gyros m.
    pub fn gyros(&self) -> usize {
        self.h.nrows()
    }

    /// Parity dimension p = m − 3.
    pub fn dim(&self) -> usize {
        self.v.nrows()
    }

    /// The mounting matrix H.
    pub fn h(&self) -> &DMatrix<f64> {
        &self.h
    }

    /// The parity matrix V.
    pub fn v(&self) -> &DMatrix<f64> {
        &self.v
    }

    /// The parity residual `r = V v` (p elements); independent of ω since `VH = 0`.
    pub fn residual(&self, gyros: &[f64]) -> DVector<f64> {
        &self.v * DVector::from_column_slice(gyros)
    }

    /// The residual's covariance `V diag(σ²) Vᵀ` for per-gyro noise σ.
    pub fn covariance(&self, sigma: &[f64]) -> DMatrix<f64> {
        let d = DMatrix::from_diagonal(&DVector::from_iterator(
            sigma.len(),
            sigma.iter().map(|s| s * s),
        ));
        &self.v * d * self.v.transpose()
    }

    /// ω by weighted least squares over the gyros with `healthy[i]`, weights 1/σᵢ²:
    /// `ω = (HₕᵀWHₕ)⁻¹HₕᵀW vₕ`. `None` when the healthy axes no longer span 3-D space.
    pub fn omega(&self, gyros: &[f64], sigma: &[f64], healthy: &[bool]) -> Option<[f64; 3]> {
        let mut a = nalgebra::Matrix3::<f64>::zeros();
        let mut b = nalgebra::Vector3::<f64>::zeros();
        for i in 0..self.gyros() {
            if !healthy.get(i).copied().unwrap_or(false) {
                continue;
            }
            let w = 1.0 / (sigma[i] * sigma[i]);
            let hi = nalgebra::Vector3::new(self.h[(i, 0)], self.h[(i, 1)], self.h[(i, 2)]);
            a += hi * hi.transpose() * w;
            b += hi * (w * gyros[i]);
        }
        let eig = a.symmetric_eigenvalues();
        let (lo, hi) = (eig.min(), eig.max());
        if lo.is_nan() || lo <= 1e-9 * hi {
            return None;
        }
        let x = a.cholesky()?.solve(&b);
        Some([x[0], x[1], x[2]])
    }
}

/// The FSS (fixed sample size) windowed χ² of seed 002 eq. 7 over the last `l'`
/// parity residuals: `λ = Rᵀ P_r⁻¹ R` with `R` the stacked residuals and `P_r`
/// block-diagonal (white gyro noise), i.e. `λ = Σ_t r_tᵀ C⁻¹ r_t ~ χ²(l'·p)`.
///
/// Serde: a monitor checkpoint saves it whole and [`FssWindow::restored`] checks it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FssWindow {
    c_inv: DMatrix<f64>,
    /// `L⁻¹` with `C = L Lᵀ`: whitens one residual.
    l_inv: DMatrix<f64>,
    window: usize,
    terms: std::collections::VecDeque<f64>,
}

impl FssWindow {
    /// A window of `window` epochs for residuals of covariance `c` (p × p, positive definite).
    pub fn new(c: &DMatrix<f64>, window: usize) -> Result<Self, ParityError> {
        if window == 0 {
            return Err(ParityError::new("fss_window", "must be at least 1"));
        }
        let chol = c.clone().cholesky().ok_or_else(|| {
            ParityError::new("sigma", "parity covariance is not positive definite")
        })?;
        let c_inv = chol.inverse();
        let p = c.nrows();
        let l_inv = chol
            .l()
            .solve_lower_triangular(&DMatrix::identity(p, p))
            .ok_or_else(|| {
                ParityError::new("sigma", "parity covariance is not positive definite")
            })?;
        Ok(FssWindow {
            c_inv,
            l_inv,
            window,
            terms: std::collections::VecDeque::with_capacity(window),
        })
    }

    /// Window length l'.
    pub fn window(&self) -> usize {
        self.window
    }

    /// Degrees of freedom of λ: `l'·p`.
    pub fn dof(&self) -> u32 {
        (self.window * self.c_inv.nrows()) as u32
    }

    /// The λ that pushing `r` would give (`None` until the window is full), without
    /// changing the window; [`FssWindow::push`] commits it.
    pub fn peek(&self, r: &DVector<f64>) -> (f64, Option<f64>) {
        let q = (r.transpose() * &self.c_inv * r)[(0, 0)];
        let full = self.terms.len() + 1 >= self.window;
        let kept = self.terms.len().min(self.window - 1);
        let sum: f64 = self.terms.iter().rev().take(kept).sum::<f64>() + q;
        (q, full.then_some(sum))
    }

    /// The whitened residual `L⁻¹ r` (`‖L⁻¹ r‖² = rᵀC⁻¹r`): what the consistency
    /// diagnostics take (docs/methods.md §M22).
    pub fn whiten(&self, r: &DVector<f64>) -> DVector<f64> {
        &self.l_inv * r
    }

    /// Appends one epoch's term `q = rᵀC⁻¹r` (from [`FssWindow::peek`]).
    pub fn push(&mut self, q: f64) {
        if self.terms.len() == self.window {
            self.terms.pop_front();
        }
        self.terms.push_back(q);
    }

    /// Empties the window.
    pub fn clear(&mut self) {
        self.terms.clear();
    }

    /// `saved` (read from a checkpoint) as the running state of this window: the same
    /// length and residual covariance (bit for bit: both are computed from the config),
    /// no more terms than the window; with the capacity [`FssWindow::new`] reserves. The
    /// reason otherwise.
    pub fn restored(&self, mut saved: FssWindow) -> Result<FssWindow, String> {
        if saved.window != self.window || saved.c_inv != self.c_inv || saved.l_inv != self.l_inv {
            return Err(format!(
                "FSS window of {} epochs over {} parity components, the monitor's is {} over {}",
                saved.window,
                saved.c_inv.nrows(),
                self.window,
                self.c_inv.nrows()
            ));
        }
        if saved.terms.len() > saved.window {
            return Err("FSS window holds more terms than its length".into());
        }
        saved
            .terms
            .reserve(saved.window.saturating_sub(saved.terms.len()));
        Ok(saved)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, StandardNormal};

    fn five_and_six() -> [DMatrix<f64>; 2] {
        // Five gyros on a cone (half-angle 54.74°, the dodecahedron-like layout) and
        // six on the faces of a dodecahedron: the usual skewed redundant sets.
        let c = SKEW;
        let s = (1.0 - c * c).sqrt();
        let five = DMatrix::from_fn(5, 3, |i, j| {
            let a = 2.0 * std::f64::consts::PI * i as f64 / 5.0;
            [s * a.cos(), s * a.sin(), c][j]
        });
        let (a, b) = (0.525_731_112_119_133_6, 0.850_650_808_352_039_9);
        let six = DMatrix::from_row_slice(
            6,
            3,
            &[
                a, 0.0, b, -a, 0.0, b, b, a, 0.0, b, -a, 0.0, 0.0, b, a, 0.0, b, -a,
            ],
        );
        [five, six]
    }

    #[test]
    fn parity_matrix_annihilates_h_and_has_orthonormal_rows_for_4_5_6_gyros() {
        let [five, six] = five_and_six();
        for h in [default_h(), five, six] {
            let m = h.nrows();
            let ps = ParitySpace::new(h.clone()).unwrap();
            assert_eq!(ps.dim(), m - 3);
            assert!((ps.v() * &h).amax() < 1e-12, "VH = 0 for m = {m}");
            let vvt = ps.v() * ps.v().transpose();
            assert!(
                (vvt - DMatrix::identity(m - 3, m - 3)).amax() < 1e-12,
                "VVᵀ = I for m = {m}"
            );
        }
    }

    #[test]
    fn default_residual_is_seed_002_equation_6_scaled() {
        // V = [1, 1, 1, −√3]/√6, so √6·r = v₁ + v₂ + v₃ − v₄/0.5774 up to the paper's
        // rounding of 1/√3 to 0.5774 (relative 2.6e-5 on the v₄ term).
        let ps = ParitySpace::default_four();
        let v = [0.3, -1.2, 0.7, 2.5];
        let ours = ps.residual(&v)[0] * 6f64.sqrt();
        let eq6 = v[0] + v[1] + v[2] - v[3] / 0.5774;
        assert!((ours - eq6).abs() < 2e-4 * v[3], "{ours} vs {eq6}");
        let w = [0.3, -1.2, 0.7, 0.0];
        let exact = ps.residual(&w)[0] * 6f64.sqrt();
        assert!((exact - (w[0] + w[1] + w[2])).abs() < 1e-12);
        let want = [1.0, 1.0, 1.0, -3f64.sqrt()].map(|x| x / 6f64.sqrt());
        for (j, w) in want.iter().enumerate() {
            assert!((ps.v()[(0, j)] - w).abs() < 1e-12);
        }
    }

    #[test]
    fn windowed_statistic_follows_chi2_of_window_times_p_under_no_fault() {
        // 5 gyros (p = 2), l' = 6 → dof 12. Non-overlapping windows are independent:
        // the share above the 0.9 and 0.99 quantiles must be near 0.1 and 0.01.
        let [five, _] = five_and_six();
        let ps = ParitySpace::new(five).unwrap();
        let sigma = [1e-3, 2e-3, 1e-3, 1.5e-3, 1e-3];
        let mut fss = FssWindow::new(&ps.covariance(&sigma), 6).unwrap();
        assert_eq!(fss.dof(), 12);
        let mut rng = StdRng::seed_from_u64(2);
        let omega = DVector::from_vec(vec![0.1, -0.05, 0.02]);
        let truth = ps.h() * omega;
        let mut lambdas = Vec::new();
        for k in 0..60_000 {
            let v: Vec<f64> = (0..5)
                .map(|i| {
                    let z: f64 = StandardNormal.sample(&mut rng);
                    truth[i] + sigma[i] * z
                })
                .collect();
            let (q, lambda) = fss.peek(&ps.residual(&v));
            fss.push(q);
            if k % 6 == 5 {
                lambdas.push(lambda.unwrap());
            }
        }
        let n = lambdas.len() as f64;
        for (p, tol) in [(0.1, 0.01), (0.01, 0.003)] {
            let t = crate::detect::chi2::threshold(12, p).unwrap();
            let share = lambdas.iter().filter(|&&l| l > t).count() as f64 / n;
            assert!((share - p).abs() < tol, "P(λ > q_{p}) = {share}");
        }
    }

    #[test]
    fn window_runs_only_once_full_and_slides() {
        let ps = ParitySpace::default_four();
        let mut fss = FssWindow::new(&ps.covariance(&[1.0; 4]), 3).unwrap();
        let r = DVector::from_vec(vec![1.0]);
        let close = |l: Option<f64>, want: Option<f64>| match (l, want) {
            (Some(a), Some(b)) => (a - b).abs() < 1e-12,
            (a, b) => a.is_none() && b.is_none(),
        };
        for want in [None, None, Some(3.0), Some(3.0)] {
            let (q, l) = fss.peek(&r);
            assert!(close(l, want), "{l:?} vs {want:?}");
            fss.push(q);
        }
        // The window now holds three 1s; pushing r = 2 drops one: 1 + 1 + 4.
        let (_, l) = fss.peek(&DVector::from_vec(vec![2.0]));
        assert!(close(l, Some(6.0)), "{l:?}");
    }

    #[test]
    fn weighted_least_squares_reconstructs_omega_exactly_without_one_gyro() {
        let [five, six] = five_and_six();
        let omega = nalgebra::Vector3::new(0.02, -0.3, 0.11);
        for h in [default_h(), five, six] {
            let m = h.nrows();
            let ps = ParitySpace::new(h.clone()).unwrap();
            let mut v: Vec<f64> = (0..m).map(|i| (h.row(i) * omega)[(0, 0)]).collect();
            let sigma: Vec<f64> = (0..m).map(|i| 1e-3 * (1.0 + i as f64)).collect();
            for bad in 0..m {
                let saved = v[bad];
                v[bad] += 5.0; // a gross fault on the excluded gyro
                let mut healthy = vec![true; m];
                healthy[bad] = false;
                let w = ps.omega(&v, &sigma, &healthy).unwrap();
                for k in 0..3 {
                    assert!((w[k] - omega[k]).abs() < 1e-12, "m = {m}, bad = {bad}");
                }
                v[bad] = saved;
            }
        }
        // Two gyros out of four leave 2 axes: no solution.
        let ps = ParitySpace::default_four();
        assert!(
            ps.omega(&[0.0; 4], &[1.0; 4], &[true, false, true, true])
                .is_some()
        );
        assert!(
            ps.omega(&[0.0; 4], &[1.0; 4], &[false, true, true, false])
                .is_none()
        );
    }

    #[test]
    fn bad_mounting_matrices_are_refused_naming_the_field() {
        let e = ParitySpace::new(DMatrix::identity(3, 3)).unwrap_err();
        assert_eq!(e.field, "h");
        let mut h = default_h();
        h.row_mut(2).fill(0.0);
        assert_eq!(ParitySpace::new(h).unwrap_err().field, "h[2]");
        let h = DMatrix::from_row_slice(4, 3, &[1., 0., 0., 2., 0., 0., 0., 1., 0., 0., 3., 0.]);
        assert!(ParitySpace::new(h).unwrap_err().reason.contains("span"));
    }

    #[test]
    fn whitened_residual_has_the_windowed_term_as_its_squared_norm() {
        let c = DMatrix::from_row_slice(2, 2, &[4.0, 1.2, 1.2, 1.0]);
        let fss = FssWindow::new(&c, 3).unwrap();
        let r = DVector::from_column_slice(&[1.5, -0.5]);
        let (q, _) = fss.peek(&r);
        assert!((fss.whiten(&r).norm_squared() - q).abs() < 1e-12);
    }
}
