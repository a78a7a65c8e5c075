//! NMEA 0183 logs → [`GnssFix`]es: GGA (position, fix quality, satellites), RMC (date,
//! speed and course), VTG (speed and course), GST (position σ); other sentences are
//! counted and skipped. Sentences are read by the `nmea` crate (AeroRust).
//!
//! # Rules
//! - Every non-blank line must be a sentence `$…*hh` whose checksum (XOR of the bytes
//!   between `$` and `*`) matches, checked here for every sentence type (the crate
//!   refuses an unknown type before it looks at the checksum, so it cannot tell "not
//!   ours" from "corrupt"); GGA, RMC, VTG and GST must then parse. A failure is an error
//!   naming the line, or with [`NmeaParams::skip_bad`] counted in [`NmeaCounts::bad`]
//!   and skipped.
//! - Sentences of one UTC time make one fix; VTG (which has no time) joins the fix of
//!   the sentence before it. A fix needs a GGA with a position, an altitude, a geoid
//!   separation and a fix quality of 1–5; others are counted in
//!   [`NmeaCounts::no_fix`] and dropped.
//! - Height: ellipsoidal = GGA altitude (above the geoid) + geoid separation.
//! - Quality: GGA 4 → RTK fixed, 5 → float, 2 → DGPS, 1 and 3 → single.
//! - Velocity (horizontal, up 0): RMC speed (knots × 1852/3600) and true course, else
//!   VTG's; east = v·sin(course), north = v·cos(course). No velocity when the RMC
//!   says the fix is invalid, or when the course is blank and the speed not zero.
//! - σ: GST σ latitude, σ longitude, σ altitude → `pos_sigma` = (σ lon, σ lat, σ alt).
//! - Time: the RMC date (carried to fixes without one, and to the ones before the
//!   first RMC; a time of day that goes back starts the next day) and the UTC time of
//!   day, on GPS time with `leap_s` = GPST − UTC (18 s since 2017).
//!
//! The crate gives altitude, separation, speed, course and σ as f32: 0.1 mm at a
//! height of 1,600 m, far below any GNSS error; latitude and longitude are f64.

use std::path::Path;

use chrono::{Datelike, NaiveDate, Timelike};
use navguard_core::geo::Lla;
use nmea::ParseResult;
use nmea::sentences::{FixType, GgaData, GstData, RmcData, VtgData, rmc::RmcStatusOfFix};

use crate::error::{At, FormatError, missing, read_to_string};
use crate::fix::{GnssFix, Quality};
use crate::gpstime::Calendar;

/// m/s per knot.
const KNOT_MPS: f64 = 1852.0 / 3600.0;

/// How to read an NMEA log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NmeaParams {
    /// GPST − UTC, s.
    pub leap_s: f64,
    /// Count and skip bad sentences instead of stopping at the first.
    pub skip_bad: bool,
}

impl Default for NmeaParams {
    fn default() -> Self {
        NmeaParams {
            leap_s: 18.0,
            skip_bad: false,
        }
    }
}

/// What the reader saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NmeaCounts {
    /// GGA sentences read.
    pub gga: usize,
    /// RMC sentences read.
    pub rmc: usize,
    /// VTG sentences read.
    pub vtg: usize,
    /// GST sentences read.
    pub gst: usize,
    /// Sentences of other types, skipped.
    pub other: usize,
    /// Bad lines skipped (with `skip_bad`).
    pub bad: usize,
    /// Time groups dropped for want of a usable GGA.
    pub no_fix: usize,
}

/// The fixes of a log and the counts.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct NmeaLog {
    /// One fix per UTC time with a usable GGA, file order.
    pub fixes: Vec<GnssFix>,
    /// What was read, skipped and dropped.
    pub counts: NmeaCounts,
}

/// The sentences of one UTC time.
#[derive(Debug, Default)]
struct Group {
    line: usize,
    /// Time of day, ms.
    tod_ms: Option<u32>,
    gga: Option<GgaData>,
    rmc: Option<RmcData>,
    vtg: Option<VtgData>,
    gst: Option<GstData>,
}

/// Reads an NMEA log.
pub fn read_nmea(path: &Path, p: NmeaParams) -> Result<NmeaLog, FormatError> {
    parse_nmea(&read_to_string(path)?, &path.display().to_string(), p)
}

/// Checks a sentence's framing and checksum.
fn checksum(line: &str) -> Result<(), String> {
    let body = line.strip_prefix('$').ok_or("a sentence starts with '$'")?;
    let (data, hex) = body.rsplit_once('*').ok_or("no '*' checksum")?;
    let found = u8::from_str_radix(hex, 16).map_err(|_| format!("checksum '{hex}' is not hex"))?;
    let computed = data.bytes().fold(0u8, |c, b| c ^ b);
    if found != computed {
        return Err(format!(
            "bad checksum: {found:02X}, computed {computed:02X}"
        ));
    }
    Ok(())
}

/// A time of day in ms.
fn tod_ms(t: chrono::NaiveTime) -> u32 {
    t.num_seconds_from_midnight() * 1000 + (t.nanosecond() + 500_000) / 1_000_000
}

/// Parses the text of an NMEA log named `file`.
pub fn parse_nmea(text: &str, file: &str, p: NmeaParams) -> Result<NmeaLog, FormatError> {
    let mut counts = NmeaCounts::default();
    let mut groups: Vec<Group> = Vec::new();
    for (k, raw) in text.lines().enumerate() {
        let at = At { file, line: k + 1 };
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        match sentence(line, &mut counts) {
            Ok(Some(s)) => add(&mut groups, s, at.line),
            Ok(None) => {}
            Err(_) if p.skip_bad => counts.bad += 1,
            Err(msg) => return Err(at.err(msg)),
        }
    }
    let fixes = fixes(groups, p.leap_s, &mut counts);
    if fixes.is_empty() {
        return Err(missing(file, "no GGA fix with a position"));
    }
    Ok(NmeaLog { fixes, counts })
}

/// One line → one of our four sentences, `None` for another type, or why it is bad.
fn sentence(line: &str, counts: &mut NmeaCounts) -> Result<Option<ParseResult>, String> {
    checksum(line)?;
    let kind = line.get(3..6).unwrap_or("");
    if !["GGA", "RMC", "VTG", "GST"].contains(&kind) {
        counts.other += 1;
        return Ok(None);
    }
    let s = nmea::parse_str(line).map_err(|e| format!("{kind}: {e}"))?;
    match &s {
        ParseResult::GGA(_) => counts.gga += 1,
        ParseResult::RMC(_) => counts.rmc += 1,
        ParseResult::VTG(_) => counts.vtg += 1,
        ParseResult::GST(_) => counts.gst += 1,
        _ => {}
    }
    Ok(Some(s))
}

/// Puts a sentence into its time group, opening a new group when its time differs.
fn add(groups: &mut Vec<Group>, s: ParseResult, line: usize) {
    let tod = match &s {
        ParseResult::GGA(g) => g.fix_time,
        ParseResult::RMC(r) => r.fix_time,
        ParseResult::GST(g) => g.time,
        _ => None,
    }
    .map(tod_ms);
    let same = |g: &Group| tod.is_none() || g.tod_ms.is_none() || g.tod_ms == tod;
    if !groups.last().is_some_and(same) {
        groups.push(Group {
            line,
            ..Group::default()
        });
    }
    let g = groups.last_mut().expect("pushed above");
    g.tod_ms = g.tod_ms.or(tod);
    match s {
        ParseResult::GGA(d) => g.gga = Some(d),
        ParseResult::RMC(d) => g.rmc = Some(d),
        ParseResult::VTG(d) => g.vtg = Some(d),
        ParseResult::GST(d) => g.gst = Some(d),
        _ => {}
    }
}

/// GGA's fix quality → quality (`None`: no usable fix).
fn quality(f: FixType) -> Option<Quality> {
    match f {
        FixType::Rtk => Some(Quality::Fixed),
        FixType::FloatRtk => Some(Quality::Float),
        FixType::DGps => Some(Quality::Dgps),
        FixType::Gps | FixType::Pps => Some(Quality::Single),
        _ => None,
    }
}

/// ENU velocity from a speed (knots) and a true course (°).
fn velocity(knots: Option<f32>, course: Option<f32>) -> Option<[f64; 3]> {
    let v = f64::from(knots?) * KNOT_MPS;
    match course {
        Some(c) => {
            let c = f64::from(c).to_radians();
            Some([v * c.sin(), v * c.cos(), 0.0])
        }
        None => (v == 0.0).then_some([0.0; 3]),
    }
}

fn group_velocity(g: &Group) -> Option<[f64; 3]> {
    match &g.rmc {
        Some(r) if r.status_of_fix == RmcStatusOfFix::Invalid => None,
        Some(r) if r.speed_over_ground.is_some() => velocity(r.speed_over_ground, r.true_course),
        _ => g
            .vtg
            .as_ref()
            .and_then(|v| velocity(v.speed_over_ground, v.true_course)),
    }
}

/// The groups with a usable GGA as fixes, dated (module docs).
fn fixes(groups: Vec<Group>, leap_s: f64, counts: &mut NmeaCounts) -> Vec<GnssFix> {
    let mut date: Option<NaiveDate> = groups
        .iter()
        .find_map(|g| g.rmc.as_ref().and_then(|r| r.fix_date));
    let mut prev_tod: Option<u32> = None;
    let mut out = Vec::new();
    for g in groups {
        let own = g.rmc.as_ref().and_then(|r| r.fix_date);
        if own.is_some() {
            date = own;
        } else if let (Some(t), Some(p)) = (g.tod_ms, prev_tod) {
            if t < p {
                date = date.and_then(|d| d.succ_opt());
            }
        }
        prev_tod = g.tod_ms.or(prev_tod);
        match fix_of(&g, date, leap_s) {
            Some(f) => out.push(f),
            None => counts.no_fix += 1,
        }
    }
    out
}

fn fix_of(g: &Group, date: Option<NaiveDate>, leap_s: f64) -> Option<GnssFix> {
    let gga = g.gga.as_ref()?;
    let quality = quality(gga.fix_type?)?;
    let (tod, date) = (g.tod_ms?, date?);
    let c = Calendar {
        year: i64::from(date.year()),
        month: date.month(),
        day: date.day(),
        hour: tod / 3_600_000,
        minute: tod / 60_000 % 60,
        second: f64::from(tod % 60_000) / 1000.0,
    };
    let h = f64::from(gga.altitude?) + f64::from(gga.geoid_separation?);
    let pos_sigma = g.gst.as_ref().and_then(|s| {
        Some([
            f64::from(s.long_sd?),
            f64::from(s.lat_sd?),
            f64::from(s.alt_sd?),
        ])
    });
    Some(GnssFix {
        line: g.line,
        t: c.utc_to_gps_seconds(leap_s),
        lla: Lla {
            lat: gga.latitude?.to_radians(),
            lon: gga.longitude?.to_radians(),
            h,
        },
        quality: Some(quality),
        ns: gga.fix_satellites,
        pos_sigma,
        vel: group_velocity(g),
        vel_sigma: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str =
        "$GNGGA,123519.00,4005.797608,N,10508.846898,W,4,21,0.6,1584.123,M,17.351,M,1.0,0000*72";

    #[test]
    fn a_bad_checksum_is_refused_with_its_line_or_skipped_and_counted() {
        let bad = GOOD.replace("*72", "*73");
        let text = format!("{GOOD}\n\n{bad}\n");
        let e = parse_nmea(&text, "b.nmea", NmeaParams::default()).unwrap_err();
        assert_eq!(e.to_string(), "b.nmea:3: bad checksum: 73, computed 72");
        let p = NmeaParams {
            skip_bad: true,
            ..NmeaParams::default()
        };
        // No RMC, so no date: the lone GGA cannot be put on GPS time.
        let e = parse_nmea(&text, "b.nmea", p).unwrap_err();
        assert!(e.to_string().contains("no GGA fix"), "{e}");
        let rmc = "$GNRMC,123519.00,A,4005.797608,N,10508.846898,W,0.0,,080725,,,R*63";
        let log = parse_nmea(&format!("{text}{rmc}\n"), "b.nmea", p).unwrap();
        assert_eq!(log.counts.bad, 1);
        assert_eq!(log.fixes.len(), 1);
    }

    #[test]
    fn a_sentence_that_does_not_parse_names_its_line() {
        let body = "GNGGA,1235xx.00,4005.797608,N,10508.846898,W,4,21,0.6,1584.123,M,17.351,M,,";
        let cs = body.bytes().fold(0u8, |c, b| c ^ b);
        let e = parse_nmea(
            &format!("${body}*{cs:02X}\n"),
            "m.nmea",
            NmeaParams::default(),
        );
        assert!(e.unwrap_err().to_string().starts_with("m.nmea:1: GGA"));
    }

    #[test]
    fn course_ninety_is_east_and_a_stationary_blank_course_is_zero() {
        let v = velocity(Some(10.0), Some(90.0)).unwrap();
        assert!((v[0] - 10.0 * KNOT_MPS).abs() < 1e-9 && v[1].abs() < 1e-9 && v[2] == 0.0);
        assert_eq!(velocity(Some(0.0), None), Some([0.0; 3]));
        assert_eq!(velocity(Some(3.0), None), None);
    }
}
