//! RINEX 2.10/2.11 and 3.0x: the fixed-column text files of geodetic receivers, read
//! at the edge of the crate into plain records ([`nav`], [`obs`]), then turned into
//! epochs of raw pseudoranges ([`convert`]) with the broadcast orbits and Klobuchar.
//!
//! [`obs::read_obs`] and [`nav::read_nav`] read the version on the first line
//! (`RINEX VERSION / TYPE`, columns 1–9) and dispatch: 2.x to the RINEX 2 readers,
//! 3.x to [`obs3`] and [`nav3`]; any other version is an error at line 1. Both
//! versions give the same records ([`obs::ObsFile`], [`nav::NavFile`]), so the
//! conversion, orbits and clocks are one code.
//!
//! References: RINEX 2.11 (Gurtner & Estey, IGS/RTCM, 2007) §§5–6 and Tables A1–A4;
//! RINEX 3.04 (IGS/RTCM, 2018) §§5–6 and Tables A1–A8. Columns below are 0-based byte
//! offsets; RINEX's are 1-based.

pub mod convert;
pub mod nav;
pub mod nav3;
pub mod obs;
pub mod obs3;

use navguard_core::epoch::{Constellation, SatId};

use crate::error::{At, FormatError};
use crate::gpstime::{Calendar, full_year};

/// The major version of a RINEX file from its first line, which must be
/// `RINEX VERSION / TYPE` (F9.2 in columns 1–9): 2 or 3, else an error at line 1.
pub(crate) fn major_version(lines: &[&str], file: &str) -> Result<u8, FormatError> {
    let at = At { file, line: 1 };
    let first = lines.first().copied().unwrap_or("");
    if label(first) != "RINEX VERSION / TYPE" {
        return Err(at.err("the first line is not RINEX VERSION / TYPE"));
    }
    let v = cols(first, 0, 9).trim();
    match v.split('.').next() {
        Some("2") => Ok(2),
        Some("3") => Ok(3),
        _ => Err(at.err(format!(
            "RINEX version '{v}' is not read (only 2.x and 3.x are)"
        ))),
    }
}

/// `APPROX POSITION XYZ` (3F14.4, the same in RINEX 2 and 3): `None` when all zero.
pub(crate) fn approx_position(line: &str, at: At<'_>) -> Result<Option<[f64; 3]>, FormatError> {
    let mut v = [0.0; 3];
    for (j, x) in v.iter_mut().enumerate() {
        *x = real(cols(line, 14 * j, 14 * j + 14), at)?.unwrap_or(0.0);
    }
    Ok(v.iter().any(|x| *x != 0.0).then_some(v))
}

/// The header label of a line (columns 61–80), trimmed.
pub(crate) fn label(line: &str) -> &str {
    line.get(60..).unwrap_or("").trim()
}

/// Columns `a..b` of a line, or "" past its end (RINEX lines may be right-trimmed).
pub(crate) fn cols(line: &str, a: usize, b: usize) -> &str {
    let b = b.min(line.len());
    if a >= b {
        ""
    } else {
        line.get(a..b).unwrap_or("")
    }
}

/// A Fortran real (`D` or `E` exponent); blank is `None`.
pub(crate) fn real(s: &str, at: At<'_>) -> Result<Option<f64>, FormatError> {
    let s = s.trim();
    if s.is_empty() {
        return Ok(None);
    }
    s.replace(['D', 'd'], "E")
        .parse::<f64>()
        .map(Some)
        .map_err(|_| at.err(format!("not a number: '{s}'")))
}

/// An integer field; blank is `None`.
pub(crate) fn int(s: &str, at: At<'_>) -> Result<Option<i64>, FormatError> {
    let s = s.trim();
    if s.is_empty() {
        return Ok(None);
    }
    s.parse::<i64>()
        .map(Some)
        .map_err(|_| at.err(format!("not an integer: '{s}'")))
}

/// A satellite field of RINEX 2 (`G05`, `G 5`, ` 5`: blank letter = `default`).
pub(crate) fn sat_id(s: &str, default: Constellation, at: At<'_>) -> Result<SatId, FormatError> {
    let mut chars = s.chars();
    let letter = chars.next().unwrap_or(' ');
    let constellation = if letter == ' ' {
        default
    } else {
        Constellation::from_letter(letter)
            .ok_or_else(|| at.err(format!("unknown constellation letter '{letter}'")))?
    };
    let prn = chars
        .as_str()
        .trim()
        .parse::<u8>()
        .map_err(|_| at.err(format!("bad satellite number in '{s}'")))?;
    Ok(SatId { constellation, prn })
}

/// A RINEX 2 date `yy mm dd hh mm ss.s` as six whitespace-separated fields.
pub(crate) fn date(s: &str, at: At<'_>) -> Result<Calendar, FormatError> {
    let f: Vec<&str> = s.split_whitespace().collect();
    if f.len() != 6 {
        return Err(at.err(format!(
            "expected a date 'yy mm dd hh mm ss', got '{}'",
            s.trim()
        )));
    }
    let n = |k: usize| {
        f[k].parse::<i64>()
            .map_err(|_| at.err(format!("bad date field '{}'", f[k])))
    };
    let second = f[5]
        .parse::<f64>()
        .map_err(|_| at.err(format!("bad seconds '{}'", f[5])))?;
    let u = |v: i64| u32::try_from(v).map_err(|_| at.err("negative date field"));
    Ok(Calendar {
        year: full_year(n(0)?),
        month: u(n(1)?)?,
        day: u(n(2)?)?,
        hour: u(n(3)?)?,
        minute: u(n(4)?)?,
        second,
    })
}
