//! `navguard replay FILE.jsonl`: streams a JSON-lines file of ingest frames
//! (one epoch per line, as `navguard simulate` writes them) into a session of a
//! running navguard over the ingest socket, at real time × a factor or as fast
//! as the server takes it, while reading the socket concurrently (alarms, state
//! changes, errors); then prints a summary with the session's `/stats`.
//!
//! The client talks only to the `--url` it is given, holds at most one batch
//! and a bounded summary in memory, and gives up with a clear message when the
//! server cannot be reached or closes the socket.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{Context, bail};
use futures_util::stream::{SplitSink, SplitStream};
use futures_util::{SinkExt, StreamExt};
use indicatif::ProgressBar;
use navguard::detect::PolicyConfig;
use navguard::epoch::Aid;
use navguard::monitor::MonitorKind;
use navguard::monitor::federated::FederatedConfigWire;
use navguard::service::session::spec::valid_name;
use navguard::service::wire::{CreateSession, MonitorSpecWire};
use navguard::session::SessionStats;
use serde::de::IgnoredAny;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use tokio::io::AsyncBufReadExt;
use tokio::time::Instant;
use tokio_tungstenite::tungstenite::protocol::CloseFrame;
use tokio_tungstenite::tungstenite::{self, Message};

use super::http::{Endpoint, ServerEvent, Socket};
use super::{progress_bar, thousands};

/// Longest the server may go without processing a frame while we wait for
/// the last ones.
const DRAIN_STALL: Duration = Duration::from_secs(30);
/// Longest wait for alarms the stats count but the socket has not delivered.
const ALARM_GRACE: Duration = Duration::from_secs(5);
/// Alarm events kept individually for `--summary-json` (the rest are counted).
const MAX_ALARM_EVENTS: usize = 100_000;
/// Error messages kept as examples.
const MAX_ERROR_SAMPLES: usize = 5;

/// How fast to stream: a multiple of real time, or as fast as the server takes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Speed {
    /// Batches back to back; the socket's backpressure sets the pace.
    Max,
    /// Epoch `t` paced at this multiple of real time (`10x`).
    Factor(f64),
}

impl FromStr for Speed {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        if s.eq_ignore_ascii_case("max") {
            return Ok(Speed::Max);
        }
        let number = s.strip_suffix(['x', 'X']).unwrap_or(s);
        match number.parse::<f64>() {
            Ok(f) if f.is_finite() && f > 0.0 => Ok(Speed::Factor(f)),
            _ => Err(format!(
                "expected `max` or a positive factor like `10x`, got {s:?}"
            )),
        }
    }
}

/// The decision policy of a session `replay` creates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum PolicyArg {
    /// Traditional residual χ² test.
    Classic,
    /// Seed 004's counters (N1, N2).
    Counters,
}

/// `navguard replay` flags.
#[derive(Debug, clap::Args)]
#[command(after_long_help = SPEC_HELP)]
pub(crate) struct ReplayArgs {
    /// JSON-lines file: one ingest epoch per line (e.g. from `navguard simulate`).
    pub file: PathBuf,
    /// The server, as ws://host:port (REST calls go to http://host:port).
    #[arg(long, default_value = "ws://127.0.0.1:8080")]
    pub url: String,
    /// Session id; created if it does not exist (see below for the monitor spec).
    #[arg(long)]
    pub session: String,
    /// `max` (as fast as the server takes it) or a multiple of real time, e.g. `10x`.
    #[arg(long, default_value = "max")]
    pub speed: Speed,
    /// Bearer token for a server started with --token.
    #[arg(long, env = "NAVGUARD_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Most epochs per frame (at `max`; paced runs send what is due, up to this).
    #[arg(long, default_value_t = 500, value_parser = clap::value_parser!(u64).range(1..=100_000))]
    pub batch: u64,
    /// Largest frame sent, bytes (keep at or below the server's --max-frame-bytes).
    #[arg(long, default_value_t = 1 << 20)]
    pub max_frame_bytes: usize,
    /// Full `POST /api/v1/sessions` body for a new session (its `id` is set to --session).
    #[arg(long, conflicts_with_all = ["monitor_config", "policy", "threshold", "p_fa"])]
    pub session_spec: Option<PathBuf>,
    /// The monitor's `config` for a new session: inline JSON or `@file`.
    #[arg(long)]
    pub monitor_config: Option<String>,
    /// Policy of a new session's monitor.
    #[arg(long, value_enum)]
    pub policy: Option<PolicyArg>,
    /// Counters policy: t2's restart value N1.
    #[arg(long, default_value_t = 10)]
    pub n1: u32,
    /// Counters policy: exceedances tolerated as suspect, N2.
    #[arg(long, default_value_t = 5)]
    pub n2: u32,
    /// Raw threshold for a new session's monitor (seed 004 uses 13 and 20).
    #[arg(long, conflicts_with = "p_fa")]
    pub threshold: Option<f64>,
    /// False-alarm probability for a new session's monitor (server default 0.002).
    #[arg(long)]
    pub p_fa: Option<f64>,
    /// Write the summary (counts, every alarm, final stats) as JSON to this file.
    #[arg(long)]
    pub summary_json: Option<PathBuf>,
    /// Write every `result`, `state` and `alarm` message received, as received, one per
    /// line, to this file (to compare a replayed recording with the original).
    #[arg(long)]
    pub messages: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// When the ingest socket drops (a cluster node killed or drained), reconnect with
    /// `resume=true` (within 30 s) and resend from the first epoch after the one the
    /// session resumed from (docs/deployment.md, Failover), instead of stopping.
    #[arg(long)]
    pub resume: bool,
}

const SPEC_HELP: &str = "\
How a new session's monitor is chosen (an existing session is used as it is):
  --session-spec FILE   the file is the whole POST /api/v1/sessions body;
  otherwise one monitor, named after its type:
    `federated` when the file has `ins` blocks, with config --monitor-config or,
        by default, {\"aids\": [the aids present in the file: gnss, dvl, cns]} and
        every other field at its seed 004 default (the `ship` scenario's setup);
    `linear` when the file has `z` blocks and no `ins` (needs --monitor-config);
  policy --policy (default counters, --n1 10 --n2 5), threshold --threshold or
  --p-fa (default p_fa 0.002).
The summary lists epochs and frames sent, errors by code, alarms by monitor,
test and state with first and last t, and the session's /stats per test. The
exit status is non-zero when the server cannot be reached or drops the socket,
not when it refuses frames (those are counted in the summary).";

/// What a first pass over the file found.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct FileScan {
    /// Epoch lines.
    pub epochs: u64,
    /// `t` of the first epoch.
    pub first_t: f64,
    /// `t` of the last epoch.
    pub last_t: f64,
    /// Some epoch has an `ins` block.
    pub ins: bool,
    /// Some epoch has a `gnss` block.
    pub gnss: bool,
    /// Some epoch has a `dvl` block.
    pub dvl: bool,
    /// Some epoch has a `cns` block.
    pub cns: bool,
    /// Some epoch has `z`.
    pub z: bool,
}

#[derive(Debug, Deserialize)]
struct Peek {
    t: f64,
    #[serde(default)]
    ins: Option<IgnoredAny>,
    #[serde(default)]
    gnss: Option<IgnoredAny>,
    #[serde(default)]
    dvl: Option<IgnoredAny>,
    #[serde(default)]
    cns: Option<IgnoredAny>,
    #[serde(default)]
    z: Option<IgnoredAny>,
}

fn peek(line: &str, number: usize) -> anyhow::Result<Peek> {
    serde_json::from_str(line).with_context(|| {
        format!("line {number}: not an epoch object with a numeric `t` (one epoch per line)")
    })
}

/// Reads the file once: epoch count, time span, which blocks occur.
pub(crate) fn scan(path: &Path) -> anyhow::Result<FileScan> {
    let file = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut out = FileScan::default();
    for (i, line) in std::io::BufReader::new(file).lines().enumerate() {
        let line = line.with_context(|| format!("reading {}", path.display()))?;
        if line.trim().is_empty() {
            continue;
        }
        let p = peek(&line, i + 1)?;
        if out.epochs == 0 {
            out.first_t = p.t;
        }
        out.last_t = p.t;
        out.epochs += 1;
        out.ins |= p.ins.is_some();
        out.gnss |= p.gnss.is_some();
        out.dvl |= p.dvl.is_some();
        out.cns |= p.cns.is_some();
        out.z |= p.z.is_some();
    }
    if out.epochs == 0 {
        bail!("{} holds no epochs", path.display());
    }
    Ok(out)
}

/// Reads inline JSON or `@file`.
fn json_arg(text: &str, what: &str) -> anyhow::Result<Value> {
    let (source, body) = match text.strip_prefix('@') {
        Some(path) => (
            path.to_owned(),
            std::fs::read_to_string(path).with_context(|| format!("reading {what} {path}"))?,
        ),
        None => ("the command line".to_owned(), text.to_owned()),
    };
    serde_json::from_str(&body).with_context(|| format!("{what} from {source} is not JSON"))
}

/// The `POST /api/v1/sessions` body for a new session (see `SPEC_HELP`).
pub(crate) fn session_body(args: &ReplayArgs, scan: &FileScan) -> anyhow::Result<CreateSession> {
    if let Some(path) = &args.session_spec {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading --session-spec {}", path.display()))?;
        let mut body: CreateSession = serde_json::from_str(&text).with_context(|| {
            format!(
                "--session-spec {} is not a POST /api/v1/sessions body",
                path.display()
            )
        })?;
        match &body.id {
            Some(id) if *id != args.session => bail!(
                "--session-spec names session '{id}' but --session is '{}'",
                args.session
            ),
            _ => body.id = Some(args.session.clone()),
        }
        return Ok(body);
    }
    let (kind, config) = if scan.ins {
        let config = match &args.monitor_config {
            Some(text) => json_arg(text, "--monitor-config")?,
            None => {
                let aids: Vec<Aid> = [
                    (Aid::Gnss, scan.gnss),
                    (Aid::Dvl, scan.dvl),
                    (Aid::Cns, scan.cns),
                ]
                .into_iter()
                .filter_map(|(name, present)| present.then_some(name))
                .collect();
                if aids.is_empty() {
                    bail!(
                        "the file has `ins` blocks but no gnss, dvl or cns: nothing to aid the INS with"
                    );
                }
                federated_config(aids)?
            }
        };
        (MonitorKind::Federated, config)
    } else if scan.z {
        let text = args.monitor_config.as_deref().context(
            "the file has `z` blocks: a `linear` monitor needs --monitor-config (its f, h, q, r, x0, p0)",
        )?;
        (MonitorKind::Linear, json_arg(text, "--monitor-config")?)
    } else {
        bail!(
            "cannot tell which monitor the file needs (no `ins` and no `z` blocks): give --session-spec"
        );
    };
    let policy = match args.policy.unwrap_or(PolicyArg::Counters) {
        PolicyArg::Classic => PolicyConfig::Classic,
        PolicyArg::Counters => PolicyConfig::Counters {
            n1: args.n1,
            n2: args.n2,
        },
    };
    let monitor = MonitorSpecWire {
        name: kind.as_str().to_owned(),
        kind,
        config,
        policy,
        p_fa: args.p_fa,
        threshold: args.threshold,
        alarm_level: None,
        tests: Default::default(),
    };
    Ok(CreateSession {
        id: Some(args.session.clone()),
        monitors: vec![monitor],
        echo: false,
        alarm_level: None,
        record: None,
    })
}

/// The `federated` config with these aids and every other field at its default
/// (written out, so the body says which values the monitor runs with).
fn federated_config(aids: Vec<Aid>) -> anyhow::Result<Value> {
    serde_json::to_value(FederatedConfigWire::new(aids)).context("serialising the federated config")
}

/// Alarms of one monitor, test and state.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub(crate) struct AlarmGroup {
    /// Monitor name.
    pub monitor: String,
    /// Test name.
    pub test: String,
    /// State entered.
    pub state: String,
    /// Alarms.
    pub count: u64,
    /// Epoch time of the first, s.
    pub first_t: f64,
    /// Epoch time of the last, s.
    pub last_t: f64,
}

/// One alarm as received.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub(crate) struct AlarmEvent {
    /// Monitor name.
    pub monitor: String,
    /// Test name.
    pub test: String,
    /// State entered.
    pub state: String,
    /// Epoch time, s.
    pub t: f64,
}

/// What the socket reader saw.
#[derive(Debug, Default)]
struct Tally {
    errors: BTreeMap<String, u64>,
    error_samples: Vec<String>,
    error_total: u64,
    numerical: u64,
    alarms: BTreeMap<(String, String, String), AlarmGroup>,
    alarm_events: Vec<AlarmEvent>,
    alarm_total: u64,
    states: u64,
    results: u64,
    closed: Option<String>,
    /// `--messages`: where every result, state and alarm message goes.
    messages: Option<std::io::BufWriter<std::fs::File>>,
}

impl Tally {
    fn take(&mut self, text: &str) {
        let Ok(event) = serde_json::from_str::<ServerEvent>(text) else {
            return;
        };
        if let (Some(out), ServerEvent::Result | ServerEvent::State(_) | ServerEvent::Alarm(_)) =
            (&mut self.messages, &event)
        {
            use std::io::Write as _;
            let _ = writeln!(out, "{text}");
        }
        match event {
            ServerEvent::Error(e) => {
                self.error_total += 1;
                if e.code == "numerical" {
                    self.numerical += 1;
                }
                if self.error_samples.len() < MAX_ERROR_SAMPLES {
                    self.error_samples
                        .push(format!("{}: {}", e.code, e.message));
                }
                *self.errors.entry(e.code).or_default() += 1;
            }
            ServerEvent::Alarm(alarm) => {
                let t = alarm.t;
                let key = (alarm.monitor, alarm.test, alarm.state.as_str().to_owned());
                self.alarm_total += 1;
                if self.alarm_events.len() < MAX_ALARM_EVENTS {
                    self.alarm_events.push(AlarmEvent {
                        monitor: key.0.clone(),
                        test: key.1.clone(),
                        state: key.2.clone(),
                        t,
                    });
                }
                let group = self.alarms.entry(key.clone()).or_insert(AlarmGroup {
                    monitor: key.0,
                    test: key.1,
                    state: key.2,
                    count: 0,
                    first_t: t,
                    last_t: t,
                });
                group.count += 1;
                group.last_t = t;
            }
            ServerEvent::State(_) => self.states += 1,
            ServerEvent::Result => self.results += 1,
            ServerEvent::Other => {}
        }
    }
}

/// The end-of-run summary (`--summary-json` writes it).
#[derive(Debug, Clone, Serialize)]
pub(crate) struct ReplaySummary {
    /// Session id.
    pub session: String,
    /// The session was created by this run.
    pub created: bool,
    /// Epochs sent.
    pub epochs_sent: u64,
    /// Frames sent.
    pub frames_sent: u64,
    /// Wall-clock seconds from the first frame to the end of the drain.
    pub wall_s: f64,
    /// Error events by code.
    pub errors: BTreeMap<String, u64>,
    /// Up to five error messages.
    pub error_samples: Vec<String>,
    /// Alarms by monitor, test and state.
    pub alarm_groups: Vec<AlarmGroup>,
    /// Every alarm received (up to 100,000), in order.
    pub alarms: Vec<AlarmEvent>,
    /// State-change events received.
    pub state_changes: u64,
    /// The session's `/stats` at the end, read through the service's own type.
    pub stats: SessionStats,
}

/// Runs the command.
pub(crate) async fn run(args: ReplayArgs) -> anyhow::Result<()> {
    if !valid_name(&args.session) {
        bail!("--session must be 1-64 characters of A-Z a-z 0-9 _ - .");
    }
    let scan = scan(&args.file)?;
    let endpoint = Endpoint::parse(&args.url, args.token.clone())?;
    let path = format!("/api/v1/sessions/{}", args.session);
    let created = ensure_session(&endpoint, &args, &scan, &path).await?;
    let baseline = stats(&endpoint, &path).await?;
    let socket = endpoint.connect(&format!("{path}/ingest")).await?;
    let (sink, stream) = socket.split();
    let messages = match &args.messages {
        Some(path) => Some(std::io::BufWriter::new(
            std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?,
        )),
        None => None,
    };
    let tally = Arc::new(Mutex::new(Tally {
        messages,
        ..Tally::default()
    }));
    let reader = tokio::spawn(read_events(stream, tally.clone()));
    let progress = progress_bar(
        scan.epochs,
        "[{bar:24}] {percent:>3}% {pos}/{len} epochs  {per_sec}  {msg}",
        !args.quiet,
    );
    let started = Instant::now();
    let link = Link {
        endpoint: &endpoint,
        path: &path,
        baseline,
    };
    let outcome = stream_file(&args, &scan, sink, &tally, &progress, link).await;
    progress.finish_and_clear();
    let (mut sink, sent, baseline) = match outcome {
        Ok(done) => done,
        Err(e) => {
            reader.abort();
            return Err(e);
        }
    };
    let drained = drain(&endpoint, &path, &baseline, &sent, &tally).await;
    let wall_s = started.elapsed().as_secs_f64();
    let _ = sink
        .send(Message::Close(Some(CloseFrame {
            code: tungstenite::protocol::frame::coding::CloseCode::Normal,
            reason: "replay finished".into(),
        })))
        .await;
    let _ = tokio::time::timeout(Duration::from_secs(2), reader).await;
    let final_stats = drained?;
    let mut tally = std::mem::take(&mut *tally.lock().unwrap_or_else(|p| p.into_inner()));
    if let Some(mut out) = tally.messages.take() {
        use std::io::Write as _;
        out.flush().context("writing --messages")?;
    }
    let summary = ReplaySummary {
        session: args.session.clone(),
        created,
        epochs_sent: sent.epochs,
        frames_sent: sent.frames,
        wall_s,
        errors: tally.errors,
        error_samples: tally.error_samples,
        alarm_groups: {
            let mut groups: Vec<AlarmGroup> = tally.alarms.into_values().collect();
            groups.sort_by(|a, b| a.first_t.total_cmp(&b.first_t));
            groups
        },
        alarms: tally.alarm_events,
        state_changes: tally.states,
        stats: final_stats,
    };
    print!("{}", render(&summary));
    if let Some(path) = &args.summary_json {
        let text = serde_json::to_string_pretty(&summary)?;
        std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// Creates the session unless it exists. Returns true when created.
async fn ensure_session(
    endpoint: &Endpoint,
    args: &ReplayArgs,
    scan: &FileScan,
    path: &str,
) -> anyhow::Result<bool> {
    let (status, body) = endpoint.call("GET", path).await?;
    match status {
        200 => {
            if args.session_spec.is_some() || args.monitor_config.is_some() {
                eprintln!(
                    "session '{}' exists: using it as it is (the given spec is ignored)",
                    args.session
                );
            }
            return Ok(false);
        }
        404 => {}
        401 => bail!("{}: unauthorized; pass --token", endpoint.http_base()),
        s => bail!("GET {path}: HTTP {s}: {body}"),
    }
    let spec = session_body(args, scan)?;
    let (status, body) = endpoint
        .request("POST", "/api/v1/sessions", Some(&spec))
        .await?;
    match status {
        201 => Ok(true),
        // Someone created it between our GET and POST: use theirs.
        409 => Ok(false),
        s => bail!("creating session '{}': HTTP {s}: {body}", args.session),
    }
}

async fn stats(endpoint: &Endpoint, path: &str) -> anyhow::Result<SessionStats> {
    let (status, body) = endpoint.call("GET", &format!("{path}/stats")).await?;
    if status != 200 {
        bail!("GET {path}/stats: HTTP {status}: {body}");
    }
    parse_stats(&body)
}

fn parse_stats(body: &str) -> anyhow::Result<SessionStats> {
    serde_json::from_str(body).context("the stats do not have the session stats' shape")
}

async fn read_events(mut stream: SplitStream<Socket>, tally: Arc<Mutex<Tally>>) {
    let closed = loop {
        match stream.next().await {
            Some(Ok(Message::Text(text))) => {
                tally.lock().unwrap_or_else(|p| p.into_inner()).take(&text);
            }
            Some(Ok(Message::Close(frame))) => {
                break frame.map_or_else(
                    || "closed".to_owned(),
                    |f| format!("closed ({}): {}", u16::from(f.code), f.reason),
                );
            }
            Some(Ok(_)) => continue,
            Some(Err(e)) => break format!("socket error: {e}"),
            None => break "connection ended".to_owned(),
        }
    };
    tally.lock().unwrap_or_else(|p| p.into_inner()).closed = Some(closed);
}

/// What was sent.
#[derive(Debug, Clone, Copy, Default)]
struct Sent {
    epochs: u64,
    frames: u64,
}

/// The session the replay streams to, and its statistics when the current socket
/// attached (the drain counts what was sent on it from there).
struct Link<'a> {
    endpoint: &'a Endpoint,
    path: &'a str,
    baseline: SessionStats,
}

/// How long `--resume` keeps trying to reconnect.
const RESUME_WINDOW: Duration = Duration::from_secs(30);

/// `--resume`: reconnects (`resume=true`) until a socket attaches, within
/// [`RESUME_WINDOW`]; the new sink and the time the session resumed after (`ready`'s
/// `resumed.t`; `None`: a fresh stream, resend everything).
async fn reconnect(
    link: &mut Link<'_>,
    tally: &Arc<Mutex<Tally>>,
) -> anyhow::Result<(SplitSink<Socket, Message>, Option<f64>)> {
    let deadline = Instant::now() + RESUME_WINDOW;
    let mut last_error = String::new();
    while Instant::now() < deadline {
        match link
            .endpoint
            .connect_ready(&format!("{}/ingest?resume=true", link.path))
            .await
        {
            Ok((socket, ready)) => {
                let (sink, stream) = socket.split();
                tally.lock().unwrap_or_else(|p| p.into_inner()).closed = None;
                tokio::spawn(read_events(stream, tally.clone()));
                link.baseline = stats(link.endpoint, link.path).await?;
                return Ok((sink, ready["resumed"]["t"].as_f64()));
            }
            Err(e) => last_error = format!("{e:#}"),
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    bail!("could not resume the stream within {RESUME_WINDOW:?}: {last_error}")
}

async fn open_lines(
    path: &Path,
) -> anyhow::Result<tokio::io::Lines<tokio::io::BufReader<tokio::fs::File>>> {
    let file = tokio::fs::File::open(path)
        .await
        .with_context(|| format!("opening {}", path.display()))?;
    Ok(tokio::io::BufReader::new(file).lines())
}

async fn stream_file(
    args: &ReplayArgs,
    scan: &FileScan,
    mut sink: SplitSink<Socket, Message>,
    tally: &Arc<Mutex<Tally>>,
    progress: &ProgressBar,
    mut link: Link<'_>,
) -> anyhow::Result<(SplitSink<Socket, Message>, Sent, SessionStats)> {
    let mut lines = open_lines(&args.file).await?;
    let mut number = 0usize;
    let start = Instant::now();
    let due = |t: f64| match args.speed {
        Speed::Max => start,
        Speed::Factor(f) => start + Duration::from_secs_f64(((t - scan.first_t) / f).max(0.0)),
    };
    let mut sent = Sent::default();
    let mut pending = next_epoch(&mut lines, &mut number).await?;
    let mut batch: Vec<String> = Vec::new();
    let mut last_t = scan.first_t;
    while let Some((t, _)) = &pending {
        if let Speed::Factor(_) = args.speed {
            tokio::time::sleep_until(due(*t)).await;
        }
        let now = Instant::now();
        batch.clear();
        let mut bytes = 1;
        while let Some((t, line)) = pending.take() {
            let fits = batch.is_empty()
                || (batch.len() < args.batch as usize && bytes + line.len() < args.max_frame_bytes);
            if !fits || due(t) > now {
                pending = Some((t, line));
                break;
            }
            bytes += line.len() + 1;
            last_t = last_t.max(t);
            batch.push(line);
            pending = next_epoch(&mut lines, &mut number).await?;
        }
        let text = if batch.len() == 1 {
            std::mem::take(&mut batch[0])
        } else {
            format!("[{}]", batch.join(","))
        };
        let closed_before = tally
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .closed
            .clone();
        let failed = match closed_before {
            Some(reason) => Some(reason),
            None => sink
                .send(Message::Text(text.into()))
                .await
                .err()
                .map(|e| e.to_string()),
        };
        if let Some(reason) = failed {
            if !args.resume {
                bail!(
                    "the server dropped the ingest socket after {} epochs: {reason} (--resume reconnects)",
                    sent.epochs
                );
            }
            progress.suspend(|| eprintln!("ingest socket lost ({reason}); resuming"));
            let (new_sink, resumed_t) = reconnect(&mut link, tally).await?;
            sink = new_sink;
            // Resend from the first epoch after the resume point (all of the file when
            // the session starts afresh); what is sent from here is counted afresh.
            lines = open_lines(&args.file).await?;
            number = 0;
            pending = next_epoch(&mut lines, &mut number).await?;
            while let (Some(after), Some((t, _))) = (resumed_t, &pending) {
                if *t > after {
                    break;
                }
                pending = next_epoch(&mut lines, &mut number).await?;
            }
            sent = Sent::default();
            progress.suspend(|| match resumed_t {
                Some(t) => eprintln!("resumed after t = {t}; resending from there"),
                None => eprintln!("resumed with a fresh stream; resending from the start"),
            });
            continue;
        }
        sent.frames += 1;
        sent.epochs += batch.len() as u64;
        let extra = {
            let tally = tally.lock().unwrap_or_else(|p| p.into_inner());
            format!(
                "t {:.0}/{:.0} s  alarms {}  errors {}",
                last_t - scan.first_t,
                scan.last_t - scan.first_t,
                tally.alarm_total,
                tally.error_total
            )
        };
        progress.set_position(sent.epochs);
        progress.set_message(extra);
    }
    Ok((sink, sent, link.baseline))
}

async fn next_epoch(
    lines: &mut tokio::io::Lines<tokio::io::BufReader<tokio::fs::File>>,
    number: &mut usize,
) -> anyhow::Result<Option<(f64, String)>> {
    loop {
        *number += 1;
        let Some(line) = lines.next_line().await? else {
            return Ok(None);
        };
        if line.trim().is_empty() {
            continue;
        }
        let t = peek(&line, *number)?.t;
        return Ok(Some((t, line)));
    }
}

/// Waits until the server has dealt with every frame sent (accepted ones
/// counted in `/stats`, refused ones answered with an `error`) and the socket
/// has delivered the alarms the stats count. Returns the final stats.
async fn drain(
    endpoint: &Endpoint,
    path: &str,
    baseline: &SessionStats,
    sent: &Sent,
    tally: &Arc<Mutex<Tally>>,
) -> anyhow::Result<SessionStats> {
    let base_frames = baseline.frames;
    let base_alarms = baseline.alarms();
    let mut last_progress = (Instant::now(), u64::MAX);
    loop {
        let current = stats(endpoint, path).await?;
        let (errors, numerical, closed) = {
            let t = tally.lock().unwrap_or_else(|p| p.into_inner());
            (t.error_total, t.numerical, t.closed.clone())
        };
        // A frame refused for a numerical failure was counted as accepted too.
        let handled = current.frames.saturating_sub(base_frames) + errors - numerical;
        if handled >= sent.frames {
            break;
        }
        if let Some(reason) = closed {
            bail!(
                "the server closed the ingest socket before handling every frame ({handled} of {}): {reason}",
                sent.frames
            );
        }
        if handled != last_progress.1 {
            last_progress = (Instant::now(), handled);
        } else if last_progress.0.elapsed() > DRAIN_STALL {
            bail!(
                "the server handled {handled} of {} frames and then nothing for {} s",
                sent.frames,
                DRAIN_STALL.as_secs()
            );
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let deadline = Instant::now() + ALARM_GRACE;
    loop {
        let current = stats(endpoint, path).await?;
        let want = current.alarms().saturating_sub(base_alarms);
        let got = tally.lock().unwrap_or_else(|p| p.into_inner()).alarm_total;
        if got >= want {
            return Ok(current);
        }
        if Instant::now() > deadline {
            eprintln!("warning: the stats count {want} alarms, the socket delivered {got}");
            return Ok(current);
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

fn num(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "—".to_owned(), |x| format!("{x:.digits$}"))
}

/// Renders the summary as text.
pub(crate) fn render(s: &ReplaySummary) -> String {
    let mut out = String::new();
    let rate = if s.wall_s > 0.0 {
        s.epochs_sent as f64 / s.wall_s
    } else {
        0.0
    };
    let _ = writeln!(
        out,
        "session {}{}: sent {} epochs in {} frames, {:.1} s ({} epochs/s)",
        s.session,
        if s.created { " (created)" } else { "" },
        thousands(s.epochs_sent),
        thousands(s.frames_sent),
        s.wall_s,
        thousands(rate.round() as u64)
    );
    if s.errors.is_empty() {
        let _ = writeln!(out, "errors: none");
    } else {
        let list: Vec<String> = s.errors.iter().map(|(c, n)| format!("{c} {n}")).collect();
        let _ = writeln!(out, "errors: {}", list.join(", "));
        for sample in &s.error_samples {
            let _ = writeln!(out, "  e.g. {sample}");
        }
    }
    let total: u64 = s.alarm_groups.iter().map(|g| g.count).sum();
    let _ = writeln!(out, "alarms: {total} ({} state changes)", s.state_changes);
    if !s.alarm_groups.is_empty() {
        let _ = writeln!(
            out,
            "  {:<12} {:<8} {:<9} {:>6} {:>10} {:>10}",
            "monitor", "test", "state", "count", "first t", "last t"
        );
        for g in &s.alarm_groups {
            let _ = writeln!(
                out,
                "  {:<12} {:<8} {:<9} {:>6} {:>10.2} {:>10.2}",
                g.monitor, g.test, g.state, g.count, g.first_t, g.last_t
            );
        }
    }
    render_stats(&mut out, &s.stats);
    out
}

/// The stats part of the summary: session counts, then one row per test.
fn render_stats(out: &mut String, view: &SessionStats) {
    let _ = writeln!(
        out,
        "stats: {} epochs processed, {} frames, {} refused, last t {}",
        thousands(view.epochs),
        thousands(view.frames),
        view.frame_errors,
        num(view.last_t, 2)
    );
    let _ = writeln!(
        out,
        "  {:<12} {:<8} {:<9} {:>8} {:>7} {:>6} {:>9} {:>10} {:>9} {:>27} {:>7}",
        "monitor",
        "test",
        "state",
        "epochs",
        "exceed",
        "alarms",
        "threshold",
        "mean λ",
        "max λ",
        "healthy/suspect/isolated s",
        "delay"
    );
    for (name, m) in &view.monitors {
        for (test, t) in &m.tests {
            let time = &t.time_in_state_s;
            let _ = writeln!(
                out,
                "  {:<12} {:<8} {:<9} {:>8} {:>7} {:>6} {:>9} {:>10} {:>9} {:>27} {:>7}",
                name,
                test,
                t.state.as_str(),
                t.epochs,
                t.exceedances,
                t.alarms,
                num(Some(t.threshold), 2),
                num(t.mean, 3),
                num(t.max, 1),
                format!(
                    "{}/{}/{}",
                    num(Some(time.healthy), 0),
                    num(Some(time.suspect), 0),
                    num(Some(time.isolated), 0)
                ),
                num(t.last_alarm_delay_s, 1)
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use navguard::detect::Health;
    use navguard::service::wire::{AlarmRecord, StateChange, tagged};
    use navguard::session::stats::TestStats;

    #[derive(Debug, Parser)]
    struct Wrap {
        #[command(flatten)]
        args: ReplayArgs,
    }

    fn args(extra: &[&str]) -> ReplayArgs {
        let mut argv = vec!["replay", "f.jsonl", "--session", "s1"];
        argv.extend_from_slice(extra);
        Wrap::try_parse_from(argv).unwrap().args
    }

    #[test]
    fn speeds_parse_as_factors_or_max() {
        assert_eq!("max".parse::<Speed>(), Ok(Speed::Max));
        assert_eq!("10x".parse::<Speed>(), Ok(Speed::Factor(10.0)));
        assert_eq!("0.5".parse::<Speed>(), Ok(Speed::Factor(0.5)));
        assert!("0x".parse::<Speed>().is_err());
        assert!("fast".parse::<Speed>().is_err());
    }

    #[test]
    fn a_file_with_ins_gets_a_federated_monitor_over_its_aids() {
        let scan = FileScan {
            epochs: 3,
            ins: true,
            gnss: true,
            cns: true,
            ..FileScan::default()
        };
        let body = session_body(&args(&["--threshold", "20"]), &scan).unwrap();
        assert_eq!(body.id.as_deref(), Some("s1"));
        let m = &body.monitors[0];
        assert_eq!(
            (m.name.as_str(), m.kind),
            ("federated", MonitorKind::Federated)
        );
        let config: FederatedConfigWire = serde_json::from_value(m.config.clone()).unwrap();
        assert_eq!(config, FederatedConfigWire::new(vec![Aid::Gnss, Aid::Cns]));
        // The monitor runs exactly as it would on the bare aids list.
        let parse = navguard::monitor::federated::FederatedConfig::from_json;
        assert_eq!(
            parse(&m.config).unwrap(),
            parse(&serde_json::json!({"aids": ["gnss", "cns"]})).unwrap()
        );
        assert_eq!(m.policy, PolicyConfig::Counters { n1: 10, n2: 5 });
        assert_eq!((m.threshold, m.p_fa), (Some(20.0), None));
        let body = session_body(&args(&["--policy", "classic"]), &scan).unwrap();
        assert_eq!(body.monitors[0].policy, PolicyConfig::Classic);
        assert_eq!(body.monitors[0].threshold, None);
    }

    #[test]
    fn a_linear_file_needs_its_model() {
        let scan = FileScan {
            epochs: 3,
            z: true,
            ..FileScan::default()
        };
        assert!(session_body(&args(&[]), &scan).is_err());
        let body = session_body(
            &args(&[
                "--monitor-config",
                r#"{"f":[[1]],"h":[[1]],"q":[[1]],"r":[[1]],"x0":[0],"p0":[[1]]}"#,
            ]),
            &scan,
        )
        .unwrap();
        assert_eq!(body.monitors[0].kind, MonitorKind::Linear);
        let wire = serde_json::to_value(&body).unwrap();
        assert_eq!(wire["monitors"][0]["config"]["f"], serde_json::json!([[1]]));
        assert_eq!(wire["monitors"][0]["type"], "linear");
        assert!(session_body(&args(&[]), &FileScan::default()).is_err());
    }

    #[test]
    fn a_bad_session_name_is_refused_before_any_request() {
        let mut a = args(&[]);
        a.session = "no spaces".into();
        let runtime = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        let err = runtime.block_on(run(a)).unwrap_err().to_string();
        assert!(err.contains("--session must be"), "{err}");
    }

    fn alarm(test: &str, t: f64) -> String {
        let record = AlarmRecord {
            id: 1,
            session: "s1".into(),
            monitor: "nav".into(),
            test: test.into(),
            state: Health::Suspect,
            t,
            statistic: 30.0,
            threshold: 20.0,
            dof: 3,
            test_ratio: 1.5,
            delay_s: 0.0,
            raised_at_ms: 0,
            cleared_t: None,
            severity: Default::default(),
        };
        tagged("alarm", &record)
    }

    #[test]
    fn tally_groups_alarms_and_counts_errors() {
        let mut t = Tally::default();
        for (i, test) in ["gnss", "gnss", "dvl"].iter().enumerate() {
            t.take(&alarm(test, i as f64 + 1.5));
        }
        t.take(r#"{"type":"error","code":"time_backwards","message":"m"}"#);
        t.take(r#"{"type":"error","code":"numerical","message":"n \"quoted\""}"#);
        let change = StateChange {
            session: "s1".into(),
            monitor: "nav".into(),
            test: "gnss".into(),
            t: 1.5,
            from: Health::Healthy,
            to: Health::Suspect,
            severity: None,
            log_id: None,
        };
        t.take(&tagged("state", &change));
        t.take(r#"{"type":"result","t":1.0,"monitors":{}}"#);
        t.take(r#"{"type":"ready","session":"s1"}"#);
        assert_eq!(t.alarm_total, 3);
        let g = &t.alarms[&("nav".into(), "gnss".into(), "suspect".into())];
        assert_eq!((g.count, g.first_t, g.last_t), (2, 1.5, 2.5));
        assert_eq!(
            (t.error_total, t.numerical, t.states, t.results),
            (2, 1, 1, 1)
        );
        assert_eq!(t.errors["time_backwards"], 1);
        assert_eq!(t.error_samples[1], r#"numerical: n "quoted""#);
    }

    #[test]
    fn stats_are_read_as_the_services_session_stats() {
        let test = |alarms: u64| {
            let mut t = TestStats::new(1, 10.0);
            t.alarms = alarms;
            t
        };
        let body = serde_json::json!({"session": "s", "connected": true, "frames": 4,
            "epochs": 8, "frame_errors": 0, "last_t": 0.8, "last_frame_at_ms": null,
            "published_at_ms": 0, "epochs_per_s": 0.0,
            "monitors": {"a": {"type": "linear", "epochs": 8, "worst_test_ratio": null,
                               "tests": {"x": test(2), "y": test(1)}},
                         "b": {"type": "federated", "epochs": 8, "worst_test_ratio": 0.5,
                               "tests": {"z": test(4)}}}});
        let stats = parse_stats(&body.to_string()).unwrap();
        assert_eq!((stats.frames, stats.alarms()), (4, 7));
        assert_eq!(stats.monitors["b"].kind, MonitorKind::Federated);
        assert!(parse_stats("{}").is_err());
    }
}
