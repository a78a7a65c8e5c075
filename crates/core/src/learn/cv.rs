//! Hyper-parameter tuning as LS-SVMlab's `tunelssvm` does it (docs/methods.md §M13): k-fold
//! cross-validation over a log-spaced grid of `gamma` and `sigma2`, optionally refined
//! around the best pair, deterministic for a seed. Called by `lssvm::train` and
//! `local::train` before the final fit; the model supplies the fold error.
//!
//! Which axes are searched: the hyper-parameters given as `"auto"`; when a `cv` block
//! is given and none is `"auto"`, both (`gamma` only for the linear kernel), the given
//! numbers being ignored. Fixed numbers are held while the others are searched.

use rand::{SeedableRng, rngs::StdRng, seq::SliceRandom};
use serde::{Deserialize, Serialize};

use super::{LearnError, Progress};

/// A hyper-parameter given as a number or `"auto"` (chosen by cross-validation).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub enum Hyper {
    /// A fixed value.
    Value(f64),
    /// Chosen by cross-validation (the default).
    #[default]
    Auto,
}

impl Hyper {
    /// The value, or `None` for `Auto`.
    pub fn value(self) -> Option<f64> {
        match self {
            Hyper::Value(v) => Some(v),
            Hyper::Auto => None,
        }
    }

    /// Checks a fixed value is a finite number greater than 0; `Auto` passes.
    pub fn check(self, field: &str) -> Result<(), LearnError> {
        match self {
            Hyper::Value(v) if !(v.is_finite() && v > 0.0) => Err(LearnError::params(
                field,
                "must be a finite number greater than 0, or \"auto\"",
            )),
            _ => Ok(()),
        }
    }
}

impl Serialize for Hyper {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Hyper::Value(v) => s.serialize_f64(*v),
            Hyper::Auto => s.serialize_str("auto"),
        }
    }
}

impl<'de> Deserialize<'de> for Hyper {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Num(f64),
            Text(String),
        }
        match Raw::deserialize(d)? {
            Raw::Num(v) => Ok(Hyper::Value(v)),
            Raw::Text(t) if t == "auto" => Ok(Hyper::Auto),
            Raw::Text(t) => Err(serde::de::Error::custom(format!(
                "expected a number or \"auto\", got \"{t}\""
            ))),
        }
    }
}

/// The `cv` block of `POST /api/v1/models`. Ranges are in the units the model trains
/// in: standardised units by default (`"standardize": true`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CvParams {
    /// Number of folds (≥ 2, ≤ the number of samples; default 5).
    #[serde(default = "default_folds")]
    pub folds: usize,
    /// Seed of the fold shuffle (default 0): the same seed gives the same folds.
    #[serde(default)]
    pub seed: u64,
    /// Grid points per searched axis (2..=50, default 7), log-spaced over the range.
    #[serde(default = "default_grid")]
    pub grid: usize,
    /// `[min, max]` of the `gamma` grid (default `[1e-2, 1e4]`).
    #[serde(default = "default_gamma_range")]
    pub gamma_range: [f64; 2],
    /// `[min, max]` of the `sigma2` grid (default `[1e-2, 1e3]`).
    #[serde(default = "default_sigma2_range")]
    pub sigma2_range: [f64; 2],
    /// Refine around the best coarse pair with a second `grid`-point grid spanning one
    /// coarse step either side (default true).
    #[serde(default = "default_refine")]
    pub refine: bool,
}

fn default_folds() -> usize {
    5
}
fn default_grid() -> usize {
    7
}
fn default_gamma_range() -> [f64; 2] {
    [1e-2, 1e4]
}
fn default_sigma2_range() -> [f64; 2] {
    [1e-2, 1e3]
}
fn default_refine() -> bool {
    true
}

impl Default for CvParams {
    fn default() -> Self {
        CvParams {
            folds: default_folds(),
            seed: 0,
            grid: default_grid(),
            gamma_range: default_gamma_range(),
            sigma2_range: default_sigma2_range(),
            refine: default_refine(),
        }
    }
}

impl CvParams {
    /// Validates the block; errors are named `cv.<field>`.
    pub fn check(&self) -> Result<(), LearnError> {
        if self.folds < 2 {
            return Err(LearnError::params("cv.folds", "must be at least 2"));
        }
        if !(2..=50).contains(&self.grid) {
            return Err(LearnError::params("cv.grid", "must be between 2 and 50"));
        }
        for (field, [lo, hi]) in [
            ("cv.gamma_range", self.gamma_range),
            ("cv.sigma2_range", self.sigma2_range),
        ] {
            if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi > lo) {
                return Err(LearnError::params(
                    field,
                    "must be [min, max] with 0 < min < max, finite",
                ));
            }
        }
        Ok(())
    }
}

/// What cross-validation chose and measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CvReport {
    /// Folds used.
    pub folds: usize,
    /// Chosen regularisation γ: wire name `reg`, as in the params (`gamma` is read
    /// from metrics stored before the rename).
    #[serde(rename = "reg", alias = "gamma")]
    pub gamma: f64,
    /// Chosen `sigma2` (absent for the linear kernel).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma2: Option<f64>,
    /// Mean squared CV error of the chosen pair (regression, original units) or CV
    /// misclassification rate.
    pub error: f64,
    /// Grid points evaluated.
    pub evaluated: usize,
}

/// One fold: the sample indices to train on (ascending) and to validate on.
#[derive(Debug, Clone, PartialEq)]
pub struct Fold {
    /// 0-based fold number.
    pub index: usize,
    /// Training indices, ascending.
    pub train: Vec<usize>,
    /// Validation indices, ascending.
    pub val: Vec<usize>,
}

/// Splits `0..n` into `folds` folds after a shuffle seeded by `seed`.
pub fn make_folds(n: usize, folds: usize, seed: u64) -> Result<Vec<Fold>, LearnError> {
    if folds > n {
        return Err(LearnError::params(
            "cv.folds",
            format!("must not exceed the {n} training samples"),
        ));
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(&mut StdRng::seed_from_u64(seed));
    let mut out = Vec::with_capacity(folds);
    for f in 0..folds {
        // Fold f takes a contiguous chunk of the shuffled order (sizes differ by ≤ 1).
        let (lo, hi) = (f * n / folds, (f + 1) * n / folds);
        let mut val = order[lo..hi].to_vec();
        let mut train: Vec<usize> = order[..lo].iter().chain(&order[hi..]).copied().collect();
        val.sort_unstable();
        train.sort_unstable();
        out.push(Fold {
            index: f,
            train,
            val,
        });
    }
    Ok(out)
}

/// The search: which axes are free and where a fixed one sits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Search {
    /// `gamma`: `None` = searched, `Some(v)` = held at `v`.
    pub gamma: Option<f64>,
    /// `sigma2`: `None` = searched, `Some(v)` = held at `v`. Ignored when `kernel_has_width` is false.
    pub sigma2: Option<f64>,
    /// False for the linear kernel (no `sigma2` axis).
    pub kernel_has_width: bool,
}

impl Search {
    /// The search for the given hyper-parameters: `"auto"` ones are free; with an explicit
    /// `cv` block and nothing `"auto"`, all are free. `None` when no search is needed.
    pub fn plan(gamma: Hyper, sigma2: Hyper, has_width: bool, cv_given: bool) -> Option<Search> {
        let sigma2 = if has_width { sigma2 } else { Hyper::Value(1.0) };
        let any_auto = gamma == Hyper::Auto || sigma2 == Hyper::Auto;
        if any_auto {
            Some(Search {
                gamma: gamma.value(),
                sigma2: sigma2.value(),
                kernel_has_width: has_width,
            })
        } else if cv_given {
            Some(Search {
                gamma: None,
                sigma2: None,
                kernel_has_width: has_width,
            })
        } else {
            None
        }
    }
}

/// `points` log-spaced values from `lo` to `hi` inclusive.
fn log_grid(lo: f64, hi: f64, points: usize) -> Vec<f64> {
    let (a, b) = (lo.ln(), hi.ln());
    (0..points)
        .map(|i| (a + (b - a) * i as f64 / (points - 1) as f64).exp())
        .collect()
}

/// The best pair found and its report.
#[derive(Debug, Clone, PartialEq)]
pub struct Tuned {
    /// Chosen γ.
    pub gamma: f64,
    /// Chosen σ² (`None` for the linear kernel).
    pub sigma2: Option<f64>,
    /// The report for `TrainingMetrics.cv`.
    pub report: CvReport,
}

/// Grid search by k-fold CV. `fold_error(fold, sigma2, gammas)` returns the sum of
/// squared validation errors of `fold` for each γ in `gammas` at width `sigma2` (the
/// model may reuse one kernel matrix across the γs); the CV error is the total over
/// folds divided by `n`, then multiplied by `scale` (e.g. the target variance, to
/// report in original units). Progress runs from `from` to `to` with stage
/// `"cv fold f/F"` (`"cv refine fold f/F"` for the refinement).
#[allow(clippy::too_many_arguments)]
pub fn grid_search(
    cv: &CvParams,
    search: Search,
    n: usize,
    scale: f64,
    progress: &dyn Progress,
    (from, to): (f64, f64),
    mut fold_error: impl FnMut(&Fold, f64, &[f64]) -> Result<Vec<f64>, LearnError>,
) -> Result<Tuned, LearnError> {
    cv.check()?;
    let folds = make_folds(n, cv.folds, cv.seed)?;
    let axis = |fixed: Option<f64>, [lo, hi]: [f64; 2]| match fixed {
        Some(v) => vec![v],
        None => log_grid(lo, hi, cv.grid),
    };
    let gammas = axis(search.gamma, cv.gamma_range);
    let sigmas = axis(search.sigma2, cv.sigma2_range);
    let mid = if cv.refine {
        from + 0.6 * (to - from)
    } else {
        to
    };
    let mut evaluated = 0;
    let coarse = evaluate_grid(
        &folds,
        &gammas,
        &sigmas,
        progress,
        (from, mid),
        "cv",
        &mut fold_error,
    )?;
    evaluated += gammas.len() * sigmas.len();
    let mut best = coarse;
    if cv.refine {
        // One coarse step either side of the best, `grid` points per free axis.
        let around = |fixed: Option<f64>, [lo, hi]: [f64; 2], at: f64| match fixed {
            Some(v) => vec![v],
            None => {
                let step = (hi / lo).powf(1.0 / (cv.grid - 1) as f64);
                log_grid(at / step, at * step, cv.grid)
            }
        };
        let g2 = around(search.gamma, cv.gamma_range, best.0);
        let s2 = around(search.sigma2, cv.sigma2_range, best.1);
        let fine = evaluate_grid(
            &folds,
            &g2,
            &s2,
            progress,
            (mid, to),
            "cv refine",
            &mut fold_error,
        )?;
        evaluated += g2.len() * s2.len();
        if fine.2 < best.2 {
            best = fine;
        }
    }
    let (gamma, sigma2, sse) = best;
    let sigma2 = search.kernel_has_width.then_some(sigma2);
    let error = sse / n as f64 * scale;
    Ok(Tuned {
        gamma,
        sigma2,
        report: CvReport {
            folds: cv.folds,
            gamma,
            sigma2,
            error,
            evaluated,
        },
    })
}

/// Evaluates every (γ, σ²) of the grid over every fold; returns the best
/// `(γ, σ², total SSE)`, ties going to the first in grid order.
fn evaluate_grid(
    folds: &[Fold],
    gammas: &[f64],
    sigmas: &[f64],
    progress: &dyn Progress,
    (from, to): (f64, f64),
    stage: &str,
    fold_error: &mut impl FnMut(&Fold, f64, &[f64]) -> Result<Vec<f64>, LearnError>,
) -> Result<(f64, f64, f64), LearnError> {
    let mut sse = vec![0.0; gammas.len() * sigmas.len()];
    let steps = (folds.len() * sigmas.len()) as f64;
    for fold in folds {
        let label = format!("{stage} fold {}/{}", fold.index + 1, folds.len());
        for (si, &s) in sigmas.iter().enumerate() {
            if progress.cancelled() {
                return Err(LearnError::Cancelled);
            }
            let done = (fold.index * sigmas.len() + si) as f64 / steps;
            progress.report(from + (to - from) * done, &label);
            let errs = fold_error(fold, s, gammas)?;
            for (gi, e) in errs.iter().enumerate() {
                // A fold that failed numerically counts as infinitely bad, not fatal.
                sse[si * gammas.len() + gi] += if e.is_finite() { *e } else { f64::INFINITY };
            }
        }
    }
    let mut best = (gammas[0], sigmas[0], f64::INFINITY);
    for (si, &s) in sigmas.iter().enumerate() {
        for (gi, &g) in gammas.iter().enumerate() {
            let e = sse[si * gammas.len() + gi];
            if e < best.2 {
                best = (g, s, e);
            }
        }
    }
    if !best.2.is_finite() {
        return Err(LearnError::Numerical(
            "cross-validation: no grid point gave a finite error".into(),
        ));
    }
    Ok(best)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::NoProgress;

    #[test]
    fn folds_partition_the_samples_and_depend_only_on_the_seed() {
        let a = make_folds(23, 5, 7).unwrap();
        let b = make_folds(23, 5, 7).unwrap();
        assert_eq!(a, b);
        assert_ne!(a, make_folds(23, 5, 8).unwrap());
        let mut all: Vec<usize> = a.iter().flat_map(|f| f.val.clone()).collect();
        all.sort_unstable();
        assert_eq!(all, (0..23).collect::<Vec<_>>());
        for f in &a {
            assert!(f.val.len() == 4 || f.val.len() == 5);
            assert_eq!(f.train.len() + f.val.len(), 23);
        }
    }

    #[test]
    fn bad_cv_blocks_name_their_field() {
        let field = |cv: CvParams| match cv.check() {
            Err(LearnError::InvalidParams { field, .. }) => field,
            other => panic!("{other:?}"),
        };
        let base = CvParams::default();
        assert_eq!(
            field(CvParams {
                folds: 1,
                ..base.clone()
            }),
            "cv.folds"
        );
        assert_eq!(
            field(CvParams {
                grid: 1,
                ..base.clone()
            }),
            "cv.grid"
        );
        assert_eq!(
            field(CvParams {
                gamma_range: [10.0, 1.0],
                ..base.clone()
            }),
            "cv.gamma_range"
        );
        assert_eq!(
            field(CvParams {
                sigma2_range: [0.0, 1.0],
                ..base.clone()
            }),
            "cv.sigma2_range"
        );
        assert!(matches!(
            make_folds(3, 5, 0),
            Err(LearnError::InvalidParams { field, .. }) if field == "cv.folds"
        ));
        let unknown = serde_json::from_value::<CvParams>(serde_json::json!({"fold": 3}));
        assert!(unknown.is_err());
    }

    #[test]
    fn grid_search_finds_the_minimum_of_a_known_bowl() {
        // Error bowl with its minimum at γ = 10, σ² = 1 (both on the default grid),
        // the same for every fold: the search must land there exactly.
        let search = Search::plan(Hyper::Auto, Hyper::Auto, true, false).unwrap();
        let cv = CvParams {
            refine: false,
            sigma2_range: [1e-3, 1e3],
            ..CvParams::default()
        };
        let t = grid_search(&cv, search, 20, 1.0, &NoProgress, (0.0, 1.0), |_, s, gs| {
            Ok(gs
                .iter()
                .map(|g| (g.log10() - 1.0).powi(2) + s.log10().powi(2))
                .collect())
        })
        .unwrap();
        assert!(
            (t.gamma - 10.0).abs() < 1e-9 && (t.sigma2.unwrap() - 1.0).abs() < 1e-9,
            "{t:?}"
        );
        assert_eq!(t.report.evaluated, 49);
    }

    #[test]
    fn only_auto_axes_are_searched_unless_a_cv_block_asks_for_all() {
        let s = Search::plan(Hyper::Value(3.0), Hyper::Auto, true, false).unwrap();
        assert_eq!((s.gamma, s.sigma2), (Some(3.0), None));
        assert!(Search::plan(Hyper::Value(3.0), Hyper::Value(1.0), true, false).is_none());
        let s = Search::plan(Hyper::Value(3.0), Hyper::Value(1.0), true, true).unwrap();
        assert_eq!((s.gamma, s.sigma2), (None, None));
        // Linear kernel: sigma2 "auto" is irrelevant, only gamma counts.
        assert!(Search::plan(Hyper::Value(3.0), Hyper::Auto, false, false).is_none());
    }
}
