//! RINEX 3.0x observation files (RINEX 3.04 §5, Tables A1–A3), read into the same
//! [`ObsFile`] as RINEX 2 so that [`super::convert`] is one code.
//!
//! - `RINEX VERSION / TYPE`: the type `O` in column 21, the system (`G`, …, `M`) in
//!   column 41.
//! - `SYS / # / OBS TYPES`: per system, the letter (column 1), the count (4–6) and up to
//!   13 three-character codes (`C1C`, `L1C`, `C2W`, …) from column 8, continued on lines
//!   whose first six columns are blank. Each system's count is checked.
//! - Epoch records: `> yyyy mm dd hh mm ss.sssssss  f nnn` (the `>` in column 1, the
//!   event flag in column 32, the satellite count in 33–35, an optional receiver clock
//!   offset after it, not used), then one line per satellite: `G05` and 16-column fields
//!   (F14.3 value, LLI, SSI) from column 4, in that system's type order.
//! - Event flags 2–5 are followed by `n` header or comment lines, flag 6 by `n`
//!   cycle-slip satellite lines: all skipped and counted.
//!
//! GPS and Galileo are kept: [`ObsFile::types`] is the `G` list and
//! [`ObsFile::galileo_types`] the `E` list; a satellite of either system without its
//! list is an error. Satellites of other systems are skipped and counted in
//! [`ObsFile::other_systems_skipped`] (their ephemerides are not read either, see
//! [`super::nav3`]).

use std::collections::BTreeMap;

use navguard_core::epoch::{Constellation, SatId};

use super::obs::{ObsEpoch, ObsFile, obs_value};
use super::{approx_position, cols, date, int, label, sat_id};
use crate::error::{At, FormatError, missing};

/// The header fields we use.
struct Header {
    /// Each system's letter → its observation codes.
    types: BTreeMap<char, Vec<String>>,
    approx: Option<[f64; 3]>,
    system: Constellation,
}

fn header(lines: &[&str], file: &str) -> Result<(Header, usize), FormatError> {
    let mut h = Header {
        types: BTreeMap::new(),
        approx: None,
        system: Constellation::Gps,
    };
    let mut counts: BTreeMap<char, usize> = BTreeMap::new();
    let mut current: Option<char> = None;
    for (k, line) in lines.iter().enumerate() {
        let at = At { file, line: k + 1 };
        match label(line) {
            "RINEX VERSION / TYPE" => {
                if cols(line, 20, 21) != "O" {
                    return Err(at.err("not an observation file (type in column 21 is not 'O')"));
                }
                // `M` (mixed) has no constellation: satellites carry their letters.
                let sys = cols(line, 40, 41).chars().next().unwrap_or('G');
                h.system = Constellation::from_letter(sys).unwrap_or(Constellation::Gps);
            }
            "SYS / # / OBS TYPES" => {
                let letter = cols(line, 0, 1).chars().next().unwrap_or(' ');
                let sys = if letter == ' ' {
                    current.ok_or_else(|| at.err("continuation line without a system"))?
                } else {
                    let n =
                        int(cols(line, 3, 6), at)?.ok_or_else(|| at.err("no observation count"))?;
                    let n = usize::try_from(n).map_err(|_| at.err("negative count"))?;
                    counts.insert(letter, n);
                    h.types.insert(letter, Vec::with_capacity(n));
                    letter
                };
                current = Some(sys);
                h.types
                    .entry(sys)
                    .or_default()
                    .extend(cols(line, 7, 60).split_whitespace().map(str::to_string));
            }
            "APPROX POSITION XYZ" => h.approx = approx_position(line, at)?,
            "END OF HEADER" => {
                for (sys, n) in &counts {
                    if h.types.get(sys).map_or(0, Vec::len) != *n || *n == 0 {
                        return Err(missing(
                            file,
                            format!("SYS / # / OBS TYPES count of '{sys}' does not match its list"),
                        ));
                    }
                }
                if counts.is_empty() {
                    return Err(missing(file, "no SYS / # / OBS TYPES"));
                }
                return Ok((h, k + 1));
            }
            _ => {}
        }
    }
    Err(missing(file, "no END OF HEADER"))
}

/// Parses the lines of a RINEX 3.0x observation file named `file` (its version
/// already checked).
pub(crate) fn parse(lines: &[&str], file: &str) -> Result<ObsFile, FormatError> {
    let (h, mut k) = header(lines, file)?;
    let (gps, gal) = (h.types.get(&'G'), h.types.get(&'E'));
    let mut epochs = Vec::new();
    let (mut events_skipped, mut other_systems_skipped) = (0, 0);
    while k < lines.len() {
        let line = lines[k];
        let at = At { file, line: k + 1 };
        if line.trim().is_empty() {
            k += 1;
            continue;
        }
        if !line.starts_with('>') {
            return Err(at.err("expected an epoch record starting with '>'"));
        }
        let flag = int(cols(line, 31, 32), at)?.unwrap_or(0);
        let n = usize::try_from(int(cols(line, 32, 35), at)?.unwrap_or(0))
            .map_err(|_| at.err("negative record count"))?;
        match flag {
            0 | 1 => {
                let t = date(cols(line, 1, 29), at)?.to_gps_seconds();
                let mut sats = Vec::with_capacity(n);
                for li in k + 1..k + 1 + n {
                    let at = At { file, line: li + 1 };
                    let line = lines
                        .get(li)
                        .ok_or_else(|| at.err("observations cut short"))?;
                    let id = sat_line_id(line, h.system, at)?;
                    let (types, letter) = match id.constellation {
                        Constellation::Gps => (gps, 'G'),
                        Constellation::Galileo => (gal, 'E'),
                        _ => {
                            other_systems_skipped += 1;
                            continue;
                        }
                    };
                    let types = types.ok_or_else(|| {
                        at.err(format!("{id} but no {letter} line in SYS / # / OBS TYPES"))
                    })?;
                    let values = (0..types.len())
                        .map(|i| obs_value(cols(line, 3 + 16 * i, 19 + 16 * i), at))
                        .collect::<Result<Vec<_>, _>>()?;
                    sats.push((id, values));
                }
                epochs.push(ObsEpoch {
                    t,
                    flag: flag as u8,
                    sats,
                });
            }
            2..=6 => events_skipped += 1,
            _ => return Err(at.err(format!("unknown event flag {flag}"))),
        }
        k += 1 + n;
    }
    Ok(ObsFile {
        types: gps.cloned().unwrap_or_default(),
        galileo_types: gal.cloned().unwrap_or_default(),
        approx_position: h.approx,
        system: h.system,
        epochs,
        events_skipped,
        other_systems_skipped,
    })
}

/// The satellite (`G05`) in columns 1–3 of an observation line.
fn sat_line_id(line: &str, default: Constellation, at: At<'_>) -> Result<SatId, FormatError> {
    let s = cols(line, 0, 3);
    if s.trim().is_empty() || s.starts_with('>') {
        return Err(at.err("expected a satellite observation line (e.g. 'G05')"));
    }
    sat_id(s, default, at)
}
