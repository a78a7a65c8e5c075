//! The `channel` monitor (docs/methods.md §M14, seeds 000 and 001): each named channel of the
//! epoch (`channels {name: value}`, a filter innovation or a measurement difference such
//! as GNSS minus barometric height) is predicted by an LS-SVM from its own past, and the
//! prediction residual is tested with T_a ([`crate::detect::ta`]). One test per channel,
//! named after it. Sits between the session actor and `learn/` + `detect/`.
//!
//! Config:
//! ```json
//! {"channels": [
//!   {"name": "dh", "dim": 1, "embedding": 5,
//!    "predictor": {"model": "m-0123456789abcdef"},
//!    "outlier_filter": {"c": 3}, "n": 10, "min_differences": 10},
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
//!   are tested — and feed T_a's variance — once the window is full: before that they
//!   measure the model's learning, not the channel's noise).
//! - `outlier_filter` (optional, seed 001 §2.2.1): values entering the predictor's history
//!   and window pass the third-difference filter first (the residual and the test always
//!   use the raw value, so a fault cannot be filtered away).
//! - `n`, `min_differences`: T_a's window and warm-up ([`TaParams`]).
//!
//! Per epoch and channel: ŷ_k from the history, `r_k = y_k − ŷ_k`, T_a, the policy. While
//! the channel's decision is **not healthy** nothing is learned from it: no sample enters
//! the online window (it keeps the model of the healthy past), T_a's V is frozen, and the
//! outlier filter is bypassed (it restarts on the return to healthy). The measured value
//! still enters the embedding history: feeding the prediction back instead (free-running
//! through the fault) was tried and deadlocks — once the free-run drifts from the signal
//! the residual stays large after the fault has ended, the channel never returns to
//! healthy and so never sees real data again. With measured inputs a fault leaves the
//! embedding m epochs after it ends and T_a's window n epochs after that. A channel absent
//! from an epoch skips it. A singular V (a residual that never varies) leaves the test
//! idle that epoch. A prediction that is not finite fails the step (state unchanged).

use std::collections::{BTreeMap, HashSet, VecDeque};
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::{
    BuildError, ConfigError, EpochError, ModelSource, Monitor, MonitorKind, MonitorReport, Outputs,
    StepError, TestBank, TestName, TestOutcome,
};
use crate::detect::{Health, TaError, TaParams, TaStatistic, ta};
use crate::epoch::Epoch;
use crate::filter::kalman::FilterError;
use crate::learn::online::{OnlineLsSvm, OnlineParams};
use crate::learn::outlier::OutlierFilter;
use crate::learn::{AnyModel, LearnError, ModelKind};

/// Default embedding length m (docs/methods.md §M14).
pub const DEFAULT_EMBEDDING: usize = 5;

/// Default outlier-filter factor c (docs/methods.md §M14).
pub const DEFAULT_OUTLIER_C: f64 = 3.0;

/// Longest accepted channel name.
const MAX_NAME: usize = 64;

/// The `config` of a `channel` monitor as the user writes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelConfigWire {
    /// The channels, each with its own test.
    pub channels: Vec<ChannelWire>,
}

/// One channel as the user writes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelWire {
    /// The channel's (and its test's) name.
    pub name: String,
    /// Components of the value (default 1).
    #[serde(default = "one")]
    pub dim: usize,
    /// Embedding length m (default [`DEFAULT_EMBEDDING`]).
    #[serde(default = "default_embedding")]
    pub embedding: usize,
    /// Where predictions come from.
    pub predictor: PredictorWire,
    /// The third-difference outlier filter, when on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outlier_filter: Option<OutlierWire>,
    /// T_a's window (default [`DEFAULT_N`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub n: Option<usize>,
    /// T_a's warm-up.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_differences: Option<usize>,
}

/// `predictor`: `{"model": id | [ids]}` or `{"online": {...}}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PredictorWire {
    /// Stored model ids: one, or one per component.
    Model(ModelIds),
    /// An online sliding-window LS-SVM per component.
    Online(OnlineParams),
}

/// One model id or an array of them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ModelIds {
    /// A single id (scalar channels).
    One(String),
    /// One id per component.
    Many(Vec<String>),
}

/// The outlier filter's settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OutlierWire {
    /// Factor c (default [`DEFAULT_OUTLIER_C`]).
    pub c: f64,
}

impl Default for OutlierWire {
    fn default() -> Self {
        OutlierWire {
            c: DEFAULT_OUTLIER_C,
        }
    }
}

fn one() -> usize {
    1
}
fn default_embedding() -> usize {
    DEFAULT_EMBEDDING
}

/// Where a channel's predictions come from.
#[derive(Debug, Clone)]
pub enum PredictorConfig {
    /// Stored models, one per component.
    Stored(Vec<Arc<AnyModel>>),
    /// An online sliding-window LS-SVM per component.
    Online(OnlineParams),
}

/// One validated channel.
#[derive(Debug, Clone)]
pub struct ChannelConfig {
    /// The channel's (and its test's) name.
    pub name: TestName,
    /// Components of the value.
    pub dim: usize,
    /// Embedding length m.
    pub embedding: usize,
    /// The predictor.
    pub predictor: PredictorConfig,
    /// Outlier-filter factor c, when the filter is on.
    pub outlier_c: Option<f64>,
    /// T_a's parameters.
    pub ta: TaParams,
}

/// A validated `channel` monitor configuration.
#[derive(Debug, Clone)]
pub struct ChannelMonitorConfig {
    /// The channels, in config order.
    pub channels: Vec<ChannelConfig>,
}

fn positive(field: String, v: usize) -> Result<usize, ConfigError> {
    if v == 0 {
        Err(ConfigError::new(field, "must be ≥ 1"))
    } else {
        Ok(v)
    }
}

fn learn_field(prefix: &str, e: LearnError) -> ConfigError {
    match e {
        LearnError::InvalidParams { field, reason } | LearnError::InvalidData { field, reason } => {
            let field = if field.is_empty() {
                prefix.to_owned()
            } else {
                format!("{prefix}.{field}")
            };
            ConfigError::new(field, reason)
        }
        other => ConfigError::new(prefix, other.to_string()),
    }
}

fn parse_predictor(
    at: &str,
    value: &PredictorWire,
    dim: usize,
    embedding: usize,
    models: &dyn ModelSource,
) -> Result<PredictorConfig, BuildError> {
    let field = format!("{at}.predictor");
    if let PredictorWire::Model(ids) = value {
        let field = format!("{field}.model");
        let ids: Vec<&str> = match ids {
            ModelIds::One(s) => vec![s.as_str()],
            ModelIds::Many(a) => a.iter().map(String::as_str).collect(),
        };
        if ids.len() != dim {
            return Err(ConfigError::new(
                field,
                format!(
                    "gives {} model ids, the channel has {dim} components (one model per component)",
                    ids.len()
                ),
            )
            .into());
        }
        let want = dim * embedding;
        let mut out = Vec::with_capacity(dim);
        for (i, id) in ids.iter().enumerate() {
            let f = if dim == 1 {
                field.clone()
            } else {
                format!("{field}[{i}]")
            };
            let model = models.model(id).ok_or_else(|| BuildError::ModelNotFound {
                field: f.clone(),
                id: (*id).to_owned(),
            })?;
            if !matches!(model.kind(), ModelKind::LsSvm | ModelKind::LwLsSvm) {
                return Err(ConfigError::new(
                    &f,
                    format!(
                        "model '{id}' is a {} model, a channel needs lssvm or lw-lssvm",
                        model.kind().as_str()
                    ),
                )
                .into());
            }
            if model.input_dim() != want {
                return Err(ConfigError::new(
                    &f,
                    format!(
                        "model '{id}' takes {} inputs, the channel's embedding has {want} (embedding × dim)",
                        model.input_dim()
                    ),
                )
                .into());
            }
            out.push(model);
        }
        return Ok(PredictorConfig::Stored(out));
    }
    let PredictorWire::Online(params) = value else {
        unreachable!("a predictor is a model or online")
    };
    let field = format!("{field}.online");
    params.check().map_err(|e| learn_field(&field, e))?;
    Ok(PredictorConfig::Online(params.clone()))
}

impl ChannelMonitorConfig {
    /// Parses and validates the `config` JSON, resolving model ids in `models`; errors
    /// name the field path.
    pub fn from_json(
        value: &serde_json::Value,
        models: &dyn ModelSource,
    ) -> Result<Self, BuildError> {
        Self::from_wire(&super::parse_config(value)?, models)
    }

    /// Validates a typed config, resolving model ids in `models` (the model lookup is why
    /// this is not a `TryFrom`).
    pub fn from_wire(
        wire: &ChannelConfigWire,
        models: &dyn ModelSource,
    ) -> Result<Self, BuildError> {
        if wire.channels.is_empty() {
            return Err(ConfigError::new("channels", "must name at least one channel").into());
        }
        let mut seen = HashSet::new();
        let mut channels = Vec::with_capacity(wire.channels.len());
        for (i, c) in wire.channels.iter().enumerate() {
            let at = format!("channels[{i}]");
            if c.name.is_empty() || c.name.len() > MAX_NAME {
                return Err(ConfigError::new(
                    format!("{at}.name"),
                    format!("must have 1 to {MAX_NAME} characters"),
                )
                .into());
            }
            if !seen.insert(c.name.clone()) {
                return Err(ConfigError::new(
                    format!("{at}.name"),
                    format!("'{}' is used twice", c.name),
                )
                .into());
            }
            let dim = positive(format!("{at}.dim"), c.dim)?;
            let embedding = positive(format!("{at}.embedding"), c.embedding)?;
            let predictor = parse_predictor(&at, &c.predictor, dim, embedding, models)?;
            let outlier_c = match c.outlier_filter {
                Some(o) if !(o.c.is_finite() && o.c > 0.0) => {
                    return Err(ConfigError::new(
                        format!("{at}.outlier_filter.c"),
                        "must be finite and > 0",
                    )
                    .into());
                }
                Some(o) => Some(o.c),
                None => None,
            };
            let mut ta = TaParams::new(dim);
            if let Some(n) = c.n {
                ta.n = positive(format!("{at}.n"), n)?;
            }
            if let Some(m) = c.min_differences {
                ta.min_differences = positive(format!("{at}.min_differences"), m)?;
            }
            channels.push(ChannelConfig {
                name: TestName::from(c.name.as_str()),
                dim,
                embedding,
                predictor,
                outlier_c,
                ta,
            });
        }
        Ok(ChannelMonitorConfig { channels })
    }
}

/// The running predictor of one channel.
#[derive(Debug, Clone)]
enum Predictor {
    Stored(Vec<Arc<AnyModel>>),
    Online(Vec<OnlineLsSvm>),
}

/// The state of one channel.
#[derive(Debug, Clone)]
struct ChannelState {
    config: ChannelConfig,
    predictor: Predictor,
    filters: Option<Vec<OutlierFilter>>,
    /// The last m values that entered the history, oldest first.
    history: VecDeque<Vec<f64>>,
    ta: TaStatistic,
    /// Index of the channel's test in the bank.
    test: usize,
}

impl ChannelState {
    fn new(config: ChannelConfig, test: usize) -> Result<Self, LearnError> {
        let predictor = match &config.predictor {
            PredictorConfig::Stored(models) => Predictor::Stored(models.clone()),
            PredictorConfig::Online(p) => Predictor::Online(
                (0..config.dim)
                    .map(|_| OnlineLsSvm::new(p.clone()))
                    .collect::<Result<_, _>>()?,
            ),
        };
        Ok(ChannelState {
            filters: config
                .outlier_c
                .map(|c| vec![OutlierFilter::new(c); config.dim]),
            history: VecDeque::with_capacity(config.embedding),
            ta: TaStatistic::new(config.ta),
            predictor,
            test,
            config,
        })
    }

    /// The embedding `x_k` (m·dim values, oldest first), once the history is full.
    fn input(&self) -> Option<Vec<f64>> {
        (self.history.len() == self.config.embedding)
            .then(|| self.history.iter().flatten().copied().collect())
    }

    /// ŷ_k per component, when the predictor can predict.
    fn predict(&self, x: &[f64]) -> Option<Vec<f64>> {
        match &self.predictor {
            Predictor::Stored(models) => Some(models.iter().map(|m| m.predict_one(x)).collect()),
            Predictor::Online(windows) => windows.iter().map(|w| w.predict(x)).collect(),
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
    /// Builds the monitor from a validated config: one test per channel with dof = dim.
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
        let bank = TestBank::new(&tests, spec, policy)?;
        let channels = config
            .channels
            .into_iter()
            .enumerate()
            .map(|(i, c)| {
                ChannelState::new(c, i).map_err(|e| {
                    BuildError::Config(learn_field(&format!("channels[{i}].predictor.online"), e))
                })
            })
            .collect::<Result<_, _>>()?;
        Ok(ChannelMonitor { channels, bank })
    }
}

/// One channel's pending changes, applied once every channel's step has succeeded.
struct Pending {
    channel: usize,
    /// The value entering the history.
    value: Vec<f64>,
    /// Online windows with the sample learned (None: keep the current ones).
    windows: Option<Vec<OnlineLsSvm>>,
    /// Filters after filtering (None: restart them).
    filters: Option<Vec<OutlierFilter>>,
    residual: Option<(Vec<f64>, bool)>,
    policy: Option<crate::detect::PolicyState>,
}

/// What one epoch reports besides the channels' pending changes: the tests that ran and
/// the `prediction` and `residual` outputs, by channel name.
#[derive(Default)]
struct StepReport {
    tests: Vec<TestOutcome>,
    prediction: BTreeMap<TestName, Vec<f64>>,
    residual: BTreeMap<TestName, Vec<f64>>,
}

/// A test's outcome and its policy's next state, previewed for the commit.
type Preview = (TestOutcome, crate::detect::PolicyState);

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

    /// One epoch of the channel (module doc) with value `y`, without changing anything:
    /// ŷ_k from the history, `r_k = y_k − ŷ_k` tested with T_a under the policy, and what
    /// the commit will learn. The test and the outputs go to `report`.
    fn step(
        &self,
        channel: usize,
        y: &[f64],
        bank: &TestBank,
        report: &mut StepReport,
    ) -> Result<Pending, StepError> {
        if y.len() != self.config.dim {
            return Err(StepError::Filter(FilterError::Dimension {
                what: "channel value",
                got_rows: y.len(),
                got_cols: 1,
                want_rows: self.config.dim,
                want_cols: 1,
            }));
        }
        let x = self.input();
        let yhat = x.as_deref().and_then(|x| self.predict(x));
        let mut health = bank.slots()[self.test].policy.health();
        let mut residual = None;
        let mut policy = None;
        if let Some(yhat) = yhat {
            let (r, ready, test) = self.test_residual(y, &yhat, bank)?;
            if let Some((outcome, state)) = test {
                health = outcome.decision.health;
                report.tests.push(outcome);
                policy = Some(state);
            }
            report.prediction.insert(self.config.name.clone(), yhat);
            report.residual.insert(self.config.name.clone(), r.clone());
            residual = ready.then_some((r, health == Health::Healthy));
        }
        let healthy = health == Health::Healthy;
        let (value, filters) = self.history_value(y, healthy);
        let windows = self.learned_windows(x.as_deref(), &value, healthy)?;
        Ok(Pending {
            channel,
            value,
            windows,
            filters,
            residual,
            policy,
        })
    }

    /// The residual `r = y − ŷ`, whether it is tested (an online window's residuals are,
    /// and feed T_a's V, once the window is full: before that its predictions are still
    /// learning, not the channel's noise), and T_a's outcome previewed under the policy
    /// (`None` in warm-up or with a residual that never varies: the test does not run).
    fn test_residual(
        &self,
        y: &[f64],
        yhat: &[f64],
        bank: &TestBank,
    ) -> Result<(Vec<f64>, bool, Option<Preview>), StepError> {
        if yhat.iter().any(|v| !v.is_finite()) {
            return Err(StepError::Filter(FilterError::NonFinite(
                "channel prediction",
            )));
        }
        let r: Vec<f64> = y.iter().zip(yhat).map(|(a, b)| a - b).collect();
        let ready = match &self.predictor {
            Predictor::Online(w) => w.iter().all(|w| w.len() >= w.params().window),
            Predictor::Stored(_) => true,
        };
        let test = match self.ta.evaluate(&r).map(|t| t.filter(|_| ready)) {
            Ok(Some(t)) => Some(bank.preview(self.test, t, self.config.dim as u32)?),
            Ok(None) | Err(TaError::Singular) => None,
            Err(TaError::NonFinite | TaError::Dimension { .. }) => {
                return Err(StepError::Filter(FilterError::NonFinite(
                    "channel residual",
                )));
            }
        };
        Ok((r, ready, test))
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

    /// The online windows with the sample `(x, value)` learned, while healthy and once the
    /// history gives an input (`None`: keep the current windows).
    fn learned_windows(
        &self,
        x: Option<&[f64]>,
        value: &[f64],
        healthy: bool,
    ) -> Result<Option<Vec<OnlineLsSvm>>, StepError> {
        match (&self.predictor, x, healthy) {
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

    /// Applies the channel's pending changes: its policy state, T_a's window, the learned
    /// windows, the outlier filters (restarted when the channel leaves healthy) and the
    /// history.
    fn commit(&mut self, p: Pending, bank: &mut TestBank) {
        if let Some(state) = p.policy {
            bank.commit(self.test, state);
        }
        if let Some((r, healthy)) = &p.residual {
            // Cannot fail: the residual was checked by `evaluate` in the step.
            let _ = self.ta.commit(r, *healthy);
        }
        if let Some(w) = p.windows {
            self.predictor = Predictor::Online(w);
        }
        match (p.filters, self.config.outlier_c) {
            (Some(f), _) => self.filters = Some(f),
            (None, Some(c)) if p.residual.as_ref().is_some_and(|(_, h)| !h) => {
                self.filters = Some(vec![OutlierFilter::new(c); self.config.dim]);
            }
            _ => {}
        }
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

    fn reset(&mut self) {
        for ch in &mut self.channels {
            if let Ok(fresh) = ChannelState::new(ch.config.clone(), ch.test) {
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

/// T_a's default window, re-exported for the config docs.
pub const DEFAULT_N: usize = ta::DEFAULT_N;

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::*;
    use crate::detect::{PolicyConfig, ThresholdSpec};
    use crate::learn::{Dataset, ModelParams, NoProgress, train};
    use crate::monitor::MonitorSpec;
    use crate::monitor::NoModels;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Normal};
    use serde_json::{Value, json};

    fn spec(config: Value) -> MonitorSpec {
        MonitorSpec {
            kind: MonitorKind::Channel,
            config: crate::monitor::MonitorConfig::parse(MonitorKind::Channel, &config).unwrap(),
            policy: PolicyConfig::Classic,
            threshold: ThresholdSpec::PFa(1e-5),
        }
    }

    fn config_error(config: Value, models: &dyn ModelSource) -> ConfigError {
        let parsed = match crate::monitor::MonitorConfig::parse(MonitorKind::Channel, &config) {
            Ok(p) => p,
            Err(e) => return e,
        };
        let spec = MonitorSpec {
            config: parsed,
            ..spec(json!({"channels": []}))
        };
        match crate::monitor::build(&spec, models) {
            Err(BuildError::Config(e)) => e,
            Err(BuildError::ModelNotFound { field, id }) => {
                ConfigError::new(field, format!("no stored model '{id}'"))
            }
            Err(other) => panic!("expected a config error, got {other:?}"),
            Ok(_) => panic!("expected a config error, got a monitor"),
        }
    }

    /// A sinusoid with white noise of σ = 0.05, plus `step` from sample `at` on.
    fn signal(len: usize, at: usize, step: f64, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        let noise = Normal::new(0.0, 0.05).unwrap();
        (0..len)
            .map(|k| {
                let s =
                    (2.0 * std::f64::consts::PI * k as f64 / 25.0).sin() + noise.sample(&mut rng);
                if k >= at { s + step } else { s }
            })
            .collect()
    }

    fn epoch(k: usize, name: &str, v: Vec<f64>) -> Epoch {
        Epoch {
            t: k as f64,
            channels: Some(vec![(name.to_owned(), v)]),
            ..Default::default()
        }
    }

    /// Runs the series through the monitor; returns the k of every non-healthy epoch.
    fn alarms(monitor: &mut dyn Monitor, series: &[f64]) -> Vec<usize> {
        let mut out = Vec::new();
        for (k, &y) in series.iter().enumerate() {
            let report = monitor.step(&epoch(k, "s", vec![y])).unwrap();
            if report
                .tests
                .iter()
                .any(|t| t.decision.health != Health::Healthy)
            {
                out.push(k);
            }
        }
        out
    }

    fn online_config() -> Value {
        json!({"channels": [{"name": "s", "predictor":
            {"online": {"window": 50, "gamma": 30.0, "sigma2": 9.0, "refresh": 1000}}}]})
    }

    #[test]
    fn config_errors_name_the_field() {
        let e = config_error(json!({}), &NoModels);
        assert!(e.reason.contains("channels"), "{e}");
        let e = config_error(json!({"channels": []}), &NoModels);
        assert_eq!(e.field, "channels");
        let e = config_error(
            json!({"channels": [{"name": "a", "embedding": 0, "predictor": {"model": "x"}}]}),
            &NoModels,
        );
        assert_eq!(e.field, "channels[0].embedding");
        let e = config_error(
            json!({"channels": [{"name": "a", "predictor": {"model": "nope"}}]}),
            &NoModels,
        );
        assert_eq!(e.field, "channels[0].predictor.model");
        assert!(e.reason.contains("nope"), "{e}");
        let e = config_error(
            json!({"channels": [{"name": "a", "dim": 2, "predictor": {"model": "x"}}]}),
            &NoModels,
        );
        assert_eq!(e.field, "channels[0].predictor.model");
        assert!(e.reason.contains("one model per component"), "{e}");
        let e = config_error(
            json!({"channels": [{"name": "a", "predictor": {"kalman": 1}}]}),
            &NoModels,
        );
        assert_eq!(e.field, "channels[0].predictor");
        let mut c = online_config();
        let first = c["channels"][0].clone();
        c["channels"].as_array_mut().unwrap().push(first);
        let e = config_error(c, &NoModels);
        assert_eq!(e.field, "channels[1].name");
        let mut c = online_config();
        c["channels"][0]["outlier_filter"] = json!({"c": -1.0});
        assert_eq!(
            config_error(c, &NoModels).field,
            "channels[0].outlier_filter.c"
        );
        let mut c = online_config();
        c["channels"][0]["n"] = json!(0);
        assert_eq!(config_error(c, &NoModels).field, "channels[0].n");
        let mut c = online_config();
        c["channels"][0]["extra"] = json!(0);
        let e = config_error(c, &NoModels);
        assert!(e.field.starts_with("channels[0]."), "{e}");
        assert!(e.reason.contains("unknown field"), "{e}");
    }

    #[test]
    fn stored_model_of_the_wrong_dimension_is_refused() {
        let (x, y) = embed_series(&signal(120, usize::MAX, 0.0, 1), 3);
        let data = Dataset::new(&x, Some(&y)).unwrap();
        let params =
            ModelParams::from_json(ModelKind::LsSvm, &json!({"gamma": 10.0, "sigma2": 5.0}))
                .unwrap();
        let model = train(&params, None, &data, &NoProgress).unwrap().model;
        let models: HashMap<String, Arc<AnyModel>> =
            HashMap::from([("m3".to_owned(), Arc::new(model))]);
        let e = config_error(
            json!({"channels": [{"name": "s", "embedding": 5, "predictor": {"model": "m3"}}]}),
            &models,
        );
        assert_eq!(e.field, "channels[0].predictor.model");
        assert!(e.reason.contains("takes 3 inputs"), "{e}");
    }

    #[test]
    fn embedding_pairs_the_last_m_values_with_the_next() {
        let (x, y) = embed_series(&[1.0, 2.0, 3.0, 4.0], 2);
        assert_eq!(x, vec![vec![1.0, 2.0], vec![2.0, 3.0]]);
        assert_eq!(y, vec![3.0, 4.0]);
        assert!(embed_series(&[1.0], 2).0.is_empty());
    }

    #[test]
    fn clean_sinusoid_on_an_online_predictor_stays_healthy() {
        let mut m = crate::monitor::build(&spec(online_config()), &NoModels).unwrap();
        let series = signal(500, usize::MAX, 0.0, 2);
        assert_eq!(alarms(m.as_mut(), &series), Vec::<usize>::new());
    }

    #[test]
    fn step_fault_on_an_online_predictor_is_detected_at_once() {
        let mut m = crate::monitor::build(&spec(online_config()), &NoModels).unwrap();
        let series = signal(500, 400, 1.0, 2);
        let a = alarms(m.as_mut(), &series);
        assert!(
            a.first().is_some_and(|&k| (400..=402).contains(&k)),
            "{a:?}"
        );
        // The window did not learn the faulty values: the fault stays flagged.
        assert!(a.contains(&499), "{a:?}");
    }

    #[test]
    fn stored_model_predictor_detects_a_step_and_not_the_clean_signal() {
        let train_series = signal(300, usize::MAX, 0.0, 3);
        let (x, y) = embed_series(&train_series, 5);
        let data = Dataset::new(&x, Some(&y)).unwrap();
        let params =
            ModelParams::from_json(ModelKind::LsSvm, &json!({"gamma": 10.0, "sigma2": 5.0}))
                .unwrap();
        let model = train(&params, None, &data, &NoProgress).unwrap().model;
        let models: HashMap<String, Arc<AnyModel>> =
            HashMap::from([("m".to_owned(), Arc::new(model))]);
        let config = json!({"channels": [{"name": "s", "predictor": {"model": "m"}}]});
        let mut m = crate::monitor::build(&spec(config.clone()), &models).unwrap();
        assert!(alarms(m.as_mut(), &signal(400, usize::MAX, 0.0, 4)).is_empty());
        let mut m = crate::monitor::build(&spec(config), &models).unwrap();
        let a = alarms(m.as_mut(), &signal(400, 300, 1.0, 4));
        assert!(a.first().is_some_and(|&k| (300..303).contains(&k)), "{a:?}");
    }

    #[test]
    fn vector_channel_predicts_each_component_and_checks_its_length() {
        let config = json!({"channels": [{"name": "v", "dim": 2, "embedding": 3, "predictor":
            {"online": {"window": 30, "gamma": 30.0, "sigma2": 9.0}}}]});
        let mut m = crate::monitor::build(&spec(config), &NoModels).unwrap();
        assert_eq!(m.tests().slots()[0].dof, 2);
        let a = signal(60, usize::MAX, 0.0, 5);
        let b = signal(60, usize::MAX, 0.0, 6);
        let mut last = None;
        for k in 0..60 {
            let e = Epoch {
                t: k as f64,
                channels: Some(vec![("v".to_owned(), vec![a[k], 2.0 * b[k]])]),
                ..Default::default()
            };
            m.check_epoch("mon", &e).unwrap();
            last = Some(m.step(&e).unwrap());
        }
        let Some(MonitorReport {
            outputs:
                Outputs::Channel {
                    prediction,
                    residual,
                },
            ..
        }) = last
        else {
            panic!("channel outputs")
        };
        assert_eq!(prediction["v"].len(), 2);
        assert_eq!(residual["v"].len(), 2);
        let bad = epoch(60, "v", vec![1.0]);
        assert!(matches!(
            m.check_epoch("mon", &bad),
            Err(EpochError::WrongLength {
                got: 1,
                want: 2,
                ..
            })
        ));
    }

    #[test]
    fn reset_restarts_predictor_and_test() {
        let mut m = crate::monitor::build(&spec(online_config()), &NoModels).unwrap();
        let series = signal(200, 150, 5.0, 7);
        assert!(!alarms(m.as_mut(), &series).is_empty());
        m.reset();
        assert_eq!(m.tests().slots()[0].policy.health(), Health::Healthy);
        let report = m.step(&epoch(0, "s", vec![0.0])).unwrap();
        assert_eq!(
            report.outputs,
            Outputs::Channel {
                prediction: BTreeMap::new(),
                residual: BTreeMap::new()
            },
            "no prediction before the history is refilled"
        );
        // Other names in the epoch are ignored.
        assert!(
            m.step(&epoch(1, "other", vec![1.0, 2.0]))
                .unwrap()
                .tests
                .is_empty()
        );
    }
}
