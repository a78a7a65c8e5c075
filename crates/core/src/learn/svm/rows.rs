//! The kernel matrix `Q_ij = y_i y_j K(x_i, x_j)` as the SMO solver
//! ([`super::smo`]) sees it: in the solver's permuted order, rows computed on
//! demand into the LRU [`RowCache`]. Samples are kept column by column and the
//! RBF exponential is a branch-free polynomial, so a row is a few vectorised
//! passes (the solver spends most of its time here).

use super::cache::RowCache;
use crate::learn::Kernel;
use crate::learn::kernel::exp_nonpos;

/// `Q` for the solver.
pub(super) struct QMatrix {
    /// Samples, one vector per feature (structure of arrays).
    cols: Vec<Vec<f64>>,
    /// `‖x_i‖²`, so `‖x_i − x_j‖² = ‖x_i‖² + ‖x_j‖² − 2x_iᵀx_j` costs one dot product.
    sq: Vec<f64>,
    y: Vec<f64>,
    kernel: Kernel,
    /// `Q_ii`.
    pub(super) diag: Vec<f64>,
    cache: RowCache,
    scratch: Vec<f64>,
}

impl QMatrix {
    /// `Q` of the row-major samples `x` (dimension `dim`) with signs `y`.
    pub(super) fn new(x: &[f64], dim: usize, y: &[f64], kernel: Kernel, cache_mb: f64) -> Self {
        let n = y.len();
        let cols: Vec<Vec<f64>> = (0..dim)
            .map(|k| x.iter().skip(k).step_by(dim).copied().collect())
            .collect();
        let sq: Vec<f64> = x
            .chunks_exact(dim)
            .map(|r| r.iter().map(|v| v * v).sum())
            .collect();
        // Q_ii = y_i² K(x_i, x_i) = K(x_i, x_i).
        let diag = sq.iter().map(|&s| kernel.eval_parts(0.0, s)).collect();
        QMatrix {
            cols,
            sq,
            y: y.to_vec(),
            kernel,
            diag,
            cache: RowCache::new(n, cache_mb),
            scratch: Vec::new(),
        }
    }

    /// Makes row `i` valid on `0..len`, computing only the missing tail.
    pub(super) fn ensure(&mut self, i: usize, len: usize) {
        let start = self.cache.prepare(i, len);
        if start >= len {
            return;
        }
        let out = &mut self.scratch;
        out.clear();
        out.resize(len - start, 0.0);
        let rbf_scale = match self.kernel {
            Kernel::Rbf { sigma2 } => Some(-1.0 / sigma2),
            Kernel::Linear => None,
        };
        kernel_tail(&self.cols, &self.sq, i, start, rbf_scale, out);
        let yi = self.y[i];
        let y = &self.y[start..len];
        self.cache
            .row_vec(i)
            .extend(out.iter().zip(y).map(|(&o, &yj)| (yi * yj * o) as f32));
    }

    /// Row `i` as far as it is valid (call [`QMatrix::ensure`] first).
    #[inline]
    pub(super) fn row(&self, i: usize) -> &[f32] {
        self.cache.row(i)
    }

    /// Follows the solver's swap of samples `i` and `j`.
    pub(super) fn swap_index(&mut self, i: usize, j: usize) {
        self.cache.swap_index(i, j);
        for col in &mut self.cols {
            col.swap(i, j);
        }
        self.sq.swap(i, j);
        self.y.swap(i, j);
        self.diag.swap(i, j);
    }
}

/// `K(x_i, x_j)` for `j ∈ start..start + out.len()` into `out` (which starts at 0):
/// the dot products column by column, then for RBF `exp(scale · ‖x_i − x_j‖²)`.
/// Uses AVX2 when [`crate::simd::avx2`] allows it (4 lanes instead of SSE2's 2).
fn kernel_tail(
    cols: &[Vec<f64>],
    sq: &[f64],
    i: usize,
    start: usize,
    rbf_scale: Option<f64>,
    out: &mut [f64],
) {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2() {
        // SAFETY: the CPU supports AVX2 (checked just above).
        unsafe { kernel_tail_avx2(cols, sq, i, start, rbf_scale, out) };
        return;
    }
    kernel_tail_body(cols, sq, i, start, rbf_scale, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn kernel_tail_avx2(
    cols: &[Vec<f64>],
    sq: &[f64],
    i: usize,
    start: usize,
    rbf_scale: Option<f64>,
    out: &mut [f64],
) {
    kernel_tail_body(cols, sq, i, start, rbf_scale, out);
}

#[inline(always)]
fn kernel_tail_body(
    cols: &[Vec<f64>],
    sq: &[f64],
    i: usize,
    start: usize,
    rbf_scale: Option<f64>,
    out: &mut [f64],
) {
    let end = start + out.len();
    for col in cols {
        let xik = col[i];
        for (o, &c) in out.iter_mut().zip(&col[start..end]) {
            *o += xik * c;
        }
    }
    if let Some(scale) = rbf_scale {
        let sqi = sq[i];
        for (o, &sqj) in out.iter_mut().zip(&sq[start..end]) {
            let dist2 = (sqi + sqj - 2.0 * *o).max(0.0);
            *o = exp_nonpos(dist2 * scale);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    #[test]
    fn the_avx2_kernel_rows_equal_the_baseline_build_to_the_bit() {
        // `kernel_tail` runs its AVX2 build on a CPU with AVX2 (`crate::simd::avx2`);
        // `kernel_tail_body` called from this function (no target features) is the
        // baseline build. Same operations in the same order: identical bits, not close ones.
        let mut rng = StdRng::seed_from_u64(8);
        let (n, d) = (37, 3);
        let cols: Vec<Vec<f64>> = (0..d)
            .map(|_| (0..n).map(|_| rng.random::<f64>() * 4.0 - 2.0).collect())
            .collect();
        let sq: Vec<f64> = (0..n)
            .map(|j| cols.iter().map(|c| c[j] * c[j]).sum())
            .collect();
        for scale in [None, Some(-0.7)] {
            for (i, start) in [(0, 0), (5, 3), (36, 1)] {
                let mut fast = vec![0.0; n - start];
                let mut base = fast.clone();
                kernel_tail(&cols, &sq, i, start, scale, &mut fast);
                kernel_tail_body(&cols, &sq, i, start, scale, &mut base);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&fast), bits(&base), "row {i} from {start}, {scale:?}");
            }
        }
    }

    #[test]
    fn rows_hold_signed_kernel_values_in_the_permuted_order() {
        let x = [0.0, 0.0, 1.0, 0.0, 0.0, 2.0];
        let k = Kernel::Rbf { sigma2: 2.0 };
        let mut q = QMatrix::new(&x, 2, &[1.0, -1.0, 1.0], k, 1.0);
        q.ensure(0, 3);
        let expect = [1.0, -(-0.5f64).exp(), (-2.0f64).exp()];
        for (a, b) in q.row(0).iter().zip(expect) {
            assert!((*a as f64 - b).abs() < 1e-7);
        }
        q.swap_index(0, 2);
        q.ensure(2, 3);
        assert!((q.row(2)[0] as f64 - (-2.0f64).exp()).abs() < 1e-7);
        assert_eq!(q.diag, vec![1.0, 1.0, 1.0]);
    }
}
