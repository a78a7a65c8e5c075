//! The `gnss` monitor's configuration (docs/methods.md §M26–§M28): as the user writes it
//! ([`GnssConfigWire`], every field optional with a documented default) and validated
//! ([`GnssConfig`]), errors naming the field.

use serde::{Deserialize, Serialize};

use super::super::ConfigError;
use crate::gnss::araim::AraimParams;
use crate::gnss::raim::SolutionSeparationParams;

/// Default elevation mask, degrees (RTKLIB's default is 15°; 10° keeps more satellites
/// for phones and still drops the noisiest low ones).
pub const DEFAULT_ELEVATION_MASK_DEG: f64 = 10.0;

/// Default horizontal alert limit, m (LPV-200's HAL).
pub const DEFAULT_HAL_M: f64 = 40.0;

/// Default missed-detection probability of the slope protection levels.
pub const DEFAULT_P_MD: f64 = 1e-3;

/// How each pseudorange's σ is obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum SigmaKind {
    /// The satellite's `sigma` where given; `sqrt(a² + b²)` for a satellite without one
    /// (3.02 m with the defaults a = 0.3 m, b = 3 m).
    #[default]
    Given,
    /// σ² = a² + b²/sin²(el) (RTKLIB's code-noise model).
    Elevation,
    /// σ² = a² + b²·10^(−C/N0 / 10) (C/N0 in dB-Hz); 10 m for a satellite without C/N0.
    Cn0,
}

/// The σ model as the user writes it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SigmaWire {
    /// Which model.
    pub model: SigmaKind,
    /// `a`, m (elevation and C/N0 models).
    pub a_m: Option<f64>,
    /// `b`, m (elevation model) or m·sqrt(Hz) scale (C/N0 model).
    pub b_m: Option<f64>,
    /// Every σ is multiplied by this (what `calibrate` proposes from fault-free data).
    pub scale: f64,
}

impl Default for SigmaWire {
    fn default() -> Self {
        SigmaWire {
            model: SigmaKind::Given,
            a_m: None,
            b_m: None,
            scale: 1.0,
        }
    }
}

/// The fault-exclusion method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum FdeKind {
    /// Detection only: nothing is excluded.
    None,
    /// RTKLIB's: leave-one-out keeping the passing subset of smallest residual RMS, one
    /// exclusion.
    Rtklib,
    /// The largest normalised residual, re-solved and re-tested, up to `max_exclusions`.
    #[default]
    Greedy,
    /// ARAIM's solution separation.
    SolutionSeparation,
}

/// Fault exclusion as the user writes it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FdeWire {
    /// Which method.
    pub method: FdeKind,
    /// Most satellites excluded in one epoch (RTKLIB's method excludes at most one).
    pub max_exclusions: usize,
}

impl Default for FdeWire {
    fn default() -> Self {
        FdeWire {
            method: FdeKind::Greedy,
            max_exclusions: 1,
        }
    }
}

/// Which protection levels decide integrity availability.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ProtectionKind {
    /// Classic RAIM slope method with `p_md`.
    Slope,
    /// ARAIM solution separation.
    #[default]
    Araim,
}

/// The `config` of a `gnss` monitor as the user writes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GnssConfigWire {
    /// Elevation mask, degrees.
    pub elevation_mask_deg: f64,
    /// σ model.
    pub sigma: SigmaWire,
    /// Fault exclusion.
    pub fde: FdeWire,
    /// Which protection levels decide availability.
    pub protection: ProtectionKind,
    /// Horizontal alert limit, m.
    pub hal_m: f64,
    /// Vertical alert limit, m; absent: availability is horizontal only.
    pub val_m: Option<f64>,
    /// Missed-detection probability of the slope protection levels.
    pub p_md: f64,
    /// ARAIM allocations, priors and tolerances; every field defaults to the ADD's
    /// (docs/methods.md §M28).
    pub araim: AraimParams,
    /// The nominal error model of the integrity support message.
    pub ism: IsmWire,
}

/// The integrity support message's nominal error model (docs/methods.md §M28).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IsmWire {
    /// σ_URA, m (integrity).
    pub sigma_ura_m: f64,
    /// σ_URE, m (accuracy and continuity).
    pub sigma_ure_m: f64,
    /// b_nom, m.
    pub b_nom_m: f64,
}

impl Default for IsmWire {
    fn default() -> Self {
        let d = SolutionSeparationParams::default();
        IsmWire {
            sigma_ura_m: d.sigma_ura_m,
            sigma_ure_m: d.sigma_ure_m,
            b_nom_m: d.b_nom_m,
        }
    }
}

impl Default for GnssConfigWire {
    fn default() -> Self {
        GnssConfigWire {
            elevation_mask_deg: DEFAULT_ELEVATION_MASK_DEG,
            sigma: SigmaWire::default(),
            fde: FdeWire::default(),
            protection: ProtectionKind::default(),
            hal_m: DEFAULT_HAL_M,
            val_m: None,
            p_md: DEFAULT_P_MD,
            araim: AraimParams::default(),
            ism: IsmWire::default(),
        }
    }
}

/// Checks that `v` is finite and inside `range`, naming `field` otherwise.
pub(super) fn checked(
    field: &str,
    v: f64,
    range: std::ops::RangeInclusive<f64>,
) -> Result<f64, ConfigError> {
    if v.is_finite() && range.contains(&v) {
        Ok(v)
    } else {
        Err(ConfigError::new(
            field,
            format!("must be a number in [{}, {}]", range.start(), range.end()),
        ))
    }
}
