//! Simulation: trajectories, sensor models, fault injection, the papers'
//! scenarios and experiment scorecards. Pure: produces epochs and truth.
//!
//! Where it sits: upstream of everything else. A scenario builds a truth path
//! ([`truth`] records, from segments by [`trajectory`] or from real RTK fixes by
//! [`track`]), corrupts it
//! with the INS error model of `filter::ins` ([`ins_truth`]) and with noisy aid
//! sensors ([`sensors`]), injects faults ([`faults`]) and hands the resulting
//! domain [`navguard_core::epoch::Epoch`]s, each with its truth, to the monitors, the
//! CLI (`navguard simulate`, which writes them as ingest frames) and the
//! experiments ([`experiment`]). [`drive_config`] is the shared car drive's raw-IMU
//! monitor config (the drive experiment's and `loadgen --input imu`'s). [`plot`] draws
//! SVG line charts, for the
//! experiments' figures and the CLI's load-ramp curve; the layers before `sim`
//! never plot.
//!
//! Reproducibility: every random draw comes from [`rng::stream`], a `StdRng`
//! seeded from the scenario seed and a fixed stream number, so a scenario is
//! identical for a given seed **and build** (`rand`'s `StdRng` algorithm may
//! change between `rand` releases; the seed → stream mapping is ours and fixed).

pub mod ads_gnss;
pub mod drive_config;
pub mod experiment;
pub mod faults;
pub mod imu_channel;
pub mod ins_truth;
pub mod plot;
pub mod rimu;
pub mod rng;
pub mod scenario;
pub mod sensors;
pub mod tacan;
pub mod track;
pub mod trajectory;
pub mod truth;

pub use faults::{Channel, Fault, FaultInjector, FaultKind};
pub use ins_truth::{InsErrorConfig, InsErrorSim};
pub use scenario::{
    SHIP_DURATION_S, SHIP_INS_RATE_HZ, SHIP_START_LAT_DEG, SHIP_START_LON_DEG, Scenario,
    ScenarioParams, SimEpoch, gnss_freeze, ship, ship_fault_free, ship_faults, ship_params,
    ship_trajectory, ship_with, simulate, station_keeping_trajectory, station_keeping_with,
    track_scenario,
};
pub use sensors::{AidSensors, CnsSpec, DvlSpec, GnssSpec, SensorConfig};
pub use track::{Track, TrackError, TrackFix};
pub use trajectory::{Segment, Trajectory, TrajectoryBuilder};
pub use truth::Truth;

/// Errors of the simulator's builders (bad parameters, faults or tracks).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// A parameter is out of range; `field` names it.
    #[error("invalid simulation parameter `{field}`: {reason}")]
    InvalidParameter {
        /// The offending parameter.
        field: String,
        /// Why it was refused.
        reason: String,
    },
    /// A fault description is inconsistent (index in the fault list).
    #[error("fault {index}: {reason}")]
    InvalidFault {
        /// Position of the fault in the list.
        index: usize,
        /// Why it was refused.
        reason: String,
    },
    /// The track file could not be parsed or used.
    #[error(transparent)]
    Track(#[from] TrackError),
}

impl SimError {
    /// An [`SimError::InvalidParameter`] naming `field`.
    pub fn param(field: impl Into<String>, reason: impl Into<String>) -> Self {
        SimError::InvalidParameter {
            field: field.into(),
            reason: reason.into(),
        }
    }
}

/// Checks that `value` is finite and strictly positive.
pub(crate) fn check_positive(field: &str, value: f64) -> Result<f64, SimError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(SimError::param(
            field,
            format!("must be finite and > 0, got {value}"),
        ))
    }
}

/// Checks that `value` is finite and not negative.
pub(crate) fn check_non_negative(field: &str, value: f64) -> Result<f64, SimError> {
    if value.is_finite() && value >= 0.0 {
        Ok(value)
    } else {
        Err(SimError::param(
            field,
            format!("must be finite and ≥ 0, got {value}"),
        ))
    }
}

#[cfg(test)]
mod core_tests;
