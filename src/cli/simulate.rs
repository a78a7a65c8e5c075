//! `navguard simulate ship`: runs a scenario of [`navguard_sim`] and writes it
//! as ingest frames, one epoch per JSON line (the input of `navguard replay`),
//! and optionally the truth, the injected faults and a matching session spec.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use navguard::service::wire::{CreateSession, MonitorSpecWire, epoch_to_wire};
use navguard_core::detect::PolicyConfig;
use navguard_core::monitor::MonitorKind;
use navguard_sim::{self as sim, Fault, Scenario, Track};

use super::thousands;

/// The scenarios `simulate` can write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum ScenarioName {
    /// Seed 004's ship: INS + GNSS (1 Hz) + DVL (1 Hz) + CNS (0.1 Hz), INS at 10 Hz, 3600 s.
    Ship,
}

/// `navguard simulate` flags.
#[derive(Debug, clap::Args)]
#[command(after_long_help = SIMULATE_HELP)]
pub(crate) struct SimulateArgs {
    /// The scenario.
    #[arg(value_enum)]
    pub scenario: ScenarioName,
    /// RNG seed (same seed and build → identical output).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output file of ingest frames, one epoch per line (`-` for stdout).
    #[arg(long)]
    pub out: PathBuf,
    /// Ride the scenario's sensors on a real track (1 Hz RTK fixes: time, lat°, lon°, h).
    #[arg(long)]
    pub track: Option<PathBuf>,
    /// Length of the run, s (default: the scenario's, or the whole track).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Faults: `ship` (seed 004's GNSS jumps), `none`, or a JSON file with a list of faults.
    #[arg(long, default_value = "ship")]
    pub faults: String,
    /// Also write the truth, one JSON line per epoch: t, lat, lon (°), h, vel [e, n, u], att [roll, pitch, yaw] (°).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Also write the injected faults (JSON list, the `--faults FILE` format).
    #[arg(long)]
    pub faults_out: Option<PathBuf>,
    /// Also write a `POST /api/v1/sessions` body whose federated monitor matches the
    /// simulated sensors (for `navguard replay --session-spec`).
    #[arg(long)]
    pub session_spec: Option<PathBuf>,
}

const SIMULATE_HELP: &str = "\
Example:
  navguard simulate ship --seed 1 --out ship.jsonl --truth truth.jsonl --session-spec ship.session.json
  navguard replay ship.jsonl --session ship1 --session-spec ship.session.json --speed max

A fault in a --faults file (units: metres for positions, m/s for velocities, ENU or body x/y/z components):
  [{\"aid\": \"gnss\", \"channel\": \"position\", \"component\": 1,
    \"kind\": {\"type\": \"ramp\", \"rate\": 1.0}, \"start_s\": 1000, \"end_s\": null}]
kinds: step {value}, ramp {rate}, stuck, gain {k}, bias {m}, failure, missing.";

/// One line of `--truth`: the true state, degrees like the ingest wire.
#[derive(Debug, serde::Serialize)]
struct TruthLine {
    t: f64,
    lat: f64,
    lon: f64,
    h: f64,
    vel: [f64; 3],
    att: [f64; 3],
}

fn faults(spec: &str) -> anyhow::Result<Vec<Fault>> {
    match spec {
        "ship" => Ok(sim::ship_faults()),
        "none" => Ok(Vec::new()),
        path => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading --faults {path}"))?;
            serde_json::from_str(&text)
                .with_context(|| format!("--faults {path}: expected a JSON list of faults"))
        }
    }
}

/// Builds the scenario the flags ask for.
pub(crate) fn scenario(args: &SimulateArgs) -> anyhow::Result<Scenario> {
    if let Some(d) = args.duration
        && !(d.is_finite() && d >= 0.0)
    {
        bail!("--duration must be a non-negative number of seconds");
    }
    let faults = faults(&args.faults)?;
    let ScenarioName::Ship = args.scenario;
    let mut scenario = match &args.track {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading --track {}", path.display()))?;
            let track =
                Track::parse(&text).with_context(|| format!("--track {}", path.display()))?;
            sim::track_scenario(&track, args.seed, faults)?
        }
        None => sim::ship_with(
            args.seed,
            faults,
            args.duration.unwrap_or(sim::SHIP_DURATION_S),
        )?,
    };
    if let (Some(d), Some(_)) = (args.duration, &args.track) {
        scenario.epochs.retain(|e| e.epoch.t <= d);
    }
    Ok(scenario)
}

fn create(path: &Path) -> anyhow::Result<Box<dyn Write>> {
    if path.as_os_str() == "-" {
        return Ok(Box::new(BufWriter::new(std::io::stdout().lock())));
    }
    let file = File::create(path).with_context(|| format!("creating {}", path.display()))?;
    Ok(Box::new(BufWriter::with_capacity(1 << 16, file)))
}

/// Runs the command.
pub(crate) fn run(args: SimulateArgs) -> anyhow::Result<()> {
    let scenario = scenario(&args)?;
    let mut out = create(&args.out)?;
    let mut truth = args.truth.as_deref().map(create).transpose()?;
    for e in &scenario.epochs {
        let line = epoch_to_wire(&e.epoch)
            .with_context(|| format!("epoch t = {} cannot be written", e.epoch.t))?;
        out.write_all(line.as_bytes())?;
        out.write_all(b"\n")?;
        if let Some(w) = truth.as_mut() {
            let t = &e.truth;
            let line = TruthLine {
                t: t.t,
                lat: t.lla.lat.to_degrees(),
                lon: t.lla.lon.to_degrees(),
                h: t.lla.h,
                vel: [t.vel.x, t.vel.y, t.vel.z],
                att: t.att.map(f64::to_degrees),
            };
            writeln!(w, "{}", serde_json::to_string(&line)?)?;
        }
    }
    out.flush()
        .with_context(|| format!("writing {}", args.out.display()))?;
    if let Some(mut w) = truth {
        w.flush()?;
    }
    if let Some(path) = &args.faults_out {
        std::fs::write(path, serde_json::to_string_pretty(&scenario.faults)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = &args.session_spec {
        let spec = CreateSession {
            id: None,
            monitors: vec![MonitorSpecWire {
                name: MonitorKind::Federated.as_str().to_owned(),
                kind: MonitorKind::Federated,
                config: serde_json::to_value(scenario.monitor_config())?,
                policy: PolicyConfig::Counters { n1: 10, n2: 5 },
                p_fa: None,
                threshold: None,
                alarm_level: None,
                tests: Default::default(),
            }],
            echo: false,
            alarm_level: None,
            record: None,
        };
        std::fs::write(path, serde_json::to_string_pretty(&spec)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let aids: Vec<&str> = scenario.aids().iter().map(|a| a.as_str()).collect();
    eprintln!(
        "{}: seed {}, {} epochs over {:.0} s (INS {} Hz; aids {}; {} faults) → {}",
        scenario.name,
        scenario.seed,
        thousands(scenario.epochs.len() as u64),
        scenario.duration_s(),
        scenario.ins_rate_hz,
        aids.join(", "),
        scenario.faults.len(),
        args.out.display()
    );
    Ok(())
}
