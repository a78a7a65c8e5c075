//! A windowed-mean test whose variance is estimated from the signal's own healthy
//! history by batch means (docs/methods.md §M20). It is the calibrated form of seed
//! 000's T_a (the `channel` monitor) and the drift test on Kalman innovations (`linear`
//! and `federated`): both sum the last `n` inputs and ask whether their mean is zero.
//!
//! - **Window**: the mean `m` of the last `n` inputs (the newest included).
//! - **Variance of `m`**: the healthy history is cut into consecutive, non-overlapping
//!   blocks of `n` inputs; the last `max_blocks` block means `m_b` give
//!   `Σ̂ = (1/B) Σ_b m_b m_bᵀ` (about zero, so a standing bias counts as variance and
//!   does not fail the test). Each block mean is a window mean, so `Σ̂` estimates the
//!   variance of exactly the statistic tested, whatever the autocorrelation of the
//!   inputs within a window (slow wander, a predictor's coloured error, correlated
//!   innovations): this is what the successive-difference V of seed 000 eq. 16 misses.
//!   A block is only formed from inputs whose epoch was healthy; an unhealthy epoch
//!   discards the block in progress, so a fault never enters `Σ̂` (frozen while not
//!   healthy).
//! - **Distribution**: with Gaussian inputs and independent blocks, `B Σ̂` is Wishart
//!   with `B` degrees of freedom and `T² = mᵀ Σ̂⁻¹ m` is Hotelling's:
//!   `T² (B − d + 1)/(B d) ~ F(d, B − d + 1)`. As `B` grows the F law tends to the χ².
//! - **Several window lengths** ("scales", e.g. 1 and 10: a step is seen by the short
//!   one at once, a slow drift by the long one): each scale has its own blocks and tail
//!   probability `p_i`; the test's tail is the Bonferroni bound `min(1, S · min_i p_i)`
//!   over its `S` scales, so the false-alarm probability stays at or below the nominal.
//! - **Reported value**: the χ²(d) value with that tail probability
//!   ([`chi2_equivalent`]), so a monitor's χ² threshold (from `p_fa`) gives the test's
//!   own false-alarm probability, and a raw threshold keeps its χ² meaning.
//! - **Warm-up**: a scale reports nothing until `min_blocks` healthy blocks exist,
//!   unless a *known* covariance `C` of one input is given (whitened Kalman
//!   innovations: `C = I`); then `n mᵀ C⁻¹ m ~ χ²(d)` is used until the blocks take over.

use std::collections::VecDeque;

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::chi2;
use super::f_law::FLaw;

/// Default number of block means kept per scale (its variance's memory is
/// `max_blocks · n` epochs).
pub const DEFAULT_MAX_BLOCKS: usize = 50;
/// Default number of healthy blocks before a scale's estimated variance is used.
pub const DEFAULT_MIN_BLOCKS: usize = 10;

/// Smallest tail probability mapped to a χ² value (below it the value saturates).
const MIN_TAIL: f64 = 1e-300;

/// Why an input could not be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WindowError {
    /// The input does not have the test's dimension.
    #[error("input has {got} components, the test expects {want}")]
    Dimension {
        /// Components received.
        got: usize,
        /// Components expected.
        want: usize,
    },
    /// A component is NaN or infinite.
    #[error("input has a non-finite component")]
    NonFinite,
    /// The known covariance has no Cholesky factor.
    #[error("the known covariance is not positive definite")]
    Singular,
}

/// Parameters of a [`WindowTest`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct WindowParams {
    /// Input dimension d (≥ 1).
    pub dim: usize,
    /// Window lengths, each also its block length (each ≥ 1; at least one).
    pub scales: Vec<usize>,
    /// Block means kept per scale (≥ `min_blocks`).
    pub max_blocks: usize,
    /// Healthy blocks before a scale's estimated variance is used (≥ d + 1, so the F law
    /// has a positive second dof).
    pub min_blocks: usize,
}

impl WindowParams {
    /// Windows of the given lengths over inputs of dimension `dim`, default block counts.
    pub fn new(dim: usize, scales: &[usize]) -> Self {
        WindowParams {
            dim,
            scales: scales.to_vec(),
            max_blocks: DEFAULT_MAX_BLOCKS,
            min_blocks: DEFAULT_MIN_BLOCKS,
        }
        .normalised()
    }

    /// Raises out-of-range values to their minimum (callers validate user input first).
    fn normalised(mut self) -> Self {
        self.dim = self.dim.max(1);
        self.min_blocks = self.min_blocks.max(self.dim + 1);
        self.max_blocks = self.max_blocks.max(self.min_blocks);
        for n in &mut self.scales {
            *n = (*n).max(1);
        }
        if self.scales.is_empty() {
            self.scales.push(1);
        }
        self
    }

    /// The longest window.
    pub fn longest(&self) -> usize {
        self.scales.iter().copied().max().unwrap_or(1)
    }
}

/// One evaluation of the test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowValue {
    /// The χ²(d) value with the test's tail probability: what is compared with the
    /// threshold.
    pub value: f64,
    /// The combined upper-tail probability under no fault (Bonferroni over the scales).
    pub tail: f64,
    /// The window length whose tail was smallest.
    pub scale: usize,
    /// That scale's `mᵀ Σ̂⁻¹ m` (Hotelling's T², or `n mᵀ C⁻¹ m` under the known
    /// covariance).
    pub raw: f64,
    /// Healthy blocks behind that scale's Σ̂ (0 while the known covariance is used).
    pub blocks: usize,
}

/// The χ²(dof) value whose upper-tail probability is `tail` (clamped to
/// `[1e-300, 1)`; a tail of 1 gives 0). Maps a test with another null law onto the χ²
/// scale of its dof, so thresholds from `p_fa` keep their meaning.
pub fn chi2_equivalent(dof: u32, tail: f64) -> f64 {
    if tail.is_nan() || tail >= 1.0 {
        return 0.0;
    }
    chi2::threshold(dof.max(1), tail.max(MIN_TAIL)).unwrap_or(0.0)
}

/// Upper-tail probability of `F(d1, d2)` at `x` ([`FLaw::upper_tail`]).
pub fn f_upper_tail(x: f64, d1: f64, d2: f64) -> f64 {
    FLaw::new(d1, d2).upper_tail(x)
}

/// Lower-tail probability of `F(d1, d2)` at `x` ([`FLaw::lower_tail`]).
pub fn f_lower_tail(x: f64, d1: f64, d2: f64) -> f64 {
    FLaw::new(d1, d2).lower_tail(x)
}

/// A completed healthy block: its mean and the sum of `r rᵀ` over its inputs.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Block {
    mean: DVector<f64>,
    sum_sq: DMatrix<f64>,
}

/// One window length: its block in progress, its kept blocks and their estimate.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Scale {
    n: usize,
    /// Blocks kept, and blocks needed before the scale judges (the params' values, or
    /// scaled to an equal memory by [`WindowTest::with_equal_memory`]).
    max_blocks: usize,
    min_blocks: usize,
    /// The block being filled: sum of inputs, sum of `r rᵀ`, inputs so far.
    partial: (DVector<f64>, DMatrix<f64>, usize),
    blocks: VecDeque<Block>,
    /// Running `Σ m_b m_bᵀ` and `Σ sum_sq` over the kept blocks, recomputed from scratch
    /// every `max_blocks` blocks so no round-off accumulates (a short scale of an
    /// equal-memory test keeps hundreds of blocks and completes one every epoch).
    sums: (DMatrix<f64>, DMatrix<f64>),
    since_recompute: usize,
    /// `(Σ̂⁻¹, per-input covariance)` from the kept blocks, once there are enough and Σ̂
    /// is positive definite.
    estimate: Option<(DMatrix<f64>, DMatrix<f64>)>,
    /// The Hotelling F law of the kept blocks, renewed with the estimate (not saved: a
    /// restored scale forms it again).
    #[serde(skip)]
    law: Option<FLaw>,
}

impl Scale {
    fn new(n: usize, d: usize, max_blocks: usize, min_blocks: usize) -> Self {
        Scale {
            n,
            max_blocks,
            min_blocks,
            partial: (DVector::zeros(d), DMatrix::zeros(d, d), 0),
            blocks: VecDeque::new(),
            sums: (DMatrix::zeros(d, d), DMatrix::zeros(d, d)),
            since_recompute: 0,
            estimate: None,
            law: None,
        }
    }

    fn discard_partial(&mut self) {
        self.partial.0.as_mut_slice().fill(0.0);
        self.partial.1.as_mut_slice().fill(0.0);
        self.partial.2 = 0;
    }

    /// Adds `r` to the block in progress; a completed block joins the kept ones and renews
    /// the estimate. Outer products are accumulated in place (each entry the same
    /// `r_i r_j` nalgebra's `r rᵀ` forms), and a block that leaves lends its storage to
    /// the next block in progress, so a full scale allocates only in [`Scale::renew`].
    fn add(&mut self, r: &DVector<f64>, params: &WindowParams) {
        add_outer(&mut self.partial.1, r, 1.0);
        self.partial.0 += r;
        self.partial.2 += 1;
        if self.partial.2 < self.n {
            return;
        }
        let d = params.dim;
        let (mut mean, sum_sq, count) = std::mem::replace(
            &mut self.partial,
            (DVector::zeros(0), DMatrix::zeros(0, 0), 0),
        );
        mean /= count as f64;
        let block = Block { mean, sum_sq };
        add_outer(&mut self.sums.0, &block.mean, 1.0);
        self.sums.1 += &block.sum_sq;
        self.blocks.push_back(block);
        self.partial = if self.blocks.len() > self.max_blocks
            && let Some(mut old) = self.blocks.pop_front()
        {
            add_outer(&mut self.sums.0, &old.mean, -1.0);
            self.sums.1 -= &old.sum_sq;
            old.mean.as_mut_slice().fill(0.0);
            old.sum_sq.as_mut_slice().fill(0.0);
            (old.mean, old.sum_sq, 0)
        } else {
            (DVector::zeros(d), DMatrix::zeros(d, d), 0)
        };
        self.since_recompute += 1;
        if self.since_recompute >= self.max_blocks {
            self.since_recompute = 0;
            self.sums.0.as_mut_slice().fill(0.0);
            self.sums.1.as_mut_slice().fill(0.0);
            for b in &self.blocks {
                add_outer(&mut self.sums.0, &b.mean, 1.0);
                self.sums.1 += &b.sum_sq;
            }
        }
        self.renew();
    }

    /// Recomputes Σ̂⁻¹ and the per-input covariance from the kept blocks' sums.
    fn renew(&mut self) {
        let b = self.blocks.len();
        if b < self.min_blocks {
            self.estimate = None;
            return;
        }
        let mut second = self.sums.0.clone();
        second /= b as f64;
        // The per-input covariance reuses the previous estimate's storage.
        let mut per_input = match self.estimate.take() {
            Some((_, mut old)) => {
                old.copy_from(&self.sums.1);
                old
            }
            None => self.sums.1.clone(),
        };
        per_input /= (b * self.n) as f64;
        let d = self.sums.0.nrows() as f64;
        self.law = Some(FLaw::reuse(self.law, d, b as f64 - d + 1.0));
        // A singular Σ̂ (no spread in some direction) leaves the scale without a variance:
        // it stays idle rather than divide by zero.
        self.estimate = second.cholesky().map(|c| (c.inverse(), per_input));
    }

    /// Checks a scale read from a checkpoint against this one (same window and block
    /// counts, every vector and matrix `d`-dimensional, no more blocks than kept) and gives
    /// it this one's block capacity.
    fn restored(&self, mut saved: Scale, d: usize) -> Result<Scale, String> {
        if (saved.n, saved.max_blocks, saved.min_blocks)
            != (self.n, self.max_blocks, self.min_blocks)
        {
            return Err(format!(
                "window scale {} keeping {} blocks, the test's is {} keeping {}",
                saved.n, saved.max_blocks, self.n, self.max_blocks
            ));
        }
        let square = |m: &DMatrix<f64>| m.shape() == (d, d);
        let fits = saved.partial.0.len() == d
            && square(&saved.partial.1)
            && saved.partial.2 < saved.n
            && saved.blocks.len() <= saved.max_blocks
            && saved
                .blocks
                .iter()
                .all(|b| b.mean.len() == d && square(&b.sum_sq))
            && square(&saved.sums.0)
            && square(&saved.sums.1)
            && saved.since_recompute < saved.max_blocks
            && saved
                .estimate
                .as_ref()
                .is_none_or(|(a, b)| square(a) && square(b));
        if !fits {
            return Err(format!(
                "window scale {} does not fit dimension {d}",
                self.n
            ));
        }
        saved
            .blocks
            .reserve((saved.max_blocks + 1).saturating_sub(saved.blocks.len()));
        Ok(saved)
    }

    /// `(tail, raw, blocks)` of this scale for the window mean `mean`, if it can judge.
    fn judge(&self, mean: &[f64], known_inv: Option<&DMatrix<f64>>) -> Option<(f64, f64, usize)> {
        let d = mean.len();
        if let Some((sigma_inv, _)) = &self.estimate {
            let b = self.blocks.len() as f64;
            let raw = quadratic_form(sigma_inv, mean).max(0.0);
            let d2 = b - d as f64 + 1.0;
            let f = raw * d2 / (b * d as f64);
            let law = FLaw::reuse(self.law, d as f64, d2);
            return Some((law.upper_tail(f), raw, self.blocks.len()));
        }
        let inv = known_inv?;
        let raw = (self.n as f64 * quadratic_form(inv, mean)).max(0.0);
        let tail = if raw > 0.0 {
            chi2::false_alarm_probability(d as u32, raw).unwrap_or(0.0)
        } else {
            1.0
        };
        Some((tail, raw, 0))
    }
}

/// `a += sign · m mᵀ` in place, entry by entry: `a_ij ± m_i m_j`, what `a += &m * m.transpose()`
/// (or `-=`) computes, to the bit, without the product's allocation.
fn add_outer(a: &mut DMatrix<f64>, m: &DVector<f64>, sign: f64) {
    let d = m.len();
    for j in 0..d {
        for i in 0..d {
            let p = m[i] * m[j];
            if sign > 0.0 {
                a[(i, j)] += p;
            } else {
                a[(i, j)] -= p;
            }
        }
    }
}

/// `mᵀ A m` for a square `A` of `m`'s dimension: nalgebra's `m.dot(&(A * m))` to the bit.
/// Below 8 components (every Kalman innovation) it is summed in that expression's order
/// (each `(A m)_i` over `j` ascending, then the dot over `i` ascending) without its
/// allocations; from 8 on nalgebra's dot splits the sum over eight accumulators, so the
/// expression itself is used.
fn quadratic_form(a: &DMatrix<f64>, m: &[f64]) -> f64 {
    if m.len() >= 8 {
        let m = DVector::from_column_slice(m);
        return m.dot(&(a * &m));
    }
    let mut q = 0.0;
    for (i, &mi) in m.iter().enumerate() {
        let mut y = 0.0;
        for (j, &mj) in m.iter().enumerate() {
            y += a[(i, j)] * mj;
        }
        q += mi * y;
    }
    q
}

/// The running windowed-mean test of one signal (serde: a monitor checkpoint saves it
/// whole, parameters included, and [`WindowTest::restored`] checks it).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct WindowTest {
    params: WindowParams,
    /// Covariance of one input under no fault, when known (whitened innovations: I).
    known: Option<DMatrix<f64>>,
    known_inv: Option<DMatrix<f64>>,
    /// The last `longest` inputs, oldest first.
    window: VecDeque<DVector<f64>>,
    scales: Vec<Scale>,
}

impl WindowTest {
    /// A fresh test whose scales report once `min_blocks` healthy blocks exist.
    pub fn new(params: WindowParams) -> Self {
        let params = params.normalised();
        let scales = params
            .scales
            .iter()
            .map(|&n| Scale::new(n, params.dim, params.max_blocks, params.min_blocks))
            .collect();
        WindowTest {
            known: None,
            known_inv: None,
            window: VecDeque::new(),
            scales,
            params,
        }
    }

    /// A test whose inputs have covariance `cov` under no fault (e.g. the identity for
    /// whitened innovations); each scale reports from its first full window.
    /// `Err(Singular)` if `cov` is not positive definite, `Err(Dimension)` if it is not
    /// d × d.
    pub fn with_known_covariance(
        params: WindowParams,
        cov: DMatrix<f64>,
    ) -> Result<Self, WindowError> {
        let mut test = WindowTest::new(params);
        let d = test.params.dim;
        if cov.nrows() != d || cov.ncols() != d {
            return Err(WindowError::Dimension {
                got: cov.nrows(),
                want: d,
            });
        }
        let inv = cov
            .clone()
            .cholesky()
            .ok_or(WindowError::Singular)?
            .inverse();
        test.known = Some(cov);
        test.known_inv = Some(inv);
        Ok(test)
    }

    /// A test whose every scale remembers the same span of healthy epochs as the longest:
    /// scale `n` keeps `max_blocks · L / n` blocks and judges once it has
    /// `min_blocks · L / n` (L the longest window), so a short window's variance is not
    /// estimated from a few dozen consecutive, correlated inputs (docs/methods.md §M20:
    /// with window 1 and AR(1) inputs of φ = 0.9, 50 inputs carry about 5 independent
    /// ones). Every scale then reports from the same epoch on.
    pub fn with_equal_memory(params: WindowParams) -> Self {
        let mut test = WindowTest::new(params);
        let longest = test.params.longest();
        for s in &mut test.scales {
            let stretch = longest / s.n;
            s.max_blocks = test.params.max_blocks * stretch;
            s.min_blocks = test.params.min_blocks * stretch;
        }
        test
    }

    /// Healthy epochs the test needs before every scale judges (its warm-up).
    pub fn warm_up_epochs(&self) -> usize {
        self.scales
            .iter()
            .map(|s| s.min_blocks * s.n)
            .max()
            .unwrap_or(0)
    }

    /// Whether every scale has its variance (the warm-up is over).
    pub fn is_ready(&self) -> bool {
        self.scales.iter().all(|s| s.estimate.is_some())
    }

    /// The parameters in force.
    pub fn params(&self) -> &WindowParams {
        &self.params
    }

    /// Healthy blocks behind the estimated variance of the shortest scale.
    pub fn blocks(&self) -> usize {
        self.scales
            .iter()
            .map(|s| s.blocks.len())
            .min()
            .unwrap_or(0)
    }

    /// The covariance of one input: estimated from the healthy blocks' inputs of the
    /// first scale with an estimate (second moment about zero), else the known one, else
    /// `None`. Used to normalise inputs for the consistency diagnostics.
    pub fn input_covariance(&self) -> Option<&DMatrix<f64>> {
        self.scales
            .iter()
            .find_map(|s| s.estimate.as_ref().map(|(_, c)| c))
            .or(self.known.as_ref())
    }

    /// `saved` (read from a checkpoint) as the running state of this test: the same
    /// parameters, scales and known covariance, every input `d`-dimensional and no
    /// longer window than the longest scale; with the capacities [`WindowTest::new`]
    /// reserves, so a commit allocates no more than before. The reason when it does
    /// not fit.
    pub fn restored(&self, mut saved: WindowTest) -> Result<WindowTest, String> {
        if saved.params != self.params {
            return Err(format!(
                "window test over {:?} in {} dimensions, the test's is over {:?} in {}",
                saved.params.scales, saved.params.dim, self.params.scales, self.params.dim
            ));
        }
        if saved.known != self.known || saved.known_inv != self.known_inv {
            return Err("window test with another known covariance".into());
        }
        let d = self.params.dim;
        let longest = self.params.longest();
        if saved.window.len() > longest || saved.window.iter().any(|x| x.len() != d) {
            return Err(format!("window test inputs do not fit {longest} × {d}"));
        }
        if saved.scales.len() != self.scales.len() {
            return Err("window test with another number of scales".into());
        }
        saved.scales = self
            .scales
            .iter()
            .zip(saved.scales)
            .map(|(mine, theirs)| mine.restored(theirs, d))
            .collect::<Result<_, _>>()?;
        saved
            .window
            .reserve((longest + 1).saturating_sub(saved.window.len()));
        Ok(saved)
    }

    /// Back to the state of a fresh test (the known covariance is kept).
    pub fn reset(&mut self) {
        self.window.clear();
        for s in &mut self.scales {
            *s = Scale::new(s.n, self.params.dim, s.max_blocks, s.min_blocks);
        }
    }

    fn check(&self, r: &[f64]) -> Result<(), WindowError> {
        if r.len() != self.params.dim {
            return Err(WindowError::Dimension {
                got: r.len(),
                want: self.params.dim,
            });
        }
        if r.iter().any(|v| !v.is_finite()) {
            return Err(WindowError::NonFinite);
        }
        Ok(())
    }

    /// The test over the windows with `r` appended as the newest input, changing nothing.
    /// `Ok(None)` until some scale has a full window and a variance. Below eight components
    /// (every Kalman innovation) the window means are formed on the stack and an
    /// evaluation allocates nothing.
    pub fn evaluate(&self, r: &[f64]) -> Result<Option<WindowValue>, WindowError> {
        self.check(r)?;
        let d = r.len();
        let mut on_stack = [0.0; 7];
        let mut on_heap = Vec::new();
        let mean: &mut [f64] = if d <= on_stack.len() {
            &mut on_stack[..d]
        } else {
            on_heap.resize(d, 0.0);
            &mut on_heap
        };
        let held = self.window.len();
        let mut best: Option<(f64, f64, usize, usize)> = None;
        for scale in &self.scales {
            if held + 1 < scale.n {
                continue;
            }
            // The sum from the newest input, then the window's oldest to newest, as the
            // vector sum `r + Σ x` does.
            mean.copy_from_slice(r);
            for x in self.window.iter().skip(held + 1 - scale.n) {
                for (m, v) in mean.iter_mut().zip(x.as_slice()) {
                    *m += v;
                }
            }
            let n = scale.n as f64;
            for m in mean.iter_mut() {
                *m /= n;
            }
            if let Some((tail, raw, blocks)) = scale.judge(mean, self.known_inv.as_ref())
                && best.is_none_or(|b| tail < b.0)
            {
                best = Some((tail, raw, scale.n, blocks));
            }
        }
        let Some((tail, raw, scale, blocks)) = best else {
            return Ok(None);
        };
        let tail = (tail * self.scales.len() as f64).min(1.0);
        Ok(Some(WindowValue {
            value: chi2_equivalent(self.params.dim as u32, tail),
            tail,
            scale,
            raw,
            blocks,
        }))
    }

    /// Appends `r` to the windows and, when its epoch was healthy, to every scale's block
    /// in progress (completing a block renews that scale's Σ̂); an unhealthy epoch
    /// discards the blocks in progress, so Σ̂ stays frozen.
    pub fn commit(&mut self, r: &[f64], healthy: bool) -> Result<(), WindowError> {
        self.check(r)?;
        // The input that leaves the longest window lends its storage to the new one.
        let r = if self.window.len() >= self.params.longest()
            && let Some(mut old) = self.window.pop_front()
        {
            old.copy_from_slice(r);
            old
        } else {
            DVector::from_column_slice(r)
        };
        for scale in &mut self.scales {
            if healthy {
                scale.add(&r, &self.params);
            } else {
                scale.discard_partial();
            }
        }
        self.window.push_back(r);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, StandardNormal};

    /// AR(1) inputs `x_k = φ x_{k−1} + √(1 − φ²) e_k` (unit variance), `dim` independent
    /// components; returns the share of epochs (after warm-up) above the χ²(dim)
    /// threshold for `p_fa`, all epochs healthy.
    fn exceedance_rate(phi: f64, dim: usize, n: usize, p_fa: f64, epochs: usize, seed: u64) -> f64 {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut test = WindowTest::new(WindowParams::new(dim, &[n]));
        let t = chi2::threshold(dim as u32, p_fa).unwrap();
        let mut x = vec![0.0; dim];
        let (mut tested, mut over) = (0usize, 0usize);
        let g = (1.0 - phi * phi).sqrt();
        for _ in 0..epochs {
            for v in x.iter_mut() {
                let e: f64 = StandardNormal.sample(&mut rng);
                *v = phi * *v + g * e;
            }
            if let Some(v) = test.evaluate(&x).unwrap() {
                tested += 1;
                over += usize::from(v.value > t);
            }
            test.commit(&x, true).unwrap();
        }
        over as f64 / tested as f64
    }

    #[test]
    fn the_in_place_products_equal_nalgebras_to_the_bit() {
        let mut rng = StdRng::seed_from_u64(15);
        for d in 1..=9 {
            for _ in 0..50 {
                let m = DVector::<f64>::from_fn(d, |_, _| StandardNormal.sample(&mut rng));
                let a = DMatrix::<f64>::from_fn(d, d, |_, _| StandardNormal.sample(&mut rng));
                let want = m.dot(&(&a * &m));
                assert_eq!(quadratic_form(&a, m.as_slice()).to_bits(), want.to_bits());

                let mut plus = a.clone();
                add_outer(&mut plus, &m, 1.0);
                let mut minus = a.clone();
                add_outer(&mut minus, &m, -1.0);
                let (want_plus, want_minus) = (&a + &m * m.transpose(), &a - &m * m.transpose());
                for (got, want) in [(plus, want_plus), (minus, want_minus)] {
                    assert!(
                        got.iter()
                            .zip(want.iter())
                            .all(|(g, w)| g.to_bits() == w.to_bits())
                    );
                }
            }
        }
    }

    #[test]
    fn f_tails_match_scipy() {
        // scipy.stats.f.sf(4.0, 1, 20) = 0.05926553544657044
        assert!((f_upper_tail(4.0, 1.0, 20.0) / 0.059_265_535_446_570_44 - 1.0).abs() < 1e-12);
        // scipy.stats.f.sf(40.0, 2, 9) = 3.325341578437592e-05
        assert!((f_upper_tail(40.0, 2.0, 9.0) / 3.325_341_578_437_592e-5 - 1.0).abs() < 1e-12);
        // scipy.stats.f.cdf(0.01, 5, 300) = 2.9566565798124943e-05
        assert!((f_lower_tail(0.01, 5.0, 300.0) / 2.956_656_579_812_494_3e-5 - 1.0).abs() < 1e-12);
        assert_eq!(f_upper_tail(0.0, 3.0, 4.0), 1.0);
        assert_eq!(f_lower_tail(0.0, 3.0, 4.0), 0.0);
    }

    #[test]
    fn the_two_dof_f_tail_closed_form_matches_mpmath() {
        // mpmath at 40 digits, rounded to the nearest f64: (1 + 2x/d2)^(−d2/2). statrs' incomplete beta, the general
        // path, is off by up to 1.4e-14 at these points.
        let reference = [
            (1.0, 1.0, 5.773_502_691_896_257e-1),
            (2.5, 0.3, 7.642_279_086_718_821e-1),
            (9.0, 40.0, 3.325_341_578_437_592_5e-5),
            (40.0, 4.0, 2.608_405_330_458_882_7e-2),
            (600.0, 1e-6, 9.999_990_000_005_017e-1),
            (600.0, 1000.0, 8.981_951_876_037_989e-192),
            (9.0, 0.01, 9.900_608_180_938_072e-1),
        ];
        for (d2, x, want) in reference {
            let got = f_upper_tail(x, 2.0, d2);
            // exp of an exponent of size |ln tail| rounds to about |ln tail| ulp.
            let tol = 2e-16 * (1.0 - f64::ln(want)) + 1e-16;
            assert!(
                (got / want - 1.0).abs() <= tol,
                "F(2, {d2}) at {x}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn chi2_equivalent_inverts_the_chi2_tail() {
        // χ²(1) at 0.002 is 9.5495 (seed 000 Table 1); χ²(3) at 1e-5 is 25.9017.
        assert!((chi2_equivalent(1, 0.002) - 9.5495).abs() < 1e-4);
        assert!((chi2_equivalent(3, 1e-5) - 25.9017).abs() < 1e-4);
        assert_eq!(chi2_equivalent(2, 1.0), 0.0);
        assert!(
            chi2_equivalent(1, 0.0) > 1300.0,
            "saturates at the 1e-300 tail"
        );
    }

    #[test]
    fn with_white_inputs_it_is_the_f_test_by_hand() {
        // n = 2, d = 1, min_blocks = max_blocks = 2: blocks [1, 3] → mean 2 and [−1, 0]
        // → −0.5; Σ̂ = (4 + 0.25)/2 = 2.125. Window [0, 2] → m = 1, T² = 1/2.125.
        let mut test = WindowTest::new(WindowParams {
            dim: 1,
            scales: vec![2],
            max_blocks: 2,
            min_blocks: 2,
        });
        for r in [1.0, 3.0, -1.0, 0.0] {
            test.commit(&[r], true).unwrap();
        }
        let v = test.evaluate(&[2.0]).unwrap().unwrap();
        let raw = 1.0 / 2.125;
        assert!((v.raw - raw).abs() < 1e-15);
        assert_eq!(v.scale, 2);
        // F = T² (B − d + 1)/(B d) = raw · 2/2 with dof (1, 2).
        let tail = f_upper_tail(raw, 1.0, 2.0);
        assert!((v.tail - tail).abs() < 1e-15);
        assert!((v.value - chi2::threshold(1, tail).unwrap()).abs() < 1e-12);
        assert_eq!(v.blocks, 2);
        // Per-input covariance: (1 + 9 + 1 + 0)/4.
        assert!((test.input_covariance().unwrap()[(0, 0)] - 2.75).abs() < 1e-15);
    }

    #[test]
    fn fault_free_rate_is_nominal_for_white_and_strongly_coloured_inputs() {
        // 200,000 epochs at p_fa 0.01: binomial sd of the marginal rate is tiny, but the
        // windows overlap (n = 10), so exceedances come in clusters; allow ±30 %.
        for (phi, seed) in [(0.0, 1), (0.9, 2), (0.97, 3)] {
            let rate = exceedance_rate(phi, 1, 10, 0.01, 200_000, seed);
            assert!(
                (0.007..0.014).contains(&rate),
                "φ = {phi}: {rate} of epochs above the 1 % threshold"
            );
        }
        let rate = exceedance_rate(0.9, 2, 10, 0.01, 200_000, 4);
        assert!((0.007..0.014).contains(&rate), "d = 2: {rate}");
    }

    #[test]
    fn two_scales_stay_at_or_below_the_nominal_rate() {
        // Bonferroni over windows 1 and 10 of AR(1) φ = 0.9 inputs: the two tests are
        // positively dependent, so the rate is at most p_fa and above p_fa / 2.
        let mut rng = StdRng::seed_from_u64(7);
        let mut test = WindowTest::new(WindowParams::new(1, &[1, 10]));
        let t = chi2::threshold(1, 0.01).unwrap();
        let (mut x, mut over, mut tested) = (0.0f64, 0usize, 0usize);
        for _ in 0..200_000 {
            let e: f64 = StandardNormal.sample(&mut rng);
            x = 0.9 * x + (1.0f64 - 0.81).sqrt() * e;
            if let Some(v) = test.evaluate(&[x]).unwrap() {
                tested += 1;
                over += usize::from(v.value > t);
            }
            test.commit(&[x], true).unwrap();
        }
        let rate = over as f64 / tested as f64;
        assert!((0.005..0.0115).contains(&rate), "{rate}");
    }

    #[test]
    fn an_uncalibrated_window_would_be_far_off_on_coloured_inputs() {
        // The same AR(1) φ = 0.9 inputs judged with the per-input variance (what a
        // white-noise assumption does): Var(mean of 10) is ≈ 6.4× σ²/10 here.
        let mut test = WindowTest::with_known_covariance(
            WindowParams {
                dim: 1,
                scales: vec![10],
                max_blocks: 50,
                min_blocks: 1_000_000,
            },
            DMatrix::identity(1, 1),
        )
        .unwrap();
        let mut rng = StdRng::seed_from_u64(5);
        let t = chi2::threshold(1, 0.01).unwrap();
        let (mut x, mut over, mut tested) = (0.0f64, 0, 0);
        for _ in 0..100_000 {
            let e: f64 = StandardNormal.sample(&mut rng);
            x = 0.9 * x + (1.0f64 - 0.81).sqrt() * e;
            if let Some(v) = test.evaluate(&[x]).unwrap() {
                tested += 1;
                over += usize::from(v.value > t);
            }
            test.commit(&[x], true).unwrap();
        }
        let rate = over as f64 / tested as f64;
        assert!(rate > 0.15, "{rate}");
    }

    #[test]
    fn a_mean_shift_of_four_sigma_over_root_n_is_flagged_and_freezes_the_variance() {
        let mut test = WindowTest::new(WindowParams::new(1, &[1, 10]));
        let mut rng = StdRng::seed_from_u64(6);
        for _ in 0..1000 {
            let e: f64 = StandardNormal.sample(&mut rng);
            test.commit(&[e], true).unwrap();
        }
        let blocks = test.blocks();
        let t = chi2::threshold(1, 0.002).unwrap();
        // A 4σ step: the window mean moves 0.4σ per epoch against sd 1/√10 = 0.32σ.
        let mut first = None;
        for k in 0..10 {
            let e: f64 = StandardNormal.sample(&mut rng);
            let r = 4.0 + e;
            let v = test.evaluate(&[r]).unwrap().unwrap();
            if v.value > t && first.is_none() {
                first = Some(k);
            }
            test.commit(&[r], v.value <= t).unwrap();
        }
        assert!(first.unwrap() <= 3, "{first:?}");
        // Unhealthy epochs complete no block.
        assert!(test.blocks() <= blocks + 1);
    }

    #[test]
    fn equal_memory_scales_span_the_same_epochs_and_report_together() {
        let mut test = WindowTest::with_equal_memory(WindowParams {
            dim: 1,
            scales: vec![1, 10],
            max_blocks: 5,
            min_blocks: 3,
        });
        // Scale 10 needs 3 blocks (30 epochs); scale 1 then needs 30 blocks of one.
        assert_eq!(test.warm_up_epochs(), 30);
        let mut rng = StdRng::seed_from_u64(8);
        for k in 0..29 {
            let e: f64 = StandardNormal.sample(&mut rng);
            test.commit(&[e], true).unwrap();
            assert!(!test.is_ready(), "{k}");
        }
        assert_eq!(test.evaluate(&[0.0]).unwrap(), None);
        test.commit(&[1.0], true).unwrap();
        assert!(test.is_ready());
        for _ in 0..200 {
            let e: f64 = StandardNormal.sample(&mut rng);
            test.commit(&[e], true).unwrap();
        }
        // Scale 1 keeps 5·10 blocks, scale 10 five: both span the last 50 epochs.
        assert_eq!(test.scales[0].blocks.len(), 50);
        assert_eq!(test.scales[1].blocks.len(), 5);
    }

    #[test]
    fn equal_memory_keeps_a_short_window_calibrated_on_coloured_inputs() {
        // AR(1) φ = 0.9, windows 1 and 10, p_fa 0.002: the short window's variance comes
        // from 500 inputs, not 50, so the rate stays near the nominal one.
        let mut rng = StdRng::seed_from_u64(9);
        let mut test = WindowTest::with_equal_memory(WindowParams::new(1, &[1, 10]));
        let t = chi2::threshold(1, 0.002).unwrap();
        let (mut x, mut over, mut tested) = (0.0f64, 0usize, 0usize);
        for _ in 0..150_000 {
            let e: f64 = StandardNormal.sample(&mut rng);
            x = 0.9 * x + (1.0f64 - 0.81).sqrt() * e;
            if let Some(v) = test.evaluate(&[x]).unwrap() {
                tested += 1;
                over += usize::from(v.value > t);
            }
            test.commit(&[x], true).unwrap();
        }
        let rate = over as f64 / tested as f64;
        assert!((0.0008..0.004).contains(&rate), "{rate}");
    }

    #[test]
    fn known_covariance_reports_from_the_first_full_window() {
        let mut test =
            WindowTest::with_known_covariance(WindowParams::new(2, &[3]), DMatrix::identity(2, 2))
                .unwrap();
        assert_eq!(test.evaluate(&[1.0, 0.0]).unwrap(), None);
        test.commit(&[1.0, 0.0], true).unwrap();
        test.commit(&[1.0, 0.0], true).unwrap();
        // m = (1, 0), n mᵀ m = 3.
        let v = test.evaluate(&[1.0, 0.0]).unwrap().unwrap();
        // Through the tail e^(−3/2) and back: a few ulp.
        assert!((v.value - 3.0).abs() < 4e-15);
        assert_eq!(v.blocks, 0);
        assert!(matches!(
            WindowTest::with_known_covariance(WindowParams::new(2, &[3]), DMatrix::zeros(2, 2)),
            Err(WindowError::Singular)
        ));
    }

    #[test]
    fn bad_inputs_are_errors_not_panics() {
        let test = WindowTest::new(WindowParams::new(2, &[3]));
        assert!(matches!(
            test.evaluate(&[1.0]),
            Err(WindowError::Dimension { got: 1, want: 2 })
        ));
        assert_eq!(test.evaluate(&[f64::NAN, 0.0]), Err(WindowError::NonFinite));
        let mut test = WindowTest::new(WindowParams::new(1, &[1]));
        // A constant zero signal: Σ̂ = 0 is singular, the test stays idle.
        for _ in 0..20 {
            test.commit(&[0.0], true).unwrap();
        }
        assert_eq!(test.evaluate(&[0.0]).unwrap(), None);
    }
}
