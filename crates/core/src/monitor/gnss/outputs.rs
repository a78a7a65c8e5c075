//! What the `gnss` monitor reports per epoch (the `result` frame's outputs and the
//! `stats` message's `gnss` snapshot): the solution, its DOPs and protection levels,
//! and per satellite its geometry, residual, use and health (docs/methods.md §M27).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::detect::Health;

/// A geodetic position: latitude and longitude in degrees, height in m.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GnssPosition {
    /// Latitude, degrees.
    pub lat: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Ellipsoidal height, m.
    pub h: f64,
}

/// Dilutions of precision of the solution's geometry (unweighted, local ENU).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Dops {
    /// Geometric.
    pub gdop: f64,
    /// Position.
    pub pdop: f64,
    /// Horizontal.
    pub hdop: f64,
    /// Vertical.
    pub vdop: f64,
}

/// One satellite of the epoch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SatOutput {
    /// Satellite id (`G05`).
    pub id: String,
    /// Elevation, degrees (null before the first solution when not given).
    pub el: Option<f64>,
    /// Azimuth, degrees clockwise from north.
    pub az: Option<f64>,
    /// Residual against the final solution, m: post-fit for a satellite used, predicted
    /// for one left out.
    pub residual: Option<f64>,
    /// The residual normalised by its standard deviation.
    pub w: Option<f64>,
    /// The satellite took part in the final solution.
    pub used: bool,
    /// Its health after this epoch (per-satellite decision policy).
    pub health: Health,
}

/// The monitor's outputs for one epoch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GnssOutputs {
    /// The final (after exclusion) position; null without a solution.
    pub position: Option<GnssPosition>,
    /// Receiver clock per constellation letter, m.
    pub clocks: BTreeMap<String, f64>,
    /// DOPs of the final solution.
    pub dop: Option<Dops>,
    /// Horizontal protection level, m.
    pub hpl: Option<f64>,
    /// Vertical protection level, m.
    pub vpl: Option<f64>,
    /// Horizontal alert limit, m.
    pub hal: f64,
    /// Vertical alert limit, m, when configured.
    pub val: Option<f64>,
    /// Horizontal position error against the epoch's truth, m.
    pub hpe: Option<f64>,
    /// Vertical position error against the epoch's truth, m (absolute).
    pub vpe: Option<f64>,
    /// Every satellite of the epoch.
    pub satellites: Vec<SatOutput>,
    /// Satellites excluded by fault exclusion this epoch, in exclusion order.
    pub excluded: Vec<String>,
}

impl GnssOutputs {
    /// The outputs of an epoch without a solution (too few satellites).
    pub fn without_solution(hal: f64, val: Option<f64>, satellites: Vec<SatOutput>) -> Self {
        GnssOutputs {
            position: None,
            clocks: BTreeMap::new(),
            dop: None,
            hpl: None,
            vpl: None,
            hal,
            val,
            hpe: None,
            vpe: None,
            satellites,
            excluded: Vec::new(),
        }
    }
}
