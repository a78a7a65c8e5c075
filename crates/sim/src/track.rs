//! Real tracks as truth: parses 1 Hz RTK fixes in the format of
//! the KF-GINS sample data (`kf-gins-gnss-rtk.txt`) and turns them into [`Truth`] at the INS
//! rate, so simulated INS and aid errors ride on real vehicle dynamics
//! (docs/methods.md §M19, `navguard simulate --track FILE`). Pure: the CLI reads the file
//! and hands the text to [`Track::parse`].
//!
//! Format: one fix per line, whitespace separated: GNSS time (s of week),
//! latitude (°), longitude (°), ellipsoidal height (m), and optionally the three
//! standard deviations (m) — 4 or 7 columns. Blank lines and lines starting with
//! `#` or `%` are skipped. Times must increase strictly.
//!
//! From fixes to truth ([`Track::truth`]):
//! - latitude, longitude and height are interpolated with a C¹ cubic Hermite
//!   spline whose knot slopes are central differences of the fixes (Catmull–Rom
//!   on a non-uniform grid; one-sided at the ends). The spline passes through every
//!   fix; the central-difference slopes are the "smoothing": velocity is the
//!   average over two fix intervals at the knots, which halves the RTK noise
//!   (σ ≈ 1 cm → ≈ 1 cm/s velocity noise, ≈ 2 cm/s² acceleration noise);
//! - velocity is the spline's derivative mapped to ENU
//!   (`v_e = λ̇ (R_N + h) cos L`, `v_n = L̇ (R_M + h)`, `v_u = ḣ`); acceleration its
//!   second derivative with the product-rule terms of `h` and `cos L` (the slow
//!   variation of the radii with latitude is ignored, < 1e-8 relative);
//! - yaw is the velocity direction `atan2(v_e, v_n)`, pitch the climb angle
//!   `atan2(v_u, |v_h|)`, roll 0 (a land vehicle's roll is not observable from
//!   positions). Below [`MOVING_SPEED_MPS`] the direction of the velocity is noise,
//!   so yaw holds its last moving value (before the first motion: the first moving
//!   value) and pitch is 0;
//! - specific force as in `trajectory` (`fⁿ = v̇ + (2ω_ie + ω_en) × v − g`);
//!   angular rate from the change of attitude between samples (forward difference
//!   of the DCM, `log(C_kᵀ C_{k+1}) / Δt`) plus Earth and transport rate.
//!
//! Truth time is measured from the first fix (t = 0).

use nalgebra::{Rotation3, Vector3};

use super::truth::{Truth, body_rate, specific_force_nav, wrap_2pi};
use super::{SimError, check_positive};
use navguard_core::geo::{self, Lla};

/// Horizontal speed below which the track's heading is held, m/s.
pub const MOVING_SPEED_MPS: f64 = 0.5;

/// Why a track could not be read; every line error names its (1-based) line.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrackError {
    /// A line is malformed.
    #[error("track line {line}: {reason}")]
    Line {
        /// 1-based line number.
        line: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// Too few fixes to interpolate.
    #[error("track has {0} fixes; at least 2 are needed")]
    TooShort(usize),
}

/// One RTK fix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackFix {
    /// GNSS time, s (of week, as in the file).
    pub t: f64,
    /// Position (rad, rad, m).
    pub lla: Lla,
    /// Standard deviations of latitude, longitude, height, m (NaN when absent).
    pub sigma_m: [f64; 3],
}

/// A parsed track: at least two fixes with strictly increasing times.
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    fixes: Vec<TrackFix>,
}

fn parse_line(line_no: usize, line: &str) -> Result<Option<TrackFix>, TrackError> {
    let trimmed = line.trim();
    if trimmed.is_empty() || trimmed.starts_with('#') || trimmed.starts_with('%') {
        return Ok(None);
    }
    let err = |reason: String| TrackError::Line {
        line: line_no,
        reason,
    };
    let cols: Vec<&str> = trimmed.split_whitespace().collect();
    if cols.len() != 4 && cols.len() != 7 {
        return Err(err(format!(
            "expected 4 or 7 columns, found {}",
            cols.len()
        )));
    }
    const NAMES: [&str; 7] = [
        "time",
        "latitude",
        "longitude",
        "height",
        "sigma_lat",
        "sigma_lon",
        "sigma_h",
    ];
    let mut v = [f64::NAN; 7];
    for (i, c) in cols.iter().enumerate() {
        let x: f64 = c
            .parse()
            .map_err(|_| err(format!("{} `{c}` is not a number", NAMES[i])))?;
        if !x.is_finite() {
            return Err(err(format!("{} `{c}` is not finite", NAMES[i])));
        }
        v[i] = x;
    }
    if v[1].abs() >= 90.0 {
        return Err(err(format!("latitude {} is not in (−90°, 90°)", v[1])));
    }
    if !(-180.0..=360.0).contains(&v[2]) {
        return Err(err(format!("longitude {} is not in [−180°, 360°]", v[2])));
    }
    Ok(Some(TrackFix {
        t: v[0],
        lla: Lla {
            lat: v[1].to_radians(),
            lon: v[2].to_radians(),
            h: v[3],
        },
        sigma_m: [v[4], v[5], v[6]],
    }))
}

/// Cubic Hermite value, first and second derivative on `[t0, t0 + h]` at fraction `s`.
fn hermite(y0: f64, y1: f64, m0: f64, m1: f64, h: f64, s: f64) -> [f64; 3] {
    let (s2, s3) = (s * s, s * s * s);
    let y = (2.0 * s3 - 3.0 * s2 + 1.0) * y0
        + (s3 - 2.0 * s2 + s) * h * m0
        + (-2.0 * s3 + 3.0 * s2) * y1
        + (s3 - s2) * h * m1;
    let d1 = (6.0 * s2 - 6.0 * s) * (y0 - y1) / h
        + (3.0 * s2 - 4.0 * s + 1.0) * m0
        + (3.0 * s2 - 2.0 * s) * m1;
    let d2 =
        (12.0 * s - 6.0) * (y0 - y1) / (h * h) + ((6.0 * s - 4.0) * m0 + (6.0 * s - 2.0) * m1) / h;
    [y, d1, d2]
}

/// Knot slopes: central differences inside, one-sided at the ends.
fn slopes(t: &[f64], y: &[f64]) -> Vec<f64> {
    let n = y.len();
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            (y[b] - y[a]) / (t[b] - t[a])
        })
        .collect()
}

impl Track {
    /// Parses the text of a track file (module doc for the format).
    ///
    /// # Errors
    /// [`TrackError::Line`] with the line number for a malformed line or a time
    /// that does not increase; [`TrackError::TooShort`] for fewer than 2 fixes.
    pub fn parse(text: &str) -> Result<Self, TrackError> {
        let mut fixes: Vec<TrackFix> = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let Some(fix) = parse_line(i + 1, line)? else {
                continue;
            };
            if let Some(prev) = fixes.last() {
                if fix.t <= prev.t {
                    return Err(TrackError::Line {
                        line: i + 1,
                        reason: format!(
                            "time {} s does not increase (previous fix {} s)",
                            fix.t, prev.t
                        ),
                    });
                }
            }
            fixes.push(fix);
        }
        if fixes.len() < 2 {
            return Err(TrackError::TooShort(fixes.len()));
        }
        Ok(Track { fixes })
    }

    /// The fixes in time order.
    pub fn fixes(&self) -> &[TrackFix] {
        &self.fixes
    }

    /// Time from the first to the last fix, s.
    pub fn duration_s(&self) -> f64 {
        self.fixes[self.fixes.len() - 1].t - self.fixes[0].t
    }

    /// The truth at `rate_hz` from the first fix to the last (module doc).
    pub fn truth(&self, rate_hz: f64) -> Result<Vec<Truth>, SimError> {
        check_positive("rate_hz", rate_hz)?;
        let samples = self.interpolate(rate_hz);
        let atts = attitudes(&samples);
        let dt = 1.0 / rate_hz;
        let dcms: Vec<_> = atts
            .iter()
            .map(|a| geo::dcm_body_to_nav(a[0], a[1], a[2]))
            .collect();
        let out = samples
            .iter()
            .enumerate()
            .map(|(k, (t, lla, vel, vel_dot))| {
                let c_bn = dcms[k];
                let omega_nb = match dcms.get(k + 1) {
                    Some(next) => {
                        Rotation3::from_matrix_unchecked(c_bn.transpose() * next).scaled_axis() / dt
                    }
                    None if k > 0 => {
                        Rotation3::from_matrix_unchecked(dcms[k - 1].transpose() * c_bn)
                            .scaled_axis()
                            / dt
                    }
                    None => Vector3::zeros(),
                };
                let f_n = specific_force_nav(lla, vel, vel_dot);
                Truth {
                    t: *t,
                    lla: *lla,
                    vel: *vel,
                    att: atts[k],
                    f_b: c_bn.transpose() * f_n,
                    omega_ib_b: body_rate(lla, vel, &c_bn, &omega_nb),
                }
            })
            .collect();
        Ok(out)
    }

    /// Position, NED velocity and its rate at `rate_hz`, from the Hermite
    /// splines through the fixes (longitude unwrapped across ±π).
    fn interpolate(&self, rate_hz: f64) -> Vec<Sample> {
        let t0 = self.fixes[0].t;
        let ts: Vec<f64> = self.fixes.iter().map(|f| f.t - t0).collect();
        let lat: Vec<f64> = self.fixes.iter().map(|f| f.lla.lat).collect();
        let h: Vec<f64> = self.fixes.iter().map(|f| f.lla.h).collect();
        // Unwrap longitude so that consecutive fixes never differ by more than π.
        let mut lon: Vec<f64> = Vec::with_capacity(ts.len());
        for f in &self.fixes {
            let l = match lon.last() {
                Some(&p) => {
                    p + (f.lla.lon - p + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                        - std::f64::consts::PI
                }
                None => f.lla.lon,
            };
            lon.push(l);
        }
        let channels = [&lat, &lon, &h];
        let m: Vec<Vec<f64>> = channels.iter().map(|y| slopes(&ts, y)).collect();
        let dt = 1.0 / rate_hz;
        let n = (self.duration_s() * rate_hz + 1e-9).floor() as usize + 1;
        let mut samples = Vec::with_capacity(n);
        let mut seg = 0;
        for k in 0..n {
            let t = k as f64 * dt;
            while seg + 2 < ts.len() && t >= ts[seg + 1] {
                seg += 1;
            }
            let span = ts[seg + 1] - ts[seg];
            let s = ((t - ts[seg]) / span).clamp(0.0, 1.0);
            let [la, lo, hh] = [0, 1, 2].map(|c| {
                hermite(
                    channels[c][seg],
                    channels[c][seg + 1],
                    m[c][seg],
                    m[c][seg + 1],
                    span,
                    s,
                )
            });
            let lla = Lla {
                lat: la[0],
                lon: wrap_pi(lo[0]),
                h: hh[0],
            };
            let r = geo::radii(lla.lat);
            let (rn, rm) = (r.prime_vertical + lla.h, r.meridian + lla.h);
            let (sl, cl) = lla.lat.sin_cos();
            let vel = Vector3::new(lo[1] * rn * cl, la[1] * rm, hh[1]);
            let vel_dot = Vector3::new(
                lo[2] * rn * cl + lo[1] * hh[1] * cl - lo[1] * rn * sl * la[1],
                la[2] * rm + la[1] * hh[1],
                hh[2],
            );
            samples.push((t, lla, vel, vel_dot));
        }
        samples
    }
}

/// One interpolated instant: time, position, velocity and its rate.
type Sample = (f64, Lla, Vector3<f64>, Vector3<f64>);

/// Roll 0, pitch from the climb and yaw from the velocity direction, the yaw
/// held while (nearly) stopped.
fn attitudes(samples: &[Sample]) -> Vec<[f64; 3]> {
    let moving = |v: &Vector3<f64>| v.xy().norm() >= MOVING_SPEED_MPS;
    let mut yaw = samples
        .iter()
        .find(|s| moving(&s.2))
        .map_or(0.0, |s| wrap_2pi(s.2.x.atan2(s.2.y)));
    samples
        .iter()
        .map(|(_, _, v, _)| {
            if moving(v) {
                yaw = wrap_2pi(v.x.atan2(v.y));
                [0.0, v.z.atan2(v.xy().norm()), yaw]
            } else {
                [0.0, 0.0, yaw]
            }
        })
        .collect()
}

/// An angle wrapped to [−π, π).
fn wrap_pi(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// The first lines of `kf-gins-gnss-rtk.txt` (stationary), then a synthetic
    /// northward run at 10 m/s (1 Hz, 10 m per fix ≈ 9.0e-5° of latitude at 30.44°N).
    const HEAD: &str = "456250.000    30.4447858054   114.4718661162     21.095    0.010    0.009    0.019 \n\
456251.000    30.4447857891   114.4718661133     21.091    0.010    0.009    0.019 \n\
456252.000    30.4447858189   114.4718661201     21.087    0.010    0.009    0.019 \n\
456253.000    30.4447858069   114.4718661154     21.092    0.010    0.009    0.019 \n";

    #[test]
    fn parses_the_real_file_head() {
        let track = Track::parse(HEAD).unwrap();
        assert_eq!(track.fixes().len(), 4);
        let f = track.fixes()[1];
        assert_eq!(f.t, 456251.0);
        assert_relative_eq!(f.lla.lat.to_degrees(), 30.4447857891, epsilon = 1e-12);
        assert_relative_eq!(f.lla.lon.to_degrees(), 114.4718661133, epsilon = 1e-12);
        assert_eq!(f.lla.h, 21.091);
        assert_eq!(f.sigma_m, [0.010, 0.009, 0.019]);
        assert_eq!(track.duration_s(), 3.0);
        // Stationary RTK noise (≈ 1 cm) → sub-2 cm/s truth velocity, gravity-dominated f_b.
        let truth = track.truth(10.0).unwrap();
        assert_eq!(truth.len(), 31);
        for s in &truth {
            assert!(s.vel.norm() < 0.02, "velocity {}", s.vel.norm());
            assert_relative_eq!(
                s.f_b.z,
                geo::normal_gravity(s.lla.lat, s.lla.h),
                epsilon = 0.1
            );
        }
        // The spline passes through the fixes.
        assert_relative_eq!(truth[20].lla.lat, track.fixes()[2].lla.lat, epsilon = 1e-15);
        assert_eq!(truth[20].lla.h, 21.087);
    }

    #[test]
    fn rejects_malformed_lines_naming_the_line() {
        let bad_number = format!("{HEAD}456254.000 30.44 x114.47 21.0 0.01 0.01 0.02\n");
        let e = Track::parse(&bad_number).unwrap_err();
        assert!(
            matches!(e, TrackError::Line { line: 5, ref reason } if reason.contains("longitude")),
            "{e}"
        );
        assert!(e.to_string().contains("line 5"));
        let short = "# header\n\n456250 30.1 114.2\n";
        assert!(matches!(
            Track::parse(short),
            Err(TrackError::Line { line: 3, .. })
        ));
        let back = format!("{HEAD}456252.5 30.44 114.47 21.0\n");
        assert!(matches!(
            Track::parse(&back),
            Err(TrackError::Line { line: 5, .. })
        ));
        assert!(matches!(
            Track::parse("456250 91 114 0\n"),
            Err(TrackError::Line { line: 1, .. })
        ));
        assert_eq!(
            Track::parse("# only a comment\n456250 30 114 0\n"),
            Err(TrackError::TooShort(1))
        );
    }

    #[test]
    fn a_straight_run_gives_speed_heading_and_level_attitude() {
        // Fixes every second, 10 m apart along the meridian.
        let lat0 = 30.0f64.to_radians();
        let dlat = 10.0 / (geo::radii(lat0).meridian + 20.0);
        let text: String = (0..20)
            .map(|i| {
                format!(
                    "{} {:.12} 114.0 20.0\n",
                    1000 + i,
                    (lat0 + dlat * f64::from(i)).to_degrees()
                )
            })
            .collect();
        let truth = Track::parse(&text).unwrap().truth(10.0).unwrap();
        let mid = &truth[95];
        assert_relative_eq!(mid.vel.y, 10.0, max_relative = 1e-6);
        assert_relative_eq!(mid.vel.x, 0.0, epsilon = 1e-9);
        assert_relative_eq!(mid.att[2], 0.0, epsilon = 1e-9);
        assert_eq!(mid.att[0], 0.0);
        // Constant velocity: f_b is gravity plus Coriolis (2Ω sinL v_n ≈ 7e-4 m/s²).
        assert!(mid.f_b.xy().norm() < 1e-3);
        assert!(mid.omega_ib_b.norm() < 1e-4);
    }
}
