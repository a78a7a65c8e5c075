//! The WGS84 ellipsoid: geodetic ↔ Earth-centred Earth-fixed coordinates,
//! radii of curvature, Earth and transport rates, and normal gravity. Every
//! other geodesy function (`frames`) and the INS error model build on these.

use nalgebra::Vector3;

/// WGS84 semi-major axis a, metres.
pub const WGS84_A: f64 = 6_378_137.0;
/// WGS84 flattening f.
pub const WGS84_F: f64 = 1.0 / 298.257_223_563;
/// WGS84 first eccentricity squared e² = f (2 − f).
pub const WGS84_E2: f64 = WGS84_F * (2.0 - WGS84_F);
/// WGS84 semi-minor axis b = a (1 − f), metres.
pub const WGS84_B: f64 = WGS84_A * (1.0 - WGS84_F);
/// Earth rotation rate Ω_ie (WGS84), rad/s.
pub const OMEGA_IE: f64 = 7.292_115e-5;

/// Normal gravity on the ellipsoid at the equator γ_e (WGS84), m/s².
const GAMMA_E: f64 = 9.780_325_335_9;
/// Somigliana constant k = b γ_p / (a γ_e) − 1 (WGS84, NIMA TR8350.2 eq. 4-1).
const SOMIGLIANA_K: f64 = 0.001_931_852_652_41;
/// m = Ω² a² b / GM (WGS84), used in the free-air height correction.
const GRAVITY_M: f64 = 0.003_449_786_506_84;

/// A geodetic position on WGS84: latitude and longitude in radians, height
/// above the ellipsoid in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lla {
    /// Geodetic latitude L, radians, north positive.
    pub lat: f64,
    /// Longitude λ, radians, east positive.
    pub lon: f64,
    /// Height above the ellipsoid h, metres.
    pub h: f64,
}

/// The two principal radii of curvature at a latitude, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Radii {
    /// Meridian radius R_M = a (1 − e²) / (1 − e² sin²L)^{3/2} (north–south).
    pub meridian: f64,
    /// Prime-vertical radius R_N = a / √(1 − e² sin²L) (east–west).
    pub prime_vertical: f64,
}

/// Radii of curvature R_M (meridian) and R_N (prime vertical) at latitude `lat` (rad).
pub fn radii(lat: f64) -> Radii {
    let s = lat.sin();
    let w2 = 1.0 - WGS84_E2 * s * s;
    let w = w2.sqrt();
    Radii {
        meridian: WGS84_A * (1.0 - WGS84_E2) / (w2 * w),
        prime_vertical: WGS84_A / w,
    }
}

/// Geodetic position → ECEF position (metres):
/// `[(R_N + h) cos L cos λ, (R_N + h) cos L sin λ, (R_N (1 − e²) + h) sin L]`.
pub fn lla_to_ecef(p: &Lla) -> Vector3<f64> {
    let n = radii(p.lat).prime_vertical;
    let (sl, cl) = p.lat.sin_cos();
    let (so, co) = p.lon.sin_cos();
    Vector3::new(
        (n + p.h) * cl * co,
        (n + p.h) * cl * so,
        (n * (1.0 - WGS84_E2) + p.h) * sl,
    )
}

/// ECEF position (metres) → geodetic position.
///
/// Bowring's parametric-latitude iteration written with `atan2` (Bowring 1976;
/// Fukushima 1999 on its convergence), so the poles (p = √(x²+y²) = 0) and the
/// equator are handled exactly: there `atan2` returns ±π/2 or 0 directly.
/// It converges cubically; we iterate until the latitude stops changing
/// (at most 8 rounds, 2–3 in practice for heights −1 km..1000 km). The
/// height uses the form `h = p cos L + (z + e² R_N sin L) sin L − R_N`, which
/// has no 1/cos L and is exact at the poles. Round trips through
/// [`lla_to_ecef`] agree to a few nanometres (the f64 resolution at 6e6 m).
/// On the polar axis the longitude is undefined and returned as 0; at the
/// Earth's centre the result is (0, 0, −a).
pub fn ecef_to_lla(r: &Vector3<f64>) -> Lla {
    let (x, y, z) = (r.x, r.y, r.z);
    let p = x.hypot(y);
    let lon = if p > 0.0 { y.atan2(x) } else { 0.0 };
    // Second eccentricity squared e'² = e² / (1 − e²).
    let ep2 = WGS84_E2 / (1.0 - WGS84_E2);
    // Parametric (reduced) latitude β: tan β = (1 − f) tan L.
    let mut beta = z.atan2((1.0 - WGS84_F) * p);
    let mut lat = 0.0;
    for _ in 0..8 {
        let (sb, cb) = beta.sin_cos();
        // Bowring: tan L = (z + e'² b sin³β) / (p − e² a cos³β).
        let next = (z + ep2 * WGS84_B * sb * sb * sb).atan2(p - WGS84_E2 * WGS84_A * cb * cb * cb);
        let done = (next - lat).abs() <= 1e-15;
        lat = next;
        if done {
            break;
        }
        beta = ((1.0 - WGS84_F) * lat.sin()).atan2(lat.cos());
    }
    let n = radii(lat).prime_vertical;
    let (sl, cl) = lat.sin_cos();
    let h = p * cl + (z + WGS84_E2 * n * sl) * sl - n;
    Lla { lat, lon, h }
}

/// Earth rotation rate seen in the local ENU frame, rad/s:
/// `ω_ie^n = [0, Ω cos L, Ω sin L]`.
pub fn earth_rate_enu(lat: f64) -> Vector3<f64> {
    Vector3::new(0.0, OMEGA_IE * lat.cos(), OMEGA_IE * lat.sin())
}

/// Transport rate (rotation of ENU relative to ECEF caused by moving over the
/// curved Earth), rad/s, for velocity `vel_enu` = [v_e, v_n, v_u] (m/s):
/// `ω_en^n = [−v_n/(R_M+h), v_e/(R_N+h), v_e tan L/(R_N+h)]`.
/// The vertical component grows without bound at the poles (tan L), as the
/// ENU frame itself is singular there.
pub fn transport_rate_enu(lat: f64, h: f64, vel_enu: &Vector3<f64>) -> Vector3<f64> {
    let rd = radii(lat);
    let rm = rd.meridian + h;
    let rn = rd.prime_vertical + h;
    Vector3::new(-vel_enu.y / rm, vel_enu.x / rn, vel_enu.x * lat.tan() / rn)
}

/// Normal gravity magnitude (m/s², pointing down along −up) at latitude `lat`
/// (rad) and height `h` (m).
///
/// Somigliana's closed form on the ellipsoid,
/// `γ₀ = γ_e (1 + k sin²L) / √(1 − e² sin²L)` (γ_e = 9.7803253359,
/// γ_p = 9.8321849378), with the WGS84 second-order free-air correction
/// `γ = γ₀ [1 − 2h/a (1 + f + m − 2f sin²L) + 3h²/a²]` (NIMA TR8350.2
/// eq. 4-3), whose height gradient at the surface is ≈ −3.086e-6 s⁻².
pub fn normal_gravity(lat: f64, h: f64) -> f64 {
    let s2 = lat.sin().powi(2);
    let g0 = GAMMA_E * (1.0 + SOMIGLIANA_K * s2) / (1.0 - WGS84_E2 * s2).sqrt();
    let free_air = 1.0 - 2.0 * h / WGS84_A * (1.0 + WGS84_F + GRAVITY_M - 2.0 * WGS84_F * s2)
        + 3.0 * h * h / (WGS84_A * WGS84_A);
    g0 * free_air
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};
    use std::f64::consts::FRAC_PI_2;

    // Reference values below were computed independently with pyproj 3.7.2 /
    // PROJ 9.5.1 (EPSG:4979 ↔ EPSG:4978, and a `cart` + `topocentric`
    // pipeline for ENU, used in `frames`) and with the textbook closed forms
    // in plain Python; the script:
    //
    // from pyproj import Transformer; import math
    // to_ecef = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
    // to_lla = Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)
    // for lat, lon, h in PTS: print(to_ecef.transform(lon, lat, h))
    // for r in ECEF: print(to_lla.transform(*r))     # -> lon, lat, h
    // topo = Transformer.from_pipeline("+proj=pipeline +step +proj=cart +ellps=WGS84"
    //     " +step +proj=topocentric +ellps=WGS84 +lat_0=30.5 +lon_0=114.3 +h_0=20")
    // for lat, lon, h in TARGETS: print(topo.transform(lon, lat, h))
    // a = 6378137.0; f = 1/298.257223563; e2 = f*(2-f); b = a*(1-f)
    // for L in (0, 45, 90): s = sin(radians(L)); w = 1 - e2*s*s
    //     print(a*(1-e2)/w**1.5, a/sqrt(w))                       # R_M, R_N
    // ge, gp = 9.7803253359, 9.8321849378                          # Somigliana
    // for L in (0, 30.5, 45, 90): c, s = cos(radians(L)), sin(radians(L))
    //     print((a*ge*c*c + b*gp*s*s)/sqrt(a*a*c*c + b*b*s*s))
    // L = radians(30.5); h = 20; ve, vn = 5, 10; ...              # transport rate
    // print([-vn/(rm+h), ve/(rn+h), ve*tan(L)/(rn+h)])

    fn deg(lat: f64, lon: f64, h: f64) -> Lla {
        Lla {
            lat: lat.to_radians(),
            lon: lon.to_radians(),
            h,
        }
    }

    #[test]
    fn equator_at_greenwich_is_the_semi_major_axis_on_x() {
        let r = lla_to_ecef(&deg(0.0, 0.0, 0.0));
        assert_abs_diff_eq!(r, Vector3::new(WGS84_A, 0.0, 0.0), epsilon = 1e-9);
        let p = ecef_to_lla(&Vector3::new(WGS84_A, 0.0, 0.0));
        assert_eq!((p.lat, p.lon), (0.0, 0.0));
        assert_abs_diff_eq!(p.h, 0.0, epsilon = 1e-9);
    }

    #[test]
    fn the_poles_map_to_the_semi_minor_axis_and_back_exactly() {
        for sign in [1.0, -1.0] {
            for h in [-1000.0, 0.0, 1234.5, 1.0e6] {
                let r = lla_to_ecef(&Lla {
                    lat: sign * FRAC_PI_2,
                    lon: 0.3,
                    h,
                });
                assert_abs_diff_eq!(r.x, 0.0, epsilon = 1e-9);
                assert_abs_diff_eq!(r.y, 0.0, epsilon = 1e-9);
                assert_abs_diff_eq!(r.z, sign * (WGS84_B + h), epsilon = 1e-8);
                let p = ecef_to_lla(&Vector3::new(0.0, 0.0, sign * (WGS84_B + h)));
                assert_eq!(p.lat, sign * FRAC_PI_2);
                assert_eq!(p.lon, 0.0);
                assert_abs_diff_eq!(p.h, h, epsilon = 1e-9);
            }
        }
    }

    #[test]
    fn points_a_few_millimetres_to_a_kilometre_from_the_pole_round_trip() {
        for offset_m in [1e-3, 1.0, 30.0, 1000.0] {
            for h in [-1000.0, 0.0, 1.0e6] {
                let p = Lla {
                    lat: FRAC_PI_2 - offset_m / 6.4e6,
                    lon: -2.0,
                    h,
                };
                let r = lla_to_ecef(&p);
                let back = ecef_to_lla(&r);
                assert_abs_diff_eq!(back.lat, p.lat, epsilon = 1e-15);
                assert_abs_diff_eq!(back.h, p.h, epsilon = 1e-8);
                assert_abs_diff_eq!(lla_to_ecef(&back), r, epsilon = 1e-8);
            }
        }
    }

    #[test]
    fn lla_to_ecef_matches_pyproj() {
        let cases = [
            (
                (45.0, 45.0, 100.0),
                [3194469.1450605746, 3194469.145060574, 4487419.119544039],
            ),
            (
                (-33.8688, 151.2093, 58.0),
                [-4646093.477288303, 2553229.5358170713, -3534404.710910369],
            ),
            (
                (30.5, 114.3, 20.0),
                [-2263473.2513405853, 5013037.564086796, 3218264.696444362],
            ),
            (
                (89.9999, -120.0, 5000.0),
                [-5.589062301336083, -9.680539872581937, 6361752.314235425],
            ),
            (
                (-60.0, -75.5, 1.0e6),
                [925681.0614637124, -3579343.082061499, -6366502.537723077],
            ),
            (
                (12.34, -170.0, -1000.0),
                [-6136097.104658306, -1081959.4757983524, 1353955.5258162012],
            ),
        ];
        for ((lat, lon, h), want) in cases {
            let r = lla_to_ecef(&deg(lat, lon, h));
            assert_abs_diff_eq!(r, Vector3::from(want), epsilon = 1e-8);
        }
    }

    #[test]
    fn ecef_to_lla_matches_pyproj() {
        // PROJ's inverse is a single Bowring step: off by 0.2 mm at 130 km height
        // (its answer re-projects 2.0e-4 m from the input; ours 1.0e-9 m), so the
        // tolerances here are 0.5 mm, and our own re-projection is checked to 1e-8 m.
        let cases = [
            ([0.0, 0.0, 6356752.314245179], (90.0, 0.0, 0.0)),
            (
                [1.0, 0.0, -6356752.0],
                (-89.99999104696553, 0.0, -0.31424517929553986),
            ),
            (
                [-2.0e6, 3.0e6, 5.4e6],
                (56.443134565166766, 123.69006752597979, 129749.3090869179),
            ),
            (
                [4.0e6, -4.5e6, -1.2e6],
                (-11.3487583638449, -48.366460663429805, -238097.60114224162),
            ),
        ];
        for (r, (lat, lon, h)) in cases {
            let p = ecef_to_lla(&Vector3::from(r));
            assert_abs_diff_eq!(p.lat.to_degrees(), lat, epsilon = 5e-9);
            assert_abs_diff_eq!(p.lon.to_degrees(), lon, epsilon = 5e-9);
            assert_abs_diff_eq!(p.h, h, epsilon = 5e-4);
            assert_abs_diff_eq!(lla_to_ecef(&p), Vector3::from(r), epsilon = 1e-8);
        }
    }

    #[test]
    fn seeded_random_points_round_trip_to_a_few_nanometres() {
        let mut rng = StdRng::seed_from_u64(3);
        for _ in 0..10 {
            let p = Lla {
                lat: rng.random_range(-FRAC_PI_2..=FRAC_PI_2),
                lon: rng.random_range(-std::f64::consts::PI..std::f64::consts::PI),
                h: rng.random_range(-1000.0..1.0e6),
            };
            let r = lla_to_ecef(&p);
            let back = ecef_to_lla(&r);
            // Position error of the round trip, metres.
            assert!((lla_to_ecef(&back) - r).norm() < 1e-8);
            assert_abs_diff_eq!(back.lat, p.lat, epsilon = 1e-14);
            assert_abs_diff_eq!(back.lon, p.lon, epsilon = 1e-14);
            assert_abs_diff_eq!(back.h, p.h, epsilon = 1e-8);
        }
    }

    #[test]
    fn radii_match_the_closed_forms_at_0_45_and_90_degrees() {
        let cases = [
            (0.0, 6335439.3272928195, 6378137.0),
            (45.0, 6367381.815619548, 6388838.290121148),
            (90.0, 6399593.625758492, 6399593.625758493),
        ];
        for (lat, rm, rn) in cases {
            let r = radii(f64::to_radians(lat));
            assert_abs_diff_eq!(r.meridian, rm, epsilon = 1e-6);
            assert_abs_diff_eq!(r.prime_vertical, rn, epsilon = 1e-6);
        }
        // At the pole both radii equal a²/b.
        let pole = radii(FRAC_PI_2);
        assert_abs_diff_eq!(pole.meridian, WGS84_A * WGS84_A / WGS84_B, epsilon = 1e-6);
    }

    #[test]
    fn earth_rate_has_magnitude_omega_and_lies_in_the_meridian_plane() {
        let lat = 30.5_f64.to_radians();
        let w = earth_rate_enu(lat);
        assert_eq!(w.x, 0.0);
        assert_abs_diff_eq!(w.norm(), OMEGA_IE, epsilon = 1e-18);
        assert_abs_diff_eq!(w.z / w.y, lat.tan(), epsilon = 1e-12);
    }

    #[test]
    fn transport_rate_for_a_known_velocity_matches_the_closed_form() {
        let w = transport_rate_enu(30.5_f64.to_radians(), 20.0, &Vector3::new(5.0, 10.0, 0.5));
        let want = Vector3::new(
            -1.5743364639293492e-06,
            7.832493074626579e-07,
            4.613691011757265e-07,
        );
        assert_abs_diff_eq!(w, want, epsilon = 1e-18);
        // Standing still turns nothing.
        assert_eq!(
            transport_rate_enu(0.7, 0.0, &Vector3::zeros()),
            Vector3::zeros()
        );
    }

    #[test]
    fn normal_gravity_matches_somigliana_at_the_equator_poles_and_between() {
        let cases = [
            (0.0, 9.7803253359),
            (30.5, 9.793640293884337),
            (45.0, 9.80619776934378),
            (90.0, 9.8321849378),
            (-90.0, 9.8321849378),
        ];
        for (lat, g) in cases {
            assert_abs_diff_eq!(
                normal_gravity(f64::to_radians(lat), 0.0),
                g,
                epsilon = 1e-10
            );
        }
    }

    #[test]
    fn normal_gravity_falls_by_about_3_086e_6_per_metre_of_height() {
        for lat in [0.0, 30.0, 45.0, 60.0, 90.0] {
            let lat = f64::to_radians(lat);
            let gradient = (normal_gravity(lat, 50.0) - normal_gravity(lat, -50.0)) / 100.0;
            // Ranges from −3.0877e-6 (equator) to −3.0834e-6 (pole).
            assert_abs_diff_eq!(gradient, -3.086e-6, epsilon = 3e-9);
        }
        // 10 km up, gravity is ~0.031 m/s² smaller.
        let drop = normal_gravity(0.0, 0.0) - normal_gravity(0.0, 10_000.0);
        assert_abs_diff_eq!(drop, 0.03086, epsilon = 2e-4);
    }
}
