//! The `gnss` monitor (docs/methods.md §M26–§M28): snapshot positioning and integrity
//! from pseudoranges, stepped once per epoch carrying a `gnss_raw` block.
//!
//! Per epoch: the satellites whose health admits them ([`health`]) are solved by
//! weighted least squares; the residual χ² of that all-in-view fix is the `raim` test
//! (its dof, n − 3 − n_clk, changes with the satellites; thresholds per dof come from the
//! monitor's spec, so p_fa, raw thresholds, policies and calibration work as for every
//! test); fault exclusion ([`FdeKind`]) removes satellites; the protection levels of the
//! final fix against the alert limits give the integrity availability (never an alarm).
//! Every satellite of the epoch then steps its own policy: one excluded this epoch, or
//! one left out whose residual against the final fix exceeds the per-satellite
//! threshold, counts as an exceedance.
//!
//! Epochs without `gnss_raw` run no test and repeat the last outputs.

pub mod config;
pub mod health;
pub mod outputs;
mod step;

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::{
    BuildError, CheckpointError, ConfigError, EpochError, Monitor, MonitorKind, MonitorReport,
    Outputs, StepError, TestBank, checkpoint,
};
use crate::detect::{PolicyConfig, PolicyState, ThresholdSpec};
use crate::epoch::Epoch;
use crate::gnss::araim::AraimError;
use crate::gnss::raim::{FdeMethod, FdeParams, SolutionSeparationParams};
use crate::gnss::wls::{SigmaModel, WlsParams};
use config::checked;
pub use config::{FdeKind, GnssConfigWire, ProtectionKind, SigmaKind};
pub use health::SatHealth;
pub use outputs::GnssOutputs;

/// The `raim` test's dofs whose thresholds are resolved ahead (up to 44 satellites of one
/// constellation); larger dofs are resolved when they occur.
pub const MAX_CACHED_DOF: u32 = 40;

/// A validated `gnss` config.
#[derive(Debug, Clone, PartialEq)]
pub struct GnssConfig {
    /// Weighted least squares settings (the start point is the monitor's last fix).
    pub wls: WlsParams,
    /// Fault exclusion; `None` detects only.
    pub fde: Option<(FdeMethod, usize)>,
    /// Which protection levels decide availability.
    pub protection: ProtectionKind,
    /// Horizontal alert limit, m.
    pub hal_m: f64,
    /// Vertical alert limit, m.
    pub val_m: Option<f64>,
    /// Missed-detection probability of the slope protection levels.
    pub p_md: f64,
    /// Solution-separation priors and budget.
    pub araim: SolutionSeparationParams,
}

fn sigma_model(w: &config::SigmaWire) -> Result<SigmaModel, ConfigError> {
    let positive = |field: &str, v: Option<f64>, default: f64| {
        checked(&format!("sigma.{field}"), v.unwrap_or(default), 1e-6..=1e5)
    };
    let SigmaModel::Elevation {
        a_m: rtk_a,
        b_m: rtk_b,
    } = SigmaModel::RTKLIB_ELEVATION
    else {
        unreachable!("RTKLIB's model is an elevation model")
    };
    let SigmaModel::Cn0 {
        a_m: cn0_a,
        b_m: cn0_b,
        fallback_m,
    } = SigmaModel::PHONE_CN0
    else {
        unreachable!("the phone model is a C/N0 model")
    };
    Ok(match w.model {
        SigmaKind::Given => SigmaModel::Given {
            fallback_m: (positive("a_m", w.a_m, rtk_a)?.powi(2)
                + positive("b_m", w.b_m, 3.0)?.powi(2))
            .sqrt(),
        },
        SigmaKind::Elevation => SigmaModel::Elevation {
            a_m: positive("a_m", w.a_m, rtk_a)?,
            b_m: positive("b_m", w.b_m, rtk_b)?,
        },
        SigmaKind::Cn0 => SigmaModel::Cn0 {
            a_m: positive("a_m", w.a_m, cn0_a)?,
            b_m: positive("b_m", w.b_m, cn0_b)?,
            fallback_m,
        },
    })
}

impl TryFrom<GnssConfigWire> for GnssConfig {
    type Error = ConfigError;

    fn try_from(w: GnssConfigWire) -> Result<Self, ConfigError> {
        let mask = checked("elevation_mask_deg", w.elevation_mask_deg, 0.0..=60.0)?;
        let scale = checked("sigma.scale", w.sigma.scale, 1e-3..=1e3)?;
        let wls = WlsParams {
            sigma_model: sigma_model(&w.sigma)?,
            sigma_scale: scale,
            elevation_mask_rad: mask.to_radians(),
            ..WlsParams::default()
        };
        if w.fde.max_exclusions > 10 {
            return Err(ConfigError::new("fde.max_exclusions", "must be at most 10"));
        }
        let fde = match w.fde.method {
            FdeKind::None => None,
            FdeKind::Rtklib => Some((FdeMethod::Rtklib, 1)),
            FdeKind::Greedy => Some((FdeMethod::Greedy, w.fde.max_exclusions)),
            FdeKind::SolutionSeparation => {
                Some((FdeMethod::SolutionSeparation, w.fde.max_exclusions))
            }
        };
        let hal_m = checked("hal_m", w.hal_m, 0.1..=1e6)?;
        let val_m = w
            .val_m
            .map(|v| checked("val_m", v, 0.1..=1e6))
            .transpose()?;
        let p_md = checked("p_md", w.p_md, 1e-12..=0.5)?;
        w.araim.check().map_err(|e| match e {
            AraimError::Param { name, .. } => {
                ConfigError::new(format!("araim.{name}"), e.to_string())
            }
            e => ConfigError::new("araim", e.to_string()),
        })?;
        let ism = |field: &str, v: f64, low: f64| checked(&format!("ism.{field}"), v, low..=1e3);
        let araim = SolutionSeparationParams {
            sigma_ura_m: ism("sigma_ura_m", w.ism.sigma_ura_m, 1e-6)?,
            sigma_ure_m: ism("sigma_ure_m", w.ism.sigma_ure_m, 1e-6)?,
            b_nom_m: ism("b_nom_m", w.ism.b_nom_m, 0.0)?,
            araim: w.araim,
        };
        Ok(GnssConfig {
            wls,
            fde,
            protection: w.protection,
            hal_m,
            val_m,
            p_md,
            araim,
        })
    }
}

/// The `gnss` monitor.
#[derive(Debug, Clone)]
pub struct GnssMonitor {
    config: GnssConfig,
    bank: TestBank,
    /// Per-satellite policy states.
    health: SatHealth,
    /// The last fix, ECEF m: the next epoch's starting point.
    last_fix: Option<[f64; 3]>,
    /// The last epoch's outputs, repeated on epochs without pseudoranges.
    outputs: Arc<GnssOutputs>,
}

impl GnssMonitor {
    /// Builds the monitor: one `raim` test with its thresholds resolved for dof
    /// 1..=[`MAX_CACHED_DOF`].
    pub fn new(
        config: GnssConfig,
        policy: PolicyConfig,
        spec: ThresholdSpec,
    ) -> Result<Self, BuildError> {
        let mut bank = TestBank::new(&[("raim", 1)], spec, policy)?;
        let dofs: Vec<u32> = (2..=MAX_CACHED_DOF).collect();
        bank.add_dofs(0, &dofs)?;
        let outputs = Arc::new(GnssOutputs::without_solution(
            config.hal_m,
            config.val_m,
            Vec::new(),
        ));
        Ok(GnssMonitor {
            config,
            bank,
            health: SatHealth::default(),
            last_fix: None,
            outputs,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &GnssConfig {
        &self.config
    }

    /// The per-satellite health.
    pub fn satellites(&self) -> &SatHealth {
        &self.health
    }

    fn fde_params(&self, p_fa: f64) -> FdeParams {
        let (method, max_exclusions) = self.config.fde.unwrap_or((FdeMethod::Greedy, 0));
        FdeParams {
            method,
            p_fa,
            max_exclusions,
            solution_separation: self.config.araim.clone(),
        }
    }
}

/// Builds a `gnss` monitor from its config.
pub fn build(
    wire: &GnssConfigWire,
    policy: PolicyConfig,
    threshold: ThresholdSpec,
) -> Result<Box<dyn Monitor>, BuildError> {
    let config = GnssConfig::try_from(wire.clone())?;
    Ok(Box::new(GnssMonitor::new(config, policy, threshold)?))
}

/// What a checkpoint of a `gnss` monitor holds: the per-satellite policies, the last fix
/// and the test. The outputs are not kept: the next epoch recomputes them.
#[derive(Serialize, Deserialize)]
struct GnssSaved {
    satellites: Vec<(String, PolicyState)>,
    last_fix: Option<[f64; 3]>,
    bank: TestBank,
}

impl Monitor for GnssMonitor {
    fn kind(&self) -> MonitorKind {
        MonitorKind::Gnss
    }

    fn tests(&self) -> &TestBank {
        &self.bank
    }

    fn tests_mut(&mut self) -> &mut TestBank {
        &mut self.bank
    }

    /// The block is validated at the edge (ids, finite numbers, orbit radii, no
    /// satellite twice): nothing here can make an epoch unusable.
    fn check_epoch(&self, _name: &str, _epoch: &Epoch) -> Result<(), EpochError> {
        Ok(())
    }

    fn step(&mut self, epoch: &Epoch) -> Result<MonitorReport, StepError> {
        let Some(block) = &epoch.gnss_raw else {
            return Ok(MonitorReport {
                tests: Vec::new(),
                outputs: Outputs::Gnss(self.outputs.clone()),
                integrity: None,
            });
        };
        step::step(self, block)
    }

    fn checkpoint(&self) -> Result<Vec<u8>, CheckpointError> {
        checkpoint::encode(
            MonitorKind::Gnss,
            &GnssSaved {
                satellites: self.health.saved(),
                last_fix: self.last_fix,
                bank: self.bank.clone(),
            },
        )
    }

    fn restore(&mut self, bytes: &[u8]) -> Result<(), CheckpointError> {
        let saved: GnssSaved = checkpoint::decode(MonitorKind::Gnss, bytes)?;
        let health = SatHealth::restored(saved.satellites).map_err(CheckpointError::Mismatch)?;
        if saved
            .last_fix
            .is_some_and(|p| p.iter().any(|x| !x.is_finite()))
        {
            return Err(CheckpointError::mismatch(
                "a non-finite last fix".to_owned(),
            ));
        }
        let bank = self
            .bank
            .restored(saved.bank)
            .map_err(CheckpointError::Mismatch)?;
        self.health = health;
        self.last_fix = saved.last_fix;
        self.bank = bank;
        Ok(())
    }

    fn reset(&mut self) {
        self.health.clear();
        self.last_fix = None;
        self.bank.reset();
        self.outputs = Arc::new(GnssOutputs::without_solution(
            self.config.hal_m,
            self.config.val_m,
            Vec::new(),
        ));
    }
}

#[cfg(test)]
mod tests;
