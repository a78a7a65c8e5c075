//! The `federated` monitor's config (docs/methods.md §M6, §M23, §M24): the wire form the
//! user writes ([`FederatedConfigWire`], every section optional with seed 004's values by
//! default), its validation into [`FederatedConfig`] (errors name the exact path, e.g.
//! `gnss.drift.windows[0]`), and the initial error estimate. Sits between the REST body
//! and [`super::FederatedMonitor`].

use serde::{Deserialize, Serialize};

use crate::detect::hpl;
use crate::epoch::Aid;
use crate::filter::federated::{self, ErrorEstimate, MAX_AIDS};
use crate::filter::ins::{ACC, ATT, ErrorMatrix, ErrorVector, GYRO, ImuErrors, POS, VEL};
use crate::filter::kalman::StateEstimate;
use crate::monitor::ConfigError;
use crate::monitor::guards::{self, DriftConfigWire, GuardConfig, StuckConfigWire};

use super::imu::{InputKind, StrapdownConfig, StrapdownSection};

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
    /// Longest convergence after a (re)start before integrity is judged anyway, s
    /// (docs/methods.md §M24). Default [`DEFAULT_CONVERGE_MAX_S`].
    pub converge_max_s: f64,
    /// Per aid in `aids` order: its drift and stuck tests (docs/methods.md §M23).
    pub guards: Vec<GuardConfig>,
    /// With `input: imu`, the strapdown front end (docs/methods.md §M31); `None`: a
    /// client's `ins` solution.
    pub strapdown: Option<StrapdownConfig>,
}

/// The `gnss` section of a `federated` config: noise (seed 004's values by default) and
/// the drift and stuck tests on its position innovation (docs/methods.md §M23).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GnssNoise {
    /// Position noise (1σ per axis), m.
    pub pos_sigma_m: f64,
    /// Velocity noise, m/s.
    pub vel_sigma_mps: f64,
    /// The `gnss.drift` test; absent: [`GNSS_DRIFT_DEFAULT_ON`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub drift: Option<DriftConfigWire>,
    /// The `gnss.stuck` test; absent: [`STUCK_DEFAULT_ON`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stuck: Option<StuckConfigWire>,
}

impl Default for GnssNoise {
    fn default() -> Self {
        GnssNoise {
            pos_sigma_m: 10.0,
            vel_sigma_mps: 0.1,
            drift: None,
            stuck: None,
        }
    }
}

/// The `dvl` section of a `federated` config.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DvlNoise {
    /// Velocity noise, m/s.
    pub vel_sigma_mps: f64,
    /// The `dvl.drift` test; absent: [`DVL_DRIFT_DEFAULT_ON`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub drift: Option<DriftConfigWire>,
    /// The `dvl.stuck` test; absent: [`STUCK_DEFAULT_ON`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stuck: Option<StuckConfigWire>,
}

impl Default for DvlNoise {
    fn default() -> Self {
        DvlNoise {
            vel_sigma_mps: 0.1,
            drift: None,
            stuck: None,
        }
    }
}

/// The `cns` section of a `federated` config.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CnsNoise {
    /// Position noise, m.
    pub pos_sigma_m: f64,
    /// The `cns.drift` test; absent: [`CNS_DRIFT_DEFAULT_ON`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub drift: Option<DriftConfigWire>,
    /// The `cns.stuck` test; absent: [`STUCK_DEFAULT_ON`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stuck: Option<StuckConfigWire>,
}

impl Default for CnsNoise {
    fn default() -> Self {
        CnsNoise {
            pos_sigma_m: 450.0,
            drift: None,
            stuck: None,
        }
    }
}

/// Whether `gnss.drift` runs when the `gnss` section has no `drift` block: on, since a
/// slow GNSS drift (spoofing) is the fault the per-epoch χ² lets grow to 50 m; measured
/// cost on the fault-free ship about 0.15 isolations and 2–3 warnings per hour
/// (docs/methods.md §M23, docs/experiments.md).
pub const GNSS_DRIFT_DEFAULT_ON: bool = true;
/// Whether `dvl.drift` runs when the `dvl` section has no `drift` block: on, since DVL
/// biases of 0.15–0.3 m/s pass the χ² test and pull the fused solution tens of metres
/// off (docs/methods.md §M6, known limit), while the drift test isolates them in seconds.
pub const DVL_DRIFT_DEFAULT_ON: bool = true;
/// Whether `cns.drift` runs when the `cns` section has no `drift` block: off, since at
/// 0.1 Hz and 450 m a 12-fix window spans two minutes and adds warnings without a
/// fault it catches earlier than the χ² test.
pub const CNS_DRIFT_DEFAULT_ON: bool = false;
/// Whether an aid's `stuck` test runs when its section has no `stuck` block: on, at its
/// own p_fa of 1e-6 it is silent on healthy data.
pub const STUCK_DEFAULT_ON: bool = true;

/// A section's `drift` block, or the default one (`on`: enabled with the defaults).
fn drift_or(block: &Option<DriftConfigWire>, on: bool) -> DriftConfigWire {
    match block {
        Some(d) => d.clone(),
        None if on => DriftConfigWire::default(),
        None => DriftConfigWire::disabled(),
    }
}

/// A section's `stuck` block, or the default one.
fn stuck_or(block: &Option<StuckConfigWire>, on: bool) -> StuckConfigWire {
    match block {
        Some(s) => s.clone(),
        None if on => StuckConfigWire::default(),
        None => StuckConfigWire::disabled(),
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
    /// Bias correlation time (first-order Gauss–Markov), s; absent: random constants.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bias_tau_s: Option<f64>,
    /// Gyro bias random walk, °/h/√h.
    pub gyro_bias_walk_dph_rthr: f64,
    /// Accelerometer bias random walk, µg/√h.
    pub accel_bias_walk_ug_rthr: f64,
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
            bias_tau_s: e.bias_tau_s,
            gyro_bias_walk_dph_rthr: e.gyro_bias_walk_dph_rthr,
            accel_bias_walk_ug_rthr: e.accel_bias_walk_ug_rthr,
        }
    }
}

/// A finite number ≥ 0 at `field`.
fn non_negative(field: &str, x: f64) -> Result<f64, ConfigError> {
    if x.is_finite() && x >= 0.0 {
        Ok(x)
    } else {
        Err(ConfigError::new(field, "must be a finite number >= 0"))
    }
}

/// The `imu` section validated into [`ImuErrors`].
fn imu_errors(s: &ImuSection) -> Result<ImuErrors, ConfigError> {
    let f = |name: &'static str| move || name.to_owned();
    Ok(ImuErrors {
        gyro_bias_dph: positive(f("imu.gyro_bias_dph"), s.gyro_bias_dph)?,
        accel_bias_ug: positive(f("imu.accel_bias_ug"), s.accel_bias_ug)?,
        arw_deg_rthr: positive(f("imu.arw_deg_rthr"), s.arw_deg_rthr)?,
        vrw_mps_rthr: positive(f("imu.vrw_mps_rthr"), s.vrw_mps_rthr)?,
        bias_tau_s: s
            .bias_tau_s
            .map(|tau| positive(f("imu.bias_tau_s"), tau))
            .transpose()?,
        gyro_bias_walk_dph_rthr: non_negative(
            "imu.gyro_bias_walk_dph_rthr",
            s.gyro_bias_walk_dph_rthr,
        )?,
        accel_bias_walk_ug_rthr: non_negative(
            "imu.accel_bias_walk_ug_rthr",
            s.accel_bias_walk_ug_rthr,
        )?,
    })
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
    /// Longest convergence after a (re)start before integrity is judged anyway, s
    /// (docs/methods.md §M24).
    #[serde(default = "default_converge_max_s")]
    pub converge_max_s: f64,
    /// Where the INS solution comes from: `ins` (default) or `imu`.
    #[serde(default, skip_serializing_if = "is_ins")]
    pub input: InputKind,
    /// The strapdown front end (only with `input: imu`; defaults when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub strapdown: Option<StrapdownSection>,
}

fn is_ins(k: &InputKind) -> bool {
    *k == InputKind::Ins
}

/// Default longest convergence, s: seed 004's filter converges from its initial errors in
/// about 150 s (docs/experiments.md), and within seconds below the default HAL; a filter
/// still above the HAL after 300 s is not converging but unavailable.
pub const DEFAULT_CONVERGE_MAX_S: f64 = 300.0;

fn default_hal_m() -> f64 {
    DEFAULT_HAL_M
}

fn default_p_md() -> f64 {
    hpl::DEFAULT_P_MD
}

fn default_converge_max_s() -> f64 {
    DEFAULT_CONVERGE_MAX_S
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
            converge_max_s: DEFAULT_CONVERGE_MAX_S,
            input: InputKind::Ins,
            strapdown: None,
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
            w.gnss.clone().unwrap_or_default(),
            w.dvl.clone().unwrap_or_default(),
            w.cns.clone().unwrap_or_default(),
        );
        let guards = w
            .aids
            .iter()
            .map(|aid| match aid {
                Aid::Gnss => guards::validate(
                    "gnss",
                    &drift_or(&g.drift, GNSS_DRIFT_DEFAULT_ON),
                    &stuck_or(&g.stuck, STUCK_DEFAULT_ON),
                ),
                Aid::Dvl => guards::validate(
                    "dvl",
                    &drift_or(&d.drift, DVL_DRIFT_DEFAULT_ON),
                    &stuck_or(&d.stuck, STUCK_DEFAULT_ON),
                ),
                Aid::Cns => guards::validate(
                    "cns",
                    &drift_or(&c.drift, CNS_DRIFT_DEFAULT_ON),
                    &stuck_or(&c.stuck, STUCK_DEFAULT_ON),
                ),
            })
            .collect::<Result<Vec<_>, _>>()?;
        let f = |s: &'static str| move || s.to_owned();
        let imu = imu_errors(&w.imu)?;
        let mut att = [0.0; 3];
        for (i, a) in w.init.att_sigma_arcsec.iter().enumerate() {
            att[i] = positive(|| format!("init.att_sigma_arcsec[{i}]"), *a)?;
        }
        if !(w.p_md > 0.0 && w.p_md < 1.0) {
            return Err(ConfigError::new("p_md", "must be in (0, 1)"));
        }
        let converge_max_s = positive(f("converge_max_s"), w.converge_max_s)?;
        let strapdown = match (w.input, w.strapdown) {
            (InputKind::Imu, section) => Some(StrapdownConfig::new(section.unwrap_or_default())?),
            (InputKind::Ins, None) => None,
            (InputKind::Ins, Some(_)) => {
                return Err(ConfigError::new(
                    "strapdown",
                    "only with \"input\": \"imu\"",
                ));
            }
        };
        Ok(FederatedConfig {
            strapdown,
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
            converge_max_s,
            guards,
            aids: w.aids,
        })
    }
}

impl FederatedConfig {
    /// Parses and validates the `config` JSON, naming the field path of any error.
    pub fn from_json(value: &serde_json::Value) -> Result<Self, ConfigError> {
        Self::try_from(crate::monitor::parse_config::<FederatedConfigWire>(value)?)
    }

    /// The initial error estimate: zero error, `P₀ = diag(att², vel², pos², ε², ∇²)` with the
    /// bias uncertainties of `imu`; the attitude σ is `init`'s, or with `input: imu` the
    /// alignment's (`strapdown.align.att_sigma_deg`).
    pub fn initial_estimate(&self) -> ErrorEstimate {
        let arcsec = (1.0f64 / 3600.0).to_radians();
        let att_rad = |i: usize| match &self.strapdown {
            Some(s) => s.section.align.att_sigma_deg[i].to_radians(),
            None => self.init_att_sigma_arcsec[i] * arcsec,
        };
        let mut d = ErrorVector::zeros();
        for i in 0..3 {
            d[ATT + i] = att_rad(i).powi(2);
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
