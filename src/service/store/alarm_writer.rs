//! Group commit for alarms. Every alarm is committed before it is announced
//! (docs/architecture.md §A4), but when many sessions raise alarms at once (1,000 federated
//! sessions all fail the same epoch), one transaction per alarm serialises them
//! on SQLite's single writer (and pay one fsync each on Postgres). One writer task takes every alarm queued at the
//! moment, inserts them in one transaction, and answers each caller with its id
//! only after the commit: the durability guarantee is unchanged, the commits
//! are shared.

use tokio::sync::{mpsc, oneshot};

use super::cluster::{FENCE_SQL, Fence};
use super::{Pool, StoreError};
use crate::service::wire::AlarmRecord;

/// Alarms taken into one transaction at most.
const GROUP: usize = 512;
/// Alarms waiting for the writer before callers wait for room.
const QUEUE: usize = 4096;

type Reply = oneshot::Sender<Result<i64, StoreError>>;

/// Where an entry was raised: the stream (its attach time, Unix ms) and the epoch's index
/// in it. With the session, monitor, test, state and severity it names the entry, so the
/// same transition raised again (the epochs after a checkpoint, replayed after a failover)
/// is the same log entry, not a second one (docs/deployment.md, Guarantees). 0: unkeyed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AlarmKey {
    /// The stream's attach time, Unix ms (0: unkeyed).
    pub stream: u64,
    /// The epoch's index in the stream.
    pub epoch_index: u64,
}

/// One queued entry.
struct Pending {
    alarm: AlarmRecord,
    key: AlarmKey,
    fence: Option<Fence>,
    reply: Reply,
}

/// The handle callers hold: a queue to the writer task.
#[derive(Debug, Clone)]
pub(super) struct AlarmWriter {
    tx: mpsc::Sender<Pending>,
}

impl AlarmWriter {
    /// Starts the writer task on the current runtime.
    pub(super) fn spawn(pool: Pool) -> Self {
        let (tx, rx) = mpsc::channel(QUEUE);
        tokio::spawn(run(pool, rx));
        AlarmWriter { tx }
    }

    /// Commits `alarm` (with whatever else is queued) and returns its id (the existing
    /// entry's id when `key` names one already stored).
    pub(super) async fn insert(
        &self,
        alarm: AlarmRecord,
        key: AlarmKey,
        fence: Option<Fence>,
    ) -> Result<i64, StoreError> {
        let (reply, answer) = oneshot::channel();
        self.tx
            .send(Pending {
                alarm,
                key,
                fence,
                reply,
            })
            .await
            .map_err(|_| StoreError::Db(sqlx::Error::PoolClosed))?;
        answer
            .await
            .map_err(|_| StoreError::Db(sqlx::Error::PoolClosed))?
    }
}

async fn run(pool: Pool, mut rx: mpsc::Receiver<Pending>) {
    let mut batch = Vec::with_capacity(GROUP);
    while rx.recv_many(&mut batch, GROUP).await > 0 {
        match commit(&pool, &batch).await {
            Ok(ids) => {
                for (pending, id) in batch.drain(..).zip(ids) {
                    let answer = id.ok_or_else(|| StoreError::Fenced(pending.alarm.session));
                    let _ = pending.reply.send(answer);
                }
            }
            Err(e) => {
                let message = e.to_string();
                tracing::error!(error = %message, alarms = batch.len(), "alarm commit failed");
                for pending in batch.drain(..) {
                    let _ = pending.reply.send(Err(StoreError::Corrupt(format!(
                        "alarm commit failed: {message}"
                    ))));
                }
            }
        }
    }
}

/// Inserts every alarm of `batch` in one transaction; ids in order, `None` for an entry
/// whose fence no longer holds (not written; the others are).
async fn commit(pool: &Pool, batch: &[Pending]) -> Result<Vec<Option<i64>>, sqlx::Error> {
    with_pool!(pool, p => {
        let mut tx = p.begin().await?;
        let mut ids = Vec::with_capacity(batch.len());
        for Pending { alarm, key, fence, .. } in batch {
            if let Some(f) = fence {
                let held = sqlx::query(FENCE_SQL)
                    .bind(&f.session)
                    .bind(&f.owner)
                    .bind(f.epoch)
                    .execute(&mut *tx)
                    .await?
                    .rows_affected();
                if held == 0 {
                    ids.push(None);
                    continue;
                }
            }
            let inserted: Option<i64> = sqlx::query_scalar(
                "INSERT INTO alarms (session, monitor, test, state, t, statistic, threshold, dof, delay_s, raised_at_ms, cleared_t, severity, stream, epoch_index)
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, NULL, $11, $12, $13)
                 ON CONFLICT (session, stream, epoch_index, monitor, test, state, severity) WHERE stream > 0 DO NOTHING
                 RETURNING id",
            )
            .bind(&alarm.session)
            .bind(&alarm.monitor)
            .bind(&alarm.test)
            .bind(alarm.state.as_str())
            .bind(alarm.t)
            .bind(alarm.statistic)
            .bind(alarm.threshold)
            .bind(i64::from(alarm.dof))
            .bind(alarm.delay_s)
            .bind(alarm.raised_at_ms)
            .bind(alarm.severity.as_str())
            .bind(key.stream as i64)
            .bind(key.epoch_index as i64)
            .fetch_optional(&mut *tx)
            .await?;
            let id = match inserted {
                Some(id) => id,
                // Raised before (replayed after a failover): the stored entry's id.
                None => sqlx::query_scalar(
                    "SELECT id FROM alarms WHERE session = $1 AND stream = $2 AND epoch_index = $3 AND monitor = $4 AND test = $5 AND state = $6 AND severity = $7",
                )
                .bind(&alarm.session)
                .bind(key.stream as i64)
                .bind(key.epoch_index as i64)
                .bind(&alarm.monitor)
                .bind(&alarm.test)
                .bind(alarm.state.as_str())
                .bind(alarm.severity.as_str())
                .fetch_one(&mut *tx)
                .await?,
            };
            ids.push(Some(id));
        }
        tx.commit().await?;
        Ok(ids)
    })
}
