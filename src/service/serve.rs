//! The HTTP edge below the router (docs/architecture.md §A13): accepts TCP
//! connections up to `--max-connections` (one more is answered with a JSON 503
//! and closed), serves each with hyper's HTTP/1 connection (a header-read
//! timeout, an idle timeout on request bodies, WebSocket upgrades) and shuts
//! down gracefully. `axum::serve` has no header timeout, so a client trickling
//! headers could hold a connection, and a file descriptor, for ever.

use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicI64, Ordering};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::Router;
use axum::body::Body;
use axum::extract::ConnectInfo;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, watch};
use tower::ServiceExt;
use tower_http::timeout::TimeoutBody;

use super::config::Limits;
use super::now_ms;

/// Refusals (503 `too_many_connections`) being written at once; beyond, a
/// connection over the limit is closed without an answer, so refusing cannot
/// itself exhaust file descriptors.
const MAX_REFUSALS: usize = 256;

/// How long a refusal may take to write its answer and see the client go.
const REFUSAL_TIME: Duration = Duration::from_secs(2);

/// Pause after an `accept` error (out of file descriptors, typically) so the
/// loop does not spin while the condition lasts.
const ACCEPT_ERROR_PAUSE: Duration = Duration::from_millis(50);

/// The connection settings of [`Limits`] the serving loop needs.
#[derive(Debug, Clone, Copy)]
pub(crate) struct EdgeLimits {
    max_connections: usize,
    header_timeout: Duration,
    idle_timeout: Duration,
}

impl From<&Limits> for EdgeLimits {
    fn from(l: &Limits) -> Self {
        EdgeLimits {
            max_connections: l.max_connections,
            header_timeout: l.header_timeout,
            idle_timeout: l.idle_timeout,
        }
    }
}

/// Serves `router` on `listener` until `shutdown` turns true, then stops
/// accepting, lets every connection finish its request (sockets close on
/// `shutdown` themselves) and returns when they have.
pub(crate) async fn serve(
    listener: TcpListener,
    router: Router,
    limits: EdgeLimits,
    mut shutdown: watch::Receiver<bool>,
) -> io::Result<()> {
    warn_if_file_limit_is_low(limits.max_connections);
    let permits = Arc::new(Semaphore::new(limits.max_connections));
    let refusals = Arc::new(Semaphore::new(MAX_REFUSALS));
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_timeout);
    // Each connection task holds a receiver; the loop waits for all of them.
    let (close_tx, close_rx) = watch::channel(());
    loop {
        let accepted = tokio::select! {
            accepted = listener.accept() => accepted,
            _ = stopped(&mut shutdown) => break,
        };
        let (stream, peer) = match accepted {
            Ok((stream, peer)) => {
                // Results and alarms are small writes that must go out at once:
                // with Nagle's algorithm, a write made while an earlier one awaits
                // its ACK waits for it, and a client's delayed ACK holds that up
                // to 40 ms (docs/performance.md, "Where the tail came from").
                if let Err(e) = stream.set_nodelay(true) {
                    tracing::debug!(error = %e, "TCP_NODELAY not set on an accepted socket");
                }
                (stream, peer)
            }
            Err(e) => {
                accept_error(&e);
                tokio::time::sleep(ACCEPT_ERROR_PAUSE).await;
                continue;
            }
        };
        match permits.clone().try_acquire_owned() {
            Ok(permit) => {
                let io = TokioIo::new(Counted {
                    stream,
                    _permit: permit,
                });
                let connection = serve_connection(
                    io,
                    peer,
                    &builder,
                    router.clone(),
                    limits.idle_timeout,
                    shutdown.clone(),
                );
                let close_rx = close_rx.clone();
                tokio::spawn(async move {
                    connection.await;
                    drop(close_rx);
                });
            }
            Err(_) => refuse(stream, &refusals, limits.max_connections),
        }
    }
    drop(close_rx);
    drop(listener);
    close_tx.closed().await;
    Ok(())
}

/// Resolves once the server shuts down (at once if it already has).
async fn stopped(shutdown: &mut watch::Receiver<bool>) {
    let _ = shutdown.wait_for(|stop| *stop).await;
}

/// One HTTP/1 connection: requests until the client leaves, a timeout fires or
/// an upgrade hands the socket to a WebSocket task (which keeps the permit).
fn serve_connection(
    io: TokioIo<Counted>,
    peer: SocketAddr,
    builder: &hyper::server::conn::http1::Builder,
    router: Router,
    idle_timeout: Duration,
    mut shutdown: watch::Receiver<bool>,
) -> impl Future<Output = ()> + Send + 'static {
    // A stalled request body fails after `idle_timeout` without data (the
    // handler's extractor answers 400 and hyper closes the connection). The peer's
    // address goes with every request, as `into_make_service_with_connect_info` would
    // give it (the audit log records it).
    let service = router.map_request(move |req: axum::http::Request<Incoming>| {
        let mut req = req.map(|body| Body::new(TimeoutBody::new(idle_timeout, body)));
        req.extensions_mut().insert(ConnectInfo(peer));
        req
    });
    let connection = builder
        .serve_connection(io, TowerToHyperService::new(service))
        .with_upgrades();
    async move {
        tokio::pin!(connection);
        let mut stopping = false;
        loop {
            tokio::select! {
                result = connection.as_mut() => {
                    if let Err(e) = result {
                        // Header timeouts, resets and parse errors: the client's doing.
                        tracing::debug!(error = %e, "connection closed");
                    }
                    break;
                }
                _ = stopped(&mut shutdown), if !stopping => {
                    stopping = true;
                    connection.as_mut().graceful_shutdown();
                }
            }
        }
    }
}

/// The JSON answer to a connection over the limit, written before closing it.
fn refusal(max_connections: usize) -> Vec<u8> {
    let body = serde_json::json!({"error": {
        "code": "too_many_connections",
        "message": format!(
            "the server has its {max_connections} connections open (--max-connections); retry later"
        ),
    }})
    .to_string();
    format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\n\
         content-length: {}\r\nretry-after: 1\r\nconnection: close\r\n\r\n{body}",
        body.len()
    )
    .into_bytes()
}

/// Answers a connection over the limit with 503 and closes it, off the accept loop.
fn refuse(mut stream: TcpStream, refusals: &Arc<Semaphore>, max_connections: usize) {
    warn_rate_limited(&LAST_LIMIT_WARNING, || {
        tracing::warn!(
            max_connections,
            "connection limit reached; refusing new connections with 503"
        );
    });
    let Ok(permit) = refusals.clone().try_acquire_owned() else {
        return; // dropping the stream closes it
    };
    tokio::spawn(async move {
        let _permit = permit;
        let _ = tokio::time::timeout(REFUSAL_TIME, async {
            stream.write_all(&refusal(max_connections)).await?;
            stream.shutdown().await?;
            // Read what the client sent until it leaves: closing a socket with
            // unread data resets the connection, and a reset may discard the
            // answer before the client has read it.
            let mut sink = [0u8; 1024];
            while stream.read(&mut sink).await? > 0 {}
            io::Result::Ok(())
        })
        .await;
    });
}

static LAST_LIMIT_WARNING: AtomicI64 = AtomicI64::new(0);
static LAST_ACCEPT_WARNING: AtomicI64 = AtomicI64::new(0);

/// Runs `log` at most once a second per `last` (an attack must not flood the log).
fn warn_rate_limited(last: &AtomicI64, log: impl FnOnce()) {
    let now = now_ms();
    let before = last.load(Ordering::Relaxed);
    if now - before >= 1000
        && last
            .compare_exchange(before, now, Ordering::Relaxed, Ordering::Relaxed)
            .is_ok()
    {
        log();
    }
}

fn accept_error(e: &io::Error) {
    // EMFILE / ENFILE: out of file descriptors. The listener stays usable;
    // connections wait in the backlog until descriptors are free again.
    warn_rate_limited(&LAST_ACCEPT_WARNING, || {
        tracing::warn!(error = %e, "accept failed; retrying");
    });
}

/// Logs at start when the process may open fewer files than `max_connections`
/// plus a margin for the store and the listener (Linux: `/proc/self/limits`).
fn warn_if_file_limit_is_low(max_connections: usize) {
    const MARGIN: u64 = 64;
    if let Some(limit) = open_file_limit()
        && limit < max_connections as u64 + MARGIN
    {
        tracing::warn!(
            open_file_limit = limit,
            max_connections,
            "the process may open only {limit} files (ulimit -n) but --max-connections is \
             {max_connections}: beyond about {} connections accept fails until some close; \
             raise ulimit -n or lower --max-connections",
            limit.saturating_sub(MARGIN)
        );
    }
}

/// The soft limit on open files, where the platform says.
fn open_file_limit() -> Option<u64> {
    let limits = std::fs::read_to_string("/proc/self/limits").ok()?;
    let line = limits.lines().find(|l| l.starts_with("Max open files"))?;
    line["Max open files".len()..]
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// A TCP stream that holds a connection permit until it is dropped, so a
/// socket upgraded to a WebSocket still counts against the limit.
struct Counted {
    stream: TcpStream,
    _permit: OwnedSemaphorePermit,
}

impl AsyncRead for Counted {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_read(cx, buf)
    }
}

impl AsyncWrite for Counted {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.stream).poll_write(cx, buf)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.stream).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.stream.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_refusal_is_a_complete_http_response_with_a_json_error() {
        let text = String::from_utf8(refusal(7)).unwrap();
        let (head, body) = text.split_once("\r\n\r\n").unwrap();
        assert!(head.starts_with("HTTP/1.1 503 "), "{head}");
        assert!(head.contains(&format!("content-length: {}", body.len())));
        let v: serde_json::Value = serde_json::from_str(body).unwrap();
        assert_eq!(v["error"]["code"], "too_many_connections");
        assert!(v["error"]["message"].as_str().unwrap().contains('7'));
    }

    #[test]
    fn the_open_file_limit_is_read_on_linux() {
        if cfg!(target_os = "linux") {
            assert!(open_file_limit().is_some_and(|n| n > 0));
        }
    }
}
