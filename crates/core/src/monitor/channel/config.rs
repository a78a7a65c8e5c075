//! The `channel` monitor's config: the wire form a user writes (`ChannelConfigWire`,
//! serde, `deny_unknown_fields`) and its validation into domain values
//! ([`ChannelMonitorConfig`]), every refusal a [`ConfigError`] naming the exact path
//! inside `config` (`channels[0].stuck.k`). docs/methods.md §M14 lists the fields and
//! their defaults; stored sessions written before a field existed load with its default.

use std::collections::HashSet;
use std::fmt;
use std::marker::PhantomData;
use std::sync::Arc;

use serde::de::{self, MapAccess, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::super::{BuildError, ConfigError, ModelSource, TestName};
use crate::detect::stuck::{self, StuckParams};
use crate::detect::window::{self, WindowParams};
use crate::detect::{TaParams, ta};
use crate::learn::online::OnlineParams;
use crate::learn::{AnyModel, LearnError, ModelKind};

/// Default embedding length m (docs/methods.md §M14).
pub const DEFAULT_EMBEDDING: usize = 5;

/// Default outlier-filter factor c (docs/methods.md §M14).
pub const DEFAULT_OUTLIER_C: f64 = 3.0;

/// Default guard: epochs after the channel's last non-healthy epoch during which nothing
/// is learned from it (docs/methods.md §M14; measured on seed 001 in docs/experiments.md).
pub const DEFAULT_GUARD: usize = 0;

/// Default longest freeze of an online predictor before it learns again (docs/methods.md
/// §M14): a fault lasting longer is learned, after it has been flagged for this long.
pub const DEFAULT_MAX_FREEZE: usize = 20;

/// Default drift windows (docs/methods.md §M14: justified by seed 000's ramps).
pub const DEFAULT_DRIFT_WINDOWS: [usize; 2] = [30, 60];

/// Longest accepted channel name.
const MAX_NAME: usize = 64;
/// Longest accepted window, block count, stuck window or guard, epochs.
const MAX_EPOCHS: usize = 100_000;
/// Most healthy residuals a batch-means test may remember per scale (blocks × window):
/// the short scale of the equal-memory test keeps one block per epoch of that memory.
const MAX_MEMORY: usize = 100_000;
/// Most drift windows.
const MAX_DRIFT_WINDOWS: usize = 8;

/// The `config` of a `channel` monitor as the user writes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelConfigWire {
    /// The channels, each with its own tests.
    pub channels: Vec<ChannelWire>,
}

/// One channel as the user writes it. Fields added after the first release are
/// optional and absent from a stored spec written before them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelWire {
    /// The channel's (and its main test's) name.
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
    /// T_a's window, epochs (default [`DEFAULT_N`]): the long scale of the batch-means
    /// test, or the successive-difference T_a's window.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub n: Option<usize>,
    /// Warm-up of the successive-difference variance, differences (ignored under
    /// batch means, so stored specs that set it still load).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_differences: Option<usize>,
    /// How T_a's variance is estimated (default `batch_means`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub variance: Option<VarianceKind>,
    /// Batch means: healthy blocks of the long window before the test reports (default
    /// [`window::DEFAULT_MIN_BLOCKS`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_blocks: Option<usize>,
    /// Batch means: blocks of the long window remembered (default
    /// [`window::DEFAULT_MAX_BLOCKS`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_blocks: Option<usize>,
    /// The `<name>.stuck` test: `true`/absent (defaults), `false`, or its settings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stuck: Option<Toggle<StuckWire>>,
    /// The `<name>.drift` test: absent/`false` (off), `true` (defaults) or its settings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drift: Option<Toggle<DriftWire>>,
    /// Epochs after the channel's last non-healthy epoch during which nothing is
    /// learned (default [`DEFAULT_GUARD`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub guard: Option<usize>,
    /// Epochs an online predictor stays frozen before it learns again although the
    /// channel is not healthy (default [`DEFAULT_MAX_FREEZE`]; 0: never).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_freeze: Option<usize>,
    /// How the residual is scaled before the main and drift tests (default `raw`;
    /// [`ResidualScale`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub residual_scale: Option<ResidualScale>,
}

impl ChannelWire {
    /// A channel with every optional field at its default.
    pub fn new(name: &str, predictor: PredictorWire) -> Self {
        ChannelWire {
            name: name.to_owned(),
            dim: 1,
            embedding: DEFAULT_EMBEDDING,
            predictor,
            outlier_filter: None,
            n: None,
            min_differences: None,
            variance: None,
            min_blocks: None,
            max_blocks: None,
            stuck: None,
            drift: None,
            guard: None,
            max_freeze: None,
            residual_scale: None,
        }
    }
}

/// How T_a's variance is estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VarianceKind {
    /// The variance of the window mean itself, from non-overlapping healthy blocks
    /// (docs/methods.md §M20): calibrated under coloured residuals.
    #[default]
    BatchMeans,
    /// Seed 000 eq. 16's successive-difference variance (docs/methods.md §M14): blind
    /// to slow components, kept so experiments can show both.
    SuccessiveDifference,
}

/// How a channel's residual is scaled before its main and drift tests (docs/methods.md
/// §M14, §M9a).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ResidualScale {
    /// The residual as it is (the default: docs/methods.md §M14 gives the measured
    /// trade-off that keeps it).
    #[default]
    Raw,
    /// Divided by `√(1 + γ m(x))`, the predictive standard deviation over the noise
    /// level (docs/methods.md §M9a): a prediction the model is unsure of (an input far
    /// from what it learned) weighs less. The tests' own healthy variance plays the noise
    /// level `σ_e²`. Ends the self-sustaining bursts of a frozen online window, at the
    /// cost of most of a persistent bias's flagged epochs (docs/methods.md §M14); with a
    /// stored `lssvm` model it costs O(N²) per epoch in the training-set size N.
    Predictive,
}

/// `true`, `false` or an object of settings.
#[derive(Debug, Clone, PartialEq)]
pub enum Toggle<T> {
    /// `true` (the defaults) or `false` (off).
    On(bool),
    /// On, with these settings.
    With(T),
}

impl<T: Default + Clone> Toggle<T> {
    /// The settings when on (`true` gives the defaults).
    pub fn settings(&self) -> Option<T> {
        match self {
            Toggle::On(true) => Some(T::default()),
            Toggle::On(false) => None,
            Toggle::With(t) => Some(t.clone()),
        }
    }
}

impl<T: Serialize> Serialize for Toggle<T> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Toggle::On(b) => s.serialize_bool(*b),
            Toggle::With(t) => t.serialize(s),
        }
    }
}

/// Deserialises a boolean or an object; the object goes through the caller's
/// deserializer, so a bad field inside keeps its path (`channels[0].stuck.k`).
impl<'de, T: Deserialize<'de>> Deserialize<'de> for Toggle<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V<T>(PhantomData<T>);
        impl<'de, T: Deserialize<'de>> Visitor<'de> for V<T> {
            type Value = Toggle<T>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("true, false or an object")
            }
            fn visit_bool<E: de::Error>(self, b: bool) -> Result<Self::Value, E> {
                Ok(Toggle::On(b))
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
                T::deserialize(de::value::MapAccessDeserializer::new(map)).map(Toggle::With)
            }
        }
        d.deserialize_any(V(PhantomData))
    }
}

/// The stuck test's settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StuckWire {
    /// Successive differences in the window (default [`stuck::DEFAULT_K`]).
    pub k: usize,
    /// The test's own false-alarm probability (default [`stuck::DEFAULT_P_FA`]).
    pub p_fa: f64,
}

impl Default for StuckWire {
    fn default() -> Self {
        StuckWire {
            k: stuck::DEFAULT_K,
            p_fa: stuck::DEFAULT_P_FA,
        }
    }
}

/// The drift test's settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DriftWire {
    /// Window lengths, epochs (default [`DEFAULT_DRIFT_WINDOWS`]).
    pub windows: Vec<usize>,
}

impl Default for DriftWire {
    fn default() -> Self {
        DriftWire {
            windows: DEFAULT_DRIFT_WINDOWS.to_vec(),
        }
    }
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

/// T_a's default window, epochs.
pub const DEFAULT_N: usize = ta::DEFAULT_N;

/// Where a channel's predictions come from.
#[derive(Debug, Clone)]
pub enum PredictorConfig {
    /// Stored models, one per component.
    Stored(Vec<Arc<AnyModel>>),
    /// An online sliding-window LS-SVM per component.
    Online(OnlineParams),
}

/// The main test of a channel, validated.
#[derive(Debug, Clone, PartialEq)]
pub enum MainTestConfig {
    /// Batch-means windowed mean over windows 1 and n, equal memory (docs/methods.md §M20).
    BatchMeans(WindowParams),
    /// Seed 000's T_a with the successive-difference variance (docs/methods.md §M14).
    SuccessiveDifference(TaParams),
}

/// The stuck test of a channel, validated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StuckConfig {
    /// The test's parameters.
    pub params: StuckParams,
    /// Its own false-alarm probability.
    pub p_fa: f64,
}

/// One validated channel.
#[derive(Debug, Clone)]
pub struct ChannelConfig {
    /// The channel's (and its main test's) name.
    pub name: TestName,
    /// Components of the value.
    pub dim: usize,
    /// Embedding length m.
    pub embedding: usize,
    /// The predictor.
    pub predictor: PredictorConfig,
    /// Outlier-filter factor c, when the filter is on.
    pub outlier_c: Option<f64>,
    /// The main test (T_a).
    pub main: MainTestConfig,
    /// The `<name>.stuck` test, when on.
    pub stuck: Option<StuckConfig>,
    /// The `<name>.drift` test's windows, when on.
    pub drift: Option<WindowParams>,
    /// Guard after a non-healthy epoch, epochs.
    pub guard: usize,
    /// Longest freeze of an online predictor, epochs (0: no limit).
    pub max_freeze: usize,
    /// How the residual is scaled before the main and drift tests.
    pub residual_scale: ResidualScale,
}

impl ChannelConfig {
    /// The stuck test's name, `<name>.stuck`.
    pub fn stuck_name(&self) -> String {
        format!("{}.stuck", self.name)
    }

    /// The drift test's name, `<name>.drift`.
    pub fn drift_name(&self) -> String {
        format!("{}.drift", self.name)
    }
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

fn in_range(field: String, v: usize, lo: usize, hi: usize) -> Result<usize, ConfigError> {
    if (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(ConfigError::new(field, format!("must be {lo} to {hi}")))
    }
}

pub(super) fn learn_field(prefix: &str, e: LearnError) -> ConfigError {
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

/// The main test from `n`, `variance`, `min_blocks`, `max_blocks` (and, for the old
/// form, `min_differences`).
fn parse_main(at: &str, c: &ChannelWire, dim: usize) -> Result<MainTestConfig, ConfigError> {
    let n = match c.n {
        Some(n) => in_range(format!("{at}.n"), n, 1, MAX_EPOCHS)?,
        None => DEFAULT_N,
    };
    match c.variance.unwrap_or_default() {
        VarianceKind::SuccessiveDifference => {
            for (field, v) in [("min_blocks", c.min_blocks), ("max_blocks", c.max_blocks)] {
                if v.is_some() {
                    return Err(ConfigError::new(
                        format!("{at}.{field}"),
                        "applies to \"variance\": \"batch_means\" only",
                    ));
                }
            }
            let mut ta = TaParams::new(dim);
            ta.n = n;
            if let Some(m) = c.min_differences {
                ta.min_differences = positive(format!("{at}.min_differences"), m)?;
            }
            Ok(MainTestConfig::SuccessiveDifference(ta))
        }
        VarianceKind::BatchMeans => {
            let min_blocks = match c.min_blocks {
                Some(b) => in_range(format!("{at}.min_blocks"), b, dim + 1, MAX_EPOCHS)?,
                None => window::DEFAULT_MIN_BLOCKS.max(dim + 1),
            };
            let max_blocks = match c.max_blocks {
                Some(b) => in_range(format!("{at}.max_blocks"), b, min_blocks, MAX_EPOCHS)?,
                None => window::DEFAULT_MAX_BLOCKS.max(min_blocks),
            };
            if max_blocks.saturating_mul(n) > MAX_MEMORY {
                return Err(ConfigError::new(
                    format!("{at}.max_blocks"),
                    format!(
                        "max_blocks × n = {} residuals remembered, at most {MAX_MEMORY}",
                        max_blocks.saturating_mul(n)
                    ),
                ));
            }
            // Windows 1 and n: a step is judged on its own epoch, a slow change by the
            // mean of n (docs/methods.md §M14).
            let scales = if n == 1 { vec![1] } else { vec![1, n] };
            Ok(MainTestConfig::BatchMeans(WindowParams {
                dim,
                scales,
                max_blocks,
                min_blocks,
            }))
        }
    }
}

fn parse_stuck(at: &str, c: &ChannelWire, dim: usize) -> Result<Option<StuckConfig>, ConfigError> {
    let Some(s) = c.stuck.clone().unwrap_or(Toggle::On(true)).settings() else {
        return Ok(None);
    };
    let k = in_range(format!("{at}.stuck.k"), s.k, 2, MAX_EPOCHS)?;
    if !(s.p_fa > 0.0 && s.p_fa < 1.0) {
        return Err(ConfigError::new(
            format!("{at}.stuck.p_fa"),
            "must lie in (0, 1)",
        ));
    }
    Ok(Some(StuckConfig {
        params: StuckParams {
            k,
            ..StuckParams::new(dim)
        },
        p_fa: s.p_fa,
    }))
}

fn parse_drift(at: &str, c: &ChannelWire, dim: usize) -> Result<Option<WindowParams>, ConfigError> {
    let Some(d) = c.drift.clone().unwrap_or(Toggle::On(false)).settings() else {
        return Ok(None);
    };
    let field = format!("{at}.drift.windows");
    if d.windows.is_empty() || d.windows.len() > MAX_DRIFT_WINDOWS {
        return Err(ConfigError::new(
            field,
            format!("must list 1 to {MAX_DRIFT_WINDOWS} window lengths"),
        ));
    }
    for (i, &w) in d.windows.iter().enumerate() {
        let longest = window::DEFAULT_MAX_BLOCKS.saturating_mul(w);
        if w < 2 || longest > MAX_MEMORY {
            return Err(ConfigError::new(
                format!("{field}[{i}]"),
                format!(
                    "must be 2 to {} epochs",
                    MAX_MEMORY / window::DEFAULT_MAX_BLOCKS
                ),
            ));
        }
    }
    Ok(Some(WindowParams::new(dim, &d.windows)))
}

impl ChannelMonitorConfig {
    /// Parses and validates the `config` JSON, resolving model ids in `models`; errors
    /// name the field path.
    pub fn from_json(
        value: &serde_json::Value,
        models: &dyn ModelSource,
    ) -> Result<Self, BuildError> {
        Self::from_wire(&super::super::parse_config(value)?, models)
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
        let mut channels: Vec<ChannelConfig> = Vec::with_capacity(wire.channels.len());
        for (i, c) in wire.channels.iter().enumerate() {
            let at = format!("channels[{i}]");
            if c.name.is_empty() || c.name.len() > MAX_NAME {
                return Err(ConfigError::new(
                    format!("{at}.name"),
                    format!("must have 1 to {MAX_NAME} characters"),
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
            let guard = match c.guard {
                Some(g) => in_range(format!("{at}.guard"), g, 0, MAX_EPOCHS)?,
                None => DEFAULT_GUARD,
            };
            let max_freeze = match c.max_freeze {
                Some(g) => in_range(format!("{at}.max_freeze"), g, 0, MAX_EPOCHS)?,
                None => DEFAULT_MAX_FREEZE,
            };
            let residual_scale = c.residual_scale.unwrap_or_default();
            channels.push(ChannelConfig {
                name: TestName::from(c.name.as_str()),
                dim,
                embedding,
                predictor,
                outlier_c,
                main: parse_main(&at, c, dim)?,
                stuck: parse_stuck(&at, c, dim)?,
                drift: parse_drift(&at, c, dim)?,
                guard,
                max_freeze,
                residual_scale,
            });
        }
        check_names(&channels)?;
        Ok(ChannelMonitorConfig { channels })
    }
}

/// Every test name (`<name>`, `<name>.stuck`, `<name>.drift`) must be unique; a clash is
/// reported at the later channel's `name`.
fn check_names(channels: &[ChannelConfig]) -> Result<(), ConfigError> {
    let mut seen: HashSet<String> = HashSet::new();
    for (i, c) in channels.iter().enumerate() {
        let mut names = vec![c.name.to_string()];
        names.extend(c.stuck.map(|_| c.stuck_name()));
        names.extend(c.drift.as_ref().map(|_| c.drift_name()));
        for n in names {
            if !seen.insert(n.clone()) {
                let reason = if n == *c.name {
                    format!("'{n}' is used twice")
                } else {
                    format!("its test '{n}' clashes with another test of the monitor")
                };
                return Err(ConfigError::new(format!("channels[{i}].name"), reason));
            }
        }
    }
    Ok(())
}
