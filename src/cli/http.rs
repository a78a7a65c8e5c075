//! The REST side of `navguard replay` (get or create a session, read its
//! stats) through reqwest, bounded in time, and the URL handling shared with
//! the socket side.

use std::time::Duration;

use anyhow::{Context, bail};
use tokio_tungstenite::tungstenite::http::Uri;

/// Longest a REST call may take, connect to last byte.
const TIMEOUT: Duration = Duration::from_secs(15);

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
        let url = format!("{}{path}", self.http_base());
        let method = reqwest::Method::from_bytes(method.as_bytes())
            .with_context(|| format!("bad HTTP method {method:?}"))?;
        let client = reqwest::Client::builder()
            .timeout(TIMEOUT)
            .user_agent("navguard-replay")
            .build()
            .context("building the HTTP client")?;
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
