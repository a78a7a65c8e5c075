//! A minimal HTTP/1.1 client for the few REST calls `navguard replay` makes
//! (get or create a session, read its stats): one request per connection
//! (`Connection: close`), JSON bodies, bounded in time and size. The crate has
//! no HTTP client dependency and needs none for this.

use std::time::Duration;

use anyhow::{Context, bail};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::http::Uri;

/// Longest a REST call may take, connect to last byte.
const TIMEOUT: Duration = Duration::from_secs(15);
/// Largest response body read.
const MAX_RESPONSE_BYTES: usize = 32 << 20;

/// The navguard server `replay` talks to, derived from the `--url` it was given.
#[derive(Debug, Clone, PartialEq)]
pub struct Endpoint {
    /// Host name or address.
    pub host: String,
    /// TCP port.
    pub port: u16,
    /// Path prefix (empty, or `/prefix` without a trailing slash).
    pub prefix: String,
    /// Bearer token, if any.
    pub token: Option<String>,
}

impl Endpoint {
    /// Parses `ws://host[:port][/prefix]` (also `http://`). `wss`/`https` are
    /// refused: this build's client has no TLS.
    pub fn parse(url: &str, token: Option<String>) -> anyhow::Result<Self> {
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
    pub fn http_base(&self) -> String {
        format!("http://{}{}", self.authority(), self.prefix)
    }

    /// `ws://host:port/prefix{path}`.
    pub fn ws_url(&self, path: &str) -> String {
        format!("ws://{}{}{path}", self.authority(), self.prefix)
    }

    /// Sends one request and returns the status and body. Connection
    /// failures and timeouts are errors that name the server.
    pub async fn request(
        &self,
        method: &str,
        path: &str,
        body: Option<&serde_json::Value>,
    ) -> anyhow::Result<(u16, String)> {
        tokio::time::timeout(TIMEOUT, self.request_inner(method, path, body))
            .await
            .with_context(|| {
                format!(
                    "{method} {}{path}: no answer within {} s",
                    self.http_base(),
                    TIMEOUT.as_secs()
                )
            })?
    }

    async fn request_inner(
        &self,
        method: &str,
        path: &str,
        body: Option<&serde_json::Value>,
    ) -> anyhow::Result<(u16, String)> {
        let mut stream = TcpStream::connect((self.host.as_str(), self.port))
            .await
            .with_context(|| format!("cannot reach navguard at {}", self.http_base()))?;
        let body = body.map(|b| b.to_string()).unwrap_or_default();
        let mut head = format!(
            "{method} {}{path} HTTP/1.1\r\nHost: {}\r\nConnection: close\r\nAccept: application/json\r\nUser-Agent: navguard-replay\r\n",
            self.prefix,
            self.authority()
        );
        if let Some(token) = &self.token {
            head.push_str(&format!("Authorization: Bearer {token}\r\n"));
        }
        if method != "GET" {
            head.push_str(&format!(
                "Content-Type: application/json\r\nContent-Length: {}\r\n",
                body.len()
            ));
        }
        head.push_str("\r\n");
        stream.write_all(head.as_bytes()).await?;
        stream.write_all(body.as_bytes()).await?;
        stream.flush().await?;
        let mut raw = Vec::new();
        let mut chunk = [0u8; 16 * 1024];
        loop {
            let n = stream.read(&mut chunk).await?;
            if n == 0 {
                break;
            }
            raw.extend_from_slice(&chunk[..n]);
            if raw.len() > MAX_RESPONSE_BYTES {
                bail!("{method} {path}: response larger than {MAX_RESPONSE_BYTES} bytes");
            }
        }
        parse_response(&raw).with_context(|| format!("{method} {path}: bad HTTP response"))
    }
}

/// Splits a full HTTP/1.1 response into status and body (content-length,
/// chunked, or read-to-close).
fn parse_response(raw: &[u8]) -> anyhow::Result<(u16, String)> {
    let split = raw
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .context("no end of headers")?;
    let head = std::str::from_utf8(&raw[..split]).context("headers are not UTF-8")?;
    let rest = &raw[split + 4..];
    let mut lines = head.split("\r\n");
    let status_line = lines.next().context("no status line")?;
    let status: u16 = status_line
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .with_context(|| format!("bad status line {status_line:?}"))?;
    let mut chunked = false;
    let mut length = None;
    for line in lines {
        if let Some((name, value)) = line.split_once(':') {
            let value = value.trim();
            if name.eq_ignore_ascii_case("transfer-encoding") {
                chunked = value.eq_ignore_ascii_case("chunked");
            } else if name.eq_ignore_ascii_case("content-length") {
                length = value.parse::<usize>().ok();
            }
        }
    }
    let body = if chunked {
        dechunk(rest)?
    } else if let Some(n) = length {
        rest.get(..n)
            .context("body shorter than its Content-Length")?
            .to_vec()
    } else {
        rest.to_vec()
    };
    Ok((status, String::from_utf8_lossy(&body).into_owned()))
}

/// Decodes a chunked body (RFC 9112 §7.1), ignoring extensions and trailers.
fn dechunk(mut data: &[u8]) -> anyhow::Result<Vec<u8>> {
    let mut out = Vec::new();
    loop {
        let eol = data
            .windows(2)
            .position(|w| w == b"\r\n")
            .context("chunk size line not terminated")?;
        let line = std::str::from_utf8(&data[..eol])?;
        let size_text = line.split(';').next().unwrap_or("").trim();
        let size = usize::from_str_radix(size_text, 16)
            .with_context(|| format!("bad chunk size {size_text:?}"))?;
        data = &data[eol + 2..];
        if size == 0 {
            return Ok(out);
        }
        out.extend_from_slice(data.get(..size).context("chunk truncated")?);
        data = data.get(size + 2..).context("chunk not terminated")?;
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

    #[test]
    fn responses_parse_with_length_chunked_or_close() {
        let r = b"HTTP/1.1 201 Created\r\ncontent-length: 2\r\n\r\n{}extra";
        assert_eq!(parse_response(r).unwrap(), (201, "{}".to_owned()));
        let r = b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n4\r\n{\"a\"\r\n3;x=y\r\n:1}\r\n0\r\n\r\n";
        assert_eq!(parse_response(r).unwrap(), (200, "{\"a\":1}".to_owned()));
        let r = b"HTTP/1.1 404 Not Found\r\n\r\nnope";
        assert_eq!(parse_response(r).unwrap(), (404, "nope".to_owned()));
        assert!(parse_response(b"garbage").is_err());
    }
}
