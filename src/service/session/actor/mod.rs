//! The session actor: one task per session running its [`SessionCore`] and carrying out
//! what the core decides, in order (docs/architecture.md §A3). It owns the session's
//! state, so nothing else touches it and the hot path takes no lock. Its jobs, one file
//! each:
//!
//! - this file: the task loop, control commands, statistics publication;
//! - [`frames`]: a frame validated, stepped a slice at a time (on this task or the
//!   compute pool), the next frame stepped while this one commits;
//! - [`effects`]: the core's effects carried out: log entries committed, then
//!   announced to the ingest socket, the events subscribers and the cluster bus;
//! - [`control`]: attach (a new or resumed stream), thresholds, persist;
//! - [`recording`]: the flight recorder's frames and their messages;
//! - [`lease`]: cluster ownership: fence, checkpoints, handover.

mod control;
mod effects;
mod frames;
mod lease;
mod recording;

use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::extract::ws::Utf8Bytes;
use bytes::BytesMut;
use tokio::sync::{mpsc, watch};

use super::SessionError;
use super::handle::{ControlCommand, FrameCommand, SessionHandle, SessionShared};
use super::spec::{NamedMonitors, build_monitors};
use crate::service::cluster::{Cluster, bus};
use crate::service::compute::ComputePool;
use crate::service::metrics::Metrics;
use crate::service::now_ms;
use crate::service::store::{Checkpoint, Fence, Store, StoredSession};
use crate::service::train::Models;
use crate::service::wire::{self, ErrorEvent, FrameError};
use lease::Owned;
use navguard_core::session::{Effect, Seat, SessionCore, SessionStats};

/// Frames queued per session before the ingest socket stops reading.
const FRAME_QUEUE: usize = 8;
/// Control commands queued per session.
const CONTROL_QUEUE: usize = 64;
/// Messages queued for the ingest socket before the actor waits for it.
const INGEST_QUEUE: usize = 1024;
/// Statistics are published at most this often while an events socket watches the
/// session (it sends ≤ 20/s).
const STATS_PERIOD: Duration = Duration::from_millis(50);
/// … and at most this often while none does: the snapshot then only feeds the session
/// list, `/metrics` and the cluster bus (which sends one per [`bus::STATS_PERIOD`]), and
/// a copy of the statistics per 10 Hz frame was ~8 % of a busy server's CPU.
const UNWATCHED_STATS_PERIOD: Duration = bus::STATS_PERIOD;

/// What an actor needs from the service.
#[derive(Debug, Clone)]
pub struct ActorDeps {
    /// The store, for alarms.
    pub store: Store,
    /// Process metrics.
    pub metrics: Arc<Metrics>,
    /// Trained models, for monitors that name one (`config.model`).
    pub models: Arc<Models>,
    /// Where monitors are stepped, off the runtime.
    pub compute: Arc<ComputePool>,
    /// Sessions record unless they say otherwise.
    pub record_default: bool,
    /// Samples of statistics history kept (one per second of epoch time).
    pub history_samples: usize,
    /// The cluster this node belongs to (`--nats`), if any.
    pub cluster: Option<Arc<Cluster>>,
}

struct Actor {
    id: Arc<str>,
    echo: bool,
    /// The session's monitors, decisions, statistics and history.
    core: SessionCore,
    /// The effects of the epoch being committed (a buffer kept across epochs).
    effects: Vec<Effect>,
    deps: ActorDeps,
    shared: Arc<SessionShared>,
    stats_tx: watch::Sender<Arc<SessionStats>>,
    last_published: Instant,
    /// Statistics changed since the last publication (held back by the rate limit);
    /// a timer publishes them so a stream's last frame is never left unseen.
    stats_pending: bool,
    ingest: Option<mpsc::Sender<Utf8Bytes>>,
    /// The `result` frames of the frame being processed, written one after another into
    /// one buffer (each is sent as a slice of it); released when the frame is done.
    results: BytesMut,
    /// Length of the last `result` frame, to size the buffer for a frame's epochs.
    result_len: usize,
    /// Where one `result` frame is serialised before it joins [`Actor::results`]
    /// (serde_json writes many small pieces, which a `Vec` takes fastest).
    scratch: Vec<u8>,
    stream: u64,
    rate_window: (Instant, u64),
    /// Record every accepted frame (docs/architecture.md §A12).
    record: bool,
    /// The current stream's id in the recording: its attach time, Unix ms (made
    /// increasing), so streams stay apart across server restarts, whose attach
    /// generations start again at 1.
    recording_stream: u64,
    /// The messages the frame being processed caused, each with its epoch index, for
    /// the recording.
    frame_events: Vec<String>,
    /// Cluster ownership: the lease this actor writes under, its checkpoints and events.
    owned: Option<Owned>,
    /// The session holds a stream's state that a resuming stream may carry on from.
    resumable: bool,
    /// Compute time per epoch of the last slice stepped (all monitors), `None` before
    /// the first: decides whether a frame is stepped on the actor's task or on the
    /// compute pool (see [`frames::INLINE_BUDGET`]).
    epoch_cost: Option<Duration>,
}

/// The built monitors of `stored`, each with its alarm level (its own, else the
/// session's, else the default).
fn seats(monitors: NamedMonitors, stored: &StoredSession) -> Vec<Seat> {
    monitors
        .into_iter()
        .zip(&stored.monitors)
        .map(|((name, monitor), wire)| Seat {
            name,
            monitor,
            alarm_level: wire.alarm_level.or(stored.alarm_level).unwrap_or_default(),
        })
        .collect()
}

/// Builds the monitors of `stored` and starts its actor.
pub async fn spawn(stored: StoredSession, deps: ActorDeps) -> Result<SessionHandle, SessionError> {
    let monitors = build_blocking(&stored, &deps.models).await?;
    spawn_inner(stored, monitors, deps, None, None)
}

/// Builds the monitors of `stored` on the blocking pool: a stored model under the
/// predictive residual scale factorises its N × N training matrix (seconds at N = 5,000,
/// docs/methods.md §M14), which must not hold a runtime worker.
async fn build_blocking(
    stored: &StoredSession,
    models: &Arc<Models>,
) -> Result<NamedMonitors, SessionError> {
    let (stored, models) = (stored.clone(), models.clone());
    tokio::task::spawn_blocking(move || build_monitors(&stored, &*models))
        .await
        .map_err(|e| SessionError::Unavailable(format!("building the monitors failed: {e}")))?
}

/// Starts the actor of a session this node holds the lease of (cluster), its state
/// restored from `checkpoint` when there is one (docs/deployment.md, Failover). A
/// checkpoint that cannot be restored (written by another version, another spec) is
/// logged and the session starts afresh.
pub async fn spawn_owned(
    stored: StoredSession,
    deps: ActorDeps,
    fence: Fence,
    checkpoint: Option<Checkpoint>,
) -> Result<SessionHandle, SessionError> {
    let monitors = build_blocking(&stored, &deps.models).await?;
    spawn_inner(stored, monitors, deps, Some(fence), checkpoint)
}

fn spawn_inner(
    stored: StoredSession,
    monitors: NamedMonitors,
    deps: ActorDeps,
    fence: Option<Fence>,
    checkpoint: Option<Checkpoint>,
) -> Result<SessionHandle, SessionError> {
    let mut core = SessionCore::new(&stored.id, seats(monitors, &stored), deps.history_samples);
    let id = core.id().clone();
    let lease_epoch = fence.as_ref().map(|f| f.epoch);
    let owned = match (&deps.cluster, fence) {
        (Some(cluster), Some(fence)) => Some(Owned::new(cluster.clone(), fence)),
        _ => None,
    };
    core.stats_mut().published_at_ms = now_ms();
    let (stats_tx, stats_rx) = watch::channel(Arc::new(core.stats().clone()));
    let (frames_tx, frames_rx) = mpsc::channel(FRAME_QUEUE);
    let (control_tx, control_rx) = mpsc::channel(CONTROL_QUEUE);
    let shared = Arc::new(SessionShared {
        stored: std::sync::Mutex::new(stored.clone()),
        subscribers: Default::default(),
    });
    let mut actor = Actor {
        id: id.clone(),
        echo: stored.echo,
        core,
        effects: Vec::new(),
        record: stored.record.unwrap_or(deps.record_default),
        deps,
        shared: shared.clone(),
        stats_tx,
        last_published: Instant::now(),
        stats_pending: false,
        ingest: None,
        results: BytesMut::new(),
        result_len: wire::RESULT_FRAME_BYTES,
        scratch: Vec::new(),
        stream: 0,
        rate_window: (Instant::now(), 0),
        epoch_cost: None,
        recording_stream: 0,
        frame_events: Vec::new(),
        owned,
        resumable: false,
    };
    if let Some(checkpoint) = checkpoint {
        actor.restore(&checkpoint);
    }
    tokio::spawn(actor.run(frames_rx, control_rx));
    Ok(SessionHandle::new(
        id,
        lease_epoch,
        frames_tx,
        control_tx,
        stats_rx,
        shared,
    ))
}

/// Whether the actor goes on after a command or frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Flow {
    Continue,
    Stop,
}

/// Moves a kept timer to `at`, touching the runtime's timer wheel only when it changes.
fn rearm(timer: std::pin::Pin<&mut tokio::time::Sleep>, at: Instant) {
    let at = tokio::time::Instant::from_std(at);
    if timer.deadline() != at {
        timer.reset(at);
    }
}

impl Actor {
    async fn run(
        mut self,
        mut frames: mpsc::Receiver<FrameCommand>,
        mut control: mpsc::Receiver<ControlCommand>,
    ) {
        // The two timers live across iterations and are moved only when their deadline
        // does: made afresh in every iteration, each 10 Hz frame registered and removed
        // a timer in the runtime's wheel.
        let trailing = tokio::time::sleep(Duration::ZERO);
        let checkpoint_at = tokio::time::sleep(Duration::ZERO);
        tokio::pin!(trailing, checkpoint_at);
        loop {
            if self.fenced() {
                tracing::warn!(session = %self.id, "lease fenced: another node owns the session; stopping here");
                break;
            }
            if self.stats_pending {
                rearm(trailing.as_mut(), self.last_published + self.stats_period());
            }
            let due = self.owned.as_ref().and_then(|o| o.due);
            if let Some(due) = due {
                rearm(checkpoint_at.as_mut(), due);
            }
            tokio::select! {
                biased;
                command = control.recv() => match command {
                    Some(command) => {
                        if self.command(command).await == Flow::Stop {
                            break;
                        }
                    }
                    None => break,
                },
                frame = frames.recv() => match frame {
                    Some(frame) => {
                        if self.frames(frame, &mut frames, &mut control).await == Flow::Stop {
                            break;
                        }
                    }
                    None => break,
                },
                () = &mut trailing, if self.stats_pending => {
                    self.publish(true);
                }
                () = &mut checkpoint_at, if due.is_some() => {
                    self.checkpoint(false).await;
                }
            }
        }
        // Close every event subscriber's queue so their sockets end too.
        self.shared
            .subscribers
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clear();
        tracing::debug!(session = %self.id, "session actor stopped");
    }

    /// Serves one control command; `Stop` when the actor must end (shutdown, the session
    /// deleted or handed over).
    async fn command(&mut self, command: ControlCommand) -> Flow {
        match command {
            ControlCommand::Shutdown => Flow::Stop,
            ControlCommand::Delete(reply) => {
                let deleted = self.delete().await;
                let stop = deleted.is_ok();
                let _ = reply.send(deleted);
                if stop { Flow::Stop } else { Flow::Continue }
            }
            ControlCommand::Release { force, reply } => {
                let answer = self.release(force).await;
                let stop = answer.is_ok();
                let _ = reply.send(answer);
                if stop { Flow::Stop } else { Flow::Continue }
            }
            ControlCommand::Attach { resume, reply } => {
                let attached = self.attach(resume).await;
                let _ = reply.send(attached);
                Flow::Continue
            }
            ControlCommand::Detach(stream) => {
                self.detach(stream);
                Flow::Continue
            }
            ControlCommand::GetThreshold(name, reply) => {
                let view = self.find(&name).map(|i| self.core.threshold_view(i));
                let _ = reply.send(view);
                Flow::Continue
            }
            ControlCommand::SetThreshold(name, update, reply) => {
                let _ = reply.send(self.set_threshold(&name, update).await);
                Flow::Continue
            }
            ControlCommand::Persist(reply) => {
                let _ = reply.send(self.persist().await);
                Flow::Continue
            }
            ControlCommand::History(since, reply) => {
                let _ = reply.send(self.core.history().view(since));
                Flow::Continue
            }
            ControlCommand::Stats(reply) => {
                self.core.refresh_consistency();
                let stats = self.core.stats_mut();
                stats.published_at_ms = now_ms();
                let _ = reply.send(stats.clone());
                Flow::Continue
            }
        }
    }

    /// The index of monitor `name`, or the 404 error.
    fn find(&self, name: &str) -> Result<usize, SessionError> {
        self.core.find(name).ok_or_else(|| SessionError::NoMonitor {
            session: self.id.to_string(),
            monitor: name.to_owned(),
        })
    }

    async fn send_ingest(&mut self, text: impl Into<Utf8Bytes>) {
        if let Some(tx) = &self.ingest
            && tx.send(text.into()).await.is_err()
        {
            self.ingest = None;
        }
    }

    async fn reject(&mut self, error: FrameError) {
        self.core.stats_mut().frame_errors += 1;
        self.deps
            .metrics
            .frame_errors
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let text = serde_json::to_string(&ErrorEvent::from(&error)).unwrap_or_default();
        self.send_ingest(text).await;
    }

    /// How often statistics are published: [`STATS_PERIOD`] while an events socket
    /// subscribes, else [`UNWATCHED_STATS_PERIOD`].
    fn stats_period(&self) -> Duration {
        let mut subscribers = self
            .shared
            .subscribers
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        subscribers.retain(|tx| !tx.is_closed());
        if subscribers.is_empty() {
            UNWATCHED_STATS_PERIOD
        } else {
            STATS_PERIOD
        }
    }

    /// Publishes the statistics (to the `watch`, and the cluster bus at its own rate)
    /// when `force` or a period has passed; else marks them pending for the timer.
    fn publish(&mut self, force: bool) {
        let now = Instant::now();
        if !force && now.duration_since(self.last_published) < self.stats_period() {
            self.stats_pending = true;
            return;
        }
        self.last_published = now;
        self.stats_pending = false;
        self.core.refresh_consistency();
        self.core.stats_mut().published_at_ms = now_ms();
        let snapshot = Arc::new(self.core.stats().clone());
        if let Some(o) = &mut self.owned
            && now.duration_since(o.last_stats) >= bus::STATS_PERIOD
        {
            o.last_stats = now;
            o.cluster
                .publish(bus::stats(&self.id, wire::tagged("stats", &*snapshot)));
        }
        self.stats_tx.send_replace(snapshot);
    }
}
