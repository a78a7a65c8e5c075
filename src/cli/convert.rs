//! `navguard convert`: reads real receiver files with [`navguard_formats`] and writes
//! ingest frames, one epoch per JSON line (the input of `navguard replay`): `gnss_raw`
//! blocks from observation files, `gnss` and `imu` blocks from solution files and IMU
//! logs ([`super::convert_drive`]). Thin: the readers, orbits and corrections live in
//! the crate.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use navguard_core::epoch::Epoch;
use navguard_core::geo::Lla;
use navguard_formats::gsdc::{self, Band};
use navguard_formats::rinex::{convert::RinexParams, nav::read_nav, obs::read_obs};
use navguard_formats::{gnsslogger, rinex};

use super::convert_drive::{self, DriveArgs, GnssFormat};
use super::thousands;
use crate::service::wire::epoch_to_wire;

/// The file formats `convert` reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum Format {
    /// RINEX 2.10/2.11 or 3.0x observation (`--obs`) + navigation (`--nav`); GPS only.
    Rinex,
    /// Android GnssLogger log (`--obs`) + RINEX 2 or 3 GPS navigation (`--nav`).
    Gnsslogger,
    /// GSDC 2021 `*_derived.csv` (`--obs`), optional `*_ground_truth.csv` (`--truth-file`).
    Gsdc2021,
    /// GSDC 2023 `device_gnss.csv` (`--obs`), optional `ground_truth.csv` (`--truth-file`).
    Gsdc2023,
    /// RTKLIB `.pos` solution (`--gnss`): `gnss` blocks with σ.
    Pos,
    /// NMEA 0183 log (`--gnss`): GGA, RMC, VTG, GST into `gnss` blocks.
    Nmea,
    /// KF-GINS GNSS text (`--gnss`, optional `--gps-week`).
    Kfgins,
    /// IMU CSV (`--imu`, optional `--tag`), merged with a solution file (`--gnss`).
    ImuCsv,
}

/// `navguard convert` flags.
#[derive(Debug, clap::Args)]
#[command(after_long_help = CONVERT_HELP)]
pub(crate) struct ConvertArgs {
    /// The input format.
    #[arg(long, value_enum)]
    pub format: Format,
    /// The observation file (RINEX obs, GnssLogger log, GSDC CSV).
    #[arg(long)]
    pub obs: Option<PathBuf>,
    /// The RINEX 2.x or 3.x navigation file, GPS records used (rinex, gnsslogger).
    #[arg(long)]
    pub nav: Option<PathBuf>,
    /// The GSDC ground-truth CSV (gsdc2021: heights corrected by −61 m).
    #[arg(long)]
    pub truth_file: Option<PathBuf>,
    /// A fixed truth `LAT,LON,H` (degrees, degrees, m ellipsoidal) for every epoch (gnsslogger).
    #[arg(long, value_parser = parse_lla, allow_hyphen_values = true)]
    pub truth: Option<Lla>,
    /// Use the RINEX header's APPROX POSITION XYZ as the truth (rinex).
    #[arg(long)]
    pub truth_approx_position: bool,
    /// Iono-free C1/P2 combination (RINEX 3: C1W, else C1C, with C2W) instead of C1 (C1C) + Klobuchar (rinex).
    #[arg(long)]
    pub iono_free: bool,
    /// Keep the L5/E5a signal instead of L1/E1/G1 (gsdc).
    #[arg(long)]
    pub l5: bool,
    /// Output file of ingest frames (default stdout).
    #[arg(short = 'o', long)]
    pub out: Option<PathBuf>,
    /// Solution files and IMU logs.
    #[command(flatten)]
    pub drive: DriveArgs,
}

const CONVERT_HELP: &str = "\
--format rinex reads RINEX 2.x and 3.x (the version on the first line decides); of RINEX 3
only GPS satellites and records are used, the other systems' are skipped.

--format pos|nmea|kfgins reads a solution file (--gnss) into gnss blocks with σ:
--sigma reported (default) keeps the file's σ, floored at 0.01 m and 0.01 m/s;
--sigma quality sets σ from the solution quality (RTK fixed 0.02 m horizontal, 0.04 m
vertical; float 0.5/1.0; DGPS and SBAS 1/2; single 3/6; docs/formats.md). NMEA times are
UTC (--leap-s, default 18); --skip-bad counts and skips bad sentences. KF-GINS times are
seconds of week unless --gps-week is given.

--format imu-csv reads an IMU CSV (--imu) into imu blocks (rates, sensor frame, SI):
--imu-columns ax=0,ay=1,az=2,gx=3,gy=4,gz=5,t=6 (0-based; the default), --accel-unit g|mps2,
--gyro-unit dps|rps, --time-unit s|ms, --imu-header-lines N. --tag puts the CSV's counter
on GPS time (first row at the tag's start, last at start + the tag's span);
--imu-time-offset is added after. With --gnss (and --gnss-format pos|nmea|kfgins), each
fix rides on the nearest IMU epoch within half a sample, the others stand alone.

Examples:
  navguard convert --format rinex --obs tests/data/gnss/rtklib/07590920.05o --nav tests/data/gnss/rtklib/07590920.05n --iono-free --truth-approx-position -o geonet.jsonl
  navguard convert --format gnsslogger --obs tests/data/gnss/gnsslogger/pseudoranges_log_2016_06_30_21_26_07.txt --nav tests/data/gnss/gnsslogger/hour1820.16n --truth 37.422578,-122.081678,-28 -o logger.jsonl
  navguard convert --format gsdc2023 --obs tests/data/gnss/gsdc/gsdc2023_pixel7pro_device_gnss.csv --truth-file tests/data/gnss/gsdc/gsdc2023_pixel7pro_ground_truth.csv
  navguard convert --format pos --gnss tests/data/drive/gnss_1934_sf.pos -o drive-gnss.jsonl
  navguard convert --format nmea --gnss tests/data/drive/sample.nmea --sigma quality
  navguard convert --format imu-csv --imu tests/data/drive/imu_1934.csv --tag tests/data/drive/imu_1934.csv.tag --accel-unit g --gyro-unit dps --time-unit ms --imu-time-offset -0.125 --gnss tests/data/drive/gnss_1934_sf.pos --gnss-format pos -o drive.jsonl";

/// `LAT,LON,H` in degrees, degrees, metres.
fn parse_lla(s: &str) -> Result<Lla, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| {
            x.trim()
                .parse::<f64>()
                .map_err(|_| format!("'{x}' is not a number"))
        })
        .collect::<Result<_, _>>()?;
    match v[..] {
        [lat, lon, h] if lat.abs() <= 90.0 && lon.abs() <= 360.0 => Ok(Lla {
            lat: lat.to_radians(),
            lon: lon.to_radians(),
            h,
        }),
        _ => Err("expected LAT,LON,H with |LAT| ≤ 90".into()),
    }
}

fn need<'a>(p: &'a Option<PathBuf>, flag: &str, format: &str) -> anyhow::Result<&'a Path> {
    match p {
        Some(p) => Ok(p),
        None => bail!("--format {format} needs {flag}"),
    }
}

/// Reads the input files into epochs.
pub(crate) fn read_epochs(a: &ConvertArgs) -> anyhow::Result<Vec<Epoch>> {
    let band = if a.l5 { Band::L5 } else { Band::L1 };
    let obs_of = |format: &str| need(&a.obs, "--obs", format);
    Ok(match a.format {
        Format::Rinex => {
            let nav =
                read_nav(need(&a.nav, "--nav", "rinex")?).context("reading the navigation file")?;
            let obs_path = obs_of("rinex")?;
            let obs = read_obs(obs_path).context("reading the observation file")?;
            let p = RinexParams {
                iono_free: a.iono_free,
                truth_approx_position: a.truth_approx_position,
            };
            let c = rinex::convert::convert(&obs, &nav, &obs_path.display().to_string(), p)?;
            eprintln!(
                "rinex: {} epochs, {} observations dropped (no code or no ephemeris in ±2 h)",
                c.epochs.len(),
                c.dropped
            );
            c.epochs
        }
        Format::Gnsslogger => {
            let nav = read_nav(need(&a.nav, "--nav", "gnsslogger")?)
                .context("reading the navigation file")?;
            let obs_path = obs_of("gnsslogger")?;
            let log = gnsslogger::read_log(obs_path).context("reading the GnssLogger log")?;
            let p = gnsslogger::GnssLoggerParams {
                truth: a.truth,
                apriori: None,
            };
            let name = obs_path.display().to_string();
            let (epochs, no_eph) = gnsslogger::convert(&log, &nav, &name, p)?;
            eprintln!(
                "gnsslogger: {} records kept, {} dropped, {no_eph} without ephemeris",
                log.records.len(),
                log.dropped
            );
            epochs
        }
        Format::Gsdc2021 => {
            let truth = a
                .truth_file
                .as_deref()
                .map(gsdc::y2021::read_truth)
                .transpose()?;
            gsdc::y2021::read(obs_of("gsdc2021")?, band, truth.as_ref())?
        }
        Format::Gsdc2023 => {
            let truth = a
                .truth_file
                .as_deref()
                .map(gsdc::y2023::read_truth)
                .transpose()?;
            gsdc::y2023::read(obs_of("gsdc2023")?, band, truth.as_ref())?
        }
        Format::Pos => convert_drive::read_solution(GnssFormat::Pos, &a.drive)?,
        Format::Nmea => convert_drive::read_solution(GnssFormat::Nmea, &a.drive)?,
        Format::Kfgins => convert_drive::read_solution(GnssFormat::Kfgins, &a.drive)?,
        Format::ImuCsv => convert_drive::read_imu(&a.drive)?,
    })
}

/// Runs `navguard convert`.
pub(crate) fn run(a: ConvertArgs) -> anyhow::Result<()> {
    let epochs = read_epochs(&a)?;
    let mut out: Box<dyn Write> = match &a.out {
        Some(p) => Box::new(BufWriter::new(
            File::create(p).with_context(|| format!("creating {}", p.display()))?,
        )),
        None => Box::new(BufWriter::new(std::io::stdout().lock())),
    };
    let bar = super::progress_bar(
        epochs.len() as u64,
        "{bar:40} {pos}/{len} epochs",
        a.out.is_some(),
    );
    for e in &epochs {
        let frame = epoch_to_wire(e).with_context(|| format!("the epoch at t = {} s", e.t))?;
        out.write_all(frame.as_bytes()).context("writing a frame")?;
        out.write_all(b"\n").context("writing a frame")?;
        bar.inc(1);
    }
    out.flush().context("flushing the output")?;
    bar.finish_and_clear();
    eprintln!("wrote {} epochs", thousands(epochs.len() as u64));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::service::wire::parse_frame;

    fn drive_file(name: &str) -> Option<PathBuf> {
        Some(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/data/drive")
                .join(name),
        )
    }

    fn drive_args(format: Format, drive: DriveArgs) -> ConvertArgs {
        ConvertArgs {
            format,
            obs: None,
            nav: None,
            truth_file: None,
            truth: None,
            truth_approx_position: false,
            iono_free: false,
            l5: false,
            out: None,
            drive,
        }
    }

    /// Every epoch written as a line parses back, alone and as one time-ordered batch.
    fn lines_parse_back(epochs: &[Epoch]) {
        let lines: Vec<String> = epochs.iter().map(|e| epoch_to_wire(e).unwrap()).collect();
        for (line, e) in lines.iter().zip(epochs).step_by(97) {
            let back = parse_frame(line, 1).unwrap();
            assert_eq!((back[0].t, back[0].imu.is_some()), (e.t, e.imu.is_some()));
            assert_eq!(back[0].gnss.is_some(), e.gnss.is_some());
        }
        let batch = parse_frame(&format!("[{}]", lines.join(",")), lines.len()).unwrap();
        assert_eq!(batch.len(), epochs.len());
    }

    #[test]
    fn the_drive_imu_csv_with_its_pos_converts_to_frames_that_parse_back() {
        let a = drive_args(
            Format::ImuCsv,
            DriveArgs {
                imu: drive_file("imu_1934.csv"),
                tag: drive_file("imu_1934.csv.tag"),
                imu_time_offset: -0.125,
                gnss: drive_file("gnss_1934_sf.pos"),
                gnss_format: Some(GnssFormat::Pos),
                ..DriveArgs::default()
            },
        );
        let epochs = read_epochs(&a).unwrap();
        // 54,860 IMU epochs; the 13 fixes before the IMU's first sample stand alone.
        assert_eq!(epochs.len(), 54_860 + 13);
        assert_eq!(epochs.iter().filter(|e| e.imu.is_some()).count(), 54_860);
        assert_eq!(epochs.iter().filter(|e| e.gnss.is_some()).count(), 2_197);
        lines_parse_back(&epochs);
    }

    #[test]
    fn a_pos_file_alone_converts_with_quality_sigma() {
        let drive = DriveArgs {
            gnss: drive_file("gnss_1934_sf.pos"),
            sigma: convert_drive::SigmaArg::Quality,
            ..DriveArgs::default()
        };
        let epochs = read_epochs(&drive_args(Format::Pos, drive)).unwrap();
        assert_eq!(epochs.len(), 2_197);
        let sigma = |e: &Epoch| e.gnss.as_ref().and_then(|g| g.pos_sigma);
        let fixed = epochs
            .iter()
            .filter(|e| sigma(e) == Some([0.02, 0.02, 0.04]));
        assert_eq!(fixed.count(), 2_189);
        let float = epochs.iter().filter(|e| sigma(e) == Some([0.5, 0.5, 1.0]));
        assert_eq!(float.count(), 8);
        lines_parse_back(&epochs);
        let none = drive_args(Format::Pos, DriveArgs::default());
        assert!(
            read_epochs(&none)
                .unwrap_err()
                .to_string()
                .contains("--gnss")
        );
    }

    #[test]
    fn truth_flag_reads_degrees_and_metres() {
        let p = parse_lla("37.422578,-122.081678,-28").unwrap();
        assert!((p.lat.to_degrees() - 37.422578).abs() < 1e-12);
        assert_eq!(p.h, -28.0);
        assert!(parse_lla("1,2").is_err());
    }
}
