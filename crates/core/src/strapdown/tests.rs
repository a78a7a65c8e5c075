//! Tests of the mechanization against closed forms (a stationary IMU, classical coning)
//! and an independent ECEF integrator, of `correct` against the `filter::ins` error
//! convention, and of the alignment helpers (docs/methods.md §M30).

use approx::assert_abs_diff_eq;
use nalgebra::{Matrix3, Rotation3, Vector3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::f64::consts::{FRAC_PI_2, PI, TAU};

use super::*;
use crate::geo::{
    OMEGA_IE, apply_offset, dcm_body_to_nav, earth_rate_enu, ecef_to_enu_rotation, ecef_to_lla,
    lla_to_ecef, local_offset, normal_gravity, transport_rate_enu,
};

fn deg(lat: f64, lon: f64, h: f64) -> Lla {
    Lla {
        lat: lat.to_radians(),
        lon: lon.to_radians(),
        h,
    }
}

/// The small rotation angle between two attitudes: ‖vee of the skew part of `a bᵀ`‖
/// (precise for small angles, where acos of the trace is not).
fn angle_between(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    let r = a * b.transpose();
    let v = Vector3::new(
        r[(2, 1)] - r[(1, 2)],
        r[(0, 2)] - r[(2, 0)],
        r[(1, 0)] - r[(0, 1)],
    );
    (0.5 * v).norm()
}

/// What a perfect IMU fixed to the Earth at `lla` with attitude `c_bn` senses over `dt`:
/// `Δθ = C_nᵇ ω_ie dt`, `Δv = C_nᵇ [0, 0, γ] dt` (constant in the body frame, so exact).
fn stationary_increments(lla: &Lla, c_bn: &Matrix3<f64>, dt: f64) -> Increments {
    let c_nb = c_bn.transpose();
    let g = Vector3::new(0.0, 0.0, normal_gravity(lla.lat, lla.h));
    Increments {
        dtheta: (c_nb * earth_rate_enu(lla.lat) * dt).into(),
        dv: (c_nb * g * dt).into(),
        dt,
    }
}

#[test]
fn earth_rate_sensing_at_rest_is_omega_dt_along_the_body_north_and_up_axes() {
    let lla = deg(40.0, -3.7, 650.0);
    let c_bn = dcm_body_to_nav(0.2, -0.1, 2.5);
    let dt = 0.01;
    let inc = stationary_increments(&lla, &c_bn, dt);
    // Closed form: Ω dt (0, cos L, sin L) in ENU, rotated into the body by C_nᵇ.
    let (s, c) = lla.lat.sin_cos();
    let (east_b, north_b, up_b) = (
        c_bn.row(0).transpose(),
        c_bn.row(1).transpose(),
        c_bn.row(2).transpose(),
    );
    let dtheta = Vector3::from(inc.dtheta);
    let want = OMEGA_IE * dt * (c * north_b + s * up_b);
    assert_abs_diff_eq!(dtheta, want, epsilon = 1e-20);
    assert_abs_diff_eq!(dtheta.dot(&east_b), 0.0, epsilon = 1e-20);
    assert_abs_diff_eq!(dtheta.norm(), OMEGA_IE * dt, epsilon = 1e-20);
    // And the accelerometers see γ along the body's view of up.
    let g = normal_gravity(lla.lat, lla.h);
    assert_abs_diff_eq!(Vector3::from(inc.dv), g * dt * up_b, epsilon = 1e-15);
}

#[test]
fn a_perfect_imu_at_rest_for_an_hour_keeps_position_velocity_and_attitude() {
    // The only errors left are rounding and the second-order term of (I − ½[ζ×]) against
    // ½ Δθ × Δv, |ζ|² g Δt ≈ 5e-19 m/s a step: over 360,000 steps well under 1e-6 m/s
    // and 1 mm, even after the vertical channel's e^(t/570 s) growth.
    let lla = deg(40.0, 116.3, 50.0);
    let c_bn = dcm_body_to_nav(0.3, -0.25, 4.0);
    let mut sd = Strapdown::new(lla, Vector3::zeros(), c_bn);
    let dt = 0.01;
    let inc = stationary_increments(&lla, &c_bn, dt);
    for _ in 0..360_000 {
        sd.step(&inc);
    }
    let dp = local_offset(&sd.lla(), &lla).norm();
    let dv = sd.vel().norm();
    let datt = angle_between(&sd.c_bn(), &c_bn);
    eprintln!("stationary 1 h: |δp| {dp:.3e} m, |δv| {dv:.3e} m/s, attitude {datt:.3e} rad");
    assert!(dp < 1e-3, "position drifted {dp} m");
    assert!(dv < 1e-6, "velocity drifted {dv} m/s");
    assert!(datt < 1e-9, "attitude drifted {datt} rad");
    // The specific force the step reports is the one sensed.
    assert_abs_diff_eq!(
        sd.f_n(),
        Vector3::new(0.0, 0.0, normal_gravity(lla.lat, lla.h)),
        epsilon = 1e-9
    );
}

/// Classical coning relative to the navigation frame of a body fixed at one place:
/// `C_bⁿ(t) = C₀ E(t)`, `E(t) = exp(α [u(t)×])`, `u(t) = (cos Ωt, sin Ωt, 0)`: a rotation
/// vector of constant length α whose axis precesses at Ω. Its body rate is
/// `ω_nb = J_r(αu) α u̇ = Ω (−sin α sin Ωt, sin α cos Ωt, −(1 − cos α))` (u ⊥ u̇), and
/// the IMU senses `ω_ib = ω_nb + Eᵀ C₀ᵀ ω_ie`, `f_b = Eᵀ C₀ᵀ [0, 0, γ]`; every term
/// integrates in closed form, since `Eᵀ = cos α I − sin α [u×] + (1 − cos α) u uᵀ`.
struct Coning {
    c0: Matrix3<f64>,
    alpha: f64,
    omega: f64,
    w_ie: Vector3<f64>,
    f_n: Vector3<f64>,
}

impl Coning {
    fn u(&self, t: f64) -> Vector3<f64> {
        let (s, c) = (self.omega * t).sin_cos();
        Vector3::new(c, s, 0.0)
    }

    fn e(&self, t: f64) -> Matrix3<f64> {
        Rotation3::from_scaled_axis(self.alpha * self.u(t)).into_inner()
    }

    fn c_bn(&self, t: f64) -> Matrix3<f64> {
        self.c0 * self.e(t)
    }

    fn rate(&self, t: f64) -> Vector3<f64> {
        let (s, c) = (self.omega * t).sin_cos();
        let (sa, ca) = self.alpha.sin_cos();
        self.omega * Vector3::new(-sa * s, sa * c, -(1.0 - ca))
    }

    /// `∫_{t0}^{t1} ω_nb dt`.
    fn int_rate(&self, t0: f64, t1: f64) -> Vector3<f64> {
        let (s0, c0) = (self.omega * t0).sin_cos();
        let (s1, c1) = (self.omega * t1).sin_cos();
        let (sa, ca) = self.alpha.sin_cos();
        Vector3::new(
            sa * (c1 - c0),
            sa * (s1 - s0),
            -self.omega * (1.0 - ca) * (t1 - t0),
        )
    }

    /// `∫_{t0}^{t1} E(t)ᵀ w dt` for a constant `w`.
    fn int_et(&self, t0: f64, t1: f64, w: &Vector3<f64>) -> Vector3<f64> {
        let om = self.omega;
        let (s0, c0) = (om * t0).sin_cos();
        let (s1, c1) = (om * t1).sin_cos();
        let dt = t1 - t0;
        let int_u = Vector3::new((s1 - s0) / om, -(c1 - c0) / om, 0.0);
        let d2 = ((2.0 * om * t1).sin() - (2.0 * om * t0).sin()) / (4.0 * om);
        let xy = (s1 * s1 - s0 * s0) / (2.0 * om);
        let int_uut = Matrix3::new(
            dt / 2.0 + d2,
            xy,
            0.0,
            xy,
            dt / 2.0 - d2,
            0.0,
            0.0,
            0.0,
            0.0,
        );
        let (sa, ca) = self.alpha.sin_cos();
        ca * dt * w - sa * int_u.cross(w) + (1.0 - ca) * int_uut * w
    }

    fn increments(&self, t0: f64, t1: f64) -> Increments {
        let c_nb = self.c0.transpose();
        Increments {
            dtheta: (self.int_rate(t0, t1) + self.int_et(t0, t1, &(c_nb * self.w_ie))).into(),
            dv: self.int_et(t0, t1, &(c_nb * self.f_n)).into(),
            dt: t1 - t0,
        }
    }
}

fn coning_at(lla: &Lla, alpha: f64, omega: f64) -> Coning {
    Coning {
        c0: dcm_body_to_nav(0.1, 0.2, 0.7),
        alpha,
        omega,
        w_ie: earth_rate_enu(lla.lat),
        f_n: Vector3::new(0.0, 0.0, normal_gravity(lla.lat, lla.h)),
    }
}

#[test]
fn the_coning_closed_forms_match_the_attitude_they_describe() {
    let lla = deg(40.0, 10.0, 0.0);
    let cone = coning_at(&lla, 0.3, 5.0);
    // ω_nb = vee(Eᵀ Ė), Ė by central differences.
    for t in [0.0, 0.37, 1.9] {
        let h = 1e-6;
        let de = (cone.e(t + h) - cone.e(t - h)) / (2.0 * h);
        let w = cone.e(t).transpose() * de;
        let w = Vector3::new(w[(2, 1)], w[(0, 2)], w[(1, 0)]);
        assert_abs_diff_eq!(w, cone.rate(t), epsilon = 1e-8);
    }
    // The integrals against composite Simpson on 2,000 panels.
    let w = Vector3::new(0.3, -1.2, 2.0);
    let (t0, t1) = (0.4, 1.3);
    let n = 2000;
    let h = (t1 - t0) / n as f64;
    let (mut int_w, mut int_ew) = (Vector3::zeros(), Vector3::zeros());
    for i in 0..=n {
        let weight = if i == 0 || i == n {
            1.0
        } else if i % 2 == 1 {
            4.0
        } else {
            2.0
        };
        let t = t0 + i as f64 * h;
        int_w += weight * h / 3.0 * cone.rate(t);
        int_ew += weight * h / 3.0 * (cone.e(t).transpose() * w);
    }
    assert_abs_diff_eq!(int_w, cone.int_rate(t0, t1), epsilon = 1e-12);
    assert_abs_diff_eq!(int_ew, cone.int_et(t0, t1, &w), epsilon = 1e-12);
}

#[test]
fn two_sample_coning_correction_holds_the_drift_to_its_fourth_order_law() {
    // Half-angle α = 0.02 rad at 2 Hz, sampled at 100 Hz (ΩΔt = 0.126), for 60 s. The
    // two-sample algorithm leaves α² Ω (ΩΔt)⁴ / 60 rad/s (module doc); without the
    // coning term the whole coning rate α² Ω (ΩΔt)² / 12 rad/s is lost.
    let lla = deg(40.0, 10.0, 100.0);
    let (alpha, omega, dt, n) = (0.02, TAU * 2.0, 0.01, 6000);
    let cone = coning_at(&lla, alpha, omega);
    let t_end = n as f64 * dt;
    let mut with = Strapdown::new(lla, Vector3::zeros(), cone.c_bn(0.0));
    let mut without = with.clone();
    for k in 0..n {
        let inc = cone.increments(k as f64 * dt, (k + 1) as f64 * dt);
        with.step(&inc);
        without.forget_history();
        without.step(&inc);
    }
    let truth = cone.c_bn(t_end);
    let err_with = angle_between(&with.c_bn(), &truth);
    let err_without = angle_between(&without.c_bn(), &truth);
    let x = omega * dt;
    let promised = alpha * alpha * omega * x.powi(4) / 60.0 * t_end;
    let uncorrected = alpha * alpha * omega * x * x / 12.0 * t_end;
    eprintln!(
        "coning 60 s: with {err_with:.3e} rad (law {promised:.3e}), \
         without {err_without:.3e} rad (law {uncorrected:.3e})"
    );
    assert!(
        (0.8 * promised..1.2 * promised).contains(&err_with),
        "two-sample drift {err_with} rad against {promised} rad"
    );
    assert!(
        (0.8 * uncorrected..1.2 * uncorrected).contains(&err_without),
        "uncorrected drift {err_without} rad against {uncorrected} rad"
    );
    assert!(err_without > 100.0 * err_with);
    // The body stays put: the sculling-corrected velocity stays small.
    assert!(with.vel().norm() < 1e-3, "velocity {}", with.vel().norm());
}

/// A body's motion relative to the local ENU frame, for the ECEF reference below: its
/// attitude and specific force over time, and the closed-form integrals of its rate
/// relative to ENU and of its specific force.
trait Motion {
    /// `C_bⁿ(t)`, relative to the local ENU frame wherever the body is.
    fn c_bn(&self, t: f64) -> Matrix3<f64>;
    /// Specific force, body frame, m/s².
    fn f_b(&self, t: f64) -> Vector3<f64>;
    /// `∫_{t0}^{t1} ω_nb dt`, body frame.
    fn int_w_nb(&self, t0: f64, t1: f64) -> Vector3<f64>;
    /// `∫_{t0}^{t1} f_b dt`.
    fn int_f_b(&self, t0: f64, t1: f64) -> Vector3<f64>;
}

/// Level at a fixed heading with constant specific force `f_b`.
struct Steady {
    c0: Matrix3<f64>,
    f_b: Vector3<f64>,
}

impl Motion for Steady {
    fn c_bn(&self, _: f64) -> Matrix3<f64> {
        self.c0
    }
    fn f_b(&self, _: f64) -> Vector3<f64> {
        self.f_b
    }
    fn int_w_nb(&self, _: f64, _: f64) -> Vector3<f64> {
        Vector3::zeros()
    }
    fn int_f_b(&self, t0: f64, t1: f64) -> Vector3<f64> {
        self.f_b * (t1 - t0)
    }
}

/// Classical sculling: pitching `θ(t) = A sin Ωt` about body x, `C_bⁿ = C₀ R_x(θ)`, while
/// the specific force along body y is `B sin Ωt` (plus `g₀` along body z): in phase, so
/// `C_bⁿ f_b` has the rectified vertical part `A B / 2`.
struct Sculling {
    c0: Matrix3<f64>,
    a: f64,
    b: f64,
    omega: f64,
    g0: f64,
}

impl Motion for Sculling {
    fn c_bn(&self, t: f64) -> Matrix3<f64> {
        let theta = self.a * (self.omega * t).sin();
        self.c0 * Rotation3::from_axis_angle(&Vector3::x_axis(), theta).into_inner()
    }
    fn f_b(&self, t: f64) -> Vector3<f64> {
        Vector3::new(0.0, self.b * (self.omega * t).sin(), self.g0)
    }
    fn int_w_nb(&self, t0: f64, t1: f64) -> Vector3<f64> {
        // Rotation about one axis: the rate integrates to the angle's change.
        let theta = |t: f64| self.a * (self.omega * t).sin();
        Vector3::new(theta(t1) - theta(t0), 0.0, 0.0)
    }
    fn int_f_b(&self, t0: f64, t1: f64) -> Vector3<f64> {
        let y = self.b * ((self.omega * t0).cos() - (self.omega * t1).cos()) / self.omega;
        Vector3::new(0.0, y, self.g0 * (t1 - t0))
    }
}

/// An independent reference in ECEF: RK4 on `ṙ = v`, `v̇ = C_nᵉ C_bⁿ(t) f_b(t) +
/// C_nᵉ [0, 0, −γ] − 2Ω × v` (normal gravity already holds the centrifugal term
/// −Ω × (Ω × r)), from rest at `start`. It returns the ECEF position and velocity every
/// `h` seconds.
fn reference_ecef(
    start: &Lla,
    motion: &dyn Motion,
    h: f64,
    n: usize,
) -> Vec<(Vector3<f64>, Vector3<f64>)> {
    let omega = Vector3::new(0.0, 0.0, OMEGA_IE);
    let accel = |t: f64, r: &Vector3<f64>, v: &Vector3<f64>| {
        let p = ecef_to_lla(r);
        let c_ne = ecef_to_enu_rotation(p.lat, p.lon).transpose();
        let f_n = motion.c_bn(t) * motion.f_b(t);
        c_ne * (f_n - Vector3::new(0.0, 0.0, normal_gravity(p.lat, p.h))) - 2.0 * omega.cross(v)
    };
    let mut out = Vec::with_capacity(n + 1);
    let (mut r, mut v) = (lla_to_ecef(start), Vector3::zeros());
    out.push((r, v));
    for i in 0..n {
        let t = i as f64 * h;
        let (k1r, k1v) = (v, accel(t, &r, &v));
        let (k2r, k2v) = (
            v + 0.5 * h * k1v,
            accel(t + 0.5 * h, &(r + 0.5 * h * k1r), &(v + 0.5 * h * k1v)),
        );
        let (k3r, k3v) = (
            v + 0.5 * h * k2v,
            accel(t + 0.5 * h, &(r + 0.5 * h * k2r), &(v + 0.5 * h * k2v)),
        );
        let (k4r, k4v) = (v + h * k3v, accel(t + h, &(r + h * k3r), &(v + h * k3v)));
        r += h / 6.0 * (k1r + 2.0 * k2r + 2.0 * k3r + k4r);
        v += h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
        out.push((r, v));
    }
    out
}

/// Position and ENU velocity of an ECEF state.
fn lla_vel(state: &(Vector3<f64>, Vector3<f64>)) -> (Lla, Vector3<f64>) {
    let p = ecef_to_lla(&state.0);
    (p, ecef_to_enu_rotation(p.lat, p.lon) * state.1)
}

/// Runs the mechanization on the increments of `motion` along the reference trajectory
/// (`n` intervals of `dt` from rest at `start`; the gyros also sense the local frame's turn
/// `ω_ie + ω_en`, integrated by Simpson on the reference's half steps). With
/// `two_sample` false the history is forgotten before every step, which drops the coning
/// and sculling terms. Returns the mechanization and the reference's final state.
fn fly(
    start: &Lla,
    motion: &dyn Motion,
    dt: f64,
    n: usize,
    two_sample: bool,
) -> (Strapdown, (Vector3<f64>, Vector3<f64>)) {
    let states = reference_ecef(start, motion, dt / 2.0, 2 * n);
    let w_ib = |i: usize| {
        let (p, v) = lla_vel(&states[i]);
        let w_in = earth_rate_enu(p.lat) + transport_rate_enu(p.lat, p.h, &v);
        motion.c_bn(i as f64 * dt / 2.0).transpose() * w_in
    };
    let mut sd = Strapdown::new(*start, Vector3::zeros(), motion.c_bn(0.0));
    for k in 0..n {
        let (t0, t1) = (k as f64 * dt, (k + 1) as f64 * dt);
        let turn = (w_ib(2 * k) + 4.0 * w_ib(2 * k + 1) + w_ib(2 * k + 2)) * dt / 6.0;
        if !two_sample {
            sd.forget_history();
        }
        sd.step(&Increments {
            dtheta: (motion.int_w_nb(t0, t1) + turn).into(),
            dv: motion.int_f_b(t0, t1).into(),
            dt,
        });
    }
    (sd, states[2 * n])
}

#[test]
fn constant_acceleration_run_agrees_with_an_independent_ecef_integrator() {
    // Level, heading 30°, 1 m/s² forward from rest for 60 s (1.8 km, 60 m/s), 100 Hz.
    let start = deg(40.0, 116.3, 50.0);
    let c0 = dcm_body_to_nav(0.0, 0.0, 30f64.to_radians());
    let f_b = Vector3::new(0.0, 1.0, normal_gravity(start.lat, start.h));
    let (sd, end) = fly(&start, &Steady { c0, f_b }, 0.01, 6000, true);
    let (p_ref, v_ref) = lla_vel(&end);
    let dp = local_offset(&sd.lla(), &p_ref);
    let dv = (sd.vel() - v_ref).norm();
    let datt = angle_between(&sd.c_bn(), &c0);
    let travelled = local_offset(&p_ref, &start);
    eprintln!(
        "acceleration 60 s: travelled {:.1} m, speed {:.3} m/s; |δp| {:.3e} m, |δv| {dv:.3e} m/s, \
         attitude {datt:.3e} rad",
        travelled.norm(),
        v_ref.norm(),
        dp.norm()
    );
    // The run is what it says: about 1.8 km at 30°, ending near 60 m/s.
    assert_abs_diff_eq!(travelled.norm(), 1800.0, epsilon = 5.0);
    assert_abs_diff_eq!(
        travelled.x.atan2(travelled.y),
        30f64.to_radians(),
        epsilon = 1e-2
    );
    // They agree to 5e-8 m and 1e-9 m/s; the bounds leave room for rounding and still
    // catch a dropped ½[ζ×] (2e-4 m/s here) or gravity taken at the interval's start.
    assert!(dp.norm() < 1e-4, "position differs by {} m", dp.norm());
    assert!(dv < 1e-6, "velocity differs by {dv} m/s");
    assert!(datt < 1e-10, "attitude drifted {datt} rad");
}

#[test]
fn sculling_correction_removes_the_rectified_velocity_error() {
    // Pitching ±5 mrad at 2 Hz with 4 m/s² along body y in phase, 100 Hz, 60 s: the
    // rectified vertical specific force A B / 2 = 1 cm/s². What the two-sample terms leave
    // is the rotation compensation's neglected second order (Δθ × (Δθ × Δv) / 6) on the
    // body-fixed g₀: g₀ A² (ΩΔt)² T / 12 in vertical velocity.
    let start = deg(40.0, 116.3, 50.0);
    let motion = Sculling {
        c0: dcm_body_to_nav(0.0, 0.0, 2.0),
        a: 0.005,
        b: 4.0,
        omega: TAU * 2.0,
        g0: normal_gravity(start.lat, start.h),
    };
    let (dt, n) = (0.01, 6000);
    let (with, end) = fly(&start, &motion, dt, n, true);
    let (without, _) = fly(&start, &motion, dt, n, false);
    let (_, v_ref) = lla_vel(&end);
    let dv_with = (with.vel() - v_ref).norm();
    let dv_without = (without.vel() - v_ref).norm();
    let x = motion.omega * dt;
    let law = motion.g0 * motion.a * motion.a * x * x * (n as f64 * dt) / 12.0;
    eprintln!(
        "sculling 60 s: with |δv| {dv_with:.3e} m/s (law {law:.3e}), without {dv_without:.3e} m/s"
    );
    // Measured 1.4e-5 m/s: the neglected term, less a remainder of the sculling series of
    // opposite sign.
    assert!(
        dv_with < 1.2 * law,
        "two-sample velocity error {dv_with} m/s against {law} m/s"
    );
    assert!(
        dv_without > 20.0 * dv_with,
        "without sculling {dv_without} m/s"
    );
}

#[test]
fn correct_removes_errors_injected_with_the_ins_convention() {
    let p = deg(40.0, -75.0, 120.0);
    let v = Vector3::new(3.0, -4.0, 0.5);
    let c = dcm_body_to_nav(0.1, -0.2, 2.0);
    let phi = Vector3::new(1e-3, -2e-3, 3e-3);
    let dv = Vector3::new(0.1, -0.2, 0.05);
    let dp = Vector3::new(12.0, -7.0, 3.0);
    // Position: apply_offset takes the radii at its base point, so out and back differ by
    // the second-order term |δp|² (1 + |tan L|) / R (geo::frames).
    let pos_bound = dp.norm_squared() * (1.0 + p.lat.tan().abs()) / 6.3e6;

    // Exact rotation: C̃ = exp(−[φ×]) C, removed to rounding.
    let c_tilde = Rotation3::from_scaled_axis(-phi).into_inner() * c;
    let mut sd = Strapdown::new(apply_offset(&p, &dp), v + dv, c_tilde);
    sd.correct(&phi, &dv, &dp);
    assert!(angle_between(&sd.c_bn(), &c) < 1e-15);
    assert_abs_diff_eq!(sd.vel(), v, epsilon = 1e-14);
    let back = local_offset(&sd.lla(), &p).norm();
    eprintln!("correct: position back to {back:.3e} m (bound {pos_bound:.3e} m)");
    assert!(back < pos_bound);

    // First order, as filter::ins writes it: C̃ = (I − [φ×]) C, whose nearest rotation
    // turns by atan|φ|, so |φ| − atan|φ| ≈ |φ|³/3 is left.
    let mut sd = Strapdown::new(p, v, c);
    sd.set_attitude((Matrix3::identity() - geo::skew(&phi)) * c);
    sd.correct(&phi, &Vector3::zeros(), &Vector3::zeros());
    let left = angle_between(&sd.c_bn(), &c);
    eprintln!(
        "correct: first-order attitude error leaves {left:.3e} rad (|φ| {:.3e})",
        phi.norm()
    );
    assert!(left < phi.norm().powi(3) / 3.0 * 1.01, "left {left} rad");
    assert_abs_diff_eq!(
        sd.c_bn().transpose() * sd.c_bn(),
        Matrix3::identity(),
        epsilon = 1e-15
    );
}

#[test]
fn forget_history_drops_the_coning_term_and_set_position_velocity_replaces_the_state() {
    let lla = deg(10.0, 20.0, 0.0);
    let cone = coning_at(&lla, 0.05, TAU);
    let mut a = Strapdown::new(lla, Vector3::zeros(), cone.c_bn(0.0));
    a.step(&cone.increments(0.0, 0.01));
    let mut b = a.clone();
    b.forget_history();
    let inc = cone.increments(0.01, 0.02);
    a.step(&inc);
    b.step(&inc);
    assert!(angle_between(&a.c_bn(), &b.c_bn()) > 1e-12);
    let there = deg(-33.0, 151.0, 10.0);
    a.set_position_velocity(there, Vector3::new(1.0, 2.0, 3.0));
    assert_eq!(a.lla(), there);
    assert_eq!(a.vel(), Vector3::new(1.0, 2.0, 3.0));
    let c = dcm_body_to_nav(-0.4, 0.3, 5.0);
    a.set_attitude(c);
    assert_abs_diff_eq!(a.c_bn(), c, epsilon = 1e-15);
    let [r, p, y] = a.att();
    assert_abs_diff_eq!(r, -0.4, epsilon = 1e-14);
    assert_abs_diff_eq!(p, 0.3, epsilon = 1e-14);
    assert_abs_diff_eq!(y, 5.0, epsilon = 1e-14);
}

#[test]
fn level_recovers_roll_and_pitch_of_seeded_random_attitudes() {
    let mut rng = StdRng::seed_from_u64(30);
    let g = 9.8;
    let mut cases = vec![(-0.5, -0.3, 1.0), (0.5, -0.3, 4.0), (-0.5, 0.3, 0.0)];
    for _ in 0..20 {
        cases.push((
            rng.random_range(-PI..PI),
            rng.random_range(-1.5..1.5),
            rng.random_range(0.0..TAU),
        ));
    }
    for (roll, pitch, yaw) in cases {
        let c_bn = dcm_body_to_nav(roll, pitch, yaw);
        let f_b = c_bn.transpose() * Vector3::new(0.0, 0.0, g);
        let (r, p) = level(&f_b);
        assert_abs_diff_eq!(r, roll, epsilon = 1e-12);
        assert_abs_diff_eq!(p, pitch, epsilon = 1e-12);
        // The levelled attitude puts the specific force on the up axis.
        let up = dcm_body_to_nav(r, p, yaw) * f_b;
        assert_abs_diff_eq!(up, Vector3::new(0.0, 0.0, g), epsilon = 1e-12);
    }
}

#[test]
fn levelling_waits_for_min_static_s_and_restarts_on_a_moving_sample() {
    let g = 9.8;
    let (roll, pitch) = (-0.05, 0.02);
    let f_b = dcm_body_to_nav(roll, pitch, 1.0).transpose() * Vector3::new(0.0, 0.0, g);
    let w_b = Vector3::new(1e-5, -2e-5, 3e-5);
    // dt = 1/8 s: 16 samples make exactly 2 s.
    let dt = 0.125;
    let mut lev = Levelling::new(2.0, 0.05, 0.01);
    for _ in 0..15 {
        lev.add(&f_b, &w_b, dt, g);
    }
    assert_eq!(lev.attitude(), None);
    assert_eq!(lev.static_seconds(), 1.875);
    // A turning sample restarts the run, and so does a jolt.
    lev.add(&f_b, &Vector3::new(0.0, 0.0, 0.02), dt, g);
    assert_eq!(lev.static_seconds(), 0.0);
    for _ in 0..15 {
        lev.add(&f_b, &w_b, dt, g);
    }
    lev.add(&(f_b * 1.01), &w_b, dt, g);
    assert_eq!(lev.static_seconds(), 0.0);
    assert_eq!(lev.mean_rate(), None);
    for _ in 0..15 {
        lev.add(&f_b, &w_b, dt, g);
    }
    assert_eq!(lev.attitude(), None);
    lev.add(&f_b, &w_b, dt, g);
    let (r, p) = lev.attitude().expect("2 s static");
    assert_abs_diff_eq!(r, roll, epsilon = 1e-12);
    assert_abs_diff_eq!(p, pitch, epsilon = 1e-12);
    assert_abs_diff_eq!(lev.mean_rate().expect("static"), w_b, epsilon = 1e-18);
}

#[test]
fn levelling_averages_seeded_noise_below_the_thresholds() {
    let mut rng = StdRng::seed_from_u64(31);
    let g = 9.8;
    let (roll, pitch) = (0.03, -0.04);
    let f_b = dcm_body_to_nav(roll, pitch, 0.0).transpose() * Vector3::new(0.0, 0.0, g);
    let mut lev = Levelling::new(10.0, 0.1, 0.01);
    for _ in 0..1000 {
        let noise = Vector3::from_fn(|_, _| rng.random_range(-0.02..0.02));
        lev.add(&(f_b + noise), &Vector3::zeros(), 0.01, g);
    }
    let (r, p) = lev.attitude().expect("10 s static");
    // Uniform ±0.02 m/s² noise, 1000 samples: the mean's σ is 3.7e-4 m/s², 3.7e-5 rad.
    assert_abs_diff_eq!(r, roll, epsilon = 2e-4);
    assert_abs_diff_eq!(p, pitch, epsilon = 2e-4);
}

#[test]
fn heading_from_velocity_is_clockwise_from_north_in_zero_to_two_pi() {
    let cases = [
        (Vector3::new(0.0, 5.0, 0.1), 0.0),
        (Vector3::new(5.0, 0.0, 0.0), FRAC_PI_2),
        (Vector3::new(0.0, -5.0, 0.0), PI),
        (Vector3::new(-5.0, 0.0, 0.0), 3.0 * FRAC_PI_2),
        (Vector3::new(-1.0, 1.0, 0.0), 1.75 * PI),
    ];
    for (v, want) in cases {
        assert_abs_diff_eq!(heading_from_velocity(&v), want, epsilon = 1e-15);
    }
    let tiny = heading_from_velocity(&Vector3::new(-1e-300, 1.0, 0.0));
    assert!((0.0..TAU).contains(&tiny));
    // Body +y along the velocity at that heading.
    let v = Vector3::new(3.0, -4.0, 0.0);
    let fwd = dcm_body_to_nav(0.0, 0.0, heading_from_velocity(&v)) * Vector3::y();
    assert_abs_diff_eq!(fwd * 5.0, v, epsilon = 1e-14);
}

#[test]
fn strapdown_and_levelling_round_trip_through_json() {
    let lla = deg(40.0, 10.0, 100.0);
    let cone = coning_at(&lla, 0.02, TAU);
    let mut sd = Strapdown::new(lla, Vector3::new(1.0, 2.0, 0.0), cone.c_bn(0.0));
    for k in 0..3 {
        sd.step(&cone.increments(k as f64 * 0.01, (k + 1) as f64 * 0.01));
    }
    let json = serde_json::to_string(&sd).expect("serialise");
    let mut back: Strapdown = serde_json::from_str(&json).expect("deserialise");
    assert_eq!(back, sd);
    // The restored state, history included, steps identically.
    let inc = cone.increments(0.03, 0.04);
    sd.step(&inc);
    back.step(&inc);
    assert_eq!(back, sd);

    let mut lev = Levelling::new(1.0, 0.1, 0.01);
    lev.add(
        &Vector3::new(0.1, -0.2, 9.8),
        &Vector3::new(1e-5, 0.0, 0.0),
        0.01,
        9.8,
    );
    let back: Levelling =
        serde_json::from_str(&serde_json::to_string(&lev).expect("serialise")).expect("parse");
    assert_eq!(back, lev);
}
