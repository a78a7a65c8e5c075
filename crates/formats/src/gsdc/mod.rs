//! The Google Smartphone Decimeter Challenge CSVs → domain epochs. These files already
//! hold each signal's satellite position at transmit time, satellite clock, inter-signal
//! bias and atmospheric delays, so no ephemeris is needed: the corrected pseudorange
//! is `raw PR − ISRB + sat clock − iono − tropo`, which we store as
//! `pr = raw PR − ISRB`, `clk = sat clock`, `iono`, `tropo`.
//!
//! One measurement per satellite per epoch: [`Band::L1`] keeps GPS L1, GLONASS G1,
//! Galileo E1 (and QZSS J1, BeiDou B1) and drops L5/E5a; [`Band::L5`] the reverse.
//! - [`y2021`]: the 2021 `*_derived.csv` with the competition hosts' quirks.
//! - [`y2023`]: the 2023 `device_gnss.csv`.

pub mod y2021;
pub mod y2023;

use std::collections::BTreeMap;
use std::path::Path;

use navguard_core::epoch::{Constellation, Epoch, GnssRawBlock, SatId, SatObs};

use crate::error::{FormatError, read_to_string};

/// Which frequency band's signal to keep for each satellite.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Band {
    /// L1 / E1 / G1 / J1 / B1 (every constellation has one).
    #[default]
    L1,
    /// L5 / E5a / J5 / B2a (GPS, Galileo, QZSS, BeiDou only).
    L5,
}

impl Band {
    /// The band of a GSDC `SignalType` (`GPS_L1_CA`, `GAL_E5A_Q`, `GLO_G1`…), if known.
    pub fn of_signal(signal: &str) -> Option<Band> {
        let s = signal.to_ascii_uppercase();
        let has = |codes: &[&str]| codes.iter().any(|c| s.split('_').any(|p| p == *c));
        if has(&["L1", "E1", "G1", "J1", "B1", "B1I", "B1C"]) {
            Some(Band::L1)
        } else if has(&["L5", "E5A", "J5", "B2A"]) {
            Some(Band::L5)
        } else {
            None
        }
    }
}

/// Android's `ConstellationType` code → constellation (GnssStatus constants).
pub fn android_constellation(code: i64) -> Option<Constellation> {
    match code {
        1 => Some(Constellation::Gps),
        2 => Some(Constellation::Sbas),
        3 => Some(Constellation::Glonass),
        4 => Some(Constellation::Qzss),
        5 => Some(Constellation::Beidou),
        6 => Some(Constellation::Galileo),
        7 => Some(Constellation::Navic),
        _ => None,
    }
}

/// A satellite id from Android's constellation code and Svid (`None` out of 1–99,
/// e.g. a GLONASS frequency-channel Svid above 99).
pub fn android_sat(code: i64, svid: i64) -> Option<SatId> {
    let constellation = android_constellation(code)?;
    let prn = u8::try_from(svid).ok().filter(|p| (1..=99).contains(p))?;
    Some(SatId { constellation, prn })
}

/// A truth file: time key (ms) → `[lat rad, lon rad, h m]`.
pub type Truths = BTreeMap<i64, [f64; 3]>;

/// A CSV row: its 1-based line number and fields.
pub(crate) type Row = (usize, Vec<String>);

/// Reads a CSV with headers into its header names and rows.
pub(crate) fn read_csv(path: &Path) -> Result<(Vec<String>, Vec<Row>), FormatError> {
    let file = path.display().to_string();
    let text = read_to_string(path)?;
    let mut rdr = csv::ReaderBuilder::new()
        .flexible(true)
        .from_reader(text.as_bytes());
    let err = |line: usize, e: csv::Error| FormatError::Malformed {
        file: file.clone(),
        line,
        msg: e.to_string(),
    };
    let headers: Vec<String> = rdr
        .headers()
        .map_err(|e| err(1, e))?
        .iter()
        .map(|s| s.trim().to_string())
        .collect();
    let mut rows = Vec::new();
    for rec in rdr.records() {
        let rec = rec.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line() as usize);
            err(line, e)
        })?;
        let line = rec.position().map_or(0, |p| p.line() as usize);
        rows.push((line, rec.iter().map(str::to_string).collect()));
    }
    Ok((headers, rows))
}

/// Column lookup by header name for one CSV.
pub(crate) struct Columns<'a> {
    pub(crate) file: &'a str,
    pub(crate) headers: &'a [String],
}

impl Columns<'_> {
    /// The index of column `name`.
    pub(crate) fn idx(&self, name: &str) -> Result<usize, FormatError> {
        self.headers
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| crate::error::missing(self.file, format!("no column {name}")))
    }

    /// Column `i` of `row` as a number; blank is `None`.
    pub(crate) fn num(&self, row: &Row, i: usize) -> Result<Option<f64>, FormatError> {
        let s = row.1.get(i).map_or("", |s| s.trim());
        if s.is_empty() {
            return Ok(None);
        }
        s.parse::<f64>()
            .map(Some)
            .map_err(|_| FormatError::Malformed {
                file: self.file.to_string(),
                line: row.0,
                msg: format!("column {}: not a number: '{s}'", self.headers[i]),
            })
    }

    /// Column `i` of `row` as a required number.
    pub(crate) fn req(&self, row: &Row, i: usize) -> Result<f64, FormatError> {
        self.num(row, i)?.ok_or_else(|| FormatError::Malformed {
            file: self.file.to_string(),
            line: row.0,
            msg: format!("column {} is blank", self.headers[i]),
        })
    }
}

/// The columns every GSDC file has for one satellite's measurement (the files name them
/// differently).
pub(crate) struct SatColumns {
    /// Raw pseudorange, m.
    pub(crate) raw: usize,
    /// Its 1-σ, m.
    pub(crate) unc: usize,
    /// Inter-signal range bias, m (subtracted from the raw pseudorange).
    pub(crate) isrb: usize,
    /// Satellite clock bias, m.
    pub(crate) clk: usize,
    /// Ionospheric delay, m.
    pub(crate) iono: usize,
    /// Tropospheric delay, m.
    pub(crate) tropo: usize,
    /// Satellite ECEF position at transmit time, m.
    pub(crate) pos: [usize; 3],
}

impl SatColumns {
    /// Satellite `id`'s measurement on `row` (C/N0, elevation, azimuth left absent).
    pub(crate) fn obs(&self, c: &Columns, row: &Row, id: SatId) -> Result<SatObs, FormatError> {
        Ok(SatObs {
            id,
            pr: c.req(row, self.raw)? - c.num(row, self.isrb)?.unwrap_or(0.0),
            pos: [
                c.req(row, self.pos[0])?,
                c.req(row, self.pos[1])?,
                c.req(row, self.pos[2])?,
            ],
            clk: c.req(row, self.clk)?,
            iono: c.num(row, self.iono)?,
            tropo: c.num(row, self.tropo)?,
            sigma: c.num(row, self.unc)?,
            cn0: None,
            el: None,
            az: None,
        })
    }
}

/// Adds `sat` to the epoch keyed `key`, the last of `epochs` (rows of one epoch are
/// consecutive); a new key starts an epoch at `t` with `truth`. A satellite's first row
/// in an epoch is kept, later ones (other signals of its band) are dropped.
pub(crate) fn push_sat(
    epochs: &mut Vec<(i64, Epoch)>,
    key: i64,
    t: f64,
    truth: Option<[f64; 3]>,
    sat: SatObs,
) {
    if epochs.last().is_none_or(|(k, _)| *k != key) {
        let block = GnssRawBlock {
            sats: Vec::new(),
            truth,
        };
        epochs.push((
            key,
            Epoch {
                t,
                gnss_raw: Some(block),
                ..Epoch::default()
            },
        ));
    }
    if let Some(block) = epochs.last_mut().and_then(|(_, e)| e.gnss_raw.as_mut()) {
        if block.sats.iter().all(|s| s.id != sat.id) {
            block.sats.push(sat);
        }
    }
}

/// Reads a ground-truth CSV: the column named `names[0]` (a time key in ms) → latitude,
/// longitude (columns `names[1]`, `names[2]`, degrees, stored in radians) and height
/// (`names[3]`, m) minus `height_error_m`.
pub(crate) fn read_truths(
    path: &Path,
    names: [&str; 4],
    height_error_m: f64,
) -> Result<Truths, FormatError> {
    let file = path.display().to_string();
    let (headers, rows) = read_csv(path)?;
    let c = Columns {
        file: &file,
        headers: &headers,
    };
    let [t, lat, lon, h] = [
        c.idx(names[0])?,
        c.idx(names[1])?,
        c.idx(names[2])?,
        c.idx(names[3])?,
    ];
    let mut out = Truths::new();
    for row in &rows {
        let key = c.req(row, t)? as i64;
        let truth = [
            c.req(row, lat)?.to_radians(),
            c.req(row, lon)?.to_radians(),
            c.req(row, h)? - height_error_m,
        ];
        out.insert(key, truth);
    }
    Ok(out)
}
