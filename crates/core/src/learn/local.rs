//! Locally weighted LS-SVM (seed 000 §1.2, made precise in docs/methods.md §M10), the channel
//! monitor's alternative to the global batch model: each query is answered by an
//! LS-SVM trained on its `k` nearest training samples, with a kernel width scaled to
//! how spread those neighbours are.
//!
//! For a query `x`: `L_j = ‖x_j − x‖²` over the `k` nearest samples,
//! `β = sin((L_min / L_max)·π/2)`, `d = max(β·mean(L), d_floor·mean(L))`, and the local
//! model uses the RBF width `σ²·d`. `d_floor` (default 1e-12) keeps the width positive
//! when the nearest neighbour coincides with the query (`β = 0`); when every neighbour
//! coincides with it (`mean(L) = 0`) `d = 1` (the kernel is then 1 whatever the width).
//! The model stores the (standardised) training set; `k` is capped at its size.

use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::cv::{self, CvParams, CvReport, Hyper, Search};
use super::lssvm::{Prepared, train_rmse};
use super::lssvm_exact::{self as exact, ExactScale};
use super::lssvm_solve as solve;
use super::variance::ModelTerm;
use super::{Dataset, Fitted, Kernel, LearnError, NoProgress, Progress, TrainingMetrics};

/// `params` of an `lw-lssvm` model (RBF kernel only: the width is what is localised).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LwLsSvmParams {
    /// Regularisation γ (> 0) or `"auto"` (the default: chosen by CV). Wire name
    /// `reg`; `gamma` is accepted as an alias (never both).
    #[serde(rename = "reg", alias = "gamma", default)]
    pub gamma: Hyper,
    /// Base RBF width σ² (> 0, multiplied by each query's `d`) or `"auto"` (default).
    #[serde(default)]
    pub sigma2: Hyper,
    /// Neighbours per query (≥ 2, default 30; capped at the training set size).
    #[serde(default = "default_k")]
    pub k: usize,
    /// Floor of `d` relative to `mean(L)` (≥ 0, default 1e-12).
    #[serde(default = "default_d_floor")]
    pub d_floor: f64,
    /// Standardise inputs and targets (default true).
    #[serde(default = "yes")]
    pub standardize: bool,
}

fn default_k() -> usize {
    30
}
fn default_d_floor() -> f64 {
    1e-12
}
fn yes() -> bool {
    true
}

impl Default for LwLsSvmParams {
    fn default() -> Self {
        LwLsSvmParams {
            gamma: Hyper::Auto,
            sigma2: Hyper::Auto,
            k: default_k(),
            d_floor: default_d_floor(),
            standardize: true,
        }
    }
}

impl LwLsSvmParams {
    /// Fixed γ and σ², other fields at their defaults.
    pub fn new(gamma: f64, sigma2: f64) -> Self {
        LwLsSvmParams {
            gamma: Hyper::Value(gamma),
            sigma2: Hyper::Value(sigma2),
            ..Self::default()
        }
    }

    /// Validates the parameters; the error names the field.
    pub fn check(&self) -> Result<ValidLwLsSvmParams, LearnError> {
        self.gamma.check("reg")?;
        self.sigma2.check("sigma2")?;
        if self.k < 2 {
            return Err(LearnError::params("k", "must be at least 2"));
        }
        if !(self.d_floor.is_finite() && self.d_floor >= 0.0) {
            return Err(LearnError::params("d_floor", "must be a finite number ≥ 0"));
        }
        Ok(ValidLwLsSvmParams(self.clone()))
    }

    /// `self.check()?.fit(data)`.
    pub fn fit(&self, data: &Dataset) -> Result<LwLsSvmModel, LearnError> {
        self.check()?.fit(data)
    }
}

/// [`LwLsSvmParams`] that passed [`LwLsSvmParams::check`]: the only way to fit.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidLwLsSvmParams(LwLsSvmParams);

impl ValidLwLsSvmParams {
    /// The checked parameters.
    pub fn params(&self) -> &LwLsSvmParams {
        &self.0
    }

    /// True when fitting runs cross-validation first: a hyper-parameter is `"auto"`
    /// or a `cv` block is given.
    pub fn tunes(&self, cv_given: bool) -> bool {
        Search::plan(self.0.gamma, self.0.sigma2, true, cv_given).is_some()
    }

    /// Fits on `data` (targets required), tuning `"auto"` hyper-parameters by CV first.
    pub fn fit(&self, data: &Dataset) -> Result<LwLsSvmModel, LearnError> {
        Ok(self.fit_with(None, data, &NoProgress)?.model)
    }

    /// The training job: CV when asked (see [`super::cv`]), then the model (which
    /// stores the training set; the local fits happen at prediction).
    pub fn fit_with(
        &self,
        cv: Option<&CvParams>,
        data: &Dataset,
        progress: &dyn Progress,
    ) -> Result<Fitted<LwLsSvmModel, LwLsSvmParams>, LearnError> {
        train(&self.0, cv, data, progress)
    }
}

/// A locally weighted LS-SVM: the training set, predicting by a local fit per query.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LwLsSvmModel {
    /// Input dimension.
    dim: usize,
    /// γ of every local fit.
    #[serde(with = "exact::one")]
    gamma: f64,
    /// Base width σ² (training units).
    #[serde(with = "exact::one")]
    sigma2: f64,
    /// Neighbours per query (already capped at the training set size).
    k: usize,
    /// Relative floor of `d`.
    #[serde(with = "exact::one")]
    d_floor: f64,
    /// Training inputs, row-major, training units.
    #[serde(with = "exact::vec")]
    rows: Vec<f64>,
    /// Training targets, training units.
    #[serde(with = "exact::vec")]
    y: Vec<f64>,
    /// Input standardisation.
    x_scale: ExactScale,
    /// Target standardisation.
    y_scale: ExactScale,
}

impl LwLsSvmModel {
    /// Input dimension.
    pub fn input_dim(&self) -> usize {
        self.dim
    }

    /// `f(x)` in original units (NaN if the local system cannot be solved).
    pub fn predict_one(&self, x: &[f64]) -> f64 {
        self.predict_with_term(x).0
    }

    /// γ of every local fit.
    pub fn gamma(&self) -> f64 {
        self.gamma
    }

    /// `f(x)` in original units and the model term `m(x)` of the local fit that answered
    /// it (docs/methods.md §M9a; its variance is `σ_e² (1 + γ m(x))`), both NaN if the
    /// local system cannot be solved. Costs what [`LwLsSvmModel::predict_one`] costs plus
    /// one forward substitution.
    pub fn predict_with_term(&self, x: &[f64]) -> (f64, f64) {
        let mut z: Vec<f64> = (0..self.dim)
            .map(|j| x.get(j).copied().unwrap_or(f64::NAN))
            .collect();
        self.x_scale.apply(&mut z);
        let local = Local {
            rows: &self.rows,
            y: &self.y,
            dim: self.dim,
        };
        let nb = local.neighbours(&z, self.k, None);
        let (f, m) = local
            .predict(&nb, &z, self.gamma, self.sigma2, self.d_floor)
            .map(|(f, term)| (f, term.at(&z)))
            .unwrap_or((f64::NAN, f64::NAN));
        (self.y_scale.invert(0, f), m)
    }
}

/// A query's neighbourhood: indices into the training rows and `L_j`.
struct Neighbours {
    idx: Vec<usize>,
    dist2: Vec<f64>,
}

/// A training set seen by the local fits (all of it, or a CV fold's part).
struct Local<'a> {
    rows: &'a [f64],
    y: &'a [f64],
    dim: usize,
}

impl Local<'_> {
    /// The `k` nearest samples to `z` among `among` (all samples when `None`).
    fn neighbours(&self, z: &[f64], k: usize, among: Option<&[usize]>) -> Neighbours {
        let d = self.dim;
        let dist = |i: usize| -> f64 {
            self.rows[i * d..(i + 1) * d]
                .iter()
                .zip(z)
                .map(|(a, b)| (a - b) * (a - b))
                .sum()
        };
        let mut all: Vec<(f64, usize)> = match among {
            Some(ids) => ids.iter().map(|&i| (dist(i), i)).collect(),
            None => (0..self.y.len()).map(|i| (dist(i), i)).collect(),
        };
        let k = k.min(all.len());
        if k < all.len() {
            all.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
            all.truncate(k);
        }
        Neighbours {
            idx: all.iter().map(|p| p.1).collect(),
            dist2: all.iter().map(|p| p.0).collect(),
        }
    }

    /// The local LS-SVM's prediction at `z` (training units), docs/methods.md §M10, and
    /// the factor of the local fit, which answers its model term (§M9a).
    fn predict(
        &self,
        nb: &Neighbours,
        z: &[f64],
        gamma: f64,
        sigma2: f64,
        d_floor: f64,
    ) -> Result<(f64, ModelTerm), LearnError> {
        let l = &nb.dist2;
        let (l_min, l_max) = l.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
        let mean = l.iter().sum::<f64>() / l.len() as f64;
        let d = if mean > 0.0 {
            // seed 000 §1.2: β = sin((L_min/L_max)·π/2), d = max(β·mean(L), floor).
            let beta = (l_min / l_max * std::f64::consts::FRAC_PI_2).sin();
            (beta * mean).max(d_floor * mean)
        } else {
            1.0
        };
        let kernel = Kernel::Rbf { sigma2: sigma2 * d };
        let dim = self.dim;
        let mut rows = Vec::with_capacity(nb.idx.len() * dim);
        for &i in &nb.idx {
            rows.extend_from_slice(&self.rows[i * dim..(i + 1) * dim]);
        }
        let y: Vec<f64> = nb.idx.iter().map(|&i| self.y[i]).collect();
        let term = ModelTerm::new(rows, dim, kernel, gamma)?;
        let sol = solve::two_solve(term.factor(), &y);
        let f = solve::evaluate(term.rows(), dim, &sol.alpha, sol.b, &kernel, z);
        Ok((f, term))
    }
}

/// k-fold CV of the local model: neighbourhoods are computed once per fold (they do not
/// depend on γ or σ²), then every grid pair is scored on them.
fn tune(
    p: &Prepared,
    params: &LwLsSvmParams,
    search: Search,
    cv: &CvParams,
    progress: &dyn Progress,
) -> Result<cv::Tuned, LearnError> {
    let local = Local {
        rows: &p.rows,
        y: &p.y,
        dim: p.dim,
    };
    let scale = p.y_scale.std[0].powi(2);
    let mut cache: Option<(usize, Vec<Neighbours>)> = None;
    cv::grid_search(
        cv,
        search,
        p.n(),
        scale,
        progress,
        (0.0, 0.9),
        |fold, sigma2, gammas| {
            if cache.as_ref().is_none_or(|c| c.0 != fold.index) {
                let nbs = fold
                    .val
                    .iter()
                    .map(|&i| {
                        local.neighbours(
                            &p.rows[i * p.dim..(i + 1) * p.dim],
                            params.k,
                            Some(&fold.train),
                        )
                    })
                    .collect();
                cache = Some((fold.index, nbs));
            }
            let nbs = &cache.as_ref().expect("filled above").1;
            let mut out = vec![0.0; gammas.len()];
            for (gi, &g) in gammas.iter().enumerate() {
                for (nb, &i) in nbs.iter().zip(&fold.val) {
                    let z = &p.rows[i * p.dim..(i + 1) * p.dim];
                    out[gi] += match local.predict(nb, z, g, sigma2, params.d_floor) {
                        Ok((f, _)) => (f - p.y[i]).powi(2),
                        Err(_) => f64::INFINITY,
                    };
                }
            }
            Ok(out)
        },
    )
}

/// [`ValidLwLsSvmParams::fit_with`] on checked `params`.
fn train(
    params: &LwLsSvmParams,
    cv: Option<&CvParams>,
    data: &Dataset,
    progress: &dyn Progress,
) -> Result<Fitted<LwLsSvmModel, LwLsSvmParams>, LearnError> {
    let started = Instant::now();
    let p = Prepared::new(data, params.standardize)?;
    let mut report: Option<CvReport> = None;
    let (gamma, sigma2) = match Search::plan(params.gamma, params.sigma2, true, cv.is_some()) {
        Some(search) => {
            let tuned = tune(
                &p,
                params,
                search,
                cv.unwrap_or(&CvParams::default()),
                progress,
            )?;
            report = Some(tuned.report);
            (tuned.gamma, tuned.sigma2.unwrap_or(1.0))
        }
        None => (
            params.gamma.value().unwrap_or(1.0),
            params.sigma2.value().unwrap_or(1.0),
        ),
    };
    if progress.cancelled() {
        return Err(LearnError::Cancelled);
    }
    progress.report(0.9, "fit");
    let model = LwLsSvmModel {
        dim: p.dim,
        gamma,
        sigma2,
        k: params.k.min(p.n()),
        d_floor: params.d_floor,
        x_scale: (&p.x_scale).into(),
        y_scale: (&p.y_scale).into(),
        rows: p.rows,
        y: p.y,
    };
    let metrics = TrainingMetrics {
        n: data.n(),
        dim: data.dim(),
        seconds: started.elapsed().as_secs_f64(),
        train_rmse: train_rmse(data, |x| model.predict_one(x)),
        cv: report,
        ..TrainingMetrics::default()
    };
    let effective = LwLsSvmParams {
        gamma: Hyper::Value(gamma),
        sigma2: Hyper::Value(sigma2),
        ..params.clone()
    };
    Ok(Fitted {
        model,
        params: effective,
        metrics,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::lssvm::LsSvmParams;
    use crate::learn::{AnyModel, ModelParams};

    /// `|x|`-like kink at 0.3 on a smooth background, sampled on a grid.
    fn kinked(x: f64) -> f64 {
        (3.0 * x).sin() + 4.0 * (x - 0.3).abs()
    }

    #[test]
    fn local_model_beats_the_global_one_near_a_kink() {
        let xs: Vec<Vec<f64>> = (0..120)
            .map(|i| vec![-1.0 + 2.0 * i as f64 / 119.0])
            .collect();
        let ys: Vec<f64> = xs.iter().map(|r| kinked(r[0])).collect();
        let data = Dataset::new(&xs, Some(&ys)).unwrap();
        // Each model with its hyper-parameters tuned by the same 5-fold CV: the global
        // model must use one width everywhere, the local one adapts it per query.
        // (Coarse grid only, to keep the debug-mode test short.)
        let cv = CvParams {
            refine: false,
            ..CvParams::default()
        };
        let global = LsSvmParams::default()
            .check()
            .unwrap()
            .fit_with(Some(&cv), &data, &NoProgress)
            .unwrap()
            .model;
        let lw = LwLsSvmParams {
            k: 20,
            ..LwLsSvmParams::default()
        };
        let local = train(&lw, Some(&cv), &data, &NoProgress).unwrap().model;
        let near: Vec<f64> = (0..40)
            .map(|i| 0.2 + 0.2 * (i as f64 + 0.5) / 40.0)
            .collect();
        let rmse = |f: &dyn Fn(&[f64]) -> f64| {
            (near
                .iter()
                .map(|&x| (f(&[x]) - kinked(x)).powi(2))
                .sum::<f64>()
                / near.len() as f64)
                .sqrt()
        };
        let (g, l) = (
            rmse(&|x| global.predict_one(x)),
            rmse(&|x| local.predict_one(x)),
        );
        assert!(l < 0.5 * g, "local {l} vs global {g}");
    }

    #[test]
    fn the_variance_term_equals_the_gp_posterior_of_the_local_fit() {
        use crate::learn::variance::bordered_reference;
        let xs: Vec<Vec<f64>> = (0..90)
            .map(|i| vec![(i as f64 * 0.37).sin() * 2.0, (i as f64 * 0.11).cos()])
            .collect();
        let ys: Vec<f64> = xs.iter().map(|r| r[0] * r[1]).collect();
        let m = LwLsSvmParams {
            k: 15,
            ..LwLsSvmParams::new(50.0, 2.0)
        }
        .fit(&Dataset::new(&xs, Some(&ys)).unwrap())
        .unwrap();
        for q in [[0.3, 0.2], [1.7, -0.4], [-1.1, 0.9], [5.0, 5.0]] {
            let z: Vec<f64> = (0..2).map(|j| m.x_scale.apply_one(j, q[j])).collect();
            // The 15 nearest training rows by brute force, and the §M10 width.
            let mut by_dist: Vec<(f64, &[f64])> = m
                .rows
                .chunks_exact(2)
                .map(|r| ((r[0] - z[0]).powi(2) + (r[1] - z[1]).powi(2), r))
                .collect();
            by_dist.sort_by(|a, b| a.0.total_cmp(&b.0));
            let near = &by_dist[..15];
            let (lo, hi) = (near[0].0, near[14].0);
            let mean = near.iter().map(|p| p.0).sum::<f64>() / 15.0;
            let d = ((lo / hi * std::f64::consts::FRAC_PI_2).sin() * mean).max(1e-12 * mean);
            let rows: Vec<f64> = near.iter().flat_map(|p| p.1.iter().copied()).collect();
            let kernel = Kernel::Rbf { sigma2: 2.0 * d };
            let reference = bordered_reference(&rows, 2, kernel, 50.0, &z);
            let (f, got) = m.predict_with_term(&q);
            assert_eq!(f, m.predict_one(&q));
            assert!(
                (got - reference).abs() <= 1e-9 * reference,
                "{q:?}: {got:e} vs {reference:e}"
            );
        }
    }

    #[test]
    fn a_query_on_a_training_point_uses_the_floor_and_stays_finite() {
        let xs: Vec<Vec<f64>> = (0..50).map(|i| vec![i as f64 * 0.1]).collect();
        let ys: Vec<f64> = xs.iter().map(|r| r[0].cos()).collect();
        let m = LwLsSvmParams {
            k: 10,
            ..LwLsSvmParams::new(1e6, 1.0)
        }
        .fit(&Dataset::new(&xs, Some(&ys)).unwrap())
        .unwrap();
        // L_min = 0 ⇒ β = 0 ⇒ d = 1e-12·mean(L): the local kernel is ≈ I and the fit
        // interpolates the training target.
        assert!((m.predict_one(&[2.0]) - 2.0f64.cos()).abs() < 1e-4);
        let dup = LwLsSvmParams {
            k: 3,
            ..LwLsSvmParams::new(10.0, 1.0)
        }
        .fit(
            &Dataset::new(
                &[vec![1.0], vec![1.0], vec![1.0], vec![2.0]],
                Some(&[1.0, 2.0, 3.0, 4.0]),
            )
            .unwrap(),
        )
        .unwrap();
        assert!(dup.predict_one(&[1.0]).is_finite());
    }

    #[test]
    fn bad_params_name_the_field_and_the_model_round_trips() {
        use crate::learn::ModelKind;
        let field = |v: serde_json::Value| match ModelParams::from_json(ModelKind::LwLsSvm, &v) {
            Err(LearnError::InvalidParams { field, .. }) => field,
            other => panic!("{other:?}"),
        };
        assert_eq!(field(serde_json::json!({"k": 1})), "k");
        assert_eq!(field(serde_json::json!({"d_floor": -1.0})), "d_floor");
        assert_eq!(field(serde_json::json!({"gamma": 0})), "gamma");
        assert_eq!(field(serde_json::json!({"reg": 0})), "reg");
        assert_eq!(field(serde_json::json!({"sigma2": "wide"})), "sigma2");
        let xs: Vec<Vec<f64>> = (0..30).map(|i| vec![i as f64, (i as f64).sqrt()]).collect();
        let ys: Vec<f64> = xs.iter().map(|r| r[1].sin()).collect();
        let t = train(
            &LwLsSvmParams {
                k: 8,
                ..LwLsSvmParams::default()
            },
            None,
            &Dataset::new(&xs, Some(&ys)).unwrap(),
            &NoProgress,
        )
        .unwrap();
        assert!(t.metrics.cv.is_some() && t.metrics.train_rmse.is_some());
        let any = AnyModel::LwLsSvm(t.model.clone());
        let back = AnyModel::from_stored_json(&any.to_stored_json()).unwrap();
        assert_eq!(back, any);
        assert_eq!(
            back.predict_one(&[3.5, 1.9]).to_bits(),
            t.model.predict_one(&[3.5, 1.9]).to_bits()
        );
    }
}
