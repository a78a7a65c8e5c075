//! The strapdown inertial mechanization: sits after `gnss` and before `filter`; it turns
//! IMU increments into attitude, velocity and position (the INS solution the error
//! model of `filter::ins` is linearised about and whose errors it estimates), and its
//! [`align`] part levels a static vehicle and takes a heading from its velocity.
//! Built on `geo` only (docs/methods.md §M30).
//!
//! Frames: navigation ENU, body RFU, `C_bⁿ` as [`geo::dcm_body_to_nav`]. One step over
//! the interval `[t_{k−1}, t_k]` of length Δt, with the increments `Δθ_k`, `Δv_k` and
//! the previous interval's `Δθ_{k−1}`, `Δv_{k−1}` (zero on the first step and after
//! [`Strapdown::forget_history`]); Groves (2013) ch. 5 and Shin (2005) as KF-GINS
//! codes them, moved from NED/FRD to ENU/RFU:
//!
//! 1. **Velocity.** The sculling-compensated increment
//!    `Δv_scul = Δv_k + ½ Δθ_k × Δv_k + (1/12)(Δθ_{k−1} × Δv_k + Δv_{k−1} × Δθ_k)`,
//!    rotated with the attitude at `k−1` and the navigation frame's own turn
//!    `ζ = (ω_ie + ω_en) Δt`: `Δvⁿ_f = (I − ½[ζ×]) C_bⁿ(k−1) Δv_scul`; then
//!    `v_k = v_{k−1} + Δvⁿ_f + (gⁿ − (2ω_ie + ω_en) × v) Δt` with `gⁿ = [0, 0, −γ(L, h)]`
//!    (normal gravity). ω_ie, ω_en, g and the Coriolis velocity are taken at the
//!    interval's midpoint, extrapolated from `k−1` with a first pass of the same update.
//! 2. **Position.** Trapezoidal: with `v̄ = (v_{k−1} + v_k)/2` and the radii at the
//!    midpoint, `L += v̄_n Δt/(R_M + h)`, `λ += v̄_e Δt/((R_N + h) cos L)`, `h += v̄_u Δt`.
//! 3. **Attitude.** `C_bⁿ(k) = C_{n(k−1)}^{n(k)} C_bⁿ(k−1) C_{b(k)}^{b(k−1)}` with the
//!    body rotation vector `φ_k = Δθ_k + (1/12) Δθ_{k−1} × Δθ_k` (two-sample coning
//!    correction), `C_{b(k)}^{b(k−1)} = exp([φ_k×])`, `C_{n(k−1)}^{n(k)} = exp(−[ζ×])`
//!    with ζ at the midpoint of the updated position and velocity; exact exponentials
//!    (unit quaternions, renormalised each step).
//!
//! Precision: the attitude update is exact for rotation about a fixed axis; what it
//! truncates is the coning series beyond the two-sample term. Under classical coning of
//! half-angle α at frequency Ω it leaves an attitude drift of `α² Ω (ΩΔt)⁴ / 60` rad/s,
//! against `α² Ω (ΩΔt)² / 12` without the coning term. The velocity update keeps the
//! rotation compensation to first order (`½ Δθ × Δv`; the `Δθ × (Δθ × Δv) / 6` term is
//! left out) and the sculling series to its two-sample term: a body-fixed specific force
//! f under angular oscillation of amplitude A at Ω is rectified wrongly by about
//! `|f| A² (ΩΔt)² / 12` m/s². The tests measure these laws. The two-sample terms assume
//! equal consecutive intervals.

pub mod align;

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::geo::{self, Lla};

pub use align::{Levelling, heading_from_velocity, level};

/// IMU increments over one sample interval, body frame (RFU): already rotated from the
/// sensor frame and bias-corrected by the caller.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Increments {
    /// Angle increment ∫ω_ib dt, rad.
    pub dtheta: [f64; 3],
    /// Velocity increment ∫f dt (specific force), m/s.
    pub dv: [f64; 3],
    /// Interval length, s (> 0).
    pub dt: f64,
}

/// The mechanization state: the INS solution and what the next step needs from the last.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Strapdown {
    /// Position (lat, lon rad; h m), serialised as `[lat, lon, h]`.
    #[serde(with = "lla_array")]
    lla: Lla,
    /// Velocity ENU, m/s.
    vel: Vector3<f64>,
    /// Attitude: the unit quaternion of `C_bⁿ` (body RFU → ENU).
    q_bn: UnitQuaternion<f64>,
    /// The previous interval's increments, for the two-sample coning and sculling
    /// terms; `None` on the first step and after a gap.
    prev: Option<Increments>,
    /// Specific force in ENU over the last step, m/s² (the error model's `fⁿ`).
    f_n: Vector3<f64>,
}

/// The navigation frame's quantities at one point: Earth rate, transport rate, gravity.
struct FrameRates {
    w_ie: Vector3<f64>,
    w_en: Vector3<f64>,
    gravity: Vector3<f64>,
}

impl FrameRates {
    fn at(lla: &Lla, vel: &Vector3<f64>) -> Self {
        FrameRates {
            w_ie: geo::earth_rate_enu(lla.lat),
            w_en: geo::transport_rate_enu(lla.lat, lla.h, vel),
            gravity: Vector3::new(0.0, 0.0, -geo::normal_gravity(lla.lat, lla.h)),
        }
    }

    /// The navigation frame's rotation ζ = (ω_ie + ω_en) Δt over `dt`.
    fn zeta(&self, dt: f64) -> Vector3<f64> {
        (self.w_ie + self.w_en) * dt
    }

    /// The velocity change `(Δvⁿ_f, Δvⁿ_g)` for the body-frame increment `c_dv` (already
    /// `C_bⁿ(k−1) Δv_scul`) at velocity `vel`: step 1 of the module doc.
    fn velocity_change(
        &self,
        c_dv: &Vector3<f64>,
        vel: &Vector3<f64>,
        dt: f64,
    ) -> (Vector3<f64>, Vector3<f64>) {
        let zeta = self.zeta(dt);
        let dv_f = c_dv - 0.5 * zeta.cross(c_dv);
        let dv_g = (self.gravity - (2.0 * self.w_ie + self.w_en).cross(vel)) * dt;
        (dv_f, dv_g)
    }
}

impl Strapdown {
    /// A mechanization at `lla`, moving at `vel_enu` (m/s) with attitude `c_bn` (body RFU
    /// → ENU; the nearest rotation is taken if it is not orthonormal), with no history.
    pub fn new(lla: Lla, vel_enu: Vector3<f64>, c_bn: Matrix3<f64>) -> Self {
        Strapdown {
            lla,
            vel: vel_enu,
            q_bn: nearest_rotation(&c_bn),
            prev: None,
            f_n: Vector3::new(0.0, 0.0, geo::normal_gravity(lla.lat, lla.h)),
        }
    }

    /// One IMU interval: velocity, position, then attitude (module doc, steps 1–3).
    pub fn step(&mut self, inc: &Increments) {
        let dt = inc.dt;
        let dtheta = Vector3::from(inc.dtheta);
        let dv = Vector3::from(inc.dv);
        let (dtheta_prev, dv_prev) = match &self.prev {
            Some(p) => (Vector3::from(p.dtheta), Vector3::from(p.dv)),
            None => (Vector3::zeros(), Vector3::zeros()),
        };
        let (lla0, vel0) = (self.lla, self.vel);

        // 1. Velocity: sculling, then a first pass at k−1 to extrapolate the midpoint.
        let dv_scul =
            dv + 0.5 * dtheta.cross(&dv) + (dtheta_prev.cross(&dv) + dv_prev.cross(&dtheta)) / 12.0;
        let c_dv = self.q_bn * dv_scul;
        let (dv_f, dv_g) = FrameRates::at(&lla0, &vel0).velocity_change(&c_dv, &vel0, dt);
        let vel_mid = vel0 + 0.5 * (dv_f + dv_g);
        let lla_mid = geo::apply_offset(&lla0, &((vel0 + vel_mid) * 0.25 * dt));
        let (dv_f, dv_g) = FrameRates::at(&lla_mid, &vel_mid).velocity_change(&c_dv, &vel_mid, dt);
        let vel1 = vel0 + dv_f + dv_g;

        // 2. Position: trapezoidal, radii at the midpoint.
        let vel_mean = 0.5 * (vel0 + vel1);
        let lla_mid = geo::apply_offset(&lla0, &(vel_mean * 0.5 * dt));
        let rd = geo::radii(lla_mid.lat);
        let lla1 = Lla {
            lat: lla0.lat + vel_mean.y * dt / (rd.meridian + lla_mid.h),
            lon: wrap_pi(
                lla0.lon + vel_mean.x * dt / ((rd.prime_vertical + lla_mid.h) * lla_mid.lat.cos()),
            ),
            h: lla0.h + vel_mean.z * dt,
        };

        // 3. Attitude: body rotation with the coning term, navigation-frame rotation
        // at the midpoint.
        let phi = dtheta + dtheta_prev.cross(&dtheta) / 12.0;
        let zeta = FrameRates::at(&lla_mid, &vel_mean).zeta(dt);
        let mut q = UnitQuaternion::from_scaled_axis(-zeta)
            * self.q_bn
            * UnitQuaternion::from_scaled_axis(phi);
        q.renormalize();

        self.lla = lla1;
        self.vel = vel1;
        self.q_bn = q;
        self.f_n = dv_f / dt;
        self.prev = Some(*inc);
    }

    /// Position (lat, lon rad; h m).
    pub fn lla(&self) -> Lla {
        self.lla
    }

    /// Velocity ENU, m/s.
    pub fn vel(&self) -> Vector3<f64> {
        self.vel
    }

    /// `C_bⁿ`: body RFU → ENU, orthonormal.
    pub fn c_bn(&self) -> Matrix3<f64> {
        self.q_bn.to_rotation_matrix().into_inner()
    }

    /// Roll, pitch, yaw (rad) as [`geo::euler_from_dcm`] gives them.
    pub fn att(&self) -> [f64; 3] {
        geo::euler_from_dcm(&self.c_bn())
    }

    /// Specific force in ENU over the last step (`Δvⁿ_f / Δt`, m/s²); `[0, 0, γ]`
    /// (normal gravity at the initial position) before any step.
    pub fn f_n(&self) -> Vector3<f64> {
        self.f_n
    }

    /// Removes estimated errors with the convention of `filter::ins` (errors are
    /// INS − true; `C̃_bⁿ = (I − [φ×]) C_bⁿ`): the attitude is turned by the exact
    /// rotation `exp([φ×])` (whose first order is `I + [φ×]`), `v ← v − δv`, and the
    /// position moved by `−δp` (ENU metres) with [`geo::apply_offset`].
    pub fn correct(&mut self, phi: &Vector3<f64>, dv: &Vector3<f64>, dp_enu: &Vector3<f64>) {
        self.q_bn = UnitQuaternion::from_scaled_axis(*phi) * self.q_bn;
        self.q_bn.renormalize();
        self.vel -= dv;
        self.lla = geo::apply_offset(&self.lla, &-dp_enu);
    }

    /// Forgets the previous increments (after a gap in the data): the next step has no
    /// coning or sculling history.
    pub fn forget_history(&mut self) {
        self.prev = None;
    }

    /// Replaces the attitude (when alignment fixes the heading); the nearest rotation is
    /// taken if `c_bn` is not orthonormal.
    pub fn set_attitude(&mut self, c_bn: Matrix3<f64>) {
        self.q_bn = nearest_rotation(&c_bn);
    }

    /// Replaces position and velocity.
    pub fn set_position_velocity(&mut self, lla: Lla, vel_enu: Vector3<f64>) {
        self.lla = lla;
        self.vel = vel_enu;
    }
}

/// The rotation nearest `c` in the Frobenius norm, the orthogonal factor of its polar
/// decomposition `U Vᵀ` (from the SVD `c = U Σ Vᵀ`, with the sign of the smallest singular
/// direction flipped if `det(U Vᵀ) < 0`); `c` itself to rounding when it is orthonormal.
fn nearest_rotation(c: &Matrix3<f64>) -> UnitQuaternion<f64> {
    // A matrix the SVD cannot take (NaN entries) falls back to Shepperd's quaternion.
    let factors = c.try_svd(true, true, f64::EPSILON, 100);
    let Some((mut u, v_t)) = factors.and_then(|svd| svd.u.zip(svd.v_t)) else {
        return UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*c));
    };
    if (u * v_t).determinant() < 0.0 {
        // nalgebra sorts singular values in decreasing order: the last is the smallest.
        u.column_mut(2).neg_mut();
    }
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(u * v_t))
}

/// Wraps an angle to [−π, π).
fn wrap_pi(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

/// `Lla` as a plain `[lat, lon, h]` array in checkpoints (geo's type carries no serde).
mod lla_array {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    use crate::geo::Lla;

    pub(super) fn serialize<S: Serializer>(p: &Lla, s: S) -> Result<S::Ok, S::Error> {
        [p.lat, p.lon, p.h].serialize(s)
    }

    pub(super) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Lla, D::Error> {
        let [lat, lon, h] = <[f64; 3]>::deserialize(d)?;
        Ok(Lla { lat, lon, h })
    }
}

#[cfg(test)]
mod tests;
