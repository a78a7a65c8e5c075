//! The truth record every scenario is built on, and the strapdown kinematics
//! shared by the two truth sources (`trajectory`, `track`): specific force from
//! acceleration and gravity, angular rate from attitude rates and the Earth and
//! transport rates. Feeds `ins_truth` (what the INS errors are linearised about
//! and corrupt), `sensors` and the experiments' error tables.
//!
//! Specific force is the INS mechanisation equation solved for `f`:
//! `fⁿ = v̇ⁿ + (2ω_ie + ω_en) × vⁿ − gⁿ`, `gⁿ = [0, 0, −γ(L, h)]` (WGS84 normal
//! gravity; plumb-line deflection ignored), where `v̇ⁿ` is the time derivative of
//! the ENU components; `f_b = C_nᵇ fⁿ`. Angular rate
//! `ω_ib^b = ω_nb^b + C_nᵇ (ω_ie + ω_en)`.

use nalgebra::{Matrix3, Vector3};

use navguard_core::geo::{self, Lla};

/// The true state of the vehicle at one instant.
#[derive(Debug, Clone, PartialEq)]
pub struct Truth {
    /// Time since the start of the scenario, s.
    pub t: f64,
    /// Position (rad, rad, m).
    pub lla: Lla,
    /// Velocity east, north, up, m/s.
    pub vel: Vector3<f64>,
    /// Roll, pitch, yaw (rad), the contract's convention; yaw in [0, 2π).
    pub att: [f64; 3],
    /// Specific force in the body frame (RFU), m/s².
    pub f_b: Vector3<f64>,
    /// Angular rate of the body relative to inertial space, in body axes, rad/s.
    pub omega_ib_b: Vector3<f64>,
}

impl Truth {
    /// Body → navigation direction cosine matrix of the true attitude.
    pub fn c_bn(&self) -> Matrix3<f64> {
        geo::dcm_body_to_nav(self.att[0], self.att[1], self.att[2])
    }
}

/// `fⁿ = v̇ⁿ + (2ω_ie + ω_en) × vⁿ + [0, 0, γ]` (module doc), m/s².
pub(crate) fn specific_force_nav(
    lla: &Lla,
    vel: &Vector3<f64>,
    vel_dot: &Vector3<f64>,
) -> Vector3<f64> {
    let w_ie = geo::earth_rate_enu(lla.lat);
    let w_en = geo::transport_rate_enu(lla.lat, lla.h, vel);
    vel_dot
        + (2.0 * w_ie + w_en).cross(vel)
        + Vector3::new(0.0, 0.0, geo::normal_gravity(lla.lat, lla.h))
}

/// `ω_ib^b = ω_nb^b + C_nᵇ (ω_ie + ω_en)`.
pub(crate) fn body_rate(
    lla: &Lla,
    vel: &Vector3<f64>,
    c_bn: &Matrix3<f64>,
    omega_nb_b: &Vector3<f64>,
) -> Vector3<f64> {
    let w_in = geo::earth_rate_enu(lla.lat) + geo::transport_rate_enu(lla.lat, lla.h, vel);
    omega_nb_b + c_bn.transpose() * w_in
}

/// An angle wrapped to [0, 2π).
pub(crate) fn wrap_2pi(a: f64) -> f64 {
    let w = a.rem_euclid(std::f64::consts::TAU);
    if w >= std::f64::consts::TAU { 0.0 } else { w }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn eastward_motion_adds_coriolis_and_transport_terms() {
        // v = 10 m/s east at 30°N: (2ω_ie + ω_en) × v = [0, 2Ω sinL v + v² tanL/R_N, −(2Ω cosL v + v²/R_N)]
        // with the sign of ω × [v, 0, 0] = [0, ω_z v, −ω_y v].
        let lla = Lla {
            lat: 30f64.to_radians(),
            lon: 0.0,
            h: 0.0,
        };
        let v = Vector3::new(10.0, 0.0, 0.0);
        let f = specific_force_nav(&lla, &v, &Vector3::zeros());
        let (s, c) = lla.lat.sin_cos();
        let rn = geo::radii(lla.lat).prime_vertical;
        let w = geo::OMEGA_IE;
        assert_relative_eq!(
            f.y,
            2.0 * w * s * 10.0 + 100.0 * s / c / rn,
            max_relative = 1e-12
        );
        let g = geo::normal_gravity(lla.lat, 0.0);
        assert_relative_eq!(
            f.z,
            g - (2.0 * w * c * 10.0 + 100.0 / rn),
            max_relative = 1e-12
        );
        assert_eq!(f.x, 0.0);
    }

    #[test]
    fn angles_wrap_into_zero_two_pi() {
        assert_relative_eq!(wrap_2pi(-0.5), std::f64::consts::TAU - 0.5);
        assert_relative_eq!(wrap_2pi(7.0), 7.0 - std::f64::consts::TAU);
        assert_eq!(wrap_2pi(-1e-300), 0.0);
    }
}
