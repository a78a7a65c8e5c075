//! Truth trajectories built from segments (straight legs, coordinated turns,
//! speed changes, vertical-speed changes and climbs), sampled at a fixed rate
//! into [`Truth`]: position, ENU velocity, attitude, body specific force and
//! angular rate. The first stage of every scenario (`scenario`); `track` builds
//! the same [`Truth`] from real RTK fixes.
//!
//! Motion model: the vehicle moves along its velocity vector (no sideslip, no
//! angle of attack), with horizontal speed `V`, heading `ψ` and vertical speed
//! `v_u`; within a segment `V̇`, `ψ̇` and `v̇_u` are constant, so velocity is
//! continuous everywhere and acceleration is piecewise constant. Attitude:
//! yaw = heading, pitch = climb angle `atan2(v_u, V)`, roll = the coordinated-turn
//! bank `atan(V ψ̇ / g)` (right turn, right wing down, positive). Bank and pitch
//! rate step at segment boundaries (roll-in is instantaneous; the angular-rate
//! samples carry no impulse there) — gentle for the ship's 0.5°/s turns (bank ≈ 0.5°).
//!
//! Specific force and angular rate follow from these kinematics as in `truth`
//! (`fⁿ = v̇ⁿ + (2ω_ie + ω_en) × vⁿ − gⁿ`, `ω_ib^b = ω_nb^b + C_nᵇ (ω_ie + ω_en)`), with
//! `ω_nb^b` from the Euler-angle rates of the closed-form attitude.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::truth::{Truth, body_rate, specific_force_nav, wrap_2pi};
use super::{SimError, check_non_negative, check_positive};
use navguard_core::geo::{self, Lla};

/// `ω_nb^b` from Euler rates for `C_bⁿ = R_z(−ψ) R_x(θ) R_y(φ)`:
/// `(R_x R_y)ᵀ [0, 0, −ψ̇] + R_yᵀ [θ̇, 0, 0] + [0, φ̇, 0]`.
fn euler_rates_to_body(att: [f64; 3], rates: [f64; 3]) -> Vector3<f64> {
    let (sr, cr) = att[0].sin_cos();
    let (sp, cp) = att[1].sin_cos();
    let r_y = Matrix3::new(cr, 0.0, sr, 0.0, 1.0, 0.0, -sr, 0.0, cr);
    let r_x = Matrix3::new(1.0, 0.0, 0.0, 0.0, cp, -sp, 0.0, sp, cp);
    (r_x * r_y).transpose() * Vector3::new(0.0, 0.0, -rates[2])
        + r_y.transpose() * Vector3::new(rates[1], 0.0, 0.0)
        + Vector3::new(0.0, rates[0], 0.0)
}

/// One piece of a trajectory; within it `V̇`, `ψ̇` and `v̇_u` are constant.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Segment {
    /// Constant velocity.
    Straight {
        /// Duration, s.
        duration_s: f64,
    },
    /// Coordinated turn at constant speed.
    Turn {
        /// Duration, s.
        duration_s: f64,
        /// Heading rate ψ̇, rad/s, positive clockwise (a right turn).
        rate_rps: f64,
    },
    /// Horizontal speed change at constant acceleration.
    SpeedChange {
        /// Duration, s.
        duration_s: f64,
        /// Horizontal acceleration, m/s².
        accel_mps2: f64,
    },
    /// Vertical speed change at constant vertical acceleration.
    VerticalSpeedChange {
        /// Duration, s.
        duration_s: f64,
        /// Vertical acceleration, m/s².
        accel_mps2: f64,
    },
}

impl Segment {
    /// The segment's duration, s.
    pub fn duration_s(&self) -> f64 {
        match *self {
            Segment::Straight { duration_s }
            | Segment::Turn { duration_s, .. }
            | Segment::SpeedChange { duration_s, .. }
            | Segment::VerticalSpeedChange { duration_s, .. } => duration_s,
        }
    }

    /// `(V̇, ψ̇, v̇_u)` during the segment.
    fn rates(&self) -> [f64; 3] {
        match *self {
            Segment::Straight { .. } => [0.0; 3],
            Segment::Turn { rate_rps, .. } => [0.0, rate_rps, 0.0],
            Segment::SpeedChange { accel_mps2, .. } => [accel_mps2, 0.0, 0.0],
            Segment::VerticalSpeedChange { accel_mps2, .. } => [0.0, 0.0, accel_mps2],
        }
    }
}

/// Horizontal speed, heading and vertical speed with their rates at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Kinematics {
    /// `[V, ψ, v_u]`.
    state: [f64; 3],
    /// `[V̇, ψ̇, v̇_u]`.
    rates: [f64; 3],
}

impl Kinematics {
    fn vel(&self) -> Vector3<f64> {
        let [v, psi, vu] = self.state;
        Vector3::new(v * psi.sin(), v * psi.cos(), vu)
    }

    fn vel_dot(&self) -> Vector3<f64> {
        let [v, psi, _] = self.state;
        let [v_dot, psi_dot, vu_dot] = self.rates;
        let (s, c) = psi.sin_cos();
        Vector3::new(
            v_dot * s + v * c * psi_dot,
            v_dot * c - v * s * psi_dot,
            vu_dot,
        )
    }
}

/// A trajectory: a start and a list of segments. Past its end the vehicle keeps
/// its final velocity (a straight leg).
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    start: Lla,
    /// `[V, ψ, v_u]` at t = 0.
    initial: [f64; 3],
    /// Each segment with its start time and start state.
    segments: Vec<(f64, [f64; 3], Segment)>,
    end: (f64, [f64; 3]),
}

impl Trajectory {
    /// Start position.
    pub fn start(&self) -> Lla {
        self.start
    }

    /// Total duration of the segments, s.
    pub fn duration_s(&self) -> f64 {
        self.end.0
    }

    /// The segments in order.
    pub fn segments(&self) -> impl Iterator<Item = &Segment> {
        self.segments.iter().map(|(_, _, s)| s)
    }

    fn kinematics(&self, t: f64) -> Kinematics {
        let i = self.segments.partition_point(|(t0, _, _)| *t0 <= t);
        if i == 0 {
            return Kinematics {
                state: self.initial,
                rates: [0.0; 3],
            };
        }
        let (t0, s0, seg) = &self.segments[i - 1];
        let tau = t - t0;
        if tau >= seg.duration_s() {
            return Kinematics {
                state: self.end.1,
                rates: [0.0; 3],
            };
        }
        let rates = seg.rates();
        let state = [
            s0[0] + rates[0] * tau,
            s0[1] + rates[1] * tau,
            s0[2] + rates[2] * tau,
        ];
        Kinematics { state, rates }
    }

    /// Samples the truth at `rate_hz` from t = 0 to `duration_s` inclusive
    /// (`⌊duration·rate⌋ + 1` samples at `t_k = k / rate`). Position integrates the
    /// velocity with the midpoint rule over the WGS84 radii (error O(Δt³) per step).
    pub fn sample(&self, rate_hz: f64, duration_s: f64) -> Result<Vec<Truth>, SimError> {
        check_positive("rate_hz", rate_hz)?;
        check_non_negative("duration_s", duration_s)?;
        let n = (duration_s * rate_hz + 1e-9).floor() as usize + 1;
        let dt = 1.0 / rate_hz;
        let mut out = Vec::with_capacity(n);
        let mut p = self.start;
        for k in 0..n {
            let t = k as f64 * dt;
            out.push(self.truth_at(t, &p));
            // Midpoint rule: velocity at t + dt/2, radii at the half-step position.
            let v_mid = self.kinematics(t + 0.5 * dt).vel();
            let mid = geo::apply_offset(&p, &(v_mid * (0.5 * dt)));
            let r = geo::radii(mid.lat);
            p = Lla {
                lat: p.lat + v_mid.y * dt / (r.meridian + mid.h),
                lon: p.lon + v_mid.x * dt / ((r.prime_vertical + mid.h) * mid.lat.cos()),
                h: p.h + v_mid.z * dt,
            };
        }
        Ok(out)
    }

    fn truth_at(&self, t: f64, lla: &Lla) -> Truth {
        let k = self.kinematics(t);
        let [v, psi, vu] = k.state;
        let [v_dot, psi_dot, vu_dot] = k.rates;
        let g = geo::normal_gravity(lla.lat, lla.h);
        let tan_roll = v * psi_dot / g;
        let roll = tan_roll.atan();
        let pitch = vu.atan2(v);
        let yaw = wrap_2pi(psi);
        let speed2 = v * v + vu * vu;
        let pitch_dot = if speed2 > 0.0 {
            (v * vu_dot - vu * v_dot) / speed2
        } else {
            0.0
        };
        let roll_dot = v_dot * psi_dot / g / (1.0 + tan_roll * tan_roll);
        let att = [roll, pitch, yaw];
        let vel = k.vel();
        let c_bn = geo::dcm_body_to_nav(roll, pitch, yaw);
        let f_n = specific_force_nav(lla, &vel, &k.vel_dot());
        let omega_nb = euler_rates_to_body(att, [roll_dot, pitch_dot, psi_dot]);
        Truth {
            t,
            lla: *lla,
            vel,
            att,
            f_b: c_bn.transpose() * f_n,
            omega_ib_b: body_rate(lla, &vel, &c_bn, &omega_nb),
        }
    }
}

/// Finite and strictly positive.
fn positive(x: f64) -> bool {
    x.is_finite() && x > 0.0
}

/// Builds a [`Trajectory`] segment by segment; the first invalid call is
/// remembered and returned by [`TrajectoryBuilder::build`].
#[derive(Debug, Clone)]
pub struct TrajectoryBuilder {
    start: Lla,
    initial: [f64; 3],
    current: [f64; 3],
    t: f64,
    segments: Vec<(f64, [f64; 3], Segment)>,
    error: Option<SimError>,
}

impl TrajectoryBuilder {
    /// Starts at `start`, horizontal speed `speed_mps` (≥ 0), heading `heading_rad`
    /// (clockwise from north), level.
    pub fn new(start: Lla, speed_mps: f64, heading_rad: f64) -> Self {
        let mut error = None;
        if !(start.lat.is_finite() && start.lon.is_finite() && start.h.is_finite())
            || start.lat.abs() >= std::f64::consts::FRAC_PI_2
        {
            error = Some(SimError::param("start", "must be finite and off the poles"));
        } else if let Err(e) = check_non_negative("speed_mps", speed_mps) {
            error = Some(e);
        } else if !heading_rad.is_finite() {
            error = Some(SimError::param("heading_rad", "must be finite"));
        }
        let initial = [speed_mps, heading_rad, 0.0];
        TrajectoryBuilder {
            start,
            initial,
            current: initial,
            t: 0.0,
            segments: Vec::new(),
            error,
        }
    }

    fn push(mut self, seg: Segment) -> Self {
        if self.error.is_some() {
            return self;
        }
        let d = seg.duration_s();
        if let Err(e) = check_non_negative("duration_s", d) {
            self.error = Some(e);
            return self;
        }
        if d == 0.0 {
            return self;
        }
        let r = seg.rates();
        self.segments.push((self.t, self.current, seg));
        self.t += d;
        self.current = [
            self.current[0] + r[0] * d,
            self.current[1] + r[1] * d,
            self.current[2] + r[2] * d,
        ];
        self
    }

    fn fail(mut self, field: &str, reason: String) -> Self {
        if self.error.is_none() {
            self.error = Some(SimError::param(field, reason));
        }
        self
    }

    /// A straight leg of `duration_s` at the current velocity.
    pub fn straight(self, duration_s: f64) -> Self {
        self.push(Segment::Straight { duration_s })
    }

    /// A coordinated turn through `heading_change_rad` (positive: right, clockwise)
    /// at `rate_rps` (> 0, the magnitude of ψ̇); bank `atan(V ψ̇ / g)`.
    pub fn turn(self, heading_change_rad: f64, rate_rps: f64) -> Self {
        if !(heading_change_rad.is_finite() && positive(rate_rps)) {
            return self.fail(
                "turn",
                format!("needs a finite change and rate > 0, got {heading_change_rad}, {rate_rps}"),
            );
        }
        let duration_s = heading_change_rad.abs() / rate_rps;
        self.push(Segment::Turn {
            duration_s,
            rate_rps: rate_rps.copysign(heading_change_rad),
        })
    }

    /// Changes horizontal speed to `target_mps` (≥ 0) at constant acceleration of
    /// magnitude `accel_mps2` (> 0).
    pub fn speed_change(self, target_mps: f64, accel_mps2: f64) -> Self {
        if !(target_mps.is_finite() && target_mps >= 0.0 && positive(accel_mps2)) {
            return self.fail(
                "speed_change",
                format!("needs target ≥ 0 and accel > 0, got {target_mps}, {accel_mps2}"),
            );
        }
        let dv = target_mps - self.current[0];
        self.push(Segment::SpeedChange {
            duration_s: dv.abs() / accel_mps2,
            accel_mps2: accel_mps2.copysign(dv),
        })
    }

    /// Changes vertical speed to `target_mps` (up positive) at constant vertical
    /// acceleration of magnitude `accel_mps2` (> 0).
    pub fn vertical_speed_change(self, target_mps: f64, accel_mps2: f64) -> Self {
        if !(target_mps.is_finite() && positive(accel_mps2)) {
            return self.fail(
                "vertical_speed_change",
                format!("needs a finite target and accel > 0, got {target_mps}, {accel_mps2}"),
            );
        }
        let dv = target_mps - self.current[2];
        self.push(Segment::VerticalSpeedChange {
            duration_s: dv.abs() / accel_mps2,
            accel_mps2: accel_mps2.copysign(dv),
        })
    }

    /// A climb (or descent, `height_change_m < 0`) from level flight: accelerate to
    /// `vertical_speed_mps` (magnitude) at `accel_mps2`, hold, and level off, so that
    /// the height changes by exactly `height_change_m`. Entry and exit together
    /// take `v²/a` of height; the hold covers the rest (refused if negative).
    pub fn climb(self, height_change_m: f64, vertical_speed_mps: f64, accel_mps2: f64) -> Self {
        if self.current[2] != 0.0 {
            return self.fail("climb", "must start from level flight".into());
        }
        let v = vertical_speed_mps.abs();
        if !(height_change_m.is_finite() && positive(v) && positive(accel_mps2)) {
            return self.fail("climb", format!("needs finite height, speed > 0, accel > 0, got {height_change_m}, {vertical_speed_mps}, {accel_mps2}"));
        }
        let hold = (height_change_m.abs() - v * v / accel_mps2) / v;
        if hold < 0.0 {
            return self.fail(
                "climb",
                format!("{height_change_m} m is too short to reach {v} m/s at {accel_mps2} m/s²"),
            );
        }
        let signed = v.copysign(height_change_m);
        self.vertical_speed_change(signed, accel_mps2)
            .straight(hold)
            .vertical_speed_change(0.0, accel_mps2)
    }

    /// The trajectory, or the first invalid parameter.
    pub fn build(self) -> Result<Trajectory, SimError> {
        if let Some(e) = self.error {
            return Err(e);
        }
        Ok(Trajectory {
            start: self.start,
            initial: self.initial,
            segments: self.segments,
            end: (self.t, self.current),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn at_30n() -> Lla {
        Lla {
            lat: 30f64.to_radians(),
            lon: 114f64.to_radians(),
            h: 0.0,
        }
    }

    #[test]
    fn straight_leg_keeps_ground_speed_and_covers_the_distance() {
        // North along a meridian and east along a parallel: 10 m/s for 100 s = 1000 m.
        for heading in [0.0, 90f64.to_radians()] {
            let traj = TrajectoryBuilder::new(at_30n(), 10.0, heading)
                .straight(100.0)
                .build()
                .unwrap();
            let truth = traj.sample(10.0, 100.0).unwrap();
            assert_eq!(truth.len(), 1001);
            for s in &truth {
                assert_relative_eq!(s.vel.xy().norm(), 10.0, max_relative = 1e-14);
                assert_eq!(s.vel.z, 0.0);
            }
            // The ECEF chord is the arc to s³/24R² ≈ 1e-6 m.
            let chord = geo::lla_to_ecef(&truth[1000].lla) - geo::lla_to_ecef(&truth[0].lla);
            assert_relative_eq!(chord.norm(), 1000.0, epsilon = 1e-5);
            assert_relative_eq!(truth[1000].att[2], heading, epsilon = 1e-15);
        }
    }

    #[test]
    fn coordinated_turn_has_the_heading_change_and_bank() {
        // 90° right at 3°/s and 50 m/s: tan φ = V ω / g.
        let rate = 3f64.to_radians();
        let traj = TrajectoryBuilder::new(at_30n(), 50.0, 0.0)
            .straight(10.0)
            .turn(90f64.to_radians(), rate)
            .straight(10.0)
            .build()
            .unwrap();
        assert_relative_eq!(traj.duration_s(), 50.0, epsilon = 1e-12);
        let truth = traj.sample(10.0, 50.0).unwrap();
        assert_relative_eq!(
            truth[500].att[2] - truth[0].att[2],
            90f64.to_radians(),
            epsilon = 1e-12
        );
        let mid = &truth[250];
        let g = geo::normal_gravity(mid.lla.lat, mid.lla.h);
        assert_relative_eq!(mid.att[0].tan(), 50.0 * rate / g, max_relative = 1e-12);
        assert!(mid.att[0] > 0.0, "a right turn banks right wing down");
        // Coordinated: no side force beyond Coriolis/transport (≲ 2Ω V ≈ 7e-3 m/s²),
        // and the vertical specific force carries the load factor g / cos φ.
        assert!(mid.f_b.x.abs() < 1e-2, "side force {}", mid.f_b.x);
        assert_relative_eq!(mid.f_b.z, g / mid.att[0].cos(), max_relative = 1e-3);
        // Body rate during the turn: ψ̇ projected on body axes, mostly −z (right turn).
        assert_relative_eq!(mid.omega_ib_b.norm(), rate, max_relative = 2e-3);
        assert_eq!(truth[50].att[0], 0.0);
        assert_eq!(truth[499].att[0], 0.0);
    }

    #[test]
    fn at_rest_specific_force_is_gravity_up_and_rate_is_earth_rate() {
        let traj = TrajectoryBuilder::new(at_30n(), 0.0, 0.0)
            .straight(10.0)
            .build()
            .unwrap();
        let s = &traj.sample(1.0, 10.0).unwrap()[5];
        let g = geo::normal_gravity(30f64.to_radians(), 0.0);
        assert_relative_eq!(s.f_b, Vector3::new(0.0, 0.0, g), epsilon = 1e-15);
        assert_relative_eq!(
            s.omega_ib_b,
            geo::earth_rate_enu(30f64.to_radians()),
            epsilon = 1e-18
        );
        assert_relative_eq!(g, 9.7933, epsilon = 1e-4);
    }

    #[test]
    fn speed_change_and_climb_follow_their_closed_forms() {
        let traj = TrajectoryBuilder::new(at_30n(), 10.0, 0.0)
            .speed_change(20.0, 0.5)
            .climb(100.0, 2.0, 0.1)
            .build()
            .unwrap();
        // 20 s of acceleration, then 20 s entry + 30 s hold + 20 s exit.
        assert_relative_eq!(traj.duration_s(), 90.0, epsilon = 1e-12);
        let truth = traj.sample(10.0, 90.0).unwrap();
        assert_relative_eq!(truth[100].vel.y, 15.0, epsilon = 1e-12);
        // Forward acceleration 0.5 m/s² shows as body y specific force (level, heading north).
        assert_relative_eq!(truth[100].f_b.y, 0.5, epsilon = 1e-3);
        assert_relative_eq!(truth[900].lla.h, 100.0, epsilon = 1e-9);
        // During the hold: pitch = atan(2 / 20).
        assert_relative_eq!(truth[450].att[1], (2.0f64 / 20.0).atan(), epsilon = 1e-12);
    }

    #[test]
    fn builder_rejects_bad_parameters_naming_them() {
        let bad = TrajectoryBuilder::new(at_30n(), 10.0, 0.0)
            .straight(-1.0)
            .build();
        assert!(
            matches!(bad, Err(SimError::InvalidParameter { ref field, .. }) if field == "duration_s")
        );
        let bad = TrajectoryBuilder::new(at_30n(), 10.0, 0.0)
            .climb(1.0, 5.0, 0.1)
            .build();
        assert!(
            matches!(bad, Err(SimError::InvalidParameter { ref field, .. }) if field == "climb")
        );
        assert!(TrajectoryBuilder::new(at_30n(), -1.0, 0.0).build().is_err());
        assert!(
            TrajectoryBuilder::new(at_30n(), 1.0, 0.0)
                .build()
                .unwrap()
                .sample(0.0, 1.0)
                .is_err()
        );
    }
}
