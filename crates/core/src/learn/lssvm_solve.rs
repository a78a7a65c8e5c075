//! The numerical core of the LS-SVM family (docs/methods.md §M9), below `lssvm`, `local`,
//! `online` and `cv`: kernel matrices, a blocked Cholesky factorisation on contiguous
//! column-major memory, triangular solves, and the two-solve trick of seed 000 eq. 6.
//!
//! The factorisation is left-looking and blocked: each block column is first updated
//! by one matrix product with everything to its left (nalgebra's `gemm`, which runs
//! `matrixmultiply`'s cache-blocked, SIMD-dispatched kernel), then its diagonal block
//! is factorised unblocked and the panel below it solved against that block. Nearly
//! all of the `n³/3` flops are in the products, so the whole runs near `gemm` speed.

use nalgebra::DMatrix;

use super::{Kernel, LearnError};

/// Block width of the factorisation: wide enough for `gemm` to reach speed, narrow
/// enough that the unblocked diagonal factorisation (`NB³/3` per block) stays cheap.
const NB: usize = 64;

/// The samples of `x` (one per row) packed row-major, so each is a contiguous slice.
pub fn pack_rows(x: &DMatrix<f64>) -> Vec<f64> {
    let (n, d) = x.shape();
    let mut rows = Vec::with_capacity(n * d);
    for i in 0..n {
        rows.extend(x.row(i).iter());
    }
    rows
}

/// `Ω + I/γ` (seed 000 eq. 6) of the `n` samples packed in `rows` (`d` values each).
/// Only the lower triangle and diagonal are filled: that is all [`cholesky`] reads.
///
/// Built column by column with the features transposed, so the squared distances of
/// a column and then its exponentials are straight vectorisable loops ([`exp_nonpos`]).
pub fn regularised_kernel(rows: &[f64], d: usize, kernel: &Kernel, gamma: f64) -> DMatrix<f64> {
    let n = rows.len() / d.max(1);
    let mut h = DMatrix::zeros(n, n);
    // Feature-major copy: feature f of every sample contiguous.
    let mut cols = vec![0.0; n * d];
    for i in 0..n {
        for f in 0..d {
            cols[f * n + i] = rows[i * d + f];
        }
    }
    let ridge = 1.0 / gamma;
    for j in 0..n {
        let col = &mut h.as_mut_slice()[j * n + j..(j + 1) * n];
        match *kernel {
            Kernel::Rbf { sigma2 } => {
                for f in 0..d {
                    let (feature, xj) = (&cols[f * n + j..(f + 1) * n], cols[f * n + j]);
                    for (out, v) in col.iter_mut().zip(feature) {
                        *out += (v - xj) * (v - xj);
                    }
                }
                let scale = -1.0 / sigma2;
                for out in col.iter_mut() {
                    *out = exp_nonpos(*out * scale);
                }
            }
            Kernel::Linear => {
                for f in 0..d {
                    let (feature, xj) = (&cols[f * n + j..(f + 1) * n], cols[f * n + j]);
                    for (out, v) in col.iter_mut().zip(feature) {
                        *out += v * xj;
                    }
                }
            }
        }
        col[0] += ridge;
    }
    h
}

pub use super::kernel::exp_nonpos;

/// `aᵀb` with four independent accumulators, so the sum pipelines and vectorises
/// (a single running sum is one long dependency chain).
#[inline]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for k in 0..4 {
            acc[k] += x[k] * y[k];
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// Factorises the symmetric positive-definite matrix whose lower triangle is in `a`
/// into `L Lᵀ`, overwriting the lower triangle with `L` (the strict upper triangle is
/// left as it was and never read). Fails on a non-positive or non-finite pivot.
pub fn cholesky(a: &mut DMatrix<f64>) -> Result<(), LearnError> {
    let n = a.nrows();
    debug_assert_eq!(n, a.ncols());
    let mut j0 = 0;
    while j0 < n {
        let nb = NB.min(n - j0);
        if j0 > 0 {
            // A[j0.., j0..j0+nb] −= L[j0.., ..j0] · L[j0..j0+nb, ..j0]ᵀ
            let (left, mut right) = a.columns_range_pair_mut(0..j0, j0..j0 + nb);
            let top = left.rows(j0, nb).transpose();
            let mut target = right.rows_mut(j0, n - j0);
            target.gemm(-1.0, &left.rows(j0, n - j0), &top, 1.0);
        }
        factor_panel(a.as_mut_slice(), n, j0, nb)?;
        j0 += nb;
    }
    Ok(())
}

/// Unblocked Cholesky of the diagonal block at `j0` (width `nb`) of the column-major
/// `n × n` matrix `a`, then the panel below it: `L21 = A21 · L11⁻ᵀ`, done column by
/// column so every inner loop runs down a contiguous column.
fn factor_panel(a: &mut [f64], n: usize, j0: usize, nb: usize) -> Result<(), LearnError> {
    for c in j0..j0 + nb {
        let pivot = a[c * n + c];
        if !(pivot > 0.0 && pivot.is_finite()) {
            return Err(LearnError::Numerical(format!(
                "Cholesky pivot {c} is {pivot:e}: the matrix is not positive definite"
            )));
        }
        let l_cc = pivot.sqrt();
        let (done, rest) = a.split_at_mut((c + 1) * n);
        let col_c = &mut done[c * n..];
        for v in &mut col_c[c..n] {
            *v /= l_cc;
        }
        // Right-looking inside the panel: columns c+1..j0+nb lose L[:, c] L[c2, c].
        for c2 in c + 1..j0 + nb {
            let f = col_c[c2];
            let col2 = &mut rest[(c2 - c - 1) * n..(c2 - c) * n];
            for (t, s) in col2[c2..n].iter_mut().zip(&col_c[c2..n]) {
                *t -= f * s;
            }
        }
    }
    Ok(())
}

/// Solves `L z = b` in place (`l` the factor from [`cholesky`]), column-oriented:
/// a contiguous axpy down each column.
pub fn forward_solve(l: &DMatrix<f64>, b: &mut [f64]) {
    let n = l.nrows();
    let s = l.as_slice();
    for j in 0..n {
        let col = &s[j * n..(j + 1) * n];
        let zj = b[j] / col[j];
        b[j] = zj;
        for (bi, lij) in b[j + 1..].iter_mut().zip(&col[j + 1..]) {
            *bi -= lij * zj;
        }
    }
}

/// Solves `L Lᵀ x = b` in place, `l` holding the factor from [`cholesky`].
pub fn cholesky_solve(l: &DMatrix<f64>, b: &mut [f64]) {
    let n = l.nrows();
    let s = l.as_slice();
    forward_solve(l, b);
    // Backward: Lᵀ x = z, row j of Lᵀ is column j of L (contiguous dot).
    for j in (0..n).rev() {
        let col = &s[j * n..(j + 1) * n];
        let dot: f64 = b[j + 1..]
            .iter()
            .zip(&col[j + 1..])
            .map(|(x, l)| x * l)
            .sum();
        b[j] = (b[j] - dot) / col[j];
    }
}

/// [`cholesky_solve`] for two right-hand sides at once: `L` (n² values, larger than
/// cache for n ≳ 500) is streamed twice instead of four times.
pub fn cholesky_solve_pair(l: &DMatrix<f64>, b: &mut [f64], c: &mut [f64]) {
    let n = l.nrows();
    let s = l.as_slice();
    for j in 0..n {
        let col = &s[j * n..(j + 1) * n];
        let (zb, zc) = (b[j] / col[j], c[j] / col[j]);
        b[j] = zb;
        c[j] = zc;
        for ((bi, ci), lij) in b[j + 1..]
            .iter_mut()
            .zip(c[j + 1..].iter_mut())
            .zip(&col[j + 1..])
        {
            *bi -= lij * zb;
            *ci -= lij * zc;
        }
    }
    for j in (0..n).rev() {
        let col = &s[j * n..(j + 1) * n];
        let (db, dc) = (
            dot(&b[j + 1..], &col[j + 1..]),
            dot(&c[j + 1..], &col[j + 1..]),
        );
        b[j] = (b[j] - db) / col[j];
        c[j] = (c[j] - dc) / col[j];
    }
}

/// The LS-SVM dual solution `f(x) = Σ αᵢ K(xᵢ, x) + b`.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// Support values α, one per training sample.
    pub alpha: Vec<f64>,
    /// Bias b.
    pub b: f64,
}

/// Solves seed 000 eq. 6, `[[0, 1ᵀ], [1, H]] [b; α] = [0; y]` with `H = Ω + I/γ`
/// already factorised by [`cholesky`], by the two-solve trick: `η = H⁻¹1`,
/// `ν = H⁻¹y`, `b = 1ᵀν / 1ᵀη`, `α = ν − bη` (block elimination of the bias row).
pub fn two_solve(l: &DMatrix<f64>, y: &[f64]) -> Solution {
    let n = l.nrows();
    let mut eta = vec![1.0; n];
    let mut nu = y.to_vec();
    cholesky_solve_pair(l, &mut eta, &mut nu);
    let b = nu.iter().sum::<f64>() / eta.iter().sum::<f64>();
    let alpha = nu.iter().zip(&eta).map(|(v, e)| v - b * e).collect();
    Solution { alpha, b }
}

/// Fits an LS-SVM on the packed samples `rows` (`d` values each) and targets `y`.
pub fn fit(
    rows: &[f64],
    d: usize,
    y: &[f64],
    kernel: &Kernel,
    gamma: f64,
) -> Result<Solution, LearnError> {
    let mut h = regularised_kernel(rows, d, kernel, gamma);
    cholesky(&mut h)?;
    Ok(two_solve(&h, y))
}

/// `Σ αᵢ K(xᵢ, x) + b` over the packed samples `rows`.
#[inline]
pub fn evaluate(
    rows: &[f64],
    d: usize,
    sol_alpha: &[f64],
    b: f64,
    kernel: &Kernel,
    x: &[f64],
) -> f64 {
    rows.chunks_exact(d)
        .zip(sol_alpha)
        .fold(b, |f, (xi, a)| f + a * kernel_value(kernel, xi, x))
}

/// `K(xᵢ, x)` as [`evaluate`] sums it (the RBF through [`exp_nonpos`] with `1/σ²`), so a
/// caller that keeps the kernel row gets the same prediction bit for bit.
#[inline]
pub fn kernel_value(kernel: &Kernel, xi: &[f64], x: &[f64]) -> f64 {
    match *kernel {
        Kernel::Rbf { sigma2 } => {
            let d2: f64 = xi.iter().zip(x).map(|(p, q)| (p - q) * (p - q)).sum();
            exp_nonpos(-d2 * (1.0 / sigma2))
        }
        Kernel::Linear => xi.iter().zip(x).map(|(p, q)| p * q).sum::<f64>(),
    }
}

/// The inverse of the matrix factorised as `L Lᵀ` in `l`, full and symmetric.
pub fn inverse_from_cholesky(l: &DMatrix<f64>) -> DMatrix<f64> {
    let n = l.nrows();
    let mut inv = DMatrix::zeros(n, n);
    let mut e = vec![0.0; n];
    for j in 0..n {
        e.iter_mut().for_each(|v| *v = 0.0);
        e[j] = 1.0;
        cholesky_solve(l, &mut e);
        inv.column_mut(j).copy_from_slice(&e);
    }
    inv
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng, rngs::StdRng};

    fn random_spd(n: usize, seed: u64) -> DMatrix<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        let g = DMatrix::from_fn(n, n, |_, _| rng.random::<f64>() - 0.5);
        &g * g.transpose() + DMatrix::identity(n, n) * (n as f64 * 0.1)
    }

    #[test]
    fn blocked_cholesky_matches_nalgebra_across_block_boundaries() {
        // 150 = two full blocks and a partial one.
        for n in [1, 5, 64, 65, 150] {
            let a = random_spd(n, n as u64);
            let mut l = a.clone();
            cholesky(&mut l).unwrap();
            let reference = a.clone().cholesky().unwrap().l();
            for j in 0..n {
                for i in j..n {
                    assert!(
                        (l[(i, j)] - reference[(i, j)]).abs() < 1e-10,
                        "n {n} ({i},{j})"
                    );
                }
            }
        }
    }

    #[test]
    fn dot_matches_the_plain_sum() {
        let a: Vec<f64> = (0..23).map(|i| i as f64 * 0.5).collect();
        let b: Vec<f64> = (0..23).map(|i| 1.0 - i as f64).collect();
        let plain: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
        assert!((dot(&a, &b) - plain).abs() < 1e-12);
    }

    #[test]
    fn cholesky_refuses_an_indefinite_matrix() {
        let mut a = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        assert!(matches!(cholesky(&mut a), Err(LearnError::Numerical(_))));
    }

    #[test]
    fn cholesky_solve_and_inverse_agree_with_the_matrix() {
        let a = random_spd(70, 7);
        let mut l = a.clone();
        cholesky(&mut l).unwrap();
        let x: Vec<f64> = (0..70).map(|i| (i as f64).sin()).collect();
        let mut b: Vec<f64> = (&a * nalgebra::DVector::from_column_slice(&x))
            .iter()
            .copied()
            .collect();
        cholesky_solve(&l, &mut b);
        for (u, v) in b.iter().zip(&x) {
            assert!((u - v).abs() < 1e-10);
        }
        let inv = inverse_from_cholesky(&l);
        let eye = &a * inv;
        assert!((eye - DMatrix::identity(70, 70)).amax() < 1e-10);
    }
}
