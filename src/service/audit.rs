//! The audit log's writer (docs/architecture.md §A5): a middleware on the `/api` routes,
//! inside the scope check, that appends one entry to the store's audit log for every
//! request that changes configuration or state and succeeds. Every method but `GET` is
//! such a change, except the computations of [`UNAUDITED`]. The handler says what it
//! changed by leaving a [`Change`] in its response's extensions; the middleware adds who
//! (the token's name), from where (the peer address, `X-Forwarded-For`), what (method,
//! route, path) and why (`X-Navguard-Reason`). A refused request (4xx, 5xx) writes nothing.

use std::net::SocketAddr;

use axum::extract::{ConnectInfo, MatchedPath, Request, State};
use axum::http::{HeaderMap, Method};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use serde_json::Value;

use super::app::AppState;
use super::error::ApiError;
use super::now_ms;
use super::store::AuditEntry;
use super::tokens::Principal;

/// Routes that take a body but change nothing (they compute an answer from it): not audited.
pub const UNAUDITED: &[(&str, &str)] = &[
    ("/api/v1/models/{id}/predict", "POST"),
    ("/api/v1/features", "POST"),
];

/// The request header that carries the caller's reason for a change.
pub const REASON_HEADER: &str = "x-navguard-reason";

/// Longest reason, characters (longer: 422).
pub const MAX_REASON_CHARS: usize = 500;

/// What a handler changed: left in its response's extensions (`Extension(change)` in
/// the handler's answer) for the audit entry.
#[derive(Debug, Clone, Default)]
pub struct Change {
    /// The session changed, if any.
    pub session: Option<String>,
    /// The value before (null when there was none: a creation).
    pub previous: Value,
    /// The value after (null when there is none: a deletion).
    pub new: Value,
}

/// True when `method` on the matched `route` is a change, recorded in the audit log.
pub fn audited(route: &str, method: &Method) -> bool {
    *method != Method::GET
        && *method != Method::HEAD
        && !UNAUDITED
            .iter()
            .any(|(r, m)| *r == route && *m == method.as_str())
}

/// The `X-Navguard-Reason` header: trimmed, `None` when absent or blank; 422 when longer
/// than [`MAX_REASON_CHARS`]. Its bytes are read as UTF-8, or, when they are not UTF-8,
/// as ISO-8859-1 (RFC 9110 §5.5: what a browser's `fetch` sends for `é`).
pub fn reason(headers: &HeaderMap) -> Result<Option<String>, ApiError> {
    let Some(value) = headers.get(REASON_HEADER) else {
        return Ok(None);
    };
    let bytes = value.as_bytes();
    let text = match std::str::from_utf8(bytes) {
        Ok(text) => text.to_owned(),
        Err(_) => bytes.iter().map(|&b| char::from(b)).collect(),
    };
    let text = text.trim();
    if text.chars().count() > MAX_REASON_CHARS {
        return Err(ApiError::invalid(
            "X-Navguard-Reason",
            format!("is longer than {MAX_REASON_CHARS} characters"),
        ));
    }
    Ok((!text.is_empty()).then(|| text.to_owned()))
}

/// Longest `X-Forwarded-For` kept, characters (the end is kept: a proxy appends).
const MAX_FORWARDED_CHARS: usize = 500;

/// Every `X-Forwarded-For` line in order, joined with `, ` as one list (HAProxy's
/// `option forwardfor` appends a line of its own after any the client sent), its last
/// [`MAX_FORWARDED_CHARS`] characters; `None` without one.
fn forwarded_for(headers: &HeaderMap) -> Option<String> {
    let lines: Vec<&str> = headers
        .get_all("x-forwarded-for")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .map(str::trim)
        .filter(|v| !v.is_empty())
        .collect();
    if lines.is_empty() {
        return None;
    }
    let list = lines.join(", ");
    let skip = list.chars().count().saturating_sub(MAX_FORWARDED_CHARS);
    Some(list.chars().skip(skip).collect())
}

/// The request's `X-Forwarded-For` list with its peer address appended, as a proxy
/// would: what a cluster node forwards with a request it hands to the session's owner.
pub fn forwarded_for_with_peer(
    headers: &HeaderMap,
    extensions: &axum::http::Extensions,
) -> Option<String> {
    let peer = extensions
        .get::<ConnectInfo<SocketAddr>>()
        .map(|c| c.0.ip().to_string());
    match (forwarded_for(headers), peer) {
        (Some(list), Some(peer)) => Some(format!("{list}, {peer}")),
        (list, peer) => list.or(peer),
    }
}

/// The `{id}` segment of a session route's path, as sent (the handler's [`Change`] names
/// the session otherwise).
fn session_in_path(path: &str) -> Option<String> {
    let rest = path.strip_prefix("/api/v1/sessions/")?;
    let id = rest.split('/').next()?;
    (!id.is_empty()).then(|| id.to_owned())
}

/// Middleware: runs the request and, when it was an audited change and succeeded,
/// appends its entry. A reason that is too long is refused (422) before the handler runs.
pub async fn record(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map(|p| p.as_str().to_owned())
        .unwrap_or_default();
    let method = req.method().clone();
    if !audited(&route, &method) {
        return next.run(req).await;
    }
    let reason = match reason(req.headers()) {
        Ok(r) => r,
        Err(e) => return e.into_response(),
    };
    let actor = req
        .extensions()
        .get::<Principal>()
        .map_or_else(|| Principal::anonymous().name, |p| p.name.clone());
    let client = req
        .extensions()
        .get::<ConnectInfo<SocketAddr>>()
        .map(|c| c.0.to_string());
    let forwarded_for = forwarded_for(req.headers());
    let path = req.uri().path().to_owned();
    let response = next.run(req).await;
    if !response.status().is_success() {
        return response;
    }
    let change = response
        .extensions()
        .get::<Change>()
        .cloned()
        .unwrap_or_default();
    let entry = AuditEntry {
        id: 0,
        at_ms: now_ms(),
        actor,
        client,
        forwarded_for,
        method: method.as_str().to_owned(),
        session: change.session.or_else(|| session_in_path(&path)),
        route,
        path,
        reason,
        previous: change.previous,
        new: change.new,
    };
    // The change is made and answered; a store that cannot take the entry is logged
    // (the same store just took the change, so this is a server fault, not the caller's).
    if let Err(e) = state.store.insert_audit(&entry).await {
        tracing::error!(error = %e, route = %entry.route, actor = %entry.actor, "audit entry not stored");
    }
    response
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::HeaderValue;

    #[test]
    fn only_changes_are_audited() {
        assert!(audited("/api/v1/sessions", &Method::POST));
        assert!(audited("/api/v1/sessions/{id}", &Method::DELETE));
        assert!(!audited("/api/v1/sessions/{id}", &Method::GET));
        assert!(!audited("/api/v1/features", &Method::POST));
        assert!(!audited("/api/v1/models/{id}/predict", &Method::POST));
    }

    #[test]
    fn forwarded_lines_are_one_list_ending_with_the_proxys() {
        let mut h = HeaderMap::new();
        assert_eq!(forwarded_for(&h), None);
        h.append("x-forwarded-for", HeaderValue::from_static("10.9.9.9"));
        h.append("x-forwarded-for", HeaderValue::from_static(" 192.0.2.7 "));
        assert_eq!(forwarded_for(&h).as_deref(), Some("10.9.9.9, 192.0.2.7"));
        let long = format!("{}, 192.0.2.7", "1".repeat(2 * MAX_FORWARDED_CHARS));
        h.insert("x-forwarded-for", HeaderValue::from_str(&long).unwrap());
        let kept = forwarded_for(&h).unwrap();
        assert_eq!(kept.chars().count(), MAX_FORWARDED_CHARS);
        assert!(kept.ends_with(", 192.0.2.7"));
    }

    #[test]
    fn a_reason_is_trimmed_and_limited() {
        let mut h = HeaderMap::new();
        assert_eq!(reason(&h).unwrap(), None);
        h.insert(REASON_HEADER, HeaderValue::from_static("  "));
        assert_eq!(reason(&h).unwrap(), None);
        h.insert(REASON_HEADER, HeaderValue::from_static(" raise p_fa "));
        assert_eq!(reason(&h).unwrap().as_deref(), Some("raise p_fa"));
        let utf8 = "é".repeat(MAX_REASON_CHARS);
        h.insert(
            REASON_HEADER,
            HeaderValue::from_bytes(utf8.as_bytes()).unwrap(),
        );
        assert_eq!(reason(&h).unwrap(), Some(utf8));
        let long = "x".repeat(MAX_REASON_CHARS + 1);
        h.insert(REASON_HEADER, HeaderValue::from_str(&long).unwrap());
        assert!(reason(&h).is_err());
        // Not UTF-8: ISO-8859-1, as a browser sends it.
        h.insert(REASON_HEADER, HeaderValue::from_bytes(b"caf\xe9").unwrap());
        assert_eq!(reason(&h).unwrap().as_deref(), Some("café"));
    }
}
