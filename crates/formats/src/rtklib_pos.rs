//! RTKLIB `.pos` solution files → [`GnssFix`]es (then domain epochs through a
//! [`SigmaPolicy`]).
//!
//! Accepted: GPST time as `yyyy/mm/dd hh:mm:ss.sss` or as `week tow`, latitude and
//! longitude in degrees, ellipsoidal height; then Q (1 fix, 2 float, 3 SBAS, 4 DGPS,
//! 5 single, 6 PPP), ns, sdn sde sdu sdne sdeu sdun (m), age, ratio and, when the solution
//! has them, vn ve vu (m/s) sdvn sdve sdvu sdvne sdveu sdvun. The columns are found by
//! name on the `%` header line that names them (`latitude(deg)`, `Q`, `sdn(m)`, `vn(m/s)`…);
//! without one, by RTKLIB's order, with velocity when a line has 24 fields or more.
//! Refused with a message: UTC or JST time, ECEF or ENU positions, degrees-minutes-seconds.
//! Other `%` lines and blank lines are skipped; any other line that does not hold a
//! solution is an error naming its line. Velocity and σ come out in ENU order
//! (ve, vn, vu and sde, sdn, sdu); the covariances sdne, sdeu, sdun are not kept.

use std::path::Path;

use navguard_core::epoch::Epoch;
use navguard_core::geo::Lla;

use crate::error::{At, FormatError, missing, read_to_string};
use crate::fix::{GnssFix, Quality, SigmaPolicy};
use crate::gpstime::{Calendar, from_week_tow};

/// Where each value is among a line's whitespace-separated fields (the time takes two).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct PosColumns {
    lat: usize,
    lon: usize,
    h: usize,
    q: usize,
    ns: usize,
    /// sde, sdn, sdu.
    sd_enu: [usize; 3],
    /// ve, vn, vu.
    vel_enu: Option<[usize; 3]>,
    /// sdve, sdvn, sdvu.
    sdv_enu: Option<[usize; 3]>,
}

impl PosColumns {
    /// RTKLIB's own order, for files without a naming header line.
    fn by_count(fields: usize) -> PosColumns {
        let with_vel = fields >= 24;
        PosColumns {
            lat: 2,
            lon: 3,
            h: 4,
            q: 5,
            ns: 6,
            sd_enu: [8, 7, 9],
            vel_enu: with_vel.then_some([16, 15, 17]),
            sdv_enu: with_vel.then_some([19, 18, 20]),
        }
    }

    /// The columns named by a `%` header line, `None` if it names none; an error for a
    /// solution form this reader does not take.
    fn from_header(line: &str, at: At<'_>) -> Result<Option<PosColumns>, FormatError> {
        let tokens: Vec<&str> = line.trim_start_matches('%').split_whitespace().collect();
        let Some(&system) = tokens.first() else {
            return Ok(None);
        };
        let names: Vec<&str> = tokens
            .iter()
            .map(|t| t.split('(').next().unwrap_or(t))
            .collect();
        let has = |n: &str| names.contains(&n);
        if !has("Q") || !has("ns") {
            return Ok(None);
        }
        if system != "GPST" {
            return Err(at.err(format!("time system {system}: only GPST is read")));
        }
        if !tokens.contains(&"latitude(deg)") || !tokens.contains(&"longitude(deg)") {
            return Err(at.err("positions must be latitude(deg) longitude(deg) height(m)"));
        }
        // Field index = name index + 1: the time name covers two fields.
        let find = |n: &str| names.iter().position(|x| *x == n).map(|i| i + 1);
        let req = |n: &str| find(n).ok_or_else(|| at.err(format!("header has no column {n}")));
        let three = |a: &str, b: &str, c: &str| Some([find(a)?, find(b)?, find(c)?]);
        Ok(Some(PosColumns {
            lat: req("latitude")?,
            lon: req("longitude")?,
            h: req("height")?,
            q: req("Q")?,
            ns: req("ns")?,
            sd_enu: [req("sde")?, req("sdn")?, req("sdu")?],
            vel_enu: three("ve", "vn", "vu"),
            sdv_enu: three("sdve", "sdvn", "sdvu"),
        }))
    }

    fn last(&self) -> usize {
        let opt = |v: Option<[usize; 3]>| v.map_or(0, |v| v.into_iter().max().unwrap_or(0));
        [self.lat, self.lon, self.h, self.q, self.ns]
            .into_iter()
            .chain(self.sd_enu)
            .chain([opt(self.vel_enu), opt(self.sdv_enu)])
            .max()
            .unwrap_or(0)
    }
}

/// Reads a `.pos` file's solutions, in file order.
pub fn read_pos(path: &Path) -> Result<Vec<GnssFix>, FormatError> {
    parse_pos(&read_to_string(path)?, &path.display().to_string())
}

/// Parses the text of a `.pos` file named `file`.
pub fn parse_pos(text: &str, file: &str) -> Result<Vec<GnssFix>, FormatError> {
    let mut cols: Option<PosColumns> = None;
    let mut fixes = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let at = At { file, line: k + 1 };
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        if line.starts_with('%') {
            if let Some(c) = PosColumns::from_header(line, at)? {
                cols = Some(c);
            }
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        let c = *cols.get_or_insert_with(|| PosColumns::by_count(f.len()));
        fixes.push(parse_line(&f, &c, at)?);
    }
    if fixes.is_empty() {
        return Err(missing(file, "no solution lines"));
    }
    Ok(fixes)
}

/// The GPS time of a line's first two fields: a GPST date and time, or week and tow.
fn parse_time(date: &str, time: &str, at: At<'_>) -> Result<f64, FormatError> {
    let bad = || at.err(format!("bad time '{date} {time}'"));
    if date.contains('/') {
        let d: Vec<&str> = date.split('/').collect();
        let t: Vec<&str> = time.split(':').collect();
        let (&[y, mo, da], &[hh, mi, ss]) = (&d[..], &t[..]) else {
            return Err(bad());
        };
        let c = Calendar {
            year: y.parse().map_err(|_| bad())?,
            month: mo.parse().map_err(|_| bad())?,
            day: da.parse().map_err(|_| bad())?,
            hour: hh.parse().map_err(|_| bad())?,
            minute: mi.parse().map_err(|_| bad())?,
            second: ss.parse().map_err(|_| bad())?,
        };
        Ok(c.to_gps_seconds())
    } else {
        let week: i64 = date.parse().map_err(|_| bad())?;
        let tow: f64 = time.parse().map_err(|_| bad())?;
        Ok(from_week_tow(week, tow))
    }
}

/// Field `i` as a number.
fn num(f: &[&str], i: usize, at: At<'_>) -> Result<f64, FormatError> {
    let s = f.get(i).copied().unwrap_or("");
    s.parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .ok_or_else(|| at.err(format!("field {}: not a number: '{s}'", i + 1)))
}

fn nums3(f: &[&str], i: [usize; 3], at: At<'_>) -> Result<[f64; 3], FormatError> {
    Ok([num(f, i[0], at)?, num(f, i[1], at)?, num(f, i[2], at)?])
}

fn parse_line(f: &[&str], c: &PosColumns, at: At<'_>) -> Result<GnssFix, FormatError> {
    if f.len() <= c.last() {
        return Err(at.err(format!(
            "{} fields, the header's columns need {}",
            f.len(),
            c.last() + 1
        )));
    }
    let q = num(f, c.q, at)?;
    let quality = Quality::from_rtklib_q(q as u32)
        .filter(|_| q.fract() == 0.0)
        .ok_or_else(|| at.err(format!("Q = {q}: not 1-6")))?;
    let lat = num(f, c.lat, at)?;
    if lat.abs() > 90.0 {
        return Err(at.err(format!("latitude {lat}° beyond ±90")));
    }
    Ok(GnssFix {
        line: at.line,
        t: parse_time(f[0], f[1], at)?,
        lla: Lla {
            lat: lat.to_radians(),
            lon: num(f, c.lon, at)?.to_radians(),
            h: num(f, c.h, at)?,
        },
        quality: Some(quality),
        ns: Some(num(f, c.ns, at)? as u32),
        pos_sigma: Some(nums3(f, c.sd_enu, at)?),
        vel: c.vel_enu.map(|i| nums3(f, i, at)).transpose()?,
        vel_sigma: c.sdv_enu.map(|i| nums3(f, i, at)).transpose()?,
    })
}

/// The fixes as GNSS-only epochs, σ by `policy`.
pub fn to_epochs(fixes: &[GnssFix], policy: &SigmaPolicy) -> Vec<Epoch> {
    fixes.iter().map(|f| policy.epoch(f)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    const HEADER: &str = "%  GPST            latitude(deg) longitude(deg) height(m) Q  ns  sdn(m)  sde(m)  sdu(m)  sdne(m)  sdeu(m)  sdun(m)  age(s)  ratio  vn(m/s)  ve(m/s)  vu(m/s)  sdvn  sdve  sdvu  sdvne  sdveu  sdvun";

    #[test]
    fn week_and_tow_times_read_as_gps_seconds() {
        let text = "%  GPST  latitude(deg) longitude(deg) height(m) Q ns sdn(m) sde(m) sdu(m) sdne(m) sdeu(m) sdun(m) age(s) ratio\n\
                    1934 123456.000 35.1 139.2 50.0 5 8 1.2 1.1 2.5 0 0 0 0 0\n";
        let f = parse_pos(text, "w.pos").unwrap();
        assert_relative_eq!(f[0].t, 1934.0 * 604_800.0 + 123_456.0);
        assert_eq!(f[0].quality, Some(Quality::Single));
        assert_eq!(f[0].pos_sigma, Some([1.1, 1.2, 2.5]));
        assert_eq!(f[0].vel, None);
    }

    #[test]
    fn columns_come_from_the_header_names_not_their_order() {
        // A header with ve before vn: the names decide.
        let h = HEADER.replace("vn(m/s)  ve(m/s)", "ve(m/s)  vn(m/s)");
        let text = format!(
            "{h}\n2025/07/08 19:34:18.499 40 -105 1600 1 20 0.01 0.02 0.03 0 0 0 0 0 1.0 2.0 3.0 0.1 0.2 0.3 0 0 0\n"
        );
        let f = parse_pos(&text, "h.pos").unwrap();
        assert_eq!(f[0].vel, Some([1.0, 2.0, 3.0]));
        assert_eq!(f[0].vel_sigma, Some([0.2, 0.1, 0.3]));
    }

    #[test]
    fn a_short_line_or_a_bad_flag_is_an_error_with_its_line() {
        let text = format!("{HEADER}\n2025/07/08 19:34:18.499 40 -105 1600 1 20\n");
        let e = parse_pos(&text, "s.pos").unwrap_err().to_string();
        assert!(e.starts_with("s.pos:2:"), "{e}");
        let text = format!(
            "{HEADER}\n\n2025/07/08 19:34:18.499 40 -105 1600 7 20 0.01 0.02 0.03 0 0 0 0 0 1 2 3 0.1 0.2 0.3 0 0 0\n"
        );
        let e = parse_pos(&text, "s.pos").unwrap_err().to_string();
        assert!(e.starts_with("s.pos:3: Q = 7"), "{e}");
    }

    #[test]
    fn utc_and_ecef_solutions_are_refused() {
        let utc = HEADER.replace("GPST", "UTC ");
        assert!(
            parse_pos(&utc, "u.pos")
                .unwrap_err()
                .to_string()
                .contains("only GPST")
        );
        let xyz = "%  GPST  x-ecef(m) y-ecef(m) z-ecef(m) Q ns sdx(m) sdy(m) sdz(m)";
        assert!(parse_pos(xyz, "x.pos").is_err());
    }
}
