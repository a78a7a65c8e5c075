//! Persistence (docs/architecture.md §A4): sessions with their monitors and thresholds,
//! the alarm log and trained models ([`models`]), through sqlx in SQLite (a file, WAL;
//! the default) or Postgres (`--db postgres://…`), with versioned migrations per backend
//! ([`migrate`]). An alarm is committed here before anyone is told about it.

/// Runs `$body` with `$p` bound to the backend's pool (or any other value of the same
/// shape): the same code, compiled once per backend. The SQL is written once, in the
/// syntax both accept (`$n` placeholders, `RETURNING`, `ON CONFLICT`).
macro_rules! with_pool {
    ($pool:expr, $p:ident => $body:expr) => {
        match $pool {
            $crate::service::store::Pool::Sqlite($p) => $body,
            $crate::service::store::Pool::Postgres($p) => $body,
        }
    };
}

mod alarm_writer;
pub mod audit;
pub mod cluster;
mod migrate;
pub mod models;
pub mod recordings;

use std::path::Path;
use std::str::FromStr;
use std::sync::{Arc, Weak};
use std::time::Duration;

use sqlx::postgres::{PgConnectOptions, PgPool, PgPoolOptions};
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteSynchronous,
};

use crate::service::wire::{AlarmLevel, AlarmRecord, MonitorSpecWire, Severity};
use navguard_core::detect::Health;

pub use alarm_writer::AlarmKey;
pub use audit::{AckOutcome, AlarmAck, AuditEntry, AuditQuery, LoggedAlarm, SessionPattern};
pub use cluster::{Acquire, Checkpoint, Fence, Lease};
pub use models::StoredModel;
pub use recordings::{RecordedFrame, Retention, StreamSummary};

/// Store failures. These are server faults (HTTP 500), never the user's input.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The database refused or failed.
    #[error("database: {0}")]
    Db(#[from] sqlx::Error),
    /// The Postgres server named by `--db` could not be reached or refused the login.
    #[error("connecting to {0}: {1}")]
    Connect(String, sqlx::Error),
    /// A stored row could not be decoded.
    #[error("corrupt stored row: {0}")]
    Corrupt(String),
    /// A group commit (alarms, checkpoints) failed: the database's reason, shared by every
    /// write of the group.
    #[error("write failed: {0}")]
    Write(String),
    /// The write was for a session whose lease this node no longer holds under the
    /// epoch it carried (docs/deployment.md): another node owns the session now.
    #[error("session '{0}' is owned by another node now (lease fenced)")]
    Fenced(String),
}

/// How many more times a group commit that lost a deadlock or a serialisation conflict
/// is run: Postgres rolls such a transaction back whole and expects the client to run it
/// again (nodes' alarm, checkpoint and lease writes lock lease rows in different orders).
const TRANSIENT_RETRIES: u32 = 4;

/// Whether `e` is a conflict that running the whole transaction again resolves:
/// Postgres' `deadlock_detected` (40P01) and `serialization_failure` (40001).
fn transient(e: &sqlx::Error) -> bool {
    e.as_database_error()
        .and_then(|d| d.code())
        .is_some_and(|c| c == "40P01" || c == "40001")
}

/// Runs `attempt` (one whole transaction) again while it fails with a transient conflict,
/// at most [`TRANSIENT_RETRIES`] more times, after pauses of 10, 20, 40, 80 ms.
async fn retry_transient<T, F, Fut>(what: &str, mut attempt: F) -> Result<T, sqlx::Error>
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = Result<T, sqlx::Error>>,
{
    let mut retries = 0;
    loop {
        match attempt().await {
            Err(e) if transient(&e) && retries < TRANSIENT_RETRIES => {
                retries += 1;
                tracing::warn!(error = %e, retry = retries, "{what}: transient conflict, run again");
                tokio::time::sleep(Duration::from_millis(5 << retries)).await;
            }
            other => return other,
        }
    }
}

/// The format version written with every stored session spec (`"format"` in the row's
/// JSON). Format 0 is the original one, without the field; it still loads.
pub const SESSION_FORMAT: u32 = 1;

/// A session spec as the `sessions.spec` column holds it: the format version beside the
/// session's fields. Loading dispatches on `format` (absent: 0); formats 0 and 1 share
/// the same fields, and a later format would convert here.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct StoredSpec<S> {
    /// Format version.
    #[serde(default)]
    format: u32,
    /// The session.
    #[serde(flatten)]
    session: S,
}

impl StoredSpec<&StoredSession> {
    fn encode(session: &StoredSession) -> Result<String, StoreError> {
        serde_json::to_string(&StoredSpec {
            format: SESSION_FORMAT,
            session,
        })
        .map_err(|e| StoreError::Corrupt(e.to_string()))
    }
}

impl StoredSpec<StoredSession> {
    fn decode(text: &str) -> Result<StoredSession, StoreError> {
        let spec: StoredSpec<StoredSession> =
            serde_json::from_str(text).map_err(|e| StoreError::Corrupt(e.to_string()))?;
        match spec.format {
            0 | SESSION_FORMAT => Ok(spec.session),
            other => Err(StoreError::Corrupt(format!(
                "session spec format {other} is newer than this server's {SESSION_FORMAT}"
            ))),
        }
    }
}

/// A stored session: its spec as created and as changed since.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StoredSession {
    /// Session id.
    pub id: String,
    /// Echo results on the ingest socket.
    pub echo: bool,
    /// Monitors with their current thresholds and policies.
    pub monitors: Vec<MonitorSpecWire>,
    /// Creation time, Unix milliseconds.
    pub created_at_ms: i64,
    /// Record every accepted frame (docs/architecture.md §A12); `None` follows the server's
    /// `--record` default.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub record: Option<bool>,
    /// The session's alarm level (monitors may override it; default `isolated`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alarm_level: Option<AlarmLevel>,
}

/// Filters for the alarm log.
#[derive(Debug, Clone, Default)]
pub struct AlarmQuery {
    /// Only this session.
    pub session: Option<String>,
    /// Only this monitor.
    pub monitor: Option<String>,
    /// Only alarms raised at or after this wall-clock time, Unix ms.
    pub since_ms: Option<i64>,
    /// Only alarms raised before this wall-clock time, Unix ms.
    pub until_ms: Option<i64>,
    /// Only alarms with an id below this (pagination cursor).
    pub before_id: Option<i64>,
    /// Only alarms with an id above this (catching up after a reconnect).
    pub after_id: Option<i64>,
    /// Only entries of this severity.
    pub severity: Option<Severity>,
    /// At most this many, newest first.
    pub limit: i64,
}

/// The connection pool of one backend.
#[derive(Debug, Clone)]
pub(crate) enum Pool {
    /// A SQLite file.
    Sqlite(SqlitePool),
    /// A Postgres database.
    Postgres(PgPool),
}

/// Which backend a `--db` value names: a `postgres://` or `postgresql://` URL is
/// Postgres, anything else a SQLite file path.
pub fn postgres_url(db: &Path) -> Option<&str> {
    let text = db.to_str()?;
    (text.starts_with("postgres://") || text.starts_with("postgresql://")).then_some(text)
}

/// `db` for logs: a Postgres URL without its password, a path as it is.
pub fn display_db(db: &Path) -> String {
    let Some(url) = postgres_url(db) else {
        return db.display().to_string();
    };
    let (scheme, rest) = url.split_once("://").unwrap_or(("postgres", url));
    let authority_end = rest.find('/').unwrap_or(rest.len());
    match rest[..authority_end].rfind('@') {
        Some(at) => {
            let user = rest[..at].split(':').next().unwrap_or("");
            format!("{scheme}://{user}@{}", &rest[at + 1..])
        }
        None => url.to_owned(),
    }
}

/// The store (SQLite or Postgres). Cheap to clone (a pool).
#[derive(Debug, Clone)]
pub struct Store {
    pool: Pool,
    /// Alarms go through one writer task that commits them in groups.
    alarms: alarm_writer::AlarmWriter,
    /// Recorded frames go through another (not awaited per frame).
    recordings: recordings::RecordingWriter,
    /// Checkpoints through a third (group commit, awaited).
    checkpoints: cluster::CheckpointWriter,
    /// Held while any clone of the store lives; SQLite's WAL checkpointer stops when it
    /// is gone ([`spawn_wal_checkpointer`]).
    _alive: Arc<()>,
}

/// How often SQLite's WAL is copied into the database file, by a task of its own.
const WAL_CHECKPOINT_PERIOD: Duration = Duration::from_millis(500);

/// WAL frames (4 KiB pages) past which the checkpoint makes the WAL start over (64 MiB).
const WAL_RESTART_FRAMES: i64 = 16_384;

/// Copies SQLite's WAL into the database file every [`WAL_CHECKPOINT_PERIOD`] (a
/// `PASSIVE` checkpoint: it waits for no reader or writer; a `RESTART` one, which waits
/// for readers, once the WAL holds more than [`WAL_RESTART_FRAMES`]), until the store is
/// dropped or closed. The connections themselves never checkpoint (`wal_autocheckpoint = 0`,
/// [`open_sqlite`]): SQLite's automatic checkpoint runs inside the commit that takes the
/// WAL past 1,000 pages, and that commit is usually the alarm writer's, holding every
/// alarm of a burst back from being announced while the WAL is copied and synced.
fn spawn_wal_checkpointer(pool: SqlitePool, alive: Weak<()>) {
    tokio::spawn(async move {
        let mut tick = tokio::time::interval(WAL_CHECKPOINT_PERIOD);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        tick.tick().await;
        loop {
            tick.tick().await;
            if alive.strong_count() == 0 || pool.is_closed() {
                return;
            }
            // (busy, frames in the WAL, frames copied)
            let passive = sqlx::query_as::<_, (i64, i64, i64)>("PRAGMA wal_checkpoint(PASSIVE)")
                .fetch_one(&pool)
                .await;
            let outcome = match passive {
                // A WAL that keeps growing (readers never let it start over) is made to
                // start over, waiting for those readers.
                Ok((_, frames, _)) if frames > WAL_RESTART_FRAMES => {
                    sqlx::query("PRAGMA wal_checkpoint(RESTART)")
                        .execute(&pool)
                        .await
                        .map(drop)
                }
                other => other.map(drop),
            };
            if let Err(e) = outcome {
                if pool.is_closed() {
                    return;
                }
                tracing::warn!(error = %e, "WAL checkpoint failed; retrying");
            }
        }
    });
}

/// Columns added to SQLite's first schema before migrations were versioned, with their
/// definitions: added to an older database at open (rows written before read their
/// default). Later changes are numbered migrations ([`migrate`]).
const ADDED_COLUMNS: &[(&str, &str, &str)] =
    &[("alarms", "severity", "TEXT NOT NULL DEFAULT 'alarm'")];

impl Store {
    /// Opens (creating if needed) the database file in WAL mode, or connects to the
    /// Postgres database `db` names ([`postgres_url`]), and applies the migrations, with
    /// the default recording retention.
    pub async fn open(db: &Path) -> Result<Self, StoreError> {
        Store::open_with(db, Retention::default()).await
    }

    /// [`Store::open`] with the given recording retention limits.
    pub async fn open_with(db: &Path, retention: Retention) -> Result<Self, StoreError> {
        let pool = match postgres_url(db) {
            Some(url) => Pool::Postgres(open_postgres(url).await?),
            None => Pool::Sqlite(open_sqlite(db).await?),
        };
        if let Pool::Sqlite(sqlite) = &pool {
            migrate::apply(&pool, 1).await?;
            add_columns(sqlite).await?;
        }
        migrate::apply(&pool, i64::MAX).await?;
        let alarms = alarm_writer::AlarmWriter::spawn(pool.clone());
        let recordings = recordings::RecordingWriter::spawn(pool.clone(), retention);
        let checkpoints = cluster::CheckpointWriter::spawn(pool.clone());
        let alive = Arc::new(());
        if let Pool::Sqlite(sqlite) = &pool {
            spawn_wal_checkpointer(sqlite.clone(), Arc::downgrade(&alive));
        }
        Ok(Store {
            pool,
            alarms,
            recordings,
            checkpoints,
            _alive: alive,
        })
    }

    /// Flushes the WAL into the main file (SQLite) and closes every connection.
    pub async fn close(&self) {
        match &self.pool {
            Pool::Sqlite(pool) => {
                let _ = sqlx::query("PRAGMA wal_checkpoint(TRUNCATE)")
                    .execute(pool)
                    .await;
                pool.close().await;
            }
            Pool::Postgres(pool) => pool.close().await,
        }
    }

    /// Inserts or replaces a session's spec. Every write of the store takes a `fence`: on
    /// a cluster node, the lease it holds (a write under a lost lease is refused as
    /// [`StoreError::Fenced`]); on a single node, `None`.
    pub async fn put_session(
        &self,
        session: &StoredSession,
        fence: Option<&Fence>,
    ) -> Result<(), StoreError> {
        let spec = StoredSpec::encode(session)?;
        with_pool!(&self.pool, p => {
            let mut tx = p.begin().await?;
            cluster::check_fence!(tx, fence);
            sqlx::query("INSERT INTO sessions (id, spec, created_at_ms) VALUES ($1, $2, $3) ON CONFLICT (id) DO UPDATE SET spec = excluded.spec")
                .bind(&session.id)
                .bind(&spec)
                .bind(session.created_at_ms)
                .execute(&mut *tx)
                .await?;
            tx.commit().await?;
        });
        Ok(())
    }

    /// Deletes a session's spec (its alarms stay in the log); the session's lease and
    /// checkpoint go with it.
    pub async fn delete_session(
        &self,
        id: &str,
        fence: Option<&Fence>,
    ) -> Result<bool, StoreError> {
        let done = with_pool!(&self.pool, p => {
            let mut tx = p.begin().await?;
            cluster::check_fence!(tx, fence);
            let done = sqlx::query("DELETE FROM sessions WHERE id = $1")
                .bind(id)
                .execute(&mut *tx)
                .await?
                .rows_affected();
            for sql in cluster::FORGET_SQL {
                sqlx::query(sql).bind(id).execute(&mut *tx).await?;
            }
            tx.commit().await?;
            done
        });
        Ok(done > 0)
    }

    /// The stored spec of session `id`.
    pub async fn session(&self, id: &str) -> Result<Option<StoredSession>, StoreError> {
        let spec: Option<String> = with_pool!(&self.pool, p => sqlx::query_scalar(
            "SELECT spec FROM sessions WHERE id = $1",
        )
        .bind(id)
        .fetch_optional(p)
        .await?);
        spec.map(|s| StoredSpec::decode(&s)).transpose()
    }

    /// The lease of session `id`, if any (docs/deployment.md).
    pub async fn lease(&self, id: &str) -> Result<Option<Lease>, StoreError> {
        cluster::lease(&self.pool, id).await
    }

    /// Takes the lease of a new session; false when the id already has one.
    pub async fn create_lease(
        &self,
        id: &str,
        owner: &str,
        address: &str,
        expires_ms: i64,
    ) -> Result<bool, StoreError> {
        cluster::create_lease(&self.pool, id, owner, address, expires_ms).await
    }

    /// Takes the lease of session `id` if it is free, expired at `now_ms`, `owner`'s
    /// already, or `force`; its epoch goes up by one.
    #[allow(clippy::too_many_arguments)]
    pub async fn acquire_lease(
        &self,
        id: &str,
        owner: &str,
        address: &str,
        now_ms: i64,
        expires_ms: i64,
        force: bool,
    ) -> Result<Acquire, StoreError> {
        cluster::acquire(&self.pool, id, owner, address, now_ms, expires_ms, force).await
    }

    /// Extends `owner`'s leases; the sessions (and epochs) it still holds.
    pub async fn renew_leases(
        &self,
        owner: &str,
        expires_ms: i64,
    ) -> Result<Vec<(String, i64)>, StoreError> {
        cluster::renew(&self.pool, owner, expires_ms).await
    }

    /// Releases a lease at once (drain, handover).
    pub async fn release_lease(&self, fence: &Fence) -> Result<bool, StoreError> {
        cluster::release(&self.pool, fence).await
    }

    /// Stores a checkpoint by the holder of `fence` (never over a newer one); checkpoints
    /// written at the same moment share one transaction.
    pub async fn put_checkpoint(
        &self,
        fence: &Fence,
        checkpoint: &Checkpoint,
    ) -> Result<(), StoreError> {
        self.checkpoints.put(fence, checkpoint.clone()).await
    }

    /// The latest checkpoint of session `id`.
    pub async fn checkpoint(&self, id: &str) -> Result<Option<Checkpoint>, StoreError> {
        cluster::checkpoint(&self.pool, id).await
    }

    /// Every stored session, oldest first.
    pub async fn sessions(&self) -> Result<Vec<StoredSession>, StoreError> {
        let specs: Vec<String> = with_pool!(&self.pool, p => sqlx::query_scalar(
            "SELECT spec FROM sessions ORDER BY created_at_ms, id",
        )
        .fetch_all(p)
        .await?);
        specs.iter().map(|spec| StoredSpec::decode(spec)).collect()
    }

    /// Commits an alarm under `key` and returns it with its id (an entry with the same key
    /// is not stored twice: its id is returned). Alarms raised at the same moment share
    /// one transaction (group commit); this returns after the commit.
    pub async fn insert_alarm(
        &self,
        mut alarm: AlarmRecord,
        key: AlarmKey,
        fence: Option<&Fence>,
    ) -> Result<AlarmRecord, StoreError> {
        alarm.id = self
            .alarms
            .insert(alarm.clone(), key, fence.cloned())
            .await?;
        Ok(alarm)
    }

    /// Queues a frame for the recording (committed by the writer, not awaited; a fenced
    /// frame is dropped).
    pub async fn record_frame(&self, frame: RecordedFrame, fence: Option<&Fence>) {
        self.recordings.record(frame, fence.cloned()).await;
    }

    /// Waits until every frame queued for the recording so far is committed.
    pub async fn flush_recordings(&self) {
        self.recordings.flush().await;
    }

    /// Up to `limit` recorded frames of a session's stream with ids above `after`,
    /// oldest first, with their ids (the cursor of the next page).
    pub async fn recording_page(
        &self,
        session: &str,
        stream: u64,
        after: i64,
        limit: i64,
    ) -> Result<Vec<(i64, RecordedFrame)>, StoreError> {
        recordings::page(&self.pool, session, stream, after, limit).await
    }

    /// The streams a session has recorded.
    pub async fn recording_streams(&self, session: &str) -> Result<Vec<StreamSummary>, StoreError> {
        recordings::streams(&self.pool, session).await
    }

    /// Marks a test's open alarms as cleared at epoch time `t` (each alarm's own `t` when
    /// unknown).
    pub async fn clear_alarms(
        &self,
        session: &str,
        monitor: &str,
        test: &str,
        t: Option<f64>,
        fence: Option<&Fence>,
    ) -> Result<(), StoreError> {
        self.alarms
            .clear(session, Some((monitor, test)), t, fence.cloned())
            .await
    }

    /// Closes every open alarm of a session whose stream restarted from scratch (its
    /// filters were reset); `cleared_t` is set to the alarm's own `t`.
    pub async fn clear_session_alarms(
        &self,
        session: &str,
        fence: Option<&Fence>,
    ) -> Result<(), StoreError> {
        self.alarms.clear(session, None, None, fence.cloned()).await
    }

    /// The alarm log, newest first.
    pub async fn alarms(&self, q: &AlarmQuery) -> Result<Vec<AlarmRecord>, StoreError> {
        Ok(self
            .alarm_log(q)
            .await?
            .into_iter()
            .map(|a| a.record)
            .collect())
    }

    /// Appends an entry to the audit log; returns its id.
    pub async fn insert_audit(&self, entry: &AuditEntry) -> Result<i64, StoreError> {
        audit::insert(&self.pool, entry).await
    }

    /// The audit log, newest first.
    pub async fn audit(&self, q: &AuditQuery) -> Result<Vec<AuditEntry>, StoreError> {
        audit::query(&self.pool, q).await
    }

    /// Acknowledges alarm-log entry `id` of `session`, unless it already is.
    pub async fn ack_alarm(
        &self,
        session: &str,
        id: i64,
        ack: &AlarmAck,
    ) -> Result<AckOutcome, StoreError> {
        audit::ack(self, session, id, ack).await
    }

    /// The alarm log with each entry's acknowledgement, newest first.
    pub async fn alarm_log(&self, q: &AlarmQuery) -> Result<Vec<LoggedAlarm>, StoreError> {
        let mut sql = String::from(
            "SELECT id, session, monitor, test, state, t, statistic, threshold, dof, delay_s, raised_at_ms, cleared_t, severity, acked_by, acked_at_ms, ack_comment FROM alarms WHERE 1 = 1",
        );
        let mut n = 0;
        let mut filter = |sql: &mut String, condition: &str| {
            n += 1;
            sql.push_str(&format!(" AND {condition} ${n}"));
        };
        if q.session.is_some() {
            filter(&mut sql, "session =");
        }
        if q.monitor.is_some() {
            filter(&mut sql, "monitor =");
        }
        if q.since_ms.is_some() {
            filter(&mut sql, "raised_at_ms >=");
        }
        if q.until_ms.is_some() {
            filter(&mut sql, "raised_at_ms <");
        }
        if q.before_id.is_some() {
            filter(&mut sql, "id <");
        }
        if q.after_id.is_some() {
            filter(&mut sql, "id >");
        }
        if q.severity.is_some() {
            filter(&mut sql, "severity =");
        }
        sql.push_str(&format!(" ORDER BY id DESC LIMIT ${}", n + 1));
        let rows: Vec<AlarmRow> = with_pool!(&self.pool, p => {
            let mut query = sqlx::query_as(&sql);
            if let Some(s) = &q.session {
                query = query.bind(s);
            }
            if let Some(m) = &q.monitor {
                query = query.bind(m);
            }
            if let Some(v) = q.since_ms {
                query = query.bind(v);
            }
            if let Some(v) = q.until_ms {
                query = query.bind(v);
            }
            if let Some(v) = q.before_id {
                query = query.bind(v);
            }
            if let Some(v) = q.after_id {
                query = query.bind(v);
            }
            if let Some(v) = q.severity {
                query = query.bind(v.as_str());
            }
            query.bind(q.limit).fetch_all(p).await?
        });
        rows.into_iter().map(alarm_from_row).collect()
    }
}

async fn open_sqlite(path: &Path) -> Result<SqlitePool, StoreError> {
    let url = format!("sqlite://{}", path.display());
    let options = SqliteConnectOptions::from_str(&url)?
        .create_if_missing(true)
        .journal_mode(SqliteJournalMode::Wal)
        // WAL + NORMAL: a committed transaction survives a process crash;
        // only an OS crash or power loss can lose the last commits.
        .synchronous(SqliteSynchronous::Normal)
        // The WAL is checkpointed by a task of its own, not inside a commit.
        .pragma("wal_autocheckpoint", "0")
        // After a checkpoint has emptied it, the WAL file is cut back to 64 MiB at most.
        .pragma("journal_size_limit", "67108864")
        .busy_timeout(std::time::Duration::from_secs(5));
    Ok(SqlitePoolOptions::new()
        .max_connections(4)
        .connect_with(options)
        .await?)
}

async fn open_postgres(url: &str) -> Result<PgPool, StoreError> {
    // Every commit is durable (synchronous_commit as the server has it, on by default).
    let options = PgConnectOptions::from_str(url)?;
    let shown = display_db(Path::new(url));
    // One connection first, for the server's own reason when it fails (the pool would
    // only report a timeout).
    use sqlx::Connection as _;
    let probe = sqlx::PgConnection::connect_with(&options)
        .await
        .map_err(|e| StoreError::Connect(shown.clone(), e))?;
    let _ = probe.close().await;
    PgPoolOptions::new()
        .max_connections(8)
        .acquire_timeout(std::time::Duration::from_secs(10))
        .connect_with(options)
        .await
        .map_err(|e| StoreError::Connect(shown, e))
}

/// Adds [`ADDED_COLUMNS`] missing from an older SQLite file.
async fn add_columns(pool: &SqlitePool) -> Result<(), StoreError> {
    for (table, column, definition) in ADDED_COLUMNS {
        let present: Vec<String> =
            sqlx::query_scalar(&format!("SELECT name FROM pragma_table_info('{table}')"))
                .fetch_all(pool)
                .await?;
        if !present.iter().any(|c| c == column) {
            sqlx::query(&format!(
                "ALTER TABLE {table} ADD COLUMN {column} {definition}"
            ))
            .execute(pool)
            .await?;
        }
    }
    Ok(())
}

/// An `alarms` row in the order [`Store::alarm_log`] selects it.
type AlarmRow = (
    i64,
    String,
    String,
    String,
    String,
    f64,
    f64,
    f64,
    i64,
    f64,
    i64,
    Option<f64>,
    String,
    Option<String>,
    Option<i64>,
    Option<String>,
);

fn alarm_from_row(row: AlarmRow) -> Result<LoggedAlarm, StoreError> {
    let (
        id,
        session,
        monitor,
        test,
        state,
        t,
        statistic,
        threshold,
        dof,
        delay_s,
        raised_at_ms,
        cleared_t,
        severity,
        acked_by,
        acked_at_ms,
        ack_comment,
    ) = row;
    let record = AlarmRecord {
        id,
        severity: Severity::parse(&severity)
            .ok_or_else(|| StoreError::Corrupt(format!("alarm severity '{severity}'")))?,
        session,
        monitor,
        test,
        state: Health::parse(&state)
            .ok_or_else(|| StoreError::Corrupt(format!("alarm state '{state}'")))?,
        t,
        statistic,
        threshold,
        dof: u32::try_from(dof).map_err(|_| StoreError::Corrupt(format!("alarm dof {dof}")))?,
        test_ratio: statistic / threshold,
        delay_s,
        raised_at_ms,
        cleared_t,
    };
    Ok(LoggedAlarm {
        record,
        acked_by,
        acked_at_ms,
        ack_comment,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A database error with a given SQLSTATE, as a Postgres server would send it.
    #[derive(Debug)]
    struct Sqlstate(&'static str);

    impl std::fmt::Display for Sqlstate {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            write!(f, "SQLSTATE {}", self.0)
        }
    }

    impl std::error::Error for Sqlstate {}

    impl sqlx::error::DatabaseError for Sqlstate {
        fn message(&self) -> &str {
            self.0
        }
        fn code(&self) -> Option<std::borrow::Cow<'_, str>> {
            Some(self.0.into())
        }
        fn as_error(&self) -> &(dyn std::error::Error + Send + Sync + 'static) {
            self
        }
        fn as_error_mut(&mut self) -> &mut (dyn std::error::Error + Send + Sync + 'static) {
            self
        }
        fn into_error(self: Box<Self>) -> Box<dyn std::error::Error + Send + Sync + 'static> {
            self
        }
        fn kind(&self) -> sqlx::error::ErrorKind {
            sqlx::error::ErrorKind::Other
        }
    }

    /// Runs `retry_transient` over attempts that fail with `codes` in turn, then succeed;
    /// the outcome and how many attempts ran.
    async fn attempts(codes: &[&'static str]) -> (Result<u32, String>, usize) {
        let tried = std::sync::atomic::AtomicUsize::new(0);
        let out = retry_transient("test", || async {
            let k = tried.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            match codes.get(k) {
                Some(code) => Err(sqlx::Error::Database(Box::new(Sqlstate(code)))),
                None => Ok(7),
            }
        })
        .await;
        (out.map_err(|e| e.to_string()), tried.into_inner())
    }

    #[tokio::test]
    async fn a_deadlock_or_serialisation_conflict_runs_the_transaction_again_and_nothing_else_does()
    {
        // A deadlock, then a serialisation failure: the third attempt commits.
        assert_eq!(attempts(&["40P01", "40001"]).await, (Ok(7), 3));
        // A unique violation is not transient: returned at once.
        let (out, tried) = attempts(&["23505"]).await;
        assert_eq!(
            (out.unwrap_err(), tried),
            ("error returned from database: SQLSTATE 23505".to_owned(), 1)
        );
        // Four retries at most: the fifth deadlock is returned.
        let (out, tried) = attempts(&["40P01"; 5]).await;
        assert!(out.unwrap_err().contains("40P01"));
        assert_eq!(tried, 5);
        assert_eq!(attempts(&["40P01"; 4]).await, (Ok(7), 5));
    }

    fn alarm(session: &str, t: f64) -> AlarmRecord {
        AlarmRecord {
            id: 0,
            severity: Severity::Alarm,
            session: session.into(),
            monitor: "m".into(),
            test: "residual".into(),
            state: Health::Isolated,
            t,
            statistic: 30.0,
            threshold: 20.0,
            dof: 2,
            test_ratio: 1.5,
            delay_s: 0.0,
            raised_at_ms: 1000 + t as i64,
            cleared_t: None,
        }
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn alarms_raised_together_share_commits_and_keep_per_session_order() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(&dir.path().join("g.db")).await.unwrap();
        // 200 sessions each raise 5 alarms at once, as a common fault would.
        let tasks: Vec<_> = (0..200)
            .map(|s| {
                let store = store.clone();
                tokio::spawn(async move {
                    let mut ids = Vec::new();
                    for k in 0..5 {
                        let a = store
                            .insert_alarm(
                                alarm(&format!("s{s}"), k as f64),
                                AlarmKey::default(),
                                None,
                            )
                            .await
                            .unwrap();
                        ids.push(a.id);
                    }
                    ids
                })
            })
            .collect();
        let mut all = Vec::new();
        for task in tasks {
            let ids = task.await.unwrap();
            assert!(ids.windows(2).all(|w| w[0] < w[1]), "in order per session");
            all.extend(ids);
        }
        all.sort_unstable();
        all.dedup();
        assert_eq!(all.len(), 1000, "every alarm got its own id");
        // Every one is committed: a fresh connection sees them all.
        store.close().await;
        let reopened = Store::open(&dir.path().join("g.db")).await.unwrap();
        let q = AlarmQuery {
            limit: 1000,
            ..AlarmQuery::default()
        };
        assert_eq!(reopened.alarms(&q).await.unwrap().len(), 1000);
    }

    /// Clears share the inserts' queue and commits: raised and cleared by 300 sessions at
    /// once, each session's entries end in the order its calls made them (the last one
    /// of each session, raised after the clears, stays open).
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn clears_raised_together_keep_their_order_per_session() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(&dir.path().join("c.db")).await.unwrap();
        let tasks: Vec<_> = (0..300)
            .map(|s| {
                let store = store.clone();
                tokio::spawn(async move {
                    let session = format!("s{s}");
                    store
                        .insert_alarm(alarm(&session, 1.0), AlarmKey::default(), None)
                        .await
                        .unwrap();
                    store
                        .clear_alarms(&session, "m", "residual", Some(2.0), None)
                        .await
                        .unwrap();
                    store
                        .insert_alarm(alarm(&session, 3.0), AlarmKey::default(), None)
                        .await
                        .unwrap();
                    if s % 2 == 0 {
                        store.clear_session_alarms(&session, None).await.unwrap();
                    }
                })
            })
            .collect();
        for task in tasks {
            task.await.unwrap();
        }
        let entries = store
            .alarms(&AlarmQuery {
                limit: 1000,
                ..AlarmQuery::default()
            })
            .await
            .unwrap();
        assert_eq!(entries.len(), 600);
        for a in entries {
            let s: usize = a.session[1..].parse().unwrap();
            let expected = match (a.t, s % 2) {
                (1.0, _) => Some(2.0), // cleared by the test's clear at t = 2
                (3.0, 0) => Some(3.0), // closed by the session clear at its own t
                (3.0, _) => None,      // raised after the clear: open
                other => panic!("unexpected entry {other:?}"),
            };
            assert_eq!(a.cleared_t, expected, "{} t = {}", a.session, a.t);
        }
    }

    /// Up to ten of the entries `query` selects, newest first.
    async fn first_ten(store: &Store, query: AlarmQuery) -> Vec<AlarmRecord> {
        let query = AlarmQuery { limit: 10, ..query };
        store.alarms(&query).await.unwrap()
    }

    /// `AlarmQuery` for one session's entries.
    fn of_session(session: &str) -> AlarmQuery {
        AlarmQuery {
            session: Some(session.into()),
            ..Default::default()
        }
    }

    #[tokio::test]
    async fn a_checkpoint_that_cannot_reach_the_database_is_a_write_failure_not_a_corrupt_row() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(&dir.path().join("k.db")).await.unwrap();
        // The database gone, as when the engines are down: the group commit fails.
        store.close().await;
        let fence = Fence {
            session: "s".into(),
            owner: "n1".into(),
            epoch: 1,
        };
        let checkpoint = Checkpoint {
            session: "s".into(),
            lease_epoch: 1,
            version: 1,
            epochs: 10,
            t: Some(9.0),
            taken_at_ms: 1,
            state: vec![1, 2, 3],
        };
        let err = store.put_checkpoint(&fence, &checkpoint).await.unwrap_err();
        assert!(
            matches!(err, StoreError::Write(_) | StoreError::Db(_)),
            "{err:?}"
        );
        assert!(!err.to_string().contains("corrupt"), "{err}");
    }

    #[tokio::test]
    async fn alarms_round_trip_newest_first_with_filters_and_clearing() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(&dir.path().join("t.db")).await.unwrap();
        for (s, t) in [("a", 1.0), ("b", 2.0), ("a", 3.0)] {
            store
                .insert_alarm(alarm(s, t), AlarmKey::default(), None)
                .await
                .unwrap();
        }
        let all = first_ten(&store, AlarmQuery::default()).await;
        assert_eq!(
            all.iter().map(|a| a.t).collect::<Vec<_>>(),
            vec![3.0, 2.0, 1.0]
        );
        assert_eq!(first_ten(&store, of_session("a")).await.len(), 2);
        let page = store
            .alarms(&AlarmQuery {
                before_id: Some(all[0].id),
                limit: 1,
                ..Default::default()
            })
            .await
            .unwrap();
        assert_eq!(page[0].t, 2.0);
        store
            .clear_alarms("a", "m", "residual", Some(9.0), None)
            .await
            .unwrap();
        let after = AlarmQuery {
            after_id: Some(all[2].id),
            ..Default::default()
        };
        let newer = first_ten(&store, after).await;
        assert_eq!(
            newer.iter().map(|a| a.t).collect::<Vec<_>>(),
            vec![3.0, 2.0]
        );
        let a = first_ten(&store, of_session("a")).await;
        assert!(a.iter().all(|x| x.cleared_t == Some(9.0)));
        store
            .insert_alarm(alarm("b", 4.0), AlarmKey::default(), None)
            .await
            .unwrap();
        store.clear_session_alarms("b", None).await.unwrap();
        let b = first_ten(&store, of_session("b")).await;
        assert_eq!(
            b.iter().map(|a| a.cleared_t).collect::<Vec<_>>(),
            vec![Some(4.0), Some(2.0)]
        );
        assert_eq!(
            a[0],
            AlarmRecord {
                id: a[0].id,
                cleared_t: Some(9.0),
                ..alarm("a", 3.0)
            }
        );
    }

    #[tokio::test]
    async fn an_alarm_log_from_before_severities_opens_and_reads_as_alarms() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("old.db");
        {
            // The alarms table as the previous version created it, with one row.
            let url = format!("sqlite://{}?mode=rwc", path.display());
            let pool = SqlitePool::connect(&url).await.unwrap();
            sqlx::query(
                "CREATE TABLE alarms (id INTEGER PRIMARY KEY AUTOINCREMENT, session TEXT NOT NULL, monitor TEXT NOT NULL, test TEXT NOT NULL, state TEXT NOT NULL, t REAL NOT NULL, statistic REAL NOT NULL, threshold REAL NOT NULL, dof INTEGER NOT NULL, delay_s REAL NOT NULL, raised_at_ms INTEGER NOT NULL, cleared_t REAL)",
            )
            .execute(&pool)
            .await
            .unwrap();
            sqlx::query("INSERT INTO alarms (session, monitor, test, state, t, statistic, threshold, dof, delay_s, raised_at_ms) VALUES ('s', 'm', 'r', 'suspect', 1.0, 30.0, 20.0, 1, 0.0, 5)")
                .execute(&pool)
                .await
                .unwrap();
            pool.close().await;
        }
        let store = Store::open(&path).await.unwrap();
        let mut warning = alarm("s", 2.0);
        warning.severity = Severity::Warning;
        store
            .insert_alarm(warning, AlarmKey::default(), None)
            .await
            .unwrap();
        let all = store
            .alarms(&AlarmQuery {
                limit: 10,
                ..Default::default()
            })
            .await
            .unwrap();
        assert_eq!(
            all.iter().map(|a| a.severity).collect::<Vec<_>>(),
            vec![Severity::Warning, Severity::Alarm]
        );
        let alarms_only = store
            .alarms(&AlarmQuery {
                severity: Some(Severity::Alarm),
                limit: 10,
                ..Default::default()
            })
            .await
            .unwrap();
        assert_eq!(alarms_only.len(), 1);
        assert_eq!(alarms_only[0].state, Health::Suspect);
    }

    #[tokio::test]
    async fn a_database_from_a_newer_server_is_refused_and_an_old_one_migrates_once() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("v.db");
        let store = Store::open(&path).await.unwrap();
        store.close().await;
        // Reopening applies nothing twice.
        let store = Store::open(&path).await.unwrap();
        let versions: Vec<i64> = with_pool!(&store.pool, p => sqlx::query_scalar("SELECT version FROM schema_version ORDER BY version")
            .fetch_all(p)
            .await
            .unwrap());
        assert_eq!(versions, [1, 2, 3]);
        with_pool!(&store.pool, p => sqlx::query("INSERT INTO schema_version (version, name, applied_at_ms) VALUES (99, 'future', 0)")
            .execute(p)
            .await
            .unwrap()
            .rows_affected());
        store.close().await;
        let err = Store::open(&path).await.unwrap_err().to_string();
        assert!(err.contains("schema version 99 is newer"), "{err}");
    }

    /// A file at the schema before the audit log (version 2), with an alarm in its log,
    /// opens at the current version: the entry reads unacknowledged, can be acknowledged
    /// once, and the audit log starts empty and takes entries.
    #[tokio::test]
    async fn a_store_from_before_the_audit_log_migrates_and_keeps_its_alarms() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("v2.db");
        {
            // As the previous server opened a new file: migration 1, the added columns, 2.
            let sqlite = open_sqlite(&path).await.unwrap();
            let pool = Pool::Sqlite(sqlite.clone());
            migrate::apply(&pool, 1).await.unwrap();
            add_columns(&sqlite).await.unwrap();
            migrate::apply(&pool, 2).await.unwrap();
            with_pool!(&pool, p => sqlx::query("INSERT INTO alarms (session, monitor, test, state, t, statistic, threshold, dof, delay_s, raised_at_ms, severity) VALUES ('s', 'm', 'r', 'isolated', 1.0, 30.0, 20.0, 1, 0.0, 5, 'alarm')")
                .execute(p)
                .await
                .unwrap()
                .rows_affected());
            with_pool!(&pool, p => p.close().await);
        }
        let store = Store::open(&path).await.unwrap();
        let versions: Vec<i64> = with_pool!(&store.pool, p => sqlx::query_scalar("SELECT version FROM schema_version ORDER BY version")
            .fetch_all(p)
            .await
            .unwrap());
        assert_eq!(versions, [1, 2, 3]);
        let q = AlarmQuery {
            limit: 10,
            ..Default::default()
        };
        let log = store.alarm_log(&q).await.unwrap();
        assert_eq!(log.len(), 1);
        assert_eq!(
            (&log[0].acked_by, log[0].acked_at_ms, &log[0].ack_comment),
            (&None, None, &None)
        );
        let ack = AlarmAck {
            acked_by: "ops".into(),
            acked_at_ms: 9,
            ack_comment: "checked the antenna".into(),
        };
        let id = log[0].record.id;
        assert_eq!(
            store.ack_alarm("other", id, &ack).await.unwrap(),
            AckOutcome::Missing
        );
        let AckOutcome::Acked(acked) = store.ack_alarm("s", id, &ack).await.unwrap() else {
            panic!("the first acknowledgement takes");
        };
        assert_eq!(acked.acked_by.as_deref(), Some("ops"));
        let second = AlarmAck {
            acked_by: "someone".into(),
            ..ack.clone()
        };
        assert_eq!(
            store.ack_alarm("s", id, &second).await.unwrap(),
            AckOutcome::Already(acked)
        );
        let audit = AuditQuery {
            limit: 10,
            ..Default::default()
        };
        assert!(store.audit(&audit).await.unwrap().is_empty());
        let entry = AuditEntry {
            id: 0,
            at_ms: 10,
            actor: "ops".into(),
            client: Some("127.0.0.1:5000".into()),
            forwarded_for: None,
            method: "DELETE".into(),
            route: "/api/v1/sessions/{id}".into(),
            path: "/api/v1/sessions/s".into(),
            session: Some("s".into()),
            reason: None,
            previous: serde_json::json!({"id": "s"}),
            new: serde_json::Value::Null,
        };
        let id = store.insert_audit(&entry).await.unwrap();
        assert_eq!(
            store.audit(&audit).await.unwrap(),
            vec![AuditEntry { id, ..entry }]
        );
    }

    #[tokio::test]
    async fn sessions_survive_reopening() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.db");
        let s = StoredSession {
            id: "x".into(),
            echo: true,
            monitors: vec![],
            created_at_ms: 5,
            record: None,
            alarm_level: None,
        };
        {
            let store = Store::open(&path).await.unwrap();
            store.put_session(&s, None).await.unwrap();
            store.close().await;
        }
        let store = Store::open(&path).await.unwrap();
        assert_eq!(store.sessions().await.unwrap(), vec![s]);
        assert!(store.delete_session("x", None).await.unwrap());
        assert!(store.sessions().await.unwrap().is_empty());
    }

    #[tokio::test]
    async fn a_spec_stored_by_the_previous_format_still_loads() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(&dir.path().join("v0.db")).await.unwrap();
        // Format 0, as written before the format version existed: no `format` field.
        let v0 = r#"{"id":"old","echo":false,"monitors":[{"name":"cv","type":"linear","config":{"f":[[1.0]],"h":[[1.0]],"q":[[0.1]],"r":[[1.0]],"x0":[0.0],"p0":[[1.0]]},"policy":{"kind":"classic"},"p_fa":0.002}],"created_at_ms":7}"#;
        with_pool!(&store.pool, p => sqlx::query("INSERT INTO sessions (id, spec, created_at_ms) VALUES ('old', $1, 7)")
            .bind(v0)
            .execute(p)
            .await
            .unwrap()
            .rows_affected());
        let loaded = store.sessions().await.unwrap();
        assert_eq!(loaded.len(), 1);
        assert_eq!((loaded[0].id.as_str(), loaded[0].created_at_ms), ("old", 7));
        assert_eq!(loaded[0].monitors[0].name, "cv");
        assert_eq!(
            loaded[0].monitors[0].config["q"],
            serde_json::json!([[0.1]])
        );
        // Written back, it carries the current format and reads the same.
        store.put_session(&loaded[0], None).await.unwrap();
        let row: String = with_pool!(&store.pool, p => sqlx::query_scalar("SELECT spec FROM sessions WHERE id = 'old'")
            .fetch_one(p)
            .await
            .unwrap());
        assert!(row.starts_with(r#"{"format":1,"#), "{row}");
        assert_eq!(store.sessions().await.unwrap(), loaded);
        // A format from the future is refused, not misread.
        with_pool!(&store.pool, p => sqlx::query("UPDATE sessions SET spec = $1 WHERE id = 'old'")
            .bind(row.replace(r#""format":1"#, r#""format":9"#))
            .execute(p)
            .await
            .unwrap()
            .rows_affected());
        assert!(matches!(
            store.sessions().await,
            Err(StoreError::Corrupt(_))
        ));
    }
}
