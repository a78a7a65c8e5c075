//! `navguard convert`: reads real receiver files with [`navguard_formats`] and writes
//! ingest frames, one epoch per JSON line, with `gnss_raw` blocks (the input of
//! `navguard replay`). Thin: the readers, orbits and corrections live in the crate.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use navguard_core::epoch::Epoch;
use navguard_core::geo::Lla;
use navguard_formats::gsdc::{self, Band};
use navguard_formats::rinex::{convert::RinexParams, nav::read_nav, obs::read_obs};
use navguard_formats::{gnsslogger, rinex};

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
    pub obs: PathBuf,
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
}

const CONVERT_HELP: &str = "\
--format rinex reads RINEX 2.x and 3.x (the version on the first line decides); of RINEX 3
only GPS satellites and records are used, the other systems' are skipped.

Examples:
  navguard convert --format rinex --obs tests/data/gnss/rtklib/07590920.05o --nav tests/data/gnss/rtklib/07590920.05n --iono-free --truth-approx-position -o geonet.jsonl
  navguard convert --format gnsslogger --obs tests/data/gnss/gnsslogger/pseudoranges_log_2016_06_30_21_26_07.txt --nav tests/data/gnss/gnsslogger/hour1820.16n --truth 37.422578,-122.081678,-28 -o logger.jsonl
  navguard convert --format gsdc2023 --obs tests/data/gnss/gsdc/gsdc2023_pixel7pro_device_gnss.csv --truth-file tests/data/gnss/gsdc/gsdc2023_pixel7pro_ground_truth.csv";

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
    let obs_name = a.obs.display().to_string();
    Ok(match a.format {
        Format::Rinex => {
            let nav =
                read_nav(need(&a.nav, "--nav", "rinex")?).context("reading the navigation file")?;
            let obs = read_obs(&a.obs).context("reading the observation file")?;
            let p = RinexParams {
                iono_free: a.iono_free,
                truth_approx_position: a.truth_approx_position,
            };
            let c = rinex::convert::convert(&obs, &nav, &obs_name, p)?;
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
            let log = gnsslogger::read_log(&a.obs).context("reading the GnssLogger log")?;
            let p = gnsslogger::GnssLoggerParams {
                truth: a.truth,
                apriori: None,
            };
            let (epochs, no_eph) = gnsslogger::convert(&log, &nav, &obs_name, p)?;
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
            gsdc::y2021::read(&a.obs, band, truth.as_ref())?
        }
        Format::Gsdc2023 => {
            let truth = a
                .truth_file
                .as_deref()
                .map(gsdc::y2023::read_truth)
                .transpose()?;
            gsdc::y2023::read(&a.obs, band, truth.as_ref())?
        }
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

    #[test]
    fn truth_flag_reads_degrees_and_metres() {
        let p = parse_lla("37.422578,-122.081678,-28").unwrap();
        assert!((p.lat.to_degrees() - 37.422578).abs() < 1e-12);
        assert_eq!(p.h, -28.0);
        assert!(parse_lla("1,2").is_err());
    }
}
