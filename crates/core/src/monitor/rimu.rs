//! The `rimu` monitor (docs/methods.md §M15, seed 002): redundant gyros `v = Hω + ε`. Each epoch's
//! gyro vector gives a parity residual `r = V v`; the FSS window of the last `l'`
//! residuals gives the `parity` test `λ ~ χ²(l'·p)` under the session's threshold and
//! policy. On a detection, each not-yet-isolated gyro's last `l` samples are turned
//! into wavelet-packet energies and classified by the stored C-SVC (fault when the
//! decision exceeds `T_I`); exactly one flagged gyro is isolated, otherwise the fault
//! is detected but not isolated. ω comes from weighted least squares over the gyros
//! not isolated.
//!
//! Config: `{"h": [[..3..], ...] (default: x, y, z + [1,1,1]/√3), "sigma": σ or [σ…]
//! (rad/s per sample, default 0.5°/√h at 100 Hz), "fss_window": 6, "feature_window":
//! 96, "wavelet": {"wavelet": "db4", "level": 3, "normalize": true}, "model": "<svm
//! id>" (optional), "t_i": 0.1}`.

use std::borrow::Cow;
use std::collections::VecDeque;
use std::sync::Arc;

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::{
    BuildError, CheckpointError, ConfigError, EpochError, ModelSource, Monitor, MonitorKind,
    MonitorReport, Outputs, StepError, TestBank, checkpoint,
};
use crate::detect::parity::{self, FssWindow, ParitySpace};
use crate::detect::{Health, PolicyConfig, ThresholdError, ThresholdSpec};
use crate::epoch::Epoch;
use crate::features::wavelet::{self, WaveletPacketParams};
use crate::learn::ModelKind;

/// Gyro sample rate, Hz, that the default σ assumes (seed 002: sample period 0.01 s).
pub const RATE_HZ: f64 = 100.0;

/// Gyro angle random walk, °/√h (seed 002 §3).
pub const ARW_DEG_PER_SQRT_H: f64 = 0.5;

/// The per-sample standard deviation (rad/s) of white rate noise with angle random
/// walk `arw_deg_per_sqrt_h` sampled every `dt_s`: `σ = ARW/√dt`.
pub fn sigma_per_sample(arw_deg_per_sqrt_h: f64, dt_s: f64) -> f64 {
    let arw_rad_per_sqrt_s = arw_deg_per_sqrt_h.to_radians() / 60.0;
    arw_rad_per_sqrt_s / dt_s.sqrt()
}

/// The default gyro noise: 0.5 °/√h at 100 Hz, ≈ 1.4544e-3 rad/s.
pub fn default_sigma() -> f64 {
    sigma_per_sample(ARW_DEG_PER_SQRT_H, 1.0 / RATE_HZ)
}

/// A gyro classifier: wavelet-packet features → decision value (> `T_I` = fault).
pub type GyroClassifier = Arc<dyn Fn(&[f64]) -> f64 + Send + Sync>;

/// `sigma`: one value for every gyro or one per gyro.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum SigmaWire {
    /// One σ for every gyro, rad/s per sample.
    Scalar(f64),
    /// One σ per gyro.
    PerGyro(Vec<f64>),
}

/// The `config` of a `rimu` monitor as the user writes it; every field has a default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RimuConfigWire {
    /// Mounting matrix rows (gyro axes in the body frame); default: x, y, z and the skew axis.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub h: Option<Vec<Vec<f64>>>,
    /// Gyro noise σ (default [`default_sigma`] for each gyro).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma: Option<SigmaWire>,
    /// FSS window l' (seed 002: 6).
    pub fss_window: usize,
    /// Feature window l: seed 002 uses 100; periodization needs a multiple of 2^level
    /// (8 at level 3), so the default is the nearest below, 96.
    pub feature_window: usize,
    /// Wavelet-packet feature parameters.
    pub wavelet: WaveletPacketParams,
    /// Stored `svm` classifier id, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    /// Decision threshold T_I (seed 002: 0.1).
    pub t_i: f64,
}

impl Default for RimuConfigWire {
    fn default() -> Self {
        RimuConfigWire {
            h: None,
            sigma: None,
            fss_window: 6,
            feature_window: 96,
            wavelet: WaveletPacketParams::default(),
            model: None,
            t_i: 0.1,
        }
    }
}

/// Longest windows accepted (a minute of 100 Hz samples; bounds memory per session).
const MAX_WINDOW: usize = 6000;

/// A validated `rimu` configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct RimuConfig {
    /// Parity space of the mounting matrix.
    pub parity: ParitySpace,
    /// Per-gyro noise σ, rad/s per sample.
    pub sigma: Vec<f64>,
    /// FSS window l'.
    pub fss_window: usize,
    /// Feature window l (samples per gyro classified).
    pub feature_window: usize,
    /// Wavelet-packet feature parameters.
    pub wavelet: WaveletPacketParams,
    /// Stored classifier id, if any.
    pub model: Option<String>,
    /// Decision threshold T_I.
    pub t_i: f64,
}

impl RimuConfig {
    /// Parses and validates a `rimu` config (without looking the model up), naming the
    /// field path of any error.
    pub fn from_json(value: &serde_json::Value) -> Result<Self, ConfigError> {
        Self::try_from(super::parse_config::<RimuConfigWire>(value)?)
    }
}

impl TryFrom<RimuConfigWire> for RimuConfig {
    type Error = ConfigError;

    /// Validates the mounting matrix, noise, windows and wavelet parameters.
    fn try_from(wire: RimuConfigWire) -> Result<Self, ConfigError> {
        let h = match &wire.h {
            None => parity::default_h(),
            Some(rows) => {
                for (i, row) in rows.iter().enumerate() {
                    if row.len() != 3 {
                        return Err(ConfigError::new(
                            format!("h[{i}]"),
                            format!("must have 3 elements (x, y, z), got {}", row.len()),
                        ));
                    }
                    if let Some(j) = row.iter().position(|v| !v.is_finite()) {
                        return Err(ConfigError::new(format!("h[{i}][{j}]"), "must be finite"));
                    }
                }
                if rows.len() > 64 {
                    return Err(ConfigError::new("h", "at most 64 gyros"));
                }
                DMatrix::from_fn(rows.len(), 3, |i, j| rows[i][j])
            }
        };
        let parity = ParitySpace::new(h).map_err(|e| ConfigError::new(e.field, e.reason))?;
        let m = parity.gyros();
        let positive = |s: f64| s.is_finite() && s > 0.0;
        let sigma = match wire.sigma {
            None => vec![default_sigma(); m],
            Some(SigmaWire::Scalar(s)) if positive(s) => vec![s; m],
            Some(SigmaWire::Scalar(_)) => {
                return Err(ConfigError::new("sigma", "must be finite and > 0"));
            }
            Some(SigmaWire::PerGyro(s)) if s.len() == m => s,
            Some(SigmaWire::PerGyro(s)) => {
                return Err(ConfigError::new(
                    "sigma",
                    format!("has {} elements, h has {m} gyros", s.len()),
                ));
            }
        };
        if let Some(i) = sigma.iter().position(|&s| !positive(s)) {
            return Err(ConfigError::new(
                format!("sigma[{i}]"),
                "must be finite and > 0",
            ));
        }
        if wire.fss_window == 0 || wire.fss_window > MAX_WINDOW {
            return Err(ConfigError::new(
                "fss_window",
                format!("must be between 1 and {MAX_WINDOW}"),
            ));
        }
        wire.wavelet
            .check()
            .map_err(|e| ConfigError::new(format!("wavelet.{}", e.field), e.reason))?;
        let nodes = wire.wavelet.dim();
        let l = wire.feature_window;
        if l == 0 || l > MAX_WINDOW || l % nodes != 0 {
            return Err(ConfigError::new(
                "feature_window",
                format!(
                    "must be a positive multiple of 2^level = {nodes}, at most {MAX_WINDOW}, got {l}"
                ),
            ));
        }
        if !wire.t_i.is_finite() {
            return Err(ConfigError::new("t_i", "must be finite"));
        }
        Ok(RimuConfig {
            parity,
            sigma,
            fss_window: wire.fss_window,
            feature_window: l,
            wavelet: wire.wavelet,
            model: wire.model,
            t_i: wire.t_i,
        })
    }
}

/// Builds a `rimu` monitor from its spec; `config.model` must name an `svm` model whose
/// input dimension is `2^level`.
pub fn build(
    wire: &RimuConfigWire,
    policy: PolicyConfig,
    threshold: ThresholdSpec,
    models: &dyn ModelSource,
) -> Result<Box<dyn Monitor>, BuildError> {
    let config = RimuConfig::try_from(wire.clone())?;
    let classifier = match &config.model {
        None => None,
        Some(id) => {
            let model = models.model(id).ok_or_else(|| BuildError::ModelNotFound {
                field: "model".into(),
                id: id.clone(),
            })?;
            if model.kind() != ModelKind::Svm {
                return Err(ConfigError::new(
                    "model",
                    format!(
                        "'{id}' is a {} model, rimu needs svm",
                        model.kind().as_str()
                    ),
                )
                .into());
            }
            let want = config.wavelet.dim();
            if model.input_dim() != want {
                return Err(ConfigError::new(
                    "model",
                    format!(
                        "'{id}' takes {} features, the wavelet packets give 2^level = {want}",
                        model.input_dim()
                    ),
                )
                .into());
            }
            let f: GyroClassifier = Arc::new(move |x: &[f64]| model.predict_one(x));
            Some(f)
        }
    };
    Ok(Box::new(RimuMonitor::new(
        config, classifier, policy, threshold,
    )?))
}

/// Index of the `parity` test in the bank.
const PARITY: usize = 0;

/// What a checkpoint of a `rimu` monitor holds (borrowed to write, owned when read): the
/// FSS window, each gyro's sample history, the flagged and isolated gyros and the test.
/// Not the classifier: the monitor built from the spec has it.
#[derive(Serialize, Deserialize)]
struct RimuSaved<'a> {
    fss: Cow<'a, FssWindow>,
    history: Cow<'a, [VecDeque<f64>]>,
    flagged: Cow<'a, [usize]>,
    isolated: Cow<'a, [usize]>,
    bank: Cow<'a, TestBank>,
}

/// The `rimu` monitor.
pub struct RimuMonitor {
    config: RimuConfig,
    classifier: Option<GyroClassifier>,
    fss: FssWindow,
    /// The last `feature_window` samples of each gyro.
    history: Vec<VecDeque<f64>>,
    flagged: Vec<usize>,
    isolated: Vec<usize>,
    bank: TestBank,
}

impl RimuMonitor {
    /// Builds the monitor; its one test `parity` has dof `l'·p`.
    pub fn new(
        config: RimuConfig,
        classifier: Option<GyroClassifier>,
        policy: PolicyConfig,
        spec: ThresholdSpec,
    ) -> Result<Self, ThresholdError> {
        let cov = config.parity.covariance(&config.sigma);
        // σ > 0 and V with orthonormal rows make V diag(σ²) Vᵀ positive definite.
        let fss = FssWindow::new(&cov, config.fss_window)
            .unwrap_or_else(|_| unreachable!("validated config"));
        let bank = TestBank::new(&[("parity", fss.dof())], spec, policy)?;
        let m = config.parity.gyros();
        let history = vec![VecDeque::with_capacity(config.feature_window); m];
        Ok(RimuMonitor {
            config,
            classifier,
            fss,
            history,
            flagged: Vec::new(),
            isolated: Vec::new(),
            bank,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &RimuConfig {
        &self.config
    }

    /// Classifies every gyro not isolated over its last `l` samples; returns the flagged.
    fn classify(&self, classifier: &GyroClassifier) -> Vec<usize> {
        let mut window = Vec::with_capacity(self.config.feature_window);
        (0..self.history.len())
            .filter(|i| !self.isolated.contains(i))
            .filter(|&i| {
                window.clear();
                window.extend(self.history[i].iter().copied());
                // The window length is validated against the level: this cannot fail.
                match wavelet::packet_energies(&window, &self.config.wavelet) {
                    Ok(phi) => classifier(&phi) > self.config.t_i, // seed 002 eq. 9
                    Err(_) => false,
                }
            })
            .collect()
    }

    fn omega(&self, gyros: &[f64]) -> Option<[f64; 3]> {
        let healthy: Vec<bool> = (0..gyros.len())
            .map(|i| !self.isolated.contains(&i))
            .collect();
        self.config
            .parity
            .omega(gyros, &self.config.sigma, &healthy)
    }
}

impl Monitor for RimuMonitor {
    fn kind(&self) -> MonitorKind {
        MonitorKind::Rimu
    }

    fn tests(&self) -> &TestBank {
        &self.bank
    }

    fn tests_mut(&mut self) -> &mut TestBank {
        &mut self.bank
    }

    fn check_epoch(&self, name: &str, epoch: &Epoch) -> Result<(), EpochError> {
        if let Some(g) = &epoch.gyros {
            let want = self.config.parity.gyros();
            if g.len() != want {
                return Err(EpochError::WrongLength {
                    monitor: name.to_owned(),
                    field: "gyros".into(),
                    got: g.len(),
                    want,
                });
            }
        }
        Ok(())
    }

    fn step(&mut self, epoch: &Epoch) -> Result<MonitorReport, StepError> {
        let Some(gyros) = epoch.gyros.as_deref() else {
            return Ok(MonitorReport {
                tests: Vec::new(),
                outputs: Outputs::Rimu {
                    parity: None,
                    flagged: self.flagged.clone(),
                    isolated: self.isolated.clone(),
                    omega: None,
                },
                integrity: None,
            });
        };
        let r = self.config.parity.residual(gyros);
        let (q, lambda) = self.fss.peek(&r);
        self.fss.push(q);
        for (h, &v) in self.history.iter_mut().zip(gyros) {
            if h.len() == self.config.feature_window {
                h.pop_front();
            }
            h.push_back(v);
        }
        let mut tests = Vec::new();
        if let Some(lambda) = lambda {
            let outcome = self.bank.evaluate(PARITY, lambda);
            let nu = self.fss.whiten(&r);
            self.bank
                .observe(PARITY, nu.as_slice(), outcome.decision.health);
            let detected = outcome.decision.health != Health::Healthy;
            let full = self.history[0].len() == self.config.feature_window;
            // Isolate once: while nothing is isolated, each detecting epoch classifies
            // again (the window holds more of the fault each time).
            if detected
                && full
                && self.isolated.is_empty()
                && let Some(classifier) = &self.classifier
            {
                self.flagged = self.classify(classifier);
                if let [one] = self.flagged[..] {
                    self.isolated.push(one);
                }
            }
            tests.push(outcome);
        }
        Ok(MonitorReport {
            tests,
            outputs: Outputs::Rimu {
                parity: Some(r.as_slice().to_vec()),
                flagged: self.flagged.clone(),
                isolated: self.isolated.clone(),
                omega: self.omega(gyros),
            },
            integrity: None,
        })
    }

    fn checkpoint(&self) -> Result<Vec<u8>, CheckpointError> {
        checkpoint::encode(
            MonitorKind::Rimu,
            &RimuSaved {
                fss: Cow::Borrowed(&self.fss),
                history: Cow::Borrowed(&self.history),
                flagged: Cow::Borrowed(&self.flagged),
                isolated: Cow::Borrowed(&self.isolated),
                bank: Cow::Borrowed(&self.bank),
            },
        )
    }

    /// Checks the FSS window (length and parity covariance), one history per gyro of at
    /// most `feature_window` samples, gyro indices in range and the test before anything
    /// is replaced.
    fn restore(&mut self, bytes: &[u8]) -> Result<(), CheckpointError> {
        let saved: RimuSaved = checkpoint::decode(MonitorKind::Rimu, bytes)?;
        let fss = self
            .fss
            .restored(saved.fss.into_owned())
            .map_err(CheckpointError::Mismatch)?;
        let (m, l) = (self.config.parity.gyros(), self.config.feature_window);
        let mut history = saved.history.into_owned();
        if history.len() != m || history.iter().any(|h| h.len() > l) {
            return Err(CheckpointError::mismatch(format!(
                "histories of {} gyros, the monitor has {m} gyros of {l} samples",
                history.len()
            )));
        }
        let (flagged, isolated) = (saved.flagged.into_owned(), saved.isolated.into_owned());
        if flagged.iter().chain(&isolated).any(|&i| i >= m) {
            return Err(CheckpointError::mismatch(format!(
                "a flagged or isolated gyro beyond the monitor's {m}"
            )));
        }
        let bank = self
            .bank
            .restored(saved.bank.into_owned())
            .map_err(CheckpointError::Mismatch)?;
        // The capacity `new` reserves, so a step allocates no more than before.
        for h in &mut history {
            h.reserve(l.saturating_sub(h.len()));
        }
        self.fss = fss;
        self.history = history;
        self.flagged = flagged;
        self.isolated = isolated;
        self.bank = bank;
        Ok(())
    }

    fn reset(&mut self) {
        self.fss.clear();
        self.history.iter_mut().for_each(VecDeque::clear);
        self.flagged.clear();
        self.isolated.clear();
        self.bank.reset();
    }
}
