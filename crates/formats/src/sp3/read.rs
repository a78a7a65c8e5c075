//! SP3-c and SP3-d text (Hilla, "The Extended Standard Product 3 Orbit Format (SP3-c)",
//! 2010; Hilla, "SP3-d", 2016): the header's version, start, epoch count, interval,
//! satellites and time system, then `*` epoch lines each followed by one `P` record per
//! satellite. Columns below are 0-based byte offsets; the format's are 1-based.
//!
//! | line | columns (1-based) | read |
//! |---|---|---|
//! | `#c`/`#d` | 2 version, 3 `P`/`V`, 4–31 start, 33–39 epoch count | all |
//! | `##` | 25–38 epoch interval, s | interval |
//! | `+` | 4–6 satellite count (SP3-c: 5–6), 10–60 up to 17 ids of 3 characters | ids |
//! | `%c` (first) | 10–12 time system | must be `GPS` (or `ccc`, the SP3-c placeholder) |
//! | `*` | 4–31 `yyyy mm dd hh mm ss.ssssssss` | epoch, GPS time |
//! | `P` | 2–4 id, 5–18 / 19–32 / 33–46 x y z km, 47–60 clock µs | sample |
//!
//! `V` (velocity), `EP`/`EV` (correlation), `++`, `%f`, `%i` and `/*` lines are skipped;
//! `EOF` ends the file. A position component of 0.000000 marks the position absent and a
//! clock of 999999.999999 (or more) the clock absent (SP3-c §"P" record). A file may hold
//! fewer epochs than its header declares (an excerpt, a product cut short), never more.

use std::collections::BTreeMap;

use navguard_core::epoch::{Constellation, SatId};

use super::{Sample, Sp3File};
use crate::error::{At, FormatError, missing};
use crate::gpstime::Calendar;
use crate::rinex::cols;

/// Parses the text of an SP3-c or SP3-d file named `file`.
pub(crate) fn parse(text: &str, file: &str) -> Result<Sp3File, FormatError> {
    let lines: Vec<&str> = text.lines().collect();
    let (mut f, declared, mut k) = header(&lines, file)?;
    let index: BTreeMap<SatId, usize> = f.sats.iter().enumerate().map(|(i, s)| (*s, i)).collect();
    let mut current: Option<Vec<Sample>> = None;
    let mut columns: Vec<Vec<Sample>> = vec![Vec::new(); f.sats.len()];
    while k < lines.len() {
        let line = lines[k];
        let at = At { file, line: k + 1 };
        k += 1;
        if line.starts_with("EOF") {
            break;
        }
        if line.starts_with('*') {
            flush(&mut current, &mut columns);
            if f.epochs.len() == declared {
                return Err(at.err(format!(
                    "more epochs than the {declared} the header declares"
                )));
            }
            let t = epoch_time(cols(line, 3, 31), at)?;
            if f.epochs.last().is_some_and(|&last| t <= last) {
                return Err(at.err("epoch not after the one before it"));
            }
            f.epochs.push(t);
            current = Some(vec![Sample::default(); f.sats.len()]);
        } else if line.starts_with('P') {
            let samples = current
                .as_mut()
                .ok_or_else(|| at.err("P record before the first '*' epoch line"))?;
            let (sat, sample) = position_record(line, at)?;
            let i = *index
                .get(&sat)
                .ok_or_else(|| at.err(format!("{sat} is not in the header's satellite list")))?;
            samples[i] = sample;
        } else if !skipped(line) {
            return Err(at.err(format!(
                "unexpected line starting '{}' (expected '*', 'P', 'V', 'EP', 'EV' or 'EOF')",
                cols(line, 0, 2)
            )));
        }
    }
    flush(&mut current, &mut columns);
    if f.epochs.is_empty() {
        return Err(missing(file, "no '*' epoch line"));
    }
    f.samples = f.sats.iter().copied().zip(columns).collect();
    Ok(f)
}

/// Appends the finished epoch's samples to each satellite's column.
fn flush(current: &mut Option<Vec<Sample>>, columns: &mut [Vec<Sample>]) {
    if let Some(samples) = current.take() {
        for (col, s) in columns.iter_mut().zip(samples) {
            col.push(s);
        }
    }
}

/// Lines the reader steps over: velocities, correlations, blanks.
fn skipped(line: &str) -> bool {
    line.trim().is_empty()
        || line.starts_with('V')
        || line.starts_with("EP")
        || line.starts_with("EV")
}

/// The header up to the first `*` (or stray `P`) line: the file with no epochs yet, the
/// declared epoch count and the index of the first line after the header.
fn header(lines: &[&str], file: &str) -> Result<(Sp3File, usize, usize), FormatError> {
    let first = lines.first().copied().unwrap_or("");
    let at = At { file, line: 1 };
    let version = match cols(first, 0, 2) {
        "#c" => 'c',
        "#d" => 'd',
        _ => {
            return Err(
                at.err("not an SP3-c or SP3-d file (the first line must start '#c' or '#d')")
            );
        }
    };
    let start = epoch_time(cols(first, 3, 31), at)?;
    let declared = count(cols(first, 32, 39), at, "epoch count")?;
    let second = lines.get(1).copied().unwrap_or("");
    let at2 = At { file, line: 2 };
    if !second.starts_with("##") {
        return Err(at2.err("the second line must start '##'"));
    }
    let interval_s = number(cols(second, 24, 38), at2, "epoch interval")?;
    if interval_s <= 0.0 {
        return Err(at2.err("epoch interval must be positive"));
    }
    let mut sats = Vec::new();
    let mut expected: Option<usize> = None;
    let mut time_system: Option<(String, usize)> = None;
    let mut k = 2;
    while k < lines.len() && !lines[k].starts_with('*') && !lines[k].starts_with('P') {
        let (line, at) = (lines[k], At { file, line: k + 1 });
        if line.starts_with('+') && !line.starts_with("++") {
            if expected.is_none() {
                expected = Some(count(cols(line, 3, 6), at, "satellite count")?);
            }
            satellite_ids(line, &mut sats, at)?;
        } else if line.starts_with("%c") && time_system.is_none() {
            time_system = Some((cols(line, 9, 12).trim().to_string(), k + 1));
        }
        k += 1;
    }
    let expected = expected.ok_or_else(|| missing(file, "no '+' satellite list"))?;
    if sats.len() != expected {
        return Err(missing(
            file,
            format!(
                "the header lists {} satellites, not the {expected} it declares",
                sats.len()
            ),
        ));
    }
    if let Some((system, line)) = time_system {
        if system != "GPS" && system != "ccc" {
            let at = At { file, line };
            return Err(at.err(format!(
                "time system '{system}' is not read (only GPS time is)"
            )));
        }
    }
    let f = Sp3File {
        version,
        start,
        interval_s,
        sats,
        epochs: Vec::new(),
        samples: BTreeMap::new(),
    };
    Ok((f, declared, k))
}

/// The satellite ids of one `+` line (columns 10–60, 3 characters each; `  0` pads).
fn satellite_ids(line: &str, sats: &mut Vec<SatId>, at: At<'_>) -> Result<(), FormatError> {
    for j in 0..17 {
        let s = cols(line, 9 + 3 * j, 12 + 3 * j);
        if s.trim().is_empty() || s.trim() == "0" {
            continue;
        }
        sats.push(sat_id(s, at)?);
    }
    Ok(())
}

/// An SP3 satellite id: a letter (blank is GPS, as in SP3-a/b) and two digits.
fn sat_id(s: &str, at: At<'_>) -> Result<SatId, FormatError> {
    let letter = s.chars().next().unwrap_or(' ');
    let constellation = if letter == ' ' {
        Constellation::Gps
    } else {
        Constellation::from_letter(letter)
            .ok_or_else(|| at.err(format!("unknown constellation letter '{letter}'")))?
    };
    let prn = cols(s, 1, 3)
        .trim()
        .parse::<u8>()
        .ok()
        .filter(|p| (1..=99).contains(p))
        .ok_or_else(|| at.err(format!("bad satellite id '{s}'")))?;
    Ok(SatId { constellation, prn })
}

/// A `P` record: the satellite and its sample in metres and seconds.
fn position_record(line: &str, at: At<'_>) -> Result<(SatId, Sample), FormatError> {
    let sat = sat_id(cols(line, 1, 4), at)?;
    let mut km = [0.0; 3];
    for (j, v) in km.iter_mut().enumerate() {
        *v = number(cols(line, 4 + 14 * j, 18 + 14 * j), at, "coordinate")?;
    }
    let clk_us = number(cols(line, 46, 60), at, "clock")?;
    let pos = (!km.contains(&0.0)).then(|| km.map(|x| x * 1e3));
    let clk_s = (clk_us < 999_999.0).then_some(clk_us * 1e-6);
    Ok((sat, Sample { pos, clk_s }))
}

/// `yyyy mm dd hh mm ss.ssssssss` (GPS time) as GPS seconds.
fn epoch_time(s: &str, at: At<'_>) -> Result<f64, FormatError> {
    let f: Vec<&str> = s.split_whitespace().collect();
    let bad = || {
        at.err(format!(
            "expected a date 'yyyy mm dd hh mm ss', got '{}'",
            s.trim()
        ))
    };
    if f.len() != 6 {
        return Err(bad());
    }
    let u = |k: usize| f[k].parse::<u32>().map_err(|_| bad());
    let c = Calendar {
        year: f[0].parse::<i64>().map_err(|_| bad())?,
        month: u(1)?,
        day: u(2)?,
        hour: u(3)?,
        minute: u(4)?,
        second: f[5].parse::<f64>().map_err(|_| bad())?,
    };
    if !(1..=12).contains(&c.month) || !(1..=31).contains(&c.day) || c.hour > 23 || c.minute > 59 {
        return Err(bad());
    }
    Ok(c.to_gps_seconds())
}

/// A real field; blank or not a number is an error naming `what`.
fn number(s: &str, at: At<'_>, what: &str) -> Result<f64, FormatError> {
    let t = s.trim();
    t.parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| at.err(format!("{what}: not a number: '{t}'")))
}

/// A non-negative integer field.
fn count(s: &str, at: At<'_>, what: &str) -> Result<usize, FormatError> {
    let t = s.trim();
    t.parse::<usize>()
        .map_err(|_| at.err(format!("{what}: not a count: '{t}'")))
}

#[cfg(test)]
mod tests {
    use super::*;

    const IGS: &str = include_str!("../../../../tests/data/gnss/rtklib/igs15904_0000-0400.sp3");

    fn g(prn: u8) -> SatId {
        SatId {
            constellation: Constellation::Gps,
            prn,
        }
    }

    /// The excerpt with line `n` (1-based) replaced.
    fn with_line(n: usize, line: &str) -> String {
        let mut v: Vec<&str> = IGS.lines().collect();
        v[n - 1] = line;
        v.join("\n")
    }

    fn error_of(text: &str) -> String {
        parse(text, "x.sp3").unwrap_err().to_string()
    }

    #[test]
    fn the_igs_excerpt_reads_in_metres_and_seconds() {
        let f = parse(IGS, "igs.sp3").unwrap();
        assert_eq!((f.version, f.interval_s, f.sats.len()), ('c', 900.0, 32));
        // 2010-07-01 00:00 GPST = week 1590, 345 600 s (the `##` line).
        assert_eq!(f.start, 1590.0 * 604_800.0 + 345_600.0);
        assert_eq!(f.epochs.len(), 17);
        assert_eq!(f.epochs[16] - f.epochs[0], 4.0 * 3600.0);
        // PG02 -14889.160729  -5131.952946 -21416.801336    269.108429 at 00:00.
        let s = f.samples[&g(2)][0];
        let want = [-14_889_160.729, -5_131_952.946, -21_416_801.336];
        for (p, w) in s.pos.unwrap().iter().zip(want) {
            assert!((p - w).abs() < 1e-6, "{p} vs {w}");
        }
        assert!((s.clk_s.unwrap() - 269.108_429e-6).abs() < 1e-18);
        // PG01 has no clock (999999.999999) but a position.
        assert!(f.samples[&g(1)][0].clk_s.is_none());
        assert!(f.samples[&g(1)][0].pos.is_some());
    }

    #[test]
    fn absent_positions_and_missing_records_are_none() {
        let text = with_line(
            25,
            "PG02      0.000000      0.000000      0.000000    269.108429",
        );
        let text = text.replace(
            "PG03  23137.793666   7181.148924  10900.702541    575.503968  9  7  7 117       \n",
            "",
        );
        let f = parse(&text, "x.sp3").unwrap();
        assert_eq!(f.samples[&g(2)][0].pos, None);
        assert!(f.samples[&g(2)][0].clk_s.is_some());
        assert_eq!(f.samples[&g(3)][0], Sample::default());
        assert!(f.samples[&g(3)][1].pos.is_some());
    }

    #[test]
    fn malformed_lines_are_named_by_file_and_line() {
        let e = error_of(&with_line(
            26,
            "PG03  23137.79x666   7181.148924  10900.702541    575.503968",
        ));
        assert!(
            e.starts_with("x.sp3:26: coordinate: not a number: '23137.79x666'"),
            "{e}"
        );
        let e = error_of(&with_line(
            25,
            "PG02 -14889.160729  -5131.952946 -21416.801336          ",
        ));
        assert!(e.starts_with("x.sp3:25: clock: not a number: ''"), "{e}");
        let e = error_of(&with_line(
            25,
            "PE05 -14889.160729  -5131.952946 -21416.801336    269.108429",
        ));
        assert!(
            e.starts_with("x.sp3:25: E05 is not in the header's satellite list"),
            "{e}"
        );
        let e = error_of(&with_line(
            25,
            "PX05 -14889.160729  -5131.952946 -21416.801336    269.108429",
        ));
        assert!(
            e.starts_with("x.sp3:25: unknown constellation letter 'X'"),
            "{e}"
        );
        let e = error_of(&with_line(56, "*  2010  7  1  0 15"));
        assert!(e.starts_with("x.sp3:56: expected a date"), "{e}");
        let e = error_of(&with_line(56, "*  2010  7  1  0  0  0.00000000"));
        assert!(e.starts_with("x.sp3:56: epoch not after"), "{e}");
        let e = error_of(&with_line(25, "XG02 1"));
        assert!(e.starts_with("x.sp3:25: unexpected line"), "{e}");
        let e = error_of(&with_line(
            1,
            "#aP2010  7  1  0  0  0.00000000      96 ORBIT IGS05 HLM  IGS",
        ));
        assert!(e.starts_with("x.sp3:1: not an SP3-c or SP3-d file"), "{e}");
        let e = error_of(&with_line(
            2,
            "## 1590 345600.00000000   -90.00000000 55378 0.0000000000000",
        ));
        assert!(
            e.starts_with("x.sp3:2: epoch interval must be positive"),
            "{e}"
        );
        let text: String = IGS
            .lines()
            .filter(|l| !l.starts_with('*'))
            .map(|l| format!("{l}\n"))
            .collect();
        let e = error_of(&text);
        assert!(e.starts_with("x.sp3:23: P record before"), "{e}");
    }

    #[test]
    fn header_counts_and_time_systems_are_checked() {
        let e = error_of(&with_line(
            1,
            "#cP2010  7  1  0  0  0.00000000      16 ORBIT IGS05 HLM  IGS",
        ));
        assert!(
            e.contains("more epochs than the 16 the header declares"),
            "{e}"
        );
        let e = error_of(&with_line(
            3,
            "+   31   G01G02G03G04G05G06G07G08G09G10G11G12G13G14G15G16G17",
        ));
        assert!(
            e.contains("lists 32 satellites, not the 31 it declares"),
            "{e}"
        );
        let e = error_of(&with_line(
            13,
            "%c G  cc UTC ccc cccc cccc cccc cccc ccccc ccccc ccccc ccccc",
        ));
        assert!(
            e.starts_with("x.sp3:13: time system 'UTC' is not read"),
            "{e}"
        );
        let header: String = IGS.lines().take(22).map(|l| format!("{l}\n")).collect();
        assert!(error_of(&header).contains("no '*' epoch line"));
        assert!(error_of("").starts_with("x.sp3:1: not an SP3"));
    }
}
