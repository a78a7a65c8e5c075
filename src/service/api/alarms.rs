//! `GET /api/v1/alarms`: the persisted alarm log, newest first, with filters and a cursor.

use axum::Json;
use axum::extract::State;
use serde::{Deserialize, Serialize};

use crate::service::app::AppState;
use crate::service::error::ApiError;
use crate::service::extract::{ApiQuery, query_integer_opt};
use crate::service::store::AlarmQuery;
use crate::service::wire::{AlarmRecord, Severity};

/// Default and largest page size.
const DEFAULT_LIMIT: i64 = 100;
const MAX_LIMIT: i64 = 1000;

/// Query string.
#[derive(Debug, Deserialize)]
pub struct AlarmsQuery {
    session: Option<String>,
    monitor: Option<String>,
    /// Raised at or after, Unix ms.
    #[serde(default, deserialize_with = "query_integer_opt")]
    since: Option<i64>,
    /// Raised before, Unix ms.
    #[serde(default, deserialize_with = "query_integer_opt")]
    until: Option<i64>,
    /// Only ids below this (the `next_before` of the previous page).
    #[serde(default, deserialize_with = "query_integer_opt")]
    before: Option<i64>,
    /// Only ids above this (catch up after a reconnect: the newest id seen).
    #[serde(default, deserialize_with = "query_integer_opt")]
    after: Option<i64>,
    /// Only `alarm` or only `warning` entries (default both).
    severity: Option<Severity>,
    #[serde(default, deserialize_with = "query_integer_opt")]
    limit: Option<i64>,
}

/// A page of the log.
#[derive(Debug, Serialize)]
pub struct AlarmPage {
    alarms: Vec<AlarmRecord>,
    /// Pass as `before` for the next (older) page; `null` when this page is
    /// shorter than `limit` (a full last page leads to one empty page).
    next_before: Option<i64>,
}

/// `GET /api/v1/alarms?session=&monitor=&since=&until=&before=&after=&severity=&limit=`
pub async fn list(
    State(state): State<AppState>,
    ApiQuery(q): ApiQuery<AlarmsQuery>,
) -> Result<Json<AlarmPage>, ApiError> {
    let limit = q.limit.unwrap_or(DEFAULT_LIMIT);
    if !(1..=MAX_LIMIT).contains(&limit) {
        return Err(ApiError::invalid(
            "limit",
            format!("must be between 1 and {MAX_LIMIT}"),
        ));
    }
    let query = AlarmQuery {
        session: q.session,
        monitor: q.monitor,
        since_ms: q.since,
        until_ms: q.until,
        before_id: q.before,
        after_id: q.after,
        severity: q.severity,
        limit,
    };
    let alarms = state.store.alarms(&query).await?;
    let next_before = if alarms.len() as i64 == limit {
        alarms.last().map(|a| a.id)
    } else {
        None
    };
    Ok(Json(AlarmPage {
        alarms,
        next_before,
    }))
}
