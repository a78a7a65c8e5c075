//! C-SVC and one-class SVM (SVDD / ν-OCSVM) trained by SMO (seeds 002 and 003,
//! DESIGN §3.7–3.8). The rimu monitor isolates a faulty gyro with a [`SvcModel`];
//! the tacan monitor flags range anomalies with an [`OcSvmModel`]; the service
//! trains both through [`train_svc`] and [`train_ocsvm`].
//!
//! Layout (linfa's split): this file is the API and the shared parameter rules;
//! [`svc`] and [`ocsvm`] set up each dual problem and hold the models; [`smo`] is
//! the solver (libsvm's, WSS 2 + shrinking); [`cache`] its LRU kernel-row cache.
//!
//! Kernel width, both conventions: the RBF kernel is `exp(−‖x − y‖² / sigma2)`
//! (LS-SVMlab, DESIGN §3.5); scikit-learn / libsvm write `exp(−gamma‖x − y‖²)`, so
//! `gamma = 1 / sigma2`. Give either `sigma2` or `gamma`, not both. Given neither,
//! `sigma2 = dim · Var(X)` over every entry of the (standardised, by default)
//! training inputs — exactly scikit-learn's `gamma = "scale"` on the same matrix,
//! and ≈ `dim` with standardisation on.

pub mod cache;
pub mod ocsvm;
pub mod smo;
pub mod svc;

pub use ocsvm::{OcSvmModel, OcSvmParams};
pub use svc::{SvcKernel, SvcModel, SvcParams};

use super::cv::CvParams;
use super::model::Trained;
use super::{Dataset, LearnError, Progress, Standardizer};

/// Default stopping tolerance on the maximal violating pair (libsvm's `-e`).
pub const DEFAULT_TOL: f64 = 1e-3;
/// Default kernel cache, MiB (scikit-learn's `cache_size`).
pub const DEFAULT_CACHE_MB: f64 = 200.0;

/// Training job entry point for `svm`. There is no hyper-parameter search for
/// the SVM kinds: a `cv` block is refused (field `cv`).
pub fn train_svc(
    params: &SvcParams,
    cv: Option<&CvParams>,
    data: &Dataset,
    progress: &dyn Progress,
) -> Result<Trained, LearnError> {
    refuse_cv(cv)?;
    svc::train(params, data, progress)
}

/// Training job entry point for `ocsvm` (no `cv`, as for `svm`).
pub fn train_ocsvm(
    params: &OcSvmParams,
    cv: Option<&CvParams>,
    data: &Dataset,
    progress: &dyn Progress,
) -> Result<Trained, LearnError> {
    refuse_cv(cv)?;
    ocsvm::train(params, data, progress)
}

fn refuse_cv(cv: Option<&CvParams>) -> Result<(), LearnError> {
    match cv {
        Some(_) => Err(LearnError::params(
            "cv",
            "cross-validation is not available for svm/ocsvm; give C (or nu) and sigma2 or gamma",
        )),
        None => Ok(()),
    }
}

fn positive(field: &str, v: f64) -> Result<(), LearnError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(LearnError::params(
            field,
            "must be a finite number greater than 0",
        ))
    }
}

/// Checks the width pair and the solver settings shared by both kinds.
fn check_common(
    sigma2: Option<f64>,
    gamma: Option<f64>,
    tol: f64,
    cache_mb: f64,
    max_iter: Option<usize>,
) -> Result<(), LearnError> {
    if sigma2.is_some() && gamma.is_some() {
        return Err(LearnError::params(
            "gamma",
            "give either sigma2 or gamma (= 1/sigma2), not both",
        ));
    }
    if let Some(s) = sigma2 {
        positive("sigma2", s)?;
    }
    if let Some(g) = gamma {
        positive("gamma", g)?;
    }
    positive("tol", tol)?;
    positive("cache_mb", cache_mb)?;
    if max_iter == Some(0) {
        return Err(LearnError::params("max_iter", "must be at least 1"));
    }
    Ok(())
}

/// The RBF width: `sigma2`, `1/gamma`, or scikit-learn's `"scale"` default
/// `dim · Var(x)` over all entries of `x` (1 when that variance is 0).
fn resolve_sigma2(sigma2: Option<f64>, gamma: Option<f64>, x: &[f64], dim: usize) -> f64 {
    if let Some(s) = sigma2 {
        return s;
    }
    if let Some(g) = gamma {
        return 1.0 / g;
    }
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
    if var > 0.0 && var.is_finite() {
        dim as f64 * var
    } else {
        1.0
    }
}

/// libsvm's iteration limit when the user gives none: `max(10⁷, 100·l)`.
fn iteration_limit(max_iter: Option<usize>, n: usize) -> usize {
    max_iter.unwrap_or_else(|| 10_000_000usize.max(n.saturating_mul(100)))
}

/// The training inputs, standardised when asked, row-major, with the transform.
fn prepare_inputs(data: &Dataset, standardize: bool) -> (Vec<f64>, Standardizer) {
    let rows: Vec<Vec<f64>> = (0..data.n()).map(|i| data.row(i)).collect();
    let scaler = if standardize {
        Standardizer::fit(rows.iter().map(|r| r.as_slice()))
    } else {
        Standardizer::identity(data.dim())
    };
    let mut flat = Vec::with_capacity(data.n() * data.dim());
    for r in &rows {
        flat.extend(scaler.applied(r));
    }
    (flat, scaler)
}

/// `Σ_k coef_k K(sv_k, z)` over row-major support vectors: the models' hot path.
fn kernel_sum(kernel: super::Kernel, sv: &[f64], coef: &[f64], z: &[f64]) -> f64 {
    sv.chunks_exact(z.len())
        .zip(coef)
        .map(|(s, &c)| c * kernel.eval(s, z))
        .sum()
}

fn default_true() -> bool {
    true
}

fn default_tol() -> f64 {
    DEFAULT_TOL
}

fn default_cache_mb() -> f64 {
    DEFAULT_CACHE_MB
}
