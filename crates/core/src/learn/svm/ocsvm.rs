//! One-class SVM for the tacan monitor (seed 003, docs/methods.md §M17), two equivalent
//! parameterisations of one RBF model:
//! - ν-OCSVM (Schölkopf et al. 2001, libsvm's form): `min ½ αᵀKα`,
//!   `0 ≤ α_i ≤ 1`, `Σα_i = νl`; decision `d(x) = Σ α_i K(x_i, x) − ρ`, ≥ 0
//!   normal — the sign and value of scikit-learn's `OneClassSVM.decision_function`.
//! - SVDD (Tax & Duin; seed 003 eqs. 8–15) with parameter `C`: `min ΣΣ β_iβ_j K_ij −
//!   Σ β_i K_ii`, `0 ≤ β_i ≤ C`, `Σβ_i = 1`. With RBF, `K_ii = 1` and the substitution
//!   `β = α/(νl)` turn it into the ν problem with `ν = 1/(N·C)`, so it is solved as
//!   that. Its decision is reported as `R² − f(z)` with `f(z) = ‖φ(z) − a‖²` the
//!   squared distance to the centre: `R² − f(z) = 2C·d(z)`, so `f(z) ≤ R²` ⇔
//!   decision ≥ 0 (normal), the same sign as the ν form.

use serde::{Deserialize, Serialize};

use super::smo::{self, Options, Problem};
use super::{
    check_common, default_cache_mb, default_tol, default_true, iteration_limit, kernel_sum,
    positive, prepare_inputs, resolve_sigma2,
};
use crate::learn::{
    Dataset, Fitted, Kernel, LearnError, NoProgress, Progress, Standardizer, TrainingMetrics,
};

/// Default ν when neither `nu` nor `C` is given.
pub const DEFAULT_NU: f64 = 0.1;

/// `params` of an `ocsvm` model (RBF kernel). Every field has a default.
///
/// `{"nu": 0.1, "gamma": 0.5, "standardize": false}` is scikit-learn's
/// `OneClassSVM(nu=0.1, gamma=0.5)`; `{"C": c}` is SVDD with `ν = 1/(N·c)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OcSvmParams {
    /// ν in (0, 1]: an upper bound on the training outlier fraction and a lower
    /// bound on the support-vector fraction. Excludes `C`. Default 0.1 when
    /// neither is given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nu: Option<f64>,
    /// SVDD's C (seed 003 eq. 9), ≥ 1/N; equivalent to `ν = 1/(N·C)`. Excludes `nu`.
    #[serde(rename = "C", default, skip_serializing_if = "Option::is_none")]
    pub c: Option<f64>,
    /// RBF width σ² (> 0) in `exp(−‖x − y‖²/σ²)`; excludes `gamma`. Default: see
    /// the module docs of `learn::svm` (scikit-learn's `"scale"`).
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
    /// SMO stopping tolerance (default 1e-3, libsvm's).
    #[serde(default = "default_tol")]
    pub tol: f64,
    /// Kernel-row cache, MiB (default 200, scikit-learn's `cache_size`).
    #[serde(default = "default_cache_mb")]
    pub cache_mb: f64,
    /// Shrink the active set during SMO (default true).
    #[serde(default = "default_true")]
    pub shrinking: bool,
    /// SMO iteration limit (default `max(10⁷, 100·n)`); reaching it is an error.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_iter: Option<usize>,
}

impl Default for OcSvmParams {
    fn default() -> Self {
        OcSvmParams {
            nu: None,
            c: None,
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

impl OcSvmParams {
    /// Validates the parameters; the error names the field.
    pub fn check(&self) -> Result<ValidOcSvmParams, LearnError> {
        match (self.nu, self.c) {
            (Some(_), Some(_)) => {
                return Err(LearnError::params(
                    "C",
                    "give either nu (ν-OCSVM) or C (SVDD), not both",
                ));
            }
            (Some(nu), None) if !(nu > 0.0 && nu <= 1.0) => {
                return Err(LearnError::params("nu", "must be in (0, 1]"));
            }
            (None, Some(c)) => positive("C", c)?,
            _ => {}
        }
        check_common(
            self.sigma2,
            self.gamma,
            self.tol,
            self.cache_mb,
            self.max_iter,
        )?;
        Ok(ValidOcSvmParams(self.clone()))
    }

    /// `self.check()?.fit(data)`.
    pub fn fit(&self, data: &Dataset) -> Result<OcSvmModel, LearnError> {
        self.check()?.fit(data)
    }
}

/// [`OcSvmParams`] that passed [`OcSvmParams::check`]: the only way to fit.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidOcSvmParams(OcSvmParams);

impl ValidOcSvmParams {
    /// The checked parameters.
    pub fn params(&self) -> &OcSvmParams {
        &self.0
    }

    /// Trains on the rows of `data` (`y` is ignored).
    pub fn fit(&self, data: &Dataset) -> Result<OcSvmModel, LearnError> {
        Ok(self.fit_with(data, &NoProgress)?.model)
    }

    /// [`ValidOcSvmParams::fit`] with progress, also returning the effective
    /// parameters (defaults filled in) and the training metrics.
    pub fn fit_with(
        &self,
        data: &Dataset,
        progress: &dyn Progress,
    ) -> Result<Fitted<OcSvmModel, OcSvmParams>, LearnError> {
        let params = &self.0;
        let n = data.n();
        let dim = data.dim();
        let mut effective = params.clone();
        let (nu, scale) = nu_and_scale(params, &mut effective, n)?;
        let (x, standardizer) = prepare_inputs(data, params.standardize);
        let sigma2 = resolve_sigma2(params.sigma2, params.gamma, &x, dim);
        if params.sigma2.is_none() && params.gamma.is_none() {
            effective.sigma2 = Some(sigma2);
        }
        let kernel = Kernel::Rbf { sigma2 };

        let alpha = feasible_start(nu, n);
        let problem = Problem {
            x: &x,
            dim,
            kernel,
            y: vec![1.0; n],
            p: vec![0.0; n],
            alpha,
            c_pos: 1.0,
            c_neg: 1.0,
        };
        let options = Options {
            tol: params.tol,
            cache_mb: params.cache_mb,
            shrinking: params.shrinking,
            max_iter: iteration_limit(params.max_iter, n),
        };
        let sol = smo::solve(&problem, &options, progress)?;

        // Training decisions from the final gradient: G_i = Σ_j α_j K_ij.
        let outliers = sol.gradient.iter().filter(|&&g| g - sol.rho < 0.0).count();
        let (sv, coef) = support_vectors(&x, dim, &sol.alpha);
        let metrics = TrainingMetrics {
            outlier_fraction: Some(outliers as f64 / n as f64),
            support_vectors: Some(coef.len()),
            iterations: Some(sol.iterations),
            objective: Some(sol.objective),
            ..TrainingMetrics::default()
        };
        let model = OcSvmModel {
            dim,
            sigma2,
            standardizer,
            support_vectors: sv,
            alpha: coef,
            rho: sol.rho,
            scale,
        };
        Ok(Fitted {
            model,
            params: effective,
            metrics,
        })
    }
}

/// ν and the decision scale: SVDD ⇔ ν-OCSVM with ν = 1/(N·C) (module docs);
/// scale turns d(z) into R² − f(z). A defaulted ν is recorded in `effective`.
fn nu_and_scale(
    params: &OcSvmParams,
    effective: &mut OcSvmParams,
    n: usize,
) -> Result<(f64, f64), LearnError> {
    Ok(match (params.nu, params.c) {
        (_, Some(c)) => {
            let nu = 1.0 / (n as f64 * c);
            if nu > 1.0 {
                return Err(LearnError::params(
                    "C",
                    format!(
                        "must be at least 1/N = {} (Σβ = 1 with β ≤ C)",
                        1.0 / n as f64
                    ),
                ));
            }
            (nu, 2.0 * c)
        }
        (Some(nu), None) => (nu, 1.0),
        (None, None) => {
            effective.nu = Some(DEFAULT_NU);
            (DEFAULT_NU, 1.0)
        }
    })
}

/// libsvm's feasible start: the first ⌊νl⌋ at 1, the next at the remainder.
fn feasible_start(nu: f64, n: usize) -> Vec<f64> {
    let total = nu * n as f64;
    let full = (total as usize).min(n);
    let mut alpha = vec![0.0; n];
    alpha[..full].fill(1.0);
    if full < n {
        alpha[full] = total - full as f64;
    }
    alpha
}

/// The support vectors (rows of `x` with α > 0, flattened) and their α.
fn support_vectors(x: &[f64], dim: usize, alpha: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut sv = Vec::new();
    let mut coef = Vec::new();
    for (i, &a) in alpha.iter().enumerate() {
        if a > 0.0 {
            sv.extend_from_slice(&x[i * dim..(i + 1) * dim]);
            coef.push(a);
        }
    }
    (sv, coef)
}

/// A trained one-class SVM: `decision(x) = scale · (Σ_k α_k K(sv_k, z) − ρ)` with
/// `z` the standardised input; `scale` is 1 (ν form, scikit-learn's value) or 2C
/// (SVDD, so the decision is `R² − f(z)`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OcSvmModel {
    dim: usize,
    sigma2: f64,
    standardizer: Standardizer,
    /// Support vectors, row-major, in standardised units.
    support_vectors: Vec<f64>,
    alpha: Vec<f64>,
    rho: f64,
    scale: f64,
}

impl OcSvmModel {
    /// Input dimension.
    pub fn input_dim(&self) -> usize {
        self.dim
    }

    /// Number of support vectors.
    pub fn n_support(&self) -> usize {
        self.alpha.len()
    }

    /// The RBF width σ² (standardised units when standardising).
    pub fn sigma2(&self) -> f64 {
        self.sigma2
    }

    /// libsvm's ρ (scikit-learn's `offset_`), before `scale`.
    pub fn rho(&self) -> f64 {
        self.rho
    }

    /// The factor the decision carries: 1 (ν form) or 2C (SVDD).
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// The input standardisation fitted on the training set (identity when the
    /// model was trained with `"standardize": false`).
    pub fn standardizer(&self) -> &Standardizer {
        &self.standardizer
    }

    /// Decision value; ≥ 0 means inside the boundary (normal). NaN for an input
    /// of the wrong dimension.
    pub fn decision_one(&self, x: &[f64]) -> f64 {
        if x.len() != self.dim {
            return f64::NAN;
        }
        let z = self.standardizer.applied(x);
        let k = Kernel::Rbf {
            sigma2: self.sigma2,
        };
        self.scale * (kernel_sum(k, &self.support_vectors, &self.alpha, &z) - self.rho)
    }

    /// +1 (normal) when [`OcSvmModel::decision_one`] ≥ 0, else −1 (anomaly).
    pub fn predict_one(&self, x: &[f64]) -> i32 {
        if self.decision_one(x) >= 0.0 { 1 } else { -1 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::AnyModel;
    use approx::assert_relative_eq;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, StandardNormal};

    /// The small fixed set of the scikit-learn golden values (also in svc.rs).
    fn golden_set() -> Vec<Vec<f64>> {
        (0..24)
            .map(|i| {
                let t = i as f64;
                vec![2.0 * (1.3 * t).sin(), 1.5 * (0.7 * t).cos() + 0.1 * t]
            })
            .collect()
    }

    fn random_set(n: usize, seed: u64) -> Dataset {
        let mut rng = StdRng::seed_from_u64(seed);
        let rows: Vec<Vec<f64>> = (0..n)
            .map(|_| {
                (0..2)
                    .map(|_| StandardNormal.sample(&mut rng))
                    .collect::<Vec<f64>>()
            })
            .collect();
        Dataset::new(&rows, None).unwrap()
    }

    fn params(nu: f64, sigma2: f64) -> OcSvmParams {
        OcSvmParams {
            nu: Some(nu),
            sigma2: Some(sigma2),
            standardize: false,
            tol: 1e-5,
            ..OcSvmParams::default()
        }
    }

    #[test]
    fn decisions_match_scikit_learn_golden_values() {
        // Produced with scikit-learn 1.9.1:
        //   i = np.arange(24); X = np.c_[2*np.sin(1.3*i), 1.5*np.cos(0.7*i) + 0.1*i]
        //   OneClassSVM(nu=0.2, gamma=0.5, tol=1e-6).fit(X).decision_function(Q)
        // offset_ = 0.8364916499688216, 13 support vectors.
        let queries = [[0.0, 0.0], [1.0, 1.0], [-2.0, 3.0], [3.0, -1.0], [0.5, 2.5]];
        let expected = [
            0.02077155716973411,
            0.03509018224956617,
            0.017301255804076487,
            -0.5620066716572889,
            -0.009579218641912468,
        ];
        let data = Dataset::new(&golden_set(), None).unwrap();
        let p = OcSvmParams {
            gamma: Some(0.5),
            sigma2: None,
            tol: 1e-6,
            ..params(0.2, 0.0)
        };
        let m = p.fit(&data).unwrap();
        assert_eq!(m.n_support(), 13);
        assert_relative_eq!(m.rho(), 0.8364916499688216, epsilon = 1e-5);
        for (q, e) in queries.iter().zip(expected) {
            assert_relative_eq!(m.decision_one(q), e, epsilon = 1e-5);
        }
    }

    #[test]
    fn nu_bounds_the_outlier_fraction_from_above_and_the_sv_fraction_from_below() {
        let data = random_set(400, 11);
        for nu in [0.05, 0.2, 0.5] {
            let fitted = params(nu, 1.0)
                .check()
                .unwrap()
                .fit_with(&data, &NoProgress)
                .unwrap();
            let (m, metrics) = (fitted.model, fitted.metrics);
            let decisions: Vec<f64> = (0..400).map(|i| m.decision_one(&data.row(i))).collect();
            // Free SVs sit on the boundary only up to the SMO tolerance (1e-5 here),
            // so "outside" is counted beyond that slack.
            let outside = decisions.iter().filter(|&&d| d < -1e-4).count() as f64 / 400.0;
            let sv = m.n_support() as f64 / 400.0;
            assert!(outside <= nu, "nu {nu}: outliers {outside}");
            assert!(sv >= nu, "nu {nu}: sv {sv}");
            // The metric (strictly negative decisions, from the solver's gradient)
            // agrees with the stored model's decisions.
            let flagged = decisions.iter().filter(|&&d| d < 0.0).count() as f64 / 400.0;
            assert!((flagged - metrics.outlier_fraction.unwrap()).abs() <= 2.0 / 400.0);
        }
    }

    #[test]
    fn svdd_with_c_gives_the_nu_decisions_for_nu_one_over_n_c() {
        let data = random_set(200, 5);
        let c = 1.0 / (200.0 * 0.15);
        let svdd = OcSvmParams {
            nu: None,
            c: Some(c),
            ..params(0.15, 2.0)
        }
        .fit(&data)
        .unwrap();
        let nu = params(0.15, 2.0).fit(&data).unwrap();
        for i in 0..200 {
            let x = data.row(i);
            let (a, b) = (svdd.decision_one(&x), nu.decision_one(&x));
            // SVDD reports R² − f(z) = 2C·d(z).
            assert_relative_eq!(a, 2.0 * c * b, epsilon = 1e-12);
        }
    }

    #[test]
    fn svdd_decision_is_radius_minus_distance_to_the_centre() {
        // Seed 003 eqs. 12–15 evaluated directly: β = C·α, centre a = Σβφ(x),
        // f(z) = K(z,z) − 2Σβ_i K(x_i,z) + ΣΣ β_iβ_j K_ij, R² = f(x_k) for a free SV.
        let data = random_set(60, 9);
        let c = 1.0 / (60.0 * 0.3);
        let m = OcSvmParams {
            nu: None,
            c: Some(c),
            ..params(0.3, 1.0)
        }
        .fit(&data)
        .unwrap();
        let k = Kernel::Rbf { sigma2: 1.0 };
        let sv: Vec<&[f64]> = m.support_vectors.chunks_exact(2).collect();
        let beta: Vec<f64> = m.alpha.iter().map(|a| c * a).collect();
        let cc: f64 = (0..sv.len())
            .flat_map(|i| (0..sv.len()).map(move |j| (i, j)))
            .map(|(i, j)| beta[i] * beta[j] * k.eval(sv[i], sv[j]))
            .sum();
        let f = |z: &[f64]| {
            1.0 - 2.0
                * sv.iter()
                    .zip(&beta)
                    .map(|(s, b)| b * k.eval(s, z))
                    .sum::<f64>()
                + cc
        };
        let free = (0..sv.len())
            .find(|&i| beta[i] > 1e-9 && beta[i] < c - 1e-9)
            .unwrap();
        let r2 = f(sv[free]);
        for z in [[0.0, 0.0], [1.0, -0.5], [2.5, 2.5]] {
            assert_relative_eq!(m.decision_one(&z), r2 - f(&z), epsilon = 1e-4);
        }
    }

    #[test]
    fn tiny_cache_and_no_shrinking_reach_the_same_solution() {
        let data = random_set(300, 3);
        let reference = params(0.1, 0.5).fit(&data).unwrap();
        let tiny = OcSvmParams {
            cache_mb: 1e-6,
            ..params(0.1, 0.5)
        }
        .fit(&data)
        .unwrap();
        let unshrunk = OcSvmParams {
            shrinking: false,
            ..params(0.1, 0.5)
        }
        .fit(&data)
        .unwrap();
        for other in [&tiny, &unshrunk] {
            assert_relative_eq!(other.rho(), reference.rho(), epsilon = 1e-4);
            for i in 0..300 {
                let x = data.row(i);
                assert_relative_eq!(
                    other.decision_one(&x),
                    reference.decision_one(&x),
                    epsilon = 1e-4
                );
            }
        }
        // The cache does not change the iterates at all.
        assert_eq!(tiny, reference);
    }

    #[test]
    fn bad_parameters_name_their_field() {
        let field = |p: OcSvmParams| match p.check() {
            Err(LearnError::InvalidParams { field, .. }) => field,
            other => panic!("expected InvalidParams, got {other:?}"),
        };
        let base = OcSvmParams::default();
        assert!(base.check().is_ok());
        let both_widths = OcSvmParams {
            sigma2: Some(1.0),
            gamma: Some(1.0),
            ..base.clone()
        };
        assert_eq!(field(both_widths), "kernel_gamma");
        for nu in [0.0, -0.1, 1.5, f64::NAN] {
            assert_eq!(
                field(OcSvmParams {
                    nu: Some(nu),
                    ..base.clone()
                }),
                "nu"
            );
        }
        let both = OcSvmParams {
            nu: Some(0.1),
            c: Some(1.0),
            ..base.clone()
        };
        assert_eq!(field(both), "C");
        assert_eq!(
            field(OcSvmParams {
                c: Some(0.0),
                ..base.clone()
            }),
            "C"
        );
        assert_eq!(
            field(OcSvmParams {
                tol: 0.0,
                ..base.clone()
            }),
            "tol"
        );
        // C below 1/N cannot hold Σβ = 1: refused at fit time.
        let data = random_set(10, 1);
        let e = OcSvmParams {
            c: Some(0.05),
            ..base
        }
        .fit(&data)
        .unwrap_err();
        assert!(matches!(e, LearnError::InvalidParams { ref field, .. } if field == "C"));
    }

    #[test]
    fn defaults_are_filled_in_and_unknown_fields_refused() {
        let p: OcSvmParams = serde_json::from_value(serde_json::json!({})).unwrap();
        assert_eq!(p, OcSvmParams::default());
        assert!(
            serde_json::from_value::<OcSvmParams>(serde_json::json!({"kernel": "rbf"})).is_err()
        );
        let data = random_set(50, 2);
        let effective = p
            .check()
            .unwrap()
            .fit_with(&data, &NoProgress)
            .unwrap()
            .params;
        assert_eq!(effective.nu, Some(DEFAULT_NU));
        // scikit-learn's gamma = "scale" on standardised data: dim · Var(z).
        let s = effective.sigma2.unwrap();
        assert_relative_eq!(s, 2.0 * 49.0 / 50.0, epsilon = 1e-12);
    }

    #[test]
    fn a_stored_model_round_trips_through_json() {
        let data = random_set(40, 4);
        let m = OcSvmParams::default().fit(&data).unwrap();
        let any = AnyModel::OcSvm(m.clone());
        let back = AnyModel::from_stored_json(&any.to_stored_json()).unwrap();
        // serde_json (without `float_roundtrip`) may move a float by one ulp.
        assert_eq!(back.input_dim(), 2);
        for x in [[0.3, -0.2], [2.0, 1.0], [-1.5, 0.0]] {
            assert_relative_eq!(back.predict_one(&x), m.decision_one(&x), epsilon = 1e-12);
        }
    }

    #[test]
    fn a_cancelled_job_stops_with_cancelled() {
        struct Stop;
        impl Progress for Stop {
            fn report(&self, _: f64, _: &str) {}
            fn cancelled(&self) -> bool {
                true
            }
        }
        let data = random_set(300, 6);
        let e = params(0.1, 1.0)
            .check()
            .unwrap()
            .fit_with(&data, &Stop)
            .unwrap_err();
        assert_eq!(e, LearnError::Cancelled);
    }
}
