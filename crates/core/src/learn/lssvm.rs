//! Batch LS-SVM regression (seed 000 eq. 6, docs/methods.md §M9): Cholesky of `Ω + I/γ` and
//! the two-solve trick. The channel monitor predicts with [`LsSvmModel`]; the service
//! trains it through [`train`] (cross-validation first when asked).
//!
//! Names: `reg` is the regularisation γ (`gamma` is accepted as its old spelling,
//! and is what LS-SVMlab calls it); `sigma2` is the RBF width.
//!
//! Defaults: `reg` and `sigma2` are `"auto"` (tuned by k-fold CV with the default
//! [`CvParams`], as LS-SVMlab's `tunelssvm`), `kernel` is `"rbf"`, `standardize` is
//! true, so `sigma2` is in standardised squared units.

use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::cv::{self, CvParams, CvReport, Hyper, Search};
pub use super::kernel::KernelKind;
use super::lssvm_exact::{self as exact, ExactScale};
use super::lssvm_solve as solve;
use super::variance::ModelTerm;
use super::{
    Dataset, Fitted, Kernel, LearnError, NoProgress, Progress, Standardizer, TrainingMetrics,
};

/// `params` of an `lssvm` model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LsSvmParams {
    /// Regularisation γ (> 0) or `"auto"` (the default: chosen by CV). Wire name
    /// `reg`; `gamma` is accepted as an alias (never both).
    #[serde(rename = "reg", alias = "gamma", default)]
    pub gamma: Hyper,
    /// RBF width σ² (> 0) or `"auto"` (the default: chosen by CV). Unused by the
    /// linear kernel.
    #[serde(default)]
    pub sigma2: Hyper,
    /// `"rbf"` (default) or `"linear"`.
    #[serde(default)]
    pub kernel: KernelKind,
    /// Standardise inputs and targets with the training mean and std (default true).
    #[serde(default = "yes")]
    pub standardize: bool,
}

fn yes() -> bool {
    true
}

impl Default for LsSvmParams {
    fn default() -> Self {
        LsSvmParams {
            gamma: Hyper::Auto,
            sigma2: Hyper::Auto,
            kernel: KernelKind::Rbf,
            standardize: true,
        }
    }
}

impl LsSvmParams {
    /// Fixed parameters: RBF kernel, given γ and σ², standardised.
    pub fn new(gamma: f64, sigma2: f64) -> Self {
        LsSvmParams {
            gamma: Hyper::Value(gamma),
            sigma2: Hyper::Value(sigma2),
            ..Self::default()
        }
    }

    /// Validates the parameters; the error names the field (`reg`, `sigma2`).
    pub fn check(&self) -> Result<ValidLsSvmParams, LearnError> {
        self.gamma.check("reg")?;
        if self.kernel == KernelKind::Rbf {
            self.sigma2.check("sigma2")?;
        }
        Ok(ValidLsSvmParams(self.clone()))
    }

    /// `self.check()?.fit(data)`.
    pub fn fit(&self, data: &Dataset) -> Result<LsSvmModel, LearnError> {
        self.check()?.fit(data)
    }
}

/// [`LsSvmParams`] that passed [`LsSvmParams::check`]: the only way to fit.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidLsSvmParams(LsSvmParams);

impl ValidLsSvmParams {
    /// The checked parameters.
    pub fn params(&self) -> &LsSvmParams {
        &self.0
    }

    /// True when fitting runs cross-validation first: a hyper-parameter is `"auto"`
    /// or a `cv` block is given.
    pub fn tunes(&self, cv_given: bool) -> bool {
        let p = &self.0;
        Search::plan(p.gamma, p.sigma2, p.kernel == KernelKind::Rbf, cv_given).is_some()
    }

    /// Fits on `data` (targets required). `"auto"` hyper-parameters are tuned first by
    /// CV with the default [`CvParams`].
    pub fn fit(&self, data: &Dataset) -> Result<LsSvmModel, LearnError> {
        Ok(self.fit_with(None, data, &NoProgress)?.model)
    }

    /// The training job: cross-validation first when a hyper-parameter is `"auto"` or
    /// `cv` is given (see [`cv`] for which axes), then the final fit.
    pub fn fit_with(
        &self,
        cv: Option<&CvParams>,
        data: &Dataset,
        progress: &dyn Progress,
    ) -> Result<Fitted<LsSvmModel, LsSvmParams>, LearnError> {
        train(&self.0, cv, data, progress)
    }
}

/// The training set in the units the model trains in (standardised or raw).
pub(crate) struct Prepared {
    /// Input statistics (identity when not standardising).
    pub x_scale: Standardizer,
    /// Target statistics (1-D; identity when not standardising).
    pub y_scale: Standardizer,
    /// Samples packed row-major, `dim` values each.
    pub rows: Vec<f64>,
    /// Targets.
    pub y: Vec<f64>,
    /// Input dimension.
    pub dim: usize,
}

impl Prepared {
    /// Standardises (or not) `data`, which must have targets.
    pub(crate) fn new(data: &Dataset, standardize: bool) -> Result<Self, LearnError> {
        let y = data.require_y()?;
        let dim = data.dim();
        let mut rows = solve::pack_rows(data.x());
        let (x_scale, y_scale) = if standardize {
            (
                Standardizer::fit(rows.chunks_exact(dim)),
                Standardizer::fit(y.as_slice().chunks_exact(1)),
            )
        } else {
            (Standardizer::identity(dim), Standardizer::identity(1))
        };
        rows.chunks_exact_mut(dim).for_each(|r| x_scale.apply(r));
        let y = y
            .iter()
            .map(|v| (v - y_scale.mean[0]) / y_scale.std[0])
            .collect();
        Ok(Prepared {
            x_scale,
            y_scale,
            rows,
            y,
            dim,
        })
    }

    /// Number of samples.
    pub(crate) fn n(&self) -> usize {
        self.y.len()
    }

    /// The packed rows and targets of the samples `idx`.
    pub(crate) fn subset(&self, idx: &[usize]) -> (Vec<f64>, Vec<f64>) {
        let d = self.dim;
        let mut rows = Vec::with_capacity(idx.len() * d);
        for &i in idx {
            rows.extend_from_slice(&self.rows[i * d..(i + 1) * d]);
        }
        (rows, idx.iter().map(|&i| self.y[i]).collect())
    }
}

/// A trained batch LS-SVM: `f(x) = Σ αᵢ K(xᵢ, x) + b` in training units (standardised
/// by default), mapped back to original units. Stored with exact floats
/// ([`super::lssvm_exact`]) so a reloaded model predicts bit for bit the same.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LsSvmModel {
    /// Input dimension.
    dim: usize,
    /// Kernel family.
    kernel: KernelKind,
    /// RBF width σ² in training units (unused by the linear kernel).
    #[serde(with = "exact::one")]
    sigma2: f64,
    /// γ it was trained with.
    #[serde(with = "exact::one")]
    gamma: f64,
    /// Training samples (every sample is a support vector in an LS-SVM), row-major,
    /// in training units.
    #[serde(with = "exact::vec")]
    support: Vec<f64>,
    /// Support values α.
    #[serde(with = "exact::vec")]
    alpha: Vec<f64>,
    /// Bias b (training units).
    #[serde(with = "exact::one")]
    b: f64,
    /// Input standardisation (identity when `standardize` was false).
    x_scale: ExactScale,
    /// Target standardisation.
    y_scale: ExactScale,
}

/// Inputs up to this dimension are standardised on the stack in `predict_one`.
const STACK_DIM: usize = 32;

impl LsSvmModel {
    /// Input dimension.
    pub fn input_dim(&self) -> usize {
        self.dim
    }

    /// The kernel (width in training units).
    pub fn kernel(&self) -> Kernel {
        kernel_of(self.kernel, self.sigma2)
    }

    /// γ it was trained with.
    pub fn gamma(&self) -> f64 {
        self.gamma
    }

    /// Support values α (training units).
    pub fn alpha(&self) -> &[f64] {
        &self.alpha
    }

    /// Bias b (training units).
    pub fn bias(&self) -> f64 {
        self.b
    }

    /// The factor that answers this model's predictive-variance term (docs/methods.md
    /// §M9a): one O(N³) factorisation of `Ω + I/γ`, kept beside the model by its user.
    pub fn model_term(&self) -> Result<ModelTerm, LearnError> {
        ModelTerm::new(self.support.clone(), self.dim, self.kernel(), self.gamma)
    }

    /// The model term `m(x)` of the prediction at `x` (original units), with `term` from
    /// [`LsSvmModel::model_term`]: its variance is `σ_e² (1 + γ m(x))`.
    pub fn variance_term(&self, term: &ModelTerm, x: &[f64]) -> f64 {
        let z: Vec<f64> = (0..self.dim)
            .map(|j| {
                self.x_scale
                    .apply_one(j, x.get(j).copied().unwrap_or(f64::NAN))
            })
            .collect();
        term.at(&z)
    }

    /// `f(x)` in original units. `x` must have [`LsSvmModel::input_dim`] values (extra
    /// values are ignored, missing ones make the result meaningless). Allocates only
    /// when the dimension exceeds 32.
    pub fn predict_one(&self, x: &[f64]) -> f64 {
        let d = self.dim;
        let mut stack = [0.0; STACK_DIM];
        let mut heap = Vec::new();
        let z: &mut [f64] = if d <= STACK_DIM {
            &mut stack[..d]
        } else {
            heap.resize(d, 0.0);
            &mut heap
        };
        for (j, v) in z.iter_mut().enumerate() {
            *v = self
                .x_scale
                .apply_one(j, x.get(j).copied().unwrap_or(f64::NAN));
        }
        let f = solve::evaluate(&self.support, d, &self.alpha, self.b, &self.kernel(), z);
        self.y_scale.invert(0, f)
    }
}

/// Fits with fixed γ (and σ² for RBF) on prepared data.
fn fit_prepared(
    p: &Prepared,
    kind: KernelKind,
    sigma2: f64,
    gamma: f64,
) -> Result<LsSvmModel, LearnError> {
    let sol = solve::fit(&p.rows, p.dim, &p.y, &kernel_of(kind, sigma2), gamma)?;
    Ok(LsSvmModel {
        dim: p.dim,
        kernel: kind,
        sigma2,
        gamma,
        support: p.rows.clone(),
        alpha: sol.alpha,
        b: sol.b,
        x_scale: (&p.x_scale).into(),
        y_scale: (&p.y_scale).into(),
    })
}

pub(crate) fn kernel_of(kind: KernelKind, sigma2: f64) -> Kernel {
    kind.with_width(sigma2)
}

/// k-fold CV of the batch LS-SVM on prepared data: one kernel matrix per fold and σ²,
/// one Cholesky per γ.
fn tune(
    p: &Prepared,
    kind: KernelKind,
    search: Search,
    cv: &CvParams,
    progress: &dyn Progress,
) -> Result<cv::Tuned, LearnError> {
    let scale = p.y_scale.std[0].powi(2);
    cv::grid_search(
        cv,
        search,
        p.n(),
        scale,
        progress,
        (0.0, 0.9),
        |fold, sigma2, gammas| {
            let kernel = kernel_of(kind, sigma2);
            let (rows, y) = p.subset(&fold.train);
            let (val_rows, val_y) = p.subset(&fold.val);
            let omega = solve::regularised_kernel(&rows, p.dim, &kernel, f64::INFINITY);
            let mut out = Vec::with_capacity(gammas.len());
            for &g in gammas {
                let mut h = omega.clone();
                for i in 0..h.nrows() {
                    h[(i, i)] += 1.0 / g;
                }
                let sse = match solve::cholesky(&mut h) {
                    Ok(()) => {
                        let sol = solve::two_solve(&h, &y);
                        val_rows
                            .chunks_exact(p.dim)
                            .zip(&val_y)
                            .map(|(x, t)| {
                                let e =
                                    solve::evaluate(&rows, p.dim, &sol.alpha, sol.b, &kernel, x)
                                        - t;
                                e * e
                            })
                            .sum()
                    }
                    Err(_) => f64::INFINITY,
                };
                out.push(sse);
            }
            Ok(out)
        },
    )
}

/// Root-mean-square error of `predict` over `data`'s samples, original units.
pub(crate) fn train_rmse(data: &Dataset, predict: impl Fn(&[f64]) -> f64) -> Option<f64> {
    let y = data.y()?;
    let mut row = vec![0.0; data.dim()];
    let mut sse = 0.0;
    for i in 0..data.n() {
        row.iter_mut()
            .zip(data.x().row(i).iter())
            .for_each(|(r, v)| *r = *v);
        sse += (predict(&row) - y[i]).powi(2);
    }
    Some((sse / data.n() as f64).sqrt())
}

/// [`ValidLsSvmParams::fit_with`] on checked `params`.
fn train(
    params: &LsSvmParams,
    cv: Option<&CvParams>,
    data: &Dataset,
    progress: &dyn Progress,
) -> Result<Fitted<LsSvmModel, LsSvmParams>, LearnError> {
    let started = Instant::now();
    let p = Prepared::new(data, params.standardize)?;
    let has_width = params.kernel == KernelKind::Rbf;
    let mut report: Option<CvReport> = None;
    let (gamma, sigma2) = match Search::plan(params.gamma, params.sigma2, has_width, cv.is_some()) {
        Some(search) => {
            let tuned = tune(
                &p,
                params.kernel,
                search,
                cv.unwrap_or(&CvParams::default()),
                progress,
            )?;
            report = Some(tuned.report);
            // The linear kernel has no width; 1.0 is stored and never used.
            (tuned.gamma, tuned.sigma2.unwrap_or(1.0))
        }
        None => (
            params.gamma.value().unwrap_or(f64::NAN),
            params.sigma2.value().unwrap_or(1.0),
        ),
    };
    if progress.cancelled() {
        return Err(LearnError::Cancelled);
    }
    progress.report(0.9, "fit");
    let model = fit_prepared(&p, params.kernel, sigma2, gamma)?;
    let effective = LsSvmParams {
        gamma: Hyper::Value(gamma),
        sigma2: if has_width {
            Hyper::Value(sigma2)
        } else {
            params.sigma2
        },
        ..params.clone()
    };
    let metrics = TrainingMetrics {
        n: data.n(),
        dim: data.dim(),
        seconds: started.elapsed().as_secs_f64(),
        train_rmse: train_rmse(data, |x| model.predict_one(x)),
        cv: report,
        ..TrainingMetrics::default()
    };
    Ok(Fitted {
        model,
        params: effective,
        metrics,
    })
}

#[cfg(test)]
#[path = "lssvm_tests.rs"]
mod tests;
