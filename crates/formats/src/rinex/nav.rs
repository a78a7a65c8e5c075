//! RINEX 2 GPS navigation files (RINEX 2.11 §6.4, Table A4): the header's Klobuchar
//! coefficients and leap seconds, and 8-line broadcast records with `D` exponents.
//! RINEX 3.0x files are read by [`super::nav3`] into the same [`NavFile`].

use std::path::Path;

use navguard_core::epoch::{Constellation, SatId};

use super::{cols, date, int, label, major_version, real, sat_id};
use crate::ephemeris::{Ephemerides, Ephemeris, GalileoMessage, GalileoNav};
use crate::error::{At, FormatError, missing, read_to_string};
use crate::gpstime::{WEEK_S, wrap_half_week};
use crate::klobuchar::Klobuchar;

/// A parsed navigation file (GPS; RINEX 3 also Galileo).
#[derive(Debug, Clone, PartialEq)]
pub struct NavFile {
    /// `ION ALPHA` / `ION BETA`, when the header has both.
    pub klobuchar: Option<Klobuchar>,
    /// `LEAP SECONDS` (GPST − UTC), s, when given.
    pub leap_seconds: Option<f64>,
    /// Every broadcast record.
    pub ephemerides: Ephemerides,
    /// RINEX 3: records of systems other than GPS and Galileo, skipped. Always 0 for
    /// RINEX 2.
    pub other_systems_skipped: usize,
}

/// Reads a RINEX 2.x GPS or 3.x navigation file (the version on its first line
/// decides; of RINEX 3 the GPS and Galileo records are kept).
pub fn read_nav(path: &Path) -> Result<NavFile, FormatError> {
    parse_nav(&read_to_string(path)?, &path.display().to_string())
}

/// Four header reals after column 2 (`ION ALPHA`/`ION BETA`: 2X,4D12.4).
fn four(line: &str, at: At<'_>) -> Result<[f64; 4], FormatError> {
    let mut out = [0.0; 4];
    for (k, v) in out.iter_mut().enumerate() {
        *v = real(cols(line, 2 + 12 * k, 14 + 12 * k), at)?
            .ok_or_else(|| at.err("blank coefficient"))?;
    }
    Ok(out)
}

/// Parses the text of a RINEX 2.x GPS or 3.x navigation file named `file`.
pub fn parse_nav(text: &str, file: &str) -> Result<NavFile, FormatError> {
    let lines: Vec<&str> = text.lines().collect();
    if major_version(&lines, file)? == 3 {
        return super::nav3::parse(&lines, file);
    }
    let (mut alpha, mut beta, mut leap) = (None, None, None);
    let mut k = 0;
    loop {
        let line = lines
            .get(k)
            .ok_or_else(|| missing(file, "no END OF HEADER"))?;
        let at = At { file, line: k + 1 };
        k += 1;
        match label(line) {
            "RINEX VERSION / TYPE" if !cols(line, 0, 9).trim().starts_with('2') => {
                return Err(at.err("only RINEX 2.x navigation files are read"));
            }
            "ION ALPHA" => alpha = Some(four(line, at)?),
            "ION BETA" => beta = Some(four(line, at)?),
            "LEAP SECONDS" => leap = int(cols(line, 0, 6), at)?.map(|v| v as f64),
            "END OF HEADER" => break,
            _ => {}
        }
    }
    let mut all = Vec::new();
    while k < lines.len() {
        if lines[k].trim().is_empty() {
            k += 1;
            continue;
        }
        all.push(record(&lines, k, file)?);
        k += 8;
    }
    let klobuchar = alpha
        .zip(beta)
        .map(|(alpha, beta)| Klobuchar { alpha, beta });
    Ok(NavFile {
        klobuchar,
        leap_seconds: leap,
        ephemerides: Ephemerides::new(all),
        other_systems_skipped: 0,
    })
}

/// The 31 reals of the 8-line record starting at line index `k`, whose first line's
/// three reals start at column `first` and the other lines' four at `indent` (RINEX 2:
/// 22 and 3; RINEX 3: 23 and 4). Missing trailing fields are 0, as blank fields are:
/// RINEX writers trim the fit interval.
pub(crate) fn record_values(
    lines: &[&str],
    k: usize,
    file: &str,
    first: usize,
    indent: usize,
) -> Result<Vec<f64>, FormatError> {
    let mut v = Vec::with_capacity(32);
    for j in 0..3 {
        let at = At { file, line: k + 1 };
        v.push(real(cols(lines[k], first + 19 * j, first + 19 + 19 * j), at)?.unwrap_or(0.0));
    }
    for i in 1..8 {
        let line = lines.get(k + i).copied().unwrap_or("");
        let at = At {
            file,
            line: k + i + 1,
        };
        for j in 0..4 {
            v.push(real(cols(line, indent + 19 * j, indent + 19 + 19 * j), at)?.unwrap_or(0.0));
        }
    }
    Ok(v)
}

/// One 8-line record (Table A4) starting at line index `k`.
fn record(lines: &[&str], k: usize, file: &str) -> Result<Ephemeris, FormatError> {
    let at = At { file, line: k + 1 };
    let sat = sat_id(
        &format!(" {}", cols(lines[k], 0, 2)),
        Constellation::Gps,
        at,
    )?;
    let toc = date(cols(lines[k], 2, 22), at)?.to_gps_seconds();
    let v = record_values(lines, k, file, 22, 3)?;
    ephemeris(sat, toc, &v, at)
}

/// The broadcast values of Table A4 (RINEX 3.04 Table A8 has the same order for GPS and,
/// but for the fields noted in [`galileo`], for Galileo) with the clock reference time
/// `toc`, as an [`Ephemeris`].
pub(crate) fn ephemeris(
    sat: SatId,
    toc: f64,
    v: &[f64],
    at: At<'_>,
) -> Result<Ephemeris, FormatError> {
    // The week field goes with t_oe (Galileo: GST week + 1024, aligned with GPS weeks);
    // t_oe near a week's edge and t_oc across it stay consistent by the half-week rule.
    let week = v[21] as i64;
    let toe_raw = week as f64 * WEEK_S + v[11];
    let toe = toc + wrap_half_week(toe_raw - toc);
    if v[10] <= 0.0 {
        return Err(at.err("√A must be positive"));
    }
    let galileo = match sat.constellation {
        Constellation::Galileo => Some(galileo(v, at)?),
        _ => None,
    };
    Ok(Ephemeris {
        sat,
        toc,
        af0: v[0],
        af1: v[1],
        af2: v[2],
        iode: v[3],
        crs: v[4],
        delta_n: v[5],
        m0: v[6],
        cuc: v[7],
        e: v[8],
        cus: v[9],
        sqrt_a: v[10],
        toe,
        cic: v[12],
        omega0: v[13],
        cis: v[14],
        i0: v[15],
        crc: v[16],
        omega: v[17],
        omega_dot: v[18],
        idot: v[19],
        week: ((toe / WEEK_S).floor()) as i64,
        health: v[24],
        tgd: v[25],
        galileo,
    })
}

/// The Galileo fields of RINEX 3.04 Table A8: data sources (orbit line 5, field 2),
/// SISA in m, health, BGD E5a/E1 and BGD E5b/E1 (orbit line 6). The clock's reference is
/// data-source bit 9 (E5b,E1: I/NAV) or bit 8 (E5a,E1: F/NAV); a file without either
/// (RINEX 3.00–3.02 writers) is read by the message bits, 1 (F/NAV E5a-I) against 0 and 2
/// (I/NAV E1-B, E5b-I).
fn galileo(v: &[f64], record: At<'_>) -> Result<GalileoNav, FormatError> {
    // The data sources are on the record's sixth line (orbit line 5).
    let at = At {
        line: record.line + 5,
        ..record
    };
    let bits = v[20];
    if !(0.0..1024.0).contains(&bits) || bits.fract() != 0.0 {
        return Err(at.err(format!(
            "Galileo data sources '{bits}' is not a 10-bit integer"
        )));
    }
    let bits = bits as u32;
    let bit = |k: u32| bits & (1 << k) != 0;
    let message = match (bit(9), bit(8), bit(0) || bit(2), bit(1)) {
        (true, false, _, _) | (false, false, true, false) => GalileoMessage::INav,
        (false, true, _, _) | (false, false, false, true) => GalileoMessage::FNav,
        _ => {
            return Err(at.err(format!(
                "Galileo data sources {bits} names no single clock (bits 8/9, or 0-2)"
            )));
        }
    };
    Ok(GalileoNav {
        message,
        bgd_e1_e5a: v[25],
        bgd_e1_e5b: v[26],
        sisa_m: v[23],
        data_sources: bits,
    })
}
