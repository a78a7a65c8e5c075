//! The `tacan` monitor (docs/methods.md §M18, seed 003): TACAN slant-range anomalies, found by
//! comparing the measured range with the range the INS position implies, through the
//! window features of [`crate::features::tacan`] and a stored one-class SVM. The
//! session actor steps it once per epoch.
//!
//! # Config
//! `{"station": {"lat": deg, "lon": deg, "h": m}, "window": 10, "crest": false,
//! "model": "<ocsvm id>", "max_gap_s": 1.0}`. `station` and `model` are required;
//! `window` (≥ 2, ≤ [`MAX_WINDOW`]) and `crest` default to the paper's 10 and false;
//! the model must be an `ocsvm` trained on the matching feature dimension (3, or 4
//! with `crest`).
//!
//! # Epochs
//! It runs on epochs that carry both `ins` and `tacan` and ignores the others (no test,
//! last outputs repeated). `d_ins = ‖P_ins − P_station‖` in ECEF (seed 003 eq. 1, the
//! square there is a typo), `d_tacan = range_m`. The pair enters a sliding window of
//! `K` samples (step 1); a gap of more than `max_gap_s` between used epochs empties it
//! (a window must span one contiguous stretch of flight, as in training). Once full,
//! the window's raw features go to the model, which standardises them with the
//! training statistics it stores (`learn`'s `Standardizer`).
//!
//! # The `range` test
//! The one-class decision `g(X)` (≥ 0 inside the boundary: normal; seed 003 eq. 15,
//! `f(z) ≤ R²`, is `g ≥ 0` up to a positive factor) is `s · (m − 1)` where
//! `m = Σ α_k K(sv_k, z) / ρ` is the kernel mass at `z` relative to the boundary's and
//! `s = scale · ρ` the model's decision scale (1 · ρ for ν-OCSVM, 2C · ρ for SVDD).
//! The statistic is
//! `value = T · 1/m = T · s / (g + s)` (capped at `T ·` [`MAX_RATIO`]),
//! `threshold = T`, `dof =` feature dimension, where `T` is the threshold in force.
//! So:
//! - the test fails exactly when the point is outside the boundary (`g < 0 ⇔ m < 1`),
//!   and `test_ratio = 1/m` does not depend on `T`, on ν or on the number of training
//!   samples: 1 on the boundary, below 1 inside, growing as `exp(d²/σ²)` with the
//!   squared distance `d²` outside (the RBF's tail);
//! - the monitor's `p_fa` / `threshold` do **not** move the boundary: it was fixed
//!   when the model was trained (ν, or C = 1/(νN) for SVDD, bounds the training
//!   outlier share, which is the false-alarm rate on normal data). They only set the
//!   scale `T` the statistic is reported in. To make the detector more or less
//!   sensitive, train the model with another ν;
//! - the session's **policy** applies as to any test: classic flags each window
//!   outside the boundary; counters (N1, N2) debounce isolated windows and isolate
//!   the TACAN after more than N2 windows outside.
//!
//! `ρ` and `scale` are read once, at build, from the model; a model with `ρ ≤ 0` (no positive
//! boundary mass, a degenerate training set) falls back to `test_ratio = 1 − g`,
//! which still fails exactly when `g < 0`.
//!
//! # Outputs
//! `features`: the window's feature vector as the model sees it (standardised with
//! the model's training statistics); `decision`: `g`. Both absent until the window
//! is full.

use std::borrow::Cow;
use std::collections::VecDeque;
use std::sync::Arc;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::{
    BuildError, CheckpointError, ConfigError, EpochError, ModelSource, Monitor, MonitorKind,
    MonitorReport, Outputs, StepError, TestBank, checkpoint,
};
use crate::detect::{PolicyConfig, ThresholdSpec};
use crate::epoch::Epoch;
use crate::features::tacan::{TacanFeatureParams, window_features};
use crate::filter::kalman::FilterError;
use crate::geo::{self, Lla};
use crate::learn::{AnyModel, ModelKind, Standardizer};

/// Longest window accepted, samples (40 s at 25 Hz).
pub const MAX_WINDOW: usize = 1000;

/// Cap of the `range` test's ratio `1/m` (far outside the boundary the kernel mass
/// underflows to 0; the statistic stays finite for the wire).
pub const MAX_RATIO: f64 = 1e6;

/// Default largest gap between used epochs that keeps the window, s.
pub const DEFAULT_MAX_GAP_S: f64 = 1.0;

/// The slant range from `p` to a station at ECEF `station_ecef`, m: the ECEF distance.
pub fn slant_range_m(p: &Lla, station_ecef: &Vector3<f64>) -> f64 {
    (geo::lla_to_ecef(p) - station_ecef).norm()
}

/// A validated `tacan` config.
#[derive(Debug, Clone, PartialEq)]
pub struct TacanConfig {
    /// The station, radians and metres.
    pub station: Lla,
    /// Window length and feature selection.
    pub features: TacanFeatureParams,
    /// Id of the stored one-class model.
    pub model: String,
    /// Largest gap between used epochs that keeps the window, s.
    pub max_gap_s: f64,
}

/// The station's position as the user writes it: degrees and metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StationWire {
    /// Latitude, degrees.
    pub lat: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Ellipsoidal height, m.
    pub h: f64,
}

/// The `config` of a `tacan` monitor as the user writes it. `station` and `model` are
/// required (checked by `TryFrom`, so their absence names the field).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TacanConfigWire {
    /// The station.
    pub station: Option<StationWire>,
    /// Window length K (default 10, seed 003).
    pub window: usize,
    /// Add the crest factor to the features (default false).
    pub crest: bool,
    /// Id of the stored `ocsvm` model.
    pub model: Option<String>,
    /// Largest gap between used epochs that keeps the window, s.
    pub max_gap_s: f64,
}

impl Default for TacanConfigWire {
    fn default() -> Self {
        let features = TacanFeatureParams::default();
        TacanConfigWire {
            station: None,
            window: features.window,
            crest: features.crest,
            model: None,
            max_gap_s: DEFAULT_MAX_GAP_S,
        }
    }
}

impl TacanConfig {
    /// Parses and validates the `config` JSON; errors name the field path (`station.lat`,
    /// `window`, `model`, …). The model itself is checked by [`build`].
    pub fn from_json(value: &serde_json::Value) -> Result<Self, ConfigError> {
        Self::try_from(super::parse_config::<TacanConfigWire>(value)?)
    }
}

impl TryFrom<TacanConfigWire> for TacanConfig {
    type Error = ConfigError;

    /// Checks ranges and the required fields.
    fn try_from(w: TacanConfigWire) -> Result<Self, ConfigError> {
        let st = w
            .station
            .ok_or_else(|| ConfigError::new("station", "required: {lat, lon, h}"))?;
        let finite = |field: &str, v: f64| {
            if v.is_finite() {
                Ok(v)
            } else {
                Err(ConfigError::new(field, "must be a finite number"))
            }
        };
        let lat = finite("station.lat", st.lat)?;
        if !(-90.0..=90.0).contains(&lat) {
            return Err(ConfigError::new(
                "station.lat",
                "must be in [−90, 90] degrees",
            ));
        }
        let lon = finite("station.lon", st.lon)?;
        if !(-180.0..=180.0).contains(&lon) {
            return Err(ConfigError::new(
                "station.lon",
                "must be in [−180, 180] degrees",
            ));
        }
        let h = finite("station.h", st.h)?;
        if !(2..=MAX_WINDOW).contains(&w.window) {
            return Err(ConfigError::new(
                "window",
                format!("must be an integer from 2 to {MAX_WINDOW}"),
            ));
        }
        let model = w
            .model
            .ok_or_else(|| ConfigError::new("model", "required: the id of an ocsvm model"))?;
        if !(w.max_gap_s.is_finite() && w.max_gap_s > 0.0) {
            return Err(ConfigError::new("max_gap_s", "must be a finite number > 0"));
        }
        Ok(TacanConfig {
            station: Lla {
                lat: lat.to_radians(),
                lon: lon.to_radians(),
                h,
            },
            features: TacanFeatureParams {
                window: w.window,
                crest: w.crest,
            },
            model,
            max_gap_s: w.max_gap_s,
        })
    }
}

/// Builds a `tacan` monitor from its config, looking its model up in `models`.
pub fn build(
    wire: &TacanConfigWire,
    policy: PolicyConfig,
    threshold: ThresholdSpec,
    models: &dyn ModelSource,
) -> Result<Box<dyn Monitor>, BuildError> {
    let config = TacanConfig::try_from(wire.clone())?;
    let model = models
        .model(&config.model)
        .ok_or_else(|| BuildError::ModelNotFound {
            field: "model".into(),
            id: config.model.clone(),
        })?;
    Ok(Box::new(TacanMonitor::new(
        config, model, policy, threshold,
    )?))
}

/// The `tacan` monitor.
#[derive(Debug, Clone)]
pub struct TacanMonitor {
    config: TacanConfig,
    model: Arc<AnyModel>,
    station_ecef: Vector3<f64>,
    bank: TestBank,
    /// The last `K` pairs `(d_ins, d_tacan)`.
    window: VecDeque<(f64, f64)>,
    last_t: Option<f64>,
    outputs: Outputs,
    /// The model's input standardisation, for the `features` output.
    standardizer: Option<Standardizer>,
    /// The decision scale `s = scale · ρ` when positive (module doc).
    decision_scale: Option<f64>,
}

/// The standardiser and the decision scale `scale · ρ` (when positive) of a one-class
/// model (module doc).
fn model_internals(model: &AnyModel) -> (Option<Standardizer>, Option<f64>) {
    let AnyModel::OcSvm(m) = model else {
        return (None, None);
    };
    let s = m.scale() * m.rho();
    (
        Some(m.standardizer().clone()),
        Some(s).filter(|s| s.is_finite() && *s > 0.0),
    )
}

/// The `range` test's ratio for decision `g` (module doc).
fn ratio(g: f64, decision_scale: Option<f64>) -> f64 {
    match decision_scale {
        Some(s) if g + s > s / MAX_RATIO => s / (g + s),
        Some(_) => MAX_RATIO,
        None => 1.0 - g,
    }
}

impl TacanMonitor {
    /// The decision scale `s = scale · ρ` (module doc), for navguard-sim's tests of this
    /// monitor.
    #[cfg(feature = "test-support")]
    #[doc(hidden)]
    pub fn decision_scale(&self) -> Option<f64> {
        self.decision_scale
    }

    /// The model's input standardisation, for navguard-sim's tests of this monitor.
    #[cfg(feature = "test-support")]
    #[doc(hidden)]
    pub fn standardizer(&self) -> Option<&Standardizer> {
        self.standardizer.as_ref()
    }

    /// Builds the monitor; the model must be an `ocsvm` of the feature dimension.
    pub fn new(
        config: TacanConfig,
        model: Arc<AnyModel>,
        policy: PolicyConfig,
        spec: ThresholdSpec,
    ) -> Result<Self, BuildError> {
        if model.kind() != ModelKind::OcSvm {
            return Err(ConfigError::new(
                "model",
                format!(
                    "'{}' is a {} model, the tacan monitor needs an ocsvm",
                    config.model,
                    model.kind().as_str()
                ),
            )
            .into());
        }
        let dim = config.features.dim();
        if model.input_dim() != dim {
            return Err(ConfigError::new(
                "model",
                format!(
                    "'{}' was trained on {} features, the window gives {dim} (crest = {})",
                    config.model,
                    model.input_dim(),
                    config.features.crest
                ),
            )
            .into());
        }
        let bank = TestBank::new(&[("range", dim as u32)], spec, policy)?;
        let station_ecef = geo::lla_to_ecef(&config.station);
        let window = VecDeque::with_capacity(config.features.window);
        let (standardizer, decision_scale) = model_internals(&model);
        Ok(TacanMonitor {
            standardizer,
            decision_scale,
            config,
            model,
            station_ecef,
            bank,
            window,
            last_t: None,
            outputs: empty(),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &TacanConfig {
        &self.config
    }

    /// The window's features as the model sees them: standardised with the model's
    /// training statistics (raw when the model does not standardise).
    fn model_view(&self, raw: &[f64]) -> Vec<f64> {
        match &self.standardizer {
            Some(s) => s.applied(raw),
            None => raw.to_vec(),
        }
    }
}

/// What a checkpoint of a `tacan` monitor holds (borrowed to write, owned when read): the
/// window of range pairs, the time of the last used epoch, the outputs repeated on epochs
/// it ignores and the test. Not the model: the monitor built from the spec has it.
#[derive(Serialize, Deserialize)]
struct TacanSaved<'a> {
    window: Cow<'a, VecDeque<(f64, f64)>>,
    last_t: Option<f64>,
    features: Option<Cow<'a, [f64]>>,
    decision: Option<f64>,
    bank: Cow<'a, TestBank>,
}

fn empty() -> Outputs {
    Outputs::Tacan {
        features: None,
        decision: None,
    }
}

impl Monitor for TacanMonitor {
    fn kind(&self) -> MonitorKind {
        MonitorKind::Tacan
    }

    fn tests(&self) -> &TestBank {
        &self.bank
    }

    fn tests_mut(&mut self) -> &mut TestBank {
        &mut self.bank
    }

    /// `ins` and `tacan` are validated (finite) at the edge and both optional: nothing
    /// here can make an epoch unusable.
    fn check_epoch(&self, _name: &str, _epoch: &Epoch) -> Result<(), EpochError> {
        Ok(())
    }

    fn step(&mut self, epoch: &Epoch) -> Result<MonitorReport, StepError> {
        let (Some(ins), Some(range)) = (&epoch.ins, epoch.tacan_range_m) else {
            return Ok(MonitorReport {
                tests: Vec::new(),
                outputs: self.outputs.clone(),
                integrity: None,
            });
        };
        let p = Lla {
            lat: ins.lat,
            lon: ins.lon,
            h: ins.h,
        };
        let d_ins = slant_range_m(&p, &self.station_ecef);
        if !(d_ins.is_finite() && range.is_finite()) {
            return Err(FilterError::NonFinite("tacan ranges").into());
        }
        // The candidate window, committed only once the step succeeds.
        let k = self.config.features.window;
        let gap = self
            .last_t
            .is_some_and(|t| !(0.0..=self.config.max_gap_s).contains(&(epoch.t - t)));
        let keep = if gap { 0 } else { self.window.len().min(k - 1) };
        let skip = self.window.len() - keep;
        let mut a = Vec::with_capacity(k);
        let mut b = Vec::with_capacity(k);
        for &(x, y) in self.window.iter().skip(skip) {
            a.push(x);
            b.push(y);
        }
        a.push(d_ins);
        b.push(range);

        let mut tests = Vec::new();
        let mut outputs = empty();
        let mut pending = None;
        if a.len() == k {
            let raw = window_features(&a, &b, &self.config.features)
                .map_err(|_| FilterError::NonFinite("tacan features"))?;
            let g = self.model.predict_one(&raw);
            if !g.is_finite() {
                return Err(FilterError::NonFinite("one-class decision").into());
            }
            let slot = &self.bank.slots()[0];
            let t = slot.threshold;
            let value = t * ratio(g, self.decision_scale);
            let (outcome, state) = self.bank.preview(0, value, slot.dof)?;
            tests.push(outcome);
            pending = Some(state);
            outputs = Outputs::Tacan {
                features: Some(self.model_view(&raw)),
                decision: Some(g),
            };
        }

        // Commit.
        if let Some(state) = pending {
            self.bank.commit(0, state);
        }
        self.window.clear();
        self.window.extend(a.into_iter().zip(b));
        self.last_t = Some(epoch.t);
        self.outputs = outputs;
        Ok(MonitorReport {
            tests,
            outputs: self.outputs.clone(),
            integrity: None,
        })
    }

    fn checkpoint(&self) -> Result<Vec<u8>, CheckpointError> {
        let Outputs::Tacan { features, decision } = &self.outputs else {
            return Err(CheckpointError::Encode(
                "tacan monitor without tacan outputs".into(),
            ));
        };
        checkpoint::encode(
            MonitorKind::Tacan,
            &TacanSaved {
                window: Cow::Borrowed(&self.window),
                last_t: self.last_t,
                features: features.as_deref().map(Cow::Borrowed),
                decision: *decision,
                bank: Cow::Borrowed(&self.bank),
            },
        )
    }

    /// Checks the window (at most `window` pairs), the feature output's dimension and the
    /// test before anything is replaced.
    fn restore(&mut self, bytes: &[u8]) -> Result<(), CheckpointError> {
        let saved: TacanSaved = checkpoint::decode(MonitorKind::Tacan, bytes)?;
        let k = self.config.features.window;
        let dim = self.config.features.dim();
        let mut window = saved.window.into_owned();
        if window.len() > k {
            return Err(CheckpointError::mismatch(format!(
                "a window of {} pairs, the monitor's holds {k}",
                window.len()
            )));
        }
        let features = saved.features.map(Cow::into_owned);
        if features.as_ref().is_some_and(|f| f.len() != dim) {
            return Err(CheckpointError::mismatch(format!(
                "features of another dimension, the monitor's have {dim}"
            )));
        }
        let bank = self
            .bank
            .restored(saved.bank.into_owned())
            .map_err(CheckpointError::Mismatch)?;
        window.reserve(k.saturating_sub(window.len()));
        self.window = window;
        self.last_t = saved.last_t;
        self.outputs = Outputs::Tacan {
            features,
            decision: saved.decision,
        };
        self.bank = bank;
        Ok(())
    }

    fn reset(&mut self) {
        self.window.clear();
        self.last_t = None;
        self.bank.reset();
        self.outputs = empty();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_range_ratio_is_one_on_the_boundary_and_grows_outside() {
        assert_eq!(ratio(0.0, Some(2.0)), 1.0);
        assert!(ratio(0.5, Some(2.0)) < 1.0);
        assert_eq!(ratio(-1.0, Some(2.0)), 2.0);
        assert_eq!(ratio(-2.0, Some(2.0)), MAX_RATIO);
        assert_eq!(ratio(-0.5, None), 1.5);
    }
}
