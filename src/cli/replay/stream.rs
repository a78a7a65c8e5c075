//! Streaming the file into the ingest socket: epochs batched into frames at the
//! chosen speed, a reader task tallying what the server sends back, and with
//! `--resume` a reconnect that resends from the epoch after the one the session
//! resumed from.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::bail;
use futures_util::stream::{SplitSink, SplitStream};
use futures_util::{SinkExt, StreamExt};
use indicatif::ProgressBar;
use navguard_core::session::SessionStats;
use tokio::time::Instant;
use tokio_tungstenite::tungstenite::Message;

use super::drain::stats;
use super::input::{EpochLines, FileScan};
use super::summary::Tally;
use super::{ReplayArgs, Speed};
use crate::cli::http::{Endpoint, Socket};

/// How long `--resume` keeps trying to reconnect.
const RESUME_WINDOW: Duration = Duration::from_secs(30);

/// The sending half of the ingest socket.
pub(super) type Sink = SplitSink<Socket, Message>;

/// What was sent.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Sent {
    /// Epochs sent.
    pub(super) epochs: u64,
    /// Frames sent.
    pub(super) frames: u64,
}

/// The session the replay streams to, and its statistics when the current socket
/// attached (the drain counts what was sent on it from there).
pub(super) struct Link<'a> {
    /// The server.
    pub(super) endpoint: &'a Endpoint,
    /// `/api/v1/sessions/{id}`.
    pub(super) path: &'a str,
    /// The session's stats when the current socket attached.
    pub(super) baseline: SessionStats,
}

/// Reads the socket until it ends, tallying every text message; then records why
/// it ended in `tally.closed`.
pub(super) async fn read_events(mut stream: SplitStream<Socket>, tally: Arc<Mutex<Tally>>) {
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

/// `--resume`: reconnects (`resume=true`) until a socket attaches, within
/// [`RESUME_WINDOW`]; the new sink and the time the session resumed after (`ready`'s
/// `resumed.t`; `None`: a fresh stream, resend everything).
async fn reconnect(
    link: &mut Link<'_>,
    tally: &Arc<Mutex<Tally>>,
) -> anyhow::Result<(Sink, Option<f64>)> {
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

/// The file's epochs on their way into frames: the next epoch not yet sent, and
/// the rest of the file behind it.
struct Feed {
    lines: EpochLines,
    pending: Option<(f64, String)>,
}

impl Feed {
    /// Opens the file at its first epoch after `after` (at its first epoch for `None`).
    async fn open(path: &Path, after: Option<f64>) -> anyhow::Result<Self> {
        let mut lines = EpochLines::open(path).await?;
        let mut pending = lines.next().await?;
        while let (Some(after), Some((t, _))) = (after, &pending) {
            if *t > after {
                break;
            }
            pending = lines.next().await?;
        }
        Ok(Self { lines, pending })
    }

    /// Moves the epochs due by `now` into `batch` (cleared first), up to `max_epochs`
    /// and under `max_bytes` as a JSON array; always at least one. Returns the
    /// largest `t` taken, or `last_t` if larger.
    async fn fill(
        &mut self,
        batch: &mut Vec<String>,
        limits: (usize, usize),
        due: impl Fn(f64) -> Instant,
        now: Instant,
        mut last_t: f64,
    ) -> anyhow::Result<f64> {
        let (max_epochs, max_bytes) = limits;
        batch.clear();
        let mut bytes = 1;
        while let Some((t, line)) = self.pending.take() {
            let fits =
                batch.is_empty() || (batch.len() < max_epochs && bytes + line.len() < max_bytes);
            if !fits || due(t) > now {
                self.pending = Some((t, line));
                break;
            }
            bytes += line.len() + 1;
            last_t = last_t.max(t);
            batch.push(line);
            self.pending = self.lines.next().await?;
        }
        Ok(last_t)
    }
}

/// One frame's text: the epoch itself, or a JSON array of several.
fn frame_text(batch: &mut [String]) -> String {
    if batch.len() == 1 {
        std::mem::take(&mut batch[0])
    } else {
        format!("[{}]", batch.join(","))
    }
}

/// Sends one frame unless the reader saw the socket end; `Some(reason)` when the
/// socket is gone.
async fn send_frame(sink: &mut Sink, tally: &Arc<Mutex<Tally>>, text: String) -> Option<String> {
    let closed_before = tally
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .closed
        .clone();
    match closed_before {
        Some(reason) => Some(reason),
        None => sink
            .send(Message::Text(text.into()))
            .await
            .err()
            .map(|e| e.to_string()),
    }
}

/// `--resume` after the socket dropped: a new socket, and the file reopened after
/// the epoch the session resumed from (all of it when the session starts afresh).
async fn resume(
    link: &mut Link<'_>,
    tally: &Arc<Mutex<Tally>>,
    file: &Path,
    progress: &ProgressBar,
) -> anyhow::Result<(Sink, Feed)> {
    let (sink, resumed_t) = reconnect(link, tally).await?;
    let feed = Feed::open(file, resumed_t).await?;
    progress.suspend(|| match resumed_t {
        Some(t) => eprintln!("resumed after t = {t}; resending from there"),
        None => eprintln!("resumed with a fresh stream; resending from the start"),
    });
    Ok((sink, feed))
}

/// The progress bar's position and message after a frame.
fn show_progress(
    progress: &ProgressBar,
    tally: &Arc<Mutex<Tally>>,
    sent: Sent,
    last_t: f64,
    scan: &FileScan,
) {
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

/// Streams the whole file: the sink, what was sent and the session's stats when
/// the last socket attached.
pub(super) async fn stream_file(
    args: &ReplayArgs,
    scan: &FileScan,
    mut sink: Sink,
    tally: &Arc<Mutex<Tally>>,
    progress: &ProgressBar,
    mut link: Link<'_>,
) -> anyhow::Result<(Sink, Sent, SessionStats)> {
    let mut feed = Feed::open(&args.file, None).await?;
    let start = Instant::now();
    let due = |t: f64| match args.speed {
        Speed::Max => start,
        Speed::Factor(f) => start + Duration::from_secs_f64(((t - scan.first_t) / f).max(0.0)),
    };
    let limits = (args.batch as usize, args.max_frame_bytes);
    let mut sent = Sent::default();
    let mut batch: Vec<String> = Vec::new();
    let mut last_t = scan.first_t;
    while let Some((t, _)) = &feed.pending {
        if let Speed::Factor(_) = args.speed {
            tokio::time::sleep_until(due(*t)).await;
        }
        let now = Instant::now();
        last_t = feed.fill(&mut batch, limits, due, now, last_t).await?;
        let text = frame_text(&mut batch);
        if let Some(reason) = send_frame(&mut sink, tally, text).await {
            if !args.resume {
                bail!(
                    "the server dropped the ingest socket after {} epochs: {reason} (--resume reconnects)",
                    sent.epochs
                );
            }
            progress.suspend(|| eprintln!("ingest socket lost ({reason}); resuming"));
            // What is sent from here is counted afresh.
            (sink, feed) = resume(&mut link, tally, &args.file, progress).await?;
            sent = Sent::default();
            continue;
        }
        sent.frames += 1;
        sent.epochs += batch.len() as u64;
        show_progress(progress, tally, sent, last_t, scan);
    }
    Ok((sink, sent, link.baseline))
}
