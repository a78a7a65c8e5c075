//! The handle to a session actor: bounded channels in, `oneshot` replies out,
//! a `watch` of the latest statistics and the list of event subscribers.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::sync::{mpsc, oneshot, watch};

use super::SessionError;
use crate::service::store::StoredSession;
use crate::service::wire::{ThresholdUpdate, ThresholdView};
use navguard_core::epoch::Epoch;
use navguard_core::session::SessionStats;

/// How long a REST call waits for a busy session actor before answering 503.
const CONTROL_TIMEOUT: Duration = Duration::from_secs(5);

/// Capacity of one event subscriber's queue of `alarm` and `state` messages.
/// A subscriber that falls this far behind is disconnected (never silently
/// skipped) and must re-read `/api/v1/alarms` after reconnecting.
pub const SUBSCRIBER_QUEUE: usize = 4096;

/// A batch of epochs from the ingest socket.
#[derive(Debug)]
pub struct FrameCommand {
    /// The stream (attach generation) the frame came from.
    pub stream: u64,
    /// Validated epochs, times non-decreasing.
    pub epochs: Vec<Epoch>,
    /// When the frame arrived, for the latency metric.
    pub received: Instant,
    /// The frame as the client sent it, for a recording session.
    pub text: Option<Arc<str>>,
}

/// Where a resumed stream carries on: the state includes the stream's epochs up to and
/// including time `t` (`epochs` of them), so the client resends from the first epoch after
/// `t` (docs/deployment.md, Failover).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Resumed {
    /// Time of the last epoch the state includes (`None`: no epoch yet).
    pub t: Option<f64>,
    /// Epochs of the stream the state includes.
    pub epochs: u64,
}

/// An attached ingest stream: its generation and the messages for its socket.
#[derive(Debug)]
pub struct IngestLink {
    /// Set when the stream resumed the session's state instead of starting afresh.
    pub resumed: Option<Resumed>,
    /// Generation number; frames carry it.
    pub stream: u64,
    /// The session records its frames: send their text with them.
    pub record: bool,
    /// Messages (JSON text) for the ingest socket.
    pub outgoing: mpsc::Receiver<axum::extract::ws::Utf8Bytes>,
}

/// Commands other than frames; the actor serves them before pending frames.
#[derive(Debug)]
pub enum ControlCommand {
    /// Attach a new ingest stream: filter state starts afresh, unless `resume` (true) and
    /// the session holds a stream's state (restored from a checkpoint, or left by the
    /// previous stream), which then carries on.
    Attach {
        /// Carry on from the session's state when it holds a stream's.
        resume: bool,
        /// The new stream, or why not.
        reply: oneshot::Sender<Result<IngestLink, SessionError>>,
    },
    /// Hand the session over (cluster): refused while a stream is attached unless
    /// `force` (a drain: the stream is told `moved` and closed); then a final checkpoint
    /// is written, the lease released and the actor stops.
    Release {
        /// Hand over even with a stream attached (a drain).
        force: bool,
        /// Answered once handed over, or why not.
        reply: oneshot::Sender<Result<(), SessionError>>,
    },
    /// The ingest socket of `stream` closed.
    Detach(u64),
    /// Read a monitor's thresholds.
    GetThreshold(String, oneshot::Sender<Result<ThresholdView, SessionError>>),
    /// Change a monitor's threshold and/or policy; answered once the change is stored,
    /// with the view before and after it.
    SetThreshold(
        String,
        ThresholdUpdate,
        oneshot::Sender<Result<(ThresholdView, ThresholdView), SessionError>>,
    ),
    /// Store the session's spec as it is now (a new session).
    Persist(oneshot::Sender<Result<(), SessionError>>),
    /// Delete the session's stored spec and stop; answered once the row is gone.
    Delete(oneshot::Sender<Result<(), SessionError>>),
    /// Current statistics.
    Stats(oneshot::Sender<SessionStats>),
    /// The statistics history at or after an epoch time.
    History(
        Option<f64>,
        oneshot::Sender<navguard_core::session::history::HistoryView>,
    ),
    /// Stop the actor.
    Shutdown,
}

/// State shared between the actor and the handles.
#[derive(Debug)]
pub struct SessionShared {
    /// The session's spec with its current thresholds and policies.
    pub stored: Mutex<StoredSession>,
    /// Subscribers to `alarm` and `state` messages.
    pub subscribers: Mutex<Vec<mpsc::Sender<Arc<str>>>>,
}

/// A cheap-to-clone reference to a running session.
#[derive(Debug, Clone)]
pub struct SessionHandle {
    id: Arc<str>,
    lease_epoch: Option<i64>,
    frames: mpsc::Sender<FrameCommand>,
    control: mpsc::Sender<ControlCommand>,
    stats: watch::Receiver<Arc<SessionStats>>,
    shared: Arc<SessionShared>,
}

impl SessionHandle {
    /// Assembles a handle (the actor module creates the channels).
    pub(super) fn new(
        id: Arc<str>,
        lease_epoch: Option<i64>,
        frames: mpsc::Sender<FrameCommand>,
        control: mpsc::Sender<ControlCommand>,
        stats: watch::Receiver<Arc<SessionStats>>,
        shared: Arc<SessionShared>,
    ) -> Self {
        SessionHandle {
            id,
            lease_epoch,
            frames,
            control,
            stats,
            shared,
        }
    }

    /// Session id.
    pub fn id(&self) -> &str {
        &self.id
    }

    /// The lease epoch this actor runs under (cluster nodes), `None` on a single node.
    pub fn lease_epoch(&self) -> Option<i64> {
        self.lease_epoch
    }

    /// True when both handles are of the same actor.
    pub fn same_actor(&self, other: &SessionHandle) -> bool {
        self.control.same_channel(&other.control)
    }

    /// The frame channel (bounded: a full channel slows the sender's socket).
    pub fn frames(&self) -> &mpsc::Sender<FrameCommand> {
        &self.frames
    }

    /// The latest published statistics (decimated by the actor).
    pub fn stats_watch(&self) -> watch::Receiver<Arc<SessionStats>> {
        self.stats.clone()
    }

    /// A copy of the stored spec.
    pub fn stored(&self) -> StoredSession {
        self.shared
            .stored
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// Registers an event subscriber; returns its queue of JSON messages.
    pub fn subscribe(&self) -> mpsc::Receiver<Arc<str>> {
        let (tx, rx) = mpsc::channel(SUBSCRIBER_QUEUE);
        self.shared
            .subscribers
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .push(tx);
        rx
    }

    async fn ask<T>(
        &self,
        make: impl FnOnce(oneshot::Sender<T>) -> ControlCommand,
    ) -> Result<T, SessionError> {
        let (tx, rx) = oneshot::channel();
        let gone = || SessionError::Stopped(self.id.to_string());
        tokio::time::timeout(CONTROL_TIMEOUT, self.control.send(make(tx)))
            .await
            .map_err(|_| SessionError::Busy(self.id.to_string()))?
            .map_err(|_| gone())?;
        tokio::time::timeout(CONTROL_TIMEOUT, rx)
            .await
            .map_err(|_| SessionError::Busy(self.id.to_string()))?
            .map_err(|_| gone())
    }

    /// Attaches an ingest stream (409 if one is already attached); `resume` carries on
    /// from the session's state when it holds one.
    pub async fn attach(&self, resume: bool) -> Result<IngestLink, SessionError> {
        self.ask(|tx| ControlCommand::Attach { resume, reply: tx })
            .await?
    }

    /// Hands the session over (see [`ControlCommand::Release`]); the actor has stopped
    /// when this returns `Ok`.
    pub async fn release(&self, force: bool) -> Result<(), SessionError> {
        self.ask(|tx| ControlCommand::Release { force, reply: tx })
            .await?
    }

    /// Detaches ingest stream `stream` (best effort: the actor may be gone).
    pub async fn detach(&self, stream: u64) {
        let _ = self.control.send(ControlCommand::Detach(stream)).await;
    }

    /// A monitor's thresholds and policy.
    pub async fn threshold(&self, monitor: &str) -> Result<ThresholdView, SessionError> {
        self.ask(|tx| ControlCommand::GetThreshold(monitor.to_owned(), tx))
            .await?
    }

    /// Applies a threshold/policy change; the actor stores it before answering, so
    /// changes are stored in the order they were applied (and acknowledged). Answers the
    /// monitor's view just before the change and after it (for the audit log).
    pub async fn set_threshold(
        &self,
        monitor: &str,
        update: ThresholdUpdate,
    ) -> Result<(ThresholdView, ThresholdView), SessionError> {
        self.ask(|tx| ControlCommand::SetThreshold(monitor.to_owned(), update, tx))
            .await?
    }

    /// Stores the session's spec as it is now (the actor writes it, in its own order).
    pub async fn persist(&self) -> Result<(), SessionError> {
        self.ask(ControlCommand::Persist).await?
    }

    /// Deletes the stored session and stops the actor, after every change queued before.
    pub async fn delete(&self) -> Result<(), SessionError> {
        self.ask(ControlCommand::Delete).await?
    }

    /// Exact current statistics.
    pub async fn stats(&self) -> Result<SessionStats, SessionError> {
        self.ask(ControlCommand::Stats).await
    }

    /// The 1 Hz statistics history from epoch time `since`.
    pub async fn history(
        &self,
        since: Option<f64>,
    ) -> Result<navguard_core::session::history::HistoryView, SessionError> {
        self.ask(|tx| ControlCommand::History(since, tx)).await
    }

    /// Asks the actor to stop.
    pub async fn shutdown(&self) {
        let _ = self.control.send(ControlCommand::Shutdown).await;
    }
}
