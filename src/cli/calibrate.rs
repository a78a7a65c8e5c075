//! `navguard calibrate FILE.jsonl --session-spec SPEC.json --far 1e-4`: replays
//! fault-free data in-process through a session's monitors and proposes, per test, the
//! threshold that gives the requested false-alarm rate on it (docs/methods.md §M25),
//! beside the χ² threshold it replaces; `--out` writes the proposals as `PUT …/threshold`
//! bodies, one per monitor.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
use serde::Serialize;

use navguard::epoch::Epoch;
use navguard::monitor::calibrate::{self, Proposal, TestCalibration};
use navguard::monitor::{self, ModelSource, NoModels};
use navguard::service::Limits;
use navguard::service::session::spec::monitor_spec;
use navguard::service::store::Store;
use navguard::service::train::Models;
use navguard::service::wire::{CreateSession, TestThresholdSpec, parse_frame};

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
    /// A navguard store to take trained models from (for `channel`, `rimu`, `tacan`).
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
    tests: Vec<TestReport>,
}

/// One test's line of the report.
#[derive(Debug, Serialize)]
struct TestReport {
    test: String,
    dof: u32,
    epochs: usize,
    chi2_threshold: f64,
    chi2_rate: f64,
    /// The proposed level (the test's own `p_fa`), when calibrated.
    p_fa: Option<f64>,
    /// The raw threshold it gives at the primary dof.
    threshold: Option<f64>,
    /// Why not, when refused.
    refused: Option<String>,
}

impl From<&TestCalibration> for TestReport {
    fn from(c: &TestCalibration) -> Self {
        let (p_fa, threshold, refused) = match c.proposal {
            Proposal::Calibrated {
                p_fa, threshold, ..
            } => (Some(p_fa), Some(threshold), None),
            Proposal::TooShort { needed } => (
                None,
                None,
                Some(format!(
                    "too short: {} epochs, the rate asked needs at least {needed}",
                    c.epochs
                )),
            ),
        };
        TestReport {
            test: c.test.clone(),
            dof: c.dof,
            epochs: c.epochs,
            chi2_threshold: c.chi2_threshold,
            chi2_rate: c.chi2_rate,
            p_fa,
            threshold,
            refused,
        }
    }
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
    if !db.exists() {
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
        let samples = calibrate::sample(&mut *m, &epochs)
            .map_err(|e| anyhow::anyhow!("monitor '{}': {e}", wire.name))?;
        let mut tests = Vec::new();
        let mut body = PutBody {
            tests: BTreeMap::new(),
        };
        for s in &samples {
            let c = calibrate::calibrate(s, args.far, args.confidence)?;
            if let Proposal::Calibrated { p_fa, .. } = c.proposal {
                body.tests.insert(
                    c.test.clone(),
                    TestThresholdSpec {
                        p_fa: Some(p_fa),
                        threshold: None,
                    },
                );
            }
            tests.push(TestReport::from(&c));
        }
        if !body.tests.is_empty() {
            bodies.insert(wire.name.clone(), body);
        }
        reports.push(MonitorReport {
            monitor: wire.name.clone(),
            tests,
        });
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

fn render(reports: &[MonitorReport], far: f64, epochs: usize) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "calibration for a false-alarm rate of {far:e} per epoch, {epochs} epochs"
    );
    let _ = writeln!(
        s,
        "{:<12} {:<14} {:>4} {:>8} {:>12} {:>14} {:>12} {:>12}",
        "monitor", "test", "dof", "epochs", "χ² thr", "χ² rate/far", "p_fa", "threshold"
    );
    for m in reports {
        for t in &m.tests {
            let (p, th) = match (t.p_fa, t.threshold) {
                (Some(p), Some(th)) => (format!("{p:.3e}"), format!("{th:.4}")),
                _ => ("—".into(), "—".into()),
            };
            let _ = writeln!(
                s,
                "{:<12} {:<14} {:>4} {:>8} {:>12.4} {:>13.2}× {:>12} {:>12}",
                m.monitor,
                t.test,
                t.dof,
                t.epochs,
                t.chi2_threshold,
                t.chi2_rate / far,
                p,
                th
            );
            if let Some(why) = &t.refused {
                let _ = writeln!(s, "{:<12} {:<14} refused: {why}", "", "");
            }
        }
    }
    s
}
