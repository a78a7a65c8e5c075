//! IMU CSVs → raw IMU samples in the sensor frame: a column map says which column holds
//! each accelerometer and gyro axis and the time, and in which units; samples come out
//! as rates in SI ([`ImuBlock`] with `dt` None: m/s², rad/s). No frame rotation here:
//! the mounting belongs to the monitor's configuration. Times stay the file's own
//! (seconds); [`timetag`](crate::timetag) or the caller puts them on GPS time.
//!
//! Fields are comma separated; the first `header_lines` lines and blank lines are
//! skipped; every other line must hold a number in each mapped column, and its time must
//! not go back, or the reader stops with the line's number.

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use navguard_core::epoch::{Epoch, ImuBlock};

use crate::error::{At, FormatError, missing, read_to_string};

/// Standard gravity, m/s² per g (CGPM 1901, the value IMU datasheets mean by "g").
pub const G0: f64 = 9.806_65;

/// The accelerometer columns' unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AccelUnit {
    /// Standard gravities (× [`G0`]).
    #[default]
    G,
    /// m/s².
    Mps2,
}

/// The gyro columns' unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum GyroUnit {
    /// Degrees per second.
    #[default]
    Dps,
    /// Radians per second.
    Rps,
}

/// The time column's unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TimeUnit {
    /// Seconds.
    Seconds,
    /// Milliseconds.
    #[default]
    Milliseconds,
}

/// Parses one of `names` (case-insensitive) into the value beside it.
fn one_of<T: Copy>(s: &str, names: &[(&str, T)]) -> Result<T, String> {
    let s = s.trim().to_ascii_lowercase();
    names
        .iter()
        .find(|(n, _)| *n == s)
        .map(|(_, v)| *v)
        .ok_or_else(|| {
            let all: Vec<&str> = names.iter().map(|(n, _)| *n).collect();
            format!("'{s}': expected one of {}", all.join(", "))
        })
}

impl FromStr for AccelUnit {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        one_of(
            s,
            &[
                ("g", AccelUnit::G),
                ("mps2", AccelUnit::Mps2),
                ("m/s2", AccelUnit::Mps2),
            ],
        )
    }
}

impl FromStr for GyroUnit {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        one_of(
            s,
            &[
                ("dps", GyroUnit::Dps),
                ("rps", GyroUnit::Rps),
                ("rad/s", GyroUnit::Rps),
            ],
        )
    }
}

impl FromStr for TimeUnit {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        one_of(
            s,
            &[("s", TimeUnit::Seconds), ("ms", TimeUnit::Milliseconds)],
        )
    }
}

/// Which 0-based column holds what: `ax=0,ay=1,az=2,gx=3,gy=4,gz=5,t=6`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImuColumns {
    /// The time column.
    pub time: usize,
    /// Accelerometer x, y, z.
    pub accel: [usize; 3],
    /// Gyro x, y, z.
    pub gyro: [usize; 3],
}

impl Default for ImuColumns {
    /// The drive logger's order: ax, ay, az, gx, gy, gz, tick.
    fn default() -> Self {
        ImuColumns {
            time: 6,
            accel: [0, 1, 2],
            gyro: [3, 4, 5],
        }
    }
}

impl FromStr for ImuColumns {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        const KEYS: [&str; 7] = ["ax", "ay", "az", "gx", "gy", "gz", "t"];
        let mut idx: [Option<usize>; 7] = [None; 7];
        for pair in s.split(',') {
            let (k, v) = pair
                .split_once('=')
                .ok_or_else(|| format!("'{pair}': expected KEY=COLUMN"))?;
            let slot = KEYS
                .iter()
                .position(|x| *x == k.trim())
                .ok_or_else(|| format!("'{k}': keys are {}", KEYS.join(", ")))?;
            let col: usize = v
                .trim()
                .parse()
                .map_err(|_| format!("'{v}': not a column number"))?;
            if idx.contains(&Some(col)) {
                return Err(format!("column {col} is mapped twice"));
            }
            idx[slot] = Some(col);
        }
        let get = |i: usize| idx[i].ok_or_else(|| format!("{} is not mapped", KEYS[i]));
        Ok(ImuColumns {
            accel: [get(0)?, get(1)?, get(2)?],
            gyro: [get(3)?, get(4)?, get(5)?],
            time: get(6)?,
        })
    }
}

impl fmt::Display for ImuColumns {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [ax, ay, az] = self.accel;
        let [gx, gy, gz] = self.gyro;
        write!(
            f,
            "ax={ax},ay={ay},az={az},gx={gx},gy={gy},gz={gz},t={}",
            self.time
        )
    }
}

/// How to read an IMU CSV.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ImuCsvLayout {
    /// Which column holds what.
    pub columns: ImuColumns,
    /// The accelerometer columns' unit.
    pub accel_unit: AccelUnit,
    /// The gyro columns' unit.
    pub gyro_unit: GyroUnit,
    /// The time column's unit.
    pub time_unit: TimeUnit,
    /// Lines skipped at the top (a header row).
    pub header_lines: usize,
}

/// One IMU row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSample {
    /// 1-based line in the file.
    pub line: usize,
    /// The file's time, s (the logger's counter, not yet GPS time).
    pub t: f64,
    /// Rates in SI, sensor frame.
    pub imu: ImuBlock,
}

/// Reads an IMU CSV with `layout`.
pub fn read_imu_csv(path: &Path, layout: &ImuCsvLayout) -> Result<Vec<ImuSample>, FormatError> {
    parse_imu_csv(&read_to_string(path)?, &path.display().to_string(), layout)
}

/// Parses the text of an IMU CSV named `file`.
pub fn parse_imu_csv(
    text: &str,
    file: &str,
    layout: &ImuCsvLayout,
) -> Result<Vec<ImuSample>, FormatError> {
    let mut out: Vec<ImuSample> = Vec::new();
    for (k, line) in text.lines().enumerate().skip(layout.header_lines) {
        let at = At { file, line: k + 1 };
        if line.trim().is_empty() {
            continue;
        }
        let s = parse_row(line, layout, at)?;
        if let Some(prev) = out.last().filter(|p| s.t < p.t) {
            return Err(at.err(format!("time {} s goes back from {} s", s.t, prev.t)));
        }
        out.push(s);
    }
    if out.is_empty() {
        return Err(missing(file, "no IMU rows"));
    }
    Ok(out)
}

fn parse_row(line: &str, layout: &ImuCsvLayout, at: At<'_>) -> Result<ImuSample, FormatError> {
    let f: Vec<&str> = line.split(',').map(str::trim).collect();
    let num = |i: usize| -> Result<f64, FormatError> {
        let s = f.get(i).copied().unwrap_or("");
        s.parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| at.err(format!("column {i}: not a number: '{s}'")))
    };
    let c = &layout.columns;
    let a_scale = match layout.accel_unit {
        AccelUnit::G => G0,
        AccelUnit::Mps2 => 1.0,
    };
    let g_scale = match layout.gyro_unit {
        GyroUnit::Dps => std::f64::consts::PI / 180.0,
        GyroUnit::Rps => 1.0,
    };
    let t_scale = match layout.time_unit {
        TimeUnit::Seconds => 1.0,
        TimeUnit::Milliseconds => 1e-3,
    };
    let three = |i: [usize; 3], s: f64| -> Result<[f64; 3], FormatError> {
        Ok([num(i[0])? * s, num(i[1])? * s, num(i[2])? * s])
    };
    Ok(ImuSample {
        line: at.line,
        t: num(c.time)? * t_scale,
        imu: ImuBlock {
            accel: three(c.accel, a_scale)?,
            gyro: three(c.gyro, g_scale)?,
            dt: None,
        },
    })
}

/// The samples as IMU-only epochs, each time put through `gps_time`.
pub fn to_epochs(samples: &[ImuSample], gps_time: impl Fn(f64) -> f64) -> Vec<Epoch> {
    samples
        .iter()
        .map(|s| Epoch {
            t: gps_time(s.t),
            imu: Some(s.imu),
            ..Epoch::default()
        })
        .collect()
}

/// The samples as IMU-only epochs on GPS time through `tag`: its linear map from the
/// samples' first and last counters ([`crate::timetag::TimeTag::mapping`]) plus
/// `offset_s` (the logger's latency, negative when it stamps late). No samples, no epochs.
pub fn to_epochs_tagged(
    samples: &[ImuSample],
    tag: &crate::timetag::TimeTag,
    offset_s: f64,
) -> Vec<Epoch> {
    let (Some(first), Some(last)) = (samples.first(), samples.last()) else {
        return Vec::new();
    };
    let map = tag.mapping(first.t, last.t, offset_s);
    to_epochs(samples, |t| map.gps(t))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn the_column_flag_maps_every_axis_and_refuses_gaps_or_twins() {
        let c: ImuColumns = "t=0,gx=1,gy=2,gz=3,ax=4,ay=5,az=6".parse().unwrap();
        assert_eq!(c.time, 0);
        assert_eq!(c.gyro, [1, 2, 3]);
        assert_eq!(c.accel, [4, 5, 6]);
        assert_eq!(c.to_string().parse::<ImuColumns>(), Ok(c));
        assert!(
            "ax=0,ay=1,az=2,gx=3,gy=4,gz=5"
                .parse::<ImuColumns>()
                .is_err()
        );
        assert!(
            "ax=0,ay=0,az=2,gx=3,gy=4,gz=5,t=6"
                .parse::<ImuColumns>()
                .is_err()
        );
        assert!(
            "ax=0,ay=1,az=2,gx=3,gy=4,gz=5,q=6"
                .parse::<ImuColumns>()
                .is_err()
        );
    }

    #[test]
    fn units_convert_to_si_and_a_header_is_skipped() {
        let layout = ImuCsvLayout {
            columns: "t=0,ax=1,ay=2,az=3,gx=4,gy=5,gz=6".parse().unwrap(),
            accel_unit: AccelUnit::Mps2,
            gyro_unit: GyroUnit::Rps,
            time_unit: TimeUnit::Seconds,
            header_lines: 1,
        };
        let text = "time,ax,ay,az,gx,gy,gz\n0.01,0.1,0.2,9.8,0.01,0.02,0.03\n";
        let s = parse_imu_csv(text, "i.csv", &layout).unwrap();
        assert_eq!(s[0].line, 2);
        assert_eq!(s[0].t, 0.01);
        assert_eq!(s[0].imu.accel, [0.1, 0.2, 9.8]);
        assert_eq!(s[0].imu.gyro, [0.01, 0.02, 0.03]);
        let g = parse_imu_csv("0,0,2,180,0,0,5", "d.csv", &ImuCsvLayout::default()).unwrap();
        assert_relative_eq!(g[0].imu.accel[2], 2.0 * G0);
        assert_relative_eq!(g[0].imu.gyro[0], std::f64::consts::PI);
        assert_relative_eq!(g[0].t, 0.005);
    }

    #[test]
    fn a_bad_number_or_a_time_going_back_names_its_line() {
        let l = ImuCsvLayout::default();
        let e = parse_imu_csv("0,0,1,0,0,0,10\n0,0,1,x,0,0,20\n", "b.csv", &l).unwrap_err();
        assert_eq!(e.to_string(), "b.csv:2: column 3: not a number: 'x'");
        let e = parse_imu_csv("0,0,1,0,0,0,10\n\n0,0,1,0,0,0,5\n", "b.csv", &l).unwrap_err();
        assert!(e.to_string().starts_with("b.csv:3: time 0.005"), "{e}");
    }
}
