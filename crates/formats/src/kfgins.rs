//! The text formats of KF-GINS (i2Nav-WHU's open-source GNSS/INS filter), whitespace
//! separated, one record a line; blank lines and lines starting with `#` or `%` are
//! skipped, every other line must hold exactly the columns below or the reader stops
//! naming it.
//!
//! - GNSS: seconds of week, latitude °, longitude °, ellipsoidal height m, σ latitude,
//!   σ longitude, σ height (m). → [`GnssFix`] with `pos_sigma` = (σ lon, σ lat, σ h)
//!   (ENU order) and no quality; `t` = GPS seconds when the caller gives the week
//!   (`from_week_tow`), else the seconds of week as they are.
//! - IMU: seconds of week, Δθ x y z (rad), Δv x y z (m/s), increments over the interval
//!   since the previous row, in the sensor's forward-right-down frame (the mounting
//!   rotation belongs to the monitor's configuration). → increment samples with
//!   `dt` = the time since the previous row; the first row only starts the clock.

use std::path::Path;

use navguard_core::epoch::{Epoch, ImuBlock};
use navguard_core::geo::Lla;

use crate::error::{At, FormatError, missing, read_to_string};
use crate::fix::GnssFix;
use crate::gpstime::from_week_tow;

/// The numbers of a record line, which must hold `n` of them; `None` for a skipped line.
fn fields<const N: usize>(line: &str, at: At<'_>) -> Result<Option<[f64; N]>, FormatError> {
    let line = line.trim();
    if line.is_empty() || line.starts_with('#') || line.starts_with('%') {
        return Ok(None);
    }
    let f: Vec<&str> = line.split_whitespace().collect();
    if f.len() != N {
        return Err(at.err(format!("{} columns, expected {N}", f.len())));
    }
    let mut out = [0.0; N];
    for (o, s) in out.iter_mut().zip(&f) {
        *o = s
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| at.err(format!("not a number: '{s}'")))?;
    }
    Ok(Some(out))
}

/// Reads a KF-GINS GNSS file; `week` puts its seconds of week on GPS time.
pub fn read_gnss(path: &Path, week: Option<i64>) -> Result<Vec<GnssFix>, FormatError> {
    parse_gnss(&read_to_string(path)?, &path.display().to_string(), week)
}

/// Parses the text of a KF-GINS GNSS file named `file`.
pub fn parse_gnss(text: &str, file: &str, week: Option<i64>) -> Result<Vec<GnssFix>, FormatError> {
    let mut out = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let at = At { file, line: k + 1 };
        let Some([tow, lat, lon, h, s_lat, s_lon, s_h]) = fields::<7>(line, at)? else {
            continue;
        };
        if lat.abs() > 90.0 {
            return Err(at.err(format!("latitude {lat}° beyond ±90")));
        }
        out.push(GnssFix {
            line: at.line,
            t: week.map_or(tow, |w| from_week_tow(w, tow)),
            lla: Lla {
                lat: lat.to_radians(),
                lon: lon.to_radians(),
                h,
            },
            quality: None,
            ns: None,
            pos_sigma: Some([s_lon, s_lat, s_h]),
            vel: None,
            vel_sigma: None,
        });
    }
    if out.is_empty() {
        return Err(missing(file, "no GNSS records"));
    }
    Ok(out)
}

/// Reads a KF-GINS IMU file into increment epochs; `week` as for [`read_gnss`].
pub fn read_imu(path: &Path, week: Option<i64>) -> Result<Vec<Epoch>, FormatError> {
    parse_imu(&read_to_string(path)?, &path.display().to_string(), week)
}

/// Parses the text of a KF-GINS IMU file named `file`.
pub fn parse_imu(text: &str, file: &str, week: Option<i64>) -> Result<Vec<Epoch>, FormatError> {
    let mut out = Vec::new();
    let mut prev: Option<f64> = None;
    for (k, line) in text.lines().enumerate() {
        let at = At { file, line: k + 1 };
        let Some([tow, gx, gy, gz, ax, ay, az]) = fields::<7>(line, at)? else {
            continue;
        };
        let t = week.map_or(tow, |w| from_week_tow(w, tow));
        if let Some(p) = prev {
            let dt = t - p;
            if dt <= 0.0 {
                return Err(at.err(format!("time {tow} s does not advance")));
            }
            out.push(Epoch {
                t,
                imu: Some(ImuBlock {
                    accel: [ax, ay, az],
                    gyro: [gx, gy, gz],
                    dt: Some(dt),
                }),
                ..Epoch::default()
            });
        }
        prev = Some(t);
    }
    if out.is_empty() {
        return Err(missing(file, "fewer than two IMU records"));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    const GNSS: &str = "456250.000    30.4447858054   114.4718661162     21.095    0.010    0.009    0.019 \n\
                        456251.000    30.4447857891   114.4718661133     21.091    0.010    0.009    0.019 \n";

    #[test]
    fn gnss_sigma_comes_out_east_north_up() {
        let f = parse_gnss(GNSS, "g.txt", None).unwrap();
        assert_eq!(f.len(), 2);
        assert_eq!(f[0].t, 456_250.0);
        assert_relative_eq!(f[0].lla.lat.to_degrees(), 30.4447858054, epsilon = 1e-12);
        assert_eq!(f[0].pos_sigma, Some([0.009, 0.010, 0.019]));
        let w = parse_gnss(GNSS, "g.txt", Some(2000)).unwrap();
        assert_eq!(w[1].t, 2000.0 * 604_800.0 + 456_251.0);
    }

    #[test]
    fn a_short_gnss_line_names_its_line() {
        let e = parse_gnss(
            "# comment\n456250.0 30.4 114.4 21.0 0.01 0.01\n",
            "g.txt",
            None,
        );
        assert_eq!(e.unwrap_err().to_string(), "g.txt:2: 6 columns, expected 7");
    }

    #[test]
    fn imu_increments_take_the_interval_from_the_previous_row() {
        let text = "100.000 0 0 0 0 0 0\n100.005 1e-4 2e-4 3e-4 0.001 0.002 -0.049\n";
        let e = parse_imu(text, "i.txt", None).unwrap();
        assert_eq!(e.len(), 1);
        let imu = e[0].imu.unwrap();
        assert_relative_eq!(imu.dt.unwrap(), 0.005, epsilon = 1e-9);
        assert_eq!(imu.gyro, [1e-4, 2e-4, 3e-4]);
        assert_eq!(imu.accel, [0.001, 0.002, -0.049]);
        let back = "100.0 0 0 0 0 0 0\n100.0 0 0 0 0 0 0\n";
        assert!(parse_imu(back, "i.txt", None).is_err());
    }
}
