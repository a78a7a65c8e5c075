//! Coarse alignment for the strapdown mechanization: levelling (roll and pitch from the
//! specific force of a static vehicle), the static-period detector that feeds it, and
//! the heading of a vehicle moving forward from its velocity (docs/methods.md §M30).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Roll and pitch (rad) from the mean specific force in the body frame (RFU) of a static
/// vehicle. At rest `C_bⁿ f_b = [0, 0, g]`, so `f_b = g · (third row of C_bⁿ)ᵀ =
/// g [−cos θ sin φ, sin θ, cos θ cos φ]` ([`crate::geo::dcm_body_to_nav`]), whence
/// `φ = atan2(−f_x, f_z)`, `θ = atan2(f_y, √(f_x² + f_z²))`; g cancels.
pub fn level(f_b_mean: &Vector3<f64>) -> (f64, f64) {
    let roll = (-f_b_mean.x).atan2(f_b_mean.z);
    let pitch = f_b_mean.y.atan2(f_b_mean.x.hypot(f_b_mean.z));
    (roll, pitch)
}

/// Heading (rad, clockwise from north, in [0, 2π)) of a vehicle moving forward along
/// body +y, from its ENU velocity: `atan2(v_e, v_n)`.
pub fn heading_from_velocity(vel_enu: &Vector3<f64>) -> f64 {
    let yaw = vel_enu.x.atan2(vel_enu.y).rem_euclid(std::f64::consts::TAU);
    // rem_euclid of a tiny negative angle can round up to exactly 2π.
    if yaw >= std::f64::consts::TAU {
        0.0
    } else {
        yaw
    }
}

/// Static-period detector and accumulator for [`level`]: a sample is static when
/// `|‖f‖ − g|` and `‖ω‖` are within the thresholds; static samples add to running
/// (time-weighted) sums of f and ω, and any other sample restarts them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Levelling {
    /// Static time needed before [`Levelling::attitude`] answers, s.
    min_static_s: f64,
    /// Largest `|‖f‖ − g|` of a static sample, m/s².
    max_accel_dev_mps2: f64,
    /// Largest `‖ω‖` of a static sample, rad/s.
    max_rate_rps: f64,
    /// Length of the current static run, s.
    static_s: f64,
    /// `∫ f dt` over the current static run, body frame, m/s.
    sum_f: Vector3<f64>,
    /// `∫ ω dt` over the current static run, body frame, rad.
    sum_w: Vector3<f64>,
}

impl Levelling {
    /// A detector that answers after `min_static_s` seconds of samples with
    /// `|‖f‖ − g| ≤ max_accel_dev_mps2` and `‖ω‖ ≤ max_rate_rps`.
    pub fn new(min_static_s: f64, max_accel_dev_mps2: f64, max_rate_rps: f64) -> Self {
        Levelling {
            min_static_s,
            max_accel_dev_mps2,
            max_rate_rps,
            static_s: 0.0,
            sum_f: Vector3::zeros(),
            sum_w: Vector3::zeros(),
        }
    }

    /// One sample: specific force `f_b` (m/s²) and angular rate `w_b` (rad/s), body frame,
    /// held for `dt` seconds, against the local gravity magnitude `gravity` (m/s²).
    pub fn add(&mut self, f_b: &Vector3<f64>, w_b: &Vector3<f64>, dt: f64, gravity: f64) {
        let is_static = (f_b.norm() - gravity).abs() <= self.max_accel_dev_mps2
            && w_b.norm() <= self.max_rate_rps;
        if is_static {
            self.static_s += dt;
            self.sum_f += f_b * dt;
            self.sum_w += w_b * dt;
        } else {
            self.restart();
        }
    }

    /// Ends the current static run (the vehicle is known to move, e.g. from GNSS).
    pub fn restart(&mut self) {
        self.static_s = 0.0;
        self.sum_f = Vector3::zeros();
        self.sum_w = Vector3::zeros();
    }

    /// Roll and pitch (rad) from the current static run's mean specific force, once it
    /// has lasted `min_static_s`; `None` before.
    pub fn attitude(&self) -> Option<(f64, f64)> {
        // The run's length is a sum of sample intervals: 1000 × 0.01 s sums to 9.99999999…
        // s, so a relative 1e-9 of rounding counts as reached.
        let reached = self.static_s >= self.min_static_s * (1.0 - 1e-9);
        (reached && self.static_s > 0.0).then(|| level(&(self.sum_f / self.static_s)))
    }

    /// The current static run's mean angular rate (rad/s, body frame): the Earth rate
    /// plus the gyro biases, for whoever wants them; `None` before any static sample.
    pub fn mean_rate(&self) -> Option<Vector3<f64>> {
        (self.static_s > 0.0).then(|| self.sum_w / self.static_s)
    }

    /// Length of the current static run, s.
    pub fn static_seconds(&self) -> f64 {
        self.static_s
    }
}
