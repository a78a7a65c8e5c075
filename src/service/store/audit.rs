//! The audit log and alarm acknowledgements (docs/architecture.md §A4): who changed what
//! through the API, when, from where and why, and who acknowledged which alarm-log entry.
//! Entries are written by `service::audit` after a change succeeded; like the alarm log
//! they are kept for ever.

use serde::Serialize;
use serde_json::Value;

use super::{Pool, StoreError};
use crate::service::wire::AlarmRecord;

/// One entry of the audit log.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AuditEntry {
    /// Store id (increasing; 0 before it is stored).
    pub id: i64,
    /// When the change was answered, Unix ms.
    pub at_ms: i64,
    /// The token's name (`default` for `--token`, `anonymous` without tokens).
    pub actor: String,
    /// The connection's peer address (`ip:port`); null when the request did not come
    /// over a connection of this node (forwarded by another cluster node).
    pub client: Option<String>,
    /// The `X-Forwarded-For` lines as the request carried them, as one list (a load
    /// balancer's `option forwardfor` appends the caller's address), recorded as given:
    /// it is whatever the peer said.
    pub forwarded_for: Option<String>,
    /// The HTTP method.
    pub method: String,
    /// The route as the router matched it (`/api/v1/sessions/{id}`).
    pub route: String,
    /// The request's path (`/api/v1/sessions/cart-1`).
    pub path: String,
    /// The session the change was about, if any.
    pub session: Option<String>,
    /// The `X-Navguard-Reason` header, if given.
    pub reason: Option<String>,
    /// The value before the change (JSON; null when there was none).
    pub previous: Value,
    /// The value after the change (JSON; null when the thing was deleted).
    pub new: Value,
}

/// Which sessions a session-limited token may see: ids and prefixes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SessionPattern {
    /// This id.
    Exact(String),
    /// Every id starting with this.
    Prefix(String),
}

/// Filters for the audit log.
#[derive(Debug, Clone, Default)]
pub struct AuditQuery {
    /// Only this session.
    pub session: Option<String>,
    /// Only entries at or after this time, Unix ms.
    pub since_ms: Option<i64>,
    /// Only this token's entries.
    pub actor: Option<String>,
    /// Only entries with an id below this (pagination cursor).
    pub before_id: Option<i64>,
    /// Only entries about these sessions (a session-limited token); `None`: every entry.
    pub visible: Option<Vec<SessionPattern>>,
    /// At most this many, newest first.
    pub limit: i64,
}

/// A person's acknowledgement of an alarm-log entry.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AlarmAck {
    /// The token's name.
    pub acked_by: String,
    /// When, Unix ms.
    pub acked_at_ms: i64,
    /// Why, or what was done about it.
    pub ack_comment: String,
}

/// An alarm-log entry as `GET /api/v1/alarms` shows it: the entry and its
/// acknowledgement (null fields until acknowledged).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LoggedAlarm {
    /// The entry.
    #[serde(flatten)]
    pub record: AlarmRecord,
    /// Who acknowledged it.
    pub acked_by: Option<String>,
    /// When, Unix ms.
    pub acked_at_ms: Option<i64>,
    /// The acknowledgement's comment.
    pub ack_comment: Option<String>,
}

impl LoggedAlarm {
    /// The entry as it was before its acknowledgement.
    pub fn unacked(&self) -> LoggedAlarm {
        LoggedAlarm {
            record: self.record.clone(),
            acked_by: None,
            acked_at_ms: None,
            ack_comment: None,
        }
    }
}

/// What an acknowledgement found.
#[derive(Debug, Clone, PartialEq)]
pub enum AckOutcome {
    /// Acknowledged now: the entry with its acknowledgement.
    Acked(LoggedAlarm),
    /// Acknowledged before: the entry with that first acknowledgement.
    Already(LoggedAlarm),
    /// No such entry in that session.
    Missing,
}

const AUDIT_COLUMNS: &str = "id, at_ms, actor, client, forwarded_for, method, route, path, session, reason, previous_value, new_value";

/// An `audit_log` row in the order of [`AUDIT_COLUMNS`].
type AuditRow = (
    i64,
    i64,
    String,
    Option<String>,
    Option<String>,
    String,
    String,
    String,
    Option<String>,
    Option<String>,
    String,
    String,
);

fn json(text: &str) -> Result<Value, StoreError> {
    serde_json::from_str(text).map_err(|e| StoreError::Corrupt(format!("audit value: {e}")))
}

fn entry_from_row(row: AuditRow) -> Result<AuditEntry, StoreError> {
    let (id, at_ms, actor, client, forwarded_for, method, route, path, session, reason, p, n) = row;
    Ok(AuditEntry {
        id,
        at_ms,
        actor,
        client,
        forwarded_for,
        method,
        route,
        path,
        session,
        reason,
        previous: json(&p)?,
        new: json(&n)?,
    })
}

/// Appends `entry` (its `id` ignored); returns the new id.
pub(super) async fn insert(pool: &Pool, entry: &AuditEntry) -> Result<i64, StoreError> {
    let previous = entry.previous.to_string();
    let new = entry.new.to_string();
    let id: i64 = with_pool!(pool, p => sqlx::query_scalar(
        "INSERT INTO audit_log (at_ms, actor, client, forwarded_for, method, route, path, session, reason, previous_value, new_value) \
         VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11) RETURNING id",
    )
    .bind(entry.at_ms)
    .bind(&entry.actor)
    .bind(&entry.client)
    .bind(&entry.forwarded_for)
    .bind(&entry.method)
    .bind(&entry.route)
    .bind(&entry.path)
    .bind(&entry.session)
    .bind(&entry.reason)
    .bind(&previous)
    .bind(&new)
    .fetch_one(p)
    .await?);
    Ok(id)
}

/// A bound value of the audit query.
enum Param<'a> {
    Text(&'a str),
    Int(i64),
    Len(i32),
}

/// The audit log, newest first.
pub(super) async fn query(pool: &Pool, q: &AuditQuery) -> Result<Vec<AuditEntry>, StoreError> {
    let mut sql = format!("SELECT {AUDIT_COLUMNS} FROM audit_log WHERE 1 = 1");
    let mut params: Vec<Param<'_>> = Vec::new();
    let next = |params: &Vec<Param<'_>>| params.len() + 1;
    if let Some(s) = &q.session {
        sql.push_str(&format!(" AND session = ${}", next(&params)));
        params.push(Param::Text(s));
    }
    if let Some(v) = q.since_ms {
        sql.push_str(&format!(" AND at_ms >= ${}", next(&params)));
        params.push(Param::Int(v));
    }
    if let Some(a) = &q.actor {
        sql.push_str(&format!(" AND actor = ${}", next(&params)));
        params.push(Param::Text(a));
    }
    if let Some(v) = q.before_id {
        sql.push_str(&format!(" AND id < ${}", next(&params)));
        params.push(Param::Int(v));
    }
    if let Some(patterns) = &q.visible {
        // Entries about no session, or about another, stay hidden.
        let mut any = Vec::new();
        for pattern in patterns {
            match pattern {
                SessionPattern::Exact(id) => {
                    any.push(format!("session = ${}", next(&params)));
                    params.push(Param::Text(id));
                }
                SessionPattern::Prefix(prefix) => {
                    // substr, not LIKE: `_` is a wildcard there and legal in an id.
                    let len = next(&params);
                    let text = len + 1;
                    any.push(format!("substr(session, 1, ${len}) = ${text}"));
                    params.push(Param::Len(
                        i32::try_from(prefix.chars().count()).unwrap_or(i32::MAX),
                    ));
                    params.push(Param::Text(prefix));
                }
            }
        }
        if any.is_empty() {
            sql.push_str(" AND 1 = 0");
        } else {
            sql.push_str(&format!(
                " AND session IS NOT NULL AND ({})",
                any.join(" OR ")
            ));
        }
    }
    sql.push_str(&format!(" ORDER BY id DESC LIMIT ${}", params.len() + 1));
    let rows: Vec<AuditRow> = with_pool!(pool, p => {
        let mut query = sqlx::query_as(&sql);
        for param in &params {
            query = match param {
                Param::Text(s) => query.bind(*s),
                Param::Int(v) => query.bind(*v),
                Param::Len(v) => query.bind(*v),
            };
        }
        query.bind(q.limit).fetch_all(p).await?
    });
    rows.into_iter().map(entry_from_row).collect()
}

/// Acknowledges entry `id` of `session` unless it already is.
pub(super) async fn ack(
    store: &super::Store,
    session: &str,
    id: i64,
    ack: &AlarmAck,
) -> Result<AckOutcome, StoreError> {
    // One statement: of two acknowledgements at once, exactly one finds it open.
    let changed = with_pool!(&store.pool, p => sqlx::query(
        "UPDATE alarms SET acked_by = $1, acked_at_ms = $2, ack_comment = $3 \
         WHERE id = $4 AND session = $5 AND acked_at_ms IS NULL",
    )
    .bind(&ack.acked_by)
    .bind(ack.acked_at_ms)
    .bind(&ack.ack_comment)
    .bind(id)
    .bind(session)
    .execute(p)
    .await?
    .rows_affected());
    let query = super::AlarmQuery {
        session: Some(session.to_owned()),
        before_id: Some(id.saturating_add(1)),
        after_id: Some(id.saturating_sub(1)),
        limit: 1,
        ..Default::default()
    };
    let Some(entry) = store.alarm_log(&query).await?.into_iter().next() else {
        return Ok(AckOutcome::Missing);
    };
    Ok(if changed == 1 {
        AckOutcome::Acked(entry)
    } else {
        AckOutcome::Already(entry)
    })
}
