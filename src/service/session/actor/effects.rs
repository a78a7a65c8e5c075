//! The core's effects carried out (docs/architecture.md §A2 steps 5–6): each stepped
//! epoch committed, its `result` sent, then each effect in order: a log entry committed
//! to the store before it is announced, then the message to the recording, the events
//! subscribers (and the cluster bus) and the ingest socket.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Instant;

use axum::extract::ws::Utf8Bytes;

use super::Actor;
use crate::service::cluster::bus;
use crate::service::now_ms;
use crate::service::store::{AlarmKey, StoreError};
use crate::service::wire::{self, AlarmRecord, Severity, StateChange};
use navguard_core::epoch::Epoch;
use navguard_core::monitor::MonitorReport;
use navguard_core::session::Effect;

impl Actor {
    /// Commits the stepped epochs in order; true if any state changed.
    pub(super) async fn commit_slice(
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

    /// Makes one stepped epoch current and carries out its effects; true if any state
    /// changed.
    async fn commit_epoch(&mut self, epoch: &Epoch, reports: &[Option<MonitorReport>]) -> bool {
        let mut effects = std::mem::take(&mut self.effects);
        self.core.commit(epoch, reports, &mut effects);
        self.deps.metrics.epochs.fetch_add(1, Ordering::Relaxed);
        if self.echo {
            let text = self.result_frame(epoch.t, reports);
            self.send_ingest(text).await;
        }
        let changed = !effects.is_empty();
        for effect in effects.drain(..) {
            self.carry_out(effect).await;
        }
        self.effects = effects;
        changed
    }

    async fn carry_out(&mut self, effect: Effect) {
        match effect {
            Effect::State { change, entry } => self.announce_state(change, entry).await,
            Effect::Availability(change) => {
                let text: Arc<str> = Arc::from(wire::tagged("availability", &change));
                self.announce(&text).await;
            }
            // After a fenced write the actor stops: raise no more (as for the first).
            Effect::Standing(_) if self.fenced() => {}
            Effect::Standing(entry) => {
                let Some(entry) = self.store_entry(entry).await else {
                    return;
                };
                self.deps.metrics.alarms.fetch_add(1, Ordering::Relaxed);
                let text: Arc<str> = Arc::from(wire::tagged("alarm", &entry));
                self.announce(&text).await;
            }
        }
    }

    /// Announces one test's state change: entering suspect or isolated, its log entry is
    /// stored first and an alarm is also sent as an `alarm` message; the return to
    /// healthy clears the test's open entries.
    async fn announce_state(&mut self, mut change: StateChange, entry: Option<AlarmRecord>) {
        let mut alarm_text = None;
        if let Some(entry) = entry {
            let Some(entry) = self.store_entry(entry).await else {
                return;
            };
            change.log_id = Some(entry.id);
            match entry.severity {
                Severity::Alarm => {
                    self.deps.metrics.alarms.fetch_add(1, Ordering::Relaxed);
                    alarm_text = Some(Arc::<str>::from(wire::tagged("alarm", &entry)));
                }
                Severity::Warning => {
                    self.deps.metrics.warnings.fetch_add(1, Ordering::Relaxed);
                }
            }
        } else {
            let fence = self.fence();
            let cleared = self
                .deps
                .store
                .clear_alarms(
                    &self.id,
                    &change.monitor,
                    &change.test,
                    Some(change.t),
                    fence.as_ref(),
                )
                .await;
            if let Err(e) = cleared {
                tracing::error!(session = %self.id, error = %e, "could not mark alarms cleared");
            }
        }
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

    /// One message to the recording, the subscribers and the ingest socket.
    async fn announce(&mut self, text: &Arc<str>) {
        self.note_event(text);
        self.broadcast(text);
        self.send_ingest(text.to_string()).await;
    }

    /// Stores a log entry (committed before it is announced, docs/architecture.md §A2)
    /// and returns it with its id, or with id -1 when the store failed: an operator must
    /// not miss an alarm because the disk did.
    /// A fenced entry (another node owns the session now) is neither stored nor
    /// announced: `None`, and the actor stops.
    async fn store_entry(&mut self, mut entry: AlarmRecord) -> Option<AlarmRecord> {
        entry.raised_at_ms = now_ms();
        let key = AlarmKey {
            stream: self.recording_stream,
            epoch_index: self.core.stream_epochs().saturating_sub(1),
        };
        let fence = self.fence();
        let handed = Instant::now();
        let stored = self
            .deps
            .store
            .insert_alarm(entry.clone(), key, fence.as_ref())
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

    /// Sends to every event subscriber; one whose queue is full is dropped
    /// (its socket closes) rather than silently missing an alarm.
    pub(super) fn broadcast(&mut self, text: &Arc<str>) {
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

    /// The epoch's `result` frame, written after the frame's earlier ones in
    /// [`Actor::results`] and split off it (no allocation of its own).
    fn result_frame(&mut self, t: f64, reports: &[Option<MonitorReport>]) -> Utf8Bytes {
        let monitors = self.core.roster().iter().zip(reports);
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
}
