//! The Klobuchar ionospheric model: the single-frequency correction a reader adds
//! to each satellite when the file gives no ionospheric delay (RINEX C1 alone,
//! GnssLogger), from the navigation header's `ION ALPHA` / `ION BETA`.
//!
//! IS-GPS-200 §20.3.3.5.2.5 and Figure 20-4, all angles in semicircles:
//! `ψ = 0.0137/(E + 0.11) − 0.022`; the pierce point
//! `φ_i = φ_u + ψ cos A` (clamped to ±0.416), `λ_i = λ_u + ψ sin A / cos φ_i`;
//! the geomagnetic latitude `φ_m = φ_i + 0.064 cos(λ_i − 1.617)`; local time
//! `t = 4.32e4·λ_i + t_GPS` (mod 86 400 s); the obliquity `F = 1 + 16(0.53 − E)³`;
//! `AMP = Σ α_n φ_mⁿ` (≥ 0), `PER = Σ β_n φ_mⁿ` (≥ 72 000 s), `x = 2π(t − 50 400)/PER`;
//! `T = F·(5e-9 + AMP(1 − x²/2 + x⁴/24))` for |x| < 1.57, else `F·5e-9` (seconds of
//! L1 delay). Multiply by c for metres. The delay on L2 would be (f1/f2)² larger;
//! only L1 is needed here.

use std::f64::consts::PI;

use crate::ephemeris::C_LIGHT;

/// The broadcast Klobuchar coefficients.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Klobuchar {
    /// α₀..α₃: s, s/semicircle, s/semicircle², s/semicircle³.
    pub alpha: [f64; 4],
    /// β₀..β₃: s, s/semicircle, s/semicircle², s/semicircle³.
    pub beta: [f64; 4],
}

impl Klobuchar {
    /// L1 ionospheric delay, m, for a user at geodetic `lat`, `lon` (rad) seeing a
    /// satellite at elevation `el` and azimuth `az` (rad) at GPS time `t_gps` (s; only
    /// its time of day matters).
    pub fn delay_m(&self, lat: f64, lon: f64, el: f64, az: f64, t_gps: f64) -> f64 {
        let phi_u = lat / PI;
        let lam_u = lon / PI;
        let e = el / PI;
        let psi = 0.0137 / (e + 0.11) - 0.022;
        let phi_i = (phi_u + psi * az.cos()).clamp(-0.416, 0.416);
        let lam_i = lam_u + psi * az.sin() / (phi_i * PI).cos();
        let phi_m = phi_i + 0.064 * ((lam_i - 1.617) * PI).cos();
        let t = (4.32e4 * lam_i + t_gps).rem_euclid(86_400.0);
        let f = 1.0 + 16.0 * (0.53 - e).powi(3);
        let poly = |c: &[f64; 4]| c[0] + phi_m * (c[1] + phi_m * (c[2] + phi_m * c[3]));
        let amp = poly(&self.alpha).max(0.0);
        let per = poly(&self.beta).max(72_000.0);
        let x = 2.0 * PI * (t - 50_400.0) / per;
        let t_iono = if x.abs() < 1.57 {
            f * (5e-9 + amp * (1.0 - x * x / 2.0 + x.powi(4) / 24.0))
        } else {
            f * 5e-9
        };
        C_LIGHT * t_iono
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// The 2005 GEONET nav header's coefficients (tests/data/gnss/rtklib/07590920.05n).
    const K2005: Klobuchar = Klobuchar {
        alpha: [1.1180e-08, 1.4900e-08, -5.9600e-08, -5.9600e-08],
        beta: [8.8060e+04, 1.6380e+04, -1.9660e+05, -1.3110e+05],
    };

    /// From crates/formats/reference/isgps200_reference.py.
    const KLOB_REF_M: f64 = 8.623_351_352;

    #[test]
    fn delay_matches_an_independent_implementation() {
        // Reference: crates/formats/reference/isgps200_reference.py, a separate
        // pure-Python transcription of IS-GPS-200 Figure 20-4 (math module only),
        // for a user at 35° N 140° E, a satellite at 30° elevation, 120° azimuth,
        // 2005-04-02 03:00 GPST (Saturday, 518 400 s + 3 h of week).
        let (lat, lon) = (35.0_f64.to_radians(), 140.0_f64.to_radians());
        let el = 30.0_f64.to_radians();
        let az = 120.0_f64.to_radians();
        let t = 518_400.0 + 3.0 * 3600.0;
        assert_relative_eq!(
            K2005.delay_m(lat, lon, el, az, t),
            KLOB_REF_M,
            epsilon = 1e-6
        );
    }

    #[test]
    fn night_delay_is_the_5ns_floor_times_obliquity() {
        // At local midnight the cosine term is off: T = F·5 ns; at zenith F = 1 + 16·0.03³.
        let lon = 0.0;
        let t = 0.0; // 00:00 GPST at λ = 0 is local midnight
        let d = K2005.delay_m(0.0, lon, PI / 2.0, 0.0, t);
        let psi_zenith_obliquity = 1.0 + 16.0 * (0.53_f64 - 0.5).powi(3);
        assert_relative_eq!(d, C_LIGHT * 5e-9 * psi_zenith_obliquity, epsilon = 1e-9);
    }

    #[test]
    fn low_satellites_see_more_ionosphere() {
        let (lat, lon, t) = (0.6, 2.4, 518_400.0 + 5.0 * 3600.0);
        let low = K2005.delay_m(lat, lon, 0.2, 1.0, t);
        let high = K2005.delay_m(lat, lon, 1.2, 1.0, t);
        assert!(low > 2.0 * high, "low {low} high {high}");
    }
}
