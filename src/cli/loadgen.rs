//! `navguard loadgen`: a load generator for a running server (DESIGN §5). It
//! creates N sessions (`echo: true`) over REST, streams simulated epochs into
//! each one's ingest socket at a set rate or as fast as the server takes them,
//! and reports throughput, frame-to-result and alarm-to-event latency, errors,
//! per-epoch ordering, and the server's resident memory (idle and loaded, from
//! `/metrics`); then deletes its sessions.
//!
//! The workload is generated once and shared by every session: the `ship`
//! scenario of [`navguard::sim`] for `federated`, a constant-velocity track for
//! `linear`. A session streams it in passes; each pass is a fresh socket (the
//! server restarts filter state and time on a new stream, DESIGN §4.1), so a
//! long run never needs an unbounded scenario in memory. The tool talks only
//! to `--url`, stops after `--duration`, and waits at most a bounded time for
//! the last answers.

use std::collections::{BTreeMap, VecDeque};
use std::fmt::Write as _;
use std::ops::Range;
use std::str::FromStr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{Context, bail};
use futures_util::{SinkExt, StreamExt};
use navguard::service::wire::epoch_to_wire;
use navguard::sim::{self, Aid, Channel, Fault, FaultKind};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use serde::Serialize;
use serde_json::{Value, json};
use tokio::sync::Notify;
use tokio::time::{Instant, MissedTickBehavior};
use tokio_tungstenite::tungstenite::{Message, Utf8Bytes};

use super::http::Endpoint;
use super::progress::thousands;

/// Most epochs generated for one pass (a pass is replayed on a fresh socket).
const MAX_PASS_EPOCHS: usize = 100_000;
/// Longest wait for the answers to frames already sent, after the last send.
const DRAIN_TIMEOUT: Duration = Duration::from_secs(20);
/// Sessions created or deleted concurrently.
const REST_CONCURRENCY: usize = 16;
/// Size of the GNSS position step (federated) or `z` step (linear) injected by `--fault-at`.
const FAULT_STEP: f64 = 100.0;

/// Frames per second per session, or as fast as the server takes them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rate {
    /// Back to back; the socket's backpressure sets the pace.
    Max,
    /// Frames per second per session.
    Hz(f64),
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
pub enum MonitorArg {
    /// INS/GNSS/DVL/CNS federated filter on the simulated ship (15 states, 3 aids).
    Federated,
    /// 4-state constant-velocity Kalman filter with 2 measurements.
    Linear,
}

/// `navguard loadgen` flags.
#[derive(Debug, clap::Args)]
#[command(after_long_help = LOADGEN_HELP)]
pub struct LoadgenArgs {
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
}

const LOADGEN_HELP: &str = "\
Examples (server in another terminal: cargo run --release -- serve --db /tmp/lg.db):
  navguard loadgen --sessions 1 --rate max --batch 200 --duration 10
  navguard loadgen --sessions 1000 --rate 10 --batch 1 --duration 30
  navguard loadgen --sessions 1 --rate 10 --fault-at 20 --duration 30
Latency: frame-to-result is from just before a frame is written to the socket
to the arrival of the `result` of its last epoch; alarm-to-event is from the
sending of the frame holding the epoch an alarm names to the alarm's arrival.
Idle memory per session is (RSS after creating the sessions − RSS before) / N,
read from the server's process_resident_memory_bytes. Sessions are named
loadgen-PID-I and deleted at the end.";

/// The workload shared by every session: pre-serialised frames of one pass.
struct Workload {
    /// Frames, ready to send (cloning shares the bytes).
    frames: Vec<Utf8Bytes>,
    /// Epoch indices of each frame.
    ranges: Vec<Range<usize>>,
    /// `t` of every epoch of the pass.
    times: Vec<f64>,
    /// `POST /api/v1/sessions` body without its `id`.
    spec: Value,
}

impl Workload {
    fn build(args: &LoadgenArgs) -> anyhow::Result<Workload> {
        let per_session = match args.rate {
            Rate::Max => MAX_PASS_EPOCHS as f64,
            Rate::Hz(hz) => (hz * args.duration * args.batch as f64).ceil() + args.batch as f64,
        };
        let epochs = (per_session.min(MAX_PASS_EPOCHS as f64) as usize).max(args.batch as usize);
        let (lines, spec) = match args.monitor {
            MonitorArg::Federated => federated_lines(epochs, args.seed, args.fault_at)?,
            MonitorArg::Linear => linear_lines(epochs, args.seed, args.fault_at),
        };
        let times = lines.iter().map(|(t, _)| *t).collect();
        let batch = args.batch as usize;
        let mut frames = Vec::with_capacity(lines.len().div_ceil(batch));
        let mut ranges = Vec::with_capacity(frames.capacity());
        for (k, chunk) in lines.chunks(batch).enumerate() {
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
            frames.push(Utf8Bytes::from(text));
            ranges.push(k * batch..k * batch + chunk.len());
        }
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
}

/// The ship scenario (10 Hz INS, GNSS and DVL at 1 Hz, CNS at 0.1 Hz) as wire lines.
fn federated_lines(
    epochs: usize,
    seed: u64,
    fault_at: Option<f64>,
) -> anyhow::Result<(Vec<(f64, String)>, Value)> {
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
    let monitor = json!({
        "name": "federated",
        "type": "federated",
        "config": scenario.default_monitor_config(),
        "policy": {"kind": "counters", "n1": 10, "n2": 5},
    });
    Ok((lines, json!({"echo": true, "monitors": [monitor]})))
}

/// A constant-velocity target seen in x and y with correlated noise, 10 Hz.
fn linear_lines(epochs: usize, seed: u64, fault_at: Option<f64>) -> (Vec<(f64, String)>, Value) {
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
    let q = 0.05 * dt;
    let (a, b) = (q * dt * dt / 3.0, q * dt / 2.0);
    let config = json!({
        "f": [[1, dt, 0, 0], [0, 1, 0, 0], [0, 0, 1, dt], [0, 0, 0, 1]],
        "h": [[1, 0, 0, 0], [0, 0, 1, 0]],
        "q": [[a, b, 0, 0], [b, q, 0, 0], [0, 0, a, b], [0, 0, b, q]],
        "r": [[1.0, 0.0], [0.0, 1.96]],
        "x0": [0, 1, 0, -1],
        "p0": [[5, 0, 0, 0], [0, 5, 0, 0], [0, 0, 5, 0], [0, 0, 0, 5]],
    });
    let monitor = json!({"name": "linear", "type": "linear", "config": config,
        "policy": {"kind": "counters", "n1": 10, "n2": 5}});
    (lines, json!({"echo": true, "monitors": [monitor]}))
}

/// Frames sent and not yet fully answered, oldest first.
#[derive(Default)]
struct Flight {
    /// (frame index, when it was sent).
    queue: VecDeque<(usize, Instant)>,
    /// The last answered frames, for alarms that arrive after their frame's result.
    recent: VecDeque<(usize, Instant)>,
}

/// What one session saw, merged into the report at the end.
#[derive(Debug, Default)]
struct Tally {
    frames_sent: u64,
    epochs_sent: u64,
    frames_answered: u64,
    results: u64,
    out_of_order: u64,
    unanswered_frames: u64,
    passes: u64,
    frame_latency_us: Vec<u32>,
    alarm_latency_us: Vec<u32>,
    alarms: u64,
    states: u64,
    errors: BTreeMap<String, u64>,
    failures: Vec<String>,
    last_answer: Option<Instant>,
}

impl Tally {
    fn merge(&mut self, other: Tally) {
        self.frames_sent += other.frames_sent;
        self.epochs_sent += other.epochs_sent;
        self.frames_answered += other.frames_answered;
        self.results += other.results;
        self.out_of_order += other.out_of_order;
        self.unanswered_frames += other.unanswered_frames;
        self.passes += other.passes;
        self.frame_latency_us.extend(other.frame_latency_us);
        self.alarm_latency_us.extend(other.alarm_latency_us);
        self.alarms += other.alarms;
        self.states += other.states;
        for (code, n) in other.errors {
            *self.errors.entry(code).or_default() += n;
        }
        if self.failures.len() < 5 {
            self.failures.extend(other.failures.into_iter().take(5));
        }
        self.last_answer = self.last_answer.max(other.last_answer);
    }
}

fn micros(d: Duration) -> u32 {
    u32::try_from(d.as_micros()).unwrap_or(u32::MAX)
}

/// The `t` of a `result` message, read without parsing the whole message
/// (the server writes `{"type":"result","t":…,` first); `None` for other messages.
fn result_t(text: &str) -> Option<f64> {
    let rest = text.strip_prefix(r#"{"type":"result","t":"#)?;
    let end = rest.find(',')?;
    rest[..end].parse().ok()
}

/// Reads one pass's socket: checks every result against the expected epoch,
/// times frames and alarms, counts errors. Returns when the socket closes.
struct Reader {
    work: Arc<Workload>,
    flight: Arc<Mutex<Flight>>,
    drained: Arc<Notify>,
    next: usize,
    tally: Tally,
}

impl Reader {
    fn answer_front(&mut self, flight: &mut Flight, now: Instant, timed: bool) {
        if let Some((frame, sent)) = flight.queue.pop_front() {
            if timed {
                self.tally.frame_latency_us.push(micros(now - sent));
            }
            self.tally.frames_answered += 1;
            self.tally.last_answer = Some(now);
            self.next = self.work.ranges[frame].end;
            flight.recent.push_back((frame, sent));
            if flight.recent.len() > 64 {
                flight.recent.pop_front();
            }
            if flight.queue.is_empty() {
                self.drained.notify_one();
            }
        }
    }

    fn take(&mut self, text: &str) {
        let now = Instant::now();
        let flight = self.flight.clone();
        let mut flight = flight.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(t) = result_t(text) {
            self.tally.results += 1;
            // serde_json's default float parser may be 1 ulp off the exact value.
            let expected = self.work.times.get(self.next).copied();
            if !expected.is_some_and(|e| (e - t).abs() <= 1e-9 * e.abs().max(1.0)) {
                self.tally.out_of_order += 1;
            }
            self.next += 1;
            if let Some(&(frame, _)) = flight.queue.front()
                && self.next >= self.work.ranges[frame].end
            {
                self.answer_front(&mut flight, now, true);
            }
            return;
        }
        let Ok(v) = serde_json::from_str::<Value>(text) else {
            *self.tally.errors.entry("unparsable".into()).or_default() += 1;
            return;
        };
        match v["type"].as_str() {
            Some("alarm") => {
                self.tally.alarms += 1;
                let t = v["t"].as_f64().unwrap_or(f64::NAN);
                let times = &self.work.times;
                let holds = |&&(frame, _): &&(usize, Instant)| {
                    let r = &self.work.ranges[frame];
                    times[r.start] <= t && t <= times[r.end - 1]
                };
                let sent = flight
                    .queue
                    .iter()
                    .find(holds)
                    .or_else(|| flight.recent.iter().rev().find(holds))
                    .map(|&(_, sent)| sent);
                if let Some(sent) = sent {
                    self.tally.alarm_latency_us.push(micros(now - sent));
                }
            }
            Some("state") => self.tally.states += 1,
            Some("error") => {
                let code = v["code"].as_str().unwrap_or("?").to_owned();
                // Frames are handled in order: the error answers the oldest one.
                // A `numerical` failure part-way leaves earlier results counted.
                *self.tally.errors.entry(code).or_default() += 1;
                self.answer_front(&mut flight, now, false);
            }
            _ => {}
        }
    }
}

/// Streams one session for the run: passes over the workload until the deadline.
async fn run_session(
    endpoint: Arc<Endpoint>,
    id: String,
    work: Arc<Workload>,
    rate: Rate,
    phase: Duration,
    deadline: Instant,
) -> Tally {
    let mut total = Tally::default();
    let path = format!("/api/v1/sessions/{id}/ingest");
    let mut first = true;
    while Instant::now() < deadline {
        let tally = match run_pass(&endpoint, &path, &work, rate, phase, first, deadline).await {
            Ok(tally) => tally,
            Err(e) => {
                total.failures.push(format!("{id}: {e:#}"));
                break;
            }
        };
        first = false;
        total.merge(tally);
    }
    total
}

async fn run_pass(
    endpoint: &Endpoint,
    path: &str,
    work: &Arc<Workload>,
    rate: Rate,
    phase: Duration,
    first: bool,
    deadline: Instant,
) -> anyhow::Result<Tally> {
    let socket = endpoint.connect(path).await?;
    let (mut sink, mut stream) = socket.split();
    let flight = Arc::new(Mutex::new(Flight::default()));
    let drained = Arc::new(Notify::new());
    let mut reader = Reader {
        work: work.clone(),
        flight: flight.clone(),
        drained: drained.clone(),
        next: 0,
        tally: Tally::default(),
    };
    let reading = tokio::spawn(async move {
        while let Some(message) = stream.next().await {
            match message {
                Ok(Message::Text(text)) => reader.take(&text),
                Ok(Message::Close(_)) | Err(_) => break,
                Ok(_) => {}
            }
        }
        reader.drained.notify_one();
        reader.tally
    });
    let mut ticks = match rate {
        Rate::Max => None,
        Rate::Hz(hz) => {
            let start = if first {
                Instant::now() + phase
            } else {
                Instant::now()
            };
            let mut ticks = tokio::time::interval_at(start, Duration::from_secs_f64(1.0 / hz));
            ticks.set_missed_tick_behavior(MissedTickBehavior::Delay);
            Some(ticks)
        }
    };
    let (mut frames_sent, mut epochs_sent) = (0u64, 0u64);
    let mut send_error = None;
    for (k, frame) in work.frames.iter().enumerate() {
        if let Some(ticks) = &mut ticks {
            ticks.tick().await;
        }
        if Instant::now() >= deadline {
            break;
        }
        flight
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .queue
            .push_back((k, Instant::now()));
        if let Err(e) = sink.send(Message::Text(frame.clone())).await {
            send_error = Some(e);
            break;
        }
        frames_sent += 1;
        epochs_sent += work.ranges[k].len() as u64;
    }
    // Wait for every frame's answer, or give up after DRAIN_TIMEOUT.
    let drain_deadline = Instant::now() + DRAIN_TIMEOUT;
    loop {
        let waiting = flight.lock().unwrap_or_else(|p| p.into_inner()).queue.len();
        if waiting == 0 || reading.is_finished() || Instant::now() >= drain_deadline {
            break;
        }
        let _ = tokio::time::timeout_at(drain_deadline, drained.notified()).await;
    }
    let _ = sink.close().await;
    let mut tally = match tokio::time::timeout(Duration::from_secs(5), reading).await {
        Ok(Ok(tally)) => tally,
        _ => bail!("the socket reader did not finish"),
    };
    tally.frames_sent = frames_sent;
    tally.epochs_sent = epochs_sent;
    tally.passes = 1;
    tally.unanswered_frames = flight.lock().unwrap_or_else(|p| p.into_inner()).queue.len() as u64;
    if let Some(e) = send_error {
        tally
            .failures
            .push(format!("the server dropped the socket: {e}"));
    }
    Ok(tally)
}

/// Latency percentiles, microseconds.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Percentiles {
    /// Observations.
    pub count: u64,
    /// Median.
    pub p50_us: u32,
    /// 99th percentile.
    pub p99_us: u32,
    /// 99.9th percentile.
    pub p999_us: u32,
    /// Largest.
    pub max_us: u32,
}

/// Nearest-rank percentiles of `samples` (sorted in place).
fn percentiles(samples: &mut [u32]) -> Percentiles {
    if samples.is_empty() {
        return Percentiles::default();
    }
    samples.sort_unstable();
    let n = samples.len();
    let rank = |p: f64| samples[((p * n as f64).ceil() as usize).clamp(1, n) - 1];
    Percentiles {
        count: n as u64,
        p50_us: rank(0.50),
        p99_us: rank(0.99),
        p999_us: rank(0.999),
        max_us: samples[n - 1],
    }
}

/// The report (`--json` prints it as is).
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// Server URL.
    pub url: String,
    /// Monitor type.
    pub monitor: String,
    /// Sessions streamed.
    pub sessions: u64,
    /// Frames per second per session (`null` for max).
    pub rate_hz: Option<f64>,
    /// Epochs per frame.
    pub batch: u64,
    /// Seconds from the first send to the last answer.
    pub wall_s: f64,
    /// Epochs sent.
    pub epochs_sent: u64,
    /// Frames sent.
    pub frames_sent: u64,
    /// `result` messages received.
    pub results: u64,
    /// Results whose `t` was not the next epoch sent.
    pub out_of_order: u64,
    /// Frames without an answer when the tool gave up waiting.
    pub unanswered_frames: u64,
    /// Sockets opened (one per session per pass over the workload).
    pub passes: u64,
    /// Results per second over `wall_s`.
    pub epochs_per_s: f64,
    /// Answered frames per second over `wall_s`.
    pub frames_per_s: f64,
    /// Frame sent → result of its last epoch.
    pub frame_latency: Percentiles,
    /// Frame holding the alarm's epoch sent → alarm received.
    pub alarm_latency: Percentiles,
    /// Alarms received.
    pub alarms: u64,
    /// State changes received.
    pub state_changes: u64,
    /// Error events by code.
    pub errors: BTreeMap<String, u64>,
    /// Sessions that failed (connection refused, socket dropped), up to five.
    pub failures: Vec<String>,
    /// Server RSS before creating the sessions, bytes.
    pub rss_baseline_bytes: Option<u64>,
    /// Server RSS with the sessions created and idle, bytes.
    pub rss_idle_bytes: Option<u64>,
    /// Server RSS at the end of the stream, bytes.
    pub rss_loaded_bytes: Option<u64>,
    /// (idle − baseline) / sessions, bytes.
    pub idle_bytes_per_session: Option<f64>,
}

/// Reads `process_resident_memory_bytes` from the server's `/metrics`.
async fn server_rss(endpoint: &Endpoint) -> anyhow::Result<Option<u64>> {
    let (status, body) = endpoint.request("GET", "/metrics", None).await?;
    if status != 200 {
        bail!("GET /metrics: HTTP {status}");
    }
    Ok(body.lines().find_map(|line| {
        let value = line.strip_prefix("process_resident_memory_bytes ")?;
        value.trim().parse::<f64>().ok().map(|v| v as u64)
    }))
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

async fn create_session(endpoint: &Endpoint, spec: &Value, id: &str) -> anyhow::Result<()> {
    let mut body = spec.clone();
    body["id"] = json!(id);
    let (status, text) = endpoint
        .request("POST", "/api/v1/sessions", Some(&body))
        .await?;
    match status {
        201 => Ok(()),
        401 => bail!("unauthorized; pass --token"),
        s => bail!("creating session '{id}': HTTP {s}: {text}"),
    }
}

async fn delete_sessions(endpoint: &Endpoint, ids: Vec<String>) -> usize {
    let results = each_concurrently(ids, |id| async move {
        let (status, text) = endpoint
            .request("DELETE", &format!("/api/v1/sessions/{id}"), None)
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
pub async fn run(args: LoadgenArgs) -> anyhow::Result<()> {
    if !(args.duration.is_finite() && args.duration > 0.0) {
        bail!("--duration must be a positive number of seconds");
    }
    if let Some(t) = args.fault_at
        && !(t.is_finite() && t >= 0.0)
    {
        bail!("--fault-at must be a non-negative epoch time, s");
    }
    let endpoint = Arc::new(Endpoint::parse(&args.url, args.token.clone())?);
    let work = Arc::new(Workload::build(&args)?);
    if !args.json {
        eprintln!(
            "workload: {} epochs per pass in {} frames of ≤ {}",
            thousands(work.epochs() as u64),
            thousands(work.frames.len() as u64),
            args.batch
        );
    }
    let rss_baseline = server_rss(&endpoint).await?;
    let ids: Vec<String> = (0..args.sessions)
        .map(|i| format!("loadgen-{}-{i}", std::process::id()))
        .collect();
    let created = each_concurrently(ids.clone(), |id| {
        let (endpoint, spec) = (&endpoint, &work.spec);
        async move { create_session(endpoint, spec, &id).await }
    })
    .await;
    if let Some(Err(e)) = created.into_iter().find(Result::is_err) {
        delete_sessions(&endpoint, ids).await;
        return Err(e.context("creating the sessions (the ones created were deleted)"));
    }
    tokio::time::sleep(Duration::from_secs_f64(args.settle.max(0.0))).await;
    let rss_idle = server_rss(&endpoint).await?;
    let outcome = stream(&args, &endpoint, &work, &ids).await;
    let rss_loaded = server_rss(&endpoint).await.ok().flatten();
    let undeleted = delete_sessions(&endpoint, ids).await;
    if undeleted > 0 {
        eprintln!("warning: {undeleted} sessions could not be deleted");
    }
    let (tally, wall_s) = outcome;
    let report = report(&args, tally, wall_s, [rss_baseline, rss_idle, rss_loaded]);
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

fn report(args: &LoadgenArgs, mut t: Tally, wall_s: f64, rss: [Option<u64>; 3]) -> Report {
    let per_s = |n: u64| if wall_s > 0.0 { n as f64 / wall_s } else { 0.0 };
    let [baseline, idle, loaded] = rss;
    Report {
        url: args.url.clone(),
        monitor: format!("{:?}", args.monitor).to_lowercase(),
        sessions: args.sessions,
        rate_hz: match args.rate {
            Rate::Max => None,
            Rate::Hz(hz) => Some(hz),
        },
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
        alarms: t.alarms,
        state_changes: t.states,
        errors: t.errors,
        failures: t.failures,
        rss_baseline_bytes: baseline,
        rss_idle_bytes: idle,
        rss_loaded_bytes: loaded,
        idle_bytes_per_session: match (baseline, idle) {
            (Some(b), Some(i)) => Some((i as f64 - b as f64) / args.sessions as f64),
            _ => None,
        },
    }
}

fn ms(us: u32) -> String {
    format!("{:.3}", f64::from(us) / 1000.0)
}

fn mib(bytes: Option<u64>) -> String {
    bytes.map_or("-".into(), |b| format!("{:.1} MiB", b as f64 / 1048576.0))
}

/// The report as a text table.
pub fn render(r: &Report) -> String {
    let mut out = String::new();
    let rate = r.rate_hz.map_or("max".into(), |hz| format!("{hz} Hz"));
    let _ = writeln!(
        out,
        "loadgen → {}: {} × {} session(s), rate {rate}, batch {}",
        r.url, r.monitor, r.sessions, r.batch
    );
    let row = |out: &mut String, k: &str, v: String| {
        let _ = writeln!(out, "  {k:<28} {v}");
    };
    row(&mut out, "wall time", format!("{:.2} s", r.wall_s));
    row(
        &mut out,
        "epochs sent / results",
        format!("{} / {}", thousands(r.epochs_sent), thousands(r.results)),
    );
    row(&mut out, "frames sent", thousands(r.frames_sent));
    row(
        &mut out,
        "epochs/s (results)",
        thousands(r.epochs_per_s.round() as u64),
    );
    row(
        &mut out,
        "frames/s (answered)",
        thousands(r.frames_per_s.round() as u64),
    );
    let pct = |p: &Percentiles| {
        if p.count == 0 {
            "-".to_owned()
        } else {
            format!(
                "p50 {}  p99 {}  p99.9 {}  max {} ms  (n = {})",
                ms(p.p50_us),
                ms(p.p99_us),
                ms(p.p999_us),
                ms(p.max_us),
                thousands(p.count)
            )
        }
    };
    row(&mut out, "frame → result latency", pct(&r.frame_latency));
    row(&mut out, "alarm → event latency", pct(&r.alarm_latency));
    row(
        &mut out,
        "alarms / state changes",
        format!("{} / {}", r.alarms, r.state_changes),
    );
    let errors = if r.errors.is_empty() {
        "none".to_owned()
    } else {
        r.errors
            .iter()
            .map(|(code, n)| format!("{code} {n}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    row(&mut out, "errors", errors);
    row(
        &mut out,
        "out of order / unanswered",
        format!("{} / {}", r.out_of_order, r.unanswered_frames),
    );
    row(&mut out, "sockets (passes)", thousands(r.passes));
    row(
        &mut out,
        "server RSS base/idle/loaded",
        format!(
            "{} / {} / {}",
            mib(r.rss_baseline_bytes),
            mib(r.rss_idle_bytes),
            mib(r.rss_loaded_bytes)
        ),
    );
    row(
        &mut out,
        "idle memory per session",
        r.idle_bytes_per_session
            .map_or("-".into(), |b| format!("{:.1} KiB", b / 1024.0)),
    );
    for f in &r.failures {
        row(&mut out, "failure", f.clone());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

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
        assert_eq!((w.epochs(), w.frames.len()), (63, 21));
        let first: Value = serde_json::from_str(w.frames[0].as_str()).unwrap();
        assert_eq!(first.as_array().map(Vec::len), Some(3));
        assert_eq!(first[1]["t"], json!(0.1));
        assert_eq!(w.ranges[20], 60..63);
        assert_eq!(w.spec["monitors"][0]["type"], "linear");
    }

    #[test]
    fn a_federated_workload_carries_the_ship_and_its_monitor() {
        let a = args(&["--rate", "1", "--duration", "2", "--fault-at", "1"]);
        let w = Workload::build(&a).unwrap();
        assert_eq!(w.epochs(), 3);
        let first: Value = serde_json::from_str(w.frames[0].as_str()).unwrap();
        assert!(first["ins"].is_object() && first["gnss"].is_object());
        assert_eq!(w.spec["echo"], json!(true));
        assert_eq!(w.spec["monitors"][0]["type"], "federated");
    }
}
