//! `navguard experiment NAME`: reruns a paper's experiment in-process (the pure
//! core, no server) through [`navguard::sim::experiment`], prints its table and
//! writes its figures. Thin: the experiment is a library function returning a
//! result struct; this file only calls it, prints, and writes files.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use navguard::sim::experiment::{ramp, seed000, seed001, seed004};

/// The experiments.
#[derive(Debug, clap::Subcommand)]
pub enum ExperimentCommand {
    /// Seed 004: classic vs counter policy at thresholds 13 and 20 on the ship scenario.
    Seed004(Seed004Args),
    /// GNSS position drifts of 0.5, 1, 2, 5 m/s: seconds and metres before the alarm.
    Ramp(RampArgs),
    /// Seed 000: plain vs locally weighted LS-SVM prediction (Fig. 3) and missed detection (Table 2).
    Seed000(Seed000Args),
    /// Seed 001: online vs batch vs global LS-SVM, IMU fault modes, outlier filter.
    Seed001(Seed001Args),
}

/// `navguard experiment seed000` flags.
#[derive(Debug, clap::Args)]
pub struct Seed000Args {
    /// Base seed of the flights.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Monte Carlo runs per fault case.
    #[arg(long, default_value_t = 200)]
    pub runs: usize,
    /// Worker threads for the Monte Carlo.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Directory for the SVG figures.
    #[arg(long, default_value = "target/experiments/seed000")]
    pub out_dir: PathBuf,
}

/// `navguard experiment seed001` flags.
#[derive(Debug, clap::Args)]
pub struct Seed001Args {
    /// Scenario seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Online window N.
    #[arg(long, default_value_t = 40)]
    pub window: usize,
    /// Repetitions for the timings.
    #[arg(long, default_value_t = 20)]
    pub reps: usize,
    /// Directory for the SVG figures.
    #[arg(long, default_value = "target/experiments/seed001")]
    pub out_dir: PathBuf,
}

/// `navguard experiment seed004` flags.
#[derive(Debug, clap::Args)]
pub struct Seed004Args {
    /// Scenario seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Directory for the SVG figures.
    #[arg(long, default_value = "target/experiments/seed004")]
    pub out_dir: PathBuf,
    /// Run length, s.
    #[arg(long, default_value_t = navguard::sim::SHIP_DURATION_S)]
    pub duration: f64,
    /// Error statistics start at this time, s (0: the whole run, initial convergence included).
    #[arg(long, default_value_t = seed004::SETTLE_S)]
    pub settle: f64,
    /// Exit non-zero unless the counter policy beats the classic one at threshold 20.
    #[arg(long)]
    pub check: bool,
}

/// `navguard experiment ramp` flags.
#[derive(Debug, clap::Args)]
pub struct RampArgs {
    /// Scenario seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Drift onset, s.
    #[arg(long, default_value_t = 1000.0)]
    pub onset: f64,
    /// How long after onset to wait for an alarm, s.
    #[arg(long, default_value_t = 600.0)]
    pub window: f64,
}

fn write_all(dir: &Path, files: &[(String, String)]) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for (name, text) in files {
        let path = dir.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// Runs the command.
pub fn run(command: ExperimentCommand) -> anyhow::Result<()> {
    match command {
        ExperimentCommand::Seed004(args) => {
            let params = seed004::Seed004Params {
                seed: args.seed,
                duration_s: args.duration,
                settle_s: args.settle,
                ..seed004::Seed004Params::default()
            };
            let result = seed004::run(params).context("seed 004 experiment")?;
            print!("{}", seed004::render(&result));
            let plots = seed004::plots(&result);
            write_all(&args.out_dir, &plots)?;
            println!(
                "\nwrote {} figures to {}",
                plots.len(),
                args.out_dir.display()
            );
            if args.check && !result.counters_beat_classic(20.0) {
                bail!("the counter policy does not beat the classic one at threshold 20");
            }
            Ok(())
        }
        ExperimentCommand::Ramp(args) => {
            let params = ramp::RampParams {
                seed: args.seed,
                onset_s: args.onset,
                window_s: args.window,
                ..ramp::RampParams::default()
            };
            let result = ramp::run(params).context("ramp experiment")?;
            print!("{}", ramp::render(&result));
            Ok(())
        }
        ExperimentCommand::Seed000(args) => {
            let params = seed000::Seed000Params {
                seed: args.seed,
                runs: args.runs,
                threads: args.threads,
                ..seed000::Seed000Params::default()
            };
            let result = seed000::run(params).context("seed 000 experiment")?;
            print!("{}", seed000::render(&result));
            let plots = seed000::plots(&result);
            write_all(&args.out_dir, &plots)?;
            println!(
                "\nwrote {} figures to {}",
                plots.len(),
                args.out_dir.display()
            );
            Ok(())
        }
        ExperimentCommand::Seed001(args) => {
            let params = seed001::Seed001Params {
                seed: args.seed,
                window: args.window,
                reps: args.reps,
                ..seed001::Seed001Params::default()
            };
            let result = seed001::run(params).context("seed 001 experiment")?;
            print!("{}", seed001::render(&result));
            let plots = seed001::plots(&result);
            write_all(&args.out_dir, &plots)?;
            println!(
                "\nwrote {} figures to {}",
                plots.len(),
                args.out_dir.display()
            );
            Ok(())
        }
    }
}
