//! Bearer-token authentication for `/api` (docs/architecture.md §A5). REST takes
//! `Authorization: Bearer TOKEN`; a WebSocket handshake on the two socket routes
//! may instead offer the subprotocol `bearer.TOKEN` (beside `navguard`) or a
//! `token` query parameter, since browsers cannot set headers on a WebSocket.
//! The query token is redacted wherever a request target is logged.

use axum::extract::{MatchedPath, Request, State};
use axum::http::header::{AUTHORIZATION, CONNECTION, SEC_WEBSOCKET_PROTOCOL, UPGRADE};
use axum::http::{Method, Uri};
use axum::middleware::Next;
use axum::response::Response;

use super::app::AppState;
use super::error::ApiError;

/// Compares in time independent of where the strings differ.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// The two socket routes, as the router matches them.
pub const SOCKET_ROUTES: [&str; 2] = [
    "/api/v1/sessions/{id}/ingest",
    "/api/v1/sessions/{id}/events",
];

/// True for a real WebSocket handshake on a socket route: `GET`, `Upgrade:
/// websocket` and `Connection: upgrade` (RFC 6455 §4.1), routed to ingest or
/// events. Only these may carry the socket-only credentials (the `token` query
/// parameter and the `bearer.TOKEN` subprotocol), so a query token is never a
/// way into a REST route.
fn is_socket_handshake(req: &Request) -> bool {
    let headers = req.headers();
    let upgrade = headers
        .get(UPGRADE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.trim().eq_ignore_ascii_case("websocket"));
    let connection = headers
        .get_all(CONNECTION)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|option| option.trim().eq_ignore_ascii_case("upgrade"));
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .is_some_and(|p| SOCKET_ROUTES.contains(&p.as_str()));
    req.method() == Method::GET && upgrade && connection && route
}

fn presented_tokens(req: &Request) -> Vec<String> {
    let mut tokens = Vec::new();
    let headers = req.headers();
    // RFC 9110 §11.1: the scheme name is case-insensitive.
    if let Some(value) = headers.get(AUTHORIZATION).and_then(|v| v.to_str().ok())
        && let Some((scheme, token)) = value.split_once(' ')
        && scheme.eq_ignore_ascii_case("bearer")
    {
        tokens.push(token.trim().to_owned());
    }
    if is_socket_handshake(req) {
        if let Some(protocols) = headers
            .get(SEC_WEBSOCKET_PROTOCOL)
            .and_then(|v| v.to_str().ok())
        {
            tokens.extend(
                protocols
                    .split(',')
                    .filter_map(|p| p.trim().strip_prefix("bearer."))
                    .map(str::to_owned),
            );
        }
        if let Some(query) = req.uri().query() {
            tokens.extend(
                query
                    .split('&')
                    .filter_map(|pair| pair.strip_prefix("token="))
                    .map(percent_decode),
            );
        }
    }
    tokens
}

/// The request target with the value of every `token` query parameter replaced
/// by `REDACTED`, for logs and spans (the token must never reach a log line).
pub fn redacted_uri(uri: &Uri) -> String {
    let Some(query) = uri.query() else {
        return uri.to_string();
    };
    let query: Vec<String> = query
        .split('&')
        .map(|pair| {
            let key = pair.split_once('=').map_or(pair, |(k, _)| k);
            // Any spelling the decoder would read as `token` (`%74oken`, `Token`).
            if percent_decode(key).eq_ignore_ascii_case("token") {
                format!("{key}=REDACTED")
            } else {
                pair.to_owned()
            }
        })
        .collect();
    let mut out = String::new();
    if let (Some(scheme), Some(authority)) = (uri.scheme_str(), uri.authority()) {
        out.push_str(&format!("{scheme}://{authority}"));
    }
    out.push_str(uri.path());
    out.push('?');
    out.push_str(&query.join("&"));
    out
}

/// Minimal percent-decoding for a token in a query string.
fn percent_decode(s: &str) -> String {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| (b as char).to_digit(16);
        match bytes[i] {
            b'%' if i + 2 < bytes.len() => match (hex(bytes[i + 1]), hex(bytes[i + 2])) {
                (Some(hi), Some(lo)) => {
                    out.push((hi * 16 + lo) as u8);
                    i += 3;
                    continue;
                }
                _ => out.push(b'%'),
            },
            b'+' => out.push(b' '),
            b => out.push(b),
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Middleware: passes the request on when no token is configured or a
/// presented token matches; otherwise 401.
pub async fn require_token(
    State(state): State<AppState>,
    req: Request,
    next: Next,
) -> Result<Response, ApiError> {
    let Some(expected) = state.config.token.as_deref() else {
        return Ok(next.run(req).await);
    };
    if presented_tokens(&req)
        .iter()
        .any(|t| constant_time_eq(t.as_bytes(), expected.as_bytes()))
    {
        Ok(next.run(req).await)
    } else {
        Err(ApiError::Unauthorized)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percent_decoding_handles_escapes_and_plain_text() {
        assert_eq!(percent_decode("abc"), "abc");
        assert_eq!(percent_decode("a%2Fb%3d"), "a/b=");
        assert_eq!(percent_decode("bad%zz"), "bad%zz");
        assert_eq!(percent_decode("end%4"), "end%4");
        assert_eq!(percent_decode("é%é"), "é%é");
    }

    #[test]
    fn token_query_values_are_redacted_and_the_rest_kept() {
        let uri: Uri = "/api/v1/sessions/a/events?x=1&token=s3cret&%74oken=two&Token=3&tokens=ok"
            .parse()
            .unwrap();
        assert_eq!(
            redacted_uri(&uri),
            "/api/v1/sessions/a/events?x=1&token=REDACTED&%74oken=REDACTED&Token=REDACTED&tokens=ok"
        );
        let bare: Uri = "/healthz".parse().unwrap();
        assert_eq!(redacted_uri(&bare), "/healthz");
        let full: Uri = "http://h:1/p?token".parse().unwrap();
        assert_eq!(redacted_uri(&full), "http://h:1/p?token=REDACTED");
    }

    #[test]
    fn constant_time_comparison_is_equality() {
        assert!(constant_time_eq(b"secret", b"secret"));
        assert!(!constant_time_eq(b"secret", b"secreT"));
        assert!(!constant_time_eq(b"secret", b"secrets"));
    }
}
