//! Cluster ownership of a session (docs/architecture.md §A14, docs/deployment.md): the
//! fence every write carries, checkpoints of the session core, the handover.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use super::Actor;
use crate::service::cluster::Cluster;
use crate::service::now_ms;
use crate::service::session::SessionError;
use crate::service::store::{Checkpoint, Fence, StoreError};

/// What an actor that owns its session through a lease keeps.
pub(super) struct Owned {
    pub(super) cluster: Arc<Cluster>,
    pub(super) fence: Fence,
    /// Sequence number of the last event published to NATS (per lease epoch).
    pub(super) event_seq: u64,
    /// Version of the last checkpoint taken.
    version: i64,
    /// When the next checkpoint is due; `None` while nothing changed since the last.
    pub(super) due: Option<Instant>,
    /// When the last checkpoint was taken.
    last: Instant,
    /// When statistics were last published to NATS.
    pub(super) last_stats: Instant,
    /// A write was fenced: another node owns the session now; the actor stops.
    fenced: bool,
    /// A background checkpoint is still being written: the next one waits for it, so a
    /// session never has more than one queued (the memory stays bounded when the store
    /// falls behind).
    in_flight: Arc<AtomicBool>,
}

impl Owned {
    /// Ownership under `fence`, nothing checkpointed yet.
    pub(super) fn new(cluster: Arc<Cluster>, fence: Fence) -> Self {
        let now = Instant::now();
        Owned {
            cluster,
            fence,
            event_seq: 0,
            version: 0,
            due: None,
            last: now,
            last_stats: now,
            fenced: false,
            in_flight: Arc::default(),
        }
    }
}

impl Actor {
    /// Restores the session from `checkpoint` at start; one that cannot be restored is
    /// logged and the session starts afresh.
    pub(super) fn restore(&mut self, checkpoint: &Checkpoint) {
        match self.core.restore(&checkpoint.state) {
            Ok(recording_stream) => {
                self.recording_stream = recording_stream;
                // A session that never streamed (a handover right after its creation)
                // has no stream to resume: its first stream starts afresh.
                self.resumable = recording_stream > 0;
                self.stats_tx
                    .send_replace(Arc::new(self.core.stats().clone()));
                tracing::info!(session = %self.id, epochs = checkpoint.epochs, t = ?checkpoint.t, "session restored from its checkpoint");
            }
            Err(e) => {
                tracing::warn!(session = %self.id, error = %e, "checkpoint not restored; the session starts afresh");
            }
        }
    }

    /// A write was fenced: the actor stops.
    pub(super) fn fenced(&self) -> bool {
        self.owned.as_ref().is_some_and(|o| o.fenced)
    }

    /// The fence of this actor's writes (cluster), cloned for a store call.
    pub(super) fn fence(&self) -> Option<Fence> {
        self.owned.as_ref().map(|o| o.fence.clone())
    }

    /// A store failure as a session error; a fenced write also stops the actor.
    pub(super) fn store_error(&mut self, e: StoreError) -> SessionError {
        if matches!(e, StoreError::Fenced(_)) {
            if let Some(o) = &mut self.owned {
                o.fenced = true;
            }
            return SessionError::Moved(self.id.to_string());
        }
        SessionError::Store(e.to_string())
    }

    /// Notes that the state changed: a checkpoint is due within the interval.
    pub(super) fn changed(&mut self) {
        if let Some(o) = &mut self.owned
            && o.due.is_none()
        {
            let interval = o.cluster.config.checkpoint_interval;
            o.due = Some((o.last + interval).max(Instant::now()));
        }
    }

    /// Takes a checkpoint and stores it: in the background (`wait` false; a later one
    /// never loses to an earlier one, they are versioned) or before returning.
    pub(super) async fn checkpoint(&mut self, wait: bool) -> bool {
        if let Some(o) = &mut self.owned
            && !wait
            && o.in_flight.load(Ordering::Acquire)
        {
            o.due = Some(Instant::now() + o.cluster.config.checkpoint_interval / 4);
            return false;
        }
        let bytes = match self.core.checkpoint(self.recording_stream) {
            Ok(b) => b,
            Err(e) => {
                tracing::error!(session = %self.id, error = %e, "checkpoint not taken");
                return false;
            }
        };
        let (t, epochs) = (self.core.last_t(), self.core.stream_epochs() as i64);
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

    /// Hands the session over: see [`crate::service::session::ControlCommand::Release`].
    pub(super) async fn release(&mut self, force: bool) -> Result<(), SessionError> {
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
                "resume": {"t": self.core.last_t(), "epochs": self.core.stream_epochs()},
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
}
