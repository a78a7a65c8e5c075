//! `navguard experiment NAME`: reruns a paper's experiment in-process (the pure
//! core, no server) through [`navguard::sim::experiment`], prints its table and
//! writes its figures. Thin: the experiment is a library function returning a
//! result struct; this file only calls it, prints, and writes files.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use navguard::sim::experiment::{ramp, seed000, seed001, seed002, seed003, seed004};

/// The experiments.
#[derive(Debug, clap::Subcommand)]
pub enum ExperimentCommand {
    /// Seed 004: classic vs counter policy at thresholds 13 and 20 on the ship scenario.
    Seed004(Seed004Args),
    /// Seed 002: redundant-gyro fault isolation (parity FSS test + wavelet-packet C-SVC).
    Seed002(Seed002Args),
    /// Seed 003: one-class SVM detection of TACAN range jumps at noise variance 5, 10, 20 m².
    Seed003(Seed003Args),
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

/// `navguard experiment seed002` flags.
#[derive(Debug, clap::Args)]
pub struct Seed002Args {
    /// Seed of the training windows; run r of each case uses seed + 1 + r.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Noise seeds per scenario × gyro × fault.
    #[arg(long, default_value_t = 20)]
    pub runs: usize,
    /// Pitch reached by the manoeuvring scenario's 4 s climb, degrees.
    #[arg(long, default_value_t = 5.0)]
    pub climb_deg: f64,
    /// Directory for the SVG figure.
    #[arg(long, default_value = "target/experiments/seed002")]
    pub out_dir: PathBuf,
    /// Exit non-zero unless every steady-flight bias fault is isolated correctly.
    #[arg(long)]
    pub check: bool,
}

/// `navguard experiment seed003` flags (defaults: the paper's sizes, training subsampled).
#[derive(Debug, clap::Args)]
pub struct Seed003Args {
    /// Base seed of the flights.
    #[arg(long, default_value_t = 3)]
    pub seed: u64,
    /// Directory for the SVG figures.
    #[arg(long, default_value = "target/experiments/seed003")]
    pub out_dir: PathBuf,
    /// Range noise variances, m² (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "5,10,20")]
    pub noise: Vec<f64>,
    /// Training flights.
    #[arg(long, default_value_t = 10)]
    pub train_flights: usize,
    /// Length of a training flight, s.
    #[arg(long, default_value_t = 1200.0)]
    pub train_duration: f64,
    /// Test flights.
    #[arg(long, default_value_t = 10)]
    pub test_flights: usize,
    /// Length of a test flight, s.
    #[arg(long, default_value_t = 600.0)]
    pub test_duration: f64,
    /// Jumps per test flight.
    #[arg(long, default_value_t = 200)]
    pub jumps: usize,
    /// Training windows kept after subsampling.
    #[arg(long, default_value_t = 30_000)]
    pub train_samples: usize,
    /// Window length, samples.
    #[arg(long, default_value_t = 10)]
    pub window: usize,
    /// Add the crest factor to the features.
    #[arg(long)]
    pub crest: bool,
    /// The ocsvm params as JSON (default {"nu": 0.002, "sigma2": 10.0}).
    #[arg(long)]
    pub model_params: Option<String>,
    /// Exit non-zero unless the mean detection probability at every level is ≥ 99 %.
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
        ExperimentCommand::Seed002(args) => {
            let params = seed002::Seed002Params {
                seed: args.seed,
                runs: args.runs,
                climb_deg: args.climb_deg,
                ..seed002::Seed002Params::default()
            };
            let result = seed002::run(params).context("seed 002 experiment")?;
            print!("{}", seed002::render(&result));
            let plots = seed002::plots(&result);
            write_all(&args.out_dir, &plots)?;
            println!(
                "\nwrote {} figure(s) to {}",
                plots.len(),
                args.out_dir.display()
            );
            let steady_bias = result.rows.iter().filter(|r| {
                r.scenario == "steady"
                    && matches!(r.fault, navguard::sim::rimu::GyroFaultKind::Bias(_))
            });
            let (_, isolated, _, runs) = seed002::totals(steady_bias);
            if args.check && isolated < runs {
                bail!("steady bias faults isolated correctly in {isolated}/{runs} runs");
            }
            Ok(())
        }
        ExperimentCommand::Seed003(args) => {
            let model_params = match &args.model_params {
                Some(text) => serde_json::from_str(text).context("--model-params")?,
                None => seed003::default_model_params(),
            };
            let params = seed003::Seed003Params {
                seed: args.seed,
                noise_vars_m2: args.noise,
                train_flights: args.train_flights,
                train_duration_s: args.train_duration,
                test_flights: args.test_flights,
                test_duration_s: args.test_duration,
                jumps: args.jumps,
                train_samples: args.train_samples,
                features: navguard::features::tacan::TacanFeatureParams {
                    window: args.window,
                    crest: args.crest,
                },
                model_params,
                ..seed003::Seed003Params::default()
            };
            let result = seed003::run(params).context("seed 003 experiment")?;
            print!("{}", seed003::render(&result));
            let plots = seed003::plots(&result);
            write_all(&args.out_dir, &plots)?;
            println!(
                "\nwrote {} figures to {}",
                plots.len(),
                args.out_dir.display()
            );
            if args.check && result.levels.iter().any(|l| l.mean_detection() < 0.99) {
                bail!("a noise level's mean detection probability is below 99 %");
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
