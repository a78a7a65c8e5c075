//! The Kalman filter at the bottom of the filter layer; every monitor's filters use it.
//!
//! One generic implementation over nalgebra dimensions serves both the fixed-size INS models
//! (`SMatrix`, e.g. 15 states × 6 measurements, no heap allocation) and user-defined linear
//! models (`DMatrix`). It has adskalman's shape: an explicit [`StateEstimate`] (x and P), model
//! traits for F/Q ([`TransitionModel`]) and H/R ([`ObservationModel`]), and an [`Innovation`]
//! value that is handed to the detectors between [`innovation`] and [`update`], so a decision
//! policy can reject a measurement before it touches the state.
//!
//! - predict: `x⁻ = Φ x (+ B u)`, `P⁻ = Φ P Φᵀ + Q`;
//! - innovation (seed 004 §1.3 eq. 6): `r = z − H x⁻`, `S = H P⁻ Hᵀ + R`,
//!   `λ = rᵀ S⁻¹ r ~ χ²(m)`;
//! - update: `K = P⁻ Hᵀ S⁻¹`, `x⁺ = x⁻ + K r`, Joseph form
//!   `P⁺ = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ`.
//!
//! Every covariance the module returns is symmetrised as `(P + Pᵀ)/2`, so it is exactly
//! symmetric. `S` is only ever used through its Cholesky factor, never inverted. Every function
//! takes its inputs by reference and returns new values, so a failed step (`Err`) leaves the
//! caller's state untouched: the caller commits on success.

use nalgebra::allocator::Allocator;
use nalgebra::storage::RawStorage;
use nalgebra::{Cholesky, DefaultAllocator, Dim, Matrix, OMatrix, OVector};
use serde::{Deserialize, Serialize};

/// Why a filter step failed; the caller's state is unchanged whenever one is returned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FilterError {
    /// `S = H P⁻ Hᵀ + R` has no Cholesky factor, so λ and the gain are undefined.
    #[error("innovation covariance S is not positive definite (Cholesky failed)")]
    NotPositiveDefinite,
    /// A NaN or infinity in an input or a result; names which one.
    #[error("non-finite value in {0}")]
    NonFinite(&'static str),
    /// A dynamically sized matrix does not fit the others (fixed sizes are checked by the type).
    #[error(
        "dimension mismatch: {what} is {got_rows}x{got_cols}, expected {want_rows}x{want_cols}"
    )]
    Dimension {
        /// Which matrix has the wrong shape.
        what: &'static str,
        /// Its rows.
        got_rows: usize,
        /// Its columns.
        got_cols: usize,
        /// The rows it needs.
        want_rows: usize,
        /// The columns it needs.
        want_cols: usize,
    },
}

/// The Kalman gain `K = P⁻ Hᵀ S⁻¹` (n×m) returned by [`update`].
pub type Gain<N, M> = OMatrix<f64, N, M>;

/// A Gaussian state estimate: explicit mean `x` and covariance `P` (serde: a monitor
/// checkpoint saves it, every f64 bit for bit).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(bound(
    serialize = "OVector<f64, N>: Serialize, OMatrix<f64, N, N>: Serialize",
    deserialize = "OVector<f64, N>: Deserialize<'de>, OMatrix<f64, N, N>: Deserialize<'de>"
))]
pub struct StateEstimate<N: Dim>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    /// State mean x.
    pub x: OVector<f64, N>,
    /// State covariance P (symmetric positive definite).
    pub p: OMatrix<f64, N, N>,
}

/// The dynamics `x_k = Φ x_{k−1} + w`, `w ~ N(0, Q)`, as adskalman's transition model.
pub trait TransitionModel<N: Dim>
where
    DefaultAllocator: Allocator<N, N>,
{
    /// State transition matrix Φ (n×n).
    fn f(&self) -> &OMatrix<f64, N, N>;
    /// Process noise covariance Q (n×n).
    fn q(&self) -> &OMatrix<f64, N, N>;
}

/// The measurement `z = H x + v`, `v ~ N(0, R)`, as adskalman's observation model.
pub trait ObservationModel<N: Dim, M: Dim>
where
    DefaultAllocator: Allocator<M, N> + Allocator<M, M>,
{
    /// Observation matrix H (m×n).
    fn h(&self) -> &OMatrix<f64, M, N>;
    /// Measurement noise covariance R (m×m).
    fn r(&self) -> &OMatrix<f64, M, M>;
}

/// A transition model built from owned Φ and Q matrices.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearTransition<N: Dim>
where
    DefaultAllocator: Allocator<N, N>,
{
    /// State transition matrix Φ (n×n).
    pub f: OMatrix<f64, N, N>,
    /// Process noise covariance Q (n×n).
    pub q: OMatrix<f64, N, N>,
}

impl<N: Dim> TransitionModel<N> for LinearTransition<N>
where
    DefaultAllocator: Allocator<N, N>,
{
    fn f(&self) -> &OMatrix<f64, N, N> {
        &self.f
    }
    fn q(&self) -> &OMatrix<f64, N, N> {
        &self.q
    }
}

/// An observation model built from owned H and R matrices.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearObservation<N: Dim, M: Dim>
where
    DefaultAllocator: Allocator<M, N> + Allocator<M, M>,
{
    /// Observation matrix H (m×n).
    pub h: OMatrix<f64, M, N>,
    /// Measurement noise covariance R (m×m).
    pub r: OMatrix<f64, M, M>,
}

impl<N: Dim, M: Dim> ObservationModel<N, M> for LinearObservation<N, M>
where
    DefaultAllocator: Allocator<M, N> + Allocator<M, M>,
{
    fn h(&self) -> &OMatrix<f64, M, N> {
        &self.h
    }
    fn r(&self) -> &OMatrix<f64, M, M> {
        &self.r
    }
}

/// The innovation of one measurement against a prior, handed to the detectors.
///
/// Built by [`innovation`]; [`update`] reuses its Cholesky factor for the gain.
#[derive(Debug, Clone)]
pub struct Innovation<M: Dim>
where
    DefaultAllocator: Allocator<M, M> + Allocator<M>,
{
    /// Residual `r = z − H x⁻` (seed 004 §1.3 eq. 6).
    pub r: OVector<f64, M>,
    /// Innovation covariance `S = H P⁻ Hᵀ + R`, symmetrised.
    pub s: OMatrix<f64, M, M>,
    /// Cholesky factorisation `S = L Lᵀ`; `s_chol.l()` is the lower factor L.
    pub s_chol: Cholesky<f64, M>,
    /// `λ = rᵀ S⁻¹ r`, χ²-distributed with [`Innovation::dof`] degrees of freedom when the
    /// model holds.
    pub statistic: f64,
}

impl<M: Dim> Innovation<M>
where
    DefaultAllocator: Allocator<M, M> + Allocator<M>,
{
    /// Degrees of freedom of λ: the measurement dimension m.
    pub fn dof(&self) -> usize {
        self.r.nrows()
    }

    /// `S⁻¹ r`, solved through the Cholesky factor (no explicit inverse).
    pub fn s_inv_r(&self) -> OVector<f64, M> {
        self.s_chol.solve(&self.r)
    }
}

/// Predicts one step without control: `x⁻ = Φ x`, `P⁻ = Φ P Φᵀ + Q`.
pub fn predict<N: Dim>(
    est: &StateEstimate<N>,
    model: &impl TransitionModel<N>,
) -> Result<StateEstimate<N>, FilterError>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    check_transition(est, model)?;
    let x = model.f() * &est.x;
    propagate(est, model, x)
}

/// Predicts one step with a control input: `x⁻ = Φ x + B u`, `P⁻ = Φ P Φᵀ + Q`.
pub fn predict_with_control<N: Dim, U: Dim>(
    est: &StateEstimate<N>,
    model: &impl TransitionModel<N>,
    b: &OMatrix<f64, N, U>,
    u: &OVector<f64, U>,
) -> Result<StateEstimate<N>, FilterError>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N> + Allocator<N, U> + Allocator<U>,
{
    check_transition(est, model)?;
    expect_shape("control matrix B", b, est.x.nrows(), u.nrows())?;
    ensure_finite("control input", u)?;
    let x = model.f() * &est.x + b * u;
    propagate(est, model, x)
}

/// Computes the innovation of measurement `z` against the prior: `r`, `S`, its Cholesky
/// factor and `λ = rᵀ S⁻¹ r`. Fails with [`FilterError::NotPositiveDefinite`] if `S` has no
/// Cholesky factor.
pub fn innovation<N: Dim, M: Dim>(
    prior: &StateEstimate<N>,
    model: &impl ObservationModel<N, M>,
    z: &OVector<f64, M>,
) -> Result<Innovation<M>, FilterError>
where
    DefaultAllocator: Allocator<N, N>
        + Allocator<N>
        + Allocator<M, N>
        + Allocator<N, M>
        + Allocator<M, M>
        + Allocator<M>,
{
    let (n, m) = (prior.x.nrows(), z.nrows());
    check_estimate(prior)?;
    expect_shape("observation matrix H", model.h(), m, n)?;
    expect_shape("measurement noise R", model.r(), m, m)?;
    ensure_finite("measurement", z)?;

    let h = model.h();
    // seed 004 §1.3 eq. 6: r_k = z_k − H_k x̂_{k/k−1}
    let r = z - h * &prior.x;
    let s = symmetrise(h * &prior.p * h.transpose() + model.r());
    ensure_finite("innovation", &r)?;
    ensure_finite("innovation covariance", &s)?;

    let s_chol = Cholesky::new(s.clone()).ok_or(FilterError::NotPositiveDefinite)?;
    // λ = rᵀ (L Lᵀ)⁻¹ r = |L⁻¹ r|²: one triangular solve, and λ ≥ 0 by construction.
    // `l_dirty` holds S's upper triangle above L, which the lower solve never reads.
    let w = s_chol.l_dirty().solve_lower_triangular_unchecked(&r);
    let statistic = w.norm_squared();
    if !statistic.is_finite() {
        return Err(FilterError::NonFinite("chi-square statistic"));
    }
    Ok(Innovation {
        r,
        s,
        s_chol,
        statistic,
    })
}

/// Updates the prior with an innovation computed by [`innovation`] from the same prior and
/// model. Returns the posterior and the gain `K = P⁻ Hᵀ S⁻¹` (n×m), whose rows the protection
/// level computation needs.
pub fn update<N: Dim, M: Dim>(
    prior: &StateEstimate<N>,
    model: &impl ObservationModel<N, M>,
    innov: &Innovation<M>,
) -> Result<(StateEstimate<N>, Gain<N, M>), FilterError>
where
    DefaultAllocator: Allocator<N, N>
        + Allocator<N>
        + Allocator<M, N>
        + Allocator<N, M>
        + Allocator<M, M>
        + Allocator<M>,
{
    let (n, m) = (prior.x.nrows(), innov.r.nrows());
    check_estimate(prior)?;
    expect_shape("observation matrix H", model.h(), m, n)?;
    expect_shape("measurement noise R", model.r(), m, m)?;
    expect_shape("innovation covariance S", &innov.s, m, m)?;
    expect_shape("Cholesky factor of S", innov.s_chol.l_dirty(), m, m)?;

    let h = model.h();
    // K = P⁻ Hᵀ S⁻¹  ⇔  S Kᵀ = H P⁻ (S and P⁻ symmetric): solve through the factor.
    let k = innov.s_chol.solve(&(h * &prior.p)).transpose();
    ensure_finite("gain", &k)?;
    let x = &prior.x + &k * &innov.r;

    // Joseph form: stays symmetric positive semi-definite under rounding and for any gain.
    let dim = prior.x.shape_generic().0;
    let i_kh = OMatrix::<f64, N, N>::identity_generic(dim, dim) - &k * h;
    let p = symmetrise(&i_kh * &prior.p * i_kh.transpose() + &k * model.r() * k.transpose());
    ensure_finite("updated state", &x)?;
    ensure_finite("updated covariance", &p)?;
    Ok((StateEstimate { x, p }, k))
}

/// Shared tail of both predictions: `P⁻ = Φ P Φᵀ + Q`, then the finiteness checks.
fn propagate<N: Dim>(
    est: &StateEstimate<N>,
    model: &impl TransitionModel<N>,
    x: OVector<f64, N>,
) -> Result<StateEstimate<N>, FilterError>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    let f = model.f();
    let p = symmetrise(f * &est.p * f.transpose() + model.q());
    ensure_finite("predicted state", &x)?;
    ensure_finite("predicted covariance", &p)?;
    Ok(StateEstimate { x, p })
}

/// Checks Φ and Q against the estimate's size.
fn check_transition<N: Dim>(
    est: &StateEstimate<N>,
    model: &impl TransitionModel<N>,
) -> Result<(), FilterError>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    let n = est.x.nrows();
    check_estimate(est)?;
    expect_shape("transition matrix F", model.f(), n, n)?;
    expect_shape("process noise Q", model.q(), n, n)
}

/// Checks that P matches x (the fields are public, so a caller can build a mismatched pair).
fn check_estimate<N: Dim>(est: &StateEstimate<N>) -> Result<(), FilterError>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    let n = est.x.nrows();
    expect_shape("covariance P", &est.p, n, n)
}

/// `Err(Dimension)` unless `m` is `rows`×`cols`; free for fixed sizes, one compare for dynamic.
fn expect_shape<R: Dim, C: Dim, S: RawStorage<f64, R, C>>(
    what: &'static str,
    m: &Matrix<f64, R, C, S>,
    rows: usize,
    cols: usize,
) -> Result<(), FilterError> {
    let (got_rows, got_cols) = m.shape();
    if (got_rows, got_cols) == (rows, cols) {
        Ok(())
    } else {
        Err(FilterError::Dimension {
            what,
            got_rows,
            got_cols,
            want_rows: rows,
            want_cols: cols,
        })
    }
}

/// `Err(NonFinite(what))` if any entry of `m` is NaN or infinite.
fn ensure_finite<R: Dim, C: Dim, S: RawStorage<f64, R, C>>(
    what: &'static str,
    m: &Matrix<f64, R, C, S>,
) -> Result<(), FilterError> {
    if m.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(FilterError::NonFinite(what))
    }
}

/// `(P + Pᵀ)/2`: entries (i, j) and (j, i) are the same sum, so the result is exactly symmetric.
fn symmetrise<N: Dim>(p: OMatrix<f64, N, N>) -> OMatrix<f64, N, N>
where
    DefaultAllocator: Allocator<N, N>,
{
    (&p + p.transpose()) * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::{
        DMatrix, DVector, Dyn, Matrix1, Matrix2, SMatrix, SVector, U1, U2, U4, U6, U15, Vector1,
        Vector2,
    };
    use proptest::prelude::*;
    use proptest::test_runner::RngSeed;

    /// Deterministic uniform numbers in [0, 1) (Knuth's MMIX LCG), so tests need no RNG crate.
    struct Lcg(u64);

    impl Lcg {
        fn next_f64(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }

        /// Roughly standard normal: sum of 12 uniforms minus 6.
        fn next_gauss(&mut self) -> f64 {
            (0..12).map(|_| self.next_f64()).sum::<f64>() - 6.0
        }
    }

    /// One full step: predict, innovation, update.
    fn step<N: Dim, M: Dim>(
        est: &StateEstimate<N>,
        trans: &impl TransitionModel<N>,
        obs: &impl ObservationModel<N, M>,
        z: &OVector<f64, M>,
    ) -> (StateEstimate<N>, Innovation<M>, Gain<N, M>)
    where
        DefaultAllocator: Allocator<N, N>
            + Allocator<N>
            + Allocator<M, N>
            + Allocator<N, M>
            + Allocator<M, M>
            + Allocator<M>,
    {
        let prior = predict(est, trans).unwrap();
        let innov = innovation(&prior, obs, z).unwrap();
        let (post, k) = update(&prior, obs, &innov).unwrap();
        (post, innov, k)
    }

    #[test]
    fn scalar_random_walk_matches_the_closed_form_recursion() {
        let (q, r) = (0.3, 2.0);
        let trans = LinearTransition::<U1> {
            f: Matrix1::new(1.0),
            q: Matrix1::new(q),
        };
        let obs = LinearObservation::<U1, U1> {
            h: Matrix1::new(1.0),
            r: Matrix1::new(r),
        };
        let mut est = StateEstimate::<U1> {
            x: Vector1::new(0.5),
            p: Matrix1::new(10.0),
        };
        let (mut x, mut p) = (0.5, 10.0);
        let mut rng = Lcg(1);
        let mut truth = 0.0;
        for _ in 0..50 {
            truth += q.sqrt() * rng.next_gauss();
            let z = truth + r.sqrt() * rng.next_gauss();
            let (post, innov, k) = step(&est, &trans, &obs, &Vector1::new(z));

            let p_minus = p + q;
            let gain = p_minus / (p_minus + r);
            let lambda = (z - x) * (z - x) / (p_minus + r);
            x += gain * (z - x);
            p = (1.0 - gain) * p_minus;

            assert_relative_eq!(k[0], gain, epsilon = 1e-12);
            assert_relative_eq!(
                innov.statistic,
                lambda,
                epsilon = 1e-12,
                max_relative = 1e-12
            );
            assert_relative_eq!(post.x[0], x, epsilon = 1e-12);
            assert_relative_eq!(post.p[(0, 0)], p, epsilon = 1e-12);
            assert_eq!(innov.dof(), 1);
            est = post;
        }
        // Converged to the steady-state Riccati solution, not stuck at P0.
        assert!(est.p[(0, 0)] < 1.0);
    }

    type M2 = [[f64; 2]; 2];

    fn mul2(a: M2, b: M2) -> M2 {
        let mut c = [[0.0; 2]; 2];
        for i in 0..2 {
            for j in 0..2 {
                c[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j];
            }
        }
        c
    }
    fn tr2(a: M2) -> M2 {
        [[a[0][0], a[1][0]], [a[0][1], a[1][1]]]
    }
    fn add2(a: M2, b: M2, sign: f64) -> M2 {
        [
            [a[0][0] + sign * b[0][0], a[0][1] + sign * b[0][1]],
            [a[1][0] + sign * b[1][0], a[1][1] + sign * b[1][1]],
        ]
    }
    fn mv2(a: M2, v: [f64; 2]) -> [f64; 2] {
        [
            a[0][0] * v[0] + a[0][1] * v[1],
            a[1][0] * v[0] + a[1][1] * v[1],
        ]
    }
    fn inv2(a: M2) -> M2 {
        let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
        [
            [a[1][1] / det, -a[0][1] / det],
            [-a[1][0] / det, a[0][0] / det],
        ]
    }
    fn to_m2(a: M2) -> Matrix2<f64> {
        Matrix2::new(a[0][0], a[0][1], a[1][0], a[1][1])
    }

    /// One step of the reference filter, and what it computed on the way.
    struct Reference {
        x: [f64; 2],
        p: M2,
        k: M2,
        res: [f64; 2],
        s: M2,
        si_r: [f64; 2],
        lambda: f64,
    }

    /// The reference: textbook form, explicit 2×2 inverse, P = (I − KH) P⁻.
    fn reference_step(
        (f, q): (M2, M2),
        (h, r): (M2, M2),
        (x, p): ([f64; 2], M2),
        z: [f64; 2],
    ) -> Reference {
        let xm = mv2(f, x);
        let pm = add2(mul2(mul2(f, p), tr2(f)), q, 1.0);
        let hx = mv2(h, xm);
        let res = [z[0] - hx[0], z[1] - hx[1]];
        let s = add2(mul2(mul2(h, pm), tr2(h)), r, 1.0);
        let s_inv = inv2(s);
        let k = mul2(mul2(pm, tr2(h)), s_inv);
        let kr = mv2(k, res);
        let si_r = mv2(s_inv, res);
        Reference {
            x: [xm[0] + kr[0], xm[1] + kr[1]],
            p: mul2(add2([[1.0, 0.0], [0.0, 1.0]], mul2(k, h), -1.0), pm),
            k,
            res,
            s,
            si_r,
            lambda: res[0] * si_r[0] + res[1] * si_r[1],
        }
    }

    impl Reference {
        /// The fixed-size filter's step agrees with this one.
        fn assert_matches(
            &self,
            post: &StateEstimate<U2>,
            innov: &Innovation<U2>,
            k: &Gain<U2, U2>,
        ) {
            let tol = 1e-10;
            assert_relative_eq!(
                post.x,
                Vector2::from(self.x),
                epsilon = tol,
                max_relative = tol
            );
            assert_relative_eq!(post.p, to_m2(self.p), epsilon = tol, max_relative = tol);
            assert_relative_eq!(*k, to_m2(self.k), epsilon = tol, max_relative = tol);
            assert_relative_eq!(innov.r, Vector2::from(self.res), epsilon = tol);
            assert_relative_eq!(
                innov.s,
                to_m2(self.s),
                epsilon = 1e-12,
                max_relative = 1e-12
            );
            assert_relative_eq!(
                innov.s_inv_r(),
                Vector2::from(self.si_r),
                epsilon = tol,
                max_relative = tol
            );
            assert_relative_eq!(
                innov.statistic,
                self.lambda,
                epsilon = tol,
                max_relative = tol
            );
        }
    }

    #[test]
    fn constant_velocity_fixed_and_dynamic_paths_agree_with_a_hand_written_reference() {
        let dt = 0.1;
        let qc = 0.5;
        let f: M2 = [[1.0, dt], [0.0, 1.0]];
        let q: M2 = [
            [qc * dt.powi(3) / 3.0, qc * dt * dt / 2.0],
            [qc * dt * dt / 2.0, qc * dt],
        ];
        // Position and a position/velocity mix, with correlated noise: S is a full 2×2.
        let h: M2 = [[1.0, 0.0], [0.3, 1.0]];
        let r: M2 = [[0.5, 0.1], [0.1, 0.2]];
        let (x0, p0): ([f64; 2], M2) = ([0.0, 1.0], [[5.0, 0.5], [0.5, 2.0]]);

        let s_trans = LinearTransition::<U2> {
            f: to_m2(f),
            q: to_m2(q),
        };
        let s_obs = LinearObservation::<U2, U2> {
            h: to_m2(h),
            r: to_m2(r),
        };
        let d = |m: Matrix2<f64>| DMatrix::from_column_slice(2, 2, m.as_slice());
        let d_trans = LinearTransition::<Dyn> {
            f: d(s_trans.f),
            q: d(s_trans.q),
        };
        let d_obs = LinearObservation::<Dyn, Dyn> {
            h: d(s_obs.h),
            r: d(s_obs.r),
        };
        let mut s_est = StateEstimate::<U2> {
            x: Vector2::from(x0),
            p: to_m2(p0),
        };
        let mut d_est = StateEstimate::<Dyn> {
            x: DVector::from_column_slice(&x0),
            p: d(to_m2(p0)),
        };
        let (mut x, mut p) = (x0, p0);

        let mut rng = Lcg(2024);
        let mut truth = [0.0, 1.0];
        for _ in 0..100 {
            truth = [truth[0] + dt * truth[1], truth[1] + 0.2 * rng.next_gauss()];
            let zt = mv2(h, truth);
            let z = [zt[0] + rng.next_gauss(), zt[1] + 0.4 * rng.next_gauss()];

            let (s_post, s_innov, s_k) = step(&s_est, &s_trans, &s_obs, &Vector2::from(z));
            let (d_post, d_innov, d_k) =
                step(&d_est, &d_trans, &d_obs, &DVector::from_column_slice(&z));

            // Same algorithm, two storages: the numbers must not drift apart.
            for (a, b) in [
                (s_post.x.as_slice(), d_post.x.as_slice()),
                (s_post.p.as_slice(), d_post.p.as_slice()),
                (s_k.as_slice(), d_k.as_slice()),
            ] {
                for (a, b) in a.iter().zip(b) {
                    assert_relative_eq!(*a, *b, epsilon = 1e-12);
                }
            }
            assert_relative_eq!(s_innov.statistic, d_innov.statistic, epsilon = 1e-12);

            let reference = reference_step((f, q), (h, r), (x, p), z);
            reference.assert_matches(&s_post, &s_innov, &s_k);
            (x, p) = (reference.x, reference.p);
            assert_eq!((s_innov.dof(), d_innov.dof()), (2, 2));

            s_est = s_post;
            d_est = d_post;
        }
    }

    /// Cross-check against filterpy 2.0.0 (`KalmanFilter.update`, Joseph form), numpy 2.4.
    /// The values below are printed by this script:
    ///
    /// ```python
    /// import numpy as np
    /// from filterpy.kalman import KalmanFilter
    /// dt = 0.5
    /// kf = KalmanFilter(dim_x=4, dim_z=2, dim_u=2)
    /// kf.F = np.array([[1, dt, 0, 0], [0, 1, 0, 0], [0, 0, 1, dt], [0, 0, 0, 1.0]])
    /// kf.B = np.array([[0.5 * dt * dt, 0], [dt, 0], [0, 0.5 * dt * dt], [0, dt]])
    /// kf.H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    /// kf.Q = np.array([[0.01, 0.02, 0, 0], [0.02, 0.05, 0, 0],
    ///                  [0, 0, 0.02, 0.01], [0, 0, 0.01, 0.03]])
    /// kf.R = np.array([[0.25, 0.05], [0.05, 0.16]])
    /// kf.x = np.array([[0.0], [1.0], [0.0], [0.5]])
    /// kf.P = np.array([[4.0, 0.5, 0, 0], [0.5, 1.0, 0, 0], [0, 0, 4.0, 0.3], [0, 0, 0.3, 1.0]])
    /// lam = []
    /// for k in range(1, 21):
    ///     u = np.array([[0.1 * ((k % 3) - 1)], [-0.05 * ((k % 4) - 2)]])
    ///     z = np.array([[k * 0.5 + ((k * 7) % 5 - 2) * 0.3],
    ///                   [0.25 * k - ((k * 3) % 7 - 3) * 0.2]])
    ///     kf.predict(u=u)
    ///     kf.update(z)  # filterpy's default update is the Joseph form
    ///     lam.append(kf.mahalanobis ** 2)
    /// print([repr(float(v)) for v in kf.x.ravel()])
    /// print([[repr(float(v)) for v in row] for row in kf.P])
    /// print([repr(float(v)) for v in lam])
    /// ```
    #[test]
    fn four_state_filter_with_control_matches_filterpy() {
        let dt = 0.5;
        #[rustfmt::skip]
        let trans = LinearTransition::<U4> {
            f: SMatrix::<f64, 4, 4>::new(
                1.0, dt, 0.0, 0.0,
                0.0, 1.0, 0.0, 0.0,
                0.0, 0.0, 1.0, dt,
                0.0, 0.0, 0.0, 1.0,
            ),
            q: SMatrix::<f64, 4, 4>::new(
                0.01, 0.02, 0.0, 0.0,
                0.02, 0.05, 0.0, 0.0,
                0.0, 0.0, 0.02, 0.01,
                0.0, 0.0, 0.01, 0.03,
            ),
        };
        #[rustfmt::skip]
        let b = SMatrix::<f64, 4, 2>::new(
            0.5 * dt * dt, 0.0,
            dt, 0.0,
            0.0, 0.5 * dt * dt,
            0.0, dt,
        );
        #[rustfmt::skip]
        let obs = LinearObservation::<U4, U2> {
            h: SMatrix::<f64, 2, 4>::new(
                1.0, 0.0, 0.0, 0.0,
                0.0, 0.0, 1.0, 0.0,
            ),
            r: Matrix2::new(0.25, 0.05, 0.05, 0.16),
        };
        #[rustfmt::skip]
        let mut est = StateEstimate::<U4> {
            x: SVector::<f64, 4>::new(0.0, 1.0, 0.0, 0.5),
            p: SMatrix::<f64, 4, 4>::new(
                4.0, 0.5, 0.0, 0.0,
                0.5, 1.0, 0.0, 0.0,
                0.0, 0.0, 4.0, 0.3,
                0.0, 0.0, 0.3, 1.0,
            ),
        };
        let mut lambdas = Vec::new();
        for k in 1..=20_i32 {
            let u = Vector2::new(0.1 * f64::from(k % 3 - 1), -0.05 * f64::from(k % 4 - 2));
            let z = Vector2::new(
                f64::from(k) * 0.5 + f64::from((k * 7) % 5 - 2) * 0.3,
                0.25 * f64::from(k) - f64::from((k * 3) % 7 - 3) * 0.2,
            );
            let prior = predict_with_control(&est, &trans, &b, &u).unwrap();
            let innov = innovation(&prior, &obs, &z).unwrap();
            est = update(&prior, &obs, &innov).unwrap().0;
            lambdas.push(innov.statistic);
        }

        let x = SVector::<f64, 4>::new(
            9.800985313928962,
            0.863787351098153,
            4.976599183028291,
            0.5499330570876481,
        );
        #[rustfmt::skip]
        let p = SMatrix::<f64, 4, 4>::new(
            0.12209787016761023, 0.07915959629163188, 0.020450072158812282, 0.00879438777554495,
            0.07915959629163186, 0.11298504079191038, 0.009840916854412653, 0.006791580692792756,
            0.020450072158812276, 0.009840916854412653, 0.08235550870352981, 0.047657759374633235,
            0.00879438777554495, 0.006791580692792753, 0.04765775937463324, 0.08284222469184846,
        );
        assert_relative_eq!(est.x, x, epsilon = 1e-9);
        assert_relative_eq!(est.p, p, epsilon = 1e-9);
        // λ after steps 2, 3, 10 and 20.
        assert_relative_eq!(lambdas[1], 1.2999145586750775, epsilon = 1e-9);
        assert_relative_eq!(lambdas[2], 3.4284091709828846, epsilon = 1e-9);
        assert_relative_eq!(lambdas[9], 2.338735363029235, epsilon = 1e-9);
        assert_relative_eq!(lambdas[19], 1.3566623849023003, epsilon = 1e-9);
    }

    /// `A Aᵀ + floor·I`: symmetric positive definite for any square `A`.
    fn spd(a: &[f64], n: usize, scale: f64, floor: f64) -> DMatrix<f64> {
        let a = DMatrix::from_row_slice(n, n, a);
        (&a * a.transpose()) * scale + DMatrix::identity(n, n) * floor
    }

    /// n, m and the raw entries of P0, Q, R, F, H, z, x0 for one random model.
    #[allow(clippy::type_complexity)]
    fn random_model() -> impl Strategy<
        Value = (
            usize,
            usize,
            (Vec<f64>, Vec<f64>, Vec<f64>),
            (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>),
        ),
    > {
        (1usize..=6, 1usize..=4).prop_flat_map(|(n, m)| {
            let v = move |len: usize| prop::collection::vec(-1.0f64..1.0, len);
            (
                Just(n),
                Just(m),
                (v(n * n), v(n * n), v(m * m)),
                (v(n * n), v(m * n), v(m), v(n)),
            )
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig {
            cases: 256,
            rng_seed: RngSeed::Fixed(0x6e61_7667),
            failure_persistence: None,
            ..ProptestConfig::default()
        })]

        #[test]
        fn covariance_stays_symmetric_positive_definite_and_shrinks_on_update(
            (n, m, (a_p, a_q, a_r), (f, h, z, x0)) in random_model()
        ) {
            let est = StateEstimate::<Dyn> {
                x: DVector::from_vec(x0) * 5.0,
                p: spd(&a_p, n, 4.0, 1e-2),
            };
            let trans = LinearTransition::<Dyn> {
                f: DMatrix::from_row_slice(n, n, &f) * 1.5,
                q: spd(&a_q, n, 0.5, 1e-3),
            };
            let obs = LinearObservation::<Dyn, Dyn> {
                h: DMatrix::from_row_slice(m, n, &h) * 3.0,
                r: spd(&a_r, m, 1.0, 1e-2),
            };
            let prior = predict(&est, &trans).unwrap();
            prop_assert_eq!(&prior.p, &prior.p.transpose());
            let innov = innovation(&prior, &obs, &(DVector::from_vec(z) * 10.0)).unwrap();
            prop_assert!(innov.statistic >= 0.0);
            let (post, _) = update(&prior, &obs, &innov).unwrap();

            prop_assert_eq!(&post.p, &post.p.transpose());
            prop_assert!(Cholesky::new(post.p.clone()).is_some());
            let scale = prior.p.trace().max(1.0);
            prop_assert!(post.p.trace() <= prior.p.trace() + 1e-9 * scale);
            // Stronger than the trace: P⁻ − P⁺ is positive semi-definite (information only grows).
            let min_eig = (&prior.p - &post.p).symmetric_eigenvalues().min();
            prop_assert!(min_eig >= -1e-9 * scale, "min eigenvalue of P⁻ − P⁺ = {min_eig}");
        }
    }

    fn dynamic_model() -> (
        StateEstimate<Dyn>,
        LinearTransition<Dyn>,
        LinearObservation<Dyn, Dyn>,
    ) {
        let est = StateEstimate::<Dyn> {
            x: DVector::from_vec(vec![1.0, -1.0]),
            p: DMatrix::identity(2, 2) * 0.1,
        };
        let trans = LinearTransition::<Dyn> {
            f: DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 0.0, 1.0]),
            q: DMatrix::identity(2, 2) * 0.01,
        };
        let obs = LinearObservation::<Dyn, Dyn> {
            h: DMatrix::identity(2, 2),
            r: DMatrix::identity(2, 2),
        };
        (est, trans, obs)
    }

    #[test]
    fn indefinite_innovation_covariance_is_an_error_and_leaves_the_estimate_unchanged() {
        let (est, _, mut obs) = dynamic_model();
        obs.r = -DMatrix::identity(2, 2); // S = 0.1 I − I is negative definite
        let before = est.clone();
        let err = innovation(&est, &obs, &DVector::from_vec(vec![1.0, 2.0])).unwrap_err();
        assert_eq!(err, FilterError::NotPositiveDefinite);
        assert_eq!(est, before);
    }

    #[test]
    fn nan_in_the_measurement_is_a_non_finite_error() {
        let (est, _, obs) = dynamic_model();
        let before = est.clone();
        let z = DVector::from_vec(vec![1.0, f64::NAN]);
        let err = innovation(&est, &obs, &z).unwrap_err();
        assert_eq!(err, FilterError::NonFinite("measurement"));
        assert_eq!(err.to_string(), "non-finite value in measurement");
        assert_eq!(est, before);
    }

    #[test]
    fn non_finite_model_values_are_errors_in_every_step() {
        let (est, trans, obs) = dynamic_model();
        let before = est.clone();

        let mut bad_trans = trans.clone();
        bad_trans.q[(1, 1)] = f64::INFINITY;
        let err = predict(&est, &bad_trans).unwrap_err();
        assert_eq!(err, FilterError::NonFinite("predicted covariance"));

        let b = DMatrix::identity(2, 1);
        let u = DVector::from_vec(vec![f64::NAN]);
        let err = predict_with_control(&est, &trans, &b, &u).unwrap_err();
        assert_eq!(err, FilterError::NonFinite("control input"));

        let mut bad_obs = obs.clone();
        bad_obs.r[(0, 0)] = f64::INFINITY;
        let err = innovation(&est, &bad_obs, &DVector::from_vec(vec![1.0, 2.0])).unwrap_err();
        assert_eq!(err, FilterError::NonFinite("innovation covariance"));

        // An innovation from a sound model, applied with a broken R: K R Kᵀ is not finite.
        let innov = innovation(&est, &obs, &DVector::from_vec(vec![1.0, 2.0])).unwrap();
        let err = update(&est, &bad_obs, &innov).unwrap_err();
        assert_eq!(err, FilterError::NonFinite("updated covariance"));
        assert_eq!(est, before);
    }

    #[test]
    fn wrong_size_dynamic_matrices_are_dimension_errors() {
        let (est, trans, obs) = dynamic_model();
        let before = est.clone();
        let z = DVector::from_vec(vec![1.0, 2.0]);

        let mut wide = obs.clone();
        wide.h = DMatrix::zeros(2, 3);
        let err = innovation(&est, &wide, &z).unwrap_err();
        let want = FilterError::Dimension {
            what: "observation matrix H",
            got_rows: 2,
            got_cols: 3,
            want_rows: 2,
            want_cols: 2,
        };
        assert_eq!(err, want);
        assert_eq!(
            err.to_string(),
            "dimension mismatch: observation matrix H is 2x3, expected 2x2"
        );

        let mut small_f = trans.clone();
        small_f.f = DMatrix::identity(3, 3);
        assert!(matches!(
            predict(&est, &small_f),
            Err(FilterError::Dimension {
                what: "transition matrix F",
                ..
            })
        ));

        let b = DMatrix::identity(3, 1);
        let u = DVector::from_vec(vec![1.0]);
        assert!(matches!(
            predict_with_control(&est, &trans, &b, &u),
            Err(FilterError::Dimension {
                what: "control matrix B",
                ..
            })
        ));

        // An innovation of a 2-vector handed to a 1-row observation model.
        let innov = innovation(&est, &obs, &z).unwrap();
        let one_row = LinearObservation::<Dyn, Dyn> {
            h: DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            r: DMatrix::identity(1, 1),
        };
        assert!(matches!(
            update(&est, &one_row, &innov),
            Err(FilterError::Dimension {
                what: "observation matrix H",
                ..
            })
        ));

        let mut ragged = est.clone();
        ragged.p = DMatrix::identity(3, 3);
        assert!(matches!(
            predict(&ragged, &trans),
            Err(FilterError::Dimension {
                what: "covariance P",
                ..
            })
        ));
        assert_eq!(est, before);
    }

    #[test]
    fn innovation_exposes_its_cholesky_factor_and_s_inverse_r() {
        let (est, _, obs) = dynamic_model();
        let innov = innovation(&est, &obs, &DVector::from_vec(vec![0.5, -2.0])).unwrap();
        let l = innov.s_chol.l();
        assert_relative_eq!(&l * l.transpose(), innov.s.clone(), epsilon = 1e-14);
        let via_lu = innov.s.clone().lu().solve(&innov.r).unwrap();
        assert_relative_eq!(innov.s_inv_r(), via_lu, epsilon = 1e-14);
        assert_relative_eq!(innov.statistic, innov.r.dot(&via_lu), epsilon = 1e-14);
        assert_eq!(innov.dof(), 2);
    }

    #[test]
    fn fifteen_state_six_measurement_fixed_size_filter_runs_without_heap_storage() {
        // Matrices are stored inline (no pointer to a heap buffer): the INS sizes stay on the stack.
        assert_eq!(
            std::mem::size_of::<StateEstimate<U15>>(),
            (15 + 15 * 15) * size_of::<f64>()
        );

        let dt = 0.1;
        let mut f = SMatrix::<f64, 15, 15>::identity();
        for i in 0..3 {
            f[(6 + i, 3 + i)] = dt; // δṗ = δv
            f[(3 + i, 12 + i)] = dt; // accelerometer bias drives δv
            f[(i, 9 + i)] = -dt; // gyro bias drives φ
        }
        let trans = LinearTransition::<U15> {
            f,
            q: SMatrix::<f64, 15, 15>::from_diagonal_element(1e-4),
        };
        let mut h = SMatrix::<f64, 6, 15>::zeros();
        for i in 0..6 {
            h[(i, 3 + i)] = 1.0; // GNSS velocity then position
        }
        let obs = LinearObservation::<U15, U6> {
            h,
            r: SMatrix::<f64, 6, 6>::from_diagonal(&SVector::from([
                0.01, 0.01, 0.01, 100.0, 100.0, 100.0,
            ])),
        };
        let mut est = StateEstimate::<U15> {
            x: SVector::zeros(),
            p: SMatrix::from_diagonal_element(1.0),
        };
        let mut rng = Lcg(15);
        for _ in 0..20 {
            let z = SVector::<f64, 6>::from_fn(|i, _| {
                let sigma = if i < 3 { 0.1 } else { 10.0 };
                sigma * rng.next_gauss()
            });
            let (post, innov, k) = step(&est, &trans, &obs, &z);
            assert_eq!(post.p, post.p.transpose());
            assert!(Cholesky::new(post.p).is_some());
            assert_eq!(innov.dof(), 6);
            assert_eq!(k.shape(), (15, 6));
            est = post;
        }
        // Measured states (velocity, position) have tightened; the unobserved roll/pitch/yaw
        // errors have only grown with Q because nothing couples them to the measurements here.
        assert!(est.p[(3, 3)] < 0.02 && est.p[(6, 6)] < 100.0);
        assert!(est.p[(0, 0)] > 1.0);
    }
}
