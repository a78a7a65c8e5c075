//! The flight recorder's side of the actor (docs/architecture.md §A12): each accepted
//! frame as the client sent it, with the epochs committed and the messages they caused.

use std::sync::Arc;

use super::Actor;
use crate::service::now_ms;
use crate::service::store::RecordedFrame;

impl Actor {
    /// Queues the frame for the recording: its text as sent, the epochs that were
    /// committed (a frame refused part-way keeps those before the refusal) and the
    /// messages they caused.
    pub(super) async fn record_frame(
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
            .record_frame(
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

    /// Notes a message the current frame caused, for the recording, at the index of the
    /// epoch last committed.
    pub(super) fn note_event(&mut self, text: &str) {
        if self.record {
            let index = self.core.stream_epochs().saturating_sub(1);
            self.frame_events
                .push(format!(r#"{{"epoch_index":{index},"message":{text}}}"#));
        }
    }
}
