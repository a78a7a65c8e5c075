//! `navguard convert` for solution files and IMU logs: RTKLIB `.pos`, NMEA, KF-GINS
//! (`gnss` blocks with σ) and IMU CSVs on GPS time through an RTKLIB time tag, merged
//! with a solution file when one is given. Thin: the readers and the merge live in
//! [`navguard_formats`].

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Context;
use navguard_core::epoch::Epoch;
use navguard_formats::fix::{GnssFix, SigmaPolicy, SigmaSource};
use navguard_formats::imu_csv::{self, AccelUnit, GyroUnit, ImuColumns, ImuCsvLayout, TimeUnit};
use navguard_formats::nmea::{NmeaParams, read_nmea};
use navguard_formats::{kfgins, merge, rtklib_pos, timetag};

use super::thousands;

/// The solution-file formats (`--format`, and `--gnss-format` beside an IMU CSV).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub(crate) enum GnssFormat {
    /// RTKLIB `.pos` (GPST, latitude/longitude in degrees).
    #[default]
    Pos,
    /// NMEA 0183 GGA, RMC, VTG, GST.
    Nmea,
    /// KF-GINS GNSS text (seconds of week, lat, lon, h, σ lat, lon, h).
    Kfgins,
}

/// Where a fix's σ comes from (`--sigma`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub(crate) enum SigmaArg {
    /// The file's σ, floored at 0.01 m and 0.01 m/s; the quality table where it has none.
    #[default]
    Reported,
    /// The quality table (docs/formats.md); the file's σ where it has no quality.
    Quality,
}

/// The flags of the solution and IMU formats.
#[derive(Debug, Default, clap::Args)]
pub(crate) struct DriveArgs {
    /// The solution file (pos, nmea, kfgins; with imu-csv: merged into the IMU epochs).
    #[arg(long)]
    pub gnss: Option<PathBuf>,
    /// The format of `--gnss` beside `--format imu-csv` [default: pos].
    #[arg(long, value_enum)]
    pub gnss_format: Option<GnssFormat>,
    /// Where σ come from: the file's or the solution quality's table.
    #[arg(long, value_enum, default_value_t)]
    pub sigma: SigmaArg,
    /// GPST − UTC for NMEA times, s [default: 18].
    #[arg(long)]
    pub leap_s: Option<f64>,
    /// NMEA: count and skip sentences with a bad checksum or that do not parse.
    #[arg(long)]
    pub skip_bad: bool,
    /// KF-GINS: the GPS week of its seconds of week (absent: times stay seconds of week).
    #[arg(long)]
    pub gps_week: Option<i64>,
    /// The IMU CSV (imu-csv).
    #[arg(long)]
    pub imu: Option<PathBuf>,
    /// The RTKLIB time tag of the IMU CSV, which puts its counter on GPS time.
    #[arg(long)]
    pub tag: Option<PathBuf>,
    /// The IMU CSV's columns, 0-based [default: ax=0,ay=1,az=2,gx=3,gy=4,gz=5,t=6].
    #[arg(long)]
    pub imu_columns: Option<ImuColumns>,
    /// The accelerometer unit, g or mps2 [default: g].
    #[arg(long)]
    pub accel_unit: Option<AccelUnit>,
    /// The gyro unit, dps or rps [default: dps].
    #[arg(long)]
    pub gyro_unit: Option<GyroUnit>,
    /// The time column's unit, s or ms [default: ms].
    #[arg(long)]
    pub time_unit: Option<TimeUnit>,
    /// Header lines to skip at the top of the IMU CSV.
    #[arg(long, default_value_t)]
    pub imu_header_lines: usize,
    /// Seconds added to every IMU time after the tag's map (the drive's logger: -0.125).
    #[arg(long, default_value_t, allow_hyphen_values = true)]
    pub imu_time_offset: f64,
}

impl DriveArgs {
    fn policy(&self) -> SigmaPolicy {
        let source = match self.sigma {
            SigmaArg::Reported => SigmaSource::Reported,
            SigmaArg::Quality => SigmaSource::Quality,
        };
        SigmaPolicy {
            source,
            ..SigmaPolicy::default()
        }
    }

    fn layout(&self) -> ImuCsvLayout {
        ImuCsvLayout {
            columns: self.imu_columns.unwrap_or_default(),
            accel_unit: self.accel_unit.unwrap_or_default(),
            gyro_unit: self.gyro_unit.unwrap_or_default(),
            time_unit: self.time_unit.unwrap_or_default(),
            header_lines: self.imu_header_lines,
        }
    }
}

fn need<'a>(p: &'a Option<PathBuf>, flag: &str, what: &str) -> anyhow::Result<&'a Path> {
    p.as_deref().with_context(|| format!("{what} needs {flag}"))
}

/// Reads a solution file's fixes and says what it held.
fn read_fixes(path: &Path, format: GnssFormat, a: &DriveArgs) -> anyhow::Result<Vec<GnssFix>> {
    let fixes = match format {
        GnssFormat::Pos => rtklib_pos::read_pos(path)?,
        GnssFormat::Kfgins => kfgins::read_gnss(path, a.gps_week)?,
        GnssFormat::Nmea => {
            let p = NmeaParams {
                leap_s: a.leap_s.unwrap_or(NmeaParams::default().leap_s),
                skip_bad: a.skip_bad,
            };
            let log = read_nmea(path, p)?;
            let c = log.counts;
            eprintln!(
                "nmea: GGA {}, RMC {}, VTG {}, GST {}, other {}, bad {} skipped, {} times without a usable GGA",
                c.gga, c.rmc, c.vtg, c.gst, c.other, c.bad, c.no_fix
            );
            log.fixes
        }
    };
    let mut by_q: BTreeMap<u32, usize> = BTreeMap::new();
    for f in &fixes {
        *by_q
            .entry(f.quality.map_or(0, |q| q.rtklib_q()))
            .or_default() += 1;
    }
    let qs: Vec<String> = by_q
        .iter()
        .map(|(q, n)| match q {
            0 => format!("no quality {}", thousands(*n as u64)),
            q => format!("Q{q} {}", thousands(*n as u64)),
        })
        .collect();
    eprintln!(
        "gnss: {} fixes ({})",
        thousands(fixes.len() as u64),
        qs.join(", ")
    );
    Ok(fixes)
}

/// `--format pos|nmea|kfgins`: GNSS-only epochs.
pub(crate) fn read_solution(format: GnssFormat, a: &DriveArgs) -> anyhow::Result<Vec<Epoch>> {
    let name = format!("--format {format:?}").to_lowercase();
    let fixes = read_fixes(need(&a.gnss, "--gnss", &name)?, format, a)?;
    let policy = a.policy();
    Ok(fixes.iter().map(|f| policy.epoch(f)).collect())
}

/// `--format imu-csv`: IMU epochs on GPS time, merged with `--gnss` when given.
pub(crate) fn read_imu(a: &DriveArgs) -> anyhow::Result<Vec<Epoch>> {
    let path = need(&a.imu, "--imu", "--format imu-csv")?;
    let samples = imu_csv::read_imu_csv(path, &a.layout())?;
    let (Some(first), Some(last)) = (samples.first(), samples.last()) else {
        anyhow::bail!("{}: no IMU samples", path.display());
    };
    let (first, last) = (first.t, last.t);
    let offset = a.imu_time_offset;
    let imu = match &a.tag {
        Some(tag_path) => {
            let tag = timetag::read_tag(tag_path)?;
            eprintln!(
                "imu: {} samples over {:.3} s of counter, on the tag's {:.3} s from GPS {:.3} s, offset {offset} s",
                thousands(samples.len() as u64),
                last - first,
                tag.span_s(),
                tag.start_gps_s
            );
            imu_csv::to_epochs_tagged(&samples, &tag, offset)
        }
        None => {
            eprintln!(
                "imu: {} samples, times taken as GPS seconds, offset {offset} s",
                thousands(samples.len() as u64)
            );
            imu_csv::to_epochs(&samples, |t| t + offset)
        }
    };
    let Some(gnss_path) = &a.gnss else {
        return Ok(imu);
    };
    let fixes = read_fixes(gnss_path, a.gnss_format.unwrap_or_default(), a)?;
    let policy = a.policy();
    let m = merge::merge(imu, fixes.iter().map(|f| policy.epoch(f)).collect());
    eprintln!(
        "merge: {} fixes ride on IMU epochs, {} stand alone (tolerance {:.2} ms)",
        thousands(m.attached as u64),
        thousands(m.standalone as u64),
        m.tolerance_s * 1e3
    );
    Ok(m.epochs)
}
