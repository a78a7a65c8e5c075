//! The events socket (docs/architecture.md §A6): `state` and `alarm` messages as they
//! happen (never dropped: a subscriber too slow to take them is disconnected),
//! and `stats` at most 20 times a second (a slow subscriber just skips some).

use std::sync::atomic::Ordering;
use std::time::Duration;

use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{Message, Utf8Bytes, WebSocket, WebSocketUpgrade};
use axum::extract::{Path, State};
use axum::response::Response;

use std::sync::Arc;

use futures_util::StreamExt;

use super::app::AppState;
use super::auth::Credential;
use super::cluster::{Cluster, bus, rpc};
use super::error::ApiError;
use super::ingest::{SUBPROTOCOL, answer_close, close_if_too_big, close_socket, upgrade_rejection};
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
    credential: Option<axum::Extension<Credential>>,
    ws: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
) -> Result<Response, ApiError> {
    if let Some(cluster) = state.cluster.clone() {
        // A cluster node: the session's events come over NATS from whichever node owns
        // it, now or after a failover, so the socket outlives a change of owner.
        if cluster.draining() {
            return Err(ApiError::Unavailable(
                "this node is draining: reconnect (the load balancer sends you to another node)"
                    .into(),
            ));
        }
        if state.registry.get(&id).is_none() && state.store.session(&id).await?.is_none() {
            return Err(ApiError::NotFound(format!("no session '{id}'")));
        }
        let ws = ws.map_err(upgrade_rejection)?;
        return Ok(configure(ws).on_upgrade(move |socket| async move {
            state.metrics.event_sockets.fetch_add(1, Ordering::Relaxed);
            let authorization = credential.map(|c| c.bearer());
            run_cluster(socket, state.clone(), cluster, id, authorization).await;
            state.metrics.event_sockets.fetch_sub(1, Ordering::Relaxed);
        }));
    }
    let handle = state
        .registry
        .get(&id)
        .ok_or_else(|| ApiError::NotFound(format!("no session '{id}'")))?;
    let ws = ws.map_err(upgrade_rejection)?;
    Ok(configure(ws).on_upgrade(move |socket| async move {
        state.metrics.event_sockets.fetch_add(1, Ordering::Relaxed);
        run(socket, state.clone(), handle).await;
        state.metrics.event_sockets.fetch_sub(1, Ordering::Relaxed);
    }))
}

/// The observer socket's settings.
fn configure(ws: WebSocketUpgrade) -> WebSocketUpgrade {
    ws.protocols([SUBPROTOCOL])
        // Observers send almost nothing; the protocol layer zero-fills its read
        // buffer before each read, so the 128 KiB default only costs (see ingest.rs).
        .read_buffer_size(8 << 10)
        .max_message_size(MAX_OBSERVER_MESSAGE_BYTES)
        .max_frame_size(MAX_OBSERVER_MESSAGE_BYTES)
}

/// The session's latest statistics for a new observer: from its actor here, or asked of
/// its owner with the observer's own credential (`authorization`; none when nobody runs
/// it).
async fn first_stats(
    state: &AppState,
    cluster: &Cluster,
    id: &str,
    authorization: Option<String>,
) -> Option<String> {
    if let Some(handle) = state.registry.get(id) {
        let snapshot = handle.stats_watch().borrow().clone();
        return Some(wire::tagged("stats", &*snapshot));
    }
    let lease = state.store.lease(id).await.ok()??;
    if !lease.live(crate::service::now_ms()) {
        return None;
    }
    let call = rpc::Call::Http {
        method: "GET".into(),
        uri: format!("/api/v1/sessions/{id}/stats"),
        authorization,
        content_type: None,
        reason: None,
        forwarded_for: None,
        body: String::new(),
        from: cluster.node_id().to_owned(),
    };
    let answer: rpc::HttpAnswer = rpc::call(cluster, &lease.owner, &call).await.ok()?;
    let stats: serde_json::Value = serde_json::from_str(&answer.body).ok()?;
    (answer.status == 200).then(|| wire::tagged("stats", &stats))
}

/// Relays one event from the bus to the socket; false when the socket is done (the bus
/// closed, the session ended, an event was missed, or the client went away). A message
/// without a valid MAC (with a cluster key) is dropped before anything else is read.
async fn relay(
    socket: &mut WebSocket,
    event: Option<async_nats::Message>,
    order: &mut bus::SeqCheck,
    cluster: &Cluster,
) -> bool {
    let Some(message) = event else {
        close_socket(socket, 1011, "the event bus closed; reconnect").await;
        return false;
    };
    if !cluster.accept(&message) {
        return true;
    }
    if bus::is_end(message.headers.as_ref()) {
        let reason = "subscriber too slow or session gone; reconnect and re-read /api/v1/alarms";
        close_socket(socket, 1008, reason).await;
        return false;
    }
    if let Some((epoch, seq)) = bus::position(message.headers.as_ref())
        && !order.accept(epoch, seq)
    {
        cluster.counters.event_gaps.fetch_add(1, Ordering::Relaxed);
        let reason = "missed events; reconnect and re-read /api/v1/alarms";
        close_socket(socket, 1008, reason).await;
        return false;
    }
    let Ok(text) = std::str::from_utf8(&message.payload) else {
        return true;
    };
    socket
        .send(Message::Text(Utf8Bytes::from(text)))
        .await
        .is_ok()
}

/// An observer on a cluster node: the session's events and statistics from NATS. A gap
/// in the events' sequence closes the socket with 1008, as a local subscriber too slow for
/// its queue is closed: the client re-reads `/api/v1/alarms?after=ID`. When the node starts
/// draining the socket closes with 1001 while the load balancer still relays it (see
/// `own::drain`); the client reconnects to another node.
async fn run_cluster(
    mut socket: WebSocket,
    state: AppState,
    cluster: Arc<Cluster>,
    id: String,
    authorization: Option<String>,
) {
    let nats = cluster.nats();
    let (Ok(mut events), Ok(mut stats)) = (
        nats.subscribe(bus::events_subject(&id)).await,
        nats.subscribe(bus::stats_subject(&id)).await,
    ) else {
        close_socket(
            &mut socket,
            1011,
            "cannot subscribe to the session's events",
        )
        .await;
        return;
    };
    if let Some(text) = first_stats(&state, &cluster, &id, authorization).await
        && socket.send(Message::Text(text.into())).await.is_err()
    {
        return;
    }
    let mut shutdown = state.shutdown.clone();
    let mut drain = cluster.drain_signal();
    let mut ticker = tokio::time::interval(STATS_INTERVAL);
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut latest_stats: Option<bytes::Bytes> = None;
    let mut order = bus::SeqCheck::default();
    // Made once, not per pass (see `ingest::run`).
    let shutting_down = shutdown.changed();
    tokio::pin!(shutting_down);
    // The answer (a read guard of the flag) is dropped at once: it must not be held
    // across the close below.
    let draining = async move {
        let _ = drain.wait_for(|d| *d).await;
    };
    tokio::pin!(draining);
    loop {
        tokio::select! {
            biased;
            _ = &mut shutting_down => {
                close_socket(&mut socket, 1001, "server shutting down").await;
                break;
            }
            _ = &mut draining => {
                close_socket(&mut socket, 1001, "node draining; reconnect").await;
                break;
            }
            event = events.next() => {
                if !relay(&mut socket, event, &mut order, &cluster).await {
                    break;
                }
            }
            snapshot = stats.next() => {
                if let Some(message) = snapshot
                    && cluster.accept(&message)
                {
                    latest_stats = Some(message.payload);
                }
            }
            _ = ticker.tick(), if latest_stats.is_some() => {
                if let Some(payload) = latest_stats.take()
                    && let Ok(text) = std::str::from_utf8(&payload)
                    && socket.send(Message::Text(Utf8Bytes::from(text))).await.is_err()
                {
                    break;
                }
            }
            incoming = socket.recv() => match incoming {
                Some(Ok(Message::Close(_))) => {
                    answer_close(&mut socket).await;
                    break;
                }
                None => break,
                Some(Err(e)) => {
                    close_if_too_big(&mut socket, e).await;
                    break;
                }
                Some(Ok(_)) => {}
            },
        }
    }
}

async fn run(mut socket: WebSocket, state: AppState, handle: SessionHandle) {
    let mut events = handle.subscribe();
    let mut stats = handle.stats_watch();
    let mut shutdown = state.shutdown.clone();
    let mut ticker = tokio::time::interval(STATS_INTERVAL);
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    // The first stats message goes out at once so a dashboard has something to draw.
    stats.mark_changed();
    // Made once, not per pass (see `ingest::run`).
    let shutting_down = shutdown.changed();
    tokio::pin!(shutting_down);
    loop {
        tokio::select! {
            biased;
            _ = &mut shutting_down => {
                close_socket(&mut socket, 1001, "server shutting down").await;
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
                    close_socket(&mut socket, 1008, "subscriber too slow or session gone; reconnect and re-read /api/v1/alarms").await;
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
                Some(Ok(Message::Close(_))) => {
                    answer_close(&mut socket).await;
                    break;
                }
                None => break,
                Some(Err(e)) => {
                    close_if_too_big(&mut socket, e).await;
                    break;
                }
                Some(Ok(_)) => {} // observers have nothing to say; ignore
            },
        }
    }
}
