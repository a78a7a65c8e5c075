//! Local-level frames: ECEF ↔ ENU about an origin, and the small-offset
//! LLA differences (`local_offset`, `apply_offset`) that the INS error model
//! uses as position errors δp and the aiding measurements as INS − aid.
//! Built on `wgs84`; used by `filter::aiding`, `filter::federated` and `sim`.

use nalgebra::{Matrix3, Vector3};

use super::wgs84::{Lla, lla_to_ecef, radii};

/// Rotation R from ECEF to the local ENU frame at (`lat`, `lon`) (rad), so
/// that `d_enu = R d_ecef`. Its rows are the east, north and up unit vectors
/// expressed in ECEF.
pub fn ecef_to_enu_rotation(lat: f64, lon: f64) -> Matrix3<f64> {
    let (sl, cl) = lat.sin_cos();
    let (so, co) = lon.sin_cos();
    Matrix3::new(-so, co, 0.0, -sl * co, -sl * so, cl, cl * co, cl * so, sl)
}

/// ECEF position `r` (m) → ENU coordinates (m) relative to `origin`: exact,
/// `R (r − r_origin)`.
pub fn ecef_to_enu(r: &Vector3<f64>, origin: &Lla) -> Vector3<f64> {
    ecef_to_enu_rotation(origin.lat, origin.lon) * (r - lla_to_ecef(origin))
}

/// ENU coordinates `d` (m) relative to `origin` → ECEF position (m): exact,
/// `r_origin + Rᵀ d` (the inverse of [`ecef_to_enu`]).
pub fn enu_to_ecef(d: &Vector3<f64>, origin: &Lla) -> Vector3<f64> {
    lla_to_ecef(origin) + ecef_to_enu_rotation(origin.lat, origin.lon).transpose() * d
}

/// Wrap an angle to [−π, π).
fn wrap_pi(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

/// `a − b` in local ENU metres at `b`, small-offset form (the contract's
/// measurement form): `[Δλ (R_N + h) cos L, ΔL (R_M + h), Δh]` with L, h and
/// the radii taken at `b`, and Δλ wrapped to [−π, π).
///
/// Against the exact [`ecef_to_enu`] the difference is second order in the
/// offset d and bounded by d² (1 + |tan L|) / R with R ≈ 6.3e6 m. Measured at
/// 300 m: 7 mm at the equator (the Earth's curvature dropping the true ENU
/// "up" by d²/2R), 1.6 cm at 60°, 4.6 cm at 80° (meridian convergence).
/// Undefined (infinite east scale) at the poles.
pub fn local_offset(a: &Lla, b: &Lla) -> Vector3<f64> {
    let rd = radii(b.lat);
    Vector3::new(
        wrap_pi(a.lon - b.lon) * (rd.prime_vertical + b.h) * b.lat.cos(),
        (a.lat - b.lat) * (rd.meridian + b.h),
        a.h - b.h,
    )
}

/// Position `b` moved by `d_enu` (east, north, up metres), the exact inverse
/// of [`local_offset`]: `L = L_b + d_n/(R_M + h_b)`,
/// `λ = λ_b + d_e/((R_N + h_b) cos L_b)` (wrapped to [−π, π)), `h = h_b + d_u`.
/// Undefined (division by cos L = 0) at the poles.
pub fn apply_offset(b: &Lla, d_enu: &Vector3<f64>) -> Lla {
    let rd = radii(b.lat);
    Lla {
        lat: b.lat + d_enu.y / (rd.meridian + b.h),
        lon: wrap_pi(b.lon + d_enu.x / ((rd.prime_vertical + b.h) * b.lat.cos())),
        h: b.h + d_enu.z,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geo::wgs84::ecef_to_lla;
    use approx::assert_abs_diff_eq;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};
    use std::f64::consts::PI;

    fn deg(lat: f64, lon: f64, h: f64) -> Lla {
        Lla {
            lat: lat.to_radians(),
            lon: lon.to_radians(),
            h,
        }
    }

    #[test]
    fn enu_rotation_is_proper_orthonormal_with_up_along_the_ellipsoid_normal() {
        let o = deg(30.5, 114.3, 20.0);
        let r = ecef_to_enu_rotation(o.lat, o.lon);
        assert_abs_diff_eq!(r * r.transpose(), Matrix3::identity(), epsilon = 1e-15);
        assert_abs_diff_eq!(r.determinant(), 1.0, epsilon = 1e-15);
        // One metre straight up along the normal is [0, 0, 1] in ENU.
        let up = lla_to_ecef(&Lla { h: o.h + 1.0, ..o }) - lla_to_ecef(&o);
        assert_abs_diff_eq!(r * up, Vector3::new(0.0, 0.0, 1.0), epsilon = 1e-9);
        // At (0°, 0°): east is +y, north is +z, up is +x.
        let r0 = ecef_to_enu_rotation(0.0, 0.0);
        assert_abs_diff_eq!(r0 * Vector3::y(), Vector3::x(), epsilon = 1e-15);
        assert_abs_diff_eq!(r0 * Vector3::z(), Vector3::y(), epsilon = 1e-15);
        assert_abs_diff_eq!(r0 * Vector3::x(), Vector3::z(), epsilon = 1e-15);
    }

    #[test]
    fn ecef_to_enu_matches_the_pyproj_topocentric_conversion() {
        // Reference script in `wgs84::tests` (PROJ `topocentric`, origin 30.5°, 114.3°, 20 m).
        let o = deg(30.5, 114.3, 20.0);
        let cases = [
            (
                (30.5027, 114.3031, 45.0),
                [297.59055236643246, 299.33072998606497, 24.986010651098894],
            ),
            (
                (30.49, 114.31, -15.0),
                [960.0852005830716, -1108.5631187037693, -35.168934150491566],
            ),
            (
                (31.0, 115.0, 2000.0),
                [66872.26459251097, 55656.67174934355, 1386.0725777280531],
            ),
        ];
        for ((lat, lon, h), want) in cases {
            let r = lla_to_ecef(&deg(lat, lon, h));
            let d = ecef_to_enu(&r, &o);
            assert_abs_diff_eq!(d, Vector3::from(want), epsilon = 1e-7);
            assert_abs_diff_eq!(enu_to_ecef(&d, &o), r, epsilon = 1e-8);
        }
    }

    #[test]
    fn local_offset_and_apply_offset_are_inverse() {
        let mut rng = StdRng::seed_from_u64(33);
        for _ in 0..20 {
            let b = Lla {
                lat: rng.random_range(-1.5..1.5),
                lon: rng.random_range(-PI..PI),
                h: rng.random_range(-1000.0..1.0e5),
            };
            let d = Vector3::new(
                rng.random_range(-500.0..500.0),
                rng.random_range(-500.0..500.0),
                rng.random_range(-50.0..50.0),
            );
            let a = apply_offset(&b, &d);
            assert_abs_diff_eq!(local_offset(&a, &b), d, epsilon = 1e-8);
        }
    }

    #[test]
    fn local_offset_agrees_with_exact_enu_to_second_order_for_a_few_hundred_metres() {
        // Small-offset form vs exact ENU: |error| ≤ d² (1 + |tan L|) / R with
        // R = 6.3e6 m (≈ 4 cm at 500 m at low latitude): the Earth's curvature
        // in "up" plus meridian convergence (the tan L term) in east/north.
        let mut rng = StdRng::seed_from_u64(34);
        let mut worst_ratio: f64 = 0.0;
        for _ in 0..50 {
            let b = Lla {
                lat: rng.random_range(-1.4..1.4),
                lon: rng.random_range(-PI..PI),
                h: rng.random_range(-100.0..1.0e4),
            };
            let d = Vector3::new(
                rng.random_range(-500.0..500.0),
                rng.random_range(-500.0..500.0),
                rng.random_range(-50.0..50.0),
            );
            let a = apply_offset(&b, &d);
            let exact = ecef_to_enu(&lla_to_ecef(&a), &b);
            let err = (exact - local_offset(&a, &b)).norm();
            let bound = d.norm_squared() * (1.0 + b.lat.tan().abs()) / 6.3e6;
            worst_ratio = worst_ratio.max(err / bound);
        }
        assert!(worst_ratio <= 1.0, "error / bound reached {worst_ratio}");
        // And the up error at 300 m due east on the ellipsoid is the curvature drop d²/(2R_N).
        let b = deg(30.5, 114.3, 0.0);
        let a = apply_offset(&b, &Vector3::new(300.0, 0.0, 0.0));
        let exact = ecef_to_enu(&lla_to_ecef(&a), &b);
        let rn = radii(b.lat).prime_vertical;
        assert_abs_diff_eq!(exact.z, -300.0 * 300.0 / (2.0 * rn), epsilon = 1e-4);
    }

    #[test]
    fn local_offset_wraps_longitude_across_the_antimeridian() {
        let b = deg(0.0, 179.999, 0.0);
        let a = deg(0.0, -179.999, 0.0);
        let d = local_offset(&a, &b);
        let want = 0.002_f64.to_radians() * crate::geo::WGS84_A;
        assert_abs_diff_eq!(d.x, want, epsilon = 1e-6);
        let back = apply_offset(&b, &d);
        assert_abs_diff_eq!(back.lon, a.lon, epsilon = 1e-14);
        // The exact conversion through ECEF agrees.
        let via_ecef = ecef_to_lla(&enu_to_ecef(&ecef_to_enu(&lla_to_ecef(&a), &b), &b));
        assert_abs_diff_eq!(via_ecef.lon, a.lon, epsilon = 1e-14);
    }
}
