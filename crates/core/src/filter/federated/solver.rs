//! The numerical kernels of the federated filter ([`super`]): the structured prediction
//! `Φ P Φᵀ + Q`, the local χ² test against a shared prior, the Joseph-form update in
//! `O(15²·M)`, independent-estimate fusion and the HPL slope. [`super::FederatedFilter`]
//! sequences them each epoch; this file only computes.

use nalgebra::{Const, Matrix, RawStorage, SMatrix, SVector, U15};

use super::ErrorEstimate;
use crate::detect::hpl;
use crate::filter::aiding::AidMeasurement;
use crate::filter::ins::{ErrorMatrix, ErrorVector, N, POS};
use crate::filter::kalman::{
    self, FilterError, LinearObservation, LinearTransition, StateEstimate,
};
#[cfg(target_arch = "x86_64")]
use crate::simd::avx2;

/// Defines `$name`, which runs `$body` compiled a second time for AVX2 (`$avx2`) when
/// [`avx2`] allows it and the baseline build of `$body` otherwise. `$body` is
/// `#[inline(always)]`, so each wrapper holds its own build of it.
macro_rules! avx2_dispatch {
    (
        $(#[$doc:meta])*
        fn $name:ident $(<const $c:ident: usize>)? ($($arg:ident: $ty:ty),* $(,)?) -> $ret:ty
        => $avx2:ident, $body:ident
    ) => {
        $(#[$doc])*
        pub(super) fn $name $(<const $c: usize>)? ($($arg: $ty),*) -> $ret {
            #[cfg(target_arch = "x86_64")]
            if avx2() {
                // SAFETY: the CPU supports AVX2 (checked just above).
                return unsafe { $avx2($($arg),*) };
            }
            $body($($arg),*)
        }

        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        fn $avx2 $(<const $c: usize>)? ($($arg: $ty),*) -> $ret {
            $body($($arg),*)
        }
    };
}

/// `(x, P/β)`.
pub(super) fn scaled(est: &ErrorEstimate, beta: f64) -> ErrorEstimate {
    StateEstimate {
        x: est.x,
        p: est.p / beta,
    }
}

/// `(P + Pᵀ)/2`, exactly symmetric.
pub(super) fn symmetrise<const R: usize>(p: &SMatrix<f64, R, R>) -> SMatrix<f64, R, R> {
    (p + p.transpose()) * 0.5
}

/// `Err(NonFinite(what))` unless every entry is finite. The entries are all read (no early
/// exit), which lets the check vectorise: it runs on every covariance the step writes.
#[inline(always)]
pub(super) fn finite<const R: usize, const C: usize>(
    what: &'static str,
    m: &SMatrix<f64, R, C>,
) -> Result<(), FilterError> {
    if m.as_slice().iter().fold(true, |ok, v| ok & v.is_finite()) {
        Ok(())
    } else {
        Err(FilterError::NonFinite(what))
    }
}

/// `A B` in nalgebra's order of operations (column by column; each entry the `k = 0`
/// product, then `+= a_ik b_kj` for `k` ascending), so the result is nalgebra's `a * b` to
/// the bit. Inlined into its caller, so that the caller's AVX2 build vectorises it too
/// (nalgebra's product is a separate function there, compiled for the baseline).
#[inline(always)]
pub(super) fn product<const R: usize, const K: usize, const C: usize, SA, SB>(
    a: &Matrix<f64, Const<R>, Const<K>, SA>,
    b: &Matrix<f64, Const<K>, Const<C>, SB>,
) -> SMatrix<f64, R, C>
where
    SA: RawStorage<f64, Const<R>, Const<K>>,
    SB: RawStorage<f64, Const<K>, Const<C>>,
{
    const { assert!(K >= 1, "an empty product") };
    let mut out = SMatrix::<f64, R, C>::zeros();
    for j in 0..C {
        let b0 = b[(0, j)];
        for i in 0..R {
            out[(i, j)] = a[(i, 0)] * b0;
        }
        for k in 1..K {
            let bkj = b[(k, j)];
            for i in 0..R {
                out[(i, j)] += a[(i, k)] * bkj;
            }
        }
    }
    out
}

avx2_dispatch! {
    /// [`kalman::predict`] into `out`, with the INS transition's structure used when `Φ` has
    /// it. The bias rows of an INS `Φ` are `[0 I]` (biases are random constants), so
    /// `W = P Φᵀ` needs only its first 9 columns and `Φ P Φᵀ = Φ W` only its top-left 9 × 9
    /// block, of which the upper triangle is computed and mirrored (exactly symmetric); the
    /// bias rows and columns are `W`'s and `P`'s own. Both products skip the zeros of `Φ`'s
    /// navigation rows (its zero 3 × 3 blocks: 84 of 135 entries are non-zero) and run on
    /// columns padded to whole vectors. Any other `Φ` takes the generic path. On `Err`,
    /// `out` may hold a partial result. Runs the AVX2 build when the CPU has it ([`avx2`]).
    fn predict_into(
        est: &ErrorEstimate,
        trans: &LinearTransition<U15>,
        out: &mut ErrorEstimate,
    ) -> Result<(), FilterError>
    => predict_into_avx2, predict_into_body
}

/// [`predict_into`] in whichever build its caller has.
#[inline(always)]
pub(super) fn predict_into_body(
    est: &ErrorEstimate,
    trans: &LinearTransition<U15>,
    out: &mut ErrorEstimate,
) -> Result<(), FilterError> {
    /// A column padded to 16 entries: four whole AVX2 vectors, no remainder loop.
    type Column = [f64; 16];
    let phi = &trans.f;
    // Column-major: rows 9..15 of column c are as_slice()[15c + 9 .. 15c + 15].
    let structured = phi.as_slice().chunks_exact(N).enumerate().all(|(c, col)| {
        col[9..]
            .iter()
            .enumerate()
            .all(|(k, &v)| v == if c == 9 + k { 1.0 } else { 0.0 })
    });
    if !structured {
        *out = kalman::predict(est, trans)?;
        return Ok(());
    }
    // P in padded columns (row 15 zero).
    let mut p: [Column; N] = [[0.0; 16]; N];
    for (j, col) in p.iter_mut().enumerate() {
        col[..N].copy_from_slice(&est.p.as_slice()[N * j..N * (j + 1)]);
    }
    // W = P Φᵀ, its first 9 columns (the rest are P's): W[:, i] = Σ_l P[:, l] Φ[i, l] over
    // the non-zero entries of Φ's row i (84 of 135 for an INS Φ: its zero blocks).
    // (Loops, not `array::from_fn`: that is a function of its own, outside the AVX2 build.)
    let mut w: [Column; 9] = [[0.0; 16]; 9];
    let mut row = [0.0; N];
    for (i, wi) in w.iter_mut().enumerate() {
        for (l, v) in row.iter_mut().enumerate() {
            *v = phi[(i, l)];
        }
        *wi = weighted_sum::<16, 16>(&p, &row);
    }
    // Φ's navigation rows, its columns padded to 12 entries (three vectors; rows 9..12 zero).
    let mut phi_nav = [[0.0; 12]; N];
    for (k, col) in phi_nav.iter_mut().enumerate() {
        col[..9].copy_from_slice(&phi.as_slice()[N * k..N * k + 9]);
    }
    // Φ P Φᵀ = Φ W; its top-left 9 × 9 block in column j, rows 0..=j only (rounded up to
    // whole vectors), mirrored below: exactly symmetric.
    let mut top = [[0.0; 12]; 9];
    for (j, tj) in top.iter_mut().enumerate() {
        let weights = &w[j];
        match j {
            0..4 => tj[..4].copy_from_slice(&weighted_sum::<12, 4>(&phi_nav, weights)),
            4..8 => tj[..8].copy_from_slice(&weighted_sum::<12, 8>(&phi_nav, weights)),
            _ => *tj = weighted_sum::<12, 12>(&phi_nav, weights),
        }
    }
    // Φ x: the navigation rows from Φ's padded columns, the bias rows x's own.
    let x_nav = weighted_sum::<12, 12>(&phi_nav, est.x.as_slice());
    out.x.as_mut_slice()[..9].copy_from_slice(&x_nav[..9]);
    out.x.as_mut_slice()[9..].copy_from_slice(&est.x.as_slice()[9..]);
    // `(Q + Qᵀ)/2` added entry by entry.
    let q = &trans.q;
    let half_q = |i: usize, j: usize| (q[(i, j)] + q[(j, i)]) * 0.5;
    for (j, (tj, wj)) in top.iter().zip(&w).enumerate() {
        for (i, t) in tj.iter().enumerate().take(j + 1) {
            let v = t + half_q(i, j);
            out.p[(i, j)] = v;
            out.p[(j, i)] = v;
        }
        // The bias rows of column j, and so of row j: W's.
        for (i, wij) in wj.iter().enumerate().take(N).skip(9) {
            let v = wij + half_q(i, j);
            out.p[(i, j)] = v;
            out.p[(j, i)] = v;
        }
    }
    for (j, pj) in p.iter().enumerate().skip(9) {
        for (i, pi) in p.iter().enumerate().skip(9) {
            out.p[(i, j)] = (pj[i] + pi[j]) * 0.5 + half_q(i, j);
        }
    }
    finite("predicted state", &out.x)?;
    finite("predicted covariance", &out.p)?;
    Ok(())
}

/// `Σ_k c_k[..R] · w_k` over the non-zero weights (the first 15 of `weights`), in `k` order,
/// the sum kept in registers (`R` a multiple of 4: whole AVX2 vectors).
#[inline(always)]
fn weighted_sum<const C: usize, const R: usize>(
    columns: &[[f64; C]; N],
    weights: &[f64],
) -> [f64; R] {
    let mut acc = [0.0; R];
    for (column, &w) in columns.iter().zip(weights) {
        if w != 0.0 {
            for r in 0..R {
                acc[r] += column[r] * w;
            }
        }
    }
    acc
}

/// True when `H`'s bias columns 9..15 are zero (every aid's H): column-major, they are the
/// last `6·M` entries.
#[inline(always)]
pub(super) fn bias_columns_zero<const M: usize>(h: &SMatrix<f64, M, N>) -> bool {
    h.as_slice()[9 * M..].iter().all(|&v| v == 0.0)
}

/// `H A` for an `H` whose bias columns are zero (every aid's: [`bias_columns_zero`]),
/// skipping `H`'s zeros: an aid's row selects one error state, or three for the DVL's
/// attitude coupling. The sum runs over `H`'s columns in ascending order, as the dense
/// product's does, so the result is the dense one (to the sign of a zero).
#[inline(always)]
fn sparse_h_times<const M: usize, const C: usize, S: RawStorage<f64, Const<N>, Const<C>>>(
    h: &SMatrix<f64, M, N>,
    a: &Matrix<f64, Const<N>, Const<C>, S>,
) -> SMatrix<f64, M, C> {
    let mut out = SMatrix::<f64, M, C>::zeros();
    for k in 0..9 {
        for i in 0..M {
            let v = h[(i, k)];
            if v != 0.0 {
                for j in 0..C {
                    out[(i, j)] += v * a[(k, j)];
                }
            }
        }
    }
    out
}

/// `A Hᵀ` for an `H` whose bias columns are zero, skipping `H`'s zeros (as
/// [`sparse_h_times`]); only `A`'s first 9 columns are read, so `A` may have just those.
#[inline(always)]
fn sparse_times_h_transpose<const R: usize, const C: usize, const M: usize>(
    a: &SMatrix<f64, R, C>,
    h: &SMatrix<f64, M, N>,
) -> SMatrix<f64, R, M> {
    const { assert!(C >= 9, "A must hold H's nine non-bias columns") };
    let mut out = SMatrix::<f64, R, M>::zeros();
    for k in 0..9 {
        for l in 0..M {
            let v = h[(l, k)];
            if v != 0.0 {
                for i in 0..R {
                    out[(i, l)] += a[(i, k)] * v;
                }
            }
        }
    }
    out
}

avx2_dispatch! {
    /// The local test of `m` against the prior `(x, P/β)` without forming `P/β`:
    /// `r = z − H x`, `S = H P Hᵀ / β + R`, `λ = |L⁻¹ r|²` with `S = L Lᵀ` — what
    /// [`kalman::innovation`] computes for that prior. Returns `λ`, the diagonal of `S⁻¹`
    /// (first M entries), which the HPL slope needs, and the normalised innovation
    /// `ν = L⁻¹ r` (first M entries; `‖ν‖² = λ`), which the consistency diagnostics and the
    /// drift and stuck tests take (docs/methods.md §M22, §M23). Runs the AVX2 build when the
    /// CPU has it ([`avx2`]).
    fn share_test<const M: usize>(
        prior: &ErrorEstimate,
        beta: f64,
        m: &AidMeasurement<M>,
    ) -> Result<ShareTest, FilterError>
    => share_test_avx2, share_test_body
}

/// [`share_test`] in whichever build its caller has.
#[inline(always)]
pub(super) fn share_test_body<const M: usize>(
    prior: &ErrorEstimate,
    beta: f64,
    m: &AidMeasurement<M>,
) -> Result<ShareTest, FilterError> {
    let h = &m.obs.h;
    let (r, hph) = if bias_columns_zero(h) {
        // H P Hᵀ reads only H P's first 9 columns (H's bias columns are zero).
        let hp = sparse_h_times(h, &prior.p.fixed_columns::<9>(0));
        (
            m.z - sparse_h_times(h, &prior.x),
            sparse_times_h_transpose(&hp, h),
        )
    } else {
        (m.z - h * prior.x, (h * prior.p) * h.transpose())
    };
    let s = symmetrise(&(hph / beta + m.obs.r));
    finite("innovation", &r)?;
    finite("innovation covariance", &s)?;
    let l_inv = inverse_cholesky_factor(&s).ok_or(FilterError::NotPositiveDefinite)?;
    // λ = rᵀ (L Lᵀ)⁻¹ r = |L⁻¹ r|², and (S⁻¹)_ii = Σ_k (L⁻¹)_ki² (column norms of L⁻¹).
    let nu_m = product(&l_inv, &r);
    let statistic = nu_m.norm_squared();
    if !statistic.is_finite() {
        return Err(FilterError::NonFinite("chi-square statistic"));
    }
    let mut s_inv = SVector::<f64, 6>::zeros();
    let mut nu = SVector::<f64, 6>::zeros();
    for i in 0..M {
        s_inv[i] = l_inv.column(i).norm_squared();
        nu[i] = nu_m[i];
    }
    Ok(ShareTest {
        statistic,
        s_inv,
        nu,
    })
}

/// What [`share_test`] computes: fixed-size, so the test allocates nothing.
#[derive(Debug, Clone, Copy)]
pub(super) struct ShareTest {
    /// `λ = rᵀ S⁻¹ r`.
    pub(super) statistic: f64,
    /// Diagonal of `S⁻¹`, first M entries.
    pub(super) s_inv: SVector<f64, 6>,
    /// `ν = L⁻¹ r`, first M entries.
    pub(super) nu: SVector<f64, 6>,
}

/// `L⁻¹` for the Cholesky factor `S = L Lᵀ` of a small SPD matrix, by plain loops (for
/// `M ≤ 6` these beat the general factor-and-solve routines several times over); `None`
/// unless `S` is positive definite.
#[inline(always)]
pub(super) fn inverse_cholesky_factor<const M: usize>(
    s: &SMatrix<f64, M, M>,
) -> Option<SMatrix<f64, M, M>> {
    let mut l = SMatrix::<f64, M, M>::zeros();
    for j in 0..M {
        let mut d = s[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        let ljj = d.sqrt();
        l[(j, j)] = ljj;
        for i in j + 1..M {
            let mut v = s[(i, j)];
            for k in 0..j {
                v -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = v / ljj;
        }
    }
    // Forward substitution, one column of L⁻¹ at a time.
    let mut inv = SMatrix::<f64, M, M>::zeros();
    for j in 0..M {
        inv[(j, j)] = 1.0 / l[(j, j)];
        for i in j + 1..M {
            let mut v = 0.0;
            for k in j..i {
                v -= l[(i, k)] * inv[(k, j)];
            }
            inv[(i, j)] = v / l[(i, i)];
        }
    }
    Some(inv)
}

/// `L A` for a lower-triangular `L`, skipping its upper zeros; each sum runs over `k`
/// ascending, as the dense product's, so the result is the dense one (to the sign of a
/// zero).
#[inline(always)]
fn lower_times<const M: usize, const C: usize>(
    l: &SMatrix<f64, M, M>,
    a: &SMatrix<f64, M, C>,
) -> SMatrix<f64, M, C> {
    let mut out = SMatrix::<f64, M, C>::zeros();
    for j in 0..C {
        for k in 0..M {
            let akj = a[(k, j)];
            for i in k..M {
                out[(i, j)] += l[(i, k)] * akj;
            }
        }
    }
    out
}

/// `Lᵀ A` for a lower-triangular `L`, skipping `Lᵀ`'s lower zeros (as [`lower_times`]).
#[inline(always)]
fn lower_transpose_times<const M: usize, const C: usize>(
    l: &SMatrix<f64, M, M>,
    a: &SMatrix<f64, M, C>,
) -> SMatrix<f64, M, C> {
    let mut out = SMatrix::<f64, M, C>::zeros();
    for j in 0..C {
        for i in 0..M {
            let mut sum = 0.0;
            for k in i..M {
                sum += l[(k, i)] * a[(k, j)];
            }
            out[(i, j)] = sum;
        }
    }
    out
}

avx2_dispatch! {
    /// The Kalman update of `est` by `m`, in place, with the Joseph form written out. With
    /// `S = HPHᵀ + R`, `Kᵀ = S⁻¹ H P` and `U = HP − ½ S Kᵀ`:
    /// `(I − KH) P (I − KH)ᵀ + K R Kᵀ = P − KHP − (KHP)ᵀ + K S Kᵀ = P − (K U + Uᵀ Kᵀ)` — the
    /// same expression as [`kalman::update`]'s (first-order insensitive to errors in K, exactly
    /// symmetric) for about `15²·M` multiplications instead of `2·15³`. On `Err`, `est` may be
    /// partly updated (the caller discards it). Runs the AVX2 build when the CPU has it
    /// ([`avx2`]).
    fn joseph_update<const M: usize>(
        est: &mut ErrorEstimate,
        m: &AidMeasurement<M>,
    ) -> Result<(), FilterError>
    => joseph_update_avx2, joseph_update_body
}

/// [`joseph_update`] in whichever build its caller has.
#[inline(always)]
pub(super) fn joseph_update_body<const M: usize>(
    est: &mut ErrorEstimate,
    m: &AidMeasurement<M>,
) -> Result<(), FilterError> {
    let h = &m.obs.h;
    // H P, turned into U in place below (no tuple of products moved out of a branch).
    let sparse = bias_columns_zero(h);
    if sparse && diagonal(&m.obs.r) {
        return sequential_update(est, m);
    }
    let mut u = if sparse {
        sparse_h_times(h, &est.p)
    } else {
        h * est.p
    };
    let hph = if sparse {
        sparse_times_h_transpose(&u, h)
    } else {
        u * h.transpose()
    };
    let r = m.z
        - if sparse {
            sparse_h_times(h, &est.x)
        } else {
            h * est.x
        };
    let s = symmetrise(&(hph + m.obs.r));
    finite("innovation", &r)?;
    finite("innovation covariance", &s)?;
    // Kᵀ = S⁻¹ (H P): S is M × M and well conditioned (R bounds it below), so its inverse
    // S⁻¹ = L⁻ᵀ L⁻¹ costs less than 15 triangular solves and loses nothing.
    let l_inv = inverse_cholesky_factor(&s).ok_or(FilterError::NotPositiveDefinite)?;
    let kt = lower_transpose_times(&l_inv, &lower_times(&l_inv, &u));
    finite("gain", &kt)?;
    let skt = product(&s, &kt);
    for j in 0..N {
        for i in 0..M {
            u[(i, j)] -= skt[(i, j)] * 0.5;
        }
    }
    let k = kt.transpose();
    let ktu = product(&k, &u);
    est.x += product(&k, &r);
    // P − (K U + (K U)ᵀ), entry by entry: the same sums without the transpose's copy.
    for j in 0..N {
        for i in 0..N {
            est.p[(i, j)] -= ktu[(i, j)] + ktu[(j, i)];
        }
    }
    finite("updated state", &est.x)?;
    finite("updated covariance", &est.p)
}

/// True when `R` has no off-diagonal entries (every aid model's): its components are
/// independent, and may be taken one at a time.
#[inline(always)]
pub(super) fn diagonal<const M: usize>(r: &SMatrix<f64, M, M>) -> bool {
    (0..M).all(|i| (0..M).all(|j| i == j || r[(i, j)] == 0.0))
}

/// [`joseph_update_body`] for a diagonal `R` and an `H` with zero bias columns, one
/// component at a time: with independent components the block update equals the `M`
/// scalar updates in turn (each against the estimate the one before left), and each is
/// the same Joseph form with `M = 1`: `c = P hᵀ`, `s = hᵀ c + r`, `k = c · (1/s)`,
/// `u = c − ½ s k`, `P − (k uᵀ + u kᵀ)` — no Cholesky factor, no `M × 15` products, and
/// `P` read and written once per component. `k uᵀ + u kᵀ` adds the same two products in
/// either order for `(i, j)` and `(j, i)`, so `P` stays exactly symmetric.
#[inline(always)]
fn sequential_update<const M: usize>(
    est: &mut ErrorEstimate,
    m: &AidMeasurement<M>,
) -> Result<(), FilterError> {
    /// A column of `P` padded to 16 entries: four whole AVX2 vectors, no remainder loop.
    type Column = [f64; 16];
    let (h, r) = (&m.obs.h, &m.obs.r);
    // P in padded columns for the M updates (row 15 stays zero: every gain and `u` has a
    // zero there), copied back once at the end.
    let mut p = [[0.0; 16]; N];
    for (j, col) in p.iter_mut().enumerate() {
        col[..N].copy_from_slice(&est.p.as_slice()[N * j..N * (j + 1)]);
    }
    for row in 0..M {
        // c = P hᵀ over h's non-zero columns (P is symmetric: columns, not rows, of P).
        let mut c: Column = [0.0; 16];
        let mut hx = 0.0;
        for k in 0..9 {
            let v = h[(row, k)];
            if v != 0.0 {
                for i in 0..16 {
                    c[i] += p[k][i] * v;
                }
                hx += v * est.x[k];
            }
        }
        let mut hph = 0.0;
        for k in 0..9 {
            let v = h[(row, k)];
            if v != 0.0 {
                hph += v * c[k];
            }
        }
        let innovation = m.z[row] - hx;
        let s = hph + r[(row, row)];
        if !innovation.is_finite() {
            return Err(FilterError::NonFinite("innovation"));
        }
        if !s.is_finite() {
            return Err(FilterError::NonFinite("innovation covariance"));
        }
        if s <= 0.0 {
            return Err(FilterError::NotPositiveDefinite);
        }
        let inv_s = 1.0 / s;
        let gain: Column = std::array::from_fn(|i| c[i] * inv_s);
        if !gain.iter().fold(true, |ok, v| ok & v.is_finite()) {
            return Err(FilterError::NonFinite("gain"));
        }
        let half_s = s * 0.5;
        let u: Column = std::array::from_fn(|i| c[i] - gain[i] * half_s);
        for (xi, gi) in est.x.iter_mut().zip(&gain) {
            *xi += gi * innovation;
        }
        for (j, col) in p.iter_mut().enumerate() {
            let (kj, uj) = (gain[j], u[j]);
            for i in 0..16 {
                col[i] -= gain[i] * uj + u[i] * kj;
            }
        }
    }
    for (j, col) in p.iter().enumerate() {
        est.p.as_mut_slice()[N * j..N * (j + 1)].copy_from_slice(&col[..N]);
    }
    finite("updated state", &est.x)?;
    finite("updated covariance", &est.p)
}

/// A Kalman update of `prior` by one aid measurement with the generic filter (the
/// reference the fast kernels are tested against).
#[cfg(test)]
pub(super) fn kalman_update<const M: usize>(
    prior: &ErrorEstimate,
    m: &AidMeasurement<M>,
) -> Result<ErrorEstimate, FilterError> {
    let innov = kalman::innovation(prior, &m.obs, &m.z)?;
    Ok(kalman::update(prior, &m.obs, &innov)?.0)
}

/// Information fusion of two independent estimates, `P = (P_a⁻¹ + P_b⁻¹)⁻¹`,
/// `x = P (P_a⁻¹ x_a + P_b⁻¹ x_b)`, as the Kalman update of `a` by `z = x_b`, `H = I`,
/// `R = P_b` (Joseph form, no explicit inverse). It runs in the coordinates `D⁻¹ x` with
/// `D = diag(sqrt(diag(P_a + P_b)))`: the INS states' variances span 1e-17 to 1e2, and
/// unscaled products would bury the bias block in the position block's rounding.
pub(super) fn fuse_estimates(
    a: &ErrorEstimate,
    b: &ErrorEstimate,
) -> Result<ErrorEstimate, FilterError> {
    let d = ErrorVector::from_fn(|i, _| (a.p[(i, i)] + b.p[(i, i)]).sqrt());
    if d.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        return Err(FilterError::NotPositiveDefinite);
    }
    let down = |e: &ErrorEstimate| StateEstimate {
        x: e.x.component_div(&d),
        p: ErrorMatrix::from_fn(|i, j| e.p[(i, j)] / (d[i] * d[j])),
    };
    let (sa, sb) = (down(a), down(b));
    let obs = LinearObservation::<U15, U15> {
        h: ErrorMatrix::identity(),
        r: sb.p,
    };
    let innov = kalman::innovation(&sa, &obs, &sb.x)?;
    let fused = kalman::update(&sa, &obs, &innov)?.0;
    Ok(StateEstimate {
        x: fused.x.component_mul(&d),
        p: ErrorMatrix::from_fn(|i, j| fused.p[(i, j)] * (d[i] * d[j])),
    })
}

avx2_dispatch! {
    /// HPL slope of one aid: `K_h = (P_g H_iᵀ R_i⁻¹)` rows east and north, and the diagonal of the
    /// local test's `S⁻¹`. `R` is diagonal for every aid model (then `R⁻¹` is a division).
    /// Runs the AVX2 build when the CPU has it ([`avx2`]).
    fn fused_slope<const M: usize>(
        p_g: &ErrorMatrix,
        m: &AidMeasurement<M>,
        s_inv: &SVector<f64, 6>,
    ) -> Result<f64, hpl::HplError>
    => fused_slope_avx2, fused_slope_body
}

/// [`fused_slope`] in whichever build its caller has.
#[inline(always)]
pub(super) fn fused_slope_body<const M: usize>(
    p_g: &ErrorMatrix,
    m: &AidMeasurement<M>,
    s_inv: &SVector<f64, 6>,
) -> Result<f64, hpl::HplError> {
    // Entry by entry: a view's `into_owned` goes through nalgebra's iterator, several times
    // slower than the copy.
    let ph = SMatrix::<f64, N, 2>::from_fn(|i, j| p_g[(i, POS + j)]);
    // M × 2 = (P_g[h, :] Hᵀ)ᵀ
    let hph = if bias_columns_zero(&m.obs.h) {
        sparse_h_times(&m.obs.h, &ph)
    } else {
        m.obs.h * ph
    };
    let r = &m.obs.r;
    // K_h = P_g[h, :] Hᵀ R⁻¹  ⇔  R K_hᵀ = H P_g[:, h]  (R symmetric).
    let k_h_t = if diagonal(r) {
        SMatrix::<f64, M, 2>::from_fn(|i, j| hph[(i, j)] / r[(i, i)])
    } else {
        let chol = r.cholesky().ok_or(hpl::HplError::NotPositiveDefinite)?;
        chol.solve(&hph)
    };
    let d = SVector::<f64, M>::from_fn(|i, _| s_inv[i]);
    hpl::slope_max_with::<M>(&k_h_t.transpose(), &d)
}
