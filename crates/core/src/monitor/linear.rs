//! The `linear` monitor (docs/methods.md §M2): a user-supplied linear Gaussian model,
//! one Kalman filter, and the residual χ² test λ = rᵀS⁻¹r ~ χ²(m) (seed 004 §1.3)
//! under the session's decision policy. It is also how navguard is checked
//! against other Kalman filter libraries.
//!
//! Optional guards on the same innovation (docs/methods.md §M23, [`super::guards`]):
//! `residual.drift`, a windowed-mean test on `ν = L⁻¹ r` for slow drifts the per-epoch
//! test misses, and `residual.stuck`, a variance collapse of `ν` (a frozen input). Both
//! are off unless the config has a `drift` or `stuck` block; when on, the filter updates
//! only if every test allows it. The residual test's `ν` feeds its consistency
//! diagnostics (docs/methods.md §M22).

use std::borrow::Cow;

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::guards::{self, DriftConfigWire, GuardConfig, InnovationGuards, StuckConfigWire};
use super::{
    CheckpointError, ConfigError, EpochError, Monitor, MonitorKind, MonitorReport, Outputs,
    StepError, TestBank, checkpoint,
};
use crate::detect::{PolicyConfig, ThresholdError, ThresholdSpec};
use crate::epoch::Epoch;
use crate::filter::kalman::{
    self, FilterError, LinearObservation, LinearTransition, StateEstimate,
};

/// The `config` of a `linear` monitor as the user writes it: row-major nested arrays.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinearConfigWire {
    /// State transition F (n × n).
    pub f: Vec<Vec<f64>>,
    /// Observation matrix H (m × n).
    pub h: Vec<Vec<f64>>,
    /// Process noise Q (n × n).
    pub q: Vec<Vec<f64>>,
    /// Measurement noise R (m × m).
    pub r: Vec<Vec<f64>>,
    /// Initial state (n).
    pub x0: Vec<f64>,
    /// Initial covariance (n × n).
    pub p0: Vec<Vec<f64>>,
    /// Control matrix B (n × k), optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub b: Option<Vec<Vec<f64>>>,
    /// The `residual.drift` test (docs/methods.md §M23); off when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drift: Option<DriftConfigWire>,
    /// The `residual.stuck` test (docs/methods.md §M21, §M23); off when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stuck: Option<StuckConfigWire>,
}

/// A validated linear model: `x = F x (+ B u) + w`, `z = H x + v`,
/// `w ~ N(0, Q)`, `v ~ N(0, R)`, prior `N(x0, P0)` before the first prediction.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearConfig {
    /// State transition F (n × n).
    pub f: DMatrix<f64>,
    /// Observation matrix H (m × n).
    pub h: DMatrix<f64>,
    /// Process noise Q (n × n, symmetric positive semi-definite).
    pub q: DMatrix<f64>,
    /// Measurement noise R (m × m, symmetric positive definite).
    pub r: DMatrix<f64>,
    /// Initial state (n).
    pub x0: DVector<f64>,
    /// Initial covariance (n × n, symmetric positive semi-definite).
    pub p0: DMatrix<f64>,
    /// Control matrix B (n × k), when the model has a control input `u`.
    pub b: Option<DMatrix<f64>>,
    /// The drift and stuck tests on the residual's normalised innovation.
    pub guards: GuardConfig,
}

/// Relative tolerance for symmetry and for the smallest eigenvalue of a
/// semi-definite matrix (round-off in user-typed or computed matrices).
const SYM_TOL: f64 = 1e-9;

fn matrix(
    field: &str,
    rows: &[Vec<f64>],
    shape: (Option<usize>, Option<usize>),
) -> Result<DMatrix<f64>, ConfigError> {
    let nrows = rows.len();
    if nrows == 0 {
        return Err(ConfigError::new(field, "must have at least one row"));
    }
    let ncols = rows[0].len();
    if ncols == 0 {
        return Err(ConfigError::new(field, "rows must not be empty"));
    }
    for (i, row) in rows.iter().enumerate() {
        if row.len() != ncols {
            return Err(ConfigError::new(
                format!("{field}[{i}]"),
                format!(
                    "ragged matrix: row has {} elements, row 0 has {ncols}",
                    row.len()
                ),
            ));
        }
        if let Some(j) = row.iter().position(|v| !v.is_finite()) {
            return Err(ConfigError::new(
                format!("{field}[{i}][{j}]"),
                "must be finite",
            ));
        }
    }
    if let Some(want) = shape.0.filter(|&w| w != nrows) {
        return Err(ConfigError::new(
            field,
            format!("has {nrows} rows, expected {want}"),
        ));
    }
    if let Some(want) = shape.1.filter(|&w| w != ncols) {
        return Err(ConfigError::new(
            field,
            format!("has {ncols} columns, expected {want}"),
        ));
    }
    Ok(DMatrix::from_fn(nrows, ncols, |i, j| rows[i][j]))
}

/// Checks symmetry and (semi-)definiteness; `strict` demands positive definite.
fn check_covariance(field: &str, m: &DMatrix<f64>, strict: bool) -> Result<(), ConfigError> {
    let scale = m.amax().max(f64::MIN_POSITIVE);
    for i in 0..m.nrows() {
        for j in 0..i {
            if (m[(i, j)] - m[(j, i)]).abs() > SYM_TOL * scale {
                return Err(ConfigError::new(
                    field,
                    format!(
                        "not symmetric: [{i}][{j}] = {} but [{j}][{i}] = {}",
                        m[(i, j)],
                        m[(j, i)]
                    ),
                ));
            }
        }
    }
    let sym = (m + m.transpose()) * 0.5;
    let min_eig = sym.symmetric_eigenvalues().min();
    if strict && min_eig <= SYM_TOL * scale {
        return Err(ConfigError::new(
            field,
            format!("not positive definite: smallest eigenvalue {min_eig:e}"),
        ));
    }
    if !strict && min_eig < -SYM_TOL * scale {
        return Err(ConfigError::new(
            field,
            format!("not positive semi-definite: smallest eigenvalue {min_eig:e}"),
        ));
    }
    Ok(())
}

impl LinearConfig {
    /// Parses and validates the `config` JSON of a `linear` monitor, naming the field path
    /// of any error.
    pub fn from_json(value: &serde_json::Value) -> Result<Self, ConfigError> {
        Self::try_from(super::parse_config::<LinearConfigWire>(value)?)
    }

    /// State dimension n.
    pub fn states(&self) -> usize {
        self.f.nrows()
    }

    /// Measurement dimension m.
    pub fn measurements(&self) -> usize {
        self.h.nrows()
    }
}

impl TryFrom<LinearConfigWire> for LinearConfig {
    type Error = ConfigError;

    /// Checks shapes, finiteness, symmetry and definiteness.
    fn try_from(wire: LinearConfigWire) -> Result<Self, ConfigError> {
        let f = matrix("f", &wire.f, (None, None))?;
        let n = f.nrows();
        if f.ncols() != n {
            return Err(ConfigError::new(
                "f",
                format!("must be square, is {}x{}", n, f.ncols()),
            ));
        }
        let h = matrix("h", &wire.h, (None, Some(n)))?;
        let m = h.nrows();
        let q = matrix("q", &wire.q, (Some(n), Some(n)))?;
        let r = matrix("r", &wire.r, (Some(m), Some(m)))?;
        let p0 = matrix("p0", &wire.p0, (Some(n), Some(n)))?;
        if wire.x0.len() != n {
            return Err(ConfigError::new(
                "x0",
                format!("has {} elements, expected {n}", wire.x0.len()),
            ));
        }
        if let Some(j) = wire.x0.iter().position(|v| !v.is_finite()) {
            return Err(ConfigError::new(format!("x0[{j}]"), "must be finite"));
        }
        let b = wire
            .b
            .as_deref()
            .map(|b| matrix("b", b, (Some(n), None)))
            .transpose()?;
        check_covariance("q", &q, false)?;
        check_covariance("r", &r, true)?;
        check_covariance("p0", &p0, false)?;
        let guards = guards::validate(
            "",
            &wire.drift.unwrap_or_else(DriftConfigWire::disabled),
            &wire.stuck.unwrap_or_else(StuckConfigWire::disabled),
        )?;
        Ok(LinearConfig {
            f,
            h,
            q,
            r,
            x0: DVector::from_vec(wire.x0),
            p0,
            b,
            guards,
        })
    }
}

/// The `linear` monitor.
pub struct LinearMonitor {
    transition: LinearTransition<nalgebra::Dyn>,
    observation: LinearObservation<nalgebra::Dyn, nalgebra::Dyn>,
    b: Option<DMatrix<f64>>,
    initial: StateEstimate<nalgebra::Dyn>,
    estimate: StateEstimate<nalgebra::Dyn>,
    bank: TestBank,
    guards: InnovationGuards,
}

/// Index of the `residual` test in the bank.
const RESIDUAL: usize = 0;

/// What a checkpoint of a `linear` monitor holds (borrowed to write, owned when read).
#[derive(Serialize, Deserialize)]
struct LinearSaved<'a> {
    estimate: Cow<'a, StateEstimate<nalgebra::Dyn>>,
    bank: Cow<'a, TestBank>,
    guards: Cow<'a, InnovationGuards>,
}

impl LinearMonitor {
    /// Builds the monitor: the test `residual` (dof m) and the guards its config enables,
    /// `residual.drift` (dof m) and `residual.stuck` (dof 1).
    pub fn new(
        config: LinearConfig,
        policy: PolicyConfig,
        spec: ThresholdSpec,
    ) -> Result<Self, ThresholdError> {
        let m = config.measurements();
        let mut bank = TestBank::new(&[("residual", m as u32)], spec, policy)?;
        let guards = InnovationGuards::new(&mut bank, "residual", m, &config.guards)?;
        let initial = StateEstimate {
            x: config.x0.clone(),
            p: config.p0.clone(),
        };
        Ok(LinearMonitor {
            transition: LinearTransition {
                f: config.f,
                q: config.q,
            },
            observation: LinearObservation {
                h: config.h,
                r: config.r,
            },
            b: config.b,
            estimate: initial.clone(),
            initial,
            bank,
            guards,
        })
    }

    /// The current state estimate.
    pub fn estimate(&self) -> &StateEstimate<nalgebra::Dyn> {
        &self.estimate
    }
}

impl Monitor for LinearMonitor {
    fn kind(&self) -> MonitorKind {
        MonitorKind::Linear
    }

    fn tests(&self) -> &TestBank {
        &self.bank
    }

    fn tests_mut(&mut self) -> &mut TestBank {
        &mut self.bank
    }

    fn check_epoch(&self, name: &str, epoch: &Epoch) -> Result<(), EpochError> {
        if let Some(z) = &epoch.z {
            let want = self.observation.h.nrows();
            if z.len() != want {
                return Err(EpochError::WrongLength {
                    monitor: name.to_owned(),
                    field: "z".into(),
                    got: z.len(),
                    want,
                });
            }
        }
        if let Some(u) = &epoch.u {
            match &self.b {
                Some(b) if u.len() != b.ncols() => {
                    return Err(EpochError::WrongLength {
                        monitor: name.to_owned(),
                        field: "u".into(),
                        got: u.len(),
                        want: b.ncols(),
                    });
                }
                Some(_) => {}
                None => {
                    return Err(EpochError::UnknownInput(format!(
                        "u given but monitor '{name}' has no control matrix b"
                    )));
                }
            }
        }
        Ok(())
    }

    fn step(&mut self, epoch: &Epoch) -> Result<MonitorReport, StepError> {
        // Predict (with control when both B and u are present; a missing u is zero).
        let prior = match (&self.b, &epoch.u) {
            (Some(b), Some(u)) => kalman::predict_with_control(
                &self.estimate,
                &self.transition,
                b,
                &DVector::from_column_slice(u),
            )?,
            _ => kalman::predict(&self.estimate, &self.transition)?,
        };
        let Some(z) = &epoch.z else {
            self.estimate = prior;
            return Ok(MonitorReport {
                tests: Vec::new(),
                outputs: Outputs::Linear {
                    innovation: None,
                    x: self.estimate.x.as_slice().to_vec(),
                },
                integrity: None,
            });
        };
        let z = DVector::from_column_slice(z);
        let innovation = kalman::innovation(&prior, &self.observation, &z)?;
        // Compute the posterior before deciding so a numerical failure leaves
        // the policy counters untouched too.
        let posterior = kalman::update(&prior, &self.observation, &innovation)?.0;
        // ν = L⁻¹ r (S = L Lᵀ): ‖ν‖² = λ; the guards' and the diagnostics' input.
        let nu = innovation
            .s_chol
            .l()
            .solve_lower_triangular(&innovation.r)
            .ok_or(FilterError::NotPositiveDefinite)?;
        let mut guard = self.guards.preview(&self.bank, nu.as_slice())?;
        let (outcome, state) = self.bank.preview(
            RESIDUAL,
            innovation.statistic,
            self.bank.slots()[RESIDUAL].dof,
        )?;
        let decision = self.guards.combined(&self.bank, &guard, outcome.decision);
        self.bank.commit(RESIDUAL, state);
        self.bank.observe(RESIDUAL, nu.as_slice(), decision.health);
        let mut tests = vec![outcome];
        let healthy = decision.health == crate::detect::Health::Healthy;
        self.guards.commit(
            &mut self.bank,
            &mut guard,
            nu.as_slice(),
            healthy,
            &mut tests,
        );
        // seed 004 §2: a suspect or isolated filter predicts without updating (any of
        // its tests can say so); `traditional` always updates (no fusion to leave).
        self.estimate = if decision.update { posterior } else { prior };
        Ok(MonitorReport {
            tests,
            outputs: Outputs::Linear {
                innovation: Some(innovation.r.as_slice().to_vec()),
                x: self.estimate.x.as_slice().to_vec(),
            },
            integrity: None,
        })
    }

    fn reset(&mut self) {
        self.estimate = self.initial.clone();
        self.bank.reset();
        self.guards.reset();
    }

    fn checkpoint(&self) -> Result<Vec<u8>, CheckpointError> {
        checkpoint::encode(
            MonitorKind::Linear,
            &LinearSaved {
                estimate: Cow::Borrowed(&self.estimate),
                bank: Cow::Borrowed(&self.bank),
                guards: Cow::Borrowed(&self.guards),
            },
        )
    }

    /// Checks the saved estimate's dimension (x of n, P n × n), the tests and the guards
    /// against this monitor's before anything is replaced.
    fn restore(&mut self, bytes: &[u8]) -> Result<(), CheckpointError> {
        let saved: LinearSaved = checkpoint::decode(MonitorKind::Linear, bytes)?;
        let estimate = saved.estimate.into_owned();
        let n = self.initial.x.len();
        if estimate.x.len() != n || estimate.p.shape() != (n, n) {
            return Err(CheckpointError::mismatch(format!(
                "a {}-state estimate, the monitor has {n} states",
                estimate.x.len()
            )));
        }
        let bank = self
            .bank
            .restored(saved.bank.into_owned())
            .map_err(CheckpointError::Mismatch)?;
        let guards = self
            .guards
            .restored(saved.guards.into_owned())
            .map_err(CheckpointError::Mismatch)?;
        self.estimate = estimate;
        self.bank = bank;
        self.guards = guards;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::Health;
    use serde_json::json;

    fn cv_config() -> serde_json::Value {
        json!({
            "f": [[1.0, 1.0], [0.0, 1.0]],
            "h": [[1.0, 0.0]],
            "q": [[0.25, 0.5], [0.5, 1.0]],
            "r": [[1.0]],
            "x0": [0.0, 0.0],
            "p0": [[10.0, 0.0], [0.0, 10.0]]
        })
    }

    fn field_error(
        mut config: serde_json::Value,
        key: &str,
        value: serde_json::Value,
    ) -> ConfigError {
        config[key] = value;
        LinearConfig::from_json(&config).unwrap_err()
    }

    #[test]
    fn valid_model_parses_with_its_dimensions() {
        let c = LinearConfig::from_json(&cv_config()).unwrap();
        assert_eq!((c.states(), c.measurements()), (2, 1));
    }

    #[test]
    fn bad_models_are_refused_naming_the_field() {
        let e = field_error(cv_config(), "f", json!([[1.0, 1.0]]));
        assert_eq!(e.field, "f");
        assert!(e.reason.contains("square"), "{e}");
        let e = field_error(cv_config(), "h", json!([[1.0, 0.0, 0.0]]));
        assert_eq!(e.field, "h");
        let e = field_error(cv_config(), "q", json!([[1.0, 0.2], [0.0, 1.0]]));
        assert_eq!(e.field, "q");
        assert!(e.reason.contains("symmetric"), "{e}");
        let e = field_error(cv_config(), "q", json!([[1.0, 2.0], [2.0, 1.0]]));
        assert!(e.reason.contains("semi-definite"), "{e}");
        let e = field_error(cv_config(), "r", json!([[0.0]]));
        assert_eq!(e.field, "r");
        assert!(e.reason.contains("positive definite"), "{e}");
        let e = field_error(cv_config(), "p0", json!([[1.0, 0.0], [0.0]]));
        assert_eq!(e.field, "p0[1]");
        assert!(e.reason.contains("ragged"), "{e}");
        let e = field_error(cv_config(), "x0", json!([0.0]));
        assert_eq!(e.field, "x0");
        let e = field_error(cv_config(), "b", json!([[1.0]]));
        assert_eq!(e.field, "b");
        let mut c = cv_config();
        c["extra"] = json!(1);
        assert!(
            LinearConfig::from_json(&c)
                .unwrap_err()
                .reason
                .contains("unknown field")
        );
    }

    #[test]
    fn wrong_length_z_is_refused_before_stepping() {
        let c = LinearConfig::from_json(&cv_config()).unwrap();
        let m = LinearMonitor::new(c, PolicyConfig::Classic, ThresholdSpec::default()).unwrap();
        let e = Epoch {
            t: 0.0,
            z: Some(vec![1.0, 2.0]),
            ..Default::default()
        };
        assert!(matches!(
            m.check_epoch("lin", &e),
            Err(EpochError::WrongLength {
                got: 2,
                want: 1,
                ..
            })
        ));
        let e = Epoch {
            t: 0.0,
            u: Some(vec![1.0]),
            ..Default::default()
        };
        assert!(matches!(
            m.check_epoch("lin", &e),
            Err(EpochError::UnknownInput(_))
        ));
    }

    #[test]
    fn first_step_matches_hand_computed_filter() {
        // x⁻ = 0, P⁻ = F P0 Fᵀ + Q = [[20.25, 10.5], [10.5, 11]], S = 21.25, r = z = 2.
        let c = LinearConfig::from_json(&cv_config()).unwrap();
        let mut m = LinearMonitor::new(c, PolicyConfig::Classic, ThresholdSpec::default()).unwrap();
        let report = m
            .step(&Epoch {
                t: 0.0,
                z: Some(vec![2.0]),
                ..Default::default()
            })
            .unwrap();
        let lambda = 4.0 / 21.25;
        assert!((report.tests[0].statistic.value - lambda).abs() < 1e-12);
        let Outputs::Linear { x, innovation } = report.outputs else {
            panic!("linear outputs")
        };
        assert_eq!(innovation, Some(vec![2.0]));
        assert!((x[0] - 20.25 / 21.25 * 2.0).abs() < 1e-12);
        assert!((x[1] - 10.5 / 21.25 * 2.0).abs() < 1e-12);
    }

    #[test]
    fn suspect_filter_predicts_without_updating() {
        let c = LinearConfig::from_json(&cv_config()).unwrap();
        let mut m = LinearMonitor::new(
            c,
            PolicyConfig::counters_default(),
            ThresholdSpec::Threshold(5.0),
        )
        .unwrap();
        let report = m
            .step(&Epoch {
                t: 0.0,
                z: Some(vec![100.0]),
                ..Default::default()
            })
            .unwrap();
        assert_eq!(report.tests[0].decision.health, Health::Suspect);
        let Outputs::Linear { x, .. } = report.outputs else {
            panic!("linear outputs")
        };
        assert_eq!(
            x,
            vec![0.0, 0.0],
            "the prior (F·0) is kept, the outlier is not used"
        );
        assert!(
            (m.estimate().p[(0, 0)] - 20.25).abs() < 1e-12,
            "P is the predicted one"
        );
    }

    #[test]
    fn epoch_without_z_only_predicts_and_runs_no_test() {
        let c = LinearConfig::from_json(&cv_config()).unwrap();
        let mut m = LinearMonitor::new(c, PolicyConfig::Classic, ThresholdSpec::default()).unwrap();
        let report = m
            .step(&Epoch {
                t: 0.0,
                ..Default::default()
            })
            .unwrap();
        assert!(report.tests.is_empty());
        assert!((m.estimate().p[(0, 0)] - 20.25).abs() < 1e-12);
    }

    /// A 1-D random walk seen with σ = 1, the residual guarded as `guards` says.
    fn walk(guards: serde_json::Value, policy: PolicyConfig) -> LinearMonitor {
        let mut c = json!({
            "f": [[1.0]], "h": [[1.0]], "q": [[1e-4]], "r": [[1.0]], "x0": [0.0], "p0": [[1.0]]
        });
        for (k, v) in guards.as_object().unwrap() {
            c[k] = v.clone();
        }
        let config = LinearConfig::from_json(&c).unwrap();
        LinearMonitor::new(config, policy, ThresholdSpec::PFa(1e-3)).unwrap()
    }

    fn noise(k: u32) -> f64 {
        // A deterministic, zero-mean, unit-variance-ish sequence (no RNG needed).
        let x = f64::from(k.wrapping_mul(2_654_435_761) % 1000) / 1000.0;
        (x - 0.5) * 12f64.sqrt()
    }

    #[test]
    fn guards_are_off_by_default_and_a_config_without_them_still_loads() {
        // A config stored before the guards existed: no `drift`, no `stuck`.
        let m = walk(json!({}), PolicyConfig::counters_default());
        let names: Vec<_> = m.tests().slots().iter().map(|s| &*s.name).collect();
        assert_eq!(names, ["residual"]);
        let m = walk(
            json!({"drift": {"windows": [5, 20]}, "stuck": {}}),
            PolicyConfig::counters_default(),
        );
        let slots = m.tests().slots();
        let names: Vec<_> = slots.iter().map(|s| (&*s.name, s.dof)).collect();
        assert_eq!(
            names,
            [
                ("residual", 1),
                ("residual.drift", 1),
                ("residual.stuck", 1)
            ]
        );
        // The drift test follows the monitor's p_fa, the stuck test keeps its 1e-6.
        assert!((slots[1].threshold - 10.8276).abs() < 1e-3);
        assert!((slots[2].threshold - 23.9281).abs() < 1e-3);
        let wire: LinearConfigWire = serde_json::from_value(cv_config()).unwrap();
        let back = serde_json::to_value(&wire).unwrap();
        assert!(
            back.get("drift").is_none(),
            "absent blocks stay absent: {back}"
        );
    }

    #[test]
    fn residual_drift_catches_a_slow_ramp_and_stops_the_update() {
        let mut m = walk(json!({"drift": {}}), PolicyConfig::counters_default());
        let (mut drift, mut chi2) = (None, None);
        for k in 0..400u32 {
            let ramp = if k >= 200 {
                0.15 * f64::from(k - 200)
            } else {
                0.0
            };
            let before = m.estimate().x[0];
            let r = m
                .step(&Epoch {
                    t: f64::from(k),
                    z: Some(vec![noise(k) + ramp]),
                    ..Default::default()
                })
                .unwrap();
            let bad = |name: &str| {
                r.tests
                    .iter()
                    .any(|o| &*o.name == name && o.decision.health != Health::Healthy)
            };
            if k >= 200 && drift.is_none() && bad("residual.drift") {
                drift = Some(k - 200);
                // The residual test is still healthy, but the filter only predicted
                // (F = 1): the combined decision stopped the update.
                assert!(!bad("residual"));
                assert_eq!(m.estimate().x[0], before);
            }
            if k >= 200 && chi2.is_none() && bad("residual") {
                chi2 = Some(k - 200);
            }
            assert!(k >= 200 || !bad("residual.drift"), "false alarm at {k}");
        }
        let drift = drift.expect("the drift test fires");
        assert!(drift < chi2.unwrap_or(u32::MAX), "{drift} vs {chi2:?}");
        // The consistency diagnostics were fed ν on the healthy epochs.
        let mut c = m.tests().slots()[RESIDUAL].consistency.clone();
        assert!(c.summary().unwrap().samples > 0);
    }

    #[test]
    fn residual_stuck_catches_a_frozen_measurement() {
        let mut m = walk(json!({"stuck": {}}), PolicyConfig::counters_default());
        let mut flagged = None;
        for k in 0..200u32 {
            // Frozen from epoch 150: the same value repeated.
            let z = if k >= 150 { noise(149) } else { noise(k) };
            let r = m
                .step(&Epoch {
                    t: f64::from(k),
                    z: Some(vec![z]),
                    ..Default::default()
                })
                .unwrap();
            let stuck = r.tests.iter().find(|o| &*o.name == "residual.stuck");
            if let Some(o) = stuck
                && o.decision.health != Health::Healthy
                && flagged.is_none()
            {
                flagged = Some(k);
            }
        }
        let k = flagged.expect("flagged");
        assert!((150..=160).contains(&k), "flagged at {k}");
    }

    #[test]
    fn traditional_on_a_filter_without_fusion_flags_but_keeps_updating() {
        let c = LinearConfig::from_json(&cv_config()).unwrap();
        let mut m = LinearMonitor::new(c, PolicyConfig::Traditional, ThresholdSpec::Threshold(5.0))
            .unwrap();
        let report = m
            .step(&Epoch {
                t: 0.0,
                z: Some(vec![100.0]),
                ..Default::default()
            })
            .unwrap();
        assert_eq!(report.tests[0].decision.health, Health::Isolated);
        let Outputs::Linear { x, .. } = report.outputs else {
            panic!("linear outputs")
        };
        assert!(x[0] > 90.0, "the outlier was used: {x:?}");
    }

    #[test]
    fn guard_blocks_are_refused_by_monitor_build_naming_the_exact_path() {
        let cases = [
            (json!({"drift": {"windows": []}}), "drift.windows"),
            (json!({"drift": {"windows": [0]}}), "drift.windows[0]"),
            (json!({"drift": {"windows": [3, 3]}}), "drift.windows[1]"),
            (json!({"drift": {"p_fa": 2}}), "drift.p_fa"),
            (json!({"drift": {"threshold": 0}}), "drift.threshold"),
            (json!({"drift": {"p_fa": 0.1, "threshold": 3}}), "drift"),
            (json!({"drift": {"window": 3}}), "drift.window"),
            (json!({"drift": {"enabled": 1}}), "drift.enabled"),
            (json!({"stuck": {"k": 1}}), "stuck.k"),
            (json!({"stuck": {"p_fa": 0}}), "stuck.p_fa"),
            (json!({"stuck": {"threshold": -2}}), "stuck.threshold"),
            (json!({"stuck": {"p_fa": 1e-6, "threshold": 24}}), "stuck"),
            (json!({"stuck": {"k": "8"}}), "stuck.k"),
        ];
        for (guards, field) in cases {
            let mut c = cv_config();
            for (k, v) in guards.as_object().unwrap() {
                c[k] = v.clone();
            }
            let spec = crate::monitor::MonitorSpec {
                kind: MonitorKind::Linear,
                config: match crate::monitor::MonitorConfig::parse(MonitorKind::Linear, &c) {
                    Ok(config) => config,
                    Err(e) => {
                        assert_eq!(e.field, field, "{guards}: {e}");
                        continue;
                    }
                },
                policy: PolicyConfig::Classic,
                threshold: ThresholdSpec::default(),
            };
            match crate::monitor::build(&spec, &crate::monitor::NoModels) {
                Err(crate::monitor::BuildError::Config(e)) => {
                    assert_eq!(e.field, field, "{guards}: {e}")
                }
                Err(e) => panic!("{guards}: {e}"),
                Ok(_) => panic!("{guards} accepted"),
            }
        }
    }

    #[test]
    fn reset_restores_the_initial_estimate() {
        let c = LinearConfig::from_json(&cv_config()).unwrap();
        let mut m = LinearMonitor::new(c, PolicyConfig::Classic, ThresholdSpec::default()).unwrap();
        m.step(&Epoch {
            t: 0.0,
            z: Some(vec![3.0]),
            ..Default::default()
        })
        .unwrap();
        m.reset();
        assert_eq!(m.estimate().x, DVector::from_vec(vec![0.0, 0.0]));
        assert_eq!(m.estimate().p[(0, 0)], 10.0);
    }
}
