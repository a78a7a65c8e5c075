//! The `federated` monitor (docs/methods.md §M6, §M7; docs/architecture.md §A6; seed 004): an INS aided by GNSS, DVL
//! and CNS through the federated filter of [`crate::filter::federated`], one χ² test per
//! configured aid (`gnss`, `dvl`, `cns`) under the session's policy, and the `hpl` test of
//! the horizontal protection level against the alert limit. The session actor steps it once
//! per epoch.
//!
//! # Epochs
//! - It runs on epochs that carry `ins` (1–100 Hz) and ignores the others (no tests, the last
//!   outputs repeated). The first INS epoch initialises the filter from the `init` config
//!   (zero error, no prediction) and already uses any aid that comes with it.
//! - `gnss`, `dvl`, `cns` are used when present, as of the INS epoch they arrive with; any may
//!   be absent for any stretch (the local filter then predicts only, its policy idle).
//!   A `gnss` block with `vel` gives the 6-dim measurement `[δV; δP]` of seed 004 eq. 3 (the
//!   `gnss` test then has dof 6), without `vel` the 3-dim position one (dof 3); both
//!   thresholds are resolved when the spec is set, never per epoch.
//! - The interval since the previous INS epoch drives the prediction: `dt = 0` (a second
//!   frame of the same instant) predicts nothing; up to [`MAX_GAP_S`] it is predicted in
//!   sub-steps of at most 1 s; a longer gap (or time going back) restarts the filter from
//!   the `init` uncertainty, as the INS may have drifted beyond the linearised model.
//!   Policies keep their state across a restart.
//!
//! # Tests
//! Per aid, `λ_i = rᵀ S⁻¹ r` of its local filter (dof 6 or 3 for `gnss`, 3 for `dvl`, 2 for
//! `cns`), thresholds and policy from the monitor's spec. `hpl`: statistic = HPL (metres),
//! threshold = `hal_m` whatever the spec, always the classic policy (HPL > HAL makes the
//! solution unavailable for that epoch, without counters: a protection level is not a noisy
//! detection to be debounced), reported with dof 2 (the horizontal plane).
//!
//! # HPL (docs/methods.md §M7, see [`crate::detect::hpl`])
//! `HPL₁ = k_md σ_h` from the fused `P_g`; `HPL₂ = max_i slope_i sqrt(λ_det,i)` over the aids
//! that take part in fusion, `λ_det,i` for the aid's dof and threshold at `p_md`. An aid's slope
//! is computed when it updates (gain onto the fused solution, its local `S`) and kept until its
//! next update, so the HPL does not jump between aid epochs at a 10 Hz INS rate; an aid left
//! out of fusion drops out of `HPL₂`.
//!
//! # Outputs
//! `solution {lat, lon (degrees), h (m), vel (m/s ENU)}`: the INS solution minus the fused
//! error estimate (open loop); `hpl` (m); `isolated`: the aids whose test is isolated.

use nalgebra::{Matrix2, Vector3};
use serde::{Deserialize, Serialize};

use super::{
    BuildError, ConfigError, EpochError, Monitor, MonitorKind, MonitorReport, Outputs, StepError,
    TestBank, TestOutcome,
};
use crate::detect::hpl::{self, DetectionNoncentrality, HplError};
use crate::detect::{Health, PolicyConfig, PolicyState, ThresholdError, ThresholdSpec};
use crate::epoch::{Aid, Epoch};
use crate::filter::aiding;
use crate::filter::federated::{
    self, ErrorEstimate, FederatedFilter, LocalTest, MAX_AIDS, Observation,
};
use crate::filter::ins::{
    ACC, ATT, ErrorMatrix, ErrorVector, GYRO, ImuErrors, NavSolution, POS, VEL,
};
use crate::filter::kalman::{FilterError, LinearTransition, StateEstimate};
use crate::geo::{self, Lla};

/// The longest gap between INS epochs that is predicted across, s; longer ones restart.
pub const MAX_GAP_S: f64 = 3600.0;

/// Default horizontal alert limit, m: IMO A.915(22)'s alert limit for ocean and coastal
/// navigation (seed 004 states none). With seed 004's aids (GNSS 10 m at 1 Hz, DVL 0.1 m/s)
/// the fault-free HPL is a few metres; it reaches 25 m after a long loss of GNSS.
pub const DEFAULT_HAL_M: f64 = 25.0;

/// A validated `federated` config; every field but `aids` defaults to seed 004's values.
#[derive(Debug, Clone, PartialEq)]
pub struct FederatedConfig {
    /// The aids, in the order given (each at most once).
    pub aids: Vec<Aid>,
    /// GNSS position noise (1σ per axis), m. Default 10.
    pub gnss_pos_sigma_m: f64,
    /// GNSS velocity noise, m/s. Default 0.1.
    pub gnss_vel_sigma_mps: f64,
    /// DVL velocity noise, m/s. Default 0.1.
    pub dvl_vel_sigma_mps: f64,
    /// CNS position noise, m. Default 450.
    pub cns_pos_sigma_m: f64,
    /// IMU errors (biases as the initial bias uncertainty, random walks as process noise).
    pub imu: ImuErrors,
    /// Initial attitude uncertainty [roll, pitch, yaw], arcsec. Default [5, 5, 30].
    pub init_att_sigma_arcsec: [f64; 3],
    /// Initial position uncertainty, m. Default 10.
    pub init_pos_sigma_m: f64,
    /// Initial velocity uncertainty, m/s. Default 0.1.
    pub init_vel_sigma_mps: f64,
    /// Information-sharing factors, one per aid in `aids` order; default equal.
    pub beta: Vec<f64>,
    /// Horizontal alert limit, m. Default [`DEFAULT_HAL_M`].
    pub hal_m: f64,
    /// Missed-detection probability for the HPL. Default 1e-3.
    pub p_md: f64,
}

/// The `gnss` section of a `federated` config; seed 004's values by default.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GnssNoise {
    /// Position noise (1σ per axis), m.
    pub pos_sigma_m: f64,
    /// Velocity noise, m/s.
    pub vel_sigma_mps: f64,
}

impl Default for GnssNoise {
    fn default() -> Self {
        GnssNoise {
            pos_sigma_m: 10.0,
            vel_sigma_mps: 0.1,
        }
    }
}

/// The `dvl` section of a `federated` config.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DvlNoise {
    /// Velocity noise, m/s.
    pub vel_sigma_mps: f64,
}

impl Default for DvlNoise {
    fn default() -> Self {
        DvlNoise { vel_sigma_mps: 0.1 }
    }
}

/// The `cns` section of a `federated` config.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CnsNoise {
    /// Position noise, m.
    pub pos_sigma_m: f64,
}

impl Default for CnsNoise {
    fn default() -> Self {
        CnsNoise { pos_sigma_m: 450.0 }
    }
}

/// The `imu` section: [`ImuErrors`] with every field optional.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ImuSection {
    /// Gyro bias, °/h.
    pub gyro_bias_dph: f64,
    /// Accelerometer bias, µg.
    pub accel_bias_ug: f64,
    /// Angle random walk, °/√h.
    pub arw_deg_rthr: f64,
    /// Velocity random walk, m/s/√h.
    pub vrw_mps_rthr: f64,
}

impl Default for ImuSection {
    fn default() -> Self {
        ImuSection::from(ImuErrors::default())
    }
}

impl From<ImuErrors> for ImuSection {
    fn from(e: ImuErrors) -> Self {
        ImuSection {
            gyro_bias_dph: e.gyro_bias_dph,
            accel_bias_ug: e.accel_bias_ug,
            arw_deg_rthr: e.arw_deg_rthr,
            vrw_mps_rthr: e.vrw_mps_rthr,
        }
    }
}

/// The `init` section: the initial error uncertainty; seed 004's values by default.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InitSigma {
    /// Attitude [roll, pitch, yaw], arcsec.
    pub att_sigma_arcsec: [f64; 3],
    /// Position, m.
    pub pos_sigma_m: f64,
    /// Velocity, m/s.
    pub vel_sigma_mps: f64,
}

impl Default for InitSigma {
    fn default() -> Self {
        InitSigma {
            att_sigma_arcsec: [5.0, 5.0, 30.0],
            pos_sigma_m: 10.0,
            vel_sigma_mps: 0.1,
        }
    }
}

/// The `beta` section: one information-sharing factor per configured aid.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BetaSection {
    /// GNSS's factor.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gnss: Option<f64>,
    /// DVL's factor.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dvl: Option<f64>,
    /// CNS's factor.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cns: Option<f64>,
}

impl BetaSection {
    fn get(&self, aid: Aid) -> Option<f64> {
        match aid {
            Aid::Gnss => self.gnss,
            Aid::Dvl => self.dvl,
            Aid::Cns => self.cns,
        }
    }
}

/// The `config` of a `federated` monitor as the user writes it; sections left out take
/// their `Default`, and an aid's section may only be given for an aid in `aids`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FederatedConfigWire {
    /// The aids, in order (each at most once; 1 to [`MAX_AIDS`]).
    #[serde(default)]
    pub aids: Vec<Aid>,
    /// GNSS noise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gnss: Option<GnssNoise>,
    /// DVL noise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dvl: Option<DvlNoise>,
    /// CNS noise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cns: Option<CnsNoise>,
    /// IMU errors.
    #[serde(default)]
    pub imu: ImuSection,
    /// Initial uncertainty.
    #[serde(default)]
    pub init: InitSigma,
    /// Sharing factors (default: equal).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beta: Option<BetaSection>,
    /// Horizontal alert limit, m.
    #[serde(default = "default_hal_m")]
    pub hal_m: f64,
    /// Missed-detection probability for the HPL.
    #[serde(default = "default_p_md")]
    pub p_md: f64,
}

fn default_hal_m() -> f64 {
    DEFAULT_HAL_M
}

fn default_p_md() -> f64 {
    hpl::DEFAULT_P_MD
}

impl FederatedConfigWire {
    /// A config for `aids` with every other field at its default.
    pub fn new(aids: Vec<Aid>) -> Self {
        FederatedConfigWire {
            aids,
            gnss: None,
            dvl: None,
            cns: None,
            imu: ImuSection::default(),
            init: InitSigma::default(),
            beta: None,
            hal_m: DEFAULT_HAL_M,
            p_md: hpl::DEFAULT_P_MD,
        }
    }
}

/// A finite positive number at `field`.
fn positive(field: impl FnOnce() -> String, x: f64) -> Result<f64, ConfigError> {
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        Err(ConfigError::new(field(), "must be a finite number > 0"))
    }
}

/// Checks `aids` (1 to [`MAX_AIDS`], no repeats) and that aid sections name listed aids.
fn check_aids(w: &FederatedConfigWire) -> Result<(), ConfigError> {
    if w.aids.is_empty() || w.aids.len() > MAX_AIDS {
        return Err(ConfigError::new(
            "aids",
            format!("must name 1 to {MAX_AIDS} aids"),
        ));
    }
    for (i, aid) in w.aids.iter().enumerate() {
        if w.aids[..i].contains(aid) {
            return Err(ConfigError::new(format!("aids[{i}]"), "duplicate aid"));
        }
    }
    let sections = [
        (Aid::Gnss, w.gnss.is_some()),
        (Aid::Dvl, w.dvl.is_some()),
        (Aid::Cns, w.cns.is_some()),
    ];
    for (aid, given) in sections {
        if given && !w.aids.contains(&aid) {
            return Err(ConfigError::new(
                aid.as_str(),
                "configured but not listed in aids",
            ));
        }
    }
    Ok(())
}

/// The sharing factors in `aids` order: each in (0, 1], summing to 1 (renormalised exactly).
fn check_beta(aids: &[Aid], beta: Option<&BetaSection>) -> Result<Vec<f64>, ConfigError> {
    let Some(map) = beta else {
        return Ok(federated::equal_betas(aids.len()));
    };
    for aid in [Aid::Gnss, Aid::Dvl, Aid::Cns] {
        if map.get(aid).is_some() && !aids.contains(&aid) {
            return Err(ConfigError::new(
                format!("beta.{}", aid.as_str()),
                "not one of the configured aids",
            ));
        }
    }
    let mut out = Vec::with_capacity(aids.len());
    for aid in aids {
        let field = || format!("beta.{}", aid.as_str());
        let b = map
            .get(*aid)
            .ok_or_else(|| ConfigError::new("beta", format!("missing {}", aid.as_str())))?;
        let b = positive(field, b)?;
        if b > 1.0 {
            return Err(ConfigError::new(field(), "must be in (0, 1]"));
        }
        out.push(b);
    }
    let sum: f64 = out.iter().sum();
    if (sum - 1.0).abs() > 1e-6 {
        return Err(ConfigError::new(
            "beta",
            format!("the sharing factors must sum to 1, got {sum}"),
        ));
    }
    Ok(out.iter().map(|b| b / sum).collect())
}

impl TryFrom<FederatedConfigWire> for FederatedConfig {
    type Error = ConfigError;

    /// Validates the config; errors name the field (`aids[1]`, `gnss.pos_sigma_m`, `beta`, …).
    fn try_from(w: FederatedConfigWire) -> Result<Self, ConfigError> {
        check_aids(&w)?;
        let beta = check_beta(&w.aids, w.beta.as_ref())?;
        let (g, d, c) = (
            w.gnss.unwrap_or_default(),
            w.dvl.unwrap_or_default(),
            w.cns.unwrap_or_default(),
        );
        let f = |s: &'static str| move || s.to_owned();
        let imu = ImuErrors {
            gyro_bias_dph: positive(f("imu.gyro_bias_dph"), w.imu.gyro_bias_dph)?,
            accel_bias_ug: positive(f("imu.accel_bias_ug"), w.imu.accel_bias_ug)?,
            arw_deg_rthr: positive(f("imu.arw_deg_rthr"), w.imu.arw_deg_rthr)?,
            vrw_mps_rthr: positive(f("imu.vrw_mps_rthr"), w.imu.vrw_mps_rthr)?,
        };
        let mut att = [0.0; 3];
        for (i, a) in w.init.att_sigma_arcsec.iter().enumerate() {
            att[i] = positive(|| format!("init.att_sigma_arcsec[{i}]"), *a)?;
        }
        if !(w.p_md > 0.0 && w.p_md < 1.0) {
            return Err(ConfigError::new("p_md", "must be in (0, 1)"));
        }
        Ok(FederatedConfig {
            gnss_pos_sigma_m: positive(f("gnss.pos_sigma_m"), g.pos_sigma_m)?,
            gnss_vel_sigma_mps: positive(f("gnss.vel_sigma_mps"), g.vel_sigma_mps)?,
            dvl_vel_sigma_mps: positive(f("dvl.vel_sigma_mps"), d.vel_sigma_mps)?,
            cns_pos_sigma_m: positive(f("cns.pos_sigma_m"), c.pos_sigma_m)?,
            imu,
            init_att_sigma_arcsec: att,
            init_pos_sigma_m: positive(f("init.pos_sigma_m"), w.init.pos_sigma_m)?,
            init_vel_sigma_mps: positive(f("init.vel_sigma_mps"), w.init.vel_sigma_mps)?,
            beta,
            hal_m: positive(f("hal_m"), w.hal_m)?,
            p_md: w.p_md,
            aids: w.aids,
        })
    }
}

impl FederatedConfig {
    /// Parses and validates the `config` JSON, naming the field path of any error.
    pub fn from_json(value: &serde_json::Value) -> Result<Self, ConfigError> {
        Self::try_from(super::parse_config::<FederatedConfigWire>(value)?)
    }

    /// The initial error estimate: zero error, `P₀ = diag(att², vel², pos², ε², ∇²)` with the
    /// bias uncertainties of `imu`.
    pub fn initial_estimate(&self) -> ErrorEstimate {
        let arcsec = (1.0f64 / 3600.0).to_radians();
        let mut d = ErrorVector::zeros();
        for i in 0..3 {
            d[ATT + i] = (self.init_att_sigma_arcsec[i] * arcsec).powi(2);
            d[VEL + i] = self.init_vel_sigma_mps.powi(2);
            d[POS + i] = self.init_pos_sigma_m.powi(2);
            d[GYRO + i] = self.imu.gyro_bias_rps().powi(2);
            d[ACC + i] = self.imu.accel_bias_mps2().powi(2);
        }
        StateEstimate {
            x: ErrorVector::zeros(),
            p: ErrorMatrix::from_diagonal(&d),
        }
    }
}

/// The corrected navigation solution on the wire: degrees, metres, m/s ENU.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FederatedSolution {
    /// Latitude, degrees.
    pub lat: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Ellipsoidal height, m.
    pub h: f64,
    /// Velocity east, north, up, m/s.
    pub vel: [f64; 3],
}

/// The `federated` monitor.
#[derive(Debug, Clone)]
pub struct FederatedMonitor {
    config: FederatedConfig,
    filter: FederatedFilter,
    bank: TestBank,
    hpl_test: usize,
    k_md: f64,
    lambda_det: DetectionNoncentrality,
    /// Per aid, `slope · sqrt(λ_det)` from its last update while fused.
    hpl2: [Option<f64>; MAX_AIDS],
    /// Time of the last INS epoch.
    last_t: Option<f64>,
    outputs: Outputs,
}

impl FederatedMonitor {
    /// Builds the monitor: one test per aid (gnss: dof 6, also 3) and the `hpl` test.
    pub fn new(
        config: FederatedConfig,
        policy: PolicyConfig,
        spec: ThresholdSpec,
    ) -> Result<Self, BuildError> {
        let tests: Vec<(&str, u32)> = config
            .aids
            .iter()
            .map(|a| {
                let dof = match a {
                    Aid::Gnss => 6,
                    Aid::Dvl => 3,
                    Aid::Cns => 2,
                };
                (a.as_str(), dof)
            })
            .collect();
        let mut bank = TestBank::new(&tests, spec, policy)?;
        if let Some(i) = config.aids.iter().position(|&a| a == Aid::Gnss) {
            bank.add_dofs(i, &[3])?;
        }
        let hpl_test = bank.add_fixed("hpl", 2, config.hal_m, PolicyConfig::Classic);
        let filter = FederatedFilter::new(&config.beta, config.initial_estimate())
            .map_err(|e| ConfigError::new("beta", e.to_string()))?;
        let k_md = hpl::k_md(config.p_md).map_err(|e| ConfigError::new("p_md", e.to_string()))?;
        let lambda_det = DetectionNoncentrality::new(config.p_md)
            .map_err(|e| ConfigError::new("p_md", e.to_string()))?;
        Ok(FederatedMonitor {
            config,
            filter,
            bank,
            hpl_test,
            k_md,
            lambda_det,
            hpl2: [None; MAX_AIDS],
            last_t: None,
            outputs: Outputs::Federated {
                solution: None,
                hpl: None,
                isolated: Vec::new(),
            },
        })
    }

    /// The configuration.
    pub fn config(&self) -> &FederatedConfig {
        &self.config
    }

    /// The federated filter (fused and local estimates).
    pub fn filter(&self) -> &FederatedFilter {
        &self.filter
    }

    /// This epoch's measurement for `aid`, when the epoch carries it.
    fn observation(&self, aid: Aid, nav: &NavSolution, epoch: &Epoch) -> Option<Observation> {
        let c = &self.config;
        match aid {
            Aid::Gnss => epoch.gnss.as_ref().map(|g| {
                let fix = Lla {
                    lat: g.lat,
                    lon: g.lon,
                    h: g.h,
                };
                match g.vel {
                    Some(v) => aiding::gnss_velocity_position(
                        nav,
                        &fix,
                        &Vector3::from(v),
                        c.gnss_pos_sigma_m,
                        c.gnss_vel_sigma_mps,
                    )
                    .into(),
                    None => aiding::gnss_position(nav, &fix, c.gnss_pos_sigma_m).into(),
                }
            }),
            Aid::Dvl => epoch
                .dvl_vel_b
                .map(|v| aiding::dvl_velocity(nav, &Vector3::from(v), c.dvl_vel_sigma_mps).into()),
            Aid::Cns => epoch
                .cns
                .as_ref()
                .map(|f| aiding::cns_position(nav, f.lat, f.lon, c.cns_pos_sigma_m).into()),
        }
    }

    fn isolated(&self) -> Vec<&'static str> {
        self.config
            .aids
            .iter()
            .enumerate()
            .filter(|&(i, _)| self.bank.slots()[i].policy.health() == Health::Isolated)
            .map(|(_, a)| a.as_str())
            .collect()
    }

    /// The transition since the last INS epoch and whether the filter restarts (module
    /// doc, Epochs): a first epoch, a gap over [`MAX_GAP_S`] or time going back restarts
    /// with `Φ = I`, `Q = 0`; otherwise [`federated::ins_transition`] over `dt`.
    fn transition(
        &self,
        nav: &NavSolution,
        t: f64,
    ) -> Result<(LinearTransition<nalgebra::U15>, bool), StepError> {
        let dt = self.last_t.map(|last| t - last);
        let restart = !matches!(dt, Some(d) if (0.0..=MAX_GAP_S).contains(&d));
        let trans = if restart {
            LinearTransition {
                f: ErrorMatrix::identity(),
                q: ErrorMatrix::zeros(),
            }
        } else {
            federated::ins_transition(nav, &self.config.imu, dt.unwrap_or(0.0))
                .map_err(|_| FilterError::NonFinite("prediction interval"))?
        };
        Ok((trans, restart))
    }

    /// The federated filter's epoch, its state left pending. Each aid's test goes through
    /// its policy with [`TestBank::preview`]; the previews are returned for the commit, so
    /// nothing in the bank changes until the whole step has succeeded.
    fn filter_step(
        &mut self,
        trans: &LinearTransition<nalgebra::U15>,
        obs: &[Option<Observation>],
        restart: bool,
    ) -> Result<(federated::FederatedStep, Previews), StepError> {
        let mut pending: Previews = [None, None, None];
        let mut threshold_error: Option<ThresholdError> = None;
        let bank = &self.bank;
        let decide = |i: usize, test: Option<LocalTest>| match test {
            Some(t) => match bank.preview(i, t.statistic, t.dof) {
                Ok((outcome, state)) => {
                    let d = outcome.decision;
                    pending[i] = Some((outcome, state));
                    d
                }
                Err(e) => {
                    threshold_error = Some(e);
                    bank.idle(i)
                }
            },
            None => bank.idle(i),
        };
        let step = if restart {
            let initial = self.config.initial_estimate();
            self.filter.restart_step(&initial, trans, obs, decide)?
        } else {
            self.filter.step(trans, obs, decide)?
        };
        if let Some(e) = threshold_error {
            return Err(e.into());
        }
        Ok((step, pending))
    }

    /// The protection level (module doc, HPL): `HPL₁ = k_md σ_h` from the fused `P_g`,
    /// `HPL₂ = max_i` of the aids' `terms` ([`FederatedMonitor::hpl2_terms`]), combined by
    /// [`hpl::combine`] and previewed against the alert limit on the `hpl` test.
    fn protection_level(
        &self,
        master: &ErrorEstimate,
        terms: [Option<f64>; MAX_AIDS],
    ) -> Result<HplStep, StepError> {
        let p_h = Matrix2::new(
            master.p[(POS, POS)],
            master.p[(POS, POS + 1)],
            master.p[(POS + 1, POS)],
            master.p[(POS + 1, POS + 1)],
        );
        let hpl1 = self.k_md * hpl::sigma_h(&p_h);
        let n = self.config.aids.len();
        let hpl2_max = terms[..n].iter().flatten().fold(0.0_f64, |m, &v| m.max(v));
        let value = hpl::combine(hpl1, hpl2_max);
        let (outcome, state) = self.bank.preview(self.hpl_test, value, 2)?;
        Ok(HplStep {
            value,
            terms,
            outcome,
            state,
        })
    }

    /// Per aid (`aids`, one step per configured aid), `slope_i sqrt(λ_det,i)` with
    /// `λ_det,i` for the dof and threshold its test used: renewed when the aid updates
    /// while fused, kept from `previous` while it is fused without an update, dropped when
    /// it is left out of fusion. A restart forgets the slopes of the old solution.
    fn hpl2_terms(
        lambda_det: &mut DetectionNoncentrality,
        previous: [Option<f64>; MAX_AIDS],
        aids: &[federated::AidStep],
        pending: &Previews,
        restart: bool,
    ) -> Result<[Option<f64>; MAX_AIDS], StepError> {
        let mut hpl2 = if restart { [None; MAX_AIDS] } else { previous };
        for (i, a) in aids.iter().enumerate() {
            if !a.fused {
                hpl2[i] = None;
            } else if let (Some(slope), Some((outcome, _))) = (a.slope, &pending[i]) {
                let s = outcome.statistic;
                let l = lambda_det.get(s.dof, s.threshold).map_err(|e| match e {
                    HplError::Chi2(c) => StepError::Threshold(c.into()),
                    _ => StepError::Filter(FilterError::NotPositiveDefinite),
                })?;
                hpl2[i] = Some(slope * l.sqrt());
            }
        }
        Ok(hpl2)
    }

    /// Makes the step current: the aids' and the `hpl` test's policy states, the filter's
    /// pending state (a restart included), the HPL terms, the time and the outputs.
    /// Returns the epoch's test outcomes, aids first.
    fn commit(
        &mut self,
        t: f64,
        pending: Previews,
        hpl: HplStep,
        solution: FederatedSolution,
    ) -> Vec<TestOutcome> {
        let n = self.config.aids.len();
        let mut tests = Vec::with_capacity(n + 1);
        for (i, p) in pending.into_iter().enumerate().take(n) {
            if let Some((outcome, state)) = p {
                self.bank.commit(i, state);
                tests.push(outcome);
            }
        }
        self.bank.commit(self.hpl_test, hpl.state);
        tests.push(hpl.outcome);
        self.filter.commit();
        self.hpl2 = hpl.terms;
        self.last_t = Some(t);
        self.outputs = Outputs::Federated {
            solution: Some(solution),
            hpl: Some(hpl.value),
            isolated: self.isolated(),
        };
        tests
    }
}

/// Each aid's previewed test outcome and policy state, committed with the step.
type Previews = [Option<(TestOutcome, PolicyState)>; MAX_AIDS];

/// One epoch's protection level, committed with the step.
struct HplStep {
    /// The HPL, m.
    value: f64,
    /// Per aid, its `HPL₂` term.
    terms: [Option<f64>; MAX_AIDS],
    /// The `hpl` test's outcome and policy state.
    outcome: TestOutcome,
    state: PolicyState,
}

/// The corrected solution: the INS minus the fused error estimate (open loop), on the
/// wire in degrees; a non-finite one fails the step.
fn corrected_solution(
    nav: &NavSolution,
    master: &ErrorEstimate,
) -> Result<FederatedSolution, StepError> {
    let x = &master.x;
    let dp = Vector3::new(x[POS], x[POS + 1], x[POS + 2]);
    let fixed = geo::apply_offset(&nav.lla, &-dp);
    let vel = nav.vel - Vector3::new(x[VEL], x[VEL + 1], x[VEL + 2]);
    if !(fixed.lat.is_finite() && fixed.lon.is_finite() && vel.iter().all(|v| v.is_finite())) {
        return Err(FilterError::NonFinite("corrected solution").into());
    }
    Ok(FederatedSolution {
        lat: fixed.lat.to_degrees(),
        lon: fixed.lon.to_degrees(),
        h: fixed.h,
        vel: [vel.x, vel.y, vel.z],
    })
}

impl Monitor for FederatedMonitor {
    fn kind(&self) -> MonitorKind {
        MonitorKind::Federated
    }

    fn tests(&self) -> &TestBank {
        &self.bank
    }

    fn tests_mut(&mut self) -> &mut TestBank {
        &mut self.bank
    }

    /// Every block is optional and already validated (finite, in range) at the edge: an aid
    /// block without `ins` is ignored, not refused, and so are blocks of unconfigured aids.
    /// Nothing here can make an epoch unusable before the step; a polar INS latitude
    /// (|L| = 90°, where east is undefined) fails the step numerically and changes nothing.
    fn check_epoch(&self, _name: &str, _epoch: &Epoch) -> Result<(), EpochError> {
        Ok(())
    }

    /// One INS epoch: transition, the aids' measurements, the filter with the policies,
    /// the protection level and the corrected solution, then the commit (module doc).
    /// Any failure leaves the monitor as it was.
    fn step(&mut self, epoch: &Epoch) -> Result<MonitorReport, StepError> {
        let Some(ins) = &epoch.ins else {
            return Ok(MonitorReport {
                tests: Vec::new(),
                outputs: self.outputs.clone(),
                integrity: None,
            });
        };
        let nav = NavSolution::from_ins(ins);
        let (trans, restart) = self.transition(&nav, epoch.t)?;
        let n = self.config.aids.len();
        let mut obs: [Option<Observation>; MAX_AIDS] = [None, None, None];
        for (i, &aid) in self.config.aids.iter().enumerate() {
            obs[i] = self.observation(aid, &nav, epoch);
        }
        let (step, pending) = self.filter_step(&trans, &obs[..n], restart)?;
        let Some(next) = self.filter.pending() else {
            return Err(FilterError::NonFinite("federated step").into());
        };
        let terms = Self::hpl2_terms(
            &mut self.lambda_det,
            self.hpl2,
            &step.aids[..n],
            &pending,
            restart,
        )?;
        let hpl = self.protection_level(&next.master, terms)?;
        let solution = corrected_solution(&nav, &next.master)?;
        let tests = self.commit(epoch.t, pending, hpl, solution);
        Ok(MonitorReport {
            tests,
            outputs: self.outputs.clone(),
            integrity: None,
        })
    }

    fn reset(&mut self) {
        self.filter.restart(self.config.initial_estimate());
        self.bank.reset();
        self.hpl2 = [None; MAX_AIDS];
        self.last_t = None;
        self.outputs = Outputs::Federated {
            solution: None,
            hpl: None,
            isolated: Vec::new(),
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::epoch::{CnsBlock, GnssBlock, InsBlock};
    use crate::filter::federated::ins_transition;
    use nalgebra::{Rotation3, SVector};
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;
    use serde_json::{Value, json};

    fn all_aids() -> Value {
        json!({"aids": ["gnss", "dvl", "cns"]})
    }

    fn monitor(config: Value, policy: PolicyConfig, spec: ThresholdSpec) -> FederatedMonitor {
        FederatedMonitor::new(FederatedConfig::from_json(&config).unwrap(), policy, spec).unwrap()
    }

    #[test]
    fn every_field_but_aids_defaults_to_seed_004() {
        let c = FederatedConfig::from_json(&all_aids()).unwrap();
        assert_eq!(c.aids, vec![Aid::Gnss, Aid::Dvl, Aid::Cns]);
        assert_eq!((c.gnss_pos_sigma_m, c.gnss_vel_sigma_mps), (10.0, 0.1));
        assert_eq!((c.dvl_vel_sigma_mps, c.cns_pos_sigma_m), (0.1, 450.0));
        assert_eq!(c.imu, ImuErrors::default());
        assert_eq!(c.init_att_sigma_arcsec, [5.0, 5.0, 30.0]);
        assert_eq!((c.init_pos_sigma_m, c.init_vel_sigma_mps), (10.0, 0.1));
        assert_eq!(c.beta, vec![1.0 / 3.0; 3]);
        assert_eq!((c.hal_m, c.p_md), (DEFAULT_HAL_M, 1e-3));
        let p0 = c.initial_estimate().p;
        let arcsec = (1.0f64 / 3600.0).to_radians();
        assert!((p0[(ATT + 2, ATT + 2)].sqrt() - 30.0 * arcsec).abs() < 1e-18);
        assert_eq!(p0[(POS, POS)], 100.0);
        let c = FederatedConfig::from_json(&json!({
            "aids": ["cns", "gnss"],
            "gnss": {"pos_sigma_m": 3},
            "beta": {"gnss": 0.75, "cns": 0.25},
            "imu": {"gyro_bias_dph": 0.01},
            "init": {"att_sigma_arcsec": [10, 10, 60]},
            "hal_m": 40,
            "p_md": 1e-4
        }))
        .unwrap();
        assert_eq!(c.aids, vec![Aid::Cns, Aid::Gnss]);
        assert_eq!(c.beta, vec![0.25, 0.75], "β follows the order of aids");
        assert_eq!(
            (c.gnss_pos_sigma_m, c.imu.gyro_bias_dph, c.hal_m),
            (3.0, 0.01, 40.0)
        );
    }

    #[test]
    fn invalid_configs_are_refused_naming_the_field() {
        let cases = [
            (json!({}), "aids"),
            (json!({"aids": []}), "aids"),
            (json!({"aids": ["gnss", "radar"]}), "aids[1]"),
            (json!({"aids": ["gnss", "gnss"]}), "aids[1]"),
            (
                json!({"aids": ["gnss"], "gnss": {"pos_sigma_m": -1}}),
                "gnss.pos_sigma_m",
            ),
            (
                json!({"aids": ["gnss"], "gnss": {"pos_sigma": 1}}),
                "gnss.pos_sigma",
            ),
            (
                json!({"aids": ["gnss"], "dvl": {"vel_sigma_mps": 1}}),
                "dvl",
            ),
            (
                json!({"aids": ["dvl"], "dvl": {"vel_sigma_mps": "x"}}),
                "dvl.vel_sigma_mps",
            ),
            (
                json!({"aids": ["cns"], "imu": {"arw_deg_rthr": 0}}),
                "imu.arw_deg_rthr",
            ),
            (
                json!({"aids": ["cns"], "init": {"att_sigma_arcsec": [1, 2]}}),
                "init.att_sigma_arcsec",
            ),
            (
                json!({"aids": ["cns"], "init": {"att_sigma_arcsec": [1, 2, 0]}}),
                "init.att_sigma_arcsec[2]",
            ),
            (
                json!({"aids": ["gnss", "cns"], "beta": {"gnss": 0.5, "cns": 0.6}}),
                "beta",
            ),
            (
                json!({"aids": ["gnss", "cns"], "beta": {"gnss": 0.5}}),
                "beta",
            ),
            (
                json!({"aids": ["gnss"], "beta": {"gnss": 0.5, "dvl": 0.5}}),
                "beta.dvl",
            ),
            (json!({"aids": ["gnss"], "beta": {"gnss": 2}}), "beta.gnss"),
            (json!({"aids": ["gnss"], "hal_m": 0}), "hal_m"),
            (json!({"aids": ["gnss"], "p_md": 1}), "p_md"),
            (json!({"aids": ["gnss"], "extra": 1}), "extra"),
        ];
        for (config, field) in cases {
            let e = FederatedConfig::from_json(&config).unwrap_err();
            assert_eq!(e.field, field, "{config}: {e}");
        }
        let spec = MonitorSpecForTest::build(json!({"aids": ["gnss"], "hal_m": -3}));
        assert_eq!(
            spec.err().map(|e| e.to_string()).unwrap_or_default(),
            "config.hal_m: must be a finite number > 0"
        );
    }

    /// `monitor::build` as the REST layer calls it.
    struct MonitorSpecForTest;

    impl MonitorSpecForTest {
        fn build(config: Value) -> Result<Box<dyn Monitor>, super::super::BuildError> {
            super::super::build(
                &super::super::MonitorSpec {
                    kind: MonitorKind::Federated,
                    config: super::super::MonitorConfig::parse(MonitorKind::Federated, &config)?,
                    policy: PolicyConfig::counters_default(),
                    threshold: ThresholdSpec::Threshold(20.0),
                },
                &super::super::NoModels,
            )
        }
    }

    #[test]
    fn one_test_per_configured_aid_and_the_hpl_test() {
        let m = monitor(
            json!({"aids": ["dvl", "gnss"], "hal_m": 55}),
            PolicyConfig::counters_default(),
            ThresholdSpec::PFa(0.002),
        );
        let slots = m.tests().slots();
        let names: Vec<_> = slots.iter().map(|s| (&*s.name, s.dof)).collect();
        assert_eq!(names, vec![("dvl", 3), ("gnss", 6), ("hpl", 2)]);
        assert!((slots[1].threshold_for(3).unwrap() - 14.7955).abs() < 1e-4);
        assert_eq!(slots[2].threshold, 55.0);
        assert_eq!(slots[2].policy.config(), PolicyConfig::Classic);
        assert!(MonitorSpecForTest::build(all_aids()).is_ok());
    }

    /// A ship at 30° N sailing north-east at 5 m/s, with an INS whose error follows the
    /// monitor's own model (seeded), and noisy aids.
    struct Ship {
        rng: StdRng,
        t: f64,
        dt: f64,
        truth: Lla,
        vel: Vector3<f64>,
        c_bn: nalgebra::Matrix3<f64>,
        error: ErrorVector,
        imu: ImuErrors,
    }

    impl Ship {
        fn new(seed: u64, dt: f64) -> Self {
            let mut rng = StdRng::seed_from_u64(seed);
            let p0 = FederatedConfig::from_json(&all_aids())
                .unwrap()
                .initial_estimate()
                .p;
            let error = ErrorVector::from_fn(|i, _| {
                p0[(i, i)].sqrt() * rng.sample::<f64, _>(StandardNormal)
            });
            let v = 5.0 * std::f64::consts::FRAC_1_SQRT_2;
            Ship {
                rng,
                t: 0.0,
                dt,
                truth: Lla {
                    lat: 30f64.to_radians(),
                    lon: 120f64.to_radians(),
                    h: 0.0,
                },
                vel: Vector3::new(v, v, 0.0),
                c_bn: geo::dcm_body_to_nav(0.0, 0.0, 45f64.to_radians()),
                error,
                imu: ImuErrors::default(),
            }
        }

        fn gauss(&mut self) -> f64 {
            self.rng.sample(StandardNormal)
        }

        fn ins(&self) -> InsBlock {
            let dp = Vector3::new(self.error[POS], self.error[POS + 1], self.error[POS + 2]);
            let phi = Vector3::new(self.error[ATT], self.error[ATT + 1], self.error[ATT + 2]);
            let c = Rotation3::new(-phi).into_inner() * self.c_bn;
            let p = geo::apply_offset(&self.truth, &dp);
            let v =
                self.vel + Vector3::new(self.error[VEL], self.error[VEL + 1], self.error[VEL + 2]);
            InsBlock {
                lat: p.lat,
                lon: p.lon,
                h: p.h,
                vel: [v.x, v.y, v.z],
                att: geo::euler_from_dcm(&c),
                f_b: None,
            }
        }

        /// The next epoch: truth and INS error advance, every aid reports.
        fn next(&mut self, gnss_offset: Vector3<f64>) -> Epoch {
            self.t += self.dt;
            self.truth = geo::apply_offset(&self.truth, &(self.vel * self.dt));
            let nav = NavSolution::from_ins(&self.ins());
            let trans = ins_transition(&nav, &self.imu, self.dt).unwrap();
            let g = crate::filter::ins::noise_input(&nav);
            let w = SVector::<f64, 6>::from_fn(|i, _| {
                let psd = if i < 3 {
                    self.imu.gyro_noise_psd()
                } else {
                    self.imu.accel_noise_psd()
                };
                (psd * self.dt).sqrt() * self.rng.sample::<f64, _>(StandardNormal)
            });
            self.error = trans.f * self.error + g * w;
            let noise = Vector3::new(self.gauss(), self.gauss(), self.gauss()) * 10.0 + gnss_offset;
            let fix = geo::apply_offset(&self.truth, &noise);
            let gv = self.vel + Vector3::new(self.gauss(), self.gauss(), self.gauss()) * 0.1;
            let dvl = self.c_bn.transpose() * self.vel
                + Vector3::new(self.gauss(), self.gauss(), self.gauss()) * 0.1;
            let cns_noise = Vector3::new(self.gauss() * 450.0, self.gauss() * 450.0, 0.0);
            let cns = geo::apply_offset(&self.truth, &cns_noise);
            Epoch {
                t: self.t,
                ins: Some(self.ins()),
                gnss: Some(GnssBlock {
                    lat: fix.lat,
                    lon: fix.lon,
                    h: fix.h,
                    vel: Some([gv.x, gv.y, gv.z]),
                }),
                dvl_vel_b: Some([dvl.x, dvl.y, dvl.z]),
                cns: Some(CnsBlock {
                    lat: cns.lat,
                    lon: cns.lon,
                }),
                ..Default::default()
            }
        }
    }

    fn outputs(r: &MonitorReport) -> (FederatedSolution, f64, Vec<&'static str>) {
        match &r.outputs {
            Outputs::Federated {
                solution: Some(s),
                hpl: Some(h),
                isolated,
            } => (*s, *h, isolated.clone()),
            other => panic!("unexpected outputs {other:?}"),
        }
    }

    #[test]
    fn fault_free_ship_is_consistent_quiet_and_inside_its_protection_level() {
        // 1,500 s at 1 Hz, every aid every epoch, counters policy at p_fa 1e-3 per test.
        let mut ship = Ship::new(21, 1.0);
        let mut m = monitor(
            all_aids(),
            PolicyConfig::counters_default(),
            ThresholdSpec::PFa(1e-3),
        );
        let epochs = 1500;
        let mut sums = [0.0; 3];
        let mut exceed = [0usize; 3];
        let mut worst_ratio: f64 = 0.0;
        let mut max_hpl: f64 = 0.0;
        for k in 0..epochs {
            let e = ship.next(Vector3::zeros());
            let r = m.step(&e).unwrap();
            let (sol, hpl, isolated) = outputs(&r);
            assert!(isolated.is_empty(), "epoch {k}: {isolated:?}");
            for o in &r.tests[..3] {
                sums[o.index] += o.statistic.value;
                exceed[o.index] += usize::from(o.statistic.exceeds());
            }
            // The corrected position against the truth, horizontally.
            let fixed = Lla {
                lat: sol.lat.to_radians(),
                lon: sol.lon.to_radians(),
                h: sol.h,
            };
            let err = geo::local_offset(&fixed, &ship.truth);
            if k >= 10 {
                worst_ratio = worst_ratio.max(err.xy().norm() / hpl);
                max_hpl = max_hpl.max(hpl);
            }
        }
        let k = f64::from(epochs);
        for (i, dof) in [6.0, 3.0, 2.0].into_iter().enumerate() {
            // Local filters carry P_g/β_i, so their NIS is at most χ²(m)'s mean, never above.
            let mean = sums[i] / k;
            assert!(
                mean < dof + 4.0 * (2.0 * dof / k).sqrt(),
                "test {i}: mean λ {mean}"
            );
            assert!(
                mean > 0.3 * dof,
                "test {i}: mean λ {mean} is implausibly small"
            );
            // Exceedances of a 1e-3 threshold: at most a handful in 1,500 (binomial, 1e-6 tail).
            assert!(exceed[i] <= 8, "test {i}: {} exceedances", exceed[i]);
        }
        assert!(
            worst_ratio < 1.0,
            "horizontal error reached {worst_ratio} × HPL"
        );
        assert!(max_hpl < DEFAULT_HAL_M, "HPL {max_hpl} m");
    }

    #[test]
    fn gnss_jump_is_suspect_then_isolated_then_readmitted_after_it_ends() {
        // Seed 004's fault: 0.02′ of latitude and longitude (≈ 37 m and 32 m) for 120 s.
        let mut ship = Ship::new(22, 1.0);
        let mut m = monitor(
            all_aids(),
            PolicyConfig::counters_default(),
            ThresholdSpec::Threshold(20.0),
        );
        let jump = Vector3::new(32.1, 36.9, 0.0);
        let (onset, end) = (300, 420);
        let mut health = Vec::new();
        for k in 0..600 {
            let offset = if (onset..end).contains(&k) {
                jump
            } else {
                Vector3::zeros()
            };
            let r = m.step(&ship.next(offset)).unwrap();
            let gnss = r.tests.iter().find(|o| &*o.name == "gnss").unwrap();
            health.push(gnss.decision.health);
            let (_, _, isolated) = outputs(&r);
            assert_eq!(
                isolated.contains(&"gnss"),
                gnss.decision.health == Health::Isolated
            );
        }
        assert!(health[..onset].iter().all(|&h| h == Health::Healthy));
        let suspect = (onset..).find(|&k| health[k] != Health::Healthy).unwrap();
        // Out of updating within 2 GNSS epochs of onset; isolated after N2 + 1 = 6
        // exceedances, allowing one quiet epoch between them. (The jump is only ≈ 2.6 σ of the
        // 10 m GNSS per axis: λ ≈ 25 against T_D = 20, so single epochs can pass.)
        assert!(suspect <= onset + 2, "suspect at {suspect}");
        let isolated = (onset..).find(|&k| health[k] == Health::Isolated).unwrap();
        assert!(isolated <= suspect + 5 + 1, "isolated at {isolated}");
        let back = (isolated..)
            .find(|&k| health[k] == Health::Healthy)
            .unwrap();
        assert!(
            back >= end,
            "readmitted at {back}, before the fault ended at {end}"
        );
        assert!(back <= end + 12, "readmitted only at {back}");
        // Fault-free again: an occasional exceedance (p_fa of χ²(6) at 20 is 0.28 %) may make
        // it suspect, never isolated.
        assert!(health[back..].iter().all(|&h| h != Health::Isolated));
    }

    #[test]
    fn hpl_above_the_alert_limit_raises_the_hpl_alarm() {
        let mut ship = Ship::new(23, 1.0);
        let mut m = monitor(
            json!({"aids": ["gnss", "dvl", "cns"], "hal_m": 5}),
            PolicyConfig::counters_default(),
            ThresholdSpec::Threshold(20.0),
        );
        let r = m.step(&ship.next(Vector3::zeros())).unwrap();
        let hpl = r.tests.iter().find(|o| &*o.name == "hpl").unwrap();
        let (_, value, _) = outputs(&r);
        assert_eq!(hpl.statistic.value, value);
        assert_eq!((hpl.statistic.threshold, hpl.statistic.dof), (5.0, 2));
        assert!(value > 5.0);
        assert_eq!(hpl.decision.health, Health::Isolated);
        assert_eq!(hpl.previous, Health::Healthy);
    }

    #[test]
    fn epochs_without_ins_are_ignored_and_gnss_without_velocity_has_dof_3() {
        let mut ship = Ship::new(24, 0.1);
        let mut m = monitor(
            all_aids(),
            PolicyConfig::counters_default(),
            ThresholdSpec::PFa(0.002),
        );
        let mut e = ship.next(Vector3::zeros());
        let aid_only = Epoch {
            ins: None,
            ..e.clone()
        };
        let r = m.step(&aid_only).unwrap();
        assert!(r.tests.is_empty());
        assert_eq!(
            r.outputs,
            Outputs::Federated {
                solution: None,
                hpl: None,
                isolated: vec![]
            }
        );
        assert!(m.check_epoch("fed", &aid_only).is_ok());
        if let Some(g) = &mut e.gnss {
            g.vel = None;
        }
        e.dvl_vel_b = None;
        let r = m.step(&e).unwrap();
        let names: Vec<_> = r
            .tests
            .iter()
            .map(|o| (&*o.name, o.statistic.dof))
            .collect();
        assert_eq!(names, vec![("gnss", 3), ("cns", 2), ("hpl", 2)]);
        assert!((r.tests[0].statistic.threshold - 14.7955).abs() < 1e-4);
        let state = m.filter().state().clone();
        let r = m.step(&aid_only).unwrap();
        assert!(r.tests.is_empty());
        assert_eq!(m.filter().state(), &state);
        let (sol, hpl, _) = outputs(&r);
        assert!(sol.lat > 29.9 && hpl > 0.0, "the last outputs are repeated");
    }

    #[test]
    fn a_failed_step_leaves_the_monitor_untouched() {
        let mut ship = Ship::new(25, 1.0);
        let mut m = monitor(
            all_aids(),
            PolicyConfig::counters_default(),
            ThresholdSpec::Threshold(20.0),
        );
        for _ in 0..5 {
            m.step(&ship.next(Vector3::zeros())).unwrap();
        }
        let state = m.filter().state().clone();
        let policies: Vec<_> = m.tests().slots().iter().map(|s| s.policy.clone()).collect();
        let outputs_before = m.outputs.clone();
        // An absurd INS velocity overflows the prediction.
        let mut bad = ship.next(Vector3::zeros());
        if let Some(ins) = &mut bad.ins {
            ins.vel = [1e300, 0.0, 0.0];
        }
        assert!(m.step(&bad).is_err());
        assert_eq!(m.filter().state(), &state);
        let after: Vec<_> = m.tests().slots().iter().map(|s| s.policy.clone()).collect();
        assert_eq!(after, policies);
        assert_eq!(m.outputs, outputs_before);
        // And it goes on from where it was.
        assert!(m.step(&ship.next(Vector3::zeros())).is_ok());
    }

    #[test]
    fn a_long_gap_restarts_the_filter_and_a_repeated_instant_predicts_nothing() {
        let mut ship = Ship::new(26, 1.0);
        let mut m = monitor(
            json!({"aids": ["gnss"]}),
            PolicyConfig::Classic,
            ThresholdSpec::PFa(0.002),
        );
        for _ in 0..20 {
            m.step(&ship.next(Vector3::zeros())).unwrap();
        }
        let converged = m.filter().master().p;
        let mut e = ship.next(Vector3::zeros());
        e.gnss = None;
        e.dvl_vel_b = None;
        e.cns = None;
        let same = Epoch {
            t: e.t - 1.0,
            ..e.clone()
        };
        // The same instant again (dt = 0): no prediction, nothing to update.
        let t_last = m.last_t.unwrap();
        m.step(&Epoch { t: t_last, ..same }).unwrap();
        assert_eq!(m.filter().master().p, converged);
        e.t += MAX_GAP_S + 10.0;
        m.step(&e).unwrap();
        let p0 = m.config().initial_estimate().p;
        assert_eq!(m.filter().master().p, p0);
    }

    #[test]
    fn outputs_serialise_in_wire_units() {
        let mut ship = Ship::new(27, 1.0);
        let mut m = monitor(
            all_aids(),
            PolicyConfig::counters_default(),
            ThresholdSpec::Threshold(20.0),
        );
        let r = m.step(&ship.next(Vector3::zeros())).unwrap();
        let v = serde_json::to_value(&r.outputs).unwrap();
        let lat = v["solution"]["lat"].as_f64().unwrap();
        assert!((lat - 30.0).abs() < 0.01, "degrees on the wire: {v}");
        assert_eq!(v["solution"]["vel"].as_array().unwrap().len(), 3);
        assert!(v["hpl"].as_f64().unwrap() > 0.0);
        assert_eq!(v["isolated"], json!([]));
        m.reset();
        assert_eq!(m.filter().master(), &m.config().initial_estimate());
        assert!(m.last_t.is_none());
    }
}
