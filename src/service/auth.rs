//! Bearer-token authentication and scopes for `/api` (docs/architecture.md §A5). REST
//! takes `Authorization: Bearer TOKEN`; a WebSocket handshake on the two socket routes
//! may instead offer the subprotocol `bearer.TOKEN` (beside `navguard`) or a
//! `token` query parameter, since browsers cannot set headers on a WebSocket.
//! The query token is redacted wherever a request target is logged. Which scope each
//! route needs is the table of `access.rs`; the tokens are `tokens.rs`'s.

use axum::extract::{MatchedPath, Request, State};
use axum::http::header::{AUTHORIZATION, CONNECTION, SEC_WEBSOCKET_PROTOCOL, UPGRADE};
use axum::http::{Method, Uri};
use axum::middleware::Next;
use axum::response::Response;

use super::access::{self, Access, SessionRef};
use super::app::AppState;
use super::error::ApiError;
use super::tokens::{Lookup, Principal, Tokens};

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

/// Minimal percent-decoding for a token in a query string (`+` is a space).
fn percent_decode(s: &str) -> String {
    decode(s, true)
}

/// Percent-decoding of a path segment (`+` is itself), as the router decodes `{id}`.
fn decode_segment(s: &str) -> String {
    decode(s, false)
}

fn decode(s: &str, plus_is_space: bool) -> String {
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
            b'+' if plus_is_space => out.push(b' '),
            b => out.push(b),
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The caller of `req`: the first presented token that is known and in date; 401
/// when there is none.
fn authenticate(tokens: &Tokens, req: &Request) -> Result<(Principal, Credential), ApiError> {
    let now = super::now_ms();
    for secret in presented_tokens(req) {
        match tokens.lookup(&secret, now) {
            Lookup::Valid(p) => return Ok((p, Credential(secret))),
            // The name only: never the secret.
            Lookup::Expired(name) => tracing::info!(token = %name, "expired token refused"),
            Lookup::Unknown => {}
        }
    }
    Err(ApiError::Unauthorized)
}

/// The session ids `req` addresses, as `session_ref` says where they are; `None`
/// when it must name one and does not.
fn named_sessions(req: &Request, session_ref: SessionRef) -> Option<Vec<String>> {
    match session_ref {
        SessionRef::None | SessionRef::Listed => Some(Vec::new()),
        SessionRef::Path => {
            let rest = req.uri().path().strip_prefix("/api/v1/sessions/")?;
            let segment = rest.split('/').next()?;
            Some(vec![decode_segment(segment)])
        }
        SessionRef::Query => {
            let ids: Vec<String> = req
                .uri()
                .query()
                .unwrap_or_default()
                .split('&')
                .filter_map(|pair| pair.split_once('='))
                .filter(|(k, _)| percent_decode(k) == "session")
                .map(|(_, v)| percent_decode(v))
                .collect();
            (!ids.is_empty()).then_some(ids)
        }
    }
}

/// The secret a request authenticated with, for a call this node makes on the caller's
/// behalf to another node (an events socket's first statistics from the session's
/// owner). Never logged: its `Debug` prints no secret.
#[derive(Clone)]
pub struct Credential(String);

impl Credential {
    /// The `Authorization` header value that presents it.
    pub fn bearer(&self) -> String {
        format!("Bearer {}", self.0)
    }
}

impl std::fmt::Debug for Credential {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Credential(REDACTED)")
    }
}

/// Middleware: finds what the matched route needs (`access::access`), the caller
/// (401 without a valid token when the server has tokens), and refuses with 403 a
/// token without the scope, or limited to sessions the request does not name,
/// before the handler runs (so the answer is the same whether the session exists).
/// The handler finds the [`Principal`] in the request's extensions.
pub async fn authorize(
    State(state): State<AppState>,
    mut req: Request,
    next: Next,
) -> Result<Response, ApiError> {
    let path = req
        .extensions()
        .get::<MatchedPath>()
        .map(|p| p.as_str().to_owned())
        .unwrap_or_default();
    let (needs, session_ref) = access::access(&path, req.method().as_str());
    if needs == Access::Public {
        return Ok(next.run(req).await);
    }
    let principal = if state.tokens.required() {
        let (principal, credential) = authenticate(&state.tokens, &req)?;
        req.extensions_mut().insert(credential);
        principal
    } else {
        Principal::anonymous()
    };
    if let Access::Scope(scope) = needs {
        if !principal.allows(scope) {
            return Err(ApiError::Forbidden {
                scope,
                message: format!("token '{}' lacks the scope '{scope}'", principal.name),
            });
        }
        if principal.sessions.is_some() {
            let Some(ids) = named_sessions(&req, session_ref) else {
                return Err(ApiError::Forbidden {
                    scope,
                    message: format!(
                        "token '{}' is limited to some sessions: name one with ?session=ID",
                        principal.name
                    ),
                });
            };
            if let Some(id) = ids.iter().find(|id| !principal.allows_session(id)) {
                return Err(ApiError::Forbidden {
                    scope,
                    message: format!("token '{}' may not use session '{id}'", principal.name),
                });
            }
        }
    }
    req.extensions_mut().insert(principal);
    Ok(next.run(req).await)
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
    fn a_path_segment_keeps_its_plus_and_decodes_escapes() {
        assert_eq!(decode_segment("veh+1%2D2"), "veh+1-2");
        assert_eq!(percent_decode("veh+1"), "veh 1");
    }
}
