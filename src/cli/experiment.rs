//! `navguard experiment NAME`: reruns a paper's experiment in-process (the pure
//! core, no server) through [`navguard_sim::experiment`], prints its table and
//! writes its figures. Thin: the experiment is a library function returning a
//! result struct; this file only calls it, prints, and writes files.

use std::path::{Path, PathBuf};

use super::spinner;

use anyhow::{Context, bail};
use navguard_core::monitor::channel::ResidualScale;
use navguard_sim::experiment::{
    alarms, coloured, coloured_grid, guards, ramp, seed000, seed001, seed002, seed003, seed004,
};

/// The experiments.
#[derive(Debug, clap::Subcommand)]
pub(crate) enum ExperimentCommand {
    /// Seed 004: traditional, classic and counter policies at thresholds 13 and 20 on the ship.
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
    /// Alarms and warnings per fault-free hour of every federated test (ship seeds, real track).
    Alarms(AlarmsArgs),
    /// Frozen GNSS fixes and small DVL biases, with and without the aids' drift and stuck tests.
    Guards(GuardsArgs),
    /// T_a's false-alarm rate on coloured residuals: successive-difference vs batch-means variance.
    Coloured(ColouredArgs),
    /// The gnss monitor on real receiver data: fault-free and injected faults, three FDE methods and one with pairs of faults monitored.
    Raim(super::experiment_raim::RaimArgs),
    /// The federated monitor on the real car drive: raw 100 Hz IMU, 1 Hz degraded GNSS, outages, faults.
    Drive(super::experiment_drive::DriveArgs),
}

/// `navguard experiment coloured` flags.
#[derive(Debug, clap::Args)]
pub(crate) struct ColouredArgs {
    /// First seed; draw i uses seed + i.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Noise draws per case.
    #[arg(long, default_value_t = 5)]
    pub seeds: usize,
    /// Epochs per run.
    #[arg(long, default_value_t = 12_000)]
    pub epochs: usize,
    /// Run the grid instead of the cases: φ 0.5, 0.7, 0.9, 0.95 × four signal forms ×
    /// online and batch LS-SVM × raw and predictive residual, with steps and ramps.
    #[arg(long)]
    pub grid: bool,
    /// Worker threads over the grid's cells.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// With `--grid`: run the channel's drift test too and score the channel's health.
    #[arg(long)]
    pub drift: bool,
}

/// What `experiment coloured` measured: the cases or the grid.
#[derive(Debug)]
pub(crate) enum ColouredOutput {
    /// The default cases.
    Cases(coloured::ColouredResult),
    /// The grid (`--grid`).
    Grid(coloured_grid::GridResult),
}

impl Experiment for ColouredArgs {
    type Output = ColouredOutput;
    const TITLE: &'static str = "coloured";

    fn run(&self) -> anyhow::Result<Self::Output> {
        let base = coloured::ColouredParams {
            seed: self.seed,
            seeds: self.seeds,
            epochs: self.epochs,
            ..coloured::ColouredParams::default()
        };
        if !self.grid {
            return Ok(ColouredOutput::Cases(coloured::run(base)?));
        }
        let params = coloured_grid::GridParams {
            base,
            threads: self.threads,
            drift: self.drift,
            ..coloured_grid::GridParams::default()
        };
        Ok(ColouredOutput::Grid(coloured_grid::run(params)?))
    }

    fn render(output: &Self::Output) -> String {
        match output {
            ColouredOutput::Cases(r) => coloured::render(r),
            ColouredOutput::Grid(r) => coloured_grid::render(r),
        }
    }
}

/// `navguard experiment guards` flags.
#[derive(Debug, clap::Args)]
pub(crate) struct GuardsArgs {
    /// Seeds (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "1,2,3,4,5")]
    pub seeds: Vec<u64>,
    /// False-alarm probability of the tests under the monitor's spec.
    #[arg(long, default_value_t = 1e-3)]
    pub p_fa: f64,
}

/// `navguard experiment alarms` flags.
#[derive(Debug, clap::Args)]
pub(crate) struct AlarmsArgs {
    /// Ship seeds (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "1,2,3,4,5")]
    pub seeds: Vec<u64>,
    /// The real track (1 Hz RTK fixes, the `simulate --track` format), e.g.
    /// `../shared/data/kf-gins-gnss-rtk.txt`; `none` to run the ship seeds only.
    /// Required: the track is not part of the repository, so there is no default.
    #[arg(long, value_name = "FILE|none")]
    pub track: PathBuf,
    /// Seed of the track run.
    #[arg(long, default_value_t = 1)]
    pub track_seed: u64,
    /// False-alarm probability of every test under the monitor's spec.
    #[arg(long, default_value_t = 1e-3)]
    pub p_fa: f64,
    /// Exit non-zero unless, with the defaults, every session raises at most one alarm in
    /// each started fault-free hour and every injected fault raises one.
    #[arg(long)]
    pub check: bool,
}

/// `navguard experiment seed000` flags.
#[derive(Debug, clap::Args)]
pub(crate) struct Seed000Args {
    /// Base seed of the flights.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Monte Carlo runs per fault case.
    #[arg(long, default_value_t = 200)]
    pub runs: usize,
    /// Worker threads for the Monte Carlo.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// How the channel's residual is scaled before its tests.
    #[arg(long, value_enum, default_value_t = ScaleArg::Raw)]
    pub residual_scale: ScaleArg,
    /// Directory for the SVG figures.
    #[arg(long, default_value = "target/experiments/seed000")]
    pub out_dir: PathBuf,
}

/// A channel's `residual_scale` on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum ScaleArg {
    /// The residual as it is.
    Raw,
    /// Over the predictor's predictive σ (docs/methods.md §M9a).
    Predictive,
}

impl From<ScaleArg> for ResidualScale {
    fn from(s: ScaleArg) -> Self {
        match s {
            ScaleArg::Raw => ResidualScale::Raw,
            ScaleArg::Predictive => ResidualScale::Predictive,
        }
    }
}

/// `navguard experiment seed001` flags.
#[derive(Debug, clap::Args)]
pub(crate) struct Seed001Args {
    /// Scenario seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Online window N.
    #[arg(long, default_value_t = 40)]
    pub window: usize,
    /// Repetitions for the timings.
    #[arg(long, default_value_t = 20)]
    pub reps: usize,
    /// Noise draws of part 2 (seeds seed, seed + 1, …).
    #[arg(long, default_value_t = 20)]
    pub seeds: usize,
    /// Fault-free samples before the paper's record in part 2.
    #[arg(long, default_value_t = 300)]
    pub lead_in: usize,
    /// Directory for the SVG figures.
    #[arg(long, default_value = "target/experiments/seed001")]
    pub out_dir: PathBuf,
}

/// `navguard experiment seed004` flags.
#[derive(Debug, clap::Args)]
pub(crate) struct Seed004Args {
    /// Scenario seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Directory for the SVG figures.
    #[arg(long, default_value = "target/experiments/seed004")]
    pub out_dir: PathBuf,
    /// Run length, s.
    #[arg(long, default_value_t = navguard_sim::SHIP_DURATION_S)]
    pub duration: f64,
    /// Error statistics start at this time, s (0: the whole run, initial convergence included).
    #[arg(long, default_value_t = seed004::SETTLE_S)]
    pub settle: f64,
    /// Exit non-zero unless the counter policy beats the traditional one at threshold 20 in
    /// every variant.
    #[arg(long)]
    pub check: bool,
}

/// `navguard experiment seed002` flags.
#[derive(Debug, clap::Args)]
pub(crate) struct Seed002Args {
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
pub(crate) struct Seed003Args {
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
pub(crate) struct RampArgs {
    /// Scenario seeds (comma-separated); mean and worst are over them.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3,4,5")]
    pub seeds: Vec<u64>,
    /// Drift onset, s.
    #[arg(long, default_value_t = 1000.0)]
    pub onset: f64,
    /// How long after onset to wait for an alarm, s.
    #[arg(long, default_value_t = 600.0)]
    pub window: f64,
    /// Drift rates, m/s (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "0.5,1,2,5")]
    pub rates: Vec<f64>,
    /// Window lengths of the drift test of the `+drift` case, GNSS epochs (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "12")]
    pub drift_windows: Vec<usize>,
    /// The drift test's own false-alarm probability in the `+drift` case (default: the
    /// monitor's).
    #[arg(long)]
    pub drift_p_fa: Option<f64>,
    /// Length of the fault-free runs, s (0: skip them).
    #[arg(long, default_value_t = navguard_sim::SHIP_DURATION_S)]
    pub fault_free: f64,
    /// Exit non-zero unless the `+drift` case excludes every 0.5 and 1 m/s drift within
    /// 20 m and every 2 m/s drift within 25 m, on every seed.
    #[arg(long)]
    pub check: bool,
}

/// What every experiment command does, so [`run`] drives them all alike:
/// build the library parameters from the flags, run in-process, print the
/// table, write the figures, then apply the command's `--check`, if any.
pub(crate) trait Experiment {
    /// The library's result.
    type Output;
    /// Name for errors and the progress spinner (`seed 004`).
    const TITLE: &'static str;
    /// Runs the library experiment with the flags' parameters.
    fn run(&self) -> anyhow::Result<Self::Output>;
    /// The table.
    fn render(output: &Self::Output) -> String;
    /// The figures, as (file name, SVG text).
    fn plots(_output: &Self::Output) -> Vec<(String, String)> {
        Vec::new()
    }
    /// Where the figures go (`None`: the experiment draws none).
    fn out_dir(&self) -> Option<&Path> {
        None
    }
    /// `--check`: an error when the result misses the paper's claim.
    fn check(&self, _output: &Self::Output) -> anyhow::Result<()> {
        Ok(())
    }
}

impl Experiment for Seed004Args {
    type Output = seed004::Seed004Result;
    const TITLE: &'static str = "seed 004";

    fn run(&self) -> anyhow::Result<Self::Output> {
        let params = seed004::Seed004Params {
            seed: self.seed,
            duration_s: self.duration,
            settle_s: self.settle,
            ..seed004::Seed004Params::default()
        };
        Ok(seed004::run(params)?)
    }

    fn render(output: &Self::Output) -> String {
        seed004::render(output)
    }

    fn plots(output: &Self::Output) -> Vec<(String, String)> {
        seed004::plots(output)
    }

    fn out_dir(&self) -> Option<&Path> {
        Some(&self.out_dir)
    }

    fn check(&self, output: &Self::Output) -> anyhow::Result<()> {
        for v in &output.variants {
            if self.check && !v.counters_beat("traditional", 20.0) {
                bail!(
                    "the counter policy does not beat the traditional one at threshold 20 (velocity fault {:?} s)",
                    v.velocity_fault_s
                );
            }
        }
        Ok(())
    }
}

impl Experiment for Seed002Args {
    type Output = seed002::Seed002Result;
    const TITLE: &'static str = "seed 002";

    fn run(&self) -> anyhow::Result<Self::Output> {
        let params = seed002::Seed002Params {
            seed: self.seed,
            runs: self.runs,
            climb_deg: self.climb_deg,
            ..seed002::Seed002Params::default()
        };
        Ok(seed002::run(params)?)
    }

    fn render(output: &Self::Output) -> String {
        seed002::render(output)
    }

    fn plots(output: &Self::Output) -> Vec<(String, String)> {
        seed002::plots(output)
    }

    fn out_dir(&self) -> Option<&Path> {
        Some(&self.out_dir)
    }

    fn check(&self, output: &Self::Output) -> anyhow::Result<()> {
        let steady_bias = output.rows.iter().filter(|r| {
            r.scenario == "steady" && matches!(r.fault, navguard_sim::rimu::GyroFaultKind::Bias(_))
        });
        let (_, isolated, _, runs) = seed002::totals(steady_bias);
        if self.check && isolated < runs {
            bail!("steady bias faults isolated correctly in {isolated}/{runs} runs");
        }
        Ok(())
    }
}

impl Experiment for Seed003Args {
    type Output = seed003::Seed003Result;
    const TITLE: &'static str = "seed 003";

    fn run(&self) -> anyhow::Result<Self::Output> {
        let model_params = match &self.model_params {
            Some(text) => serde_json::from_str(text).context("--model-params")?,
            None => seed003::default_model_params(),
        };
        let params = seed003::Seed003Params {
            seed: self.seed,
            noise_vars_m2: self.noise.clone(),
            train_flights: self.train_flights,
            train_duration_s: self.train_duration,
            test_flights: self.test_flights,
            test_duration_s: self.test_duration,
            jumps: self.jumps,
            train_samples: self.train_samples,
            features: navguard_core::features::tacan::TacanFeatureParams {
                window: self.window,
                crest: self.crest,
            },
            model_params,
            ..seed003::Seed003Params::default()
        };
        Ok(seed003::run(params)?)
    }

    fn render(output: &Self::Output) -> String {
        seed003::render(output)
    }

    fn plots(output: &Self::Output) -> Vec<(String, String)> {
        seed003::plots(output)
    }

    fn out_dir(&self) -> Option<&Path> {
        Some(&self.out_dir)
    }

    fn check(&self, output: &Self::Output) -> anyhow::Result<()> {
        if self.check && output.levels.iter().any(|l| l.mean_detection() < 0.99) {
            bail!("a noise level's mean detection probability is below 99 %");
        }
        Ok(())
    }
}

impl Experiment for RampArgs {
    type Output = ramp::RampResult;
    const TITLE: &'static str = "ramp";

    fn run(&self) -> anyhow::Result<Self::Output> {
        let mut cases = ramp::default_cases();
        for case in &mut cases {
            if let Some(d) = &mut case.drift {
                d.windows = self.drift_windows.clone();
                d.p_fa = self.drift_p_fa;
            }
        }
        let params = ramp::RampParams {
            seeds: self.seeds.clone(),
            onset_s: self.onset,
            window_s: self.window,
            rates_mps: self.rates.clone(),
            cases,
            fault_free_s: self.fault_free,
            ..ramp::RampParams::default()
        };
        Ok(ramp::run(params)?)
    }

    fn render(output: &Self::Output) -> String {
        ramp::render(output)
    }

    fn check(&self, output: &Self::Output) -> anyhow::Result<()> {
        if !self.check {
            return Ok(());
        }
        for row in output.rows.iter().filter(|r| r.case.drift.is_some()) {
            let limit = if row.rate_mps <= 1.0 { 20.0 } else { 25.0 };
            if row.rate_mps > 2.0 {
                continue;
            }
            match row.drift_at_exclusion_m() {
                Some((_, worst)) if worst <= limit => {}
                other => bail!(
                    "{} at {} m/s: worst drift at exclusion {other:?}, target ≤ {limit} m",
                    row.label(),
                    row.rate_mps
                ),
            }
        }
        Ok(())
    }
}

impl Experiment for Seed000Args {
    type Output = seed000::Seed000Result;
    const TITLE: &'static str = "seed 000";

    fn run(&self) -> anyhow::Result<Self::Output> {
        let params = seed000::Seed000Params {
            seed: self.seed,
            runs: self.runs,
            threads: self.threads,
            residual_scale: self.residual_scale.into(),
            ..seed000::Seed000Params::default()
        };
        Ok(seed000::run(params)?)
    }

    fn render(output: &Self::Output) -> String {
        seed000::render(output)
    }

    fn plots(output: &Self::Output) -> Vec<(String, String)> {
        seed000::plots(output)
    }

    fn out_dir(&self) -> Option<&Path> {
        Some(&self.out_dir)
    }
}

impl Experiment for Seed001Args {
    type Output = seed001::Seed001Result;
    const TITLE: &'static str = "seed 001";

    fn run(&self) -> anyhow::Result<Self::Output> {
        let params = seed001::Seed001Params {
            seed: self.seed,
            window: self.window,
            reps: self.reps,
            seeds: self.seeds,
            lead_in: self.lead_in,
            ..seed001::Seed001Params::default()
        };
        Ok(seed001::run(params)?)
    }

    fn render(output: &Self::Output) -> String {
        seed001::render(output)
    }

    fn plots(output: &Self::Output) -> Vec<(String, String)> {
        seed001::plots(output)
    }

    fn out_dir(&self) -> Option<&Path> {
        Some(&self.out_dir)
    }
}

impl Experiment for AlarmsArgs {
    type Output = alarms::AlarmsResult;
    const TITLE: &'static str = "alarms";

    fn run(&self) -> anyhow::Result<Self::Output> {
        let track = if self.track.as_os_str() == "none" {
            None
        } else {
            let text = std::fs::read_to_string(&self.track)
                .with_context(|| format!("reading --track {}", self.track.display()))?;
            let track = navguard_sim::Track::parse(&text)
                .with_context(|| format!("--track {}", self.track.display()))?;
            Some((track, self.track_seed))
        };
        let params = alarms::AlarmsParams {
            seeds: self.seeds.clone(),
            track,
            p_fa: self.p_fa,
            ..alarms::AlarmsParams::default()
        };
        Ok(alarms::run(params)?)
    }

    fn render(output: &Self::Output) -> String {
        alarms::render(output)
    }

    fn check(&self, output: &Self::Output) -> anyhow::Result<()> {
        let defaults = alarms::AlarmsConfig::Defaults;
        if self.check && !output.within_target(defaults) {
            bail!("a session raised more than one alarm in a fault-free hour");
        }
        if self.check && !output.every_fault_alarmed(defaults) {
            bail!("an injected fault raised no alarm");
        }
        Ok(())
    }
}

impl Experiment for GuardsArgs {
    type Output = guards::GuardsResult;
    const TITLE: &'static str = "guards";

    fn run(&self) -> anyhow::Result<Self::Output> {
        let params = guards::GuardsParams {
            seeds: self.seeds.clone(),
            p_fa: self.p_fa,
            ..guards::GuardsParams::default()
        };
        Ok(guards::run(params)?)
    }

    fn render(output: &Self::Output) -> String {
        guards::render(output)
    }
}

fn write_all(dir: &Path, files: &[(String, String)]) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for (name, text) in files {
        let path = dir.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// Runs one experiment (a spinner on stderr while it works), prints its
/// table, writes its figures and applies its check.
fn execute<E: Experiment>(experiment: &E) -> anyhow::Result<()> {
    let spinner = spinner(&format!("running the {} experiment", E::TITLE), true);
    let output = experiment.run();
    spinner.finish_and_clear();
    let output = output.with_context(|| format!("{} experiment", E::TITLE))?;
    print!("{}", E::render(&output));
    if let Some(dir) = experiment.out_dir() {
        let plots = E::plots(&output);
        write_all(dir, &plots)?;
        let noun = if plots.len() == 1 {
            "figure"
        } else {
            "figures"
        };
        println!("\nwrote {} {noun} to {}", plots.len(), dir.display());
    }
    experiment.check(&output)
}

/// Runs the command.
pub(crate) fn run(command: ExperimentCommand) -> anyhow::Result<()> {
    match command {
        ExperimentCommand::Seed004(args) => execute(&args),
        ExperimentCommand::Seed002(args) => execute(&args),
        ExperimentCommand::Seed003(args) => execute(&args),
        ExperimentCommand::Ramp(args) => execute(&args),
        ExperimentCommand::Seed000(args) => execute(&args),
        ExperimentCommand::Seed001(args) => execute(&args),
        ExperimentCommand::Coloured(args) => execute(&args),
        ExperimentCommand::Alarms(args) => execute(&args),
        ExperimentCommand::Guards(args) => execute(&args),
        ExperimentCommand::Raim(args) => execute(&args),
        ExperimentCommand::Drive(args) => execute(&args),
    }
}
