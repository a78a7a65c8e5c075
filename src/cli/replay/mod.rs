//! `navguard replay FILE.jsonl`: streams a JSON-lines file of ingest frames
//! (one epoch per line, as `navguard simulate` writes them) into a session of a
//! running navguard over the ingest socket, at real time × a factor or as fast
//! as the server takes it, while reading the socket concurrently (alarms, state
//! changes, errors); then prints a summary with the session's `/stats`.
//!
//! The client talks only to the `--url` it is given, holds at most one batch
//! and a bounded summary in memory, and gives up with a clear message when the
//! server cannot be reached or closes the socket.
//!
//! In the order a run goes: [`input`] scans and then reads the file, [`spec`]
//! finds or creates the session, [`stream`] sends the epochs and reads the
//! socket, [`drain`] waits for the server to finish, and [`summary`] tallies
//! what came back and prints it.

use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{Context, bail};
use futures_util::{SinkExt, StreamExt};
use navguard::service::session::spec::valid_name;
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_tungstenite::tungstenite::protocol::CloseFrame;
use tokio_tungstenite::tungstenite::{self, Message};

use super::http::Endpoint;
use super::progress_bar;

mod drain;
mod input;
mod spec;
mod stream;
mod summary;

use drain::{drain, stats};
use input::scan;
use spec::ensure_session;
use stream::{Link, Sink, read_events, stream_file};
use summary::{ReplaySummary, Tally, render};

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
    `federated` with `input: imu` when the file has `imu` blocks and no `ins`
        (`navguard convert --format imu-csv`'s output), with config
        --monitor-config or, by default, {\"aids\": [\"gnss\"], \"input\": \"imu\"};
    `gnss` when the file has `gnss_raw` blocks and no `ins` (`navguard convert`'s
        output), with config --monitor-config or, by default, {} (every default);
    `linear` when the file has `z` blocks and no `ins` (needs --monitor-config);
  policy --policy (default counters, --n1 10 --n2 5), threshold --threshold or
  --p-fa (default p_fa 0.002).
The summary lists epochs and frames sent, errors by code, alarms by monitor,
test and state with first and last t, and the session's /stats per test. The
exit status is non-zero when the server cannot be reached or drops the socket,
not when it refuses frames (those are counted in the summary).";

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
    let messages = messages_file(args.messages.as_deref())?;
    let tally = Arc::new(Mutex::new(Tally::new(messages)));
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
    let (sink, sent, baseline) = match outcome {
        Ok(done) => done,
        Err(e) => {
            reader.abort();
            return Err(e);
        }
    };
    let drained = drain(&endpoint, &path, &baseline, &sent, &tally).await;
    let wall_s = started.elapsed().as_secs_f64();
    close(sink, reader).await;
    let final_stats = drained?;
    let mut tally = std::mem::take(&mut *tally.lock().unwrap_or_else(|p| p.into_inner()));
    tally.flush_messages()?;
    let summary = ReplaySummary::new(
        args.session.clone(),
        created,
        sent,
        wall_s,
        tally,
        final_stats,
    );
    print!("{}", render(&summary));
    if let Some(path) = &args.summary_json {
        let text = serde_json::to_string_pretty(&summary)?;
        std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// `--messages`: the file every result, state and alarm message is copied to.
fn messages_file(path: Option<&Path>) -> anyhow::Result<Option<BufWriter<std::fs::File>>> {
    path.map(|path| {
        std::fs::File::create(path)
            .map(BufWriter::new)
            .with_context(|| format!("creating {}", path.display()))
    })
    .transpose()
}

/// Closes the ingest socket normally and gives the reader up to 2 s to see the close.
async fn close(mut sink: Sink, reader: JoinHandle<()>) {
    let _ = sink
        .send(Message::Close(Some(CloseFrame {
            code: tungstenite::protocol::frame::coding::CloseCode::Normal,
            reason: "replay finished".into(),
        })))
        .await;
    let _ = tokio::time::timeout(Duration::from_secs(2), reader).await;
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Wrap {
        #[command(flatten)]
        args: ReplayArgs,
    }

    /// `replay f.jsonl --session s1` with `extra` flags.
    pub(super) fn args(extra: &[&str]) -> ReplayArgs {
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
    fn a_bad_session_name_is_refused_before_any_request() {
        let mut a = args(&[]);
        a.session = "no spaces".into();
        let runtime = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        let err = runtime.block_on(run(a)).unwrap_err().to_string();
        assert!(err.contains("--session must be"), "{err}");
    }
}
