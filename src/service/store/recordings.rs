//! The flight recorder's storage (docs/architecture.md §A12): every accepted ingest
//! frame of a recording session, in order, as the client sent it, with the state
//! changes, alarms and availability changes it caused and their epoch index, in the
//! `recording_frames` table of the same database.
//!
//! Frames reach a writer task through a bounded queue and are committed in groups as
//! soon as they arrive (no timer): a frame is stored within one commit of the moment its
//! epochs were processed, so a `kill -9` loses at most the frames processed during the
//! last commit and those still queued (bounded by [`QUEUE`]); what was committed is intact
//! (SQLite WAL, or Postgres). The writer also applies the retention limits after each commit:
//!
//! 1. frames older than the maximum age, from every session;
//! 2. a session over its byte limit loses its oldest frames;
//! 3. over the total byte limit, the oldest frames of all (lowest ids first).

use std::collections::HashMap;
use std::sync::Arc;

use tokio::sync::{mpsc, oneshot};

use super::{Pool, StoreError};

/// Frames waiting for the writer before actors wait for room (the loss window's bound).
pub const QUEUE: usize = 4096;
/// Frames taken into one transaction at most.
const GROUP: usize = 512;

/// Retention limits (docs/architecture.md §A12).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Retention {
    /// Bytes of frames kept per session.
    pub session_bytes: u64,
    /// Bytes of frames kept in all.
    pub total_bytes: u64,
    /// Age beyond which frames are dropped, ms.
    pub max_age_ms: i64,
}

impl Default for Retention {
    fn default() -> Self {
        Retention {
            session_bytes: 64 << 20,
            total_bytes: 1 << 30,
            max_age_ms: 7 * 24 * 3600 * 1000,
        }
    }
}

/// One recorded frame.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedFrame {
    /// Session id.
    pub session: String,
    /// The ingest stream it came on: its attach time, Unix ms (unique per session, also
    /// across server restarts).
    pub stream: u64,
    /// Index, within its stream, of the frame's first epoch.
    pub first_epoch: u64,
    /// Epochs of the frame that were processed (a frame refused part-way keeps the
    /// epochs before the refusal).
    pub epochs: u64,
    /// Wall-clock time it was processed, Unix ms.
    pub recorded_at_ms: i64,
    /// The frame as the client sent it.
    pub frame: Arc<str>,
    /// The messages it caused (`state`, `alarm`, `availability`), each a JSON object
    /// with its `epoch_index`, as a JSON array.
    pub events: String,
}

enum Command {
    /// A frame, written only while its fence (if any) holds.
    Frame(RecordedFrame, Option<super::Fence>),
    /// Answered once everything queued before it is committed.
    Flush(oneshot::Sender<()>),
}

/// The handle actors hold: a queue to the writer task.
#[derive(Debug, Clone)]
pub struct RecordingWriter {
    tx: mpsc::Sender<Command>,
}

impl std::fmt::Debug for Command {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Command::Frame(r, _) => write!(f, "Frame({}, {})", r.session, r.first_epoch),
            Command::Flush(_) => write!(f, "Flush"),
        }
    }
}

impl RecordingWriter {
    /// Starts the writer task on the current runtime.
    pub(super) fn spawn(pool: Pool, retention: Retention) -> Self {
        let (tx, rx) = mpsc::channel(QUEUE);
        tokio::spawn(run(pool, rx, retention));
        RecordingWriter { tx }
    }

    /// Queues a frame (waits only for room in the queue), written only while `fence`
    /// holds.
    pub async fn record(&self, frame: RecordedFrame, fence: Option<super::Fence>) {
        if self.tx.send(Command::Frame(frame, fence)).await.is_err() {
            tracing::error!("recording writer stopped; frame not recorded");
        }
    }

    /// Waits until every frame queued before this call is committed.
    pub async fn flush(&self) {
        let (tx, rx) = oneshot::channel();
        if self.tx.send(Command::Flush(tx)).await.is_ok() {
            let _ = rx.await;
        }
    }
}

async fn run(pool: Pool, mut rx: mpsc::Receiver<Command>, retention: Retention) {
    let mut bytes = match Usage::load(&pool).await {
        Ok(u) => u,
        Err(e) => {
            tracing::error!(error = %e, "could not read the recording sizes; retention starts from zero");
            Usage::default()
        }
    };
    let mut batch = Vec::with_capacity(GROUP);
    while rx.recv_many(&mut batch, GROUP).await > 0 {
        let mut waiting = Vec::new();
        let mut frames = Vec::with_capacity(batch.len());
        for c in batch.drain(..) {
            match c {
                Command::Frame(f, fence) => frames.push((f, fence)),
                Command::Flush(reply) => waiting.push(reply),
            }
        }
        if !frames.is_empty() {
            match commit(&pool, &frames).await {
                Ok(written) => {
                    for (f, _) in frames.iter().zip(written).filter(|(_, w)| *w) {
                        bytes.add(&f.0.session, f.0.frame.len() as u64);
                    }
                }
                Err(e) => {
                    tracing::error!(error = %e, frames = frames.len(), "recording commit failed")
                }
            }
            if let Err(e) = enforce(&pool, &mut bytes, &retention).await {
                tracing::error!(error = %e, "recording retention failed");
            }
        }
        for reply in waiting {
            let _ = reply.send(());
        }
    }
}

/// Inserts `frames` in one transaction; which were written (a frame whose fence no
/// longer holds is not).
async fn commit(
    pool: &Pool,
    frames: &[(RecordedFrame, Option<super::Fence>)],
) -> Result<Vec<bool>, sqlx::Error> {
    with_pool!(pool, p => {
        let mut tx = p.begin().await?;
        let mut written = Vec::with_capacity(frames.len());
        for (f, fence) in frames {
            if let Some(fence) = fence {
                let held = sqlx::query(super::cluster::FENCE_SQL)
                    .bind(&fence.session)
                    .bind(&fence.owner)
                    .bind(fence.epoch)
                    .execute(&mut *tx)
                    .await?
                    .rows_affected();
                written.push(held > 0);
                if held == 0 {
                    continue;
                }
            } else {
                written.push(true);
            }
            sqlx::query(
                "INSERT INTO recording_frames (session, stream, first_epoch, epochs, recorded_at_ms, bytes, frame, events)
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
            )
            .bind(&f.session)
            .bind(f.stream as i64)
            .bind(f.first_epoch as i64)
            .bind(f.epochs as i64)
            .bind(f.recorded_at_ms)
            .bind(f.frame.len() as i64)
            .bind(&*f.frame)
            .bind(&f.events)
            .execute(&mut *tx)
            .await?;
        }
        tx.commit().await?;
        Ok(written)
    })
}

/// Bytes recorded per session and in all, kept by the writer (loaded once at start).
#[derive(Debug, Default)]
struct Usage {
    per_session: HashMap<String, u64>,
    total: u64,
}

impl Usage {
    async fn load(pool: &Pool) -> Result<Self, sqlx::Error> {
        // CAST: Postgres sums BIGINT as NUMERIC.
        let rows: Vec<(String, i64)> = with_pool!(pool, p => sqlx::query_as(
            "SELECT session, CAST(SUM(bytes) AS BIGINT) AS b FROM recording_frames GROUP BY session",
        )
        .fetch_all(p)
        .await?);
        let mut u = Usage::default();
        for (session, b) in rows {
            u.add(&session, b as u64);
        }
        Ok(u)
    }

    fn add(&mut self, session: &str, bytes: u64) {
        *self.per_session.entry(session.to_owned()).or_default() += bytes;
        self.total += bytes;
    }
}

/// Applies the retention limits in their order (module doc); recomputes the usage
/// whenever something was dropped.
async fn enforce(pool: &Pool, usage: &mut Usage, r: &Retention) -> Result<(), sqlx::Error> {
    let mut dropped = false;
    let cutoff = super::super::now_ms() - r.max_age_ms;
    let done = with_pool!(pool, p => sqlx::query("DELETE FROM recording_frames WHERE recorded_at_ms < $1")
        .bind(cutoff)
        .execute(p)
        .await?
        .rows_affected());
    dropped |= done > 0;
    let over: Vec<String> = usage
        .per_session
        .iter()
        .filter(|(_, b)| **b > r.session_bytes)
        .map(|(s, _)| s.clone())
        .collect();
    for session in over {
        // Drop the session's oldest frames until what stays fits its limit.
        with_pool!(pool, p => sqlx::query(
            "DELETE FROM recording_frames WHERE session = $1 AND id <= (
                SELECT id FROM (
                    SELECT id, CAST(SUM(bytes) OVER (ORDER BY id DESC) AS BIGINT) AS newer
                    FROM recording_frames WHERE session = $1
                ) AS w WHERE newer > $2 ORDER BY id DESC LIMIT 1
            )",
        )
        .bind(&session)
        .bind(r.session_bytes as i64)
        .execute(p)
        .await?.rows_affected());
        dropped = true;
    }
    if dropped {
        *usage = Usage::load(pool).await?;
    }
    if usage.total > r.total_bytes {
        with_pool!(pool, p => sqlx::query(
            "DELETE FROM recording_frames WHERE id <= (
                SELECT id FROM (
                    SELECT id, CAST(SUM(bytes) OVER (ORDER BY id DESC) AS BIGINT) AS newer
                    FROM recording_frames
                ) AS w WHERE newer > $1 ORDER BY id DESC LIMIT 1
            )",
        )
        .bind(r.total_bytes as i64)
        .execute(p)
        .await?.rows_affected());
        *usage = Usage::load(pool).await?;
    }
    Ok(())
}

/// A page of a session's recording: frames with an id above `after`, oldest first.
pub(super) async fn page(
    pool: &Pool,
    session: &str,
    stream: u64,
    after: i64,
    limit: i64,
) -> Result<Vec<(i64, RecordedFrame)>, StoreError> {
    type FrameRow = (i64, String, i64, i64, i64, i64, String, String);
    let rows: Vec<FrameRow> = with_pool!(pool, p => sqlx::query_as(
        "SELECT id, session, stream, first_epoch, epochs, recorded_at_ms, frame, events
         FROM recording_frames WHERE session = $1 AND stream = $2 AND id > $3 ORDER BY id LIMIT $4",
    )
    .bind(session)
    .bind(stream as i64)
    .bind(after)
    .bind(limit)
    .fetch_all(p)
    .await?);
    Ok(rows
        .into_iter()
        .map(
            |(id, session, stream, first_epoch, epochs, recorded_at_ms, frame, events)| {
                (
                    id,
                    RecordedFrame {
                        session,
                        stream: stream as u64,
                        first_epoch: first_epoch as u64,
                        epochs: epochs as u64,
                        recorded_at_ms,
                        frame: Arc::from(frame),
                        events,
                    },
                )
            },
        )
        .collect())
}

/// The streams a session has recorded, with their frames, epochs and bytes.
pub(super) async fn streams(pool: &Pool, session: &str) -> Result<Vec<StreamSummary>, StoreError> {
    let rows: Vec<(i64, i64, i64, i64, i64, i64)> = with_pool!(pool, p => sqlx::query_as(
        "SELECT stream, COUNT(*) AS frames, CAST(SUM(epochs) AS BIGINT) AS epochs,
                CAST(SUM(bytes) AS BIGINT) AS bytes,
                MIN(recorded_at_ms) AS first_ms, MAX(recorded_at_ms) AS last_ms
         FROM recording_frames WHERE session = $1 GROUP BY stream ORDER BY stream",
    )
    .bind(session)
    .fetch_all(p)
    .await?);
    Ok(rows
        .into_iter()
        .map(
            |(stream, frames, epochs, bytes, first_ms, last_ms)| StreamSummary {
                stream: stream as u64,
                frames: frames as u64,
                epochs: epochs as u64,
                bytes: bytes as u64,
                first_ms,
                last_ms,
            },
        )
        .collect())
}

/// One recorded stream of a session.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StreamSummary {
    /// The stream: its attach time, Unix ms.
    pub stream: u64,
    /// Frames kept.
    pub frames: u64,
    /// Epochs kept.
    pub epochs: u64,
    /// Bytes kept.
    pub bytes: u64,
    /// When the oldest kept frame was processed, Unix ms.
    pub first_ms: i64,
    /// When the newest was, Unix ms.
    pub last_ms: i64,
}
