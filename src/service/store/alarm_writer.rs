//! Group commit for alarms. Every alarm is committed before it is announced
//! (docs/architecture.md §A4), but when many sessions raise alarms at once (1,000 federated
//! sessions all fail the same epoch), one transaction per alarm serialises them
//! on SQLite's single writer (and pay one fsync each on Postgres). One writer task takes every alarm queued at the
//! moment, inserts them in one transaction, and answers each caller with its id
//! only after the commit: the durability guarantee is unchanged, the commits
//! are shared.

use tokio::sync::{mpsc, oneshot};

use super::{Pool, StoreError};
use crate::service::wire::AlarmRecord;

/// Alarms taken into one transaction at most.
const GROUP: usize = 512;
/// Alarms waiting for the writer before callers wait for room.
const QUEUE: usize = 4096;

type Reply = oneshot::Sender<Result<i64, StoreError>>;

/// The handle callers hold: a queue to the writer task.
#[derive(Debug, Clone)]
pub(super) struct AlarmWriter {
    tx: mpsc::Sender<(AlarmRecord, Reply)>,
}

impl AlarmWriter {
    /// Starts the writer task on the current runtime.
    pub(super) fn spawn(pool: Pool) -> Self {
        let (tx, rx) = mpsc::channel(QUEUE);
        tokio::spawn(run(pool, rx));
        AlarmWriter { tx }
    }

    /// Commits `alarm` (with whatever else is queued) and returns its id.
    pub(super) async fn insert(&self, alarm: AlarmRecord) -> Result<i64, StoreError> {
        let (reply, answer) = oneshot::channel();
        self.tx
            .send((alarm, reply))
            .await
            .map_err(|_| StoreError::Db(sqlx::Error::PoolClosed))?;
        answer
            .await
            .map_err(|_| StoreError::Db(sqlx::Error::PoolClosed))?
    }
}

async fn run(pool: Pool, mut rx: mpsc::Receiver<(AlarmRecord, Reply)>) {
    let mut batch = Vec::with_capacity(GROUP);
    while rx.recv_many(&mut batch, GROUP).await > 0 {
        match commit(&pool, &batch).await {
            Ok(ids) => {
                for ((_, reply), id) in batch.drain(..).zip(ids) {
                    let _ = reply.send(Ok(id));
                }
            }
            Err(e) => {
                let message = e.to_string();
                tracing::error!(error = %message, alarms = batch.len(), "alarm commit failed");
                for (_, reply) in batch.drain(..) {
                    let _ = reply.send(Err(StoreError::Corrupt(format!(
                        "alarm commit failed: {message}"
                    ))));
                }
            }
        }
    }
}

/// Inserts every alarm of `batch` in one transaction; ids in order.
async fn commit(pool: &Pool, batch: &[(AlarmRecord, Reply)]) -> Result<Vec<i64>, sqlx::Error> {
    with_pool!(pool, p => {
        let mut tx = p.begin().await?;
        let mut ids = Vec::with_capacity(batch.len());
        for (alarm, _) in batch {
            let id: i64 = sqlx::query_scalar(
                "INSERT INTO alarms (session, monitor, test, state, t, statistic, threshold, dof, delay_s, raised_at_ms, cleared_t, severity)
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, NULL, $11) RETURNING id",
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
            .fetch_one(&mut *tx)
            .await?;
            ids.push(id);
        }
        tx.commit().await?;
        Ok(ids)
    })
}
