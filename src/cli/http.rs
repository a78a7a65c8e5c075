//! The client side shared by `navguard replay` and `navguard loadgen`: the
//! URL handling, REST calls through one reqwest client (bounded in time), and
//! opening an ingest socket up to its `ready` message.

use std::sync::OnceLock;
use std::time::Duration;

use anyhow::{Context, bail};
use futures_util::StreamExt;
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::{HeaderValue, Uri};
use tokio_tungstenite::tungstenite::{self, Message};
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

/// Longest a REST call may take, connect to last byte.
const TIMEOUT: Duration = Duration::from_secs(15);
/// Longest wait for a socket to open and say `ready`.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);

/// The client socket's read buffer: the protocol layer zero-fills it before
/// every read, so the 128 KiB default costs more than the messages themselves.
const READ_BUFFER_BYTES: usize = 8 << 10;

fn socket_config() -> tungstenite::protocol::WebSocketConfig {
    tungstenite::protocol::WebSocketConfig::default().read_buffer_size(READ_BUFFER_BYTES)
}

/// A client WebSocket to the server.
pub(crate) type Socket = WebSocketStream<MaybeTlsStream<TcpStream>>;

/// The navguard server a tool talks to, derived from the `--url` it was given.
#[derive(Debug, Clone)]
pub(crate) struct Endpoint {
    /// Host name or address.
    pub host: String,
    /// TCP port.
    pub port: u16,
    /// Path prefix (empty, or `/prefix` without a trailing slash).
    pub prefix: String,
    /// Bearer token, if any.
    pub token: Option<String>,
    /// One HTTP client (and its connection pool) for every REST call.
    client: OnceLock<reqwest::Client>,
}

impl Endpoint {
    /// Parses `ws://host[:port][/prefix]` (also `http://`). `wss`/`https` are
    /// refused: this build's client has no TLS.
    pub(crate) fn parse(url: &str, token: Option<String>) -> anyhow::Result<Self> {
        let uri: Uri = url
            .parse()
            .with_context(|| format!("--url {url:?} is not a URL"))?;
        let scheme = uri.scheme_str().unwrap_or("");
        let default_port = match scheme {
            "ws" | "http" => 80,
            "wss" | "https" => bail!(
                "--url {url}: TLS is not supported by this client; use ws:// (behind a TLS proxy, replay from the same host)"
            ),
            _ => bail!("--url {url}: expected ws://host:port"),
        };
        let host = uri
            .host()
            .with_context(|| format!("--url {url} has no host"))?
            .trim_start_matches('[')
            .trim_end_matches(']')
            .to_owned();
        let prefix = uri.path().trim_end_matches('/').to_owned();
        Ok(Endpoint {
            host,
            port: uri.port_u16().unwrap_or(default_port),
            prefix,
            token: token.filter(|t| !t.is_empty()),
            client: OnceLock::new(),
        })
    }

    fn authority(&self) -> String {
        if self.host.contains(':') {
            format!("[{}]:{}", self.host, self.port)
        } else {
            format!("{}:{}", self.host, self.port)
        }
    }

    /// `http://host:port/prefix`, for messages.
    pub(crate) fn http_base(&self) -> String {
        format!("http://{}{}", self.authority(), self.prefix)
    }

    /// `ws://host:port/prefix{path}`.
    pub(crate) fn ws_url(&self, path: &str) -> String {
        format!("ws://{}{}{path}", self.authority(), self.prefix)
    }

    /// Sends a bodiless request (`GET`, `DELETE`) and returns the status and body.
    pub(crate) async fn call(&self, method: &str, path: &str) -> anyhow::Result<(u16, String)> {
        self.request::<()>(method, path, None).await
    }

    /// Sends one request with an optional JSON body (one of the service's own
    /// wire types) and returns the status and body. Connection failures and
    /// timeouts are errors that name the server.
    pub(crate) async fn request<B: serde::Serialize + ?Sized>(
        &self,
        method: &str,
        path: &str,
        body: Option<&B>,
    ) -> anyhow::Result<(u16, String)> {
        let url = format!("{}{path}", self.http_base());
        let method = reqwest::Method::from_bytes(method.as_bytes())
            .with_context(|| format!("bad HTTP method {method:?}"))?;
        let client = match self.client.get() {
            Some(client) => client,
            None => {
                let built = reqwest::Client::builder()
                    .timeout(TIMEOUT)
                    .user_agent("navguard-cli")
                    .build()
                    .context("building the HTTP client")?;
                self.client.get_or_init(|| built)
            }
        };
        let mut request = client.request(method.clone(), &url);
        if let Some(token) = &self.token {
            request = request.bearer_auth(token);
        }
        if let Some(body) = body {
            request = request.json(body);
        }
        let response = request
            .send()
            .await
            .with_context(|| format!("cannot reach navguard at {}", self.http_base()))?;
        let status = response.status().as_u16();
        let text = response
            .text()
            .await
            .with_context(|| format!("{method} {url}: reading the answer"))?;
        Ok((status, text))
    }

    /// Opens the socket at `path` (offering the `navguard` subprotocol and the
    /// token) and waits for the server's `ready` message.
    pub(crate) async fn connect(&self, path: &str) -> anyhow::Result<Socket> {
        Ok(self.connect_ready(path).await?.0)
    }

    /// [`Endpoint::connect`], also giving the server's `ready` message.
    pub(crate) async fn connect_ready(
        &self,
        path: &str,
    ) -> anyhow::Result<(Socket, serde_json::Value)> {
        let url = self.ws_url(path);
        let mut request = url.as_str().into_client_request()?;
        request.headers_mut().insert(
            "Sec-WebSocket-Protocol",
            HeaderValue::from_static("navguard"),
        );
        if let Some(token) = &self.token {
            request.headers_mut().insert(
                "Authorization",
                HeaderValue::from_str(&format!("Bearer {token}"))?,
            );
        }
        let (mut socket, _) = tokio::time::timeout(
            CONNECT_TIMEOUT,
            // `true`: TCP_NODELAY, so small frames are not held back by Nagle's algorithm.
            tokio_tungstenite::connect_async_with_config(request, Some(socket_config()), true),
        )
        .await
        .with_context(|| format!("{url}: no WebSocket handshake within 10 s"))?
        .map_err(|e| match e {
            tungstenite::Error::Http(response) => {
                let body = response
                    .body()
                    .as_deref()
                    .map(String::from_utf8_lossy)
                    .unwrap_or_default()
                    .into_owned();
                anyhow::anyhow!("{url}: HTTP {}: {body}", response.status())
            }
            e => anyhow::anyhow!("cannot open the ingest socket {url}: {e}"),
        })?;
        let ready = tokio::time::timeout(CONNECT_TIMEOUT, async {
            while let Some(message) = socket.next().await {
                match message? {
                    Message::Text(text) => return Ok(Some(text.to_string())),
                    Message::Close(frame) => bail!("the server closed the socket: {frame:?}"),
                    _ => continue,
                }
            }
            Ok(None)
        })
        .await
        .context("no `ready` from the server within 10 s")??;
        match ready {
            Some(text) if text.contains("\"ready\"") => {
                Ok((socket, serde_json::from_str(&text).unwrap_or_default()))
            }
            Some(text) => bail!("expected `ready` from the server, got {text}"),
            None => bail!("the server closed the socket before `ready`"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ws_urls_give_host_port_and_prefix() {
        let e = Endpoint::parse("ws://127.0.0.1:8080", Some("t".into())).unwrap();
        assert_eq!(
            (e.host.as_str(), e.port, e.prefix.as_str()),
            ("127.0.0.1", 8080, "")
        );
        assert_eq!(e.ws_url("/api/v1/x"), "ws://127.0.0.1:8080/api/v1/x");
        let e = Endpoint::parse("ws://[::1]:9/nav/", None).unwrap();
        assert_eq!(
            (e.host.as_str(), e.port, e.prefix.as_str()),
            ("::1", 9, "/nav")
        );
        assert_eq!(e.http_base(), "http://[::1]:9/nav");
        assert!(Endpoint::parse("wss://x:1", None).is_err());
        assert!(Endpoint::parse("127.0.0.1:8080", None).is_err());
    }
}

/// A message the server sends on an ingest socket, read through the service's
/// own wire types (so a change to them breaks this at compile time).
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub(crate) enum ServerEvent {
    /// A test moved into suspect or isolated.
    Alarm(navguard::service::wire::AlarmRecord),
    /// A test changed health (the tools only count these; the body is parsed
    /// so that a change to the service's type is caught here).
    #[allow(dead_code)]
    State(navguard::service::wire::StateChange),
    /// A frame was refused.
    Error(RefusedFrame),
    /// One epoch's result (`echo` sessions).
    Result,
    /// Anything else (`ready`, `stats`, …).
    #[serde(other)]
    Other,
}

/// The `error` event's fields, owned (the service's `ErrorEvent` borrows).
#[derive(Debug, Clone, serde::Deserialize)]
pub(crate) struct RefusedFrame {
    /// Stable code (`time_backwards`, `numerical`, …).
    pub code: String,
    /// Reason.
    pub message: String,
}
