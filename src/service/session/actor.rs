//! The session actor: one task per session owning its monitors, counters and
//! statistics. It validates each frame against the session state, steps every
//! monitor, commits alarms to the store before announcing them, and answers
//! control commands (attach, thresholds, stats) ahead of pending frames.

mod checkpoint;

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use axum::extract::ws::Utf8Bytes;
use bytes::BytesMut;
use tokio::sync::{mpsc, watch};

use super::SessionError;
use super::handle::{
    ControlCommand, FrameCommand, IngestLink, Resumed, SessionHandle, SessionShared,
};
use super::history::History;
use super::spec::{NamedMonitors, build_monitors};
use super::stats::{IntegrityStats, MonitorStats, Position, SessionStats, TestStats, Track};
use crate::detect::{Health, ThresholdSpec};
use crate::epoch::Epoch;
use crate::monitor::{
    Availability, Integrity, Monitor, MonitorReport, Outputs, StepError, TestOutcome,
};
use crate::service::cluster::{Cluster, bus};
use crate::service::compute::{ComputeError, ComputePool, SLICE_BUDGET};
use crate::service::metrics::Metrics;
use crate::service::now_ms;
use crate::service::store::{
    AlarmKey, Checkpoint, Fence, RecordedFrame, Store, StoreError, StoredSession,
};
use crate::service::train::Models;
use crate::service::wire::{
    self, AlarmLevel, AlarmRecord, AvailabilityChange, ErrorEvent, FrameError, FrameErrorCode,
    Severity, StateChange, TestThreshold, ThresholdUpdate, ThresholdView,
};

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

/// What the actor keeps beside each monitor (in [`Actor::engines`], same order): its
/// name, alarm level and last availability. Committing an epoch needs only these, so a
/// frame's last epochs can be committed while the monitors step the next frame on the
/// compute pool ([`Actor::frame`]).
struct NamedMonitor {
    name: String,
    /// Which state change of its tests is an alarm.
    alarm_level: AlarmLevel,
    /// Availability at the last epoch that reported one; `None` for a monitor without
    /// a protection level and before its first such epoch (a stream starts converging).
    availability: Option<Availability>,
}

struct Actor {
    id: Arc<str>,
    echo: bool,
    monitors: Vec<NamedMonitor>,
    /// The monitors themselves, in the order of [`Actor::monitors`]. Empty while a step
    /// job has them on the compute pool.
    engines: Vec<Box<dyn Monitor>>,
    stats: SessionStats,
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
    last_t: Option<f64>,
    rate_window: (Instant, u64),
    /// Record every accepted frame (docs/architecture.md §A12).
    record: bool,
    /// Epochs committed on the current stream (the recording's epoch index).
    stream_epochs: u64,
    /// The current stream's id in the recording: its attach time, Unix ms (made
    /// increasing), so streams stay apart across server restarts, whose attach
    /// generations start again at 1.
    recording_stream: u64,
    /// The messages the frame being processed caused, each with its epoch index, for
    /// the recording.
    frame_events: Vec<String>,
    history: History,
    /// Cluster ownership: the lease this actor writes under, its checkpoints and events.
    owned: Option<Owned>,
    /// The session holds a stream's state that a resuming stream may carry on from.
    resumable: bool,
    /// Compute time per epoch of the last slice stepped (all monitors), `None` before
    /// the first: decides whether a frame is stepped on the actor's task or on the
    /// compute pool (see [`INLINE_BUDGET`]).
    epoch_cost: Option<Duration>,
}

/// A frame whose epochs are expected to take at most this much compute (from the
/// session's last measured cost per epoch) is stepped on the actor's own task instead of
/// the compute pool. The hop to the pool and back (a queue, a thread wake-up, a task
/// wake-up) costs more than a 10 Hz single-epoch federated step, and at 1,000 sessions it
/// is 10,000 hops a second competing for the same cores; a runtime worker held for at
/// most this long delays no other task noticeably. Anything heavier (large models, long
/// batches, a session's first frame) still goes to the pool, so a heavy session cannot
/// hold a runtime worker (docs/architecture.md §A2).
const INLINE_BUDGET: Duration = Duration::from_micros(100);

/// What an actor that owns its session through a lease keeps (docs/deployment.md).
struct Owned {
    cluster: Arc<Cluster>,
    fence: Fence,
    /// Sequence number of the last event published to NATS (per lease epoch).
    event_seq: u64,
    /// Version of the last checkpoint taken.
    version: i64,
    /// When the next checkpoint is due; `None` while nothing changed since the last.
    due: Option<Instant>,
    /// When the last checkpoint was taken.
    last: Instant,
    /// When statistics were last published to NATS.
    last_stats: Instant,
    /// A write was fenced: another node owns the session now; the actor stops.
    fenced: bool,
    /// A background checkpoint is still being written: the next one waits for it, so a
    /// session never has more than one queued (the memory stays bounded when the store
    /// falls behind).
    in_flight: Arc<std::sync::atomic::AtomicBool>,
}

/// The built monitors of `stored`, each with its alarm level (its own, else the
/// session's, else the default) and no availability seen yet, and the monitors
/// themselves in the same order.
fn with_alarm_levels(
    monitors: NamedMonitors,
    stored: &StoredSession,
) -> (Vec<NamedMonitor>, Vec<Box<dyn Monitor>>) {
    monitors
        .into_iter()
        .zip(&stored.monitors)
        .map(|((name, monitor), wire)| {
            let named = NamedMonitor {
                name,
                alarm_level: wire.alarm_level.or(stored.alarm_level).unwrap_or_default(),
                availability: None,
            };
            (named, monitor)
        })
        .unzip()
}

/// Builds the monitors of `stored` and starts its actor.
pub fn spawn(stored: StoredSession, deps: ActorDeps) -> Result<SessionHandle, SessionError> {
    spawn_inner(stored, deps, None, None)
}

/// Starts the actor of a session this node holds the lease of (cluster), its state
/// restored from `checkpoint` when there is one (docs/deployment.md, Failover). A
/// checkpoint that cannot be restored (written by another version, another spec) is
/// logged and the session starts afresh.
pub fn spawn_owned(
    stored: StoredSession,
    deps: ActorDeps,
    fence: Fence,
    checkpoint: Option<Checkpoint>,
) -> Result<SessionHandle, SessionError> {
    spawn_inner(stored, deps, Some(fence), checkpoint)
}

fn spawn_inner(
    stored: StoredSession,
    deps: ActorDeps,
    fence: Option<Fence>,
    checkpoint: Option<Checkpoint>,
) -> Result<SessionHandle, SessionError> {
    let monitors = build_monitors(&stored, &*deps.models)?;
    let id: Arc<str> = Arc::from(stored.id.as_str());
    let stats = initial_stats(&id, &monitors);
    let history = History::new(deps.history_samples, &stats);
    let deps_record_default = deps.record_default;
    let lease_epoch = fence.as_ref().map(|f| f.epoch);
    let owned = match (&deps.cluster, fence) {
        (Some(cluster), Some(fence)) => {
            let now = Instant::now();
            Some(Owned {
                cluster: cluster.clone(),
                fence,
                event_seq: 0,
                version: 0,
                due: None,
                last: now,
                last_stats: now,
                in_flight: Arc::default(),
                fenced: false,
            })
        }
        _ => None,
    };
    let (stats_tx, stats_rx) = watch::channel(Arc::new(stats.clone()));
    let (frames_tx, frames_rx) = mpsc::channel(FRAME_QUEUE);
    let (control_tx, control_rx) = mpsc::channel(CONTROL_QUEUE);
    let shared = Arc::new(SessionShared {
        stored: std::sync::Mutex::new(stored.clone()),
        subscribers: Default::default(),
    });
    let (monitors, engines) = with_alarm_levels(monitors, &stored);
    let mut actor = Actor {
        id: id.clone(),
        echo: stored.echo,
        monitors,
        engines,
        stats,
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
        last_t: None,
        rate_window: (Instant::now(), 0),
        epoch_cost: None,
        record: stored.record.unwrap_or(deps_record_default),
        stream_epochs: 0,
        recording_stream: 0,
        frame_events: Vec::new(),
        history,
        owned,
        resumable: false,
    };
    if let Some(checkpoint) = checkpoint {
        match checkpoint::restore(&mut actor, &checkpoint) {
            Ok(()) => {
                // A session that never streamed (a handover right after its creation)
                // has no stream to resume: its first stream starts afresh.
                actor.resumable = actor.recording_stream > 0;
                actor.stats_tx.send_replace(Arc::new(actor.stats.clone()));
                tracing::info!(session = %actor.id, epochs = checkpoint.epochs, t = ?checkpoint.t, "session restored from its checkpoint");
            }
            Err(e) => {
                tracing::warn!(session = %actor.id, error = %e, "checkpoint not restored; the session starts afresh");
            }
        }
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

fn initial_stats(id: &str, monitors: &NamedMonitors) -> SessionStats {
    SessionStats {
        session: id.to_owned(),
        connected: false,
        frames: 0,
        epochs: 0,
        frame_errors: 0,
        last_t: None,
        last_frame_at_ms: None,
        published_at_ms: now_ms(),
        epochs_per_s: 0.0,
        monitors: monitors
            .iter()
            .map(|(name, m)| {
                let tests = m
                    .tests()
                    .slots()
                    .iter()
                    .map(|s| (s.name.clone(), TestStats::new(s.dof, s.threshold)))
                    .collect();
                (
                    name.clone(),
                    MonitorStats {
                        kind: m.kind(),
                        epochs: 0,
                        worst_test_ratio: None,
                        tests,
                        track: None,
                        integrity: None,
                    },
                )
            })
            .collect(),
    }
}

/// Whether the actor goes on after a command or frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Flow {
    Continue,
    Stop,
}

/// One slice of a frame stepped on the compute pool: the monitors and epochs (moved in
/// and handed back), each stepped epoch's reports (`None` for a monitor that failed on
/// it) and the first failure (epoch index, monitor index, error).
struct Slice {
    engines: Vec<Box<dyn Monitor>>,
    epochs: Vec<Epoch>,
    stepped: Vec<Vec<Option<MonitorReport>>>,
    failure: Option<(usize, usize, StepError)>,
    /// Compute time the slice took.
    elapsed: Duration,
}

/// A frame the actor handles next (see [`Actor::frame`]).
enum Next {
    /// Not stepped yet: handled as a frame from the queue.
    Queued(FrameCommand),
    /// Checked, and its first slice stepped while the previous frame's last epochs were
    /// committed; `frame.epochs` went with the step and come back in `slice`.
    Stepped {
        frame: FrameCommand,
        total: usize,
        slice: Result<Slice, ComputeError>,
    },
}

/// What [`Actor::prefetch`] found in the queue.
enum Prefetch {
    /// Nothing, or a control command waits.
    None,
    /// A frame to handle after this one, as if it had stayed in the queue.
    Queued(FrameCommand),
    /// A frame to step now.
    Step(FrameCommand),
}

/// Steps every monitor through the epochs from `from`, until the frame ends, a monitor
/// fails (that epoch is the last, stepped by the others) or the slice has used
/// [`SLICE_BUDGET`] of compute.
fn step_slice(mut engines: Vec<Box<dyn Monitor>>, epochs: Vec<Epoch>, from: usize) -> Slice {
    let start = Instant::now();
    let mut stepped = Vec::new();
    let mut failure = None;
    for (i, epoch) in epochs.iter().enumerate().skip(from) {
        let mut reports = Vec::with_capacity(engines.len());
        for (k, engine) in engines.iter_mut().enumerate() {
            match engine.step(epoch) {
                Ok(report) => reports.push(Some(report)),
                Err(e) => {
                    reports.push(None);
                    failure.get_or_insert((i, k, e));
                }
            }
        }
        stepped.push(reports);
        if failure.is_some() || start.elapsed() >= SLICE_BUDGET {
            break;
        }
    }
    Slice {
        engines,
        epochs,
        stepped,
        failure,
        elapsed: start.elapsed(),
    }
}

/// Moves a kept timer to `at`, touching the runtime's timer wheel only when it changes.
fn rearm(timer: std::pin::Pin<&mut tokio::time::Sleep>, at: Instant) {
    let at = tokio::time::Instant::from_std(at);
    if timer.deadline() != at {
        timer.reset(at);
    }
}

/// The 422 reason for a test name the monitor does not have.
fn unknown_test(test: &str, bank: &crate::monitor::TestBank) -> String {
    let names: Vec<&str> = bank.slots().iter().map(|s| &*s.name).collect();
    format!(
        "no test '{test}' in this monitor; its tests are {}",
        names.join(", ")
    )
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
            if self.owned.as_ref().is_some_and(|o| o.fenced) {
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

    /// Handles `frame` and any frame taken from the queue with it (see
    /// [`Actor::frame`]). A frame taken early but not stepped waits behind the control
    /// commands that came meanwhile, as it would have in the queue; one already stepped
    /// is committed first.
    async fn frames(
        &mut self,
        frame: FrameCommand,
        frames: &mut mpsc::Receiver<FrameCommand>,
        control: &mut mpsc::Receiver<ControlCommand>,
    ) -> Flow {
        let mut next = Some(Next::Queued(frame));
        while let Some(frame) = next.take() {
            if self.owned.as_ref().is_some_and(|o| o.fenced) {
                break; // the run loop stops
            }
            if matches!(frame, Next::Queued(_)) {
                while let Ok(command) = control.try_recv() {
                    if self.command(command).await == Flow::Stop {
                        return Flow::Stop;
                    }
                }
            }
            // Boxed, allocated per frame: a frame's future is large (its commits' store
            // and send futures, the step overlapping a commit), and held inline it would
            // be part of every session's task, idle or not (about 1.5 kB).
            let (flow, carry) = Box::pin(self.frame(frame, frames, control)).await;
            if flow == Flow::Stop {
                return Flow::Stop;
            }
            next = carry;
        }
        Flow::Continue
    }

    /// Serves one control command; `Stop` when the actor must end (shutdown, or the
    /// session deleted).
    async fn command(&mut self, command: ControlCommand) -> Flow {
        match command {
            ControlCommand::Shutdown => Flow::Stop,
            ControlCommand::Delete(reply) => {
                // docs/architecture.md §A4: the row goes in the session's own order, after
                // every change acknowledged before; then the actor stops, so nothing can
                // write the session back.
                let fence = self.fence();
                match self
                    .deps
                    .store
                    .delete_session_fenced(&self.id, fence.as_ref())
                    .await
                {
                    Ok(_) => {
                        if let Some(o) = &self.owned {
                            // Observers on other nodes hear of it as local ones do
                            // (their queue closes): the events socket ends.
                            o.cluster.publish(bus::end(&self.id));
                        }
                        let _ = reply.send(Ok(()));
                        Flow::Stop
                    }
                    Err(e) => {
                        let _ = reply.send(Err(self.store_error(e)));
                        Flow::Continue
                    }
                }
            }
            ControlCommand::Release(force, reply) => {
                let answer = self.release(force).await;
                let stop = answer.is_ok();
                let _ = reply.send(answer);
                if stop { Flow::Stop } else { Flow::Continue }
            }
            command => {
                self.control(command).await;
                Flow::Continue
            }
        }
    }

    async fn control(&mut self, command: ControlCommand) {
        match command {
            ControlCommand::Attach(resume, reply) => {
                let attached = self.attach(resume).await;
                let _ = reply.send(attached);
            }
            ControlCommand::Detach(stream) => {
                if stream == self.stream {
                    self.ingest = None;
                    self.stats.connected = false;
                    self.stats.epochs_per_s = 0.0;
                    self.rate_window = (Instant::now(), 0);
                    self.publish(true);
                }
            }
            ControlCommand::GetThreshold(name, reply) => {
                let _ = reply.send(self.find(&name).map(|i| self.threshold_view(i)));
            }
            ControlCommand::SetThreshold(name, update, reply) => {
                let answer = self.set_threshold_stored(&name, update).await;
                let _ = reply.send(answer);
            }
            ControlCommand::Persist(reply) => {
                let stored = self.stored();
                let fence = self.fence();
                let answer = self
                    .deps
                    .store
                    .put_session_fenced(&stored, fence.as_ref())
                    .await
                    .map_err(|e| self.store_error(e));
                let _ = reply.send(answer);
            }
            ControlCommand::History(since, reply) => {
                let _ = reply.send(self.history.view(since));
            }
            ControlCommand::Stats(reply) => {
                self.refresh_consistency();
                self.stats.published_at_ms = now_ms();
                let _ = reply.send(self.stats.clone());
            }
            // Served by `command`, which stops the actor.
            ControlCommand::Shutdown | ControlCommand::Delete(_) | ControlCommand::Release(..) => {}
        }
    }

    /// A copy of the session's spec as in force.
    fn stored(&self) -> StoredSession {
        self.shared
            .stored
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// Applies a threshold change and stores the spec before answering (docs/architecture.md
    /// §A4: stored in the order applied). If the store refuses, the change is undone, so
    /// the state in force always equals the state stored.
    async fn set_threshold_stored(
        &mut self,
        name: &str,
        update: ThresholdUpdate,
    ) -> Result<ThresholdView, SessionError> {
        let index = self.find(name)?;
        let before = (
            self.engines[index].tests().clone(),
            self.monitors[index].alarm_level,
            self.stored(),
        );
        let (view, stored) = self.set_threshold(name, update)?;
        let fence = self.fence();
        if let Err(e) = self
            .deps
            .store
            .put_session_fenced(&stored, fence.as_ref())
            .await
        {
            let (bank, level, spec) = before;
            *self.engines[index].tests_mut() = bank;
            self.monitors[index].alarm_level = level;
            *self.shared.stored.lock().unwrap_or_else(|p| p.into_inner()) = spec;
            return Err(self.store_error(e));
        }
        self.changed();
        Ok(view)
    }

    async fn attach(&mut self, resume: bool) -> Result<IngestLink, SessionError> {
        if self.ingest.as_ref().is_some_and(|tx| !tx.is_closed()) {
            return Err(SessionError::AlreadyAttached(self.id.to_string()));
        }
        if resume && self.resumable {
            return Ok(self.attach_resumed());
        }
        self.resumable = true;
        // docs/architecture.md §A3: filter state starts afresh when a session's stream
        // reconnects. Tests left suspect or isolated by the previous stream
        // return to healthy: say so, and clear their open alarms.
        let mut returned = Vec::new();
        for (m, engine) in self.monitors.iter_mut().zip(&mut self.engines) {
            for slot in engine.tests().slots() {
                if slot.policy.health() != Health::Healthy {
                    returned.push((m.name.clone(), slot.name.clone(), slot.policy.health()));
                }
            }
            engine.reset();
            m.availability = None;
        }
        let t = self.last_t;
        let fence = self.fence();
        for (monitor, test, from) in returned {
            if let Err(e) = self
                .deps
                .store
                .clear_alarms_fenced(&self.id, &monitor, &test, t, fence.as_ref())
                .await
            {
                tracing::error!(session = %self.id, error = %e, "could not mark alarms cleared");
            }
            let change = StateChange {
                session: self.id.to_string(),
                monitor,
                test: test.to_string(),
                t: t.unwrap_or(0.0),
                from,
                to: Health::Healthy,
                severity: None,
                log_id: None,
            };
            self.broadcast(&Arc::from(wire::tagged("state", &change)));
        }
        // Alarms left open by a stream that ended before a restart are closed too.
        if let Err(e) = self
            .deps
            .store
            .clear_session_alarms_fenced(&self.id, fence.as_ref())
            .await
        {
            tracing::error!(session = %self.id, error = %e, "could not mark alarms cleared");
        }
        self.last_t = None;
        self.stream += 1;
        self.stream_epochs = 0;
        self.recording_stream = (now_ms().max(0) as u64).max(self.recording_stream + 1);
        self.history.clear();
        let (tx, rx) = mpsc::channel(INGEST_QUEUE);
        self.ingest = Some(tx);
        self.stats.connected = true;
        // Stats are keyed by name (sorted), monitors and slots are in session
        // order: match them by name, never by position.
        for (m, engine) in self.monitors.iter().zip(&self.engines) {
            let Some(monitor_stats) = self.stats.monitors.get_mut(&m.name) else {
                continue;
            };
            for slot in engine.tests().slots() {
                if let Some(test) = monitor_stats.tests.get_mut(&slot.name) {
                    test.state = slot.policy.health();
                    test.consistency = None;
                }
            }
            monitor_stats.integrity = None;
        }
        self.publish(true);
        // A cluster owner stores the new stream at once: a failover from here on resumes
        // this stream (its id keys its alarms), never an older one.
        if self.owned.is_some() {
            self.checkpoint(false).await;
        }
        Ok(IngestLink {
            resumed: None,
            stream: self.stream,
            record: self.record,
            outgoing: rx,
        })
    }

    /// A stream that carries on from the session's state: nothing is reset, the
    /// recording stream and epoch count go on, and the client is told where.
    fn attach_resumed(&mut self) -> IngestLink {
        self.stream += 1;
        let (tx, rx) = mpsc::channel(INGEST_QUEUE);
        self.ingest = Some(tx);
        self.stats.connected = true;
        self.publish(true);
        IngestLink {
            resumed: Some(Resumed {
                t: self.last_t,
                epochs: self.stream_epochs,
            }),
            stream: self.stream,
            record: self.record,
            outgoing: rx,
        }
    }

    /// The fence of this actor's writes (cluster), cloned for a store call.
    fn fence(&self) -> Option<Fence> {
        self.owned.as_ref().map(|o| o.fence.clone())
    }

    /// A store failure as a session error; a fenced write also stops the actor.
    fn store_error(&mut self, e: StoreError) -> SessionError {
        if matches!(e, StoreError::Fenced(_)) {
            if let Some(o) = &mut self.owned {
                o.fenced = true;
            }
            return SessionError::Moved(self.id.to_string());
        }
        SessionError::Store(e.to_string())
    }

    /// Notes that the state changed: a checkpoint is due within the interval.
    fn changed(&mut self) {
        if let Some(o) = &mut self.owned
            && o.due.is_none()
        {
            let interval = o.cluster.config.checkpoint_interval;
            o.due = Some((o.last + interval).max(Instant::now()));
        }
    }

    /// Takes a checkpoint and stores it: in the background (`wait` false; a later one
    /// never loses to an earlier one, they are versioned) or before returning.
    async fn checkpoint(&mut self, wait: bool) -> bool {
        if let Some(o) = &mut self.owned
            && !wait
            && o.in_flight.load(Ordering::Acquire)
        {
            o.due = Some(Instant::now() + o.cluster.config.checkpoint_interval / 4);
            return false;
        }
        let bytes = match checkpoint::encode(self) {
            Ok(b) => b,
            Err(e) => {
                tracing::error!(session = %self.id, error = %e, "checkpoint not taken");
                return false;
            }
        };
        let (t, epochs) = (self.last_t, self.stream_epochs as i64);
        let Some(o) = &mut self.owned else {
            return false;
        };
        o.version += 1;
        o.due = None;
        o.last = Instant::now();
        let checkpoint = Checkpoint {
            session: self.id.to_string(),
            lease_epoch: o.fence.epoch,
            version: o.version,
            epochs,
            t,
            taken_at_ms: now_ms(),
            state: bytes,
        };
        let (store, fence, cluster) = (self.deps.store.clone(), o.fence.clone(), o.cluster.clone());
        let in_flight = o.in_flight.clone();
        if !wait {
            in_flight.store(true, Ordering::Release);
        }
        let write = async move {
            let written = store.put_checkpoint(&fence, &checkpoint).await;
            if !wait {
                in_flight.store(false, Ordering::Release);
            }
            let counters = &cluster.counters;
            match &written {
                Ok(()) => counters.checkpoints.fetch_add(1, Ordering::Relaxed),
                Err(e) => {
                    tracing::warn!(session = %fence.session, error = %e, "checkpoint not stored");
                    counters.checkpoint_failures.fetch_add(1, Ordering::Relaxed)
                }
            };
            written
        };
        if wait {
            match write.await {
                Ok(()) => true,
                Err(e) => {
                    let _ = self.store_error(e);
                    false
                }
            }
        } else {
            tokio::spawn(write);
            true
        }
    }

    /// Hands the session over: see [`ControlCommand::Release`].
    async fn release(&mut self, force: bool) -> Result<(), SessionError> {
        let attached = self.ingest.as_ref().is_some_and(|tx| !tx.is_closed());
        if attached && !force {
            return Err(SessionError::AlreadyAttached(self.id.to_string()));
        }
        if self.owned.is_none() {
            return Ok(());
        }
        if !self.checkpoint(true).await {
            return Err(SessionError::Moved(self.id.to_string()));
        }
        if attached {
            let moved = serde_json::json!({
                "type": "moved",
                "session": &*self.id,
                "resume": {"t": self.last_t, "epochs": self.stream_epochs},
                "message": "this node hands the session over: reconnect with resume=true and resend the epochs after t",
            })
            .to_string();
            self.send_ingest(moved).await;
            self.ingest = None;
        }
        let Some(o) = &self.owned else {
            return Ok(());
        };
        match self.deps.store.release_lease(&o.fence).await {
            Ok(_) => {
                o.cluster
                    .counters
                    .leases_released
                    .fetch_add(1, Ordering::Relaxed);
                tracing::info!(session = %self.id, "session handed over");
                Ok(())
            }
            Err(e) => Err(self.store_error(e)),
        }
    }

    fn find(&self, name: &str) -> Result<usize, SessionError> {
        self.monitors
            .iter()
            .position(|m| m.name == name)
            .ok_or_else(|| SessionError::NoMonitor {
                session: self.id.to_string(),
                monitor: name.to_owned(),
            })
    }

    fn threshold_view(&self, index: usize) -> ThresholdView {
        let m = &self.monitors[index];
        let bank = self.engines[index].tests();
        let spec = bank.spec();
        ThresholdView {
            monitor: m.name.clone(),
            p_fa: spec.p_fa_part(),
            threshold: spec.threshold_part(),
            policy: bank.policy(),
            alarm_level: m.alarm_level,
            tests: bank
                .slots()
                .iter()
                .map(|s| {
                    let own = s.own_spec.unwrap_or(spec);
                    let p_fa = own.p_fa(s.dof).unwrap_or(f64::NAN);
                    (
                        s.name.to_string(),
                        TestThreshold {
                            dof: s.dof,
                            threshold: s.threshold,
                            p_fa,
                            own: s.own_spec.is_some(),
                        },
                    )
                })
                .collect(),
        }
    }

    fn set_threshold(
        &mut self,
        name: &str,
        update: ThresholdUpdate,
    ) -> Result<(ThresholdView, StoredSession), SessionError> {
        let index = self.find(name)?;
        if update.p_fa.is_none()
            && update.threshold.is_none()
            && update.policy.is_none()
            && update.alarm_level.is_none()
            && update.tests.is_none()
        {
            return Err(SessionError::Invalid {
                field: None,
                reason: "give `p_fa` or `threshold`, `policy`, `alarm_level` and/or `tests`".into(),
            });
        }
        // Everything is applied to a copy of the bank first, so a refused part changes
        // nothing.
        let mut bank = self.engines[index].tests().clone();
        if update.p_fa.is_some() || update.threshold.is_some() {
            let spec = ThresholdSpec::from_parts(update.p_fa, update.threshold)
                .map_err(|e| SessionError::invalid("p_fa", e.to_string()))?;
            bank.set_spec(spec)
                .map_err(|e| SessionError::invalid("p_fa", e.to_string()))?;
        }
        if let Some(policy) = update.policy {
            policy
                .check()
                .map_err(|e| SessionError::invalid("policy", e.to_string()))?;
            bank.set_policy(policy);
        }
        for (test, spec) in update.tests.iter().flatten() {
            let field = format!("tests.{test}");
            let Some(i) = bank.index_of(test) else {
                return Err(SessionError::invalid(field, unknown_test(test, &bank)));
            };
            let own = spec
                .map(|s| super::spec::test_spec(&s))
                .transpose()
                .map_err(|e| SessionError::invalid(field.clone(), e))?;
            bank.set_test_spec(i, own)
                .map_err(|e| SessionError::invalid(field, e.to_string()))?;
        }
        *self.engines[index].tests_mut() = bank;
        if let Some(level) = update.alarm_level {
            self.monitors[index].alarm_level = level;
        }
        let bank = self.engines[index].tests();
        let (spec, policy) = (bank.spec(), bank.policy());
        if let Some(stats) = self.stats.monitors.get_mut(name) {
            for slot in bank.slots() {
                if let Some(t) = stats.tests.get_mut(&slot.name) {
                    t.threshold = slot.threshold;
                }
            }
        }
        let stored = {
            let mut stored = self.shared.stored.lock().unwrap_or_else(|p| p.into_inner());
            let wire = &mut stored.monitors[index];
            wire.p_fa = spec.p_fa_part();
            wire.threshold = spec.threshold_part();
            wire.policy = policy;
            if let Some(level) = update.alarm_level {
                wire.alarm_level = Some(level);
            }
            for (test, own) in update.tests.iter().flatten() {
                match own {
                    Some(own) => {
                        wire.tests.insert(test.clone(), *own);
                    }
                    None => {
                        wire.tests.remove(test);
                    }
                }
            }
            stored.clone()
        };
        self.publish(true);
        Ok((self.threshold_view(index), stored))
    }

    /// Checks a whole frame against the session before anything changes, `last_t` being
    /// the time of the last epoch before it.
    fn validate(&self, epochs: &[Epoch], last_t: Option<f64>) -> Result<(), FrameError> {
        if let (Some(last), Some(first)) = (last_t, epochs.first())
            && first.t < last
        {
            return Err(FrameError::new(
                FrameErrorCode::TimeBackwards,
                format!("t = {} goes back from {last}", first.t),
            )
            .at(0));
        }
        for (i, epoch) in epochs.iter().enumerate() {
            for (m, engine) in self.monitors.iter().zip(&self.engines) {
                engine.check_epoch(&m.name, epoch).map_err(|e| {
                    let code = match e {
                        crate::monitor::EpochError::WrongLength { .. } => {
                            FrameErrorCode::WrongLength
                        }
                        crate::monitor::EpochError::UnknownInput(_) => FrameErrorCode::UnknownInput,
                    };
                    FrameError::new(code, e.to_string()).at(i)
                })?;
            }
        }
        Ok(())
    }

    async fn send_ingest(&mut self, text: impl Into<Utf8Bytes>) {
        if let Some(tx) = &self.ingest
            && tx.send(text.into()).await.is_err()
        {
            self.ingest = None;
        }
    }

    /// Sends to every event subscriber; one whose queue is full is dropped
    /// (its socket closes) rather than silently missing an alarm.
    fn broadcast(&mut self, text: &Arc<str>) {
        {
            let mut subscribers = self
                .shared
                .subscribers
                .lock()
                .unwrap_or_else(|p| p.into_inner());
            subscribers.retain(|tx| tx.try_send(text.clone()).is_ok());
        }
        if let Some(o) = &mut self.owned {
            o.event_seq += 1;
            o.cluster
                .publish(bus::event(&self.id, o.fence.epoch, o.event_seq, text));
        }
    }

    async fn reject(&mut self, error: FrameError) {
        self.stats.frame_errors += 1;
        self.deps
            .metrics
            .frame_errors
            .fetch_add(1, Ordering::Relaxed);
        let text = serde_json::to_string(&ErrorEvent::from(&error)).unwrap_or_default();
        self.send_ingest(text).await;
    }

    /// One frame: validated as a whole, then stepped on the compute pool a slice at a
    /// time, each slice's epochs committed in order (docs/architecture.md §A2 step 3).
    /// An epoch on which a monitor fails numerically is still committed for the
    /// monitors that stepped it (their results, state changes and alarms are stored and
    /// announced; the failing monitor's state is unchanged), then refused as `numerical`,
    /// and the rest of the frame is not used.
    ///
    /// When the frame's last slice has stepped and the next frame is already queued, the
    /// next frame's first slice is stepped on the pool while this frame's last epochs are
    /// committed ([`Actor::prefetch`]); that frame comes back with the answer and must be
    /// handled next, before anything else.
    async fn frame(
        &mut self,
        next: Next,
        frames: &mut mpsc::Receiver<FrameCommand>,
        control: &mut mpsc::Receiver<ControlCommand>,
    ) -> (Flow, Option<Next>) {
        let (frame, total, mut stepped_first) = match next {
            Next::Queued(frame) => {
                if frame.stream != self.stream {
                    // from a stream that has since been replaced
                    return (Flow::Continue, None);
                }
                if let Err(error) = self.validate(&frame.epochs, self.last_t) {
                    self.reject(error).await;
                    return (Flow::Continue, None);
                }
                let total = frame.epochs.len();
                (frame, total, None)
            }
            Next::Stepped {
                frame,
                total,
                slice,
            } => {
                self.note_cost(&slice);
                (frame, total, Some(slice))
            }
        };
        self.stats.frames += 1;
        self.stats.last_frame_at_ms = Some(now_ms());
        self.deps.metrics.frames.fetch_add(1, Ordering::Relaxed);
        let FrameCommand {
            epochs,
            received,
            stream: frame_stream,
            text,
        } = frame;
        if self.echo {
            // One buffer for the frame's results, with some room for longer ones.
            self.results
                .reserve(total * (self.result_len + self.result_len / 8));
        }
        let first_epoch = self.stream_epochs;
        let recording_stream = self.recording_stream;
        self.frame_events.clear();
        let mut epochs = epochs;
        let mut from = 0;
        let mut changed = false;
        let mut carry = None;
        while from < total {
            let slice = match stepped_first.take() {
                Some(slice) => slice,
                None => self.step(epochs, from).await,
            };
            let Slice {
                engines,
                epochs: returned,
                stepped,
                failure,
                elapsed: _,
            } = match slice {
                Ok(slice) => slice,
                Err(e) => {
                    // The monitors went with the job: start them afresh from the spec.
                    tracing::error!(session = %self.id, error = %e, "stepping failed; monitors rebuilt");
                    self.rebuild_monitors();
                    let error = FrameError::new(
                        FrameErrorCode::Internal,
                        "the session's monitors could not process this frame; they were restarted from their configuration",
                    );
                    self.reject(error.at(from)).await;
                    break;
                }
            };
            self.engines = engines;
            epochs = returned;
            let end = from + stepped.len();
            let committing = &epochs[from..end];
            let prefetch = match (end == total, &failure, committing.last()) {
                (true, None, Some(last)) => self.prefetch(frames, control, last.t, &stepped),
                _ => Prefetch::None,
            };
            changed |= match prefetch {
                Prefetch::Step(mut next) => {
                    self.deps
                        .metrics
                        .frames_prestepped
                        .fetch_add(1, Ordering::Relaxed);
                    // The statistics published when this frame ends must not see the
                    // next frame's epochs: what they read of the monitors is read now.
                    self.refresh_consistency();
                    let total = next.epochs.len();
                    let engines = std::mem::take(&mut self.engines);
                    let next_epochs = std::mem::take(&mut next.epochs);
                    let compute = self.deps.compute.clone();
                    let job = async move {
                        compute
                            .run(move || step_slice(engines, next_epochs, 0))
                            .await
                    };
                    let (slice, changed) =
                        tokio::join!(job, self.commit_slice(committing, &stepped));
                    carry = Some(Next::Stepped {
                        frame: next,
                        total,
                        slice,
                    });
                    changed
                }
                Prefetch::Queued(next) => {
                    carry = Some(Next::Queued(next));
                    self.commit_slice(committing, &stepped).await
                }
                Prefetch::None => self.commit_slice(committing, &stepped).await,
            };
            from = end;
            if failure.is_none() && from < total {
                // Between slices: observers see progress, and control commands are served
                // (a threshold change applies from the next epoch). A new stream or a
                // delete ends this frame: its later epochs belong to the old stream.
                self.publish(false);
                while let Ok(command) = control.try_recv() {
                    let new_stream = matches!(command, ControlCommand::Attach(..));
                    if self.command(command).await == Flow::Stop {
                        return (Flow::Stop, None);
                    }
                    if new_stream || frame_stream != self.stream {
                        self.record_frame(text, recording_stream, first_epoch, from)
                            .await;
                        self.finish_frame(received, from, changed);
                        return (Flow::Continue, None);
                    }
                }
            }
            if let Some((index, monitor, e)) = failure {
                let t = epochs[index].t;
                let monitor = &self.monitors[monitor].name;
                let error = FrameError::new(
                    FrameErrorCode::Numerical,
                    format!(
                        "monitor '{monitor}' could not process t = {t}: {e}; the other monitors took this epoch, later epochs of the frame were not used"
                    ),
                );
                self.reject(error.at(index)).await;
                break;
            }
        }
        let committed = (self.stream_epochs - first_epoch) as usize;
        self.record_frame(text, recording_stream, first_epoch, committed)
            .await;
        self.finish_frame(received, total, changed);
        (Flow::Continue, carry)
    }

    /// Steps the session's monitors through `epochs[from..]` (one slice): on this task
    /// when the session's measured cost says it fits in [`INLINE_BUDGET`], else on the
    /// compute pool. A panic is caught either way (the monitors are then lost, as on the
    /// pool).
    async fn step(&mut self, epochs: Vec<Epoch>, from: usize) -> Result<Slice, ComputeError> {
        let engines = std::mem::take(&mut self.engines);
        let slice = if self.inline(epochs.len() - from) {
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                step_slice(engines, epochs, from)
            }))
            .map_err(|_| ComputeError::Panicked)
        } else {
            self.deps
                .compute
                .run(move || step_slice(engines, epochs, from))
                .await
        };
        self.note_cost(&slice);
        slice
    }

    /// Whether `epochs` epochs fit in [`INLINE_BUDGET`] at the session's last measured
    /// cost (never before the first measure).
    fn inline(&self, epochs: usize) -> bool {
        let epochs = u32::try_from(epochs).unwrap_or(u32::MAX);
        self.epoch_cost
            .is_some_and(|cost| cost.saturating_mul(epochs) <= INLINE_BUDGET)
    }

    /// Keeps a stepped slice's compute time per epoch (see [`Actor::inline`]).
    fn note_cost(&mut self, slice: &Result<Slice, ComputeError>) {
        if let Ok(slice) = slice
            && let Ok(n) = u32::try_from(slice.stepped.len())
            && n > 0
        {
            self.epoch_cost = Some(slice.elapsed / n);
        }
    }

    /// At the end of a frame whose epochs all stepped (their commit still to come): takes
    /// the next frame from the queue, if there is one, and says whether it may be stepped
    /// now, on the compute pool, while those epochs are committed
    /// ([`Prefetch::Step`], docs/architecture.md §A2). It may not ([`Prefetch::Queued`]:
    /// it is handled after this frame as if it had stayed in the queue) when it would be
    /// stepped on this task anyway, belongs to another stream, would be refused, or when
    /// committing this frame's epochs needs the monitors themselves: a monitor leaving
    /// `converging` raises the alarms its tests stand in (see
    /// [`Actor::announce_availability`]), read from the monitors. Nothing is taken while
    /// a control command waits, so a command waits at most one frame more.
    fn prefetch(
        &self,
        frames: &mut mpsc::Receiver<FrameCommand>,
        control: &mpsc::Receiver<ControlCommand>,
        last_t: f64,
        stepped: &[Vec<Option<MonitorReport>>],
    ) -> Prefetch {
        if !control.is_empty() {
            return Prefetch::None;
        }
        let Ok(frame) = frames.try_recv() else {
            return Prefetch::None;
        };
        // (An empty frame never gets here, the edge refuses it; it is not stepped early
        // either, since no slice of it would bring the monitors back.)
        if frame.stream != self.stream
            || frame.epochs.is_empty()
            || self.inline(frame.epochs.len())
            || self.leaves_converging(stepped)
            || self.validate(&frame.epochs, Some(last_t)).is_err()
        {
            return Prefetch::Queued(frame);
        }
        Prefetch::Step(frame)
    }

    /// Whether committing `stepped` would take a monitor out of `converging` (its first
    /// report of a protection level in another state counts: a stream starts converging,
    /// [`Actor::record`]).
    fn leaves_converging(&self, stepped: &[Vec<Option<MonitorReport>>]) -> bool {
        self.monitors.iter().enumerate().any(|(index, m)| {
            let mut state = self
                .stats
                .monitors
                .get(&m.name)
                .and_then(|s| s.integrity.as_ref())
                .map_or(Availability::Converging, |i| i.state);
            stepped.iter().any(|reports| {
                let Some(Some(report)) = reports.get(index) else {
                    return false;
                };
                let Some(integrity) = &report.integrity else {
                    return false;
                };
                let leaves = state == Availability::Converging && integrity.state != state;
                state = integrity.state;
                leaves
            })
        })
    }

    /// Commits the stepped epochs in order; true if any state changed.
    async fn commit_slice(
        &mut self,
        epochs: &[Epoch],
        stepped: &[Vec<Option<MonitorReport>>],
    ) -> bool {
        let mut changed = false;
        for (epoch, reports) in epochs.iter().zip(stepped) {
            // An epoch no monitor could take changes nothing: it is not committed.
            if reports.iter().any(Option::is_some) {
                changed |= self.commit_epoch(epoch, reports).await;
            }
        }
        changed
    }

    /// Queues the frame for the recording: its text as sent, the epochs that were
    /// committed (a frame refused part-way keeps those before the refusal) and the
    /// messages they caused.
    async fn record_frame(
        &mut self,
        text: Option<Arc<str>>,
        stream: u64,
        first_epoch: u64,
        epochs: usize,
    ) {
        let (true, Some(frame), 1..) = (self.record, text, epochs) else {
            return;
        };
        let events = format!("[{}]", self.frame_events.join(","));
        self.frame_events.clear();
        let fence = self.fence();
        self.deps
            .store
            .record_frame_fenced(
                RecordedFrame {
                    session: self.id.to_string(),
                    stream,
                    first_epoch,
                    epochs: epochs as u64,
                    recorded_at_ms: now_ms(),
                    frame,
                    events,
                },
                fence.as_ref(),
            )
            .await;
    }

    /// Notes a message the current frame caused, for the recording.
    fn note_event(&mut self, text: &str) {
        if self.record {
            let index = self.stream_epochs.saturating_sub(1);
            self.frame_events
                .push(format!(r#"{{"epoch_index":{index},"message":{text}}}"#));
        }
    }

    /// Makes one stepped epoch current: time, counters, the `result` (with the monitors
    /// that stepped it), statistics, state changes and alarms.
    async fn commit_epoch(&mut self, epoch: &Epoch, reports: &[Option<MonitorReport>]) -> bool {
        self.stream_epochs += 1;
        self.last_t = Some(epoch.t);
        self.stats.epochs += 1;
        self.stats.last_t = Some(epoch.t);
        self.deps.metrics.epochs.fetch_add(1, Ordering::Relaxed);
        if self.echo {
            let text = self.result_frame(epoch.t, reports);
            self.send_ingest(text).await;
        }
        let changed = self.record(epoch, reports).await;
        self.history.offer(epoch.t, &self.stats);
        changed
    }

    /// Builds the monitors again from the stored spec (after a compute job lost them),
    /// with their thresholds, policies and alarm levels as stored.
    fn rebuild_monitors(&mut self) {
        let stored = self
            .shared
            .stored
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone();
        match build_monitors(&stored, &*self.deps.models) {
            Ok(monitors) => {
                (self.monitors, self.engines) = with_alarm_levels(monitors, &stored);
            }
            Err(e) => {
                tracing::error!(session = %self.id, error = %e, "could not rebuild the monitors");
            }
        }
    }

    fn finish_frame(&mut self, received: Instant, epochs: usize, changed: bool) {
        // The frame's results are queued; what is left of their buffer goes with it.
        self.results = BytesMut::new();
        self.changed();
        let now = Instant::now();
        self.rate_window.1 += epochs as u64;
        let elapsed = now.duration_since(self.rate_window.0);
        if elapsed >= Duration::from_secs(1) {
            self.stats.epochs_per_s = self.rate_window.1 as f64 / elapsed.as_secs_f64();
            self.rate_window = (now, 0);
        }
        self.deps
            .metrics
            .observe_frame_latency(now.duration_since(received));
        self.publish(changed);
    }

    /// The epoch's `result` frame, written after the frame's earlier ones in
    /// [`Actor::results`] and split off it (no allocation of its own).
    fn result_frame(&mut self, t: f64, reports: &[Option<MonitorReport>]) -> Utf8Bytes {
        let monitors = self.monitors.iter().zip(reports);
        self.scratch.clear();
        wire::write_result_frame(
            &mut self.scratch,
            t,
            monitors.filter_map(|(m, r)| Some((m.name.as_str(), r.as_ref()?))),
        );
        self.results.extend_from_slice(&self.scratch);
        let text = self.results.split().freeze();
        self.result_len = text.len();
        // serde_json writes UTF-8; the check is a formality that cannot fail.
        Utf8Bytes::try_from(text).unwrap_or_default()
    }

    /// Updates statistics; announces state changes, alarms and availability changes.
    /// Returns true if any state changed.
    async fn record(&mut self, epoch: &Epoch, reports: &[Option<MonitorReport>]) -> bool {
        let t = epoch.t;
        let mut transitions: Vec<(usize, TestOutcome, f64)> = Vec::new();
        let mut availability: Vec<(usize, Availability, Integrity)> = Vec::new();
        let mut latest: Vec<(usize, Availability)> = Vec::new();
        for (index, (m, report)) in self.monitors.iter().zip(reports).enumerate() {
            let Some(report) = report else {
                continue; // this monitor failed on the epoch; its state is unchanged
            };
            let Some(monitor_stats) = self.stats.monitors.get_mut(&m.name) else {
                continue;
            };
            monitor_stats.epochs += 1;
            let mut worst: Option<f64> = None;
            for outcome in &report.tests {
                let Some(test) = monitor_stats.tests.get_mut(&outcome.name) else {
                    continue;
                };
                let delay_s = test.record(t, outcome);
                let ratio = outcome.statistic.test_ratio();
                worst = Some(worst.map_or(ratio, |w| w.max(ratio)));
                if outcome.previous != outcome.decision.health {
                    transitions.push((index, outcome.clone(), delay_s));
                }
            }
            if worst.is_some() {
                monitor_stats.worst_test_ratio = worst;
            }
            if let Some(integrity) = &report.integrity {
                let from = match &mut monitor_stats.integrity {
                    Some(stats) => stats.record(t, integrity),
                    None => {
                        monitor_stats.integrity = Some(IntegrityStats::new(t, integrity));
                        // A stream starts converging: a first epoch in another state is
                        // a change.
                        (integrity.state != Availability::Converging)
                            .then_some(Availability::Converging)
                    }
                };
                if let Some(from) = from {
                    availability.push((index, from, *integrity));
                } else if m.availability.is_none() {
                    latest.push((index, integrity.state));
                }
            }
            // The track moves only on INS epochs: on the others the monitor repeats
            // its last solution, which is already recorded with its own time.
            if let (
                Outputs::Federated {
                    solution: Some(s), ..
                },
                Some(ins),
            ) = (&report.outputs, &epoch.ins)
            {
                monitor_stats.track = Some(Track {
                    t,
                    solution: Position {
                        lat: s.lat,
                        lon: s.lon,
                        h: s.h,
                    },
                    ins: Position {
                        lat: ins.lat.to_degrees(),
                        lon: ins.lon.to_degrees(),
                        h: ins.h,
                    },
                });
            }
        }
        let changed = !transitions.is_empty() || !availability.is_empty();
        for (index, state) in latest {
            self.monitors[index].availability = Some(state);
        }
        for (index, outcome, delay_s) in transitions {
            self.announce(index, t, &outcome, delay_s).await;
        }
        for (index, from, integrity) in availability {
            self.announce_availability(index, t, from, &integrity).await;
        }
        changed
    }

    /// The severity of test `outcome` of monitor `index` entering its new state: a
    /// warning while the monitor is still converging (docs/methods.md §M24), else what
    /// the monitor's alarm level says.
    fn severity(&self, index: usize, to: Health) -> Option<Severity> {
        let m = &self.monitors[index];
        let severity = m.alarm_level.severity(to)?;
        Some(if m.availability == Some(Availability::Converging) {
            Severity::Warning
        } else {
            severity
        })
    }

    /// Stores a log entry (committed before it is announced, docs/architecture.md §A2)
    /// and returns it with its id, or with id -1 when the store failed: an operator must
    /// not miss an alarm because the disk did.
    /// A fenced entry (another node owns the session now) is neither stored nor
    /// announced: `None`, and the actor stops.
    async fn store_entry(&mut self, entry: AlarmRecord) -> Option<AlarmRecord> {
        let key = AlarmKey {
            stream: self.recording_stream,
            epoch_index: self.stream_epochs.saturating_sub(1),
        };
        let fence = self.fence();
        let handed = Instant::now();
        let stored = self
            .deps
            .store
            .insert_alarm_keyed(entry.clone(), key, fence.as_ref())
            .await;
        self.deps.metrics.observe_alarm_commit(handed.elapsed());
        match stored {
            Ok(stored) => Some(stored),
            Err(e @ StoreError::Fenced(_)) => {
                let _ = self.store_error(e);
                None
            }
            Err(e) => {
                tracing::error!(session = %entry.session, error = %e, "could not store alarm");
                Some(AlarmRecord { id: -1, ..entry })
            }
        }
    }

    /// Announces one test's state change: `state` always; entering suspect or isolated
    /// also stores a log entry of the change's severity, and an `alarm` event for an
    /// alarm; the return to healthy clears the open entries.
    async fn announce(&mut self, index: usize, t: f64, outcome: &TestOutcome, delay_s: f64) {
        let monitor = self.monitors[index].name.clone();
        let (from, to) = (outcome.previous, outcome.decision.health);
        let severity = self.severity(index, to);
        let mut alarm_text = None;
        let mut log_id = None;
        if let Some(severity) = severity {
            let Some(entry) = self
                .store_entry(AlarmRecord {
                    id: 0,
                    severity,
                    session: self.id.to_string(),
                    monitor: monitor.clone(),
                    test: outcome.name.to_string(),
                    state: to,
                    t,
                    statistic: outcome.statistic.value,
                    threshold: outcome.statistic.threshold,
                    dof: outcome.statistic.dof,
                    test_ratio: outcome.statistic.test_ratio(),
                    delay_s,
                    raised_at_ms: now_ms(),
                    cleared_t: None,
                })
                .await
            else {
                return;
            };
            log_id = Some(entry.id);
            if let Some(test) = self
                .stats
                .monitors
                .get_mut(&monitor)
                .and_then(|m| m.tests.get_mut(&outcome.name))
            {
                test.count(severity, delay_s);
            }
            match severity {
                Severity::Alarm => {
                    self.deps.metrics.alarms.fetch_add(1, Ordering::Relaxed);
                    alarm_text = Some(Arc::<str>::from(wire::tagged("alarm", &entry)));
                }
                Severity::Warning => {
                    self.deps.metrics.warnings.fetch_add(1, Ordering::Relaxed);
                }
            }
        } else if let Err(e) = {
            let fence = self.fence();
            self.deps
                .store
                .clear_alarms_fenced(&self.id, &monitor, &outcome.name, Some(t), fence.as_ref())
                .await
        } {
            tracing::error!(session = %self.id, error = %e, "could not mark alarms cleared");
        }
        let change = StateChange {
            session: self.id.to_string(),
            monitor,
            test: outcome.name.to_string(),
            t,
            from,
            to,
            severity,
            log_id,
        };
        let state_text: Arc<str> = Arc::from(wire::tagged("state", &change));
        self.note_event(&state_text);
        if let Some(text) = &alarm_text {
            self.note_event(text);
        }
        self.broadcast(&state_text);
        if let Some(text) = &alarm_text {
            self.broadcast(text);
        }
        self.send_ingest(state_text.to_string()).await;
        if let Some(text) = alarm_text {
            self.send_ingest(text.to_string()).await;
        }
    }

    /// Announces a change of monitor `index`'s availability (never an alarm). When the
    /// monitor has just converged, a test it left suspect or isolated while converging
    /// (a warning then) is raised now at its alarm level, so a fault present from the
    /// start is not left unannounced.
    async fn announce_availability(
        &mut self,
        index: usize,
        t: f64,
        from: Availability,
        integrity: &Integrity,
    ) {
        self.monitors[index].availability = Some(integrity.state);
        let change = AvailabilityChange {
            session: self.id.to_string(),
            monitor: self.monitors[index].name.clone(),
            t,
            from,
            to: integrity.state,
            protection_level: integrity.protection_level,
            alert_limit: integrity.alert_limit,
        };
        let text: Arc<str> = Arc::from(wire::tagged("availability", &change));
        self.note_event(&text);
        self.broadcast(&text);
        self.send_ingest(text.to_string()).await;
        if from == Availability::Converging {
            self.raise_left_over(index, t).await;
        }
    }

    /// Raises an alarm for every test of monitor `index` that stands in a state its alarm
    /// level counts as an alarm (see [`Actor::announce_availability`]).
    async fn raise_left_over(&mut self, index: usize, t: f64) {
        let m = &self.monitors[index];
        let Some(engine) = self.engines.get(index) else {
            // Only while a step job holds the monitors, which Actor::prefetch never
            // allows when a commit can get here.
            tracing::error!(session = %self.id, monitor = %m.name, "monitors away when raising standing alarms");
            return;
        };
        let standing: Vec<_> = engine
            .tests()
            .slots()
            .iter()
            .filter(|s| m.alarm_level.severity(s.policy.health()) == Some(Severity::Alarm))
            .map(|s| (s.name.clone(), s.policy.health(), s.dof))
            .collect();
        let monitor = m.name.clone();
        for (test, state, dof) in standing {
            let Some(stats) = self
                .stats
                .monitors
                .get(&monitor)
                .and_then(|m| m.tests.get(&test))
            else {
                continue;
            };
            let (statistic, threshold) = (stats.last.unwrap_or(0.0), stats.threshold);
            let delay_s = stats.episode_delay(t);
            let Some(entry) = self
                .store_entry(AlarmRecord {
                    id: 0,
                    severity: Severity::Alarm,
                    session: self.id.to_string(),
                    monitor: monitor.clone(),
                    test: test.to_string(),
                    state,
                    t,
                    statistic,
                    threshold,
                    dof,
                    test_ratio: statistic / threshold,
                    delay_s,
                    raised_at_ms: now_ms(),
                    cleared_t: None,
                })
                .await
            else {
                return;
            };
            if let Some(stats) = self
                .stats
                .monitors
                .get_mut(&monitor)
                .and_then(|m| m.tests.get_mut(&test))
            {
                stats.count(Severity::Alarm, delay_s);
            }
            self.deps.metrics.alarms.fetch_add(1, Ordering::Relaxed);
            let text: Arc<str> = Arc::from(wire::tagged("alarm", &entry));
            self.note_event(&text);
            self.broadcast(&text);
            self.send_ingest(text.to_string()).await;
        }
    }

    /// Copies each test's consistency diagnostics into the statistics (done at
    /// publication, at most [`STATS_PERIOD`]⁻¹ times a second, not per epoch).
    fn refresh_consistency(&mut self) {
        for (m, engine) in self.monitors.iter().zip(&mut self.engines) {
            let Some(monitor_stats) = self.stats.monitors.get_mut(&m.name) else {
                continue;
            };
            for slot in engine.tests_mut().slots_mut() {
                if let Some(test) = monitor_stats.tests.get_mut(&slot.name) {
                    test.consistency = slot.consistency.summary();
                }
            }
        }
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

    fn publish(&mut self, force: bool) {
        let now = Instant::now();
        if force || now.duration_since(self.last_published) >= self.stats_period() {
            self.last_published = now;
            self.stats_pending = false;
            self.refresh_consistency();
            self.stats.published_at_ms = now_ms();
            let snapshot = Arc::new(self.stats.clone());
            if let Some(o) = &mut self.owned
                && now.duration_since(o.last_stats) >= bus::STATS_PERIOD
            {
                o.last_stats = now;
                o.cluster
                    .publish(bus::stats(&self.id, wire::tagged("stats", &*snapshot)));
            }
            self.stats_tx.send_replace(snapshot);
        } else {
            self.stats_pending = true;
        }
    }
}
