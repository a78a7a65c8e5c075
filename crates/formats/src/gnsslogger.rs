//! Android GnssLogger logs (`Raw` records) + a RINEX navigation file → domain epochs:
//! pseudoranges from the Android clock fields, satellite positions and clocks from the
//! broadcast ephemerides, Klobuchar at an a-priori position. GPS L1 C/A only.
//!
//! # Pseudorange (as Google's `ProcessGnssMeas.m`, Android `GnssClock` docs)
//! `week_ns = ⌊−FullBiasNanos / 604800e9⌋·604800e9`,
//! `t_Rx = (TimeNanos − FullBiasNanos − week_ns − TimeOffsetNanos − BiasNanos)·1e-9`
//! (seconds of week), `t_Tx = ReceivedSvTimeNanos·1e-9` (GPS time of week when State
//! has TOW decoded), `PR = (t_Rx − t_Tx)·c` with the week crossover wrapped;
//! σ = `ReceivedSvTimeUncertaintyNanos`·1e-9·c. Integer nanoseconds are kept in `i64`
//! until reduced to the week (an f64 of 1e18 ns would lose 256 ns, 77 m).
//!
//! # FullBiasNanos: per epoch, not the first
//! `ProcessGnssMeas.m` keeps the log's first FullBiasNanos. With duty cycling this log
//! re-estimates it 215 times and the receiver clock then drifts to tens of milliseconds
//! (thousands of km of common bias). We use each epoch's own FullBiasNanos (one value per
//! `TimeNanos` in these logs), so each epoch's receiver clock bias stays small and the
//! epoch time is the phone's GPS time. Satellite positions are computed at the satellite
//! time t_Tx (from ReceivedSvTimeNanos), which does not depend on that choice.
//!
//! Records kept: FullBiasNanos ≠ 0, ConstellationType 1 (GPS), State bits 0 (code lock)
//! and 3 (TOW decoded) set; one record per satellite per epoch (the first).

use std::collections::HashMap;
use std::path::Path;

use navguard_core::epoch::{Constellation, Epoch, GnssRawBlock, SatId, SatObs};
use navguard_core::geo::Lla;

use crate::ephemeris::{C_LIGHT, ClockFor};
use crate::error::{At, FormatError, missing, read_to_string};
use crate::geometry::Station;
use crate::gpstime::wrap_half_week;
use crate::rinex::nav::NavFile;

const WEEK_NS: i64 = 604_800_000_000_000;

/// How to convert a GnssLogger log.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GnssLoggerParams {
    /// The true position, put in every epoch's `truth` (evaluation only).
    pub truth: Option<Lla>,
    /// The a-priori position for Klobuchar and look angles; default: the log's first
    /// `Fix` line.
    pub apriori: Option<Lla>,
}

/// One kept `Raw` record, in the units we use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawRecord {
    /// 1-based line number in the log.
    pub line: usize,
    /// The receiver time tag of the epoch (TimeNanos).
    pub time_nanos: i64,
    /// The satellite.
    pub sat: SatId,
    /// Receive time, GPS s since 1980-01-06 (this record's FullBiasNanos).
    pub t_rx: f64,
    /// Pseudorange, m.
    pub pr: f64,
    /// Pseudorange 1-σ, m.
    pub sigma: f64,
    /// C/N0, dB-Hz.
    pub cn0: f64,
}

/// The kept records of a log and its first `Fix` position.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GnssLoggerLog {
    /// Kept `Raw` records, file order.
    pub records: Vec<RawRecord>,
    /// `Raw` records dropped by the keep rules.
    pub dropped: usize,
    /// The first `Fix` line's latitude, longitude, altitude.
    pub first_fix: Option<Lla>,
}

/// Reads a GnssLogger log's `Raw` and first `Fix` records.
pub fn read_log(path: &Path) -> Result<GnssLoggerLog, FormatError> {
    parse_log(&read_to_string(path)?, &path.display().to_string())
}

/// Parses the text of a GnssLogger log named `file`.
pub fn parse_log(text: &str, file: &str) -> Result<GnssLoggerLog, FormatError> {
    let mut cols: Option<HashMap<String, usize>> = None;
    let mut log = GnssLoggerLog::default();
    for (k, line) in text.lines().enumerate() {
        let at = At { file, line: k + 1 };
        if let Some(h) = line.strip_prefix("# Raw,") {
            let names = std::iter::once("Raw").chain(h.split(','));
            cols = Some(
                names
                    .enumerate()
                    .map(|(i, n)| (n.trim().to_string(), i))
                    .collect(),
            );
        } else if let Some(fix) = line.strip_prefix("Fix,") {
            if log.first_fix.is_none() {
                log.first_fix = Some(parse_fix(fix, at)?);
            }
        } else if line.starts_with("Raw,") {
            let cols = cols
                .as_ref()
                .ok_or_else(|| at.err("Raw record before the '# Raw,' header"))?;
            match parse_raw(line, cols, at)? {
                Some(r) => log.records.push(r),
                None => log.dropped += 1,
            }
        }
    }
    if log.records.is_empty() {
        return Err(missing(file, "no usable Raw records"));
    }
    Ok(log)
}

fn parse_fix(fix: &str, at: At<'_>) -> Result<Lla, FormatError> {
    let f: Vec<&str> = fix.split(',').collect();
    let num = |i: usize| {
        f.get(i)
            .and_then(|s| s.trim().parse::<f64>().ok())
            .ok_or_else(|| at.err("bad Fix line"))
    };
    Ok(Lla {
        lat: num(1)?.to_radians(),
        lon: num(2)?.to_radians(),
        h: num(3)?,
    })
}

/// One `Raw` line; `None` when the keep rules drop it.
fn parse_raw(
    line: &str,
    cols: &HashMap<String, usize>,
    at: At<'_>,
) -> Result<Option<RawRecord>, FormatError> {
    let f: Vec<&str> = line.split(',').collect();
    let field = |name: &str| -> Result<&str, FormatError> {
        let i = *cols
            .get(name)
            .ok_or_else(|| at.err(format!("no column {name} in the header")))?;
        Ok(f.get(i).map_or("", |s| s.trim()))
    };
    let int = |name: &str| -> Result<i64, FormatError> {
        let s = field(name)?;
        s.parse::<i64>()
            .map_err(|_| at.err(format!("{name}: not an integer: '{s}'")))
    };
    let real = |name: &str| -> Result<f64, FormatError> {
        let s = field(name)?;
        if s.is_empty() {
            Ok(0.0)
        } else {
            s.parse::<f64>()
                .map_err(|_| at.err(format!("{name}: not a number: '{s}'")))
        }
    };
    let full_bias = int("FullBiasNanos")?;
    let state = int("State")?;
    if full_bias == 0 || int("ConstellationType")? != 1 || state & 0b1001 != 0b1001 {
        return Ok(None);
    }
    let time_nanos = int("TimeNanos")?;
    let week_ns = (-full_bias).div_euclid(WEEK_NS) * WEEK_NS;
    let rx_ns_of_week =
        (time_nanos - full_bias - week_ns) as f64 - real("TimeOffsetNanos")? - real("BiasNanos")?;
    let t_rx_week = rx_ns_of_week * 1e-9;
    let t_tx = int("ReceivedSvTimeNanos")? as f64 * 1e-9;
    let pr = wrap_half_week(t_rx_week - t_tx) * C_LIGHT;
    let prn = u8::try_from(int("Svid")?).map_err(|_| at.err("Svid out of range"))?;
    Ok(Some(RawRecord {
        line: at.line,
        time_nanos,
        sat: SatId {
            constellation: Constellation::Gps,
            prn,
        },
        t_rx: (week_ns / 1_000_000_000) as f64 + t_rx_week,
        pr,
        sigma: real("ReceivedSvTimeUncertaintyNanos")? * 1e-9 * C_LIGHT,
        cn0: real("Cn0DbHz")?,
    }))
}

/// Converts a parsed log with its navigation file; returns the epochs and how many
/// kept records had no healthy ephemeris within ±2 h.
pub fn convert(
    log: &GnssLoggerLog,
    nav: &NavFile,
    file: &str,
    p: GnssLoggerParams,
) -> Result<(Vec<Epoch>, usize), FormatError> {
    let apriori = p.apriori.or(log.first_fix).map(Station::from_lla);
    let (Some(station), Some(klob)) = (apriori, nav.klobuchar) else {
        return Err(missing(
            file,
            "Klobuchar needs an a-priori position (a Fix line) and the nav header's ION ALPHA/BETA",
        ));
    };
    let truth = p.truth.map(|t| Station::from_lla(t).as_truth());
    let mut epochs: Vec<Epoch> = Vec::new();
    let mut no_eph = 0;
    let mut last_tag = None;
    for r in &log.records {
        if last_tag != Some(r.time_nanos) {
            last_tag = Some(r.time_nanos);
            epochs.push(Epoch {
                t: r.t_rx,
                gnss_raw: Some(GnssRawBlock {
                    sats: vec![],
                    truth,
                }),
                ..Epoch::default()
            });
        }
        let block = epochs
            .last_mut()
            .and_then(|e| e.gnss_raw.as_mut())
            .expect("pushed above");
        if block.sats.iter().any(|s| s.id == r.sat) {
            continue;
        }
        let Some(eph) = nav.ephemerides.select(r.sat, r.t_rx) else {
            no_eph += 1;
            continue;
        };
        let s = eph.at_reception(r.t_rx, r.pr, ClockFor::L1);
        let (el, az) = station.look_angles(s.pos);
        let iono = klob.delay_m(station.lla.lat, station.lla.lon, el, az, s.t_tx);
        block.sats.push(SatObs {
            id: r.sat,
            pr: r.pr,
            pos: s.pos,
            clk: s.clk_m,
            iono: Some(iono),
            tropo: None,
            sigma: Some(r.sigma),
            cn0: Some(r.cn0),
            el: Some(el),
            az: Some(az),
        });
    }
    epochs.retain(|e| e.gnss_raw.as_ref().is_some_and(|b| !b.sats.is_empty()));
    Ok((epochs, no_eph))
}
