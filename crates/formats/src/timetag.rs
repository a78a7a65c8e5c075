//! RTKLIB time-tag files (`.tag`, written beside a logged stream by RTKLIB's `str2str`
//! and demo5 loggers): the GPS time of a logger's start and the logger's millisecond
//! ticks, which put an IMU CSV's own counter on GPS time.
//!
//! # Layout (little-endian)
//! A 60-byte text header (`TIMETAG RTKLIB demo5…`, NUL padded), u32 tick at start (the
//! logger's system tick, not used), u32 GPST seconds since 1970-01-01 (GPS time counted
//! from the Unix epoch, not UTC: GPS seconds = it − 315,964,800), f64 fraction of a
//! second; then 8-byte records, u32 tick in ms since the start and u32 byte offset in
//! the logged stream.
//!
//! # Mapping a CSV counter to GPS time
//! The CSV's own counter and the tag's ticks run on clocks that differ slightly (on the
//! drive of tests/data/drive, 548.590 s of counter against 548.731 s of ticks), so the
//! first row is put at the tag's start and the last at start + the last record's tick,
//! linearly between: `t = start + (c − c_first)·span_tag/(c_last − c_first) + offset`,
//! where `offset` is the logger's latency correction (−0.125 s on that drive).

use std::path::Path;

use crate::error::{FormatError, missing, read_bytes};

/// Bytes of the text header.
const HEADER_LEN: usize = 60;
/// Bytes before the first record: header, u32 tick, u32 seconds, f64 fraction.
const FIRST_RECORD: usize = HEADER_LEN + 4 + 4 + 8;
/// Bytes of one record.
const RECORD_LEN: usize = 8;
/// Seconds from 1970-01-01 to the GPS epoch 1980-01-06.
pub const GPS_EPOCH_FROM_1970_S: f64 = 315_964_800.0;

/// A time-tag file.
#[derive(Debug, Clone, PartialEq)]
pub struct TimeTag {
    /// The header text, up to its first NUL.
    pub header: String,
    /// GPS seconds since 1980-01-06 of the logger's start.
    pub start_gps_s: f64,
    /// Each record's tick, ms since the start.
    pub ticks_ms: Vec<u32>,
}

impl TimeTag {
    /// Seconds from the start to the last record.
    pub fn span_s(&self) -> f64 {
        self.ticks_ms.last().map_or(0.0, |&t| f64::from(t) / 1000.0)
    }

    /// The linear map from a CSV counter (s) to GPS time whose first and last rows are
    /// `first_s` and `last_s`, with the latency `offset_s` added.
    pub fn mapping(&self, first_s: f64, last_s: f64, offset_s: f64) -> TagMapping {
        let counter_span = last_s - first_s;
        let scale = if counter_span > 0.0 {
            self.span_s() / counter_span
        } else {
            1.0
        };
        TagMapping {
            start_gps_s: self.start_gps_s,
            first_s,
            scale,
            offset_s,
        }
    }
}

/// A CSV counter → GPS time map (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TagMapping {
    /// GPS seconds of the first row (before the offset).
    pub start_gps_s: f64,
    /// The first row's counter, s.
    pub first_s: f64,
    /// Tag seconds per counter second.
    pub scale: f64,
    /// Added after the map (latency correction), s.
    pub offset_s: f64,
}

impl TagMapping {
    /// GPS seconds of counter value `counter_s`.
    pub fn gps(&self, counter_s: f64) -> f64 {
        self.start_gps_s + (counter_s - self.first_s) * self.scale + self.offset_s
    }
}

/// Reads a `.tag` file.
pub fn read_tag(path: &Path) -> Result<TimeTag, FormatError> {
    parse_tag(&read_bytes(path)?, &path.display().to_string())
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// Parses the bytes of a `.tag` file named `file`.
pub fn parse_tag(b: &[u8], file: &str) -> Result<TimeTag, FormatError> {
    let corrupt = |offset: usize, msg: String| FormatError::Corrupt {
        file: file.to_string(),
        offset,
        msg,
    };
    if b.len() < FIRST_RECORD {
        return Err(missing(
            file,
            format!("{} bytes, shorter than the header", b.len()),
        ));
    }
    let text_end = b[..HEADER_LEN]
        .iter()
        .position(|&c| c == 0)
        .unwrap_or(HEADER_LEN);
    let header = String::from_utf8_lossy(&b[..text_end]).into_owned();
    if !header.starts_with("TIMETAG") {
        return Err(corrupt(0, format!("header '{header}' is not TIMETAG")));
    }
    let sec_1970 = u32_at(b, HEADER_LEN + 4);
    let frac = f64::from_le_bytes(b[HEADER_LEN + 8..FIRST_RECORD].try_into().expect("8 bytes"));
    if !(0.0..1.0).contains(&frac) {
        return Err(corrupt(
            HEADER_LEN + 8,
            format!("fraction {frac} not in [0, 1)"),
        ));
    }
    let body = &b[FIRST_RECORD..];
    if body.len() % RECORD_LEN != 0 {
        return Err(corrupt(
            FIRST_RECORD + body.len() / RECORD_LEN * RECORD_LEN,
            format!("a partial record of {} bytes", body.len() % RECORD_LEN),
        ));
    }
    let mut ticks_ms = Vec::with_capacity(body.len() / RECORD_LEN);
    for (k, rec) in body.chunks_exact(RECORD_LEN).enumerate() {
        let tick = u32_at(rec, 0);
        if ticks_ms.last().is_some_and(|&prev| tick < prev) {
            return Err(corrupt(
                FIRST_RECORD + k * RECORD_LEN,
                format!("tick {tick} ms goes back (record {})", k + 1),
            ));
        }
        ticks_ms.push(tick);
    }
    if ticks_ms.is_empty() {
        return Err(missing(file, "no records"));
    }
    Ok(TimeTag {
        header,
        start_gps_s: f64::from(sec_1970) - GPS_EPOCH_FROM_1970_S + frac,
        ticks_ms,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tag(records: &[(u32, u32)]) -> Vec<u8> {
        let mut b = b"TIMETAG RTKLIB demo5".to_vec();
        b.resize(HEADER_LEN, 0);
        b.extend(7u32.to_le_bytes());
        b.extend(1_000_000_000u32.to_le_bytes());
        b.extend(0.25f64.to_le_bytes());
        for (t, o) in records {
            b.extend(t.to_le_bytes());
            b.extend(o.to_le_bytes());
        }
        b
    }

    #[test]
    fn the_start_is_gps_seconds_and_the_map_is_linear() {
        let t = parse_tag(&tag(&[(10, 0), (2000, 50)]), "x.tag").unwrap();
        assert_eq!(t.start_gps_s, 1_000_000_000.0 - 315_964_800.0 + 0.25);
        assert_eq!(t.span_s(), 2.0);
        let m = t.mapping(100.0, 101.0, -0.125);
        assert_eq!(m.gps(100.0), t.start_gps_s - 0.125);
        assert_eq!(m.gps(101.0), t.start_gps_s + 2.0 - 0.125);
    }

    #[test]
    fn a_partial_record_or_a_tick_going_back_names_its_byte() {
        let mut b = tag(&[(10, 0)]);
        b.push(1);
        let e = parse_tag(&b, "x.tag").unwrap_err().to_string();
        assert_eq!(e, "x.tag: byte 84: a partial record of 1 bytes");
        let e = parse_tag(&tag(&[(10, 0), (5, 1)]), "x.tag")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("x.tag: byte 84: tick 5 ms goes back"), "{e}");
    }
}
