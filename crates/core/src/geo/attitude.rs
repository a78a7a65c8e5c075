//! Attitude: the body-to-navigation direction cosine matrix C_bⁿ from Euler
//! angles and back, and the skew-symmetric (cross-product) matrix. Used by the
//! INS error model (`filter::ins`), the DVL aiding model and the simulator.
//!
//! Convention: navigation frame ENU, body frame RFU
//! (x right, y forward, z up); yaw = heading clockwise from north, pitch
//! nose-up positive, roll right-wing-down positive;
//! `C_bⁿ = R_z(−yaw) · R_x(pitch) · R_y(roll)`.

use nalgebra::{Matrix3, Vector3};

/// Body (RFU) → navigation (ENU) direction cosine matrix
/// `C_bⁿ = R_z(−yaw) R_x(pitch) R_y(roll)` for angles in radians.
///
/// Written out (c = cos, s = sin, φ roll, θ pitch, ψ yaw):
/// ```text
/// [ cψcφ + sψsθsφ    sψcθ    cψsφ − sψsθcφ ]
/// [ −sψcφ + cψsθsφ   cψcθ   −sψsφ − cψsθcφ ]
/// [ −cθsφ            sθ      cθcφ          ]
/// ```
pub fn dcm_body_to_nav(roll: f64, pitch: f64, yaw: f64) -> Matrix3<f64> {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sy, cy) = yaw.sin_cos();
    Matrix3::new(
        cy * cr + sy * sp * sr,
        sy * cp,
        cy * sr - sy * sp * cr,
        -sy * cr + cy * sp * sr,
        cy * cp,
        -sy * sr - cy * sp * cr,
        -cp * sr,
        sp,
        cp * cr,
    )
}

/// Euler angles `[roll, pitch, yaw]` (rad) of a body → ENU matrix built as in
/// [`dcm_body_to_nav`]: pitch = asin C₃₂ in [−π/2, π/2], roll =
/// atan2(−C₃₁, C₃₃) in (−π, π], yaw = atan2(C₁₂, C₂₂) in [0, 2π).
/// At pitch = ±90° (gimbal lock) roll and yaw are not separable; the
/// result is then still finite but only their combination is meaningful.
pub fn euler_from_dcm(c_bn: &Matrix3<f64>) -> [f64; 3] {
    let pitch = c_bn[(2, 1)].clamp(-1.0, 1.0).asin();
    let roll = (-c_bn[(2, 0)]).atan2(c_bn[(2, 2)]);
    let mut yaw = c_bn[(0, 1)]
        .atan2(c_bn[(1, 1)])
        .rem_euclid(std::f64::consts::TAU);
    // rem_euclid of a tiny negative angle can round up to exactly 2π.
    if yaw >= std::f64::consts::TAU {
        yaw = 0.0;
    }
    [roll, pitch, yaw]
}

/// Skew-symmetric matrix [v×], so that `skew(a) * b = a × b`.
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};
    use std::f64::consts::{FRAC_PI_2, PI, TAU};

    fn rx(a: f64) -> Matrix3<f64> {
        let (s, c) = a.sin_cos();
        Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
    }
    fn ry(a: f64) -> Matrix3<f64> {
        let (s, c) = a.sin_cos();
        Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
    }
    fn rz(a: f64) -> Matrix3<f64> {
        let (s, c) = a.sin_cos();
        Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
    }

    #[test]
    fn yaw_90_degrees_maps_body_forward_to_east_and_right_to_south() {
        let c = dcm_body_to_nav(0.0, 0.0, FRAC_PI_2);
        assert_abs_diff_eq!(c * Vector3::y(), Vector3::x(), epsilon = 1e-15);
        assert_abs_diff_eq!(c * Vector3::x(), -Vector3::y(), epsilon = 1e-15);
        // Zero attitude: body RFU coincides with ENU (forward = north).
        assert_abs_diff_eq!(dcm_body_to_nav(0.0, 0.0, 0.0), Matrix3::identity());
    }

    #[test]
    fn pitch_up_raises_forward_and_roll_right_wing_down_lowers_body_x() {
        let up = dcm_body_to_nav(0.0, 0.1, 0.0) * Vector3::y();
        assert_abs_diff_eq!(up.z, 0.1_f64.sin(), epsilon = 1e-15);
        let right = dcm_body_to_nav(0.1, 0.0, 0.0) * Vector3::x();
        assert_abs_diff_eq!(right.z, -0.1_f64.sin(), epsilon = 1e-15);
        // Rolling does not move the forward axis; pitching does not move the right axis.
        assert_abs_diff_eq!(dcm_body_to_nav(0.3, 0.0, 0.0) * Vector3::y(), Vector3::y());
        assert_abs_diff_eq!(dcm_body_to_nav(0.0, 0.3, 0.0) * Vector3::x(), Vector3::x());
    }

    #[test]
    fn dcm_is_the_product_of_the_elementary_rotations_and_orthonormal() {
        let mut rng = StdRng::seed_from_u64(4);
        for _ in 0..20 {
            let (r, p, y) = (
                rng.random_range(-PI..PI),
                rng.random_range(-FRAC_PI_2..FRAC_PI_2),
                rng.random_range(0.0..TAU),
            );
            let c = dcm_body_to_nav(r, p, y);
            assert_abs_diff_eq!(c, rz(-y) * rx(p) * ry(r), epsilon = 1e-15);
            assert_abs_diff_eq!(c.transpose() * c, Matrix3::identity(), epsilon = 1e-15);
            assert_abs_diff_eq!(c.determinant(), 1.0, epsilon = 1e-14);
        }
    }

    #[test]
    fn euler_from_dcm_recovers_seeded_random_angles() {
        let mut rng = StdRng::seed_from_u64(5);
        for _ in 0..50 {
            let roll = rng.random_range(-PI..PI);
            let pitch = rng.random_range(-1.45..1.45); // ±83°, away from gimbal lock
            let yaw = rng.random_range(0.0..TAU);
            let [r, p, y] = euler_from_dcm(&dcm_body_to_nav(roll, pitch, yaw));
            assert_abs_diff_eq!(r, roll, epsilon = 1e-12);
            assert_abs_diff_eq!(p, pitch, epsilon = 1e-12);
            assert_abs_diff_eq!(y, yaw, epsilon = 1e-12);
        }
    }

    #[test]
    fn euler_from_dcm_returns_yaw_in_zero_to_two_pi() {
        let [_, _, y] = euler_from_dcm(&dcm_body_to_nav(0.0, 0.0, -0.1));
        assert_abs_diff_eq!(y, TAU - 0.1, epsilon = 1e-14);
        let [_, _, y] = euler_from_dcm(&dcm_body_to_nav(0.0, 0.0, -1e-300));
        assert!((0.0..TAU).contains(&y));
    }

    #[test]
    fn skew_a_times_b_is_the_cross_product() {
        let mut rng = StdRng::seed_from_u64(6);
        for _ in 0..10 {
            let a = Vector3::from_fn(|_, _| rng.random_range(-10.0..10.0));
            let b = Vector3::from_fn(|_, _| rng.random_range(-10.0..10.0));
            assert_abs_diff_eq!(skew(&a) * b, a.cross(&b), epsilon = 1e-12);
            assert_abs_diff_eq!(skew(&a).transpose(), -skew(&a));
        }
    }
}
