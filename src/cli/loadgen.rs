//! `navguard loadgen`: a load generator for a running server (docs/performance.md). It
//! creates N sessions (`echo: true`) over REST, streams simulated epochs into
//! each one's ingest socket at a set rate or as fast as the server takes them,
//! and reports throughput, frame-to-result and alarm-to-event latency, errors,
//! per-epoch ordering, the server's resident memory (idle and loaded, from
//! `/metrics`) and the CPU time the server and the generator itself spent; then
//! deletes its sessions. `--ramp` repeats the run with more sessions each step
//! until the p99 crosses a limit ([`ramp`]).
//!
//! The workload is generated once and shared by the sessions: the `ship`
//! scenario of [`navguard_sim`] for `federated`, a synthetic car's raw IMU at
//! 100 Hz for `federated` with `--input imu` ([`imu`]; a few variants of it on
//! different seeds, session i streaming variant i mod their count), a
//! constant-velocity track for `linear`. A session streams it in passes; each pass is a fresh socket (the
//! server restarts filter state and time on a new stream, docs/architecture.md §A3), so a
//! long run never needs an unbounded scenario in memory. The tool talks only
//! to `--url`, stops after `--duration`, and waits at most a bounded time for
//! the last answers.

use std::ops::Range;
use std::path::PathBuf;
use std::str::FromStr;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, bail};
use futures_util::StreamExt;
use navguard::service::metrics::process_cpu_seconds;
use navguard::service::wire::{CreateSession, MonitorSpecWire, epoch_to_wire};
use navguard_core::detect::PolicyConfig;
use navguard_core::epoch::Aid;
use navguard_core::monitor::MonitorKind;
use navguard_core::monitor::linear::LinearConfigWire;
use navguard_sim::{self as sim, Channel, Fault, FaultKind};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use serde_json::Value;
use tokio::time::Instant;
use tokio_tungstenite::tungstenite::Utf8Bytes;

use super::http::Endpoint;
use super::{progress_bar, thousands};

mod imu;
mod ramp;
mod report;
mod stream;

use report::{CommitShare, CpuShare, Report, percentiles, render};
use stream::{Tally, run_session};

/// Most epochs generated for one pass (a pass is replayed on a fresh socket).
const MAX_PASS_EPOCHS: usize = 100_000;
/// Longest wait for the answers to frames already sent, after the last send.
const DRAIN_TIMEOUT: Duration = Duration::from_secs(20);
/// Sessions created or deleted concurrently.
const REST_CONCURRENCY: usize = 16;
/// Size of the GNSS position step (federated) or `z` step (linear) injected by `--fault-at`.
const FAULT_STEP: f64 = 100.0;
/// Most variants of the raw-IMU stream (each on its own seed) the sessions share.
const IMU_VARIANTS: u64 = 16;

/// Frames per second per session, or as fast as the server takes them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Rate {
    /// Back to back; the socket's backpressure sets the pace.
    Max,
    /// Frames per second per session.
    Hz(f64),
}

impl Rate {
    /// Frames per second per session; `None` for [`Rate::Max`].
    pub(crate) fn hz(self) -> Option<f64> {
        match self {
            Rate::Max => None,
            Rate::Hz(hz) => Some(hz),
        }
    }
}

impl FromStr for Rate {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        if s.eq_ignore_ascii_case("max") {
            return Ok(Rate::Max);
        }
        match s.parse::<f64>() {
            Ok(f) if f.is_finite() && f > 0.0 => Ok(Rate::Hz(f)),
            _ => Err(format!(
                "expected `max` or a positive rate in Hz, got {s:?}"
            )),
        }
    }
}

/// The monitor every loadgen session runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum MonitorArg {
    /// INS/GNSS/DVL/CNS federated filter on the simulated ship (15 states, 3 aids).
    Federated,
    /// 4-state constant-velocity Kalman filter with 2 measurements.
    Linear,
}

/// What a `federated` session's epochs carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum InputArg {
    /// The simulated ship's `ins` solutions with GNSS, DVL and CNS aids.
    Ins,
    /// A synthetic car's raw `imu` rates at 100 Hz with a 1 Hz `gnss` fix, mechanized
    /// by the monitor (`input: imu`, the real drive's config).
    Imu,
}

/// `navguard loadgen` flags.
#[derive(Debug, clap::Args)]
#[command(after_long_help = LOADGEN_HELP)]
pub(crate) struct LoadgenArgs {
    /// The server, as ws://host:port (REST calls go to http://host:port).
    #[arg(long, default_value = "ws://127.0.0.1:8080")]
    pub url: String,
    /// Bearer token for a server started with --token.
    #[arg(long, env = "NAVGUARD_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Sessions to create and stream into concurrently.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=100_000))]
    pub sessions: u64,
    /// Frames per second per session, or `max`.
    #[arg(long, default_value = "10")]
    pub rate: Rate,
    /// Epochs per frame (1 sends single-epoch objects, more send arrays).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=10_000))]
    pub batch: u64,
    /// How long to stream, seconds (then it waits for the last answers).
    #[arg(long, default_value_t = 10.0)]
    pub duration: f64,
    /// The monitor each session runs.
    #[arg(long, value_enum, default_value = "federated")]
    pub monitor: MonitorArg,
    /// What the federated sessions' epochs carry: `ins` solutions (the ship) or raw
    /// `imu` samples at 100 Hz (a car; `--rate 100 --batch 1` is real time, and so is
    /// `--rate 10 --batch 10`).
    #[arg(long, value_enum, default_value = "ins")]
    pub input: InputArg,
    /// Epoch time t (s) at which a 100 m step starts on GNSS position (federated)
    /// or on z[0] (linear), in every session and pass, lasting to the pass's end.
    #[arg(long)]
    pub fault_at: Option<f64>,
    /// RNG seed of the simulated workload.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Seconds to wait after creating the sessions before reading idle memory.
    #[arg(long, default_value_t = 1.0)]
    pub settle: f64,
    /// Print the report as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Ramp: after a first step of --sessions, add this many sessions per step
    /// (each step streams every session for --duration s) until the
    /// frame-to-result p99 reaches --ramp-p99-ms or --ramp-max is streamed.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=100_000))]
    pub ramp: Option<u64>,
    /// The frame-to-result p99 that ends a ramp, milliseconds.
    #[arg(long, default_value_t = 5.0, requires = "ramp")]
    pub ramp_p99_ms: f64,
    /// Most sessions a ramp streams.
    #[arg(long, default_value_t = 10_000, requires = "ramp",
          value_parser = clap::value_parser!(u64).range(1..=100_000))]
    pub ramp_max: u64,
    /// Write the ramp's curve (sessions against frame-to-result p50 and p99) to
    /// this SVG file.
    #[arg(long, requires = "ramp")]
    pub svg: Option<PathBuf>,
}

const LOADGEN_HELP: &str = "\
Examples (server in another terminal: cargo run --release -- serve --db /tmp/lg.db):
  navguard loadgen --sessions 1 --rate max --batch 200 --duration 10
  navguard loadgen --sessions 1000 --rate 10 --batch 1 --duration 30
  navguard loadgen --sessions 1 --rate 10 --fault-at 20 --duration 30
  navguard loadgen --input imu --sessions 200 --rate 100 --batch 1 --duration 40
  navguard loadgen --sessions 250 --ramp 250 --duration 10 --svg ramp.svg
Latency: frame-to-result is from just before a frame is written to the socket
to the arrival of the `result` of its last epoch; alarm-to-event is from the
sending of the frame holding the epoch an alarm names to the alarm's arrival.
Idle memory per session is (RSS after creating the sessions − RSS before) / N,
read from the server's process_resident_memory_bytes; loaded memory per
session is (RSS at the end of the stream − RSS before) / N. CPU is the server's
process_cpu_seconds_total and the generator's own over the stream, in cores
(CPU s / wall s). A ramp's steps keep the sessions of the steps before and
stream all of them again; it reports the largest count whose p99 stayed under
the limit with every frame answered. Sessions are named loadgen-PID-I and
deleted at the end.";

/// The workload shared by the sessions: pre-serialised frames of one pass.
struct Workload {
    /// Frames of each variant of the pass, ready to send (cloning shares the bytes);
    /// every variant has the same epoch times. Session i streams variant i mod their count.
    frames: Vec<Vec<Utf8Bytes>>,
    /// Epoch indices of each frame.
    ranges: Vec<Range<usize>>,
    /// `t` of every epoch of the pass.
    times: Vec<f64>,
    /// `POST /api/v1/sessions` body without its `id`.
    spec: CreateSession,
}

impl Workload {
    fn build(args: &LoadgenArgs) -> anyhow::Result<Workload> {
        let per_session = match args.rate {
            Rate::Max => MAX_PASS_EPOCHS as f64,
            Rate::Hz(hz) => (hz * args.duration * args.batch as f64).ceil() + args.batch as f64,
        };
        let epochs = (per_session.min(MAX_PASS_EPOCHS as f64) as usize).max(args.batch as usize);
        let (variants, spec) = match (args.monitor, args.input) {
            (MonitorArg::Federated, InputArg::Ins) => {
                let (lines, spec) = federated_lines(epochs, args.seed, args.fault_at)?;
                (vec![lines], spec)
            }
            (MonitorArg::Federated, InputArg::Imu) => {
                let most = args.ramp.map_or(args.sessions, |_| args.ramp_max);
                imu_lines(epochs, args.seed, args.fault_at, most.min(IMU_VARIANTS))?
            }
            (MonitorArg::Linear, InputArg::Ins) => {
                let (lines, spec) = linear_lines(epochs, args.seed, args.fault_at);
                (vec![lines], spec)
            }
            (MonitorArg::Linear, InputArg::Imu) => {
                bail!("--input imu needs --monitor federated")
            }
        };
        let times: Vec<f64> = variants[0].iter().map(|(t, _)| *t).collect();
        let batch = args.batch as usize;
        let ranges: Vec<Range<usize>> = (0..times.len())
            .step_by(batch)
            .map(|start| start..(start + batch).min(times.len()))
            .collect();
        let frames = variants
            .iter()
            .map(|lines| frames_of(lines, batch))
            .collect();
        Ok(Workload {
            frames,
            ranges,
            times,
            spec,
        })
    }

    fn epochs(&self) -> usize {
        self.times.len()
    }

    /// Frames in one pass.
    fn frame_count(&self) -> usize {
        self.ranges.len()
    }

    /// The frames session `i` streams.
    fn frames_of_session(&self, i: usize) -> &[Utf8Bytes] {
        &self.frames[i % self.frames.len()]
    }
}

/// Each epoch's time and wire line.
type Lines = Vec<(f64, String)>;

/// Wire lines grouped `batch` to a frame: a line alone for 1, arrays for more.
fn frames_of(lines: &[(f64, String)], batch: usize) -> Vec<Utf8Bytes> {
    lines
        .chunks(batch)
        .map(|chunk| {
            let text = if batch == 1 {
                chunk[0].1.clone()
            } else {
                let mut text = String::with_capacity(chunk.iter().map(|l| l.1.len() + 1).sum());
                text.push('[');
                for (i, (_, line)) in chunk.iter().enumerate() {
                    if i > 0 {
                        text.push(',');
                    }
                    text.push_str(line);
                }
                text.push(']');
                text
            };
            Utf8Bytes::from(text)
        })
        .collect()
}

/// The ship scenario (10 Hz INS, GNSS and DVL at 1 Hz, CNS at 0.1 Hz) as wire lines.
fn federated_lines(
    epochs: usize,
    seed: u64,
    fault_at: Option<f64>,
) -> anyhow::Result<(Vec<(f64, String)>, CreateSession)> {
    let faults = fault_at
        .map(|start_s| {
            vec![Fault {
                aid: Aid::Gnss,
                channel: Channel::Position,
                component: 1,
                kind: FaultKind::Step { value: FAULT_STEP },
                start_s,
                end_s: None,
            }]
        })
        .unwrap_or_default();
    let duration = (epochs - 1) as f64 / sim::SHIP_INS_RATE_HZ;
    let scenario = sim::ship_with(seed, faults, duration).context("simulating the ship")?;
    let lines = scenario
        .epochs
        .iter()
        .map(|e| {
            epoch_to_wire(&e.epoch)
                .map(|line| (e.epoch.t, line))
                .map_err(|e| anyhow::anyhow!("serialising a simulated epoch: {}", e.message))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let config = federated_config(&scenario)?;
    Ok((lines, echo_session(MonitorKind::Federated, config)))
}

/// `variants` raw-IMU drives on seeds `seed`, `seed + 1`, … as wire lines, and the
/// session body of a `federated` monitor with `input: imu` on the real drive's config.
fn imu_lines(
    epochs: usize,
    seed: u64,
    fault_at: Option<f64>,
    variants: u64,
) -> anyhow::Result<(Vec<Lines>, CreateSession)> {
    let lines = (0..variants.max(1))
        .map(|v| {
            imu::drive(epochs, seed.wrapping_add(v), fault_at, FAULT_STEP)
                .iter()
                .map(|d| {
                    epoch_to_wire(&d.epoch)
                        .map(|line| (d.epoch.t, line))
                        .map_err(|e| anyhow::anyhow!("serialising an IMU epoch: {}", e.message))
                })
                .collect::<anyhow::Result<Vec<_>>>()
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok((
        lines,
        echo_session(MonitorKind::Federated, imu::monitor_config()),
    ))
}

/// The `federated` config for the simulated ship: its aids, IMU and initial errors.
fn federated_config(scenario: &sim::Scenario) -> anyhow::Result<Value> {
    serde_json::to_value(scenario.monitor_config()).context("serialising the federated config")
}

/// A session body (no id) with one monitor of `kind`, named after it, under
/// the counters policy (N1 10, N2 5), echoing every result.
fn echo_session(kind: MonitorKind, config: Value) -> CreateSession {
    CreateSession {
        id: None,
        monitors: vec![MonitorSpecWire {
            name: kind.as_str().to_owned(),
            kind,
            config,
            policy: PolicyConfig::Counters { n1: 10, n2: 5 },
            p_fa: None,
            threshold: None,
            alarm_level: None,
            tests: Default::default(),
        }],
        echo: true,
        alarm_level: None,
        record: None,
    }
}

/// A constant-velocity target seen in x and y with correlated noise, 10 Hz.
fn linear_lines(
    epochs: usize,
    seed: u64,
    fault_at: Option<f64>,
) -> (Vec<(f64, String)>, CreateSession) {
    let mut rng = StdRng::seed_from_u64(seed);
    let noise = Normal::new(0.0, 1.0).expect("unit normal");
    let dt = 0.1;
    let lines = (0..epochs)
        .map(|k| {
            let t = k as f64 * dt;
            let step = if fault_at.is_some_and(|f| t >= f) {
                FAULT_STEP
            } else {
                0.0
            };
            let x = t + noise.sample(&mut rng) + step;
            let y = -t + 1.4 * noise.sample(&mut rng);
            (t, format!(r#"{{"t":{t},"z":[{x},{y}]}}"#))
        })
        .collect();
    let config = serde_json::to_value(linear_config(dt)).expect("finite matrices serialise");
    (lines, echo_session(MonitorKind::Linear, config))
}

/// The `linear` config: a 2-D constant-velocity model sampled every `dt` s,
/// seeing x and y with variances 1 and 1.96.
fn linear_config(dt: f64) -> LinearConfigWire {
    let q = 0.05 * dt;
    let (a, b) = (q * dt * dt / 3.0, q * dt / 2.0);
    LinearConfigWire {
        f: vec![
            vec![1.0, dt, 0.0, 0.0],
            vec![0.0, 1.0, 0.0, 0.0],
            vec![0.0, 0.0, 1.0, dt],
            vec![0.0, 0.0, 0.0, 1.0],
        ],
        h: vec![vec![1.0, 0.0, 0.0, 0.0], vec![0.0, 0.0, 1.0, 0.0]],
        q: vec![
            vec![a, b, 0.0, 0.0],
            vec![b, q, 0.0, 0.0],
            vec![0.0, 0.0, a, b],
            vec![0.0, 0.0, b, q],
        ],
        r: vec![vec![1.0, 0.0], vec![0.0, 1.96]],
        x0: vec![0.0, 1.0, 0.0, -1.0],
        p0: diagonal(&[5.0; 4]),
        b: None,
        drift: None,
        stuck: None,
    }
}

/// A square matrix with `d` on its diagonal, as nested rows.
fn diagonal(d: &[f64]) -> Vec<Vec<f64>> {
    (0..d.len())
        .map(|i| {
            (0..d.len())
                .map(|j| if i == j { d[i] } else { 0.0 })
                .collect()
        })
        .collect()
}

/// The server's resident memory and CPU time at one moment, from `/metrics`
/// (`None` where the server does not export them, as off Linux).
#[derive(Debug, Clone, Default)]
struct ServerSample {
    /// `process_resident_memory_bytes`.
    rss: Option<u64>,
    /// `process_cpu_seconds_total`.
    cpu_s: Option<f64>,
    /// `navguard_alarm_commit_seconds` as cumulative `(upper bound s, count)` buckets,
    /// `+Inf` last (empty when the server does not export it).
    alarm_commit: Vec<(f64, u64)>,
}

/// Reads the server's `/metrics`.
async fn server_sample(endpoint: &Endpoint) -> anyhow::Result<ServerSample> {
    let (status, body) = endpoint.call("GET", "/metrics").await?;
    if status != 200 {
        bail!("GET /metrics: HTTP {status}");
    }
    Ok(sample_of_metrics(&body))
}

/// The process metrics and the alarm-commit histogram of a Prometheus text page.
fn sample_of_metrics(body: &str) -> ServerSample {
    let alarm_commit = body
        .lines()
        .filter_map(|line| {
            let rest = line.strip_prefix("navguard_alarm_commit_seconds_bucket{le=\"")?;
            let (bound, count) = rest.split_once("\"} ")?;
            let bound = if bound == "+Inf" {
                f64::INFINITY
            } else {
                bound.parse().ok()?
            };
            Some((bound, count.trim().parse().ok()?))
        })
        .collect();
    let value = |name: &str| {
        body.lines().find_map(|line| {
            let v = line.strip_prefix(name)?.strip_prefix(' ')?;
            v.trim().parse::<f64>().ok()
        })
    };
    ServerSample {
        rss: value("process_resident_memory_bytes").map(|v| v as u64),
        cpu_s: value("process_cpu_seconds_total"),
        alarm_commit,
    }
}

/// Runs `f` over `items` with at most [`REST_CONCURRENCY`] at a time.
async fn each_concurrently<T, F, Fut>(items: Vec<T>, f: F) -> Vec<anyhow::Result<()>>
where
    F: Fn(T) -> Fut,
    Fut: std::future::Future<Output = anyhow::Result<()>>,
{
    futures_util::stream::iter(items.into_iter().map(f))
        .buffer_unordered(REST_CONCURRENCY)
        .collect()
        .await
}

async fn create_session(endpoint: &Endpoint, spec: &CreateSession, id: &str) -> anyhow::Result<()> {
    let body = CreateSession {
        id: Some(id.to_owned()),
        ..spec.clone()
    };
    let (status, text) = endpoint
        .request("POST", "/api/v1/sessions", Some(&body))
        .await?;
    match status {
        201 => Ok(()),
        401 => bail!("unauthorized; pass --token"),
        s => bail!("creating session '{id}': HTTP {s}: {text}"),
    }
}

/// Creates every session of `ids` (at most [`REST_CONCURRENCY`] at a time); the
/// first failure, if any. The caller deletes what was created.
async fn create_sessions(
    endpoint: &Endpoint,
    spec: &CreateSession,
    ids: &[String],
) -> anyhow::Result<()> {
    let created = each_concurrently(ids.to_vec(), |id| async move {
        create_session(endpoint, spec, &id).await
    })
    .await;
    created.into_iter().find(Result::is_err).unwrap_or(Ok(()))
}

async fn delete_sessions(endpoint: &Endpoint, ids: Vec<String>) -> usize {
    let results = each_concurrently(ids, |id| async move {
        let (status, text) = endpoint
            .call("DELETE", &format!("/api/v1/sessions/{id}"))
            .await?;
        match status {
            204 | 404 => Ok(()),
            s => bail!("deleting session '{id}': HTTP {s}: {text}"),
        }
    })
    .await;
    results.iter().filter(|r| r.is_err()).count()
}

/// Runs the command.
pub(crate) async fn run(args: LoadgenArgs) -> anyhow::Result<()> {
    if !(args.duration.is_finite() && args.duration > 0.0) {
        bail!("--duration must be a positive number of seconds");
    }
    if let Some(t) = args.fault_at
        && !(t.is_finite() && t >= 0.0)
    {
        bail!("--fault-at must be a non-negative epoch time, s");
    }
    if !(args.ramp_p99_ms.is_finite() && args.ramp_p99_ms > 0.0) {
        bail!("--ramp-p99-ms must be a positive number of milliseconds");
    }
    let endpoint = Arc::new(Endpoint::parse(&args.url, args.token.clone())?);
    let work = Arc::new(Workload::build(&args)?);
    if !args.json {
        eprintln!(
            "workload: {} epochs per pass in {} frames of ≤ {}",
            thousands(work.epochs() as u64),
            thousands(work.frame_count() as u64),
            args.batch
        );
    }
    if let Some(step) = args.ramp {
        return ramp::run(&args, step, &endpoint, &work).await;
    }
    let baseline = server_sample(&endpoint).await?;
    let ids = session_ids(0..args.sessions);
    if let Err(e) = create_sessions(&endpoint, &work.spec, &ids).await {
        delete_sessions(&endpoint, ids).await;
        return Err(e.context("creating the sessions (the ones created were deleted)"));
    }
    let measured = measure(&args, &endpoint, &work, &ids, baseline).await;
    let undeleted = delete_sessions(&endpoint, ids).await;
    if undeleted > 0 {
        eprintln!("warning: {undeleted} sessions could not be deleted");
    }
    let report = measured?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", render(&report));
    }
    if report.failures.is_empty() {
        Ok(())
    } else {
        bail!("{} session(s) failed", report.failures.len())
    }
}

/// Session names `loadgen-PID-I` for `I` in `range`.
fn session_ids(range: Range<u64>) -> Vec<String> {
    range
        .map(|i| format!("loadgen-{}-{i}", std::process::id()))
        .collect()
}

/// One measured run over the sessions `ids` (already created): settles, reads
/// the idle server, streams every session for `--duration`, and reports
/// against `baseline` (the server before any session was created).
async fn measure(
    args: &LoadgenArgs,
    endpoint: &Arc<Endpoint>,
    work: &Arc<Workload>,
    ids: &[String],
    baseline: ServerSample,
) -> anyhow::Result<Report> {
    tokio::time::sleep(Duration::from_secs_f64(args.settle.max(0.0))).await;
    let idle = server_sample(endpoint).await?;
    let progress = progress_bar(
        (args.duration * 10.0).ceil() as u64,
        "[{bar:24}] {percent:>3}% {elapsed} of the run  {msg}",
        !args.json,
    );
    progress.set_message(format!("{} session(s)", ids.len()));
    let ticker = {
        let progress = progress.clone();
        tokio::spawn(async move {
            let start = Instant::now();
            loop {
                progress.set_position((start.elapsed().as_secs_f64() * 10.0) as u64);
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        })
    };
    let own_before = process_cpu_seconds();
    let (tally, wall_s) = stream(args, endpoint, work, ids).await;
    let own_after = process_cpu_seconds();
    ticker.abort();
    progress.finish_and_clear();
    let loaded = server_sample(endpoint).await.unwrap_or_default();
    let cores = |before: Option<f64>, after: Option<f64>| match (before, after) {
        (Some(b), Some(a)) if wall_s > 0.0 => Some((a - b) / wall_s),
        _ => None,
    };
    let cpu = CpuShare::new(
        cores(idle.cpu_s, loaded.cpu_s),
        cores(own_before, own_after),
    );
    let alarm_commit = CommitShare::between(&idle.alarm_commit, &loaded.alarm_commit);
    Ok(report(
        args,
        ids.len() as u64,
        tally,
        wall_s,
        [baseline, idle, loaded],
        cpu,
        alarm_commit,
    ))
}

async fn stream(
    args: &LoadgenArgs,
    endpoint: &Arc<Endpoint>,
    work: &Arc<Workload>,
    ids: &[String],
) -> (Tally, f64) {
    let started = Instant::now();
    let deadline = started + Duration::from_secs_f64(args.duration);
    let period = match args.rate {
        Rate::Max => Duration::ZERO,
        Rate::Hz(hz) => Duration::from_secs_f64(1.0 / hz),
    };
    let n = ids.len() as u32;
    let tasks: Vec<_> = ids
        .iter()
        .enumerate()
        .map(|(i, id)| {
            // Spread the sessions' first frames over one period.
            let phase = period * i as u32 / n.max(1);
            tokio::spawn(run_session(
                endpoint.clone(),
                id.clone(),
                work.clone(),
                i,
                args.rate,
                phase,
                deadline,
            ))
        })
        .collect();
    let mut total = Tally::default();
    for task in tasks {
        match task.await {
            Ok(tally) => total.merge(tally),
            Err(e) => total.failures.push(format!("a session task failed: {e}")),
        }
    }
    let end = total.last_answer.unwrap_or_else(Instant::now);
    (total, (end - started).as_secs_f64())
}

/// The workload's name in reports: the monitor, and `/imu` for raw-IMU input.
fn workload_label(args: &LoadgenArgs) -> String {
    match (args.monitor, args.input) {
        (MonitorArg::Federated, InputArg::Imu) => "federated/imu".into(),
        (monitor, _) => format!("{monitor:?}").to_lowercase(),
    }
}

fn report(
    args: &LoadgenArgs,
    sessions: u64,
    mut t: Tally,
    wall_s: f64,
    samples: [ServerSample; 3],
    cpu: CpuShare,
    alarm_commit: Option<CommitShare>,
) -> Report {
    let per_s = |n: u64| if wall_s > 0.0 { n as f64 / wall_s } else { 0.0 };
    let [baseline, idle, loaded] = samples.map(|s| s.rss);
    let per_session = |after: Option<u64>| match (baseline, after) {
        (Some(b), Some(a)) => Some((a as f64 - b as f64) / sessions as f64),
        _ => None,
    };
    Report {
        url: args.url.clone(),
        monitor: workload_label(args),
        sessions,
        rate_hz: args.rate.hz(),
        batch: args.batch,
        wall_s,
        epochs_sent: t.epochs_sent,
        frames_sent: t.frames_sent,
        results: t.results,
        out_of_order: t.out_of_order,
        unanswered_frames: t.unanswered_frames,
        passes: t.passes,
        epochs_per_s: per_s(t.results),
        frames_per_s: per_s(t.frames_answered),
        frame_latency: percentiles(&mut t.frame_latency_us),
        alarm_latency: percentiles(&mut t.alarm_latency_us),
        alarm_commit,
        alarms: t.alarms,
        state_changes: t.states,
        errors: t.errors,
        failures: t.failures,
        rss_baseline_bytes: baseline,
        rss_idle_bytes: idle,
        rss_loaded_bytes: loaded,
        idle_bytes_per_session: per_session(idle),
        loaded_bytes_per_session: per_session(loaded),
        cpu,
    }
}

#[cfg(test)]
mod tests {
    use super::stream::result_t;
    use super::*;
    use clap::Parser;
    use futures_util::SinkExt;
    use serde_json::json;
    use tokio_tungstenite::tungstenite::Message;

    #[derive(Parser)]
    struct Wrap {
        #[command(flatten)]
        args: LoadgenArgs,
    }

    fn args(extra: &[&str]) -> LoadgenArgs {
        Wrap::parse_from(std::iter::once("loadgen").chain(extra.iter().copied())).args
    }

    #[test]
    fn rates_parse_as_hz_or_max() {
        assert_eq!("max".parse::<Rate>(), Ok(Rate::Max));
        assert_eq!("12.5".parse::<Rate>(), Ok(Rate::Hz(12.5)));
        assert!("0".parse::<Rate>().is_err());
        assert!("fast".parse::<Rate>().is_err());
    }

    #[test]
    fn result_t_reads_the_leading_time_only_of_results() {
        assert_eq!(
            result_t(r#"{"type":"result","t":12.5,"monitors":{}}"#),
            Some(12.5)
        );
        assert_eq!(result_t(r#"{"type":"alarm","t":12.5}"#), None);
    }

    #[test]
    fn the_process_metrics_are_read_by_their_exact_names() {
        let page = "# TYPE process_resident_memory_bytes gauge\n\
                    process_resident_memory_bytes 1048576\n\
                    process_cpu_seconds_total_other 9\n\
                    process_cpu_seconds_total 12.5\n";
        let s = sample_of_metrics(page);
        assert_eq!((s.rss, s.cpu_s), (Some(1_048_576), Some(12.5)));
        let none = sample_of_metrics("navguard_sessions 3\n");
        assert_eq!((none.rss, none.cpu_s), (None, None));
    }

    #[test]
    fn the_server_commit_share_is_the_histogram_difference_over_the_stream() {
        let page = |counts: [u64; 4]| {
            format!(
                "navguard_frame_latency_seconds_bucket{{le=\"0.001\"}} 99\n\
                 navguard_alarm_commit_seconds_bucket{{le=\"0.001\"}} {}\n\
                 navguard_alarm_commit_seconds_bucket{{le=\"0.01\"}} {}\n\
                 navguard_alarm_commit_seconds_bucket{{le=\"0.05\"}} {}\n\
                 navguard_alarm_commit_seconds_bucket{{le=\"+Inf\"}} {}\n\
                 navguard_alarm_commit_seconds_count {}\n",
                counts[0], counts[1], counts[2], counts[3], counts[3]
            )
        };
        let before = sample_of_metrics(&page([5, 5, 5, 5]));
        assert_eq!(
            before.alarm_commit,
            vec![(0.001, 5), (0.01, 5), (0.05, 5), (f64::INFINITY, 5)]
        );
        // 100 entries during the stream: 10 under 1 ms, 50 more under 10 ms, 39 more
        // under 50 ms, one over: the median falls in (1, 10] ms, the 99th in (10, 50].
        let after = sample_of_metrics(&page([15, 65, 104, 105]));
        let share = CommitShare::between(&before.alarm_commit, &after.alarm_commit).unwrap();
        assert_eq!(share.count, 100);
        assert_eq!(share.p50_le_ms, Some(10.0));
        assert_eq!(share.p99_le_ms, Some(50.0));
        // Two entries over the last finite bound are "beyond the buckets", not a number.
        let after = sample_of_metrics(&page([5, 5, 103, 105]));
        let share = CommitShare::between(&before.alarm_commit, &after.alarm_commit).unwrap();
        assert_eq!((share.p50_le_ms, share.p99_le_ms), (Some(50.0), None));
        // Nothing committed, an older server without the histogram, or other buckets.
        let idle = CommitShare::between(&before.alarm_commit, &before.alarm_commit).unwrap();
        assert_eq!((idle.count, idle.p50_le_ms), (0, None));
        assert_eq!(CommitShare::between(&[], &[]), None);
        assert_eq!(
            CommitShare::between(&[(0.002, 1), (f64::INFINITY, 1)], &after.alarm_commit),
            None
        );
    }

    #[test]
    fn percentiles_use_the_nearest_rank() {
        let mut v: Vec<u32> = (1..=1000).rev().collect();
        let p = percentiles(&mut v);
        assert_eq!(
            (p.count, p.p50_us, p.p99_us, p.p999_us, p.max_us),
            (1000, 500, 990, 999, 1000)
        );
        assert_eq!(percentiles(&mut []).count, 0);
    }

    #[test]
    fn a_linear_workload_is_batched_into_arrays_with_every_epoch_once() {
        let a = args(&[
            "--monitor",
            "linear",
            "--rate",
            "10",
            "--duration",
            "2",
            "--batch",
            "3",
        ]);
        let w = Workload::build(&a).unwrap();
        // 10 Hz × 2 s × 3 epochs + one spare frame = 63 epochs in 21 frames.
        assert_eq!((w.epochs(), w.frame_count()), (63, 21));
        let first: Value = serde_json::from_str(w.frames[0][0].as_str()).unwrap();
        assert_eq!(first.as_array().map(Vec::len), Some(3));
        assert_eq!(first[1]["t"], json!(0.1));
        assert_eq!(w.ranges[20], 60..63);
        assert_eq!(w.spec.monitors[0].kind, MonitorKind::Linear);
        assert_eq!(
            w.spec.monitors[0].config["r"],
            json!([[1.0, 0.0], [0.0, 1.96]])
        );
    }

    #[test]
    fn a_federated_workload_carries_the_ship_and_its_monitor() {
        let a = args(&["--rate", "1", "--duration", "2", "--fault-at", "1"]);
        let w = Workload::build(&a).unwrap();
        assert_eq!(w.epochs(), 3);
        let first: Value = serde_json::from_str(w.frames[0][0].as_str()).unwrap();
        assert!(first["ins"].is_object() && first["gnss"].is_object());
        assert!(w.spec.echo);
        assert_eq!(w.spec.monitors[0].kind, MonitorKind::Federated);
        assert_eq!(
            w.spec.monitors[0].policy,
            PolicyConfig::Counters { n1: 10, n2: 5 }
        );
    }

    #[test]
    fn an_imu_workload_streams_100_hz_rates_with_a_fix_a_second_in_variants() {
        let a = args(&[
            "--input",
            "imu",
            "--sessions",
            "3",
            "--rate",
            "10",
            "--batch",
            "10",
            "--duration",
            "2",
        ]);
        let w = Workload::build(&a).unwrap();
        // 10 frames/s × 2 s × 10 epochs + one spare frame, at 100 Hz.
        assert_eq!((w.epochs(), w.frame_count()), (210, 21));
        assert!((w.times[1] - 0.01).abs() < 1e-12);
        // One variant per session (up to IMU_VARIANTS), the same times in each.
        assert_eq!(w.frames.len(), 3);
        assert_ne!(w.frames_of_session(0)[0], w.frames_of_session(1)[0]);
        assert_eq!(w.frames_of_session(3)[0], w.frames_of_session(0)[0]);
        let first: Value = serde_json::from_str(w.frames[1][0].as_str()).unwrap();
        let epochs = first.as_array().unwrap();
        assert_eq!(epochs.len(), 10);
        assert!(epochs[0]["imu"]["f"].is_array() && epochs[0]["imu"]["w"].is_array());
        assert!(epochs[0]["gnss"]["vel"].is_array());
        assert!(epochs[1].get("gnss").is_none() && epochs[1].get("ins").is_none());
        let second: Value = serde_json::from_str(w.frames[1][10].as_str()).unwrap();
        assert_eq!(second[0]["t"], json!(1.0));
        assert!(second[0]["gnss"].is_object());
        let spec = &w.spec.monitors[0];
        assert_eq!(spec.kind, MonitorKind::Federated);
        assert_eq!(spec.config["input"], "imu");
        assert_eq!(
            spec.config["strapdown"]["mounting_deg"],
            json!([0.0, 0.0, 0.0])
        );
        assert_eq!(workload_label(&a), "federated/imu");
        // Sixteen variants at most, however many sessions.
        let many = args(&["--input", "imu", "--sessions", "1000", "--duration", "0.1"]);
        assert_eq!(Workload::build(&many).unwrap().frames.len(), 16);
    }

    /// The raw-IMU workload through a real server on port 0: the session's monitor levels
    /// over the stop, takes the heading from the first fix at speed, then tests every fix,
    /// healthy throughout.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn an_imu_session_aligns_on_a_real_server_then_tests_every_fix() {
        let dir = tempfile::tempdir().unwrap();
        let server = navguard::service::start(navguard::service::ServiceConfig::new(
            "127.0.0.1:0".parse().unwrap(),
            dir.path().join("imu.db"),
        ))
        .await
        .unwrap();
        let url = format!("ws://{}", server.addr);
        // 1 frame/s of 100 epochs for 29 s: 30 s of the drive, in 30 frames.
        let a = args(&["--url", &url, "--input", "imu", "--rate", "1"]);
        let a = LoadgenArgs {
            batch: 100,
            duration: 29.0,
            ..a
        };
        let w = Workload::build(&a).unwrap();
        assert_eq!(w.epochs(), 3_000);
        let endpoint = Endpoint::parse(&url, None).unwrap();
        create_session(&endpoint, &w.spec, "imu").await.unwrap();
        let socket = endpoint
            .connect("/api/v1/sessions/imu/ingest")
            .await
            .unwrap();
        let (mut sink, mut stream) = socket.split();
        for frame in w.frames_of_session(0) {
            sink.send(Message::Text(frame.clone())).await.unwrap();
        }
        let (mut results, mut aligned_at, mut gnss_tests) = (0, None, 0);
        while results < w.epochs() {
            let message = tokio::time::timeout(Duration::from_secs(60), stream.next())
                .await
                .expect("results keep coming")
                .expect("the socket is open")
                .expect("no socket error");
            let Message::Text(text) = message else {
                continue;
            };
            let v: Value = serde_json::from_str(&text).unwrap();
            // Availability and state changes may come too; no alarm, no error.
            assert!(v["type"] != "alarm" && v["type"] != "error", "{v}");
            if v["type"] != "result" {
                continue;
            }
            let m = &v["monitors"]["federated"];
            if m["alignment"] == "aligned" && aligned_at.is_none() {
                aligned_at = v["t"].as_f64();
            }
            if let Some(gnss) = m["tests"].get("gnss") {
                assert_eq!(gnss["state"], "healthy", "{v}");
                gnss_tests += 1;
            }
            results += 1;
        }
        let at = aligned_at.expect("the monitor aligned");
        assert!(
            (imu::STATIC_S..imu::STATIC_S + 5.0).contains(&at),
            "aligned at {at} s"
        );
        // A fix a second from alignment to the drive's 30th second.
        assert!(gnss_tests >= 14, "{gnss_tests} gnss tests");
        sink.close().await.unwrap();
        server.shutdown().await;
    }

    #[test]
    fn imu_input_needs_the_federated_monitor() {
        let a = args(&["--input", "imu", "--monitor", "linear"]);
        let err = Workload::build(&a).err().unwrap();
        assert!(err.to_string().contains("--monitor federated"), "{err}");
    }
}
