//! `GET /api/v1/alarms`: the persisted alarm log, newest first, with filters and a cursor,
//! each entry with its acknowledgement; `POST …/alarms/{alarm_id}/ack`: a person
//! acknowledges an entry.

use axum::extract::{Path, State};
use axum::{Extension, Json};
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::service::app::AppState;
use crate::service::audit::Change;
use crate::service::error::ApiError;
use crate::service::extract::{ApiQuery, JsonBody, from_value, query_integer_opt, refuse_nulls};
use crate::service::now_ms;
use crate::service::store::{AckOutcome, AlarmAck, AlarmQuery, LoggedAlarm};
use crate::service::tokens::Principal;
use crate::service::wire::Severity;

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
    alarms: Vec<LoggedAlarm>,
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
    let alarms = state.store.alarm_log(&query).await?;
    let next_before = if alarms.len() as i64 == limit {
        alarms.last().map(|a| a.record.id)
    } else {
        None
    };
    Ok(Json(AlarmPage {
        alarms,
        next_before,
    }))
}

/// Longest acknowledgement comment, characters.
pub const MAX_COMMENT_CHARS: usize = 500;

/// The body of an acknowledgement.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct AckBody {
    /// What was found or done (required, not blank).
    comment: String,
}

/// `POST /api/v1/sessions/{id}/alarms/{alarm_id}/ack {"comment"}` → 200 with the entry and
/// its acknowledgement; 404 for an id that names no entry of the session, 409 when the
/// entry is already acknowledged. The audit entry holds the entry before and after.
pub async fn ack(
    State(state): State<AppState>,
    Path((session, alarm_id)): Path<(String, String)>,
    principal: Option<Extension<Principal>>,
    JsonBody(body): JsonBody,
) -> Result<(Extension<Change>, Json<LoggedAlarm>), ApiError> {
    let missing = || {
        ApiError::NotFound(format!(
            "no alarm-log entry '{alarm_id}' in session '{session}'"
        ))
    };
    let id: i64 = alarm_id.parse().map_err(|_| missing())?;
    refuse_nulls(&body)?;
    let AckBody { comment } = from_value(body)?;
    // The limit counts the comment as sent (the contract's maxLength); it is stored trimmed.
    if comment.chars().count() > MAX_COMMENT_CHARS {
        return Err(ApiError::invalid(
            "comment",
            format!("is longer than {MAX_COMMENT_CHARS} characters"),
        ));
    }
    let comment = comment.trim();
    if comment.is_empty() {
        return Err(ApiError::invalid("comment", "must not be blank"));
    }
    let ack = AlarmAck {
        acked_by: principal.map_or_else(|| Principal::anonymous().name, |Extension(p)| p.name),
        acked_at_ms: now_ms(),
        ack_comment: comment.to_owned(),
    };
    match state.store.ack_alarm(&session, id, &ack).await? {
        AckOutcome::Acked(entry) => {
            let change = Change {
                session: Some(session.clone()),
                previous: json!(entry.unacked()),
                new: json!(entry),
            };
            Ok((Extension(change), Json(entry)))
        }
        AckOutcome::Already(entry) => Err(ApiError::Conflict(format!(
            "alarm-log entry {id} of session '{session}' was acknowledged by '{}' at {} ms",
            entry.acked_by.unwrap_or_default(),
            entry.acked_at_ms.unwrap_or_default()
        ))),
        AckOutcome::Missing => Err(missing()),
    }
}
