//! C-SVC (Cortes & Vapnik 1995; seed 002's gyro-fault classifier): the dual
//! `min ½ αᵀQα − eᵀα, yᵀα = 0, 0 ≤ α ≤ C` with `Q_ij = y_i y_j K(x_i, x_j)`,
//! solved by [`super::smo`]; decision `f(x) = Σ y_i α_i K(x_i, x) + b`, `b = −ρ`.
//! Labels are +1 / −1; `f(x) ≥ 0` is the positive class (+1 = fault in seed 002).

use serde::{Deserialize, Serialize};

use super::smo::{self, Options, Problem};
use super::{
    check_common, default_cache_mb, default_tol, default_true, iteration_limit, kernel_sum,
    positive, prepare_inputs, resolve_sigma2,
};
use crate::learn::{
    Dataset, Fitted, Kernel, KernelKind, LearnError, NoProgress, Progress, Standardizer,
    TrainingMetrics,
};

/// `params` of an `svm` model (C-SVC). Every field has a default.
///
/// `{"C": 1, "kernel": "rbf", "sigma2": 8}` is the same model as scikit-learn's
/// `SVC(C=1, kernel="rbf", gamma=1/8)` on standardised inputs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SvcParams {
    /// Box constraint C (> 0, default 1): the price of a margin violation, as in
    /// libsvm and scikit-learn.
    #[serde(rename = "C", default = "one")]
    pub c: f64,
    /// `"rbf"` (default) or `"linear"`.
    #[serde(default)]
    pub kernel: KernelKind,
    /// RBF width σ² (> 0) in `exp(−‖x − y‖²/σ²)`; excludes `gamma`. Default: see
    /// the module docs (scikit-learn's `"scale"`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma2: Option<f64>,
    /// scikit-learn / libsvm RBF width `gamma = 1/σ²` (> 0); excludes `sigma2`. Wire
    /// name `kernel_gamma`; `gamma` is accepted as an alias (never both).
    #[serde(
        rename = "kernel_gamma",
        alias = "gamma",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub gamma: Option<f64>,
    /// Standardise inputs with the training mean and std (default true, docs/methods.md
    /// §M8); `false` trains on raw values as libsvm and scikit-learn do.
    #[serde(default = "default_true")]
    pub standardize: bool,
    /// SMO stopping tolerance on the maximal violating pair (default 1e-3, libsvm's).
    #[serde(default = "default_tol")]
    pub tol: f64,
    /// Kernel-row cache, MiB (default 200, scikit-learn's `cache_size`).
    #[serde(default = "default_cache_mb")]
    pub cache_mb: f64,
    /// Shrink the active set during SMO (default true).
    #[serde(default = "default_true")]
    pub shrinking: bool,
    /// SMO iteration limit (default libsvm's `max(10⁷, 100·n)`); reaching it fails
    /// the training with a numerical error.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_iter: Option<usize>,
}

fn one() -> f64 {
    1.0
}

impl Default for SvcParams {
    fn default() -> Self {
        SvcParams {
            c: 1.0,
            kernel: KernelKind::Rbf,
            sigma2: None,
            gamma: None,
            standardize: true,
            tol: super::DEFAULT_TOL,
            cache_mb: super::DEFAULT_CACHE_MB,
            shrinking: true,
            max_iter: None,
        }
    }
}

impl SvcParams {
    /// Validates the parameters; the error names the field.
    pub fn check(&self) -> Result<ValidSvcParams, LearnError> {
        positive("C", self.c)?;
        if self.kernel == KernelKind::Linear {
            for (field, v) in [("sigma2", self.sigma2), ("kernel_gamma", self.gamma)] {
                if v.is_some() {
                    return Err(LearnError::params(field, "only the rbf kernel has a width"));
                }
            }
        }
        check_common(
            self.sigma2,
            self.gamma,
            self.tol,
            self.cache_mb,
            self.max_iter,
        )?;
        Ok(ValidSvcParams(self.clone()))
    }

    /// `self.check()?.fit(data)`.
    pub fn fit(&self, data: &Dataset) -> Result<SvcModel, LearnError> {
        self.check()?.fit(data)
    }
}

/// [`SvcParams`] that passed [`SvcParams::check`]: the only way to fit.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidSvcParams(SvcParams);

impl ValidSvcParams {
    /// The checked parameters.
    pub fn params(&self) -> &SvcParams {
        &self.0
    }

    /// Trains on `data` (labels `y` must be +1 / −1 with both present).
    pub fn fit(&self, data: &Dataset) -> Result<SvcModel, LearnError> {
        Ok(self.fit_with(data, &NoProgress)?.model)
    }

    /// [`ValidSvcParams::fit`] with progress, also returning the effective parameters
    /// (default width filled in) and the training metrics.
    pub fn fit_with(
        &self,
        data: &Dataset,
        progress: &dyn Progress,
    ) -> Result<Fitted<SvcModel, SvcParams>, LearnError> {
        let params = &self.0;
        let y = signed_labels(data)?;
        let dim = data.dim();
        let (x, standardizer) = prepare_inputs(data, params.standardize);
        let mut effective = params.clone();
        let kernel = resolve_kernel(params, &mut effective, &x, dim);
        let n = y.len();
        let problem = Problem {
            x: &x,
            dim,
            kernel,
            p: vec![-1.0; n],
            alpha: vec![0.0; n],
            y,
            c_pos: params.c,
            c_neg: params.c,
        };
        let options = Options {
            tol: params.tol,
            cache_mb: params.cache_mb,
            shrinking: params.shrinking,
            max_iter: iteration_limit(params.max_iter, n),
        };
        let sol = smo::solve(&problem, &options, progress)?;

        let correct = count_correct(&problem.y, &sol);
        let (sv, coef) = support_vectors(&x, dim, &problem.y, &sol.alpha);
        let w = (kernel == Kernel::Linear).then(|| linear_weights(&sv, &coef, dim));
        let metrics = TrainingMetrics {
            train_accuracy: Some(correct as f64 / n as f64),
            support_vectors: Some(coef.len()),
            iterations: Some(sol.iterations),
            objective: Some(sol.objective),
            ..TrainingMetrics::default()
        };
        let model = SvcModel {
            dim,
            kernel,
            standardizer,
            support_vectors: sv,
            coef,
            b: -sol.rho,
            w,
        };
        Ok(Fitted {
            model,
            params: effective,
            metrics,
        })
    }
}

/// The training labels, each checked to be +1 or −1, with both classes present.
fn signed_labels(data: &Dataset) -> Result<Vec<f64>, LearnError> {
    let labels = data.require_y()?;
    let mut y = Vec::with_capacity(data.n());
    for (i, &v) in labels.iter().enumerate() {
        if v != 1.0 && v != -1.0 {
            return Err(LearnError::data(
                format!("y[{i}]"),
                format!("C-SVC labels must be +1 or -1, got {v}"),
            ));
        }
        y.push(v);
    }
    if y.iter().all(|&v| v == y[0]) {
        return Err(LearnError::data(
            "y",
            "C-SVC needs both classes (+1 and -1) in the training set",
        ));
    }
    Ok(y)
}

/// The kernel to train with; a defaulted RBF width is recorded in `effective`.
fn resolve_kernel(params: &SvcParams, effective: &mut SvcParams, x: &[f64], dim: usize) -> Kernel {
    match params.kernel {
        KernelKind::Linear => Kernel::Linear,
        KernelKind::Rbf => {
            let sigma2 = resolve_sigma2(params.sigma2, params.gamma, x, dim);
            if params.sigma2.is_none() && params.gamma.is_none() {
                effective.sigma2 = Some(sigma2);
            }
            Kernel::Rbf { sigma2 }
        }
    }
}

/// How many training points the solution classifies correctly, read from the
/// final gradient: G_i = y_i Σ_j y_j α_j K_ij − 1.
fn count_correct(y: &[f64], sol: &smo::Solution) -> usize {
    (0..y.len())
        .filter(|&i| {
            let yi = y[i];
            let f = yi * (sol.gradient[i] + 1.0) - sol.rho;
            (f >= 0.0) == (yi > 0.0)
        })
        .count()
}

/// The support vectors (rows of `x` with α > 0, flattened) and their
/// coefficients `y_i α_i`.
fn support_vectors(x: &[f64], dim: usize, y: &[f64], alpha: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut sv = Vec::new();
    let mut coef = Vec::new();
    for (i, (&yi, &a)) in y.iter().zip(alpha).enumerate() {
        if a > 0.0 {
            sv.extend_from_slice(&x[i * dim..(i + 1) * dim]);
            coef.push(yi * a);
        }
    }
    (sv, coef)
}

/// Linear kernel: w = Σ y_i α_i x_i, so a decision is one dot product.
fn linear_weights(sv: &[f64], coef: &[f64], dim: usize) -> Vec<f64> {
    let mut w = vec![0.0; dim];
    for (s, c) in sv.chunks_exact(dim).zip(coef) {
        for (wk, sk) in w.iter_mut().zip(s) {
            *wk += c * sk;
        }
    }
    w
}

/// A trained C-SVC: `f(x) = Σ_k coef_k K(sv_k, z) + b` with `z` the standardised
/// input and `coef_k = y_k α_k`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SvcModel {
    dim: usize,
    kernel: Kernel,
    standardizer: Standardizer,
    /// Support vectors, row-major, in standardised units.
    support_vectors: Vec<f64>,
    coef: Vec<f64>,
    b: f64,
    /// Primal weights (linear kernel only), standardised units.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    w: Option<Vec<f64>>,
}

impl SvcModel {
    /// Input dimension.
    pub fn input_dim(&self) -> usize {
        self.dim
    }

    /// Number of support vectors.
    pub fn n_support(&self) -> usize {
        self.coef.len()
    }

    /// The kernel (its width in standardised units when standardising).
    pub fn kernel(&self) -> Kernel {
        self.kernel
    }

    /// Offset `b` (= −ρ of libsvm, scikit-learn's `intercept_`).
    pub fn intercept(&self) -> f64 {
        self.b
    }

    /// Primal weights `w` in standardised units (linear kernel only).
    pub fn weights(&self) -> Option<&[f64]> {
        self.w.as_deref()
    }

    /// Decision value; ≥ 0 means the positive class (+1). NaN for an input of the
    /// wrong dimension.
    pub fn decision_one(&self, x: &[f64]) -> f64 {
        if x.len() != self.dim {
            return f64::NAN;
        }
        let z = self.standardizer.applied(x);
        match &self.w {
            Some(w) => w.iter().zip(&z).map(|(a, b)| a * b).sum::<f64>() + self.b,
            None => kernel_sum(self.kernel, &self.support_vectors, &self.coef, &z) + self.b,
        }
    }

    /// Label +1 when [`SvcModel::decision_one`] ≥ 0, else −1.
    pub fn predict_one(&self, x: &[f64]) -> i32 {
        if self.decision_one(x) >= 0.0 { 1 } else { -1 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::AnyModel;
    use approx::assert_relative_eq;

    fn set(rows: &[[f64; 2]], y: &[f64]) -> Dataset {
        let rows: Vec<Vec<f64>> = rows.iter().map(|r| r.to_vec()).collect();
        Dataset::new(&rows, Some(y)).unwrap()
    }

    fn hard_margin() -> SvcParams {
        SvcParams {
            c: 1e6,
            kernel: KernelKind::Linear,
            standardize: false,
            tol: 1e-8,
            ..SvcParams::default()
        }
    }

    #[test]
    fn linear_svc_reaches_the_max_margin_hyperplane_on_separable_sets() {
        // Two points: the bisector, w = (x₊ − x₋)/‖x₊ − x₋‖²·2 = (½, ½), b = 0.
        let m = hard_margin()
            .fit(&set(&[[1.0, 1.0], [-1.0, -1.0]], &[1.0, -1.0]))
            .unwrap();
        let w = m.weights().unwrap();
        assert_relative_eq!(w[0], 0.5, epsilon = 1e-6);
        assert_relative_eq!(w[1], 0.5, epsilon = 1e-6);
        assert_relative_eq!(m.intercept(), 0.0, epsilon = 1e-6);
        // Hulls {(2,0),(3,−1),(2,2)} and {(0,0),(−1,1),(0,−2)} are 2 apart along x:
        // the max-margin plane is x = 1, i.e. w = (1, 0), b = −1 (margin 1/‖w‖ = 1).
        let rows = [
            [2.0, 0.0],
            [3.0, -1.0],
            [2.0, 2.0],
            [0.0, 0.0],
            [-1.0, 1.0],
            [0.0, -2.0],
        ];
        let y = [1.0, 1.0, 1.0, -1.0, -1.0, -1.0];
        let data = set(&rows, &y);
        let fitted = hard_margin()
            .check()
            .unwrap()
            .fit_with(&data, &NoProgress)
            .unwrap();
        let (m, metrics) = (fitted.model, fitted.metrics);
        let w = m.weights().unwrap();
        assert_relative_eq!(w[0], 1.0, epsilon = 1e-6);
        assert_relative_eq!(w[1], 0.0, epsilon = 1e-6);
        assert_relative_eq!(m.intercept(), -1.0, epsilon = 1e-6);
        assert_eq!(metrics.train_accuracy, Some(1.0));
        // Dual objective −½‖w‖² at the optimum.
        assert_relative_eq!(metrics.objective.unwrap(), -0.5, epsilon = 1e-6);
        assert_relative_eq!(m.decision_one(&[2.0, 5.0]), 1.0, epsilon = 1e-6);
    }

    #[test]
    fn rbf_decisions_match_scikit_learn_golden_values() {
        // Produced with scikit-learn 1.9.1:
        //   i = np.arange(24); X = np.c_[2*np.sin(1.3*i), 1.5*np.cos(0.7*i) + 0.1*i]
        //   y = where(X[:,0] + 0.5*X[:,1] − 0.8 > 0, 1, −1), then y[[3, 7]] *= −1
        //   SVC(C=2, gamma=0.25, tol=1e-6).fit(X, y).decision_function(Q)
        // intercept_ = −0.31937257829511234, 13 support vectors.
        let rows: Vec<Vec<f64>> = (0..24)
            .map(|i| {
                let t = i as f64;
                vec![2.0 * (1.3 * t).sin(), 1.5 * (0.7 * t).cos() + 0.1 * t]
            })
            .collect();
        let mut y: Vec<f64> = rows
            .iter()
            .map(|r| {
                if r[0] + 0.5 * r[1] - 0.8 > 0.0 {
                    1.0
                } else {
                    -1.0
                }
            })
            .collect();
        y[3] = -y[3];
        y[7] = -y[7];
        let data = Dataset::new(&rows, Some(&y)).unwrap();
        let m = SvcParams {
            c: 2.0,
            gamma: Some(0.25),
            standardize: false,
            tol: 1e-6,
            ..SvcParams::default()
        }
        .fit(&data)
        .unwrap();
        assert_eq!(m.n_support(), 13);
        assert_relative_eq!(m.intercept(), -0.31937257829511234, epsilon = 1e-5);
        let queries = [[0.0, 0.0], [1.0, 1.0], [-2.0, 3.0], [3.0, -1.0], [0.5, 2.5]];
        let expected = [
            -1.293524777716588,
            0.5823456125544613,
            -1.133511762703408,
            0.3188431096354063,
            0.5082759552415048,
        ];
        for (q, e) in queries.iter().zip(expected) {
            assert_relative_eq!(m.decision_one(q), e, epsilon = 1e-5);
        }
    }

    #[test]
    fn shrinking_and_cache_size_do_not_change_the_solution() {
        let rows: Vec<Vec<f64>> = (0..150)
            .map(|i| {
                let t = i as f64;
                vec![(0.37 * t).sin() * 3.0, (0.11 * t).cos() * 2.0 + (0.05 * t)]
            })
            .collect();
        let y: Vec<f64> = rows
            .iter()
            .map(|r| if r[0] * r[1] > 0.3 { 1.0 } else { -1.0 })
            .collect();
        let data = Dataset::new(&rows, Some(&y)).unwrap();
        let base = SvcParams {
            c: 10.0,
            tol: 1e-6,
            ..SvcParams::default()
        };
        let reference = base.fit(&data).unwrap();
        let tiny = SvcParams {
            cache_mb: 1e-6,
            ..base.clone()
        }
        .fit(&data)
        .unwrap();
        assert_eq!(tiny, reference);
        let unshrunk = SvcParams {
            shrinking: false,
            ..base
        }
        .fit(&data)
        .unwrap();
        for r in &rows {
            assert_relative_eq!(
                unshrunk.decision_one(r),
                reference.decision_one(r),
                epsilon = 1e-4
            );
        }
    }

    #[test]
    fn labels_other_than_plus_minus_one_and_single_class_sets_are_refused() {
        let p = SvcParams::default();
        let e = p
            .fit(&set(&[[0.0, 0.0], [1.0, 1.0]], &[1.0, 2.0]))
            .unwrap_err();
        assert!(matches!(e, LearnError::InvalidData { ref field, .. } if field == "y[1]"));
        let e = p
            .fit(&set(&[[0.0, 0.0], [1.0, 1.0]], &[-1.0, -1.0]))
            .unwrap_err();
        assert!(matches!(e, LearnError::InvalidData { ref field, .. } if field == "y"));
        let rows = vec![vec![0.0]];
        let e = p.fit(&Dataset::new(&rows, None).unwrap()).unwrap_err();
        assert!(matches!(e, LearnError::InvalidData { ref field, .. } if field == "y"));
    }

    #[test]
    fn bad_parameters_name_their_field() {
        let field = |p: SvcParams| match p.check() {
            Err(LearnError::InvalidParams { field, .. }) => field,
            other => panic!("expected InvalidParams, got {other:?}"),
        };
        let base = SvcParams::default();
        assert!(base.check().is_ok());
        for c in [0.0, -1.0, f64::INFINITY] {
            assert_eq!(field(SvcParams { c, ..base.clone() }), "C");
        }
        let both = SvcParams {
            sigma2: Some(2.0),
            gamma: Some(0.5),
            ..base.clone()
        };
        assert_eq!(field(both), "kernel_gamma");
        assert_eq!(
            field(SvcParams {
                sigma2: Some(-1.0),
                ..base.clone()
            }),
            "sigma2"
        );
        let linear_width = SvcParams {
            kernel: KernelKind::Linear,
            gamma: Some(1.0),
            ..base.clone()
        };
        assert_eq!(field(linear_width), "kernel_gamma");
        assert_eq!(
            field(SvcParams {
                cache_mb: 0.0,
                ..base.clone()
            }),
            "cache_mb"
        );
        assert_eq!(
            field(SvcParams {
                max_iter: Some(0),
                ..base
            }),
            "max_iter"
        );
        let json = serde_json::json!({"C": 3, "kernel": "linear", "shrinking": false});
        let p: SvcParams = serde_json::from_value(json).unwrap();
        assert_eq!(
            (p.c, p.kernel, p.shrinking),
            (3.0, KernelKind::Linear, false)
        );
        assert!(
            serde_json::from_value::<SvcParams>(serde_json::json!({"kernel": "poly"})).is_err()
        );
    }

    #[test]
    fn the_iteration_limit_is_a_numerical_error() {
        let rows: Vec<Vec<f64>> = (0..40)
            .map(|i| vec![(i as f64).sin(), (i as f64).cos()])
            .collect();
        let y: Vec<f64> = (0..40)
            .map(|i| if i % 3 == 0 { 1.0 } else { -1.0 })
            .collect();
        let data = Dataset::new(&rows, Some(&y)).unwrap();
        let e = SvcParams {
            max_iter: Some(2),
            ..SvcParams::default()
        }
        .fit(&data)
        .unwrap_err();
        assert!(matches!(e, LearnError::Numerical(_)));
    }

    #[test]
    fn a_stored_model_round_trips_and_keeps_its_labels() {
        let data = set(
            &[[0.0, 0.0], [1.0, 0.2], [3.0, 3.0], [4.0, 3.5]],
            &[-1.0, -1.0, 1.0, 1.0],
        );
        let fitted = SvcParams::default()
            .check()
            .unwrap()
            .fit_with(&data, &NoProgress)
            .unwrap();
        let (m, effective, metrics) = (fitted.model, fitted.params, fitted.metrics);
        assert!(effective.sigma2.is_some());
        assert_eq!(metrics.train_accuracy, Some(1.0));
        assert_eq!(m.predict_one(&[3.5, 3.2]), 1);
        assert_eq!(m.predict_one(&[0.2, 0.1]), -1);
        let any = AnyModel::Svm(m.clone());
        let back = AnyModel::from_stored_json(&any.to_stored_json()).unwrap();
        for x in [[3.5, 3.2], [0.2, 0.1], [2.0, 1.0]] {
            assert_relative_eq!(back.predict_one(&x), m.decision_one(&x), epsilon = 1e-12);
        }
    }
}

#[cfg(test)]
mod progress_tests {
    use super::*;
    use std::sync::Mutex;

    struct Record(Mutex<Vec<(f64, String)>>);

    impl Progress for Record {
        fn report(&self, fraction: f64, stage: &str) {
            self.0.lock().unwrap().push((fraction, stage.to_owned()));
        }
    }

    #[test]
    fn progress_is_reported_as_a_growing_fraction_of_stage_smo() {
        // Interleaved labels with a large C need thousands of SMO iterations.
        let rows: Vec<Vec<f64>> = (0..200)
            .map(|i| vec![(i as f64 * 0.917).sin(), (i as f64 * 0.31).cos()])
            .collect();
        let y: Vec<f64> = (0..200)
            .map(|i| if (i * 7919) % 13 < 6 { 1.0 } else { -1.0 })
            .collect();
        let data = Dataset::new(&rows, Some(&y)).unwrap();
        let record = Record(Mutex::new(Vec::new()));
        let p = SvcParams {
            c: 1e4,
            sigma2: Some(0.05),
            tol: 1e-6,
            ..SvcParams::default()
        };
        let metrics = p.check().unwrap().fit_with(&data, &record).unwrap().metrics;
        let reports = record.0.into_inner().unwrap();
        assert!(metrics.iterations.unwrap() >= 1000, "{metrics:?}");
        assert!(!reports.is_empty());
        assert!(
            reports
                .iter()
                .all(|(f, s)| (0.0..=1.0).contains(f) && s == "smo")
        );
        assert!(reports.windows(2).all(|w| w[1].0 >= w[0].0));
    }
}
