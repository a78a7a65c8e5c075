//! `navguard calibrate FILE.jsonl --session-spec SPEC.json --far 1e-4`: replays
//! fault-free data in-process through a session's monitors and proposes, per test, the
//! threshold that gives the requested false-alarm rate on it with the threshold live
//! (docs/methods.md §M25), beside the χ² threshold it replaces, and checks it on a
//! held-out part of the data; `--out` writes the proposals as `PUT …/threshold` bodies,
//! one per monitor.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
use serde::Serialize;

use navguard::service::Limits;
use navguard::service::session::spec::monitor_spec;
use navguard::service::store::Store;
use navguard::service::train::Models;
use navguard::service::wire::{CreateSession, TestThresholdSpec, calibrated_tests, parse_frame};
use navguard_core::epoch::Epoch;
use navguard_core::monitor::calibrate::CalibrationLine;
use navguard_core::monitor::calibrate::live::{LiveOptions, calibrate_live};
use navguard_core::monitor::{self, ModelSource, NoModels};

/// Flags of `navguard calibrate`.
#[derive(Debug, Args)]
pub(crate) struct CalibrateArgs {
    /// Fault-free epochs as JSON lines (the `simulate`/`replay` format, or a recording).
    file: PathBuf,
    /// The session whose monitors to calibrate (a `POST /api/v1/sessions` body).
    #[arg(long)]
    session_spec: PathBuf,
    /// The false-alarm rate per epoch and test to calibrate for.
    #[arg(long, default_value_t = 1e-4)]
    far: f64,
    /// Confidence that the true rate at the proposed threshold is at most `--far`.
    #[arg(long, default_value_t = 0.95)]
    confidence: f64,
    /// Tests to calibrate, by name (comma-separated or repeated); default each monitor's
    /// main tests (not the `.drift`/`.stuck` guards). A monitor without any of them is
    /// skipped.
    #[arg(long, value_delimiter = ',')]
    tests: Vec<String>,
    /// The share of the epochs, at the end, held out to check the proposal on (0: none).
    #[arg(long, default_value_t = 0.5)]
    holdout: f64,
    /// Refuse a proposal that fails more than this multiple of `--far` of the held-out
    /// epochs.
    #[arg(long, default_value_t = 2.0)]
    max_transfer: f64,
    /// A navguard store to take trained models from (for `channel`, `rimu`, `tacan`):
    /// a SQLite file or a `postgres://` URL.
    #[arg(long)]
    db: Option<PathBuf>,
    /// Write the proposals as `PUT /api/v1/sessions/{id}/monitors/{name}/threshold`
    /// bodies: a JSON object from monitor name to its body.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the report as JSON instead of a table.
    #[arg(long)]
    json: bool,
}

/// One monitor's calibration.
#[derive(Debug, Serialize)]
struct MonitorReport {
    monitor: String,
    tests: Vec<CalibrationLine>,
}

/// The `PUT …/threshold` body for one monitor.
#[derive(Debug, Serialize)]
struct PutBody {
    tests: BTreeMap<String, TestThresholdSpec>,
}

fn read_epochs(file: &PathBuf) -> anyhow::Result<Vec<Epoch>> {
    let text =
        std::fs::read_to_string(file).with_context(|| format!("reading {}", file.display()))?;
    let mut epochs = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let frame = parse_frame(line, usize::MAX).map_err(|e| {
            anyhow::anyhow!(
                "{}:{}: {} ({})",
                file.display(),
                i + 1,
                e.message,
                e.code.as_str()
            )
        })?;
        epochs.extend(frame);
    }
    if let Some(w) = epochs.windows(2).position(|w| w[1].t < w[0].t) {
        bail!("{}: time goes back at epoch {}", file.display(), w + 1);
    }
    Ok(epochs)
}

async fn model_source(db: Option<&PathBuf>) -> anyhow::Result<Box<dyn ModelSource>> {
    let Some(db) = db else {
        return Ok(Box::new(NoModels));
    };
    // A SQLite file must exist (calibrate never creates a store); a URL is the server's.
    if navguard::service::store::postgres_url(db).is_none() && !db.exists() {
        bail!("no store at {}", db.display());
    }
    let store = Store::open(db).await.context("opening the store")?;
    let models = Models::load(store, &Limits::default())
        .await
        .context("loading models")?;
    Ok(Box::new(models))
}

/// Runs `navguard calibrate`.
pub(crate) async fn run(args: CalibrateArgs) -> anyhow::Result<()> {
    let spec_text = std::fs::read_to_string(&args.session_spec)
        .with_context(|| format!("reading {}", args.session_spec.display()))?;
    let session: CreateSession = serde_json::from_str(&spec_text)
        .with_context(|| format!("{} is not a session body", args.session_spec.display()))?;
    let epochs = read_epochs(&args.file)?;
    let models = model_source(args.db.as_ref()).await?;
    let mut reports = Vec::new();
    let mut bodies = BTreeMap::new();
    for (i, wire) in session.monitors.iter().enumerate() {
        let mut m = monitor_spec(wire)
            .and_then(|spec| monitor::build(&spec, &*models))
            .map_err(|e| anyhow::anyhow!("monitors[{i}]: {e}"))?;
        let Some(options) = options(&args, &mut *m) else {
            continue;
        };
        eprintln!(
            "calibrating monitor '{}' on {} epochs (the last {:.0} % held out)…",
            wire.name,
            epochs.len(),
            100.0 * options.holdout
        );
        let tests = calibrate_live(&mut *m, &epochs, &options)
            .map_err(|e| anyhow::anyhow!("monitor '{}': {e}", wire.name))?;
        let body = PutBody {
            tests: calibrated_tests(&tests),
        };
        if !body.tests.is_empty() {
            bodies.insert(wire.name.clone(), body);
        }
        reports.push(MonitorReport {
            monitor: wire.name.clone(),
            tests,
        });
    }
    if let Some(name) = args
        .tests
        .iter()
        .find(|&n| !reports.iter().any(|r| r.tests.iter().any(|t| &t.test == n)))
    {
        bail!("no monitor of the session has a calibratable test '{name}'");
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&reports)?);
    } else {
        print!("{}", render(&reports, args.far, epochs.len()));
    }
    if let Some(out) = &args.out {
        std::fs::write(out, serde_json::to_string_pretty(&bodies)? + "\n")
            .with_context(|| format!("writing {}", out.display()))?;
        eprintln!(
            "wrote {} PUT bodies to {} (e.g. jq '.NAME' {} | curl -X PUT -H 'content-type: application/json' -d @- …/monitors/NAME/threshold)",
            bodies.len(),
            out.display(),
            out.display()
        );
    }
    if bodies.is_empty() {
        bail!(
            "no test could be calibrated for a rate of {} (see above)",
            args.far
        );
    }
    Ok(())
}

/// The live options for one monitor: with `--tests`, only those of its tests (`None` when
/// it has none of them).
fn options(args: &CalibrateArgs, m: &mut dyn monitor::Monitor) -> Option<LiveOptions> {
    let mut options = LiveOptions {
        holdout: args.holdout,
        max_transfer: args.max_transfer,
        ..LiveOptions::new(args.far, args.confidence)
    };
    if !args.tests.is_empty() {
        let bank = m.tests_mut();
        let mine: Vec<String> = args
            .tests
            .iter()
            .filter(|t| bank.index_of(t).is_some())
            .cloned()
            .collect();
        if mine.is_empty() {
            return None;
        }
        options.tests = Some(mine);
    }
    Some(options)
}

fn render(reports: &[MonitorReport], far: f64, epochs: usize) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "calibration for a false-alarm rate of {far:e} per epoch, {epochs} epochs"
    );
    let _ = writeln!(
        s,
        "{:<12} {:<14} {:>4} {:>8} {:>12} {:>14} {:>12} {:>12} {:>8}",
        "monitor", "test", "dof", "epochs", "χ² thr", "χ² rate/far", "p_fa", "threshold", "σ scale"
    );
    for m in reports {
        for t in &m.tests {
            let (p, th) = match (t.p_fa, t.threshold) {
                (Some(p), Some(th)) => (format!("{p:.3e}"), format!("{th:.4}")),
                _ => ("—".into(), "—".into()),
            };
            let _ = writeln!(
                s,
                "{:<12} {:<14} {:>4} {:>8} {:>12.4} {:>13.2}× {:>12} {:>12} {:>8}",
                m.monitor,
                t.test,
                t.dof,
                t.epochs,
                t.chi2_threshold,
                t.chi2_rate / far,
                p,
                th,
                t.noise_scale.map_or("—".into(), |k| format!("{k:.3}"))
            );
            if let (Some(n), Some(rate)) = (t.holdout_epochs, t.holdout_rate) {
                let _ = writeln!(
                    s,
                    "{:<12} {:<14} live replays: {}; held out: {rate:.3e} of {n} epochs ({:.2}× far)",
                    "",
                    "",
                    t.replays.unwrap_or(0),
                    rate / far
                );
            }
            if let Some(why) = &t.refused {
                let _ = writeln!(s, "{:<12} {:<14} refused: {why}", "", "");
            }
        }
    }
    s
}
