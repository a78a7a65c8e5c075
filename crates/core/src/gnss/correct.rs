//! Pseudorange corrections, the first step of the `gnss` layer: Earth rotation during the
//! signal's transit (Sagnac), elevation and azimuth, the Saastamoinen troposphere with a
//! standard atmosphere, and the corrected pseudorange `pr + clk − iono − tropo` that
//! [`super::wls`] fits.

use nalgebra::Vector3;

use crate::epoch::SatObs;
use crate::geo::{Lla, ecef_to_enu_rotation};

/// Speed of light in vacuum, m/s (IS-GPS-200).
pub const SPEED_OF_LIGHT: f64 = 299_792_458.0;

/// Earth rotation rate, rad/s, as the GPS interface specification (IS-GPS-200) and the
/// GSDC data use it (`geo::OMEGA_IE` is the rounded WGS84 value the INS uses).
pub const OMEGA_E: f64 = 7.292_115_146_7e-5;

/// Relative humidity of RTKLIB's standard atmosphere (`REL_HUMI` in pntpos.c).
pub const RTKLIB_REL_HUMIDITY: f64 = 0.7;

/// Lowest receiver height (m, ellipsoidal) at which the model troposphere applies.
///
/// RTKLIB's `tropmodel` returns 0 below −100 m; ellipsoidal heights of sea-level sites
/// reach −106 m (the geoid low south of India) and land sites lie lower still (Dead Sea
/// shore, −430 m), so we keep the model down to −1 km. Below that the position is not a
/// receiver on the ground (typically a Gauss–Newton iterate started at the Earth's
/// centre) and the troposphere is set to 0 so that the iterate stays finite.
pub const TROPO_MIN_HEIGHT_M: f64 = -1_000.0;

/// Highest receiver height (m) at which the model troposphere applies (as RTKLIB): above
/// it the standard atmosphere's tropospheric lapse rate no longer holds; a user above
/// 10 km supplies `SatObs::tropo`.
pub const TROPO_MAX_HEIGHT_M: f64 = 10_000.0;

/// Elevation and azimuth of a satellite seen from a receiver, rad.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AzEl {
    /// Azimuth, clockwise from north, in [0, 2π).
    pub az: f64,
    /// Elevation above the local horizon (ellipsoid normal), in [−π/2, π/2].
    pub el: f64,
}

/// `r` rotated about the z axis by `angle` (rad) as a change of frame: the coordinates,
/// in a frame turned by `angle`, of a point fixed in the old frame.
pub fn rotate_frame_z(r: &Vector3<f64>, angle: f64) -> Vector3<f64> {
    let (s, c) = angle.sin_cos();
    Vector3::new(c * r.x + s * r.y, -s * r.x + c * r.y, r.z)
}

/// The satellite position `sat_tx` (ECEF of the transmit time) expressed in the ECEF frame
/// of the receive time, seen from `rx` (Sagnac correction): the Earth turns by `ω_E·τ`
/// during the transit `τ = range/c`. τ starts from the geometric range and is refined
/// twice with the rotated one (the second pass changes the range by well under a
/// micrometre).
pub fn sagnac_rotate(sat_tx: &Vector3<f64>, rx: &Vector3<f64>) -> Vector3<f64> {
    let mut rotated = *sat_tx;
    for _ in 0..2 {
        let tau = (rotated - rx).norm() / SPEED_OF_LIGHT;
        rotated = rotate_frame_z(sat_tx, OMEGA_E * tau);
    }
    rotated
}

/// The first-order Sagnac range correction `ω_E/c·(x_s y_r − y_s x_r)` (m): what
/// [`sagnac_rotate`] adds to the geometric range, to about a millimetre (RTKLIB's
/// `geodist`, IS-GPS-200 §20.3.3.4.3.4).
pub fn sagnac_range_correction(sat_tx: &Vector3<f64>, rx: &Vector3<f64>) -> f64 {
    OMEGA_E / SPEED_OF_LIGHT * (sat_tx.x * rx.y - sat_tx.y * rx.x)
}

/// Azimuth and elevation of the satellite at `sat` (ECEF, receive-time frame) from the
/// receiver at `rx` (ECEF) whose geodetic position is `rx_lla`.
pub fn az_el(rx: &Vector3<f64>, rx_lla: &Lla, sat: &Vector3<f64>) -> AzEl {
    let los = sat - rx;
    let norm = los.norm();
    if norm == 0.0 {
        return AzEl { az: 0.0, el: 0.0 };
    }
    let enu = ecef_to_enu_rotation(rx_lla.lat, rx_lla.lon) * (los / norm);
    let az = enu.x.atan2(enu.y).rem_euclid(std::f64::consts::TAU);
    let el = enu.z.clamp(-1.0, 1.0).asin();
    AzEl { az, el }
}

/// Slant tropospheric delay (m) by the Saastamoinen model with a standard atmosphere, as
/// RTKLIB's `tropmodel` (rtkcmn.c, RTKLIB 2.4.2; manual appendix E.5):
///
/// - height `h` clamped to ≥ 0; pressure `P = 1013.25·(1 − 2.2557e-5·h)^5.2568` hPa,
///   temperature `T = 15 − 6.5e-3·h + 273.16` K, water-vapour pressure
///   `e = 6.108·RH·exp((17.15·T − 4684)/(T − 38.45))` hPa;
/// - hydrostatic `0.0022768·P / (1 − 0.00266·cos 2φ − 0.00028·h/1e3) / sin(el)`, wet
///   `0.002277·(1255/T + 0.05)·e / sin(el)` (Saastamoinen 1972, the `1/cos z` mapping).
///
/// 0 for `el ≤ 0` and outside [[`TROPO_MIN_HEIGHT_M`], [`TROPO_MAX_HEIGHT_M`]].
pub fn saastamoinen(lat: f64, h: f64, el: f64, rel_humidity: f64) -> f64 {
    if !(TROPO_MIN_HEIGHT_M..=TROPO_MAX_HEIGHT_M).contains(&h) || el <= 0.0 {
        return 0.0;
    }
    let hgt = h.max(0.0);
    let pressure_hpa = 1013.25 * (1.0 - 2.2557e-5 * hgt).powf(5.2568);
    let temp_k = 15.0 - 6.5e-3 * hgt + 273.16;
    let e_hpa = 6.108 * rel_humidity * ((17.15 * temp_k - 4684.0) / (temp_k - 38.45)).exp();
    let sin_el = el.sin();
    let hydrostatic =
        0.002_276_8 * pressure_hpa / (1.0 - 0.002_66 * (2.0 * lat).cos() - 0.000_28 * hgt / 1e3);
    let wet = 0.002_277 * (1255.0 / temp_k + 0.05) * e_hpa;
    (hydrostatic + wet) / sin_el
}

/// The corrected pseudorange `pr + clk − iono − tropo` (m), with `model_tropo` where the
/// observation carries no tropospheric delay and no ionospheric delay where it carries
/// none (an iono-free code).
pub fn corrected_pseudorange(obs: &SatObs, model_tropo: f64) -> f64 {
    obs.pr + obs.clk - obs.iono.unwrap_or(0.0) - obs.tropo.unwrap_or(model_tropo)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geo::{ecef_to_lla, lla_to_ecef};

    fn deg(x: f64) -> f64 {
        x.to_radians()
    }

    #[test]
    fn saastamoinen_zenith_delay_is_about_2_3_m_at_sea_level_and_grows_as_one_over_sin_el() {
        let zenith = saastamoinen(deg(45.0), 0.0, deg(90.0), RTKLIB_REL_HUMIDITY);
        assert!((2.3..2.5).contains(&zenith), "zenith delay {zenith}");
        for el_deg in [5.0_f64, 10.0, 30.0, 60.0] {
            let slant = saastamoinen(deg(45.0), 0.0, deg(el_deg), RTKLIB_REL_HUMIDITY);
            let expected = zenith / deg(el_deg).sin();
            assert!(
                (slant - expected).abs() < 1e-12,
                "{el_deg}°: {slant} vs {expected}"
            );
        }
        // Drier and thinner air higher up; none below the horizon or out of range.
        assert!(saastamoinen(deg(45.0), 2000.0, deg(90.0), 0.7) < zenith * 0.85);
        assert_eq!(saastamoinen(deg(45.0), 0.0, deg(-1.0), 0.7), 0.0);
        assert_eq!(saastamoinen(deg(45.0), -6.0e6, deg(30.0), 0.7), 0.0);
        assert_eq!(saastamoinen(deg(45.0), 12_000.0, deg(30.0), 0.7), 0.0);
    }

    #[test]
    fn saastamoinen_matches_an_independent_python_evaluation() {
        // Python 3 (math module), the same formula written separately:
        //   h=150; lat=radians(37.4); el=radians(20); P=1013.25*(1-2.2557e-5*h)**5.2568
        //   T=15-6.5e-3*h+273.16; e=6.108*0.7*exp((17.15*T-4684)/(T-38.45))
        //   (0.0022768*P/(1-0.00266*cos(2*lat)-0.00028*h/1e3) + 0.002277*(1255/T+0.05)*e)/sin(el)
        // printed 6.962737882998056 (and 2.42745528255487 at h=0, lat=45°, el=90°).
        let v = saastamoinen(deg(37.4), 150.0, deg(20.0), 0.7);
        assert!((v - 6.962_737_882_998_056).abs() < 1e-9, "{v}");
        let z = saastamoinen(deg(45.0), 0.0, deg(90.0), 0.7);
        assert!((z - 2.427_455_282_554_87).abs() < 1e-9, "{z}");
    }

    #[test]
    fn sagnac_rotation_matches_the_closed_form_correction_and_reaches_tens_of_metres() {
        let rx = lla_to_ecef(&Lla {
            lat: deg(37.0),
            lon: deg(-122.0),
            h: 0.0,
        });
        let rx_lla = ecef_to_lla(&rx);
        let mut largest = 0.0_f64;
        // Satellites at 20 200 km altitude all round the sky.
        for az_deg in (0..360).step_by(15) {
            for el_deg in [5.0, 30.0, 60.0, 89.0] {
                let sat = satellite_at(&rx, &rx_lla, deg(az_deg as f64), deg(el_deg));
                let rotated = sagnac_rotate(&sat, &rx);
                let delta = (rotated - rx).norm() - (sat - rx).norm();
                let closed = sagnac_range_correction(&sat, &rx);
                assert!((delta - closed).abs() < 2e-3, "{delta} vs {closed}");
                largest = largest.max(delta.abs());
            }
        }
        assert!(
            (20.0..40.0).contains(&largest),
            "largest Sagnac correction {largest} m"
        );
    }

    #[test]
    fn az_el_recovers_the_direction_a_satellite_was_placed_in() {
        let rx_lla = Lla {
            lat: deg(-33.0),
            lon: deg(151.0),
            h: 40.0,
        };
        let rx = lla_to_ecef(&rx_lla);
        for (az_deg, el_deg) in [(10.0, 5.0), (135.0, 45.0), (300.0, 80.0)] {
            let sat = satellite_at(&rx, &rx_lla, deg(az_deg), deg(el_deg));
            let a = az_el(&rx, &rx_lla, &sat);
            assert!((a.az - deg(az_deg)).abs() < 1e-9 && (a.el - deg(el_deg)).abs() < 1e-9);
        }
    }

    #[test]
    fn corrected_pseudorange_uses_the_model_only_when_tropo_is_absent() {
        let mut obs = SatObs {
            id: crate::epoch::SatId::parse("G05").unwrap(),
            pr: 2.0e7,
            pos: [0.0; 3],
            clk: 10.0,
            iono: Some(3.0),
            tropo: Some(2.0),
            sigma: None,
            cn0: None,
            el: None,
            az: None,
        };
        assert_eq!(corrected_pseudorange(&obs, 7.0), 2.0e7 + 10.0 - 3.0 - 2.0);
        obs.tropo = None;
        obs.iono = None;
        assert_eq!(corrected_pseudorange(&obs, 7.0), 2.0e7 + 10.0 - 7.0);
    }

    /// A satellite 20 200 km above the ellipsoid-ish, in direction (az, el) from `rx`.
    pub(crate) fn satellite_at(rx: &Vector3<f64>, rx_lla: &Lla, az: f64, el: f64) -> Vector3<f64> {
        let enu = Vector3::new(az.sin() * el.cos(), az.cos() * el.cos(), el.sin());
        let dir = ecef_to_enu_rotation(rx_lla.lat, rx_lla.lon).transpose() * enu;
        // Range to a sphere of radius 26 560 km from a point at |rx|.
        let b = rx.dot(&dir);
        let c = rx.norm_squared() - 26_560_000.0_f64.powi(2);
        let range = -b + (b * b - c).sqrt();
        rx + dir * range
    }
}
