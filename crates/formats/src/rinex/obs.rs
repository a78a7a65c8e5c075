//! RINEX 2.10/2.11 observation files (RINEX 2.11 §5.1, Tables A1–A2): the header's
//! observation types and approximate position, and the epoch records. RINEX 3.0x files
//! are read by [`super::obs3`] into the same [`ObsFile`].
//!
//! An epoch line holds the date (columns 2–26), the event flag (column 29), the
//! satellite count (30–32) and up to 12 satellites (33–68), continued on lines that
//! start with 32 blanks. Each satellite then has `ceil(n_types / 5)` lines of 16-column
//! fields: the value (F14.3), the loss-of-lock indicator and the signal strength.
//! Event flags 2–5 are followed by `n` header or comment lines (their date may be blank,
//! as in RINEX FILE SPLICE records): skipped. Flag 6 (cycle-slip records) carries
//! observation lines, also skipped.

use std::path::Path;

use navguard_core::epoch::{Constellation, SatId};

use super::{approx_position, cols, date, int, label, major_version, real, sat_id};
use crate::error::{At, FormatError, missing, read_to_string};

/// One observed value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObsValue {
    /// The value (m for codes, cycles for phases, dB-Hz for S).
    pub value: f64,
    /// Loss-of-lock indicator, when given.
    pub lli: Option<u8>,
    /// Signal-strength indicator 1–9, when given.
    pub ssi: Option<u8>,
}

/// One epoch record with observations (event flag 0 or 1).
#[derive(Debug, Clone, PartialEq)]
pub struct ObsEpoch {
    /// The receiver's time tag, GPS s (includes the receiver clock offset).
    pub t: f64,
    /// The event flag: 0 OK, 1 power failure before this epoch.
    pub flag: u8,
    /// Each satellite's values, in the order of its system's list
    /// ([`ObsFile::types_of`]).
    pub sats: Vec<(SatId, Vec<Option<ObsValue>>)>,
}

/// A parsed observation file.
#[derive(Debug, Clone, PartialEq)]
pub struct ObsFile {
    /// RINEX 2 `# / TYPES OF OBSERV`, e.g. `["L1", "C1", "L2", "P2"]`; RINEX 3 the
    /// GPS list of `SYS / # / OBS TYPES`, e.g. `["C1C", "L1C", "C2W", "L2W"]`.
    pub types: Vec<String>,
    /// RINEX 3: the Galileo list of `SYS / # / OBS TYPES` (e.g. `["C1C", "C5Q"]`);
    /// RINEX 2: the one list again, which every system's satellites use.
    pub galileo_types: Vec<String>,
    /// `APPROX POSITION XYZ`, ECEF m, when given and not zero.
    pub approx_position: Option<[f64; 3]>,
    /// The file's satellite system (`G`, or `M` for mixed: blanks read as GPS).
    pub system: Constellation,
    /// The epochs with observations.
    pub epochs: Vec<ObsEpoch>,
    /// How many event records (flags 2–6) were skipped.
    pub events_skipped: usize,
    /// RINEX 3: satellite observations of systems other than GPS and Galileo, not kept.
    /// Always 0 for RINEX 2, whose mixed files keep every satellite.
    pub other_systems_skipped: usize,
}

impl ObsFile {
    /// The observation codes, in value order, of a satellite of constellation `c`.
    pub fn types_of(&self, c: Constellation) -> &[String] {
        match c {
            Constellation::Galileo => &self.galileo_types,
            _ => &self.types,
        }
    }
}

/// Reads a RINEX 2.x or 3.x observation file (the version on its first line decides).
pub fn read_obs(path: &Path) -> Result<ObsFile, FormatError> {
    parse_obs(&read_to_string(path)?, &path.display().to_string())
}

/// The header fields we use and the index of the first data line.
struct Header {
    types: Vec<String>,
    approx: Option<[f64; 3]>,
    system: Constellation,
    n_types: usize,
}

fn header(lines: &[&str], file: &str) -> Result<(Header, usize), FormatError> {
    let mut h = Header {
        types: vec![],
        approx: None,
        system: Constellation::Gps,
        n_types: 0,
    };
    for (k, line) in lines.iter().enumerate() {
        let at = At { file, line: k + 1 };
        match label(line) {
            "RINEX VERSION / TYPE" => {
                if !cols(line, 0, 9).trim().starts_with('2') {
                    return Err(at.err("only RINEX 2.x observation files are read"));
                }
                let sys = cols(line, 40, 41).chars().next().unwrap_or('G');
                h.system = Constellation::from_letter(sys).unwrap_or(Constellation::Gps);
            }
            "# / TYPES OF OBSERV" => {
                if let Some(n) = int(cols(line, 0, 6), at)? {
                    h.n_types = usize::try_from(n).map_err(|_| at.err("negative count"))?;
                }
                h.types
                    .extend(cols(line, 6, 60).split_whitespace().map(str::to_string));
            }
            "APPROX POSITION XYZ" => h.approx = approx_position(line, at)?,
            "END OF HEADER" => {
                if h.types.len() != h.n_types || h.n_types == 0 {
                    return Err(missing(
                        file,
                        "# / TYPES OF OBSERV count does not match its list",
                    ));
                }
                return Ok((h, k + 1));
            }
            _ => {}
        }
    }
    Err(missing(file, "no END OF HEADER"))
}

/// Parses the text of a RINEX 2.x or 3.x observation file named `file`.
pub fn parse_obs(text: &str, file: &str) -> Result<ObsFile, FormatError> {
    let lines: Vec<&str> = text.lines().collect();
    if major_version(&lines, file)? == 3 {
        return super::obs3::parse(&lines, file);
    }
    let (h, mut k) = header(&lines, file)?;
    let mut epochs = Vec::new();
    let mut events_skipped = 0;
    let per_sat = h.n_types.div_ceil(5);
    while k < lines.len() {
        let line = lines[k];
        let at = At { file, line: k + 1 };
        if line.trim().is_empty() {
            k += 1;
            continue;
        }
        let flag = int(cols(line, 28, 29), at)?.unwrap_or(0);
        let n = usize::try_from(int(cols(line, 29, 32), at)?.unwrap_or(0))
            .map_err(|_| at.err("negative record count"))?;
        match flag {
            0 | 1 => {
                let (epoch, next) = epoch_record(&lines, k, file, &h, per_sat, n)?;
                epochs.push(ObsEpoch {
                    flag: flag as u8,
                    ..epoch
                });
                k = next;
            }
            2..=5 => {
                events_skipped += 1;
                k += 1 + n;
            }
            6 => {
                events_skipped += 1;
                k += sat_lines(n) + n * per_sat;
            }
            _ => return Err(at.err(format!("unknown event flag {flag}"))),
        }
    }
    Ok(ObsFile {
        galileo_types: h.types.clone(),
        types: h.types,
        approx_position: h.approx,
        system: h.system,
        epochs,
        events_skipped,
        other_systems_skipped: 0,
    })
}

/// Lines taken by the satellite list of an epoch with `n` satellites (12 per line).
fn sat_lines(n: usize) -> usize {
    n.div_ceil(12).max(1)
}

/// One epoch with `n` satellites starting at line index `k`; returns the next index.
fn epoch_record(
    lines: &[&str],
    k: usize,
    file: &str,
    h: &Header,
    per_sat: usize,
    n: usize,
) -> Result<(ObsEpoch, usize), FormatError> {
    let at = At { file, line: k + 1 };
    let t = date(cols(lines[k], 0, 26), at)?.to_gps_seconds();
    let mut ids = Vec::with_capacity(n);
    for j in 0..n {
        let li = k + j / 12;
        let line = lines
            .get(li)
            .ok_or_else(|| at.err("satellite list cut short"))?;
        let s = cols(line, 32 + 3 * (j % 12), 35 + 3 * (j % 12));
        ids.push(sat_id(s, h.system, At { file, line: li + 1 })?);
    }
    let mut next = k + sat_lines(n);
    let mut sats = Vec::with_capacity(n);
    for id in ids {
        let mut values = Vec::with_capacity(h.n_types);
        for t_i in 0..h.n_types {
            let li = next + t_i / 5;
            let line = lines
                .get(li)
                .ok_or_else(|| at.err("observations cut short"))?;
            values.push(obs_value(
                cols(line, 16 * (t_i % 5), 16 * (t_i % 5) + 16),
                At { file, line: li + 1 },
            )?);
        }
        next += per_sat;
        sats.push((id, values));
    }
    Ok((ObsEpoch { t, flag: 0, sats }, next))
}

/// A 16-column field: F14.3, LLI (I1), SSI (I1); blank value is `None`.
pub(crate) fn obs_value(field: &str, at: At<'_>) -> Result<Option<ObsValue>, FormatError> {
    let Some(value) = real(cols(field, 0, 14), at)? else {
        return Ok(None);
    };
    let digit = |s: &str| s.trim().parse::<u8>().ok();
    Ok(Some(ObsValue {
        value,
        lli: digit(cols(field, 14, 15)),
        ssi: digit(cols(field, 15, 16)),
    }))
}
