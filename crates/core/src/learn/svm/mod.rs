//! C-SVC and one-class SVM (SVDD / ν-OCSVM) trained by SMO (seeds 002 and 003,
//! docs/methods.md §M17). The rimu monitor isolates a faulty gyro with a [`SvcModel`];
//! the tacan monitor flags range anomalies with an [`OcSvmModel`]; the service
//! trains both through `learn::model::train`, which refuses a `cv` block with
//! [`refuse_cv`].
//!
//! Layout (linfa's split): this file is the API and the shared parameter rules;
//! [`svc`] and [`ocsvm`] set up each dual problem and hold the models; [`smo`] is
//! the solver (libsvm's, WSS 2 + shrinking); `rows` the kernel matrix it reads;
//! [`cache`] the LRU kernel-row cache.
//!
//! Kernel width, both conventions: the RBF kernel is `exp(−‖x − y‖² / sigma2)`
//! (LS-SVMlab, docs/methods.md §M8); scikit-learn / libsvm write `exp(−gamma‖x − y‖²)`, so
//! `gamma = 1 / sigma2`, given as `kernel_gamma` (`gamma` is accepted as its alias:
//! for these kinds it always means this width, never a regularisation). Give either
//! `sigma2` or `kernel_gamma`, not both. Given neither,
//! `sigma2 = dim · Var(X)` over every entry of the (standardised, by default)
//! training inputs — exactly scikit-learn's `gamma = "scale"` on the same matrix,
//! and ≈ `dim` with standardisation on.

pub mod cache;
pub mod ocsvm;
mod rows;
pub mod smo;
pub mod svc;

pub use ocsvm::{OcSvmModel, OcSvmParams, ValidOcSvmParams};
pub use svc::{SvcModel, SvcParams, ValidSvcParams};

use super::cv::CvParams;
use super::{Dataset, LearnError, Standardizer};

/// Default stopping tolerance on the maximal violating pair (libsvm's `-e`).
pub const DEFAULT_TOL: f64 = 1e-3;
/// Default kernel cache, MiB (scikit-learn's `cache_size`).
pub const DEFAULT_CACHE_MB: f64 = 200.0;

/// There is no hyper-parameter search for the SVM kinds: a `cv` block is refused
/// (field `cv`).
pub fn refuse_cv(cv: Option<&CvParams>) -> Result<(), LearnError> {
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
            "kernel_gamma",
            "give either sigma2 or kernel_gamma (alias gamma, = 1/sigma2), not both",
        ));
    }
    if let Some(s) = sigma2 {
        positive("sigma2", s)?;
    }
    if let Some(g) = gamma {
        positive("kernel_gamma", g)?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::model::{ModelKind, ModelParams, Prediction, train};
    use crate::learn::{AnyModel, NoProgress};
    use serde_json::json;

    fn field_of(e: LearnError) -> String {
        assert!(matches!(e, LearnError::InvalidParams { .. }), "{e:?}");
        e.field().unwrap_or_default().to_owned()
    }

    #[test]
    fn rest_params_are_checked_and_errors_name_the_field() {
        let e = ModelParams::from_json(ModelKind::Svm, &json!({"sigma2": 1, "gamma": 1}));
        assert_eq!(field_of(e.unwrap_err()), "gamma");
        let e = ModelParams::from_json(ModelKind::Svm, &json!({"sigma2": 1, "kernel_gamma": 1}));
        assert_eq!(field_of(e.unwrap_err()), "kernel_gamma");
        // `kernel_gamma` is the wire name, `gamma` its alias: same params either way.
        let new = ModelParams::from_json(ModelKind::OcSvm, &json!({"kernel_gamma": 0.5}));
        let old = ModelParams::from_json(ModelKind::OcSvm, &json!({"gamma": 0.5}));
        assert_eq!(new.unwrap(), old.unwrap());
        let shown = ModelParams::from_json(ModelKind::Svm, &json!({"gamma": 0.5})).unwrap();
        assert_eq!(shown.to_json()["kernel_gamma"], 0.5);
        assert!(shown.to_json().get("gamma").is_none());
        let e = ModelParams::from_json(ModelKind::Svm, &json!({"C": -2}));
        assert_eq!(field_of(e.unwrap_err()), "C");
        let e = ModelParams::from_json(ModelKind::OcSvm, &json!({"nu": 1.5}));
        assert_eq!(field_of(e.unwrap_err()), "nu");
        let e = ModelParams::from_json(ModelKind::OcSvm, &json!({"nu": 0.1, "C": 0.5}));
        assert_eq!(field_of(e.unwrap_err()), "C");
        let e = ModelParams::from_json(ModelKind::OcSvm, &json!({"kernel": "linear"}));
        assert_eq!(field_of(e.unwrap_err()), "kernel");
        let ok = ModelParams::from_json(ModelKind::Svm, &serde_json::Value::Null).unwrap();
        assert_eq!(ok, ModelParams::Svm(SvcParams::default()));
    }

    #[test]
    fn a_cv_block_is_refused_for_the_svm_kinds() {
        let data = Dataset::new(&[vec![0.0], vec![1.0]], Some(&[-1.0, 1.0])).unwrap();
        let cv = CvParams::default();
        for params in [
            ModelParams::Svm(SvcParams::default()),
            ModelParams::OcSvm(OcSvmParams::default()),
        ] {
            let e = train(&params, Some(&cv), &data, &NoProgress).unwrap_err();
            assert_eq!(field_of(e), "cv");
        }
    }

    #[test]
    fn the_training_entry_point_fills_metrics_and_predicts_labels() {
        let rows: Vec<Vec<f64>> = (0..60)
            .map(|i| vec![(i as f64 * 0.7).sin(), (i as f64 * 0.3).cos()])
            .collect();
        let y: Vec<f64> = rows
            .iter()
            .map(|r| if r[0] > 0.0 { 1.0 } else { -1.0 })
            .collect();
        let data = Dataset::new(&rows, Some(&y)).unwrap();
        let svm = ModelParams::from_json(ModelKind::Svm, &json!({"C": 10})).unwrap();
        let t = train(&svm, None, &data, &NoProgress).unwrap();
        assert!(t.metrics.train_accuracy.unwrap() > 0.95);
        assert!(t.metrics.support_vectors.unwrap() > 0);
        assert!(t.metrics.iterations.unwrap() > 0);
        assert!(t.metrics.objective.unwrap() < 0.0);
        // The effective parameters show the default width that was used.
        assert!(matches!(t.params, ModelParams::Svm(ref p) if p.sigma2.is_some()));
        let q = Dataset::new(&[vec![0.9, 0.0], vec![-0.9, 0.0]], None).unwrap();
        match t.model.predict(&q).unwrap() {
            Prediction::Classification { label, .. } => assert_eq!(label, vec![1, -1]),
            other => panic!("expected labels, got {other:?}"),
        }
        let oc = ModelParams::from_json(ModelKind::OcSvm, &json!({"nu": 0.2})).unwrap();
        let t = train(&oc, None, &data, &NoProgress).unwrap();
        assert!(t.metrics.outlier_fraction.unwrap() <= 0.25);
        assert!(matches!(t.model, AnyModel::OcSvm(_)));
        assert_eq!(t.model.input_dim(), 2);
    }
}
