//! The shared store's part in scale-out (docs/deployment.md): session leases with a
//! fencing epoch, and the owners' checkpoints.
//!
//! A **lease** row says which node owns a session, until when, and under which
//! **epoch**. Taking a lease (free, expired, or its owner known to be gone) always
//! increments the epoch. Every write a node makes for a session it owns carries a
//! [`Fence`]; the write's transaction first runs [`FENCE_SQL`], which matches only while
//! the lease still has the fence's owner and epoch. In Postgres that `UPDATE` also locks
//! the lease row until the write commits, so a takeover (an `UPDATE` of the same row)
//! waits for it: a write is either committed before the takeover or refused after it,
//! never lost half-way. SQLite has one writer at a time, which gives the same order.
//! A node whose lease was taken can therefore never write for that session again.
//!
//! Times are the nodes' own clocks (Unix ms): they must agree to well within a lease
//! (NTP does).

use tokio::sync::{mpsc, oneshot};

use super::{Pool, StoreError};

/// Matches the lease row while `owner` still holds it under `epoch` (binds: session,
/// owner, epoch). Run first in a fenced write's transaction; 0 rows means fenced.
pub(super) const FENCE_SQL: &str =
    "UPDATE leases SET epoch = epoch WHERE session = $1 AND owner = $2 AND epoch = $3";

/// What a fenced write carries: the session, the owner and the lease epoch it holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Fence {
    /// Session id.
    pub session: String,
    /// The owning node's id.
    pub owner: String,
    /// The lease epoch the owner took.
    pub epoch: i64,
}

/// A session's lease as stored.
#[derive(Debug, Clone, PartialEq, Eq, sqlx::FromRow)]
pub struct Lease {
    /// Session id.
    pub session: String,
    /// The node that holds (or last held) it.
    pub owner: String,
    /// Fencing epoch: incremented by every acquisition.
    pub epoch: i64,
    /// Until when it holds, Unix ms; 0 once released.
    pub expires_ms: i64,
    /// Where the owner serves (`--advertise`), for a client sent there.
    pub address: String,
}

impl Lease {
    /// True while the lease holds at `now_ms`.
    pub fn live(&self, now_ms: i64) -> bool {
        self.expires_ms > now_ms
    }
}

/// A session checkpoint as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct Checkpoint {
    /// Session id.
    pub session: String,
    /// The lease epoch of the owner that wrote it.
    pub lease_epoch: i64,
    /// Increasing per owner: a late write of an older checkpoint never replaces a newer.
    pub version: i64,
    /// Epochs of the stream the state includes.
    pub epochs: i64,
    /// Time of the last epoch it includes.
    pub t: Option<f64>,
    /// When it was taken, Unix ms.
    pub taken_at_ms: i64,
    /// The session's state (`session::checkpoint`).
    pub state: Vec<u8>,
}

/// Why a lease could not be taken.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Acquire {
    /// Taken, under this epoch.
    Taken(i64),
    /// Another node holds it.
    Held(Lease),
}

/// Checks `fence` inside transaction `tx`; `Err(Fenced)` when the lease moved on.
macro_rules! check_fence {
    ($tx:expr, $fence:expr) => {
        if let Some(f) = $fence {
            let n = sqlx::query($crate::service::store::cluster::FENCE_SQL)
                .bind(&f.session)
                .bind(&f.owner)
                .bind(f.epoch)
                .execute(&mut *$tx)
                .await?
                .rows_affected();
            if n == 0 {
                return Err($crate::service::store::StoreError::Fenced(
                    f.session.clone(),
                ));
            }
        }
    };
}
pub(super) use check_fence;

/// The lease of `session`, if it has one.
pub(super) async fn lease(pool: &Pool, session: &str) -> Result<Option<Lease>, StoreError> {
    Ok(with_pool!(pool, p => sqlx::query_as::<_, Lease>(
        "SELECT session, owner, epoch, expires_ms, address FROM leases WHERE session = $1",
    )
    .bind(session)
    .fetch_optional(p)
    .await?))
}

/// Takes the lease of a **new** session for `owner`; false when the session already has
/// one (its id is taken, on this node or another).
pub(super) async fn create_lease(
    pool: &Pool,
    session: &str,
    owner: &str,
    address: &str,
    expires_ms: i64,
) -> Result<bool, StoreError> {
    let n = with_pool!(pool, p => sqlx::query(
        "INSERT INTO leases (session, owner, epoch, expires_ms, address) VALUES ($1, $2, 1, $3, $4)
         ON CONFLICT (session) DO NOTHING",
    )
    .bind(session)
    .bind(owner)
    .bind(expires_ms)
    .bind(address)
    .execute(p)
    .await?
    .rows_affected());
    Ok(n == 1)
}

/// Takes the lease of `session` for `owner` if it is free, expired at `now_ms`, already
/// `owner`'s, or `force` (its owner is known to be gone); the epoch goes up by one.
pub(super) async fn acquire(
    pool: &Pool,
    session: &str,
    owner: &str,
    address: &str,
    now_ms: i64,
    expires_ms: i64,
    force: bool,
) -> Result<Acquire, StoreError> {
    let taken: Option<i64> = with_pool!(pool, p => sqlx::query_scalar(
        "INSERT INTO leases (session, owner, epoch, expires_ms, address) VALUES ($1, $2, 1, $3, $4)
         ON CONFLICT (session) DO UPDATE SET owner = excluded.owner, epoch = leases.epoch + 1,
             expires_ms = excluded.expires_ms, address = excluded.address
         WHERE leases.expires_ms <= $5 OR leases.owner = $2 OR $6
         RETURNING epoch",
    )
    .bind(session)
    .bind(owner)
    .bind(expires_ms)
    .bind(address)
    .bind(now_ms)
    .bind(force)
    .fetch_optional(p)
    .await?);
    match taken {
        Some(epoch) => Ok(Acquire::Taken(epoch)),
        None => match lease(pool, session).await? {
            Some(held) => Ok(Acquire::Held(held)),
            // Deleted between the two statements: nothing to take.
            None => Err(StoreError::Fenced(session.to_owned())),
        },
    }
}

/// Extends every lease `owner` still holds to `expires_ms`; returns them with their
/// epochs (a session missing from the answer was taken by another node).
pub(super) async fn renew(
    pool: &Pool,
    owner: &str,
    expires_ms: i64,
) -> Result<Vec<(String, i64)>, StoreError> {
    let renewal = || async {
        with_pool!(pool, p => sqlx::query_as(
            "UPDATE leases SET expires_ms = $2 WHERE owner = $1 AND expires_ms > 0 RETURNING session, epoch",
        )
        .bind(owner)
        .bind(expires_ms)
        .fetch_all(p)
        .await)
    };
    Ok(super::retry_transient("lease renewal", renewal).await?)
}

/// Gives a lease up at once (a drain or a handover): the next node takes it without
/// waiting for it to expire. Only the holder under that epoch can release it.
pub(super) async fn release(pool: &Pool, fence: &Fence) -> Result<bool, StoreError> {
    let n = with_pool!(pool, p => sqlx::query(
        "UPDATE leases SET expires_ms = 0 WHERE session = $1 AND owner = $2 AND epoch = $3",
    )
    .bind(&fence.session)
    .bind(&fence.owner)
    .bind(fence.epoch)
    .execute(p)
    .await?
    .rows_affected());
    Ok(n == 1)
}

/// Checkpoints taken into one transaction at most.
const CHECKPOINT_GROUP: usize = 256;
/// Checkpoints waiting for the writer before owners wait for room.
const CHECKPOINT_QUEUE: usize = 4096;

type CheckpointReply = oneshot::Sender<Result<(), StoreError>>;

/// Group commit for checkpoints: a thousand sessions checkpointing once a second each
/// would be a thousand transactions a second; one writer task takes every checkpoint
/// queued at the moment into one transaction (each still fenced on its own) and answers
/// each owner after the commit.
#[derive(Debug, Clone)]
pub(super) struct CheckpointWriter {
    tx: mpsc::Sender<(Fence, Checkpoint, CheckpointReply)>,
}

impl CheckpointWriter {
    /// Starts the writer task on the current runtime.
    pub(super) fn spawn(pool: Pool) -> Self {
        let (tx, rx) = mpsc::channel(CHECKPOINT_QUEUE);
        tokio::spawn(run_checkpoints(pool, rx));
        CheckpointWriter { tx }
    }

    /// Writes `checkpoint` unless the lease moved on (fenced) or a newer one is stored;
    /// returns after the commit.
    pub(super) async fn put(
        &self,
        fence: &Fence,
        checkpoint: Checkpoint,
    ) -> Result<(), StoreError> {
        let (reply, answer) = oneshot::channel();
        let closed = || StoreError::Db(sqlx::Error::PoolClosed);
        self.tx
            .send((fence.clone(), checkpoint, reply))
            .await
            .map_err(|_| closed())?;
        answer.await.map_err(|_| closed())?
    }
}

async fn run_checkpoints(pool: Pool, mut rx: mpsc::Receiver<(Fence, Checkpoint, CheckpointReply)>) {
    let mut batch = Vec::with_capacity(CHECKPOINT_GROUP);
    while rx.recv_many(&mut batch, CHECKPOINT_GROUP).await > 0 {
        match super::retry_transient("checkpoint commit", || commit_checkpoints(&pool, &batch))
            .await
        {
            Ok(held) => {
                for ((fence, _, reply), held) in batch.drain(..).zip(held) {
                    let answer = if held {
                        Ok(())
                    } else {
                        Err(StoreError::Fenced(fence.session))
                    };
                    let _ = reply.send(answer);
                }
            }
            Err(e) => {
                let message = e.to_string();
                tracing::error!(error = %message, checkpoints = batch.len(), "checkpoint commit failed");
                for (_, _, reply) in batch.drain(..) {
                    let _ = reply.send(Err(StoreError::Write(format!(
                        "checkpoint commit: {message}"
                    ))));
                }
            }
        }
    }
}

/// The upsert of one checkpoint, never over a newer one.
const UPSERT_CHECKPOINT: &str = "INSERT INTO checkpoints (session, lease_epoch, version, epochs, t, taken_at_ms, state)
     VALUES ($1, $2, $3, $4, $5, $6, $7)
     ON CONFLICT (session) DO UPDATE SET lease_epoch = excluded.lease_epoch,
         version = excluded.version, epochs = excluded.epochs, t = excluded.t,
         taken_at_ms = excluded.taken_at_ms, state = excluded.state
     WHERE checkpoints.lease_epoch < excluded.lease_epoch
        OR (checkpoints.lease_epoch = excluded.lease_epoch AND checkpoints.version < excluded.version)";

/// Postgres: the fence check of a whole batch in one statement (arrays of session,
/// owner, epoch; one prepared statement whatever the batch size).
const PG_FENCE_BATCH: &str = "UPDATE leases AS l SET epoch = l.epoch
     FROM UNNEST($1::text[], $2::text[], $3::bigint[]) AS f(session, owner, epoch)
     WHERE l.session = f.session AND l.owner = f.owner AND l.epoch = f.epoch
     RETURNING l.session, l.owner, l.epoch";

/// Postgres: the upsert of a batch (one row per session) in one statement.
const PG_UPSERT_BATCH: &str = "INSERT INTO checkpoints (session, lease_epoch, version, epochs, t, taken_at_ms, state)
     SELECT * FROM UNNEST($1::text[], $2::bigint[], $3::bigint[], $4::bigint[], $5::float8[], $6::bigint[], $7::bytea[])
     ON CONFLICT (session) DO UPDATE SET lease_epoch = excluded.lease_epoch,
         version = excluded.version, epochs = excluded.epochs, t = excluded.t,
         taken_at_ms = excluded.taken_at_ms, state = excluded.state
     WHERE checkpoints.lease_epoch < excluded.lease_epoch
        OR (checkpoints.lease_epoch = excluded.lease_epoch AND checkpoints.version < excluded.version)";

/// Upserts every checkpoint of `batch` in one transaction; for each, whether its fence
/// held (a fenced one is not written). Postgres takes the batch in two statements (one
/// fence check, one upsert of the newest checkpoint per session); SQLite, whose
/// statements cost no round trip, row by row.
async fn commit_checkpoints(
    pool: &Pool,
    batch: &[(Fence, Checkpoint, CheckpointReply)],
) -> Result<Vec<bool>, sqlx::Error> {
    match pool {
        Pool::Postgres(p) => commit_checkpoints_pg(p, batch).await,
        Pool::Sqlite(p) => {
            let mut tx = p.begin().await?;
            let mut held = Vec::with_capacity(batch.len());
            for (f, c, _) in batch {
                let n = sqlx::query(FENCE_SQL)
                    .bind(&f.session)
                    .bind(&f.owner)
                    .bind(f.epoch)
                    .execute(&mut *tx)
                    .await?
                    .rows_affected();
                held.push(n > 0);
                if n > 0 {
                    bind_checkpoint(sqlx::query(UPSERT_CHECKPOINT), c)
                        .execute(&mut *tx)
                        .await?;
                }
            }
            tx.commit().await?;
            Ok(held)
        }
    }
}

fn bind_checkpoint<'q, DB: sqlx::Database>(
    q: sqlx::query::Query<'q, DB, <DB as sqlx::Database>::Arguments<'q>>,
    c: &'q Checkpoint,
) -> sqlx::query::Query<'q, DB, <DB as sqlx::Database>::Arguments<'q>>
where
    String: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
    i64: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
    Option<f64>: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
    Vec<u8>: sqlx::Encode<'q, DB> + sqlx::Type<DB>,
{
    q.bind(&c.session)
        .bind(c.lease_epoch)
        .bind(c.version)
        .bind(c.epochs)
        .bind(c.t)
        .bind(c.taken_at_ms)
        .bind(&c.state)
}

async fn commit_checkpoints_pg(
    pool: &sqlx::PgPool,
    batch: &[(Fence, Checkpoint, CheckpointReply)],
) -> Result<Vec<bool>, sqlx::Error> {
    let mut tx = pool.begin().await?;
    let sessions: Vec<&str> = batch.iter().map(|(f, _, _)| f.session.as_str()).collect();
    let owners: Vec<&str> = batch.iter().map(|(f, _, _)| f.owner.as_str()).collect();
    let epochs: Vec<i64> = batch.iter().map(|(f, _, _)| f.epoch).collect();
    let held: std::collections::HashSet<(String, String, i64)> = sqlx::query_as(PG_FENCE_BATCH)
        .bind(&sessions)
        .bind(&owners)
        .bind(&epochs)
        .fetch_all(&mut *tx)
        .await?
        .into_iter()
        .collect();
    let holds = |f: &Fence| held.contains(&(f.session.clone(), f.owner.clone(), f.epoch));
    // The newest checkpoint of each session whose fence held: one row is upserted once.
    let mut newest: std::collections::HashMap<&str, &Checkpoint> = Default::default();
    for (f, c, _) in batch.iter().filter(|(f, _, _)| holds(f)) {
        let slot = newest.entry(f.session.as_str()).or_insert(c);
        if (c.lease_epoch, c.version) > (slot.lease_epoch, slot.version) {
            *slot = c;
        }
    }
    if !newest.is_empty() {
        let rows: Vec<&Checkpoint> = newest.into_values().collect();
        sqlx::query(PG_UPSERT_BATCH)
            .bind(rows.iter().map(|c| c.session.as_str()).collect::<Vec<_>>())
            .bind(rows.iter().map(|c| c.lease_epoch).collect::<Vec<_>>())
            .bind(rows.iter().map(|c| c.version).collect::<Vec<_>>())
            .bind(rows.iter().map(|c| c.epochs).collect::<Vec<_>>())
            .bind(rows.iter().map(|c| c.t).collect::<Vec<_>>())
            .bind(rows.iter().map(|c| c.taken_at_ms).collect::<Vec<_>>())
            .bind(rows.iter().map(|c| c.state.as_slice()).collect::<Vec<_>>())
            .execute(&mut *tx)
            .await?;
    }
    tx.commit().await?;
    Ok(batch.iter().map(|(f, _, _)| holds(f)).collect())
}

/// The latest checkpoint of `session`.
pub(super) async fn checkpoint(
    pool: &Pool,
    session: &str,
) -> Result<Option<Checkpoint>, StoreError> {
    type Row = (String, i64, i64, i64, Option<f64>, i64, Vec<u8>);
    let row: Option<Row> = with_pool!(pool, p => sqlx::query_as(
        "SELECT session, lease_epoch, version, epochs, t, taken_at_ms, state FROM checkpoints WHERE session = $1",
    )
    .bind(session)
    .fetch_optional(p)
    .await?);
    Ok(row.map(
        |(session, lease_epoch, version, epochs, t, taken_at_ms, state)| Checkpoint {
            session,
            lease_epoch,
            version,
            epochs,
            t,
            taken_at_ms,
            state,
        },
    ))
}

/// Removes the lease and the checkpoint of a deleted session (inside its delete).
pub(super) const FORGET_SQL: [&str; 2] = [
    "DELETE FROM checkpoints WHERE session = $1",
    "DELETE FROM leases WHERE session = $1",
];
