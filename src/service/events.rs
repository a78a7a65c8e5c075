//! The events socket (docs/architecture.md §A6): `state` and `alarm` messages as they
//! happen (never dropped: a subscriber too slow to take them is disconnected),
//! and `stats` at most 20 times a second (a slow subscriber just skips some).

use std::sync::atomic::Ordering;
use std::time::Duration;

use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{CloseFrame, Message, Utf8Bytes, WebSocket, WebSocketUpgrade};
use axum::extract::{Path, State};
use axum::response::Response;

use super::app::AppState;
use super::error::ApiError;
use super::ingest::{SUBPROTOCOL, close_if_too_big, upgrade_rejection};
use super::session::SessionHandle;
use super::wire;

/// Minimum interval between two `stats` messages on one socket (≤ 20/s).
const STATS_INTERVAL: Duration = Duration::from_millis(50);

/// Largest message an observer may send (it is ignored anyway); a larger one
/// gets close 1009 instead of costing the protocol's 64 MiB default in memory.
const MAX_OBSERVER_MESSAGE_BYTES: usize = 64 << 10;

/// `GET /api/v1/sessions/{id}/events`
pub async fn events(
    State(state): State<AppState>,
    Path(id): Path<String>,
    ws: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
) -> Result<Response, ApiError> {
    let handle = state
        .registry
        .get(&id)
        .ok_or_else(|| ApiError::NotFound(format!("no session '{id}'")))?;
    let ws = ws.map_err(upgrade_rejection)?;
    Ok(ws
        .protocols([SUBPROTOCOL])
        // Observers send almost nothing; the protocol layer zero-fills its read
        // buffer before each read, so the 128 KiB default only costs (see ingest.rs).
        .read_buffer_size(8 << 10)
        .max_message_size(MAX_OBSERVER_MESSAGE_BYTES)
        .max_frame_size(MAX_OBSERVER_MESSAGE_BYTES)
        .on_upgrade(move |socket| async move {
            state.metrics.event_sockets.fetch_add(1, Ordering::Relaxed);
            run(socket, state.clone(), handle).await;
            state.metrics.event_sockets.fetch_sub(1, Ordering::Relaxed);
        }))
}

async fn run(mut socket: WebSocket, state: AppState, handle: SessionHandle) {
    let mut events = handle.subscribe();
    let mut stats = handle.stats_watch();
    let mut shutdown = state.shutdown.clone();
    let mut ticker = tokio::time::interval(STATS_INTERVAL);
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    // The first stats message goes out at once so a dashboard has something to draw.
    stats.mark_changed();
    loop {
        tokio::select! {
            biased;
            _ = shutdown.changed() => {
                let _ = socket.send(Message::Close(Some(CloseFrame { code: 1001, reason: Utf8Bytes::from_static("server shutting down") }))).await;
                break;
            }
            event = events.recv() => match event {
                Some(text) => {
                    if socket.send(Message::Text(Utf8Bytes::from(&*text))).await.is_err() {
                        break;
                    }
                }
                None => {
                    // Dropped by the session: too far behind, or the session was deleted.
                    let _ = socket.send(Message::Close(Some(CloseFrame { code: 1008, reason: Utf8Bytes::from_static("subscriber too slow or session gone; reconnect and re-read /api/v1/alarms") }))).await;
                    break;
                }
            },
            _ = ticker.tick() => {
                if stats.has_changed().unwrap_or(false) {
                    let snapshot = stats.borrow_and_update().clone();
                    let text = wire::tagged("stats", &*snapshot);
                    if socket.send(Message::Text(text.into())).await.is_err() {
                        break;
                    }
                }
            }
            incoming = socket.recv() => match incoming {
                Some(Ok(Message::Close(_))) | None => break,
                Some(Err(e)) => {
                    close_if_too_big(&mut socket, e).await;
                    break;
                }
                Some(Ok(_)) => {} // observers have nothing to say; ignore
            },
        }
    }
}
