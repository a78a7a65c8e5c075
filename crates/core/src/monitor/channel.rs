//! The `channel` monitor (docs/methods.md §M14, seeds 000 and 001): each named channel of the
//! epoch (`channels {name: value}`, a filter innovation or a measurement difference such
//! as GNSS minus barometric height) is predicted by an LS-SVM from its own past, and the
//! prediction residual is tested with T_a. Sits between the session actor and `learn/` +
//! `detect/`.
//!
//! Config (every field but `name` and `predictor` optional; [`config`] validates it):
//! ```json
//! {"channels": [
//!   {"name": "dh", "dim": 1, "embedding": 5,
//!    "predictor": {"model": "m-0123456789abcdef"},
//!    "outlier_filter": {"c": 3}, "n": 10, "variance": "batch_means",
//!    "min_blocks": 10, "max_blocks": 50,
//!    "stuck": {"k": 8, "p_fa": 1e-6}, "drift": {"windows": [30, 60]}, "guard": 10},
//!   {"name": "gyro", "predictor": {"online": {"window": 50, "gamma": 30, "sigma2": 9, "refresh": 1000}}}
//! ]}
//! ```
//! - `dim` (default 1): components of the channel's value. `embedding` m (default 5): the
//!   input is `x_k = [y_{k−m}, …, y_{k−1}]` → `y_k`; for a vector channel the m past
//!   values are concatenated oldest first (m·dim inputs).
//! - `predictor`: a stored model id (`lssvm` or `lw-lssvm`, input dimension m·dim) — for a
//!   vector channel an array of ids, **one model per component**, each fed the whole
//!   embedding — or `online`: a sliding-window LS-SVM per component (seed 001, raw units,
//!   learning as it goes; it predicts once its window holds two samples, and its residuals
//!   are tested — and feed the tests' variances — once the window is full).
//! - `outlier_filter` (optional, seed 001 §2.2.1): values entering the predictor's history
//!   and window pass the third-difference filter first (the residual and the tests always
//!   use the raw value, so a fault cannot be filtered away).
//! - **Tests** of a channel `c`: `c` (T_a on the residual: by default the batch-means
//!   windowed mean over windows 1 and `n`, docs/methods.md §M20; with `"variance":
//!   "successive_difference"` seed 000's eq. 14–16 form, [`crate::detect::ta`]),
//!   `c.stuck` (variance collapse of the raw values, its own `p_fa`, on by default,
//!   docs/methods.md §M21) and `c.drift` (a longer-window batch-means mean test on the
//!   residual, off by default). All run under the monitor's policy.
//! - `residual_scale` (default `"raw"`): with `"predictive"` the main and drift tests see
//!   the residual over `√(1 + γ m(x))`, its predictive σ relative to the noise level
//!   (docs/methods.md §M9a, §M14: short fault-free bursts, at the cost of a persistent
//!   bias's flagged epochs).
//!
//! Per epoch and channel: ŷ_k from the history, `r_k = y_k − ŷ_k`, the tests, the policy.
//! **Learning** (the online window's sample, the tests' variances and the stuck test's
//! reference) happens only on epochs where every test of the channel is healthy and the
//! last non-healthy epoch is more than `guard` epochs back (docs/methods.md §M14): a fault
//! flagged now and then is never learned between its flags. An online predictor frozen for
//! `max_freeze` epochs learns again (not the variances) until the channel is healthy: a
//! frozen sliding window cannot follow a signal that moves on, so without this a false
//! alarm on a changing signal turns into a permanent one (measured in docs/experiments.md;
//! `"max_freeze": 0` never relearns). The outlier filter is bypassed
//! while a test is not healthy (it restarts on the return). The measured value still
//! enters the embedding history: feeding the prediction back instead (free-running
//! through the fault) was tried and deadlocks — once the free-run drifts from the signal
//! the residual stays large after the fault has ended, the channel never returns to
//! healthy and so never sees real data again. A channel absent from an epoch skips it. A
//! prediction that is not finite fails the step (state unchanged).

mod config;
#[cfg(test)]
mod lockin_tests;
mod saved;
#[cfg(test)]
mod tests;

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

pub use config::{
    ChannelConfig, ChannelConfigWire, ChannelMonitorConfig, ChannelWire, DEFAULT_DRIFT_WINDOWS,
    DEFAULT_EMBEDDING, DEFAULT_GUARD, DEFAULT_MAX_FREEZE, DEFAULT_N, DEFAULT_OUTLIER_C, DriftWire,
    MainTestConfig, ModelIds, OutlierWire, PredictorConfig, PredictorWire, ResidualScale,
    StuckConfig, StuckWire, Toggle, VarianceKind,
};

use super::{
    BuildError, CheckpointError, EpochError, ModelSource, Monitor, MonitorKind, MonitorReport,
    Outputs, StepError, TestBank, TestName, TestOutcome,
};
use crate::detect::stuck::{StuckError, StuckTest};
use crate::detect::window::{WindowError, WindowTest};
use crate::detect::{Health, PolicyState, TaError, TaStatistic, ThresholdSpec};
use crate::epoch::Epoch;
use crate::filter::kalman::FilterError;
use crate::learn::online::OnlineLsSvm;
use crate::learn::outlier::OutlierFilter;
use crate::learn::variance::ModelTerm;
use crate::learn::{AnyModel, LearnError};
use config::learn_field;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// The running predictor of one channel.
#[derive(Debug, Clone)]
enum Predictor {
    Stored(Vec<Arc<AnyModel>>),
    Online(Vec<OnlineLsSvm>),
}

/// The running main test of one channel.
#[derive(Debug, Clone, Serialize, Deserialize)]
enum MainTest {
    BatchMeans(WindowTest),
    SuccessiveDifference(TaStatistic),
}

impl MainTest {
    fn new(config: &MainTestConfig) -> Self {
        match config {
            MainTestConfig::BatchMeans(p) => {
                MainTest::BatchMeans(WindowTest::with_equal_memory(p.clone()))
            }
            MainTestConfig::SuccessiveDifference(p) => {
                MainTest::SuccessiveDifference(TaStatistic::new(*p))
            }
        }
    }

    /// The statistic with `r` as the newest residual (`None`: warm-up, or a variance
    /// without spread).
    fn evaluate(&self, r: &[f64]) -> Result<Option<f64>, StepError> {
        let bad = || StepError::Filter(FilterError::NonFinite("channel residual"));
        match self {
            MainTest::BatchMeans(w) => match w.evaluate(r) {
                Ok(v) => Ok(v.map(|v| v.value)),
                Err(WindowError::Singular) => Ok(None),
                Err(_) => Err(bad()),
            },
            MainTest::SuccessiveDifference(ta) => match ta.evaluate(r) {
                Ok(v) => Ok(v),
                Err(TaError::Singular) => Ok(None),
                Err(_) => Err(bad()),
            },
        }
    }

    /// `L⁻¹ r` with `L Lᵀ` the per-residual covariance in force (the batch means' healthy
    /// second moment, or V), for the consistency diagnostics (docs/methods.md §M22).
    fn normalise(&self, r: &[f64]) -> Option<Vec<f64>> {
        let cov: DMatrix<f64> = match self {
            MainTest::BatchMeans(w) => w.input_covariance()?.clone(),
            MainTest::SuccessiveDifference(ta) => {
                if ta.differences() < ta.params().min_differences {
                    return None;
                }
                ta.variance().clone()
            }
        };
        let l = cov.cholesky()?.l();
        let nu = l.solve_lower_triangular(&DVector::from_column_slice(r))?;
        Some(nu.as_slice().to_vec())
    }

    fn commit(&mut self, r: &[f64], learn: bool) {
        // Cannot fail: the residual was checked by `evaluate` in the step.
        let _ = match self {
            MainTest::BatchMeans(w) => w.commit(r, learn).map_err(|_| ()),
            MainTest::SuccessiveDifference(ta) => ta.commit(r, learn).map_err(|_| ()),
        };
    }
}

/// Bank indices of one channel's tests.
#[derive(Debug, Clone, Copy)]
struct TestIndices {
    main: usize,
    stuck: Option<usize>,
    drift: Option<usize>,
}

/// The state of one channel.
#[derive(Debug, Clone)]
struct ChannelState {
    config: ChannelConfig,
    predictor: Predictor,
    filters: Option<Vec<OutlierFilter>>,
    /// The last m values that entered the history, oldest first.
    history: VecDeque<Vec<f64>>,
    main: MainTest,
    stuck: Option<StuckTest>,
    drift: Option<WindowTest>,
    tests: TestIndices,
    /// Consecutive epochs, up to the last one, on which every test of the channel was
    /// healthy (saturating; starts high so a fresh channel learns at once).
    quiet: usize,
    /// Consecutive epochs, up to the last one, on which the channel did not teach.
    frozen: usize,
    /// The predictor learns again after `max_freeze` frozen epochs, until the channel is
    /// healthy (module doc).
    relearning: bool,
    /// Per component, the factor answering a stored batch LS-SVM's predictive-variance
    /// term (built once from the model when the residual scale is `predictive`; `None`
    /// otherwise). Shared: derived from the model, never changed.
    terms: Arc<[Option<ModelTerm>]>,
}

impl ChannelState {
    fn new(config: ChannelConfig, tests: TestIndices) -> Result<Self, LearnError> {
        let terms = Self::model_terms(&config)?;
        Self::with_terms(config, tests, terms)
    }

    /// The factors of a stored batch model's variance term, per component (empty unless
    /// the residual scale is `predictive`): O(N³) each, so built once per monitor.
    fn model_terms(config: &ChannelConfig) -> Result<Arc<[Option<ModelTerm>]>, LearnError> {
        match (&config.predictor, config.residual_scale) {
            (PredictorConfig::Stored(models), ResidualScale::Predictive) => models
                .iter()
                .map(|m| match &**m {
                    AnyModel::LsSvm(m) => m.model_term().map(Some),
                    _ => Ok(None),
                })
                .collect(),
            _ => Ok(Arc::from(Vec::new())),
        }
    }

    /// A fresh channel with the variance factors `terms` already built.
    fn with_terms(
        config: ChannelConfig,
        tests: TestIndices,
        terms: Arc<[Option<ModelTerm>]>,
    ) -> Result<Self, LearnError> {
        let predictor = match &config.predictor {
            PredictorConfig::Stored(models) => Predictor::Stored(models.clone()),
            PredictorConfig::Online(p) => Predictor::Online(
                (0..config.dim)
                    .map(|_| OnlineLsSvm::new(p.clone()))
                    .collect::<Result<_, _>>()?,
            ),
        };
        Ok(ChannelState {
            terms,
            filters: config
                .outlier_c
                .map(|c| vec![OutlierFilter::new(c); config.dim]),
            history: VecDeque::with_capacity(config.embedding),
            main: MainTest::new(&config.main),
            stuck: config.stuck.map(|s| StuckTest::new(s.params)),
            drift: config.drift.clone().map(WindowTest::new),
            predictor,
            tests,
            quiet: usize::MAX / 2,
            frozen: 0,
            relearning: false,
            config,
        })
    }

    /// The embedding `x_k` (m·dim values, oldest first), once the history is full.
    fn input(&self) -> Option<Vec<f64>> {
        (self.history.len() == self.config.embedding)
            .then(|| self.history.iter().flatten().copied().collect())
    }

    /// ŷ_k per component, when the predictor can predict, with the residual's scale per
    /// component: `√(1 + γ m(x))` under the `predictive` residual scale (docs/methods.md
    /// §M9a; 1 for a model kind without a variance), else 1.
    fn predict(&self, x: &[f64]) -> Option<(Vec<f64>, Vec<f64>)> {
        let predictive = self.config.residual_scale == ResidualScale::Predictive;
        let scale = |gamma: f64, m: f64| (1.0 + gamma * m).sqrt();
        match &self.predictor {
            Predictor::Stored(models) => Some(
                models
                    .iter()
                    .enumerate()
                    .map(|(i, m)| match (&**m, predictive) {
                        (AnyModel::LwLsSvm(lw), true) => {
                            let (f, term) = lw.predict_with_term(x);
                            (f, scale(lw.gamma(), term))
                        }
                        (AnyModel::LsSvm(ls), true) => {
                            let term = self.terms.get(i).and_then(Option::as_ref);
                            let s = term.map_or(1.0, |t| scale(ls.gamma(), ls.variance_term(t, x)));
                            (ls.predict_one(x), s)
                        }
                        _ => (m.predict_one(x), 1.0),
                    })
                    .unzip(),
            ),
            Predictor::Online(windows) => windows
                .iter()
                .map(|w| {
                    if predictive {
                        let (f, term) = w.predict_with_term(x)?;
                        Some((f, scale(w.params().gamma, term)))
                    } else {
                        Some((w.predict(x)?, 1.0))
                    }
                })
                .collect::<Option<Vec<_>>>()
                .map(|v| v.into_iter().unzip()),
        }
    }

    /// Whether the predictor's residuals are tested (an online window's once it is
    /// full: before that its predictions measure its learning, not the channel's noise).
    fn ready(&self) -> bool {
        match &self.predictor {
            Predictor::Online(w) => w.iter().all(|w| w.len() >= w.params().window),
            Predictor::Stored(_) => true,
        }
    }
}

/// Builds the embedding training set of a scalar series: rows `[y_{k−m}, …, y_{k−1}]`
/// and targets `y_k` for k = m … len−1 (what a stored channel model is trained on).
pub fn embed_series(series: &[f64], m: usize) -> (Vec<Vec<f64>>, Vec<f64>) {
    if m == 0 || series.len() <= m {
        return (Vec::new(), Vec::new());
    }
    let x = series.windows(m + 1).map(|w| w[..m].to_vec()).collect();
    let y = series[m..].to_vec();
    (x, y)
}

/// The `channel` monitor.
pub struct ChannelMonitor {
    channels: Vec<ChannelState>,
    bank: TestBank,
}

impl ChannelMonitor {
    /// Builds the monitor from a validated config: one main test per channel with dof =
    /// dim (indices 0…, in channel order, as before the stuck and drift tests existed),
    /// then each channel's `.drift` (dof dim) and `.stuck` (dof 1, its own `p_fa`).
    pub fn new(
        config: ChannelMonitorConfig,
        policy: crate::detect::PolicyConfig,
        spec: crate::detect::ThresholdSpec,
    ) -> Result<Self, BuildError> {
        let tests: Vec<(&str, u32)> = config
            .channels
            .iter()
            .map(|c| (&*c.name, c.dim as u32))
            .collect();
        let mut bank = TestBank::new(&tests, spec, policy)?;
        let mut channels = Vec::with_capacity(config.channels.len());
        for (i, c) in config.channels.into_iter().enumerate() {
            let drift = match &c.drift {
                Some(_) => Some(bank.add_test(&c.drift_name(), c.dim as u32, None)?),
                None => None,
            };
            let stuck = match &c.stuck {
                Some(s) => {
                    Some(bank.add_test(&c.stuck_name(), 1, Some(ThresholdSpec::PFa(s.p_fa)))?)
                }
                None => None,
            };
            let tests = TestIndices {
                main: i,
                stuck,
                drift,
            };
            let state = ChannelState::new(c, tests).map_err(|e| {
                BuildError::Config(learn_field(&format!("channels[{i}].predictor.online"), e))
            })?;
            channels.push(state);
        }
        Ok(ChannelMonitor { channels, bank })
    }
}

/// One channel's pending changes, applied once every channel's step has succeeded.
struct Pending {
    channel: usize,
    /// The value entering the history.
    value: Vec<f64>,
    /// The raw value, for the stuck test.
    raw: Vec<f64>,
    /// Online windows with the sample learned (None: keep the current ones).
    windows: Option<Vec<OnlineLsSvm>>,
    /// Filters after filtering (None: restart them when the channel is not healthy).
    filters: Option<Vec<OutlierFilter>>,
    /// The residual as the tests see it (over its predictive scale when that is on), when
    /// the predictor's residuals are tested.
    residual: Option<Vec<f64>>,
    /// Every test of the channel was healthy this epoch.
    healthy: bool,
    /// This epoch teaches the channel (healthy and past the guard).
    learn: bool,
    /// The predictor learns this epoch although the channel does not teach (the freeze
    /// has lasted `max_freeze` epochs).
    forced: bool,
    /// Policy states of the tests that ran.
    policies: Vec<(usize, PolicyState)>,
    /// The main test's normalised residual and health, for the consistency diagnostics.
    observed: Option<(Vec<f64>, Health)>,
}

/// The predictor's part of one epoch ([`ChannelState::residual_statistics`]).
#[derive(Default)]
struct ResidualStatistics {
    /// The residual kept for the commit (once the channel is ready).
    residual: Option<Vec<f64>>,
    /// The main test's statistic (`None`: it does not run this epoch).
    main: Option<f64>,
    /// The drift test's statistic (`None`: no drift test, or it does not run).
    drift: Option<f64>,
}

/// What one epoch reports besides the channels' pending changes: the tests that ran and
/// the `prediction` and `residual` outputs, by channel name.
#[derive(Default)]
struct StepReport {
    tests: Vec<TestOutcome>,
    prediction: BTreeMap<TestName, Vec<f64>>,
    residual: BTreeMap<TestName, Vec<f64>>,
}

impl ChannelState {
    /// The channel's value in `epoch`, when present.
    fn value_in<'e>(&self, epoch: &'e Epoch) -> Option<&'e Vec<f64>> {
        epoch
            .channels
            .iter()
            .flatten()
            .find(|(n, _)| **n == *self.config.name)
            .map(|(_, v)| v)
    }

    /// Previews test `index` with `value` (when it runs) and returns its health this
    /// epoch: the new one, or the current one for a test that does not run.
    fn run_test(
        index: usize,
        value: Option<f64>,
        dof: u32,
        bank: &TestBank,
        report: &mut StepReport,
        policies: &mut Vec<(usize, PolicyState)>,
    ) -> Result<Health, StepError> {
        let Some(value) = value else {
            return Ok(bank.slots()[index].policy.health());
        };
        let (outcome, state) = bank.preview(index, value, dof)?;
        let health = outcome.decision.health;
        report.tests.push(outcome);
        policies.push((index, state));
        Ok(health)
    }

    /// One epoch of the channel (module doc) with value `y`, without changing anything:
    /// ŷ_k from the history, `r_k = y_k − ŷ_k` tested by the main and drift tests, `y_k`
    /// by the stuck test, each under the policy, and what the commit will learn. The
    /// tests and the outputs go to `report`.
    fn step(
        &self,
        channel: usize,
        y: &[f64],
        bank: &TestBank,
        report: &mut StepReport,
    ) -> Result<Pending, StepError> {
        let dim = self.config.dim;
        if y.len() != dim {
            return Err(StepError::Filter(FilterError::Dimension {
                what: "channel value",
                got_rows: y.len(),
                got_cols: 1,
                want_rows: dim,
                want_cols: 1,
            }));
        }
        let x = self.input();
        let ResidualStatistics {
            residual,
            main: main_value,
            drift: drift_value,
        } = self.residual_statistics(x.as_deref(), y, report)?;
        let stuck_value = self.stuck_statistic(y)?;
        let mut policies = Vec::new();
        let t = self.tests;
        let main_health =
            Self::run_test(t.main, main_value, dim as u32, bank, report, &mut policies)?;
        let mut healthy = main_health == Health::Healthy;
        if let Some(i) = t.drift {
            let h = Self::run_test(i, drift_value, dim as u32, bank, report, &mut policies)?;
            healthy &= h == Health::Healthy;
        }
        if let Some(i) = t.stuck {
            let h = Self::run_test(i, stuck_value, 1, bank, report, &mut policies)?;
            healthy &= h == Health::Healthy;
        }
        let learn = healthy && self.quiet >= self.config.guard;
        let max_freeze = self.config.max_freeze;
        // Only an online predictor relearns: a stored model does not go stale, and its
        // variances must not absorb a lasting fault.
        let online = matches!(self.predictor, Predictor::Online(_));
        let forced =
            online && !learn && max_freeze > 0 && (self.relearning || self.frozen >= max_freeze);
        let observed = match (&residual, main_value) {
            (Some(r), Some(_)) => self.main.normalise(r).map(|nu| (nu, main_health)),
            _ => None,
        };
        let (value, filters) = self.history_value(y, healthy);
        let windows = self.learned_windows(x.as_deref(), &value, learn || forced)?;
        Ok(Pending {
            channel,
            value,
            raw: y.to_vec(),
            windows,
            filters,
            residual,
            healthy,
            learn,
            forced,
            policies,
            observed,
        })
    }

    /// The predictor's part of an epoch with value `y`: ŷ_k from the history's input
    /// `x` (none before the history is long enough), then, once the channel is ready,
    /// `r_k = y_k − ŷ_k` and the main and drift tests' statistics of it. The
    /// `prediction` and `residual` outputs go to `report`.
    fn residual_statistics(
        &self,
        x: Option<&[f64]>,
        y: &[f64],
        report: &mut StepReport,
    ) -> Result<ResidualStatistics, StepError> {
        let Some((yhat, scale)) = x.and_then(|x| self.predict(x)) else {
            return Ok(ResidualStatistics::default());
        };
        if yhat.iter().chain(&scale).any(|v| !v.is_finite()) {
            return Err(StepError::Filter(FilterError::NonFinite(
                "channel prediction",
            )));
        }
        let r: Vec<f64> = y.iter().zip(&yhat).map(|(a, b)| a - b).collect();
        // What the tests see: the residual over its predictive scale (1 when raw).
        let tested: Vec<f64> = r.iter().zip(&scale).map(|(r, s)| r / s).collect();
        let (mut residual, mut main_value, mut drift_value) = (None, None, None);
        if self.ready() {
            main_value = self.main.evaluate(&tested)?;
            if let Some(d) = &self.drift {
                drift_value = match d.evaluate(&tested) {
                    Ok(v) => v.map(|v| v.value),
                    Err(WindowError::Singular) => None,
                    Err(_) => {
                        return Err(StepError::Filter(FilterError::NonFinite(
                            "channel residual",
                        )));
                    }
                };
            }
            residual = Some(tested);
        }
        report.prediction.insert(self.config.name.clone(), yhat);
        report.residual.insert(self.config.name.clone(), r);
        Ok(ResidualStatistics {
            residual,
            main: main_value,
            drift: drift_value,
        })
    }

    /// The stuck test's statistic of the value `y` itself (`None`: no stuck test, or
    /// none yet).
    fn stuck_statistic(&self, y: &[f64]) -> Result<Option<f64>, StepError> {
        match &self.stuck {
            Some(s) => match s.evaluate(y) {
                Ok(v) => Ok(v.map(|v| v.value)),
                Err(StuckError::NonFinite | StuckError::Dimension { .. }) => {
                    Err(StepError::Filter(FilterError::NonFinite("channel value")))
                }
            },
            None => Ok(None),
        }
    }

    /// What enters the history (module doc): the measurement, through the outlier filter
    /// while healthy, with the filters after filtering (`None`: none ran).
    fn history_value(&self, y: &[f64], healthy: bool) -> (Vec<f64>, Option<Vec<OutlierFilter>>) {
        match (&self.filters, healthy) {
            (Some(f), true) => {
                let mut f = f.clone();
                let v = y
                    .iter()
                    .zip(f.iter_mut())
                    .map(|(&v, f)| f.filter(v).0)
                    .collect();
                (v, Some(f))
            }
            _ => (y.to_vec(), None),
        }
    }

    /// The online windows with the sample `(x, value)` learned, when the epoch teaches
    /// and the history gives an input (`None`: keep the current windows).
    fn learned_windows(
        &self,
        x: Option<&[f64]>,
        value: &[f64],
        learn: bool,
    ) -> Result<Option<Vec<OnlineLsSvm>>, StepError> {
        match (&self.predictor, x, learn) {
            (Predictor::Online(w), Some(x), true) => {
                let mut w = w.clone();
                for (win, &v) in w.iter_mut().zip(value) {
                    win.push(x, v)
                        .map_err(|_| StepError::Filter(FilterError::NotPositiveDefinite))?;
                }
                Ok(Some(w))
            }
            _ => Ok(None),
        }
    }

    /// Applies the channel's pending changes: the policy states, the consistency
    /// diagnostics, the tests' windows and variances, the learned windows, the outlier
    /// filters (restarted when the channel leaves healthy), the guard count and the
    /// history.
    fn commit(&mut self, p: Pending, bank: &mut TestBank) {
        for (index, state) in p.policies {
            bank.commit(index, state);
        }
        if let Some((nu, health)) = &p.observed {
            bank.observe(self.tests.main, nu, *health);
        }
        if let Some(r) = &p.residual {
            // A forced relearn re-baselines the variances too (module doc).
            let learn = p.learn || p.forced;
            self.main.commit(r, learn);
            if let Some(d) = &mut self.drift {
                // Cannot fail: checked by `evaluate` in the step.
                let _ = d.commit(r, learn);
            }
        }
        if let Some(s) = &mut self.stuck {
            let _ = s.commit(&p.raw, p.learn);
        }
        if let Some(w) = p.windows {
            self.predictor = Predictor::Online(w);
        }
        match (p.filters, self.config.outlier_c) {
            (Some(f), _) => self.filters = Some(f),
            (None, Some(c)) if !p.healthy => {
                self.filters = Some(vec![OutlierFilter::new(c); self.config.dim]);
            }
            _ => {}
        }
        self.quiet = if p.healthy {
            self.quiet.saturating_add(1)
        } else {
            0
        };
        self.frozen = if p.learn {
            0
        } else {
            self.frozen.saturating_add(1)
        };
        self.relearning = !p.healthy && (self.relearning || p.forced);
        if self.history.len() == self.config.embedding {
            self.history.pop_front();
        }
        self.history.push_back(p.value);
    }
}

impl Monitor for ChannelMonitor {
    fn kind(&self) -> MonitorKind {
        MonitorKind::Channel
    }

    fn tests(&self) -> &TestBank {
        &self.bank
    }

    fn tests_mut(&mut self) -> &mut TestBank {
        &mut self.bank
    }

    fn check_epoch(&self, name: &str, epoch: &Epoch) -> Result<(), EpochError> {
        for (cname, value) in epoch.channels.iter().flatten() {
            if let Some(c) = self.channels.iter().find(|c| *c.config.name == **cname) {
                if value.len() != c.config.dim {
                    return Err(EpochError::WrongLength {
                        monitor: name.to_owned(),
                        field: format!("channels.{cname}").into(),
                        got: value.len(),
                        want: c.config.dim,
                    });
                }
            }
        }
        Ok(())
    }

    /// Every channel present in the epoch is stepped without changing anything; only when
    /// all have succeeded are their changes committed.
    fn step(&mut self, epoch: &Epoch) -> Result<MonitorReport, StepError> {
        let mut report = StepReport::default();
        let mut pending = Vec::new();
        for (ci, ch) in self.channels.iter().enumerate() {
            if let Some(y) = ch.value_in(epoch) {
                pending.push(ch.step(ci, y, &self.bank, &mut report)?);
            }
        }
        for p in pending {
            self.channels[p.channel].commit(p, &mut self.bank);
        }
        Ok(MonitorReport {
            tests: report.tests,
            outputs: Outputs::Channel {
                prediction: report.prediction,
                residual: report.residual,
            },
            integrity: None,
        })
    }

    fn checkpoint(&self) -> Result<Vec<u8>, CheckpointError> {
        self.save()
    }

    /// Checks every channel's state (in config order) and the tests against this monitor's
    /// before anything is replaced.
    fn restore(&mut self, bytes: &[u8]) -> Result<(), CheckpointError> {
        self.load(bytes)
    }

    fn reset(&mut self) {
        for ch in &mut self.channels {
            // The variance factors derive from the stored models, which a reset keeps.
            let terms = ch.terms.clone();
            if let Ok(fresh) = ChannelState::with_terms(ch.config.clone(), ch.tests, terms) {
                *ch = fresh;
            }
        }
        self.bank.reset();
    }
}

/// Builds a `channel` monitor from its spec, resolving stored models in `models`.
pub fn build(
    wire: &ChannelConfigWire,
    policy: crate::detect::PolicyConfig,
    threshold: crate::detect::ThresholdSpec,
    models: &dyn ModelSource,
) -> Result<Box<dyn Monitor>, BuildError> {
    let config = ChannelMonitorConfig::from_wire(wire, models)?;
    Ok(Box::new(ChannelMonitor::new(config, policy, threshold)?))
}
