//! `GET /api/v1/audit`: the audit log (who changed what, when, from where and why),
//! newest first, with filters and a cursor. A token limited to some sessions sees only
//! the entries about those sessions.

use axum::extract::State;
use axum::{Extension, Json};
use serde::{Deserialize, Serialize};

use crate::service::app::AppState;
use crate::service::error::ApiError;
use crate::service::extract::{ApiQuery, query_integer_opt};
use crate::service::store::{AuditEntry, AuditQuery, SessionPattern};
use crate::service::tokens::{Principal, Scope};

/// Default and largest page size.
const DEFAULT_LIMIT: i64 = 100;
const MAX_LIMIT: i64 = 1000;

/// Query string.
#[derive(Debug, Deserialize)]
pub struct AuditParams {
    /// Only entries about this session.
    session: Option<String>,
    /// At or after, Unix ms.
    #[serde(default, deserialize_with = "query_integer_opt")]
    since: Option<i64>,
    /// Only this token's changes.
    actor: Option<String>,
    /// Only ids below this (the `next_before` of the previous page).
    #[serde(default, deserialize_with = "query_integer_opt")]
    before: Option<i64>,
    #[serde(default, deserialize_with = "query_integer_opt")]
    limit: Option<i64>,
}

/// A page of the audit log.
#[derive(Debug, Serialize)]
pub struct AuditPage {
    entries: Vec<AuditEntry>,
    /// Pass as `before` for the next (older) page; `null` when this page is shorter than
    /// `limit`.
    next_before: Option<i64>,
}

/// `GET /api/v1/audit?session=&since=&actor=&before=&limit=`
pub async fn list(
    State(state): State<AppState>,
    principal: Option<Extension<Principal>>,
    ApiQuery(q): ApiQuery<AuditParams>,
) -> Result<Json<AuditPage>, ApiError> {
    let limit = q.limit.unwrap_or(DEFAULT_LIMIT);
    if !(1..=MAX_LIMIT).contains(&limit) {
        return Err(ApiError::invalid(
            "limit",
            format!("must be between 1 and {MAX_LIMIT}"),
        ));
    }
    let visible = principal
        .as_ref()
        .and_then(|Extension(p)| p.sessions.as_ref())
        .map(|filter| {
            filter
                .patterns()
                .into_iter()
                .map(|p| match p.strip_suffix('*') {
                    Some(prefix) => SessionPattern::Prefix(prefix.to_owned()),
                    None => SessionPattern::Exact(p),
                })
                .collect()
        });
    if let (Some(Extension(p)), Some(id)) = (&principal, &q.session)
        && !p.allows_session(id)
    {
        return Err(ApiError::Forbidden {
            scope: Scope::Read,
            message: format!("token '{}' may not use session '{id}'", p.name),
        });
    }
    let query = AuditQuery {
        session: q.session,
        since_ms: q.since,
        actor: q.actor,
        before_id: q.before,
        visible,
        limit,
    };
    let entries = state.store.audit(&query).await?;
    let next_before = if entries.len() as i64 == limit {
        entries.last().map(|e| e.id)
    } else {
        None
    };
    Ok(Json(AuditPage {
        entries,
        next_before,
    }))
}
