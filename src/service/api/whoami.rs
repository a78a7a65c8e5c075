//! `GET /api/v1/whoami`: the caller's token name and scopes, so the dashboard can
//! hide what the token may not do (docs/architecture.md §A5, §A10).

use axum::{Extension, Json};
use serde::Serialize;

use crate::service::tokens::{Principal, Scope};

/// The answer of `whoami`.
#[derive(Debug, Serialize)]
pub struct WhoAmI {
    /// The token's name (`default` for `--token`, `anonymous` on a server without tokens).
    pub name: String,
    /// Every scope the token may use (`admin` expanded to all four).
    pub scopes: Vec<Scope>,
    /// The session ids and `prefix*` patterns it is limited to; `null`: all sessions.
    pub sessions: Option<Vec<String>>,
    /// When it expires, Unix milliseconds; `null`: never.
    pub expires_ms: Option<i64>,
}

/// `GET /api/v1/whoami` (any valid token).
pub async fn whoami(principal: Option<Extension<Principal>>) -> Json<WhoAmI> {
    // The auth middleware always sets it; without it, the server has no tokens.
    let p = principal.map_or_else(Principal::anonymous, |Extension(p)| p);
    Json(WhoAmI {
        scopes: p.effective_scopes(),
        sessions: p.sessions.as_ref().map(|f| f.patterns()),
        expires_ms: p.expires_ms,
        name: p.name,
    })
}
