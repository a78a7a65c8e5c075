//! Events over NATS (docs/deployment.md, Guarantees). The owner of a session publishes
//!
//! - `navguard.events.<session>`: `state`, `alarm` and `availability` messages, each with
//!   the headers `Navguard-Epoch` (the owner's lease epoch) and `Navguard-Seq` (1, 2, …
//!   per session and epoch), in the order the session raised them;
//! - `navguard.stats.<session>`: the session's statistics, at most every
//!   [`STATS_PERIOD`] (skippable: a subscriber keeps the latest).
//!
//! NATS keeps the order of one publisher's messages on a subject, so a subscriber sees a
//! session's events in order. Delivery is at most once (core NATS, no persistence): a
//! subscriber that sees a gap in `Navguard-Seq` within one epoch missed messages, and its
//! socket closes with 1008 so the client re-reads `GET /api/v1/alarms?after=ID`, exactly as
//! a local subscriber too slow for its queue does. Alarms are in the shared log before
//! they are published.
//!
//! With a cluster key every message also carries `Navguard-Sender`, `Navguard-Time` and
//! `Navguard-Mac` ([`super::mac`]), added as it leaves the publisher; a subscriber drops a
//! message without a valid MAC before reading anything else of it.

use std::time::Duration;

use async_nats::{HeaderMap, Subject};
use bytes::Bytes;
use tokio::sync::mpsc;

/// Messages waiting for the NATS client before new ones are dropped (and counted).
pub const PUBLISH_QUEUE: usize = 1 << 16;

/// Statistics are published to NATS at most this often per session.
pub const STATS_PERIOD: Duration = Duration::from_millis(500);

/// Header: the publishing owner's lease epoch.
pub const EPOCH_HEADER: &str = "Navguard-Epoch";
/// Header: the message's sequence number within the session and epoch.
pub const SEQ_HEADER: &str = "Navguard-Seq";

/// One message for NATS.
#[derive(Debug)]
pub struct Outgoing {
    /// Subject.
    pub subject: Subject,
    /// Headers (events only).
    pub headers: Option<HeaderMap>,
    /// JSON text.
    pub payload: Bytes,
}

/// A session id as a subject token: ids are letters, digits, `_`, `-` and `.`; the dot
/// separates tokens in NATS, so it is written `~2e` (`~` never occurs in an id).
pub fn token(id: &str) -> String {
    id.replace('.', "~2e")
}

/// The subject of a session's events.
pub fn events_subject(session: &str) -> Subject {
    Subject::from(format!("navguard.events.{}", token(session)))
}

/// The subject of a session's statistics.
pub fn stats_subject(session: &str) -> Subject {
    Subject::from(format!("navguard.stats.{}", token(session)))
}

/// An event message with its epoch and sequence headers.
pub fn event(session: &str, epoch: i64, seq: u64, text: &str) -> Outgoing {
    let mut headers = HeaderMap::new();
    headers.insert(EPOCH_HEADER, epoch.to_string().as_str());
    headers.insert(SEQ_HEADER, seq.to_string().as_str());
    Outgoing {
        subject: events_subject(session),
        headers: Some(headers),
        payload: Bytes::copy_from_slice(text.as_bytes()),
    }
}

/// Header: the session ended (deleted); its events sockets close.
pub const END_HEADER: &str = "Navguard-End";

/// The last message on a deleted session's events subject.
pub fn end(session: &str) -> Outgoing {
    let mut headers = HeaderMap::new();
    headers.insert(END_HEADER, "deleted");
    Outgoing {
        subject: events_subject(session),
        headers: Some(headers),
        payload: Bytes::from_static(b"{}"),
    }
}

/// True for [`end`]'s message.
pub fn is_end(headers: Option<&HeaderMap>) -> bool {
    headers.is_some_and(|h| h.get(END_HEADER).is_some())
}

/// A statistics message.
pub fn stats(session: &str, text: String) -> Outgoing {
    Outgoing {
        subject: stats_subject(session),
        headers: None,
        payload: Bytes::from(text),
    }
}

/// Reads `(epoch, seq)` from an event's headers.
pub fn position(headers: Option<&HeaderMap>) -> Option<(i64, u64)> {
    let h = headers?;
    let epoch = h.get(EPOCH_HEADER)?.as_str().parse().ok()?;
    let seq = h.get(SEQ_HEADER)?.as_str().parse().ok()?;
    Some((epoch, seq))
}

/// Tracks one session's event sequence at a subscriber: a message is in order when it
/// follows the last one of its epoch, or starts a newer epoch (a new owner).
#[derive(Debug, Default, Clone, Copy)]
pub struct SeqCheck {
    last: Option<(i64, u64)>,
}

impl SeqCheck {
    /// Accepts `(epoch, seq)`; false on a gap (a message of this epoch was missed).
    /// Messages of an older epoch (the previous owner's last words, late) are accepted
    /// without moving the cursor back.
    pub fn accept(&mut self, epoch: i64, seq: u64) -> bool {
        match self.last {
            Some((e, s)) if epoch == e => {
                let in_order = seq == s + 1;
                self.last = Some((e, seq.max(s)));
                in_order
            }
            Some((e, _)) if epoch < e => true,
            // A first message, or a new owner: its sequence starts here. A subscriber that
            // joins late sees any seq first; a new owner's events start at 1, and the
            // handover itself is in the log.
            _ => {
                self.last = Some((epoch, seq));
                true
            }
        }
    }
}

/// Publishes queued messages in order (one task per node, so one session's messages keep
/// the order the actor queued them in), each sealed with the cluster key if there is one.
/// It holds no reference to the [`super::Cluster`], so it ends when the cluster is dropped.
pub(super) async fn publisher(
    nats: async_nats::Client,
    keyring: Option<std::sync::Arc<super::mac::Keyring>>,
    node_id: String,
    mut rx: mpsc::Receiver<Outgoing>,
) {
    while let Some(m) = rx.recv().await {
        let headers = super::mac::seal(
            keyring.as_deref(),
            &node_id,
            m.subject.as_str(),
            m.headers,
            &m.payload,
        );
        let sent = match headers {
            Some(h) => nats.publish_with_headers(m.subject, h, m.payload).await,
            None => nats.publish(m.subject, m.payload).await,
        };
        if let Err(e) = sent {
            tracing::warn!(error = %e, "nats publish failed");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_map_to_one_token_each() {
        assert_eq!(token("ship-1.a"), "ship-1~2ea");
        assert_ne!(token("a.b"), token("a~2eb".replace('~', "_").as_str()));
        assert_eq!(events_subject("s.1").as_str(), "navguard.events.s~2e1");
    }

    #[test]
    fn a_gap_within_an_epoch_is_caught_and_a_new_owner_restarts_the_count() {
        let mut c = SeqCheck::default();
        assert!(c.accept(3, 17), "a late joiner starts anywhere");
        assert!(c.accept(3, 18));
        assert!(!c.accept(3, 20), "19 was missed");
        assert!(c.accept(4, 1), "a new owner");
        assert!(
            c.accept(3, 21),
            "the old owner's late message does not rewind"
        );
        assert!(c.accept(4, 2));
    }

    #[test]
    fn positions_round_trip_through_the_headers() {
        let m = event("s", 7, 42, "{}");
        assert_eq!(position(m.headers.as_ref()), Some((7, 42)));
        assert_eq!(position(None), None);
    }
}
