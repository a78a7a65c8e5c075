//! Monitors: each wires filters and detectors for one sensor set and yields,
//! per epoch, one `Statistic` and health decision per test plus its outputs.
//! Pure and synchronous; the session actor in `service/session` drives them.

pub mod calibrate;
pub mod channel;
pub mod checkpoint;
pub mod federated;
pub mod gnss;
pub mod guards;
pub mod linear;
pub mod rimu;
pub mod tacan;
pub mod tests_bank;

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

use serde::Serialize;

pub use checkpoint::CheckpointError;
pub use tests_bank::{TestBank, TestName, TestOutcome};

use crate::detect::{PolicyConfig, PolicyError, ThresholdError, ThresholdSpec};
use crate::epoch::Epoch;
use crate::filter::kalman::FilterError;
use crate::learn::AnyModel;

/// The kinds of monitor a session can run (docs/architecture.md §A3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MonitorKind {
    /// A user-supplied linear Gaussian model streaming `z` (docs/methods.md §M2).
    Linear,
    /// Federated INS/GNSS/DVL/CNS filter (docs/methods.md §M6).
    Federated,
    /// LS-SVM channel prediction with T_a (docs/methods.md §M14).
    Channel,
    /// Redundant gyros, parity and SVM isolation (docs/methods.md §M15).
    Rimu,
    /// TACAN range one-class SVM (docs/methods.md §M18).
    Tacan,
    /// GNSS pseudoranges: least squares, RAIM FDE, protection levels (docs/methods.md §M26–§M28).
    Gnss,
}

impl MonitorKind {
    /// The wire name.
    pub fn as_str(self) -> &'static str {
        match self {
            MonitorKind::Linear => "linear",
            MonitorKind::Federated => "federated",
            MonitorKind::Channel => "channel",
            MonitorKind::Rimu => "rimu",
            MonitorKind::Tacan => "tacan",
            MonitorKind::Gnss => "gnss",
        }
    }
}

/// A monitor configuration that cannot run, naming the offending field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {reason}")]
pub struct ConfigError {
    /// Dotted path of the field inside the monitor's `config`, e.g. `q` or `h[1]`.
    pub field: String,
    /// Why it was refused.
    pub reason: String,
}

impl ConfigError {
    /// Builds an error for `field`.
    pub fn new(field: impl Into<String>, reason: impl Into<String>) -> Self {
        ConfigError {
            field: field.into(),
            reason: reason.into(),
        }
    }
}

/// An epoch a monitor cannot consume; the epoch is refused before any state changes.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EpochError {
    /// A vector has the wrong number of elements for the monitor's model.
    #[error("{field} has {got} elements, monitor '{monitor}' expects {want}")]
    WrongLength {
        /// The monitor's name.
        monitor: String,
        /// The epoch field (`z`, `u`, `channels.<name>`, …).
        field: Cow<'static, str>,
        /// Elements received.
        got: usize,
        /// Elements expected.
        want: usize,
    },
    /// The epoch carries an input no monitor of the session can use.
    #[error("{0}")]
    UnknownInput(String),
}

/// A step that failed numerically; the monitor's state is left as it was.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StepError {
    /// The filter could not proceed (indefinite S, non-finite values).
    #[error("filter: {0}")]
    Filter(#[from] FilterError),
    /// A threshold could not be evaluated.
    #[error("threshold: {0}")]
    Threshold(#[from] ThresholdError),
}

/// Outputs a monitor adds beside its tests in the `result` frame (docs/architecture.md §A6).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Outputs {
    /// `linear`: the innovation (absent on epochs without `z`) and the state.
    Linear {
        /// r = z − H x⁻.
        innovation: Option<Vec<f64>>,
        /// Posterior state estimate.
        x: Vec<f64>,
    },
    /// `federated`: the corrected solution and the HPL (both absent before the first INS
    /// epoch) and the aids whose tests are isolated.
    Federated {
        /// INS minus the fused error: lat, lon in degrees, h in m, vel ENU in m/s.
        solution: Option<federated::FederatedSolution>,
        /// Horizontal protection level, m (docs/methods.md §M7).
        hpl: Option<f64>,
        /// Names of the aids currently isolated.
        isolated: Vec<&'static str>,
        /// With `input: imu`, the strapdown alignment state (docs/methods.md §M31).
        #[serde(skip_serializing_if = "Option::is_none")]
        alignment: Option<federated::Alignment>,
    },
    /// `channel`: per channel, the prediction ŷ_k and the residual r_k = y_k − ŷ_k
    /// (a channel appears once its predictor has enough history).
    Channel {
        /// ŷ_k per channel name (scalar channels give one element).
        prediction: BTreeMap<TestName, Vec<f64>>,
        /// r_k per channel name.
        residual: BTreeMap<TestName, Vec<f64>>,
    },
    /// `rimu`: the parity vector, the gyros the classifier flagged at the last
    /// detection, the gyros isolated, and ω from the healthy gyros (rad/s, body).
    Rimu {
        /// Parity residual `V v` (absent on epochs without `gyros`).
        parity: Option<Vec<f64>>,
        /// Gyro indices (0-based) flagged by the classifier at the last detection.
        flagged: Vec<usize>,
        /// Gyro indices (0-based) isolated.
        isolated: Vec<usize>,
        /// Angular rate by least squares over the healthy gyros, rad/s.
        omega: Option<[f64; 3]>,
    },
    /// `tacan`: the window's feature vector (standardised as the model sees it) and the
    /// one-class decision value (≥ 0 normal), once the window is full.
    Tacan {
        /// Feature vector `X = |X_ins − X_tacan|`, standardised.
        features: Option<Vec<f64>>,
        /// One-class decision value.
        decision: Option<f64>,
    },
    /// `gnss`: the fix, its DOPs and protection levels, and every satellite
    /// (shared with the statistics' snapshot, so a step copies no satellite list).
    Gnss(Arc<gnss::GnssOutputs>),
}

/// Whether a monitor's solution can be trusted to its protection level
/// (docs/methods.md §M7): a state of the solution, not a fault of a sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Availability {
    /// The filter is still converging from its initial covariance: the protection level
    /// is not yet below the alert limit for the first time. Nothing raises a fault alarm.
    Converging,
    /// Protection level within the alert limit.
    Available,
    /// Protection level above the alert limit: integrity is not available this epoch.
    Unavailable,
}

impl Availability {
    /// The wire name.
    pub fn as_str(self) -> &'static str {
        match self {
            Availability::Converging => "converging",
            Availability::Available => "available",
            Availability::Unavailable => "unavailable",
        }
    }
}

/// A monitor's integrity this epoch: its protection level against its alert limit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Integrity {
    /// Available, unavailable or still converging.
    pub state: Availability,
    /// The protection level, m.
    pub protection_level: f64,
    /// The alert limit, m.
    pub alert_limit: f64,
}

/// What one monitor yields for one epoch.
#[derive(Debug, Clone, PartialEq)]
pub struct MonitorReport {
    /// The tests that ran this epoch (a test without data does not run).
    pub tests: Vec<TestOutcome>,
    /// The monitor's outputs.
    pub outputs: Outputs,
    /// Integrity availability, for monitors with a protection level (`federated`).
    pub integrity: Option<Integrity>,
}

/// A monitor: a model and its tests, stepped once per epoch.
pub trait Monitor: Send {
    /// The monitor kind.
    fn kind(&self) -> MonitorKind;

    /// The monitor's tests, thresholds and policies.
    fn tests(&self) -> &TestBank;

    /// Mutable access to the tests, for live threshold and policy changes.
    fn tests_mut(&mut self) -> &mut TestBank;

    /// Checks that `epoch` fits the monitor (vector lengths and the like)
    /// without changing any state.
    fn check_epoch(&self, name: &str, epoch: &Epoch) -> Result<(), EpochError>;

    /// Consumes one epoch. On `Err` the monitor's state is unchanged.
    fn step(&mut self, epoch: &Epoch) -> Result<MonitorReport, StepError>;

    /// Restarts the filter state from the configured initial conditions
    /// (a new stream) and the policies from their initial counters.
    fn reset(&mut self);

    /// The monitor's evolving state (filters, detectors, policies and their counters, test
    /// health), as bytes for a checkpoint (docs/architecture.md §A14).
    fn checkpoint(&self) -> Result<Vec<u8>, CheckpointError>;

    /// Replaces the evolving state with one saved by [`Monitor::checkpoint`] on a monitor
    /// built from the same spec. On `Err` the monitor is unchanged.
    ///
    /// The tests' thresholds and policies are the checkpoint's ([`TestBank::restored`]):
    /// re-apply through [`Monitor::tests_mut`] any change made after the checkpoint.
    fn restore(&mut self, bytes: &[u8]) -> Result<(), CheckpointError>;
}

/// Deserialises a monitor's `config` into its typed form, keeping the path of the field
/// at fault (`q[1][0]`, `gnss.pos_sigma_m`, `channels[0].predictor`; empty for the
/// config itself, e.g. a missing required field).
pub fn parse_config<T: serde::de::DeserializeOwned>(
    value: &serde_json::Value,
) -> Result<T, ConfigError> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        let field = config_path(e.path());
        ConfigError::new(field, e.into_inner().to_string())
    })
}

/// A serde path as a config field: `a.b[1]`, or empty at the root.
fn config_path(path: &serde_path_to_error::Path) -> String {
    let mut out = String::new();
    for segment in path.iter() {
        match segment {
            serde_path_to_error::Segment::Seq { index } => {
                out.push_str(&format!("[{index}]"));
            }
            serde_path_to_error::Segment::Map { key } => {
                if !out.is_empty() {
                    out.push('.');
                }
                out.push_str(key);
            }
            serde_path_to_error::Segment::Enum { variant } => {
                if !out.is_empty() {
                    out.push('.');
                }
                out.push_str(variant);
            }
            serde_path_to_error::Segment::Unknown => {}
        }
    }
    out
}

/// A monitor's configuration, typed by kind (each variant is the kind's user-facing
/// config; the monitor validates it with `TryFrom` when it is built).
// The federated config is the largest by far; a config is built once per monitor and
// never moved in a hot path, so boxing would only add noise at every match.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum MonitorConfig {
    /// `linear`.
    Linear(linear::LinearConfigWire),
    /// `federated`.
    Federated(federated::FederatedConfigWire),
    /// `channel`.
    Channel(channel::ChannelConfigWire),
    /// `rimu`.
    Rimu(rimu::RimuConfigWire),
    /// `tacan`.
    Tacan(tacan::TacanConfigWire),
    /// `gnss`.
    Gnss(gnss::GnssConfigWire),
}

impl MonitorConfig {
    /// Parses the `config` JSON of a monitor of `kind`; errors name the field path.
    pub fn parse(kind: MonitorKind, value: &serde_json::Value) -> Result<Self, ConfigError> {
        Ok(match kind {
            MonitorKind::Linear => MonitorConfig::Linear(parse_config(value)?),
            MonitorKind::Federated => MonitorConfig::Federated(parse_config(value)?),
            MonitorKind::Channel => MonitorConfig::Channel(parse_config(value)?),
            MonitorKind::Rimu => MonitorConfig::Rimu(parse_config(value)?),
            MonitorKind::Tacan => MonitorConfig::Tacan(parse_config(value)?),
            MonitorKind::Gnss => MonitorConfig::Gnss(parse_config(value)?),
        })
    }

    /// The kind this config is for.
    pub fn kind(&self) -> MonitorKind {
        match self {
            MonitorConfig::Linear(_) => MonitorKind::Linear,
            MonitorConfig::Federated(_) => MonitorKind::Federated,
            MonitorConfig::Channel(_) => MonitorKind::Channel,
            MonitorConfig::Rimu(_) => MonitorKind::Rimu,
            MonitorConfig::Tacan(_) => MonitorKind::Tacan,
            MonitorConfig::Gnss(_) => MonitorKind::Gnss,
        }
    }
}

/// Everything needed to build a monitor.
#[derive(Debug, Clone)]
pub struct MonitorSpec {
    /// Monitor kind.
    pub kind: MonitorKind,
    /// The kind's configuration.
    pub config: MonitorConfig,
    /// Decision policy for every test of the monitor.
    pub policy: PolicyConfig,
    /// Threshold for every test of the monitor.
    pub threshold: ThresholdSpec,
}

/// Why a monitor could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BuildError {
    /// The `config` is invalid.
    #[error("config.{0}")]
    Config(#[from] ConfigError),
    /// The policy is invalid.
    #[error("policy: {0}")]
    Policy(#[from] PolicyError),
    /// The threshold is invalid.
    #[error("threshold: {0}")]
    Threshold(#[from] ThresholdError),
    /// `config.<field>` names a model the [`ModelSource`] does not hold (never stored,
    /// or deleted since).
    #[error("config.{field}: no stored model '{id}'")]
    ModelNotFound {
        /// Path of the field inside `config`, e.g. `model` or `channels[0].predictor.model`.
        field: String,
        /// The id asked for.
        id: String,
    },
    /// The kind exists in the design but is not available in this build.
    #[error("monitor type '{0}' is not implemented yet")]
    Unsupported(&'static str),
}

/// Where monitors find trained models by id (`config.model`). The service passes its
/// model cache; library users can pass a `HashMap` or [`NoModels`].
pub trait ModelSource {
    /// The model stored under `id`, if any.
    fn model(&self, id: &str) -> Option<Arc<AnyModel>>;
}

/// A [`ModelSource`] with no models.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoModels;

impl ModelSource for NoModels {
    fn model(&self, _id: &str) -> Option<Arc<AnyModel>> {
        None
    }
}

impl ModelSource for HashMap<String, Arc<AnyModel>> {
    fn model(&self, id: &str) -> Option<Arc<AnyModel>> {
        self.get(id).cloned()
    }
}

/// Builds a monitor from its spec, validating everything first. Monitors that use a
/// trained model (`channel`, `rimu`, `tacan`) look it up in `models`.
pub fn build(spec: &MonitorSpec, models: &dyn ModelSource) -> Result<Box<dyn Monitor>, BuildError> {
    spec.policy.check()?;
    spec.threshold.check()?;
    let (policy, threshold) = (spec.policy, spec.threshold);
    if spec.config.kind() != spec.kind {
        return Err(BuildError::Config(ConfigError::new(
            "",
            format!(
                "is a {} config, the monitor is {}",
                spec.config.kind().as_str(),
                spec.kind.as_str()
            ),
        )));
    }
    match &spec.config {
        MonitorConfig::Linear(c) => {
            let config = linear::LinearConfig::try_from(c.clone())?;
            Ok(Box::new(linear::LinearMonitor::new(
                config, policy, threshold,
            )?))
        }
        MonitorConfig::Federated(c) => {
            let config = federated::FederatedConfig::try_from(c.clone())?;
            Ok(Box::new(federated::FederatedMonitor::new(
                config, policy, threshold,
            )?))
        }
        MonitorConfig::Channel(c) => channel::build(c, policy, threshold, models),
        MonitorConfig::Rimu(c) => rimu::build(c, policy, threshold, models),
        MonitorConfig::Tacan(c) => tacan::build(c, policy, threshold, models),
        MonitorConfig::Gnss(c) => gnss::build(c, policy, threshold),
    }
}
