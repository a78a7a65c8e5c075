//! The actor's control commands that change the session: a stream attached (afresh or
//! resumed) or detached, a threshold change stored before it is answered, the spec
//! persisted, the session deleted (docs/architecture.md §A3, §A4).

use std::sync::Arc;
use std::time::Instant;

use tokio::sync::mpsc;

use super::{Actor, INGEST_QUEUE};
use crate::service::cluster::bus;
use crate::service::now_ms;
use crate::service::session::SessionError;
use crate::service::session::handle::{IngestLink, Resumed};
use crate::service::store::StoredSession;
use crate::service::wire::{self, StateChange, ThresholdUpdate, ThresholdView};
use navguard_core::detect::Health;

impl Actor {
    /// A copy of the session's spec as in force.
    pub(super) fn stored(&self) -> StoredSession {
        self.shared
            .stored
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// Attaches a new ingest stream: refused while one is attached; carries on from the
    /// session's state when asked and it holds one; else every monitor starts afresh
    /// (docs/architecture.md §A3), tests left suspect or isolated are announced healthy
    /// and every open log entry of the session is cleared.
    pub(super) async fn attach(&mut self, resume: bool) -> Result<IngestLink, SessionError> {
        if self.ingest.as_ref().is_some_and(|tx| !tx.is_closed()) {
            return Err(SessionError::AlreadyAttached(self.id.to_string()));
        }
        if resume && self.resumable {
            return Ok(self.attach_resumed());
        }
        self.resumable = true;
        let fence = self.fence();
        for returned in self.core.restart() {
            if let Err(e) = self
                .deps
                .store
                .clear_alarms(
                    &self.id,
                    &returned.monitor,
                    &returned.test,
                    returned.t,
                    fence.as_ref(),
                )
                .await
            {
                tracing::error!(session = %self.id, error = %e, "could not mark alarms cleared");
            }
            let change = StateChange {
                session: self.id.to_string(),
                monitor: returned.monitor,
                test: returned.test.to_string(),
                t: returned.t.unwrap_or(0.0),
                from: returned.from,
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
            .clear_session_alarms(&self.id, fence.as_ref())
            .await
        {
            tracing::error!(session = %self.id, error = %e, "could not mark alarms cleared");
        }
        self.stream += 1;
        self.recording_stream = (now_ms().max(0) as u64).max(self.recording_stream + 1);
        let link = self.open_stream(None);
        // A cluster owner stores the new stream at once: a failover from here on resumes
        // this stream (its id keys its alarms), never an older one.
        if self.owned.is_some() {
            self.checkpoint(false).await;
        }
        Ok(link)
    }

    /// A stream that carries on from the session's state: nothing is reset, the
    /// recording stream and epoch count go on, and the client is told where.
    fn attach_resumed(&mut self) -> IngestLink {
        self.stream += 1;
        let resumed = Resumed {
            t: self.core.last_t(),
            epochs: self.core.stream_epochs(),
        };
        self.open_stream(Some(resumed))
    }

    /// The queue of a newly attached stream, the session marked connected.
    fn open_stream(&mut self, resumed: Option<Resumed>) -> IngestLink {
        let (tx, rx) = mpsc::channel(INGEST_QUEUE);
        self.ingest = Some(tx);
        self.core.stats_mut().connected = true;
        self.publish(true);
        IngestLink {
            resumed,
            stream: self.stream,
            record: self.record,
            outgoing: rx,
        }
    }

    /// The ingest socket of `stream` closed (a later stream's is left alone).
    pub(super) fn detach(&mut self, stream: u64) {
        if stream == self.stream {
            self.ingest = None;
            let stats = self.core.stats_mut();
            stats.connected = false;
            stats.epochs_per_s = 0.0;
            self.rate_window = (Instant::now(), 0);
            self.publish(true);
        }
    }

    /// Applies a threshold change and stores the spec before answering
    /// (docs/architecture.md §A4: stored in the order applied). If the store refuses, the
    /// change is undone, so the state in force always equals the state stored.
    pub(super) async fn set_threshold(
        &mut self,
        name: &str,
        update: ThresholdUpdate,
    ) -> Result<(ThresholdView, ThresholdView), SessionError> {
        let index = self.find(name)?;
        let previous = self.core.threshold_view(index);
        let before = self.stored();
        let undo = self.core.apply_threshold(index, &update)?;
        let stored = self.store_threshold(index, &update);
        self.publish(true);
        let fence = self.fence();
        if let Err(e) = self.deps.store.put_session(&stored, fence.as_ref()).await {
            self.core.undo_threshold(undo);
            *self.shared.stored.lock().unwrap_or_else(|p| p.into_inner()) = before;
            let error = self.store_error(e);
            self.publish(true);
            return Err(error);
        }
        self.changed();
        Ok((previous, self.core.threshold_view(index)))
    }

    /// Writes monitor `index`'s thresholds, policy and alarm level as now in force into
    /// the session's spec; returns a copy to store.
    fn store_threshold(&mut self, index: usize, update: &ThresholdUpdate) -> StoredSession {
        let bank = self.core.engines()[index].tests();
        let (spec, policy) = (bank.spec(), bank.policy());
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
    }

    /// Stores the session's spec as in force (a new session).
    pub(super) async fn persist(&mut self) -> Result<(), SessionError> {
        let stored = self.stored();
        let fence = self.fence();
        self.deps
            .store
            .put_session(&stored, fence.as_ref())
            .await
            .map_err(|e| self.store_error(e))
    }

    /// Deletes the session's row in its own order, after every change acknowledged
    /// before (docs/architecture.md §A4); on success the actor stops, so nothing can
    /// write the session back.
    pub(super) async fn delete(&mut self) -> Result<(), SessionError> {
        let fence = self.fence();
        match self
            .deps
            .store
            .delete_session(&self.id, fence.as_ref())
            .await
        {
            Ok(_) => {
                if let Some(o) = &self.owned {
                    // Observers on other nodes hear of it as local ones do (their queue
                    // closes): the events socket ends.
                    o.cluster.publish(bus::end(&self.id));
                }
                Ok(())
            }
            Err(e) => Err(self.store_error(e)),
        }
    }
}
