//! `navguard experiment raim`: reads the real GNSS data sets with the converter's readers
//! and runs [`navguard_sim::experiment::raim`] on them; prints its tables and writes one
//! Stanford diagram per data set.

use std::path::{Path, PathBuf};

use navguard_core::geo::Lla;
use navguard_sim::experiment::raim;

use super::experiment::Experiment;
use crate::cli::convert::{ConvertArgs, Format, read_epochs};

/// `navguard experiment raim` flags.
#[derive(Debug, clap::Args)]
pub(crate) struct RaimArgs {
    /// The folder holding the real data sets (the repository's `tests/data/gnss`).
    #[arg(long, default_value = "tests/data/gnss")]
    pub data: PathBuf,
    /// First seed of the fault draws.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Draws per fault case, method and data set.
    #[arg(long, default_value_t = 100)]
    pub draws: usize,
    /// Epochs per faulted draw.
    #[arg(long, default_value_t = 20)]
    pub window: usize,
    /// False-alarm probability of the raim test.
    #[arg(long, default_value_t = 1e-3)]
    pub p_fa: f64,
    /// Horizontal alert limit, m.
    #[arg(long, default_value_t = 40.0)]
    pub hal: f64,
    /// Directory for the Stanford diagrams.
    #[arg(long, default_value = "target/experiments/raim")]
    pub out_dir: PathBuf,
}

fn args(format: Format, obs: PathBuf) -> ConvertArgs {
    ConvertArgs {
        format,
        obs: Some(obs),
        nav: None,
        sp3: Vec::new(),
        truth_file: None,
        truth: None,
        truth_approx_position: false,
        iono_free: false,
        l5: false,
        out: None,
        drive: Default::default(),
    }
}

/// The four data sets of `tests/data/gnss` (its README says what each is).
fn datasets(dir: &Path) -> anyhow::Result<Vec<raim::Dataset>> {
    let given = serde_json::json!({"model": "given"});
    let geonet = ConvertArgs {
        nav: Some(dir.join("rtklib/07590920.05n")),
        iono_free: true,
        truth_approx_position: true,
        ..args(Format::Rinex, dir.join("rtklib/07590920.05o"))
    };
    let logger = ConvertArgs {
        nav: Some(dir.join("gnsslogger/hour1820.16n")),
        truth: Some(Lla {
            lat: 37.422578f64.to_radians(),
            lon: (-122.081678f64).to_radians(),
            h: -28.0,
        }),
        ..args(
            Format::Gnsslogger,
            dir.join("gnsslogger/pseudoranges_log_2016_06_30_21_26_07.txt"),
        )
    };
    let g21 = ConvertArgs {
        truth_file: Some(dir.join("gsdc/gsdc2021_Pixel4_ground_truth.csv")),
        ..args(
            Format::Gsdc2021,
            dir.join("gsdc/gsdc2021_Pixel4_derived.csv"),
        )
    };
    let g23 = ConvertArgs {
        truth_file: Some(dir.join("gsdc/gsdc2023_pixel7pro_ground_truth.csv")),
        ..args(
            Format::Gsdc2023,
            dir.join("gsdc/gsdc2023_pixel7pro_device_gnss.csv"),
        )
    };
    let set = |name: &str, a: &ConvertArgs, sigma: serde_json::Value| -> anyhow::Result<_> {
        Ok(raim::Dataset {
            name: name.into(),
            epochs: read_epochs(a)?,
            sigma,
        })
    };
    Ok(vec![
        set(
            "geonet (RINEX, iono-free)",
            &geonet,
            serde_json::json!({"model": "elevation"}),
        )?,
        set("gnsslogger (2016 demo log)", &logger, given.clone())?,
        set("gsdc2021 (Pixel 4)", &g21, given.clone())?,
        set("gsdc2023 (Pixel 7 Pro)", &g23, given)?,
    ])
}

impl Experiment for RaimArgs {
    type Output = raim::RaimResult;
    const TITLE: &'static str = "raim";

    fn run(&self) -> anyhow::Result<Self::Output> {
        let params = raim::RaimParams {
            seed: self.seed,
            draws: self.draws,
            window: self.window,
            p_fa: self.p_fa,
            hal_m: self.hal,
            ..raim::RaimParams::default()
        };
        Ok(raim::run(&datasets(&self.data)?, &params)?)
    }

    fn render(output: &Self::Output) -> String {
        raim::render(output)
    }

    fn plots(output: &Self::Output) -> Vec<(String, String)> {
        output
            .datasets
            .iter()
            .map(|d| {
                let slug: String = d
                    .name
                    .split_whitespace()
                    .next()
                    .unwrap_or("data")
                    .to_owned();
                let mut points: Vec<(f64, f64)> = d
                    .fault_free
                    .values()
                    .flat_map(|f| f.points.iter().copied())
                    .collect();
                for by_method in d.faulted.values() {
                    for f in by_method.values() {
                        points.extend(f.points.iter().copied());
                    }
                }
                let title = format!(
                    "Stanford diagram: {} (fault-free and faulted epochs)",
                    d.name
                );
                (
                    format!("stanford_{slug}.svg"),
                    raim::stanford_svg(&title, &points, output.hal_m),
                )
            })
            .collect()
    }

    fn out_dir(&self) -> Option<&Path> {
        Some(&self.out_dir)
    }
}
