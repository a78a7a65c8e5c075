//! RINEX 3.0x navigation files (RINEX 3.04 §6, Tables A5–A8), read into the same
//! [`NavFile`] as RINEX 2 so that orbits and clocks are one code.
//!
//! - `RINEX VERSION / TYPE`: the type `N` in column 21 (any system, `M` for mixed).
//! - `IONOSPHERIC CORR`: `GPSA` (α₀..α₃) and `GPSB` (β₀..β₃), 4D12.4 from column 6,
//!   are the Klobuchar coefficients; the other models' lines (`GAL`, `QZSA`, `BDSA`, …)
//!   are ignored (Galileo's NeQuick is not computed).
//! - `LEAP SECONDS`: I6 in columns 1–6, as RINEX 2.
//! - GPS and Galileo records: `G05 yyyy mm dd hh mm ss` (`E11 …`) and three D19.12 from
//!   column 24, then seven broadcast-orbit lines of four D19.12 after a 4-space indent.
//!   GPS in the order of RINEX 2 (Table A8 = RINEX 2.11 Table A4); Galileo in the same
//!   places for the Kepler elements and clock, with IODnav for IODE, the data sources,
//!   GAL week (aligned with GPS weeks), SISA, health and BGD E5a/E1 and E5b/E1 where GPS
//!   has its own fields ([`super::nav::ephemeris`]). A satellite with both I/NAV and F/NAV
//!   records keeps both, told apart by the data sources.
//! - Records of other systems (GLONASS and SBAS of 4 or 5 lines, BeiDou, QZSS, IRNSS of 8)
//!   are skipped by their continuation lines (those starting with a blank) and counted in
//!   [`NavFile::other_systems_skipped`].

use navguard_core::epoch::Constellation;

use super::nav::{NavFile, ephemeris, record_values};
use super::{cols, date, int, label, real, sat_id};
use crate::ephemeris::Ephemerides;
use crate::error::{At, FormatError, missing};
use crate::klobuchar::Klobuchar;

/// The four coefficients of an `IONOSPHERIC CORR` line (A4,1X,4D12.4).
fn four(line: &str, at: At<'_>) -> Result<[f64; 4], FormatError> {
    let mut out = [0.0; 4];
    for (k, v) in out.iter_mut().enumerate() {
        *v = real(cols(line, 5 + 12 * k, 17 + 12 * k), at)?
            .ok_or_else(|| at.err("blank coefficient"))?;
    }
    Ok(out)
}

/// Parses the lines of a RINEX 3.0x navigation file named `file` (its version already
/// checked).
pub(crate) fn parse(lines: &[&str], file: &str) -> Result<NavFile, FormatError> {
    let (mut alpha, mut beta, mut leap) = (None, None, None);
    let mut k = 0;
    loop {
        let line = lines
            .get(k)
            .ok_or_else(|| missing(file, "no END OF HEADER"))?;
        let at = At { file, line: k + 1 };
        k += 1;
        match label(line) {
            "RINEX VERSION / TYPE" if cols(line, 20, 21) != "N" => {
                return Err(at.err("not a navigation file (type in column 21 is not 'N')"));
            }
            "IONOSPHERIC CORR" => match cols(line, 0, 4).trim() {
                "GPSA" => alpha = Some(four(line, at)?),
                "GPSB" => beta = Some(four(line, at)?),
                _ => {}
            },
            "LEAP SECONDS" => leap = int(cols(line, 0, 6), at)?.map(|v| v as f64),
            "END OF HEADER" => break,
            _ => {}
        }
    }
    let mut all = Vec::new();
    let mut other_systems_skipped = 0;
    let starts_record = |l: &str| !l.is_empty() && !l.starts_with(' ');
    while k < lines.len() {
        let line = lines[k];
        let at = At { file, line: k + 1 };
        if line.trim().is_empty() {
            k += 1;
            continue;
        }
        if !starts_record(line) {
            return Err(at.err("expected a record starting with a satellite (e.g. 'G05')"));
        }
        let sat = sat_id(cols(line, 0, 3), Constellation::Gps, at)?;
        if !matches!(
            sat.constellation,
            Constellation::Gps | Constellation::Galileo
        ) {
            other_systems_skipped += 1;
            k += 1;
            while k < lines.len() && !starts_record(lines[k]) && !lines[k].trim().is_empty() {
                k += 1;
            }
            continue;
        }
        if let Some(j) = (k + 1..(k + 8).min(lines.len())).find(|&j| starts_record(lines[j])) {
            return Err(At { file, line: j + 1 }.err(format!(
                "{sat} record of line {} cut short: 7 broadcast-orbit lines expected",
                k + 1
            )));
        }
        let toc = date(cols(line, 4, 23), at)?.to_gps_seconds();
        let v = record_values(lines, k, file, 23, 4)?;
        all.push(ephemeris(sat, toc, &v, at)?);
        k += 8;
    }
    let klobuchar = alpha
        .zip(beta)
        .map(|(alpha, beta)| Klobuchar { alpha, beta });
    Ok(NavFile {
        klobuchar,
        leap_seconds: leap,
        ephemerides: Ephemerides::new(all),
        other_systems_skipped,
    })
}
