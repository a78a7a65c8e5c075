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
    Ok(with_pool!(pool, p => sqlx::query_as(
        "UPDATE leases SET expires_ms = $2 WHERE owner = $1 AND expires_ms > 0 RETURNING session, epoch",
    )
    .bind(owner)
    .bind(expires_ms)
    .fetch_all(p)
    .await?))
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

/// Writes `checkpoint` unless the lease moved on (fenced) or a newer one is stored.
pub(super) async fn put_checkpoint(
    pool: &Pool,
    fence: &Fence,
    c: &Checkpoint,
) -> Result<(), StoreError> {
    with_pool!(pool, p => {
        let mut tx = p.begin().await?;
        check_fence!(tx, Some(fence));
        sqlx::query(
            "INSERT INTO checkpoints (session, lease_epoch, version, epochs, t, taken_at_ms, state)
             VALUES ($1, $2, $3, $4, $5, $6, $7)
             ON CONFLICT (session) DO UPDATE SET lease_epoch = excluded.lease_epoch,
                 version = excluded.version, epochs = excluded.epochs, t = excluded.t,
                 taken_at_ms = excluded.taken_at_ms, state = excluded.state
             WHERE checkpoints.lease_epoch < excluded.lease_epoch
                OR (checkpoints.lease_epoch = excluded.lease_epoch AND checkpoints.version < excluded.version)",
        )
        .bind(&c.session)
        .bind(c.lease_epoch)
        .bind(c.version)
        .bind(c.epochs)
        .bind(c.t)
        .bind(c.taken_at_ms)
        .bind(&c.state)
        .execute(&mut *tx)
        .await?;
        tx.commit().await?;
    });
    Ok(())
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
