//! The ingest socket (docs/architecture.md §A6): a thin task that parses frames at the edge,
//! hands epochs to the session actor through its bounded channel, and writes
//! back what the actor sends (results, state changes, alarms, errors).

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{CloseFrame, Message, Utf8Bytes, WebSocket, WebSocketUpgrade};
use axum::extract::{Path, RawQuery, State};
use axum::response::Response;
use futures_util::SinkExt;
use serde_json::json;
use tokio::sync::mpsc::error::TrySendError;

use super::app::AppState;
use super::error::ApiError;
use super::session::handle::IngestLink;
use super::session::{FrameCommand, SessionHandle};
use super::wire::{self, ErrorEvent, FrameError, FrameErrorCode};

/// The subprotocol the server selects when a client offers it (browsers
/// offering a `bearer.TOKEN` protocol must also offer this one).
pub const SUBPROTOCOL: &str = "navguard";

/// Hard cap on a WebSocket message, as a multiple of the frame limit. Frames
/// between the limit and the cap get an `error` event and the socket stays
/// open; beyond the cap the protocol layer stops reading and the server sends
/// close 1009 (message too big) before closing.
const HARD_CAP_FACTOR: usize = 16;

/// The socket's read buffer. The protocol layer zero-fills the whole buffer
/// before each read, so its 128 KiB default cost ~70 % of the server's
/// instructions with single-epoch frames (callgrind) and 128 KiB per open
/// socket; larger frames just take several reads.
const READ_BUFFER_BYTES: usize = 8 << 10;

/// Messages for the client written before one flush (one system call).
const FLUSH_EVERY: usize = 256;

/// How long a closing socket waits for its Close frame to be written and, when the server
/// closes, for the client's answering Close, before the connection is dropped anyway.
const CLOSE_WAIT: Duration = Duration::from_secs(2);

/// `resume=true` (or `1`): carry on from the session's state instead of starting afresh
/// (docs/deployment.md, Failover); `false`, `0` or absent: a fresh stream. Other
/// parameters (`token`) are left to others.
fn resume_param(query: Option<&str>) -> Result<bool, ApiError> {
    let mut resume = false;
    for pair in query.unwrap_or("").split('&') {
        let (key, value) = pair.split_once('=').unwrap_or((pair, ""));
        if key == "resume" {
            resume = match value {
                "true" | "1" => true,
                "false" | "0" => false,
                other => {
                    return Err(ApiError::BadRequest(format!(
                        "resume={other}: give true or false"
                    )));
                }
            };
        }
    }
    Ok(resume)
}

/// `GET /api/v1/sessions/{id}/ingest`
pub async fn ingest(
    State(state): State<AppState>,
    Path(id): Path<String>,
    RawQuery(query): RawQuery,
    ws: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
) -> Result<Response, ApiError> {
    let resume = resume_param(query.as_deref())?;
    let path = format!("/api/v1/sessions/{id}/ingest");
    let handle = super::cluster::own::claim(&state, &id, &path).await?;
    let ws = ws.map_err(upgrade_rejection)?;
    let link = handle.attach(resume).await?;
    let cap = state
        .config
        .limits
        .max_frame_bytes
        .saturating_mul(HARD_CAP_FACTOR);
    Ok(ws
        .protocols([SUBPROTOCOL])
        .read_buffer_size(READ_BUFFER_BYTES)
        .max_message_size(cap)
        .max_frame_size(cap)
        .on_upgrade(move |socket| async move {
            state.metrics.ingest_sockets.fetch_add(1, Ordering::Relaxed);
            run(socket, state.clone(), handle, link).await;
            state.metrics.ingest_sockets.fetch_sub(1, Ordering::Relaxed);
        }))
}

/// A socket route requested without a valid upgrade: JSON 426 (or 400 for a
/// malformed handshake) instead of axum's plain text.
pub fn upgrade_rejection(rejection: WebSocketUpgradeRejection) -> ApiError {
    let text = format!("this route is a WebSocket: {}", rejection.body_text());
    match rejection {
        // A plain HTTP request (no Connection/Upgrade headers, or a proxy stripped them).
        WebSocketUpgradeRejection::InvalidConnectionHeader(_)
        | WebSocketUpgradeRejection::InvalidUpgradeHeader(_)
        | WebSocketUpgradeRejection::ConnectionNotUpgradable(_) => ApiError::UpgradeRequired(text),
        _ => ApiError::BadRequest(text),
    }
}

/// What to do with one text frame.
enum Next {
    Forward(FrameCommand),
    Refuse(FrameError),
}

fn on_text(text: &str, link: (u64, bool), state: &AppState) -> Next {
    let (stream, record) = link;
    let limits = &state.config.limits;
    if text.len() > limits.max_frame_bytes {
        return Next::Refuse(FrameError::new(
            FrameErrorCode::FrameTooLarge,
            format!(
                "frame is {} bytes, the limit is {}",
                text.len(),
                limits.max_frame_bytes
            ),
        ));
    }
    match wire::parse_frame(text, limits.max_batch_epochs) {
        Ok(epochs) => Next::Forward(FrameCommand {
            stream,
            epochs,
            received: Instant::now(),
            text: record.then(|| std::sync::Arc::from(text)),
        }),
        Err(e) => Next::Refuse(e),
    }
}

/// What one read from the client means for the socket's loop.
enum Read {
    /// A frame's text.
    Text(Utf8Bytes),
    /// A frame refused before parsing (binary, not UTF-8).
    Refuse(FrameError),
    /// Nothing to do (ping and pong are answered by the protocol layer).
    Skip,
    /// The socket ends: the client closed (answered), went away, or broke the protocol.
    End,
}

/// Reads the text of a frame from what the socket gave; a Close is answered here.
async fn read(
    socket: &mut WebSocket,
    incoming: Option<Result<Message, axum::Error>>,
    session: &str,
) -> Read {
    match incoming {
        Some(Ok(Message::Text(text))) => Read::Text(text),
        Some(Ok(Message::Binary(bytes))) => match std::str::from_utf8(&bytes) {
            Ok(s) => Read::Text(Utf8Bytes::from(s)),
            Err(_) => Read::Refuse(FrameError::new(
                FrameErrorCode::MalformedJson,
                "binary frame is not UTF-8 JSON",
            )),
        },
        Some(Ok(Message::Close(_))) => {
            answer_close(socket).await;
            Read::End
        }
        None => Read::End,
        Some(Ok(_)) => Read::Skip,
        Some(Err(e)) => {
            if !close_if_too_big(socket, e).await {
                tracing::debug!(session = %session, "ingest socket error");
            }
            Read::End
        }
    }
}

async fn run(mut socket: WebSocket, state: AppState, handle: SessionHandle, link: IngestLink) {
    let (stream, record) = (link.stream, link.record);
    let mut outgoing = link.outgoing;
    let mut shutdown = state.shutdown.clone();
    let mut ready =
        json!({"type": "ready", "session": handle.id(), "stream": stream, "resumed": link.resumed});
    if let Some(cluster) = &state.cluster {
        ready["node"] = json!(cluster.node_id());
    }
    let ready = ready.to_string();
    if socket.send(Message::Text(ready.into())).await.is_err() {
        handle.detach(stream).await;
        return;
    }
    let mut pending: Option<FrameCommand> = None;
    // Made once: a fresh `changed()` in every pass of the loop joined and left the
    // shutdown signal's waiter list, shared by every socket, three or four times a frame.
    let shutting_down = shutdown.changed();
    tokio::pin!(shutting_down);
    loop {
        tokio::select! {
            biased;
            _ = &mut shutting_down => {
                close_socket(&mut socket, 1001, "server shutting down").await;
                break;
            }
            message = outgoing.recv() => match message {
                Some(text) => {
                    // Write what is already queued (a batch's results) with one
                    // flush instead of one system call per message.
                    if write_queued(&mut socket, text, &mut outgoing).await.is_err() {
                        break;
                    }
                }
                // The actor replaced or dropped this stream.
                None => {
                    close_socket(&mut socket, 1000, "stream detached").await;
                    break;
                }
            },
            permit = handle.frames().reserve(), if pending.is_some() => match permit {
                Ok(permit) => {
                    if let Some(frame) = pending.take() {
                        permit.send(frame);
                    }
                }
                Err(_) => break,
            },
            incoming = socket.recv(), if pending.is_none() => {
                let text = match read(&mut socket, incoming, handle.id()).await {
                    Read::Text(text) => text,
                    Read::Refuse(e) => {
                        if send_error(&mut socket, &state, &e).await.is_err() { break; }
                        continue;
                    }
                    Read::Skip => continue,
                    Read::End => break,
                };
                match on_text(&text, (stream, record), &state) {
                    // Straight into the actor's queue when it has room (one pass of this
                    // loop less per frame); when full, the frame waits for a permit while
                    // the socket is still written.
                    Next::Forward(frame) => match handle.frames().try_send(frame) {
                        Ok(()) => {}
                        Err(TrySendError::Full(frame)) => pending = Some(frame),
                        Err(TrySendError::Closed(_)) => break,
                    },
                    Next::Refuse(e) => {
                        if send_error(&mut socket, &state, &e).await.is_err() { break; }
                    }
                }
            }
        }
    }
    handle.detach(stream).await;
}

/// The client sent a Close frame: writes the answering Close the protocol layer queued
/// when it read it (RFC 6455 §5.5.1: the client's code echoed, or none when it gave none),
/// after which the connection ends. The layer writes it only on a later read or flush,
/// and the task ends right after this, so without the flush the connection dropped
/// without a Close frame, which the client reports as 1006 (abnormal closure).
pub(crate) async fn answer_close(socket: &mut WebSocket) {
    // The flush ends with the protocol layer's "connection closed": the expected outcome.
    let _ = tokio::time::timeout(CLOSE_WAIT, socket.flush()).await;
}

/// Closes from the server's side (RFC 6455 §7.1.2): sends a Close frame with `code` and
/// `reason`, then reads and drops whatever the client still sends until its answering
/// Close ends the connection (at most [`CLOSE_WAIT`]). Dropping the connection with the
/// client's frames still unread would reset it, and a reset can discard the Close frame
/// (and a `moved` before it) before the client, or a proxy between, has read them.
pub(crate) async fn close_socket(socket: &mut WebSocket, code: u16, reason: &'static str) {
    let frame = CloseFrame {
        code,
        reason: Utf8Bytes::from_static(reason),
    };
    if socket.send(Message::Close(Some(frame))).await.is_err() {
        return;
    }
    let _ = tokio::time::timeout(CLOSE_WAIT, async {
        while let Some(Ok(_)) = socket.recv().await {}
    })
    .await;
}

/// On a socket error: when it is a message over the size cap, sends close 1009
/// (RFC 6455 §7.4.1, "message too big") so the client learns why, and says
/// true. Any other error (a reset, a protocol violation) is logged and false.
/// The protocol layer reads nothing more of an oversize message (its header
/// stays pending), so the socket can only be closed after this.
pub(crate) async fn close_if_too_big(socket: &mut WebSocket, e: axum::Error) -> bool {
    let e = e.into_inner();
    let too_big = matches!(
        e.downcast_ref::<tungstenite::Error>(),
        Some(tungstenite::Error::Capacity(_))
    );
    if too_big {
        let close = CloseFrame {
            code: 1009,
            reason: Utf8Bytes::from_static("message too big for this socket"),
        };
        let _ = socket.send(Message::Close(Some(close))).await;
    } else {
        tracing::debug!(error = %e, "socket error");
    }
    too_big
}

async fn write_queued(
    socket: &mut WebSocket,
    first: Utf8Bytes,
    outgoing: &mut tokio::sync::mpsc::Receiver<Utf8Bytes>,
) -> Result<(), axum::Error> {
    socket.feed(Message::Text(first)).await?;
    for _ in 1..FLUSH_EVERY {
        match outgoing.try_recv() {
            Ok(text) => socket.feed(Message::Text(text)).await?,
            Err(_) => break,
        }
    }
    socket.flush().await
}

async fn send_error(
    socket: &mut WebSocket,
    state: &AppState,
    e: &FrameError,
) -> Result<(), axum::Error> {
    state.metrics.frame_errors.fetch_add(1, Ordering::Relaxed);
    let text = serde_json::to_string(&ErrorEvent::from(e)).unwrap_or_default();
    socket.send(Message::Text(text.into())).await
}
