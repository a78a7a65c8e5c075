//! The SMO solver behind C-SVC and the one-class SVM: libsvm's `Solver` (Chang &
//! Lin 2011) for the dual
//! `min ½ αᵀQα + pᵀα  s.t.  yᵀα = Δ, 0 ≤ α_i ≤ C_i` with `Q_ij = y_i y_j K(x_i, x_j)`,
//! second-order working-set selection (Fan, Chen & Lin 2005, "WSS 2"), shrinking
//! with gradient reconstruction before the final optimality check, and kernel rows
//! from an LRU [`super::cache::RowCache`]. Pure and deterministic: the same problem gives the
//! same iterates. Called by [`super::svc`] and [`super::ocsvm`].

use super::rows::QMatrix;
use crate::learn::{Kernel, LearnError, Progress};

/// libsvm's `TAU`: the curvature used when `K_ii + K_jj − 2K_ij ≤ 0`.
const TAU: f64 = 1e-12;

/// One dual problem. `x` holds `n` samples of dimension `dim`, row-major.
#[derive(Debug, Clone)]
pub struct Problem<'a> {
    /// Samples, row-major (`n · dim` values).
    pub x: &'a [f64],
    /// Dimension of a sample.
    pub dim: usize,
    /// The kernel.
    pub kernel: Kernel,
    /// Signs `y_i ∈ {+1, −1}`.
    pub y: Vec<f64>,
    /// Linear term `p`.
    pub p: Vec<f64>,
    /// A feasible starting point (its `yᵀα` fixes Δ).
    pub alpha: Vec<f64>,
    /// Upper bound for `y_i = +1`.
    pub c_pos: f64,
    /// Upper bound for `y_i = −1`.
    pub c_neg: f64,
}

/// Solver settings (the user's `tol`, `cache_mb`, `shrinking`, `max_iter`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Stop when the maximal violating pair's gap `m(α) − M(α)` is below this.
    pub tol: f64,
    /// Kernel cache budget, MiB.
    pub cache_mb: f64,
    /// Shrink the active set.
    pub shrinking: bool,
    /// Iteration limit; reaching it is an error.
    pub max_iter: usize,
}

/// The solution, in the caller's sample order.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// Dual variables.
    pub alpha: Vec<f64>,
    /// Offset ρ: the decision is `Σ y_i α_i K(x_i, x) − ρ`.
    pub rho: f64,
    /// Dual objective `½ αᵀQα + pᵀα`.
    pub objective: f64,
    /// SMO iterations.
    pub iterations: usize,
    /// Gradient `Qα + p` at the solution (gives the training decisions for free).
    pub gradient: Vec<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Bound {
    Lower,
    Upper,
    Free,
}

/// Solver state (libsvm `Solver`), all vectors in permuted order.
struct Smo {
    q: QMatrix,
    y: Vec<f64>,
    p: Vec<f64>,
    alpha: Vec<f64>,
    status: Vec<Bound>,
    g: Vec<f64>,
    g_bar: Vec<f64>,
    active_set: Vec<usize>,
    active_size: usize,
    c_pos: f64,
    c_neg: f64,
    tol: f64,
    unshrink: bool,
}

impl Smo {
    /// The solver at `problem`'s starting point: every variable active, statuses and
    /// gradients from α.
    fn new(problem: &Problem<'_>, options: &Options) -> Self {
        let l = problem.y.len();
        let mut s = Smo {
            q: QMatrix::new(
                problem.x,
                problem.dim,
                &problem.y,
                problem.kernel,
                options.cache_mb,
            ),
            y: problem.y.clone(),
            p: problem.p.clone(),
            alpha: problem.alpha.clone(),
            status: vec![Bound::Free; l],
            g: Vec::new(),
            g_bar: Vec::new(),
            active_set: (0..l).collect(),
            active_size: l,
            c_pos: problem.c_pos,
            c_neg: problem.c_neg,
            tol: options.tol,
            unshrink: false,
        };
        for i in 0..l {
            s.update_status(i);
        }
        s.init_gradient();
        s
    }

    /// The solution after `iterations`, in the caller's sample order.
    fn solution(&self, iterations: usize) -> Solution {
        let l = self.l();
        let rho = self.rho();
        let objective = (0..l)
            .map(|i| self.alpha[i] * (self.g[i] + self.p[i]))
            .sum::<f64>()
            / 2.0;
        let mut alpha = vec![0.0; l];
        let mut gradient = vec![0.0; l];
        for k in 0..l {
            alpha[self.active_set[k]] = self.alpha[k];
            gradient[self.active_set[k]] = self.g[k];
        }
        Solution {
            alpha,
            rho,
            objective,
            iterations,
            gradient,
        }
    }

    fn l(&self) -> usize {
        self.y.len()
    }

    fn c(&self, i: usize) -> f64 {
        if self.y[i] > 0.0 {
            self.c_pos
        } else {
            self.c_neg
        }
    }

    fn update_status(&mut self, i: usize) {
        let c = self.c(i);
        self.status[i] = if self.alpha[i] >= c {
            Bound::Upper
        } else if self.alpha[i] <= 0.0 {
            Bound::Lower
        } else {
            Bound::Free
        };
    }

    fn upper(&self, i: usize) -> bool {
        self.status[i] == Bound::Upper
    }

    fn lower(&self, i: usize) -> bool {
        self.status[i] == Bound::Lower
    }

    fn swap_index(&mut self, i: usize, j: usize) {
        self.q.swap_index(i, j);
        self.y.swap(i, j);
        self.g.swap(i, j);
        self.status.swap(i, j);
        self.alpha.swap(i, j);
        self.p.swap(i, j);
        self.active_set.swap(i, j);
        self.g_bar.swap(i, j);
    }

    /// Gradient from scratch: `G = p + Σ_{α_i>0} α_i Q_i`, and `Ḡ = Σ_{α_i=C_i} C_i Q_i`
    /// (the part of G kept for shrunk variables).
    fn init_gradient(&mut self) {
        let l = self.l();
        self.g.clone_from(&self.p);
        self.g_bar = vec![0.0; l];
        for i in 0..l {
            if self.lower(i) {
                continue;
            }
            self.q.ensure(i, l);
            let (ai, ci, up) = (self.alpha[i], self.c(i), self.upper(i));
            let qi = self.q.row(i);
            for (g, &q) in self.g.iter_mut().zip(qi) {
                *g += ai * q as f64;
            }
            if up {
                for (gb, &q) in self.g_bar.iter_mut().zip(qi) {
                    *gb += ci * q as f64;
                }
            }
        }
    }

    /// Rebuilds the gradient of the shrunk variables from Ḡ and the free ones
    /// (libsvm `reconstruct_gradient`), choosing the cheaper loop order.
    fn reconstruct_gradient(&mut self) {
        let (l, active) = (self.l(), self.active_size);
        if active == l {
            return;
        }
        for j in active..l {
            self.g[j] = self.g_bar[j] + self.p[j];
        }
        let nr_free = (0..active)
            .filter(|&j| self.status[j] == Bound::Free)
            .count();
        if nr_free * l > 2 * active * (l - active) {
            for i in active..l {
                self.q.ensure(i, active);
                let s: f64 = (self.q.row(i)[..active].iter())
                    .zip(&self.status[..active])
                    .zip(&self.alpha[..active])
                    .filter(|((_, st), _)| **st == Bound::Free)
                    .map(|((&q, _), &a)| a * q as f64)
                    .sum();
                self.g[i] += s;
            }
        } else {
            for i in 0..active {
                if self.status[i] != Bound::Free {
                    continue;
                }
                self.q.ensure(i, l);
                let ai = self.alpha[i];
                let qi = &self.q.row(i)[active..l];
                for (g, &q) in self.g[active..l].iter_mut().zip(qi) {
                    *g += ai * q as f64;
                }
            }
        }
    }

    /// WSS 2 (Fan, Chen & Lin 2005, Alg. 2): `i` maximises `−y_t G_t` over
    /// I_up; `j` minimises the second-order decrease `−b²/a` over I_low with
    /// `b = m(α) + y_t G_t > 0`. Returns the pair, or `None` with the gap when
    /// the gap `m(α) − M(α)` is below `tol`.
    fn select_working_set(&mut self) -> (Option<(usize, usize)>, f64) {
        let active = self.active_size;
        let mut gmax = f64::NEG_INFINITY;
        let mut gmax2 = f64::NEG_INFINITY;
        let mut gmax_idx = None;
        for t in 0..active {
            if self.y[t] > 0.0 {
                if !self.upper(t) && -self.g[t] >= gmax {
                    gmax = -self.g[t];
                    gmax_idx = Some(t);
                }
            } else if !self.lower(t) && self.g[t] >= gmax {
                gmax = self.g[t];
                gmax_idx = Some(t);
            }
        }
        let Some(i) = gmax_idx else {
            return (None, 0.0);
        };
        self.q.ensure(i, active);
        let qi = self.q.row(i);
        let (yi, qdi) = (self.y[i], self.q.diag[i]);
        let mut gmin_idx = None;
        let mut obj_diff_min = f64::INFINITY;
        for (j, &qij) in qi.iter().enumerate().take(active) {
            let qij = qij as f64;
            let (grad_diff, quad) = if self.y[j] > 0.0 {
                if self.lower(j) {
                    continue;
                }
                gmax2 = gmax2.max(self.g[j]);
                (gmax + self.g[j], qdi + self.q.diag[j] - 2.0 * yi * qij)
            } else {
                if self.upper(j) {
                    continue;
                }
                gmax2 = gmax2.max(-self.g[j]);
                (gmax - self.g[j], qdi + self.q.diag[j] + 2.0 * yi * qij)
            };
            if grad_diff > 0.0 {
                let obj_diff = -(grad_diff * grad_diff) / if quad > 0.0 { quad } else { TAU };
                if obj_diff <= obj_diff_min {
                    gmin_idx = Some(j);
                    obj_diff_min = obj_diff;
                }
            }
        }
        let gap = gmax + gmax2;
        match gmin_idx {
            Some(j) if gap >= self.tol => (Some((i, j)), gap),
            _ => (None, gap),
        }
    }

    /// A bound variable can leave the active set when its gradient says it will
    /// stay at its bound (libsvm `be_shrunk`).
    fn be_shrunk(&self, i: usize, gmax1: f64, gmax2: f64) -> bool {
        let pos = self.y[i] > 0.0;
        match self.status[i] {
            Bound::Upper => -self.g[i] > if pos { gmax1 } else { gmax2 },
            Bound::Lower => self.g[i] > if pos { gmax2 } else { gmax1 },
            Bound::Free => false,
        }
    }

    fn do_shrinking(&mut self) {
        let mut gmax1 = f64::NEG_INFINITY; // max over I_up of −y G
        let mut gmax2 = f64::NEG_INFINITY; // max over I_low of y G
        for i in 0..self.active_size {
            let g = self.g[i];
            if self.y[i] > 0.0 {
                if !self.upper(i) {
                    gmax1 = gmax1.max(-g);
                }
                if !self.lower(i) {
                    gmax2 = gmax2.max(g);
                }
            } else {
                if !self.upper(i) {
                    gmax2 = gmax2.max(-g);
                }
                if !self.lower(i) {
                    gmax1 = gmax1.max(g);
                }
            }
        }
        // Near the end, bring every variable back once so the shrunk ones are
        // checked against the final gradient.
        if !self.unshrink && gmax1 + gmax2 <= self.tol * 10.0 {
            self.unshrink = true;
            self.reconstruct_gradient();
            self.active_size = self.l();
        }
        let mut i = 0;
        while i < self.active_size {
            if self.be_shrunk(i, gmax1, gmax2) {
                self.active_size -= 1;
                while self.active_size > i {
                    if !self.be_shrunk(self.active_size, gmax1, gmax2) {
                        self.swap_index(i, self.active_size);
                        break;
                    }
                    self.active_size -= 1;
                }
            }
            i += 1;
        }
    }

    /// Analytic solution of the two-variable subproblem, clipped to the box (libsvm
    /// `Solver::Solve`'s update of α_i, α_j), then G and Ḡ brought up to date.
    fn update_pair(&mut self, i: usize, j: usize) {
        let active = self.active_size;
        self.q.ensure(i, active);
        self.q.ensure(j, active);
        let (ci, cj) = (self.c(i), self.c(j));
        let (old_i, old_j) = (self.alpha[i], self.alpha[j]);
        let qij = self.q.row(i)[j] as f64;
        let (qdi, qdj) = (self.q.diag[i], self.q.diag[j]);
        let (ai, aj) = if self.y[i] != self.y[j] {
            let quad = qdi + qdj + 2.0 * qij;
            let quad = if quad > 0.0 { quad } else { TAU };
            let delta = (-self.g[i] - self.g[j]) / quad;
            clip_opposite_labels(old_i, old_j, delta, ci, cj)
        } else {
            let quad = qdi + qdj - 2.0 * qij;
            let quad = if quad > 0.0 { quad } else { TAU };
            let delta = (self.g[i] - self.g[j]) / quad;
            clip_equal_labels(old_i, old_j, delta, ci, cj)
        };
        self.alpha[i] = ai;
        self.alpha[j] = aj;
        let (dai, daj) = (ai - old_i, aj - old_j);
        {
            let (qi, qj) = (self.q.row(i), self.q.row(j));
            for ((g, &a), &b) in self.g[..active].iter_mut().zip(qi).zip(qj) {
                *g += a as f64 * dai + b as f64 * daj;
            }
        }
        for (k, ck) in [(i, ci), (j, cj)] {
            self.update_status_and_g_bar(k, ck);
        }
    }

    /// Keeps Ḡ in step when variable `k` (bound `ck`) enters or leaves its upper bound.
    fn update_status_and_g_bar(&mut self, k: usize, ck: f64) {
        let was_upper = self.upper(k);
        self.update_status(k);
        if was_upper != self.upper(k) {
            let l = self.l();
            self.q.ensure(k, l);
            let sign = if was_upper { -ck } else { ck };
            let qk = self.q.row(k);
            for (gb, &v) in self.g_bar.iter_mut().zip(qk) {
                *gb += sign * v as f64;
            }
        }
    }

    /// ρ: the mean of `y_i G_i` over free variables, or the middle of the feasible
    /// interval when none is free (libsvm `calculate_rho`).
    fn rho(&self) -> f64 {
        let (mut ub, mut lb) = (f64::INFINITY, f64::NEG_INFINITY);
        let (mut n_free, mut sum_free) = (0usize, 0.0);
        for i in 0..self.active_size {
            let yg = self.y[i] * self.g[i];
            let pos = self.y[i] > 0.0;
            match self.status[i] {
                Bound::Upper if pos => lb = lb.max(yg),
                Bound::Upper => ub = ub.min(yg),
                Bound::Lower if pos => ub = ub.min(yg),
                Bound::Lower => lb = lb.max(yg),
                Bound::Free => {
                    n_free += 1;
                    sum_free += yg;
                }
            }
        }
        if n_free > 0 {
            sum_free / n_free as f64
        } else {
            (ub + lb) / 2.0
        }
    }
}

/// `y_i ≠ y_j`: α_i and α_j both move by `delta` (keeping `α_i − α_j`), then are
/// clipped back into `[0, C_i] × [0, C_j]` along that line (libsvm's clipping).
fn clip_opposite_labels(ai: f64, aj: f64, delta: f64, ci: f64, cj: f64) -> (f64, f64) {
    let (mut ai, mut aj) = (ai, aj);
    let diff = ai - aj;
    ai += delta;
    aj += delta;
    if diff > 0.0 {
        if aj < 0.0 {
            aj = 0.0;
            ai = diff;
        }
    } else if ai < 0.0 {
        ai = 0.0;
        aj = -diff;
    }
    if diff > ci - cj {
        if ai > ci {
            ai = ci;
            aj = ci - diff;
        }
    } else if aj > cj {
        aj = cj;
        ai = cj + diff;
    }
    (ai, aj)
}

/// `y_i = y_j`: α_i falls and α_j rises by `delta` (keeping `α_i + α_j`), then both
/// are clipped back into `[0, C_i] × [0, C_j]` along that line (libsvm's clipping).
fn clip_equal_labels(ai: f64, aj: f64, delta: f64, ci: f64, cj: f64) -> (f64, f64) {
    let (mut ai, mut aj) = (ai, aj);
    let sum = ai + aj;
    ai -= delta;
    aj += delta;
    if sum > ci {
        if ai > ci {
            ai = ci;
            aj = sum - ci;
        }
    } else if aj < 0.0 {
        aj = 0.0;
        ai = sum;
    }
    if sum > cj {
        if aj > cj {
            aj = cj;
            ai = sum - cj;
        }
    } else if ai < 0.0 {
        ai = 0.0;
        aj = sum;
    }
    (ai, aj)
}

/// Solves `problem`, reporting progress as stage `"smo"` and stopping with
/// [`LearnError::Cancelled`] when asked: libsvm's main loop (shrinking, cancellation,
/// the optimality re-check on the full set), then the solution unpermuted.
pub fn solve(
    problem: &Problem<'_>,
    options: &Options,
    progress: &dyn Progress,
) -> Result<Solution, LearnError> {
    let l = problem.y.len();
    let mut s = Smo::new(problem, options);
    let mut iter = 0usize;
    let mut counter = l.min(1000) + 1;
    let mut first_gap = None;
    let mut reported = 0.0f64;
    loop {
        counter -= 1;
        if counter == 0 {
            counter = l.min(1000);
            if options.shrinking {
                s.do_shrinking();
            }
            if progress.cancelled() {
                return Err(LearnError::Cancelled);
            }
        }
        let (pair, gap) = s.select_working_set();
        let (i, j) = match pair {
            Some(pair) => pair,
            None => {
                // Optimal on the active set: check every variable before stopping.
                s.reconstruct_gradient();
                s.active_size = l;
                match s.select_working_set().0 {
                    Some(pair) => {
                        counter = 1; // shrink again at the next iteration
                        pair
                    }
                    None => break,
                }
            }
        };
        if iter >= options.max_iter {
            return Err(LearnError::Numerical(format!(
                "SMO did not reach tol = {} within max_iter = {} iterations",
                options.tol, options.max_iter
            )));
        }
        iter += 1;
        let g0 = *first_gap.get_or_insert(gap.max(options.tol * 10.0));
        if iter % 1000 == 0 {
            // Progress from the gap's log-distance to tol (the gap falls roughly
            // geometrically); never moves backwards.
            let done =
                ((g0 / gap.max(options.tol)).ln() / (g0 / options.tol).ln()).clamp(0.0, 0.99);
            reported = reported.max(done);
            progress.report(reported, "smo");
        }
        s.update_pair(i, j);
    }
    Ok(s.solution(iter))
}
