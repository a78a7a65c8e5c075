//! Online sliding-window LS-SVM (seed 001 §2.2, docs/methods.md §M11), the channel monitor's
//! adaptive predictor: when a sample enters and the oldest leaves, `P = H⁻¹ =
//! (Ω + I/γ)⁻¹` is updated in O(N²) by block (Schur-complement) remove and add steps
//! instead of re-solved in O(N³); every `refresh` updates it is re-factorised from
//! scratch to bound round-off drift.
//!
//! Raw units: the window is not standardised (a sliding window has no fixed training
//! statistics), so `sigma2` is in squared input units. Kernel: RBF.
//!
//! Storage is by slot: a sample keeps its row/column of `P` for its life and the
//! newcomer takes the leaver's slot, so nothing is shifted. `η = P·1` and `ν = P·y`
//! are updated in O(N) alongside `P`, giving `b = 1ᵀν / 1ᵀη` and `α = ν − bη` (the
//! two-solve trick) without a solve.

use serde::{Deserialize, Serialize};

use super::lssvm_solve as solve;
use super::{Kernel, LearnError};

/// Parameters of the online window (raw units: no standardisation).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OnlineParams {
    /// Window length N (≥ 2).
    pub window: usize,
    /// Regularisation γ (> 0).
    pub gamma: f64,
    /// RBF width σ² (> 0), squared input units.
    pub sigma2: f64,
    /// Re-factorise from scratch every this many updates (≥ 1, default 1000).
    #[serde(default = "default_refresh")]
    pub refresh: usize,
}

fn default_refresh() -> usize {
    1000
}

impl OnlineParams {
    /// Validates the parameters; the error names the field.
    pub fn check(&self) -> Result<(), LearnError> {
        if self.window < 2 {
            return Err(LearnError::params("window", "must be at least 2"));
        }
        if !(self.gamma.is_finite() && self.gamma > 0.0) {
            return Err(LearnError::params(
                "gamma",
                "must be a finite number greater than 0",
            ));
        }
        Kernel::Rbf {
            sigma2: self.sigma2,
        }
        .check()?;
        if self.refresh == 0 {
            return Err(LearnError::params("refresh", "must be at least 1"));
        }
        Ok(())
    }
}

/// The sliding-window model (serde: a monitor checkpoint saves it, parameters included,
/// scratch buffers not; [`OnlineLsSvm::restored`] checks it).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct OnlineLsSvm {
    params: OnlineParams,
    kernel: Kernel,
    /// Input dimension, fixed by the first sample.
    dim: usize,
    /// Samples by slot, `dim` values each.
    xs: Vec<f64>,
    /// Targets by slot.
    ys: Vec<f64>,
    /// `H⁻¹` by slot, N × N row-major, symmetric: only the upper triangle (`j ≥ i`) is
    /// kept current between refreshes (half the memory traffic per slide); rows and
    /// columns of free slots are 0.
    p: Vec<f64>,
    /// `η = H⁻¹1` and `ν = H⁻¹y` by slot.
    eta: Vec<f64>,
    nu: Vec<f64>,
    /// `α` by slot and `b`, current after every push.
    alpha: Vec<f64>,
    b: f64,
    /// Samples in the window.
    len: usize,
    /// Slot of the oldest sample once the window is full (the next to leave).
    oldest: usize,
    /// Updates since the last re-factorisation.
    since_refresh: usize,
    /// The last add's rank-1 term `u uᵀ / s`, not yet applied to `p` (`pending_s` = 0:
    /// none): it is folded into the next slide's single pass over `P`.
    pending_u: Vec<f64>,
    pending_s: f64,
    /// Scratch: kernel column of the newcomer, `u = P k`, leaver's row (each written in
    /// full before it is read, so not part of the state).
    #[serde(skip)]
    k: Vec<f64>,
    #[serde(skip)]
    u: Vec<f64>,
    #[serde(skip)]
    q: Vec<f64>,
}

impl OnlineLsSvm {
    /// An empty window.
    pub fn new(params: OnlineParams) -> Result<Self, LearnError> {
        params.check()?;
        let n = params.window;
        Ok(OnlineLsSvm {
            kernel: Kernel::Rbf {
                sigma2: params.sigma2,
            },
            params,
            dim: 0,
            xs: Vec::new(),
            ys: vec![0.0; n],
            p: vec![0.0; n * n],
            eta: vec![0.0; n],
            nu: vec![0.0; n],
            alpha: vec![0.0; n],
            b: 0.0,
            len: 0,
            oldest: 0,
            since_refresh: 0,
            pending_u: vec![0.0; n],
            pending_s: 0.0,
            k: vec![0.0; n],
            u: vec![0.0; n],
            q: vec![0.0; n],
        })
    }

    /// The parameters.
    pub fn params(&self) -> &OnlineParams {
        &self.params
    }

    /// The input dimension, fixed by the first sample (0 before it).
    pub fn input_dim(&self) -> usize {
        self.dim
    }

    /// `saved` (read from a checkpoint) as the running state of this window: the same
    /// parameters and kernel, every buffer of the window's size, counts within it; the
    /// scratch buffers are allocated here, as [`OnlineLsSvm::new`] does. The reason
    /// otherwise.
    pub fn restored(&self, mut saved: OnlineLsSvm) -> Result<OnlineLsSvm, String> {
        if saved.params != self.params || saved.kernel != self.kernel {
            return Err(format!(
                "online window {:?}, the channel's is {:?}",
                saved.params, self.params
            ));
        }
        let n = self.params.window;
        let fits = saved.xs.len() == n * saved.dim
            && [
                &saved.ys,
                &saved.eta,
                &saved.nu,
                &saved.alpha,
                &saved.pending_u,
            ]
            .iter()
            .all(|v| v.len() == n)
            && saved.p.len() == n * n
            && saved.len <= n
            && (saved.dim > 0 || saved.len == 0)
            && (saved.oldest < n)
            && saved.since_refresh < self.params.refresh;
        if !fits {
            return Err("online window state does not fit its parameters".into());
        }
        saved.k = vec![0.0; n];
        saved.u = vec![0.0; n];
        saved.q = vec![0.0; n];
        Ok(saved)
    }

    /// Samples in the window.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when the window holds no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Slots in chronological order, oldest first.
    fn slots(&self) -> impl Iterator<Item = usize> + '_ {
        let n = self.params.window;
        (0..self.len).map(move |i| {
            if self.len == n {
                (self.oldest + i) % n
            } else {
                i
            }
        })
    }

    /// `(α, b)` with `α` oldest first, as a batch solve of the window gives them.
    pub fn coefficients(&self) -> (Vec<f64>, f64) {
        (self.slots().map(|s| self.alpha[s]).collect(), self.b)
    }

    /// The window's samples oldest first: inputs (`dim` values each) and targets.
    pub fn window(&self) -> (Vec<f64>, Vec<f64>) {
        let d = self.dim;
        let xs = self
            .slots()
            .flat_map(|s| self.xs[s * d..(s + 1) * d].iter().copied())
            .collect();
        (xs, self.slots().map(|s| self.ys[s]).collect())
    }

    /// Adds a sample; once the window is full the oldest leaves. The first sample
    /// fixes the input dimension; later ones must match it and be finite.
    pub fn push(&mut self, x: &[f64], y: f64) -> Result<(), LearnError> {
        if self.dim == 0 {
            if x.is_empty() {
                return Err(LearnError::data("x", "a sample needs at least one feature"));
            }
            self.dim = x.len();
            self.xs = vec![0.0; self.params.window * self.dim];
        }
        if x.len() != self.dim {
            return Err(LearnError::data(
                "x",
                format!("has {} features, the window holds {}", x.len(), self.dim),
            ));
        }
        if let Some(j) = x.iter().position(|v| !v.is_finite()) {
            return Err(LearnError::data(format!("x[{j}]"), "must be finite"));
        }
        if !y.is_finite() {
            return Err(LearnError::data("y", "must be finite"));
        }
        let (n, d) = (self.params.window, self.dim);
        let full = self.len == n;
        let slot = if full { self.oldest } else { self.len };
        self.xs[slot * d..(slot + 1) * d].copy_from_slice(x);
        self.ys[slot] = y;
        if full {
            self.oldest = (slot + 1) % n;
        } else {
            self.len += 1;
        }
        self.kernel_column(slot);
        if full {
            self.remove_and_project(slot);
        } else {
            self.project();
        }
        self.since_refresh += 1;
        if self.since_refresh >= self.params.refresh || !self.add(slot, full) {
            self.refresh()?;
        }
        self.update_coefficients();
        Ok(())
    }

    /// `k`: the kernel column of the sample in `slot` against the other samples in the
    /// window (0 at `slot` and at free slots).
    fn kernel_column(&mut self, slot: usize) {
        let (n, d) = (self.params.window, self.dim);
        let x = &self.xs[slot * d..(slot + 1) * d];
        let scale = -1.0 / self.params.sigma2;
        for s in 0..n {
            let active = s != slot && (self.len == n || s < self.len);
            self.k[s] = if active {
                let d2: f64 = self.xs[s * d..(s + 1) * d]
                    .iter()
                    .zip(x)
                    .map(|(a, b)| (a - b) * (a - b))
                    .sum();
                solve::exp_nonpos(d2 * scale)
            } else {
                0.0
            };
        }
    }

    /// `u = P k` from the upper triangle: row `i` gives `kᵢ P[i, i..]` (axpy) to
    /// `u[i..]` and `P[i, i+1..]·k[i+1..]` (dot) to `u[i]`.
    fn project(&mut self) {
        let n = self.params.window;
        self.u.iter_mut().for_each(|v| *v = 0.0);
        for i in 0..n {
            let row = &self.p[i * n..(i + 1) * n];
            let ki = self.k[i];
            if ki != 0.0 {
                for (u, pij) in self.u[i..].iter_mut().zip(&row[i..]) {
                    *u += ki * pij;
                }
            }
            self.u[i] += solve::dot(&row[i + 1..], &self.k[i + 1..]);
        }
    }

    /// Schur-complement removal of the sample that held `slot`, fused with the pending
    /// rank-1 term of the previous add and with [`Self::project`], in one pass over `P`
    /// (the step is bound by memory traffic, so one pass instead of three is what
    /// makes it fast): with `q` the leaver's row of the true `P` and `p = q[slot]`, the
    /// inverse without it is `P − q qᵀ / p` on the other slots, and `u = P' k` is
    /// accumulated from each updated row.
    fn remove_and_project(&mut self, slot: usize) {
        let n = self.params.window;
        let ps = self.pending_s;
        // The leaver's row of the symmetric P, gathered from the upper triangle.
        for j in 0..n {
            self.q[j] = self.p[j.min(slot) * n + j.max(slot)];
        }
        if ps != 0.0 {
            let a = self.pending_u[slot] / ps;
            for (qj, uj) in self.q.iter_mut().zip(&self.pending_u) {
                *qj += a * uj;
            }
        }
        let pss = self.q[slot];
        // η' = η − q η_s / p (likewise ν), derived from η = P1 block-wise.
        let (fe, fn_) = (self.eta[slot] / pss, self.nu[slot] / pss);
        for i in 0..n {
            self.eta[i] -= self.q[i] * fe;
            self.nu[i] -= self.q[i] * fn_;
        }
        self.u.iter_mut().for_each(|v| *v = 0.0);
        let pass = SlidePass {
            q: &self.q,
            pending_u: &self.pending_u,
            k: &self.k,
            ps,
            pss,
        };
        pass.run(&mut self.p, &mut self.u);
        self.pending_s = 0.0;
        self.clear_slot(slot);
        self.u[slot] = 0.0;
    }

    fn clear_slot(&mut self, slot: usize) {
        let n = self.params.window;
        self.p[slot * n..(slot + 1) * n]
            .iter_mut()
            .for_each(|v| *v = 0.0);
        for i in 0..n {
            self.p[i * n + slot] = 0.0;
        }
        self.eta[slot] = 0.0;
        self.nu[slot] = 0.0;
    }

    /// Schur-complement addition of the sample already stored in `slot` (whose row and
    /// column of `P` are 0), given `k` and `u = P k`: with
    /// `s = K(x, x) + 1/γ − kᵀu`, the new inverse is
    /// `[[P + u uᵀ/s, −u/s], [−uᵀ/s, 1/s]]`. False if `s` is not positive (then the
    /// caller re-factorises).
    fn add(&mut self, slot: usize, defer: bool) -> bool {
        let n = self.params.window;
        let schur = 1.0 + 1.0 / self.params.gamma - solve::dot(&self.k, &self.u);
        if !(schur > 0.0 && schur.is_finite()) {
            return false;
        }
        // η and ν of the grown system (block inverse times 1 and y), O(N).
        let sum_u: f64 = self.u.iter().sum();
        let y = self.ys[slot];
        let uy = solve::dot(&self.u, &self.ys) - self.u[slot] * y;
        for i in 0..n {
            self.eta[i] += self.u[i] * (sum_u - 1.0) / schur;
            self.nu[i] += self.u[i] * (uy - y) / schur;
        }
        self.eta[slot] = (1.0 - sum_u) / schur;
        self.nu[slot] = (y - uy) / schur;
        if defer {
            // u[slot] = 0, so the deferred term leaves row/column `slot` alone.
            self.pending_u.copy_from_slice(&self.u);
            self.pending_s = schur;
        } else {
            self.apply_rank1(schur);
        }
        for i in 0..n {
            self.p[i * n + slot] = -self.u[i] / schur;
            self.p[slot * n + i] = -self.u[i] / schur;
        }
        self.p[slot * n + slot] = 1.0 / schur;
        true
    }

    /// `P += u uᵀ / s` (upper triangle).
    fn apply_rank1(&mut self, schur: f64) {
        let n = self.params.window;
        for i in 0..n {
            let f = self.u[i] / schur;
            if f == 0.0 {
                continue;
            }
            for (pij, uj) in self.p[i * n + i..(i + 1) * n].iter_mut().zip(&self.u[i..]) {
                *pij += f * uj;
            }
        }
    }

    /// Re-factorises `H` of the current window from scratch (Cholesky, then the
    /// explicit inverse) and recomputes `η`, `ν`: O(N³), run every `refresh` updates.
    pub fn refresh(&mut self) -> Result<(), LearnError> {
        let (n, d) = (self.params.window, self.dim);
        self.since_refresh = 0;
        self.pending_s = 0.0;
        if self.len == 0 {
            return Ok(());
        }
        // Active slots are 0..len whether or not the window is full.
        let m = self.len;
        let mut h =
            solve::regularised_kernel(&self.xs[..m * d], d, &self.kernel, self.params.gamma);
        solve::cholesky(&mut h)?;
        let inv = solve::inverse_from_cholesky(&h);
        self.p.iter_mut().for_each(|v| *v = 0.0);
        for i in 0..m {
            for j in 0..m {
                self.p[i * n + j] = inv[(i, j)];
            }
        }
        for i in 0..n {
            let row = &self.p[i * n..(i + 1) * n];
            self.eta[i] = row.iter().sum();
            self.nu[i] = solve::dot(row, &self.ys);
        }
        Ok(())
    }

    /// `b = 1ᵀν / 1ᵀη`, `α = ν − bη` (seed 000 eq. 6 by the two-solve trick).
    fn update_coefficients(&mut self) {
        let se: f64 = self.eta.iter().sum();
        let sn: f64 = self.nu.iter().sum();
        self.b = sn / se;
        for i in 0..self.params.window {
            self.alpha[i] = self.nu[i] - self.b * self.eta[i];
        }
    }

    /// The model term `m(x)` of the prediction at `x` (docs/methods.md §M9a; its variance
    /// is `σ_e² (1 + γ m(x))`); `None` when [`OnlineLsSvm::predict`] gives none. See
    /// [`OnlineLsSvm::predict_with_term`].
    pub fn model_term(&self, x: &[f64]) -> Option<f64> {
        self.predict_with_term(x).map(|(_, term)| term)
    }

    /// The prediction at `x` (bit for bit [`OnlineLsSvm::predict`]'s) and its model term
    /// from the same kernel row: `kᵀPk` over the upper triangle of the inverse the window
    /// keeps plus the pending rank-1 term, and `ηᵀk`, `1ᵀη` for the bias, so O(N²) like
    /// the slide.
    pub fn predict_with_term(&self, x: &[f64]) -> Option<(f64, f64)> {
        if self.len < 2 || x.len() != self.dim {
            return None;
        }
        let (n, d) = (self.params.window, self.dim);
        let m = self.len;
        let k: Vec<f64> = self.xs[..m * d]
            .chunks_exact(d)
            .map(|xi| solve::kernel_value(&self.kernel, xi, x))
            .collect();
        let f = k
            .iter()
            .zip(&self.alpha[..m])
            .fold(self.b, |f, (ki, a)| f + a * ki);
        let mut quad = 0.0;
        for (i, ki) in k.iter().enumerate() {
            let row = &self.p[i * n + i..i * n + m];
            quad += ki * (ki * row[0] + 2.0 * solve::dot(&row[1..], &k[i + 1..]));
        }
        if self.pending_s != 0.0 {
            quad += solve::dot(&k, &self.pending_u[..m]).powi(2) / self.pending_s;
        }
        let a = solve::dot(&k, &self.eta[..m]);
        let c: f64 = self.eta.iter().sum();
        let term = (self.kernel.eval(x, x) - quad + (1.0 - a) * (1.0 - a) / c).max(0.0);
        Some((f, term))
    }

    /// `f(x) = Σ αᵢ K(xᵢ, x) + b`, or `None` until the window holds at least two
    /// samples or when `x` has the wrong dimension.
    pub fn predict(&self, x: &[f64]) -> Option<f64> {
        if self.len < 2 || x.len() != self.dim {
            return None;
        }
        let m = if self.len == self.params.window {
            self.params.window
        } else {
            self.len
        };
        Some(solve::evaluate(
            &self.xs[..m * self.dim],
            self.dim,
            &self.alpha[..m],
            self.b,
            &self.kernel,
            x,
        ))
    }
}

/// The one pass over `P`'s upper triangle of a slide: `P += a uₚᵀ − f qᵀ` row by row
/// (`a = uₚ/s`, `f = q/p`), accumulating `u = P k` as `project` does.
struct SlidePass<'a> {
    q: &'a [f64],
    pending_u: &'a [f64],
    k: &'a [f64],
    ps: f64,
    pss: f64,
}

impl SlidePass<'_> {
    /// Runs the pass with AVX2 when [`crate::simd::avx2`] allows it (the default x86-64
    /// target only assumes SSE2; twice the vector width matters for this bandwidth-bound
    /// loop).
    fn run(&self, p: &mut [f64], u: &mut [f64]) {
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2() {
            // SAFETY: the CPU supports AVX2, checked just above.
            unsafe { self.run_avx2(p, u) };
            return;
        }
        self.run_generic(p, u);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn run_avx2(&self, p: &mut [f64], u: &mut [f64]) {
        self.run_generic(p, u);
    }

    #[inline(always)]
    fn run_generic(&self, p: &mut [f64], u: &mut [f64]) {
        let n = self.q.len();
        for (i, row) in p.chunks_exact_mut(n).enumerate() {
            let a = if self.ps != 0.0 {
                self.pending_u[i] / self.ps
            } else {
                0.0
            };
            let f = self.q[i] / self.pss;
            let ki = self.k[i];
            for (((pij, qj), pu), uj) in row[i..]
                .iter_mut()
                .zip(&self.q[i..])
                .zip(&self.pending_u[i..])
                .zip(u[i..].iter_mut())
            {
                *pij += a * pu - f * qj;
                *uj += ki * *pij;
            }
            u[i] += solve::dot(&row[i + 1..], &self.k[i + 1..]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    #[test]
    fn the_avx2_slide_equals_the_baseline_build_to_the_bit() {
        // `SlidePass::run` takes its AVX2 build on a CPU with AVX2 (`crate::simd::avx2`);
        // `run_generic` called from this function is the baseline build.
        let mut rng = StdRng::seed_from_u64(9);
        let n = 23;
        let mut draw =
            |len: usize| -> Vec<f64> { (0..len).map(|_| rng.random::<f64>() - 0.5).collect() };
        let (q, pending_u, k, p0, u0) = (draw(n), draw(n), draw(n), draw(n * n), draw(n));
        for ps in [0.0, 0.37] {
            let pass = SlidePass {
                q: &q,
                pending_u: &pending_u,
                k: &k,
                ps,
                pss: 1.9,
            };
            let (mut p_fast, mut u_fast) = (p0.clone(), u0.clone());
            let (mut p_base, mut u_base) = (p0.clone(), u0.clone());
            pass.run(&mut p_fast, &mut u_fast);
            pass.run_generic(&mut p_base, &mut u_base);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&p_fast), bits(&p_base), "P, ps = {ps}");
            assert_eq!(bits(&u_fast), bits(&u_base), "u, ps = {ps}");
        }
    }

    fn series(k: usize) -> ([f64; 3], f64) {
        // A smooth nonlinear channel embedded with m = 3.
        let t = |j: usize| ((j as f64) * 0.07).sin() + 0.3 * ((j as f64) * 0.011).cos();
        ([t(k), t(k + 1), t(k + 2)], t(k + 3))
    }

    fn batch(w: &OnlineLsSvm) -> (Vec<f64>, f64) {
        let (xs, ys) = w.window();
        let s = solve::fit(&xs, w.dim, &ys, &w.kernel, w.params.gamma).unwrap();
        (s.alpha, s.b)
    }

    fn assert_close(online: (Vec<f64>, f64), batch: (Vec<f64>, f64), tol: f64) {
        let scale = batch.0.iter().fold(batch.1.abs(), |m, a| m.max(a.abs()));
        assert!(
            (online.1 - batch.1).abs() <= tol * scale,
            "b {} vs {}",
            online.1,
            batch.1
        );
        for (a, b) in online.0.iter().zip(&batch.0) {
            assert!((a - b).abs() <= tol * scale, "α {a} vs {b}");
        }
    }

    #[test]
    fn ten_thousand_slides_match_a_batch_solve_of_the_window() {
        // refresh = 1000 (default) and refresh never (drift of 10,000 pure Schur steps).
        for refresh in [1000, 1_000_000] {
            let params = OnlineParams {
                window: 30,
                gamma: 30.0,
                sigma2: 9.0,
                refresh,
            };
            let mut w = OnlineLsSvm::new(params).unwrap();
            for k in 0..10_040 + 7 {
                let (x, y) = series(k);
                w.push(&x, y).unwrap();
            }
            assert_eq!(w.len(), 30);
            assert_close(w.coefficients(), batch(&w), 1e-8);
        }
    }

    #[test]
    fn a_filling_window_matches_batch_at_every_size() {
        let params = OnlineParams {
            window: 10,
            gamma: 5.0,
            sigma2: 0.5,
            refresh: 1000,
        };
        let mut w = OnlineLsSvm::new(params).unwrap();
        assert!(w.is_empty() && w.predict(&[0.0, 0.0, 0.0]).is_none());
        for k in 0..25 {
            let (x, y) = series(3 * k);
            w.push(&x, y).unwrap();
            if w.len() >= 2 {
                assert_close(w.coefficients(), batch(&w), 1e-10);
            }
        }
        let (x, _) = series(80);
        let (xs, ys) = w.window();
        let (alpha, b) = batch(&w);
        let expected = solve::evaluate(&xs, 3, &alpha, b, &w.kernel, &x);
        assert!((w.predict(&x).unwrap() - expected).abs() < 1e-10);
        assert_eq!(ys.len(), 10);
    }

    #[test]
    fn the_variance_term_equals_the_gp_posterior_of_the_window_while_it_fills_and_slides() {
        use crate::learn::variance::bordered_reference;
        // refresh 7 puts re-factorisations between the checks; the pending rank-1 term
        // is present on every check after the window is full.
        let params = OnlineParams {
            window: 25,
            gamma: 30.0,
            sigma2: 2.0,
            refresh: 7,
        };
        let mut w = OnlineLsSvm::new(params).unwrap();
        for k in 0..400 {
            let (x, y) = series(k);
            w.push(&x, y).unwrap();
            if w.len() < 2 || k % 13 != 0 {
                continue;
            }
            let (xs, _) = w.window();
            for query in [series(k + 1).0, [2.0, -1.0, 0.5], [9.0, 9.0, 9.0]] {
                let reference = bordered_reference(&xs, 3, w.kernel, 30.0, &query);
                let got = w.model_term(&query).unwrap();
                assert!(
                    (got - reference).abs() <= 1e-9 * reference,
                    "k {k}: {got:e} vs {reference:e}"
                );
            }
        }
        assert_eq!(w.model_term(&[1.0]), None);
    }

    #[test]
    fn bad_params_and_samples_are_refused_by_name() {
        let ok = OnlineParams {
            window: 10,
            gamma: 5.0,
            sigma2: 0.5,
            refresh: 1000,
        };
        let field = |p: OnlineParams| match OnlineLsSvm::new(p) {
            Err(LearnError::InvalidParams { field, .. }) => field,
            other => panic!("{other:?}"),
        };
        assert_eq!(
            field(OnlineParams {
                window: 1,
                ..ok.clone()
            }),
            "window"
        );
        assert_eq!(
            field(OnlineParams {
                gamma: 0.0,
                ..ok.clone()
            }),
            "gamma"
        );
        assert_eq!(
            field(OnlineParams {
                sigma2: -1.0,
                ..ok.clone()
            }),
            "sigma2"
        );
        assert_eq!(
            field(OnlineParams {
                refresh: 0,
                ..ok.clone()
            }),
            "refresh"
        );
        let mut w = OnlineLsSvm::new(ok).unwrap();
        w.push(&[1.0, 2.0], 0.0).unwrap();
        assert!(matches!(
            w.push(&[1.0], 0.0),
            Err(LearnError::InvalidData { .. })
        ));
        assert!(matches!(
            w.push(&[1.0, f64::NAN], 0.0),
            Err(LearnError::InvalidData { .. })
        ));
        assert_eq!(w.len(), 1);
    }
}
