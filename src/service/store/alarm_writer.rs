//! Group commit for the alarm log. Every alarm is committed before it is announced
//! (docs/architecture.md §A4), but when many sessions raise alarms at once (1,000 federated
//! sessions all fail the same epoch), one transaction per alarm serialises them
//! on SQLite's single writer (and pay one fsync each on Postgres). One writer task takes every
//! write queued at the moment, runs them in one transaction, and answers each caller
//! only after the commit: the durability guarantee is unchanged, the commits
//! are shared. Clearing entries (a test back to healthy, a stream starting afresh) goes
//! through the same queue, so a burst of returns to healthy or of streams attaching is a
//! few shared commits too, in each session's order.

use tokio::sync::{mpsc, oneshot};

use super::cluster::{FENCE_SQL, Fence};
use super::{Pool, StoreError};
use crate::service::wire::AlarmRecord;

/// Alarms taken into one transaction at most.
const GROUP: usize = 512;
/// Alarms waiting for the writer before callers wait for room.
const QUEUE: usize = 4096;

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

/// What a queued write does: insert an entry, or close open entries (one test's, or a
/// whole session's). Clears go through the same queue as inserts so that they share the
/// inserts' commits and keep their order per session: a burst of sessions returning to
/// healthy, or a thousand streams attaching at once, is a few transactions, not one each
/// (SQLite has one writer; every extra transaction waits for the previous one).
#[derive(Debug)]
enum Op {
    Insert {
        alarm: AlarmRecord,
        key: AlarmKey,
    },
    /// `UPDATE … SET cleared_t = COALESCE(t_clear, t)` for `(monitor, test)` of the
    /// session, or (`test: None`) every open entry of the session with `cleared_t = t`.
    Clear {
        session: String,
        test: Option<(String, String)>,
        t: Option<f64>,
    },
}

/// What became of one queued write.
enum Done {
    /// The entry's id (the stored one when its key named an entry already there).
    Id(i64),
    /// The clear ran.
    Cleared,
    /// The fence no longer holds: nothing was written.
    Fenced,
}

/// One queued write.
struct Pending {
    op: Op,
    fence: Option<Fence>,
    reply: oneshot::Sender<Result<Done, StoreError>>,
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

    async fn submit(&self, op: Op, fence: Option<Fence>) -> Result<Done, StoreError> {
        let (reply, answer) = oneshot::channel();
        self.tx
            .send(Pending { op, fence, reply })
            .await
            .map_err(|_| StoreError::Db(sqlx::Error::PoolClosed))?;
        answer
            .await
            .map_err(|_| StoreError::Db(sqlx::Error::PoolClosed))?
    }

    /// Commits `alarm` (with whatever else is queued) and returns its id (the existing
    /// entry's id when `key` names one already stored).
    pub(super) async fn insert(
        &self,
        alarm: AlarmRecord,
        key: AlarmKey,
        fence: Option<Fence>,
    ) -> Result<i64, StoreError> {
        let session = alarm.session.clone();
        match self.submit(Op::Insert { alarm, key }, fence).await? {
            Done::Id(id) => Ok(id),
            Done::Fenced => Err(StoreError::Fenced(session)),
            Done::Cleared => Err(StoreError::Corrupt("an insert answered as a clear".into())),
        }
    }

    /// Closes the open entries of `(monitor, test)` of `session` (`test: Some`) at
    /// `t` (`None`: each entry's own `t`), or every open entry of the session
    /// (`test: None`, at each entry's own `t`); returns after the commit.
    pub(super) async fn clear(
        &self,
        session: &str,
        test: Option<(&str, &str)>,
        t: Option<f64>,
        fence: Option<Fence>,
    ) -> Result<(), StoreError> {
        let op = Op::Clear {
            session: session.to_owned(),
            test: test.map(|(m, t)| (m.to_owned(), t.to_owned())),
            t,
        };
        match self.submit(op, fence).await? {
            Done::Fenced => Err(StoreError::Fenced(session.to_owned())),
            Done::Cleared | Done::Id(_) => Ok(()),
        }
    }
}

async fn run(pool: Pool, mut rx: mpsc::Receiver<Pending>) {
    let mut batch = Vec::with_capacity(GROUP);
    while rx.recv_many(&mut batch, GROUP).await > 0 {
        match super::retry_transient("alarm commit", || commit(&pool, &batch)).await {
            Ok(done) => {
                for (pending, done) in batch.drain(..).zip(done) {
                    let _ = pending.reply.send(Ok(done));
                }
            }
            Err(e) => {
                let message = e.to_string();
                tracing::error!(error = %message, writes = batch.len(), "alarm commit failed");
                for pending in batch.drain(..) {
                    let _ = pending
                        .reply
                        .send(Err(StoreError::Write(format!("alarm commit: {message}"))));
                }
            }
        }
    }
}

/// Rows of one multi-row `INSERT` at most: 13 values a row stays under SQLite's 32,766
/// bound parameters and Postgres' 65,535.
const INSERT_ROWS: usize = 512;

/// The columns an entry is matched back by from the `RETURNING` rows of a multi-row
/// insert: everything that names it, and `t` (as bits) for the unkeyed ones.
type RowKey = (String, String, String, String, String, i64, i64, u64);

fn row_key(alarm: &AlarmRecord, key: &AlarmKey) -> RowKey {
    (
        alarm.session.clone(),
        alarm.monitor.clone(),
        alarm.test.clone(),
        alarm.state.as_str().to_owned(),
        alarm.severity.as_str().to_owned(),
        key.stream as i64,
        key.epoch_index as i64,
        t_bits(alarm.t),
    )
}

/// `t`'s bits with −0 as +0 (a store may give back either).
fn t_bits(t: f64) -> u64 {
    (t + 0.0).to_bits()
}

/// Inserts the queued entries `rows` (`(index in the batch, entry, key)`) with one
/// multi-row `INSERT … ON CONFLICT DO NOTHING RETURNING` per [`INSERT_ROWS`], inside the
/// writer's transaction `$tx`, and sets each one's [`Done::Id`] in `$done`. Returned rows
/// are matched back by what names them (the order of `RETURNING` rows is not
/// guaranteed); an entry with no returned row was already stored under its key (replayed
/// after a failover) and takes the stored entry's id. One statement per chunk instead of
/// one per entry: on SQLite every statement is a round trip to its worker thread, and one
/// per entry would make those most of a burst's commit time (docs/performance.md).
macro_rules! insert_rows {
    ($tx:ident, $rows:expr, $done:ident) => {
        for chunk in $rows.chunks(INSERT_ROWS) {
            let mut q = sqlx::QueryBuilder::new(
                "INSERT INTO alarms (session, monitor, test, state, t, statistic, threshold, dof, delay_s, raised_at_ms, severity, stream, epoch_index) ",
            );
            q.push_values(chunk, |mut b, (_, alarm, key)| {
                b.push_bind(alarm.session.as_str())
                    .push_bind(alarm.monitor.as_str())
                    .push_bind(alarm.test.as_str())
                    .push_bind(alarm.state.as_str())
                    .push_bind(alarm.t)
                    .push_bind(alarm.statistic)
                    .push_bind(alarm.threshold)
                    .push_bind(i64::from(alarm.dof))
                    .push_bind(alarm.delay_s)
                    .push_bind(alarm.raised_at_ms)
                    .push_bind(alarm.severity.as_str())
                    .push_bind(key.stream as i64)
                    .push_bind(key.epoch_index as i64);
            });
            q.push(
                " ON CONFLICT (session, stream, epoch_index, monitor, test, state, severity) WHERE stream > 0 DO NOTHING \
                 RETURNING id, session, monitor, test, state, severity, stream, epoch_index, t",
            );
            let returned: Vec<(i64, String, String, String, String, String, i64, i64, f64)> =
                q.build_query_as().fetch_all(&mut *$tx).await?;
            let mut ids: std::collections::HashMap<RowKey, Vec<i64>> =
                std::collections::HashMap::with_capacity(returned.len());
            for (id, session, monitor, test, state, severity, stream, epoch_index, t) in returned {
                ids.entry((session, monitor, test, state, severity, stream, epoch_index, t_bits(t)))
                    .or_default()
                    .push(id);
            }
            // Identical unkeyed entries take their ids in insertion order.
            for list in ids.values_mut() {
                list.sort_unstable_by(|a, b| b.cmp(a));
            }
            for (index, alarm, key) in chunk {
                let id = match ids.get_mut(&row_key(alarm, key)).and_then(Vec::pop) {
                    Some(id) => id,
                    // An unkeyed entry is always inserted: no row for it is a fault, and
                    // the whole group is refused (rolled back) rather than misnumbered.
                    None if key.stream == 0 => return Err(sqlx::Error::RowNotFound),
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
                    .fetch_one(&mut *$tx)
                    .await?,
                };
                $done[*index] = Some(Done::Id(id));
            }
        }
    };
}

/// Runs every write of `batch` in one transaction, in order; what became of each, in
/// order ([`Done::Fenced`] for a write whose fence no longer holds: not written, the
/// others are). Consecutive inserts go in as multi-row inserts ([`insert_rows!`]); a clear
/// first inserts the entries queued before it, so each session's order holds.
async fn commit(pool: &Pool, batch: &[Pending]) -> Result<Vec<Done>, sqlx::Error> {
    with_pool!(pool, p => {
        let mut tx = p.begin().await?;
        let mut done: Vec<Option<Done>> = batch.iter().map(|_| None).collect();
        let mut rows: Vec<(usize, &AlarmRecord, &AlarmKey)> = Vec::with_capacity(batch.len());
        for (index, Pending { op, fence, .. }) in batch.iter().enumerate() {
            if let Some(f) = fence {
                let held = sqlx::query(FENCE_SQL)
                    .bind(&f.session)
                    .bind(&f.owner)
                    .bind(f.epoch)
                    .execute(&mut *tx)
                    .await?
                    .rows_affected();
                if held == 0 {
                    done[index] = Some(Done::Fenced);
                    continue;
                }
            }
            match op {
                Op::Insert { alarm, key } => rows.push((index, alarm, key)),
                Op::Clear { session, test, t } => {
                    insert_rows!(tx, rows, done);
                    rows.clear();
                    match test {
                        Some((monitor, test)) => sqlx::query("UPDATE alarms SET cleared_t = COALESCE($1, t) WHERE session = $2 AND monitor = $3 AND test = $4 AND cleared_t IS NULL")
                            .bind(t)
                            .bind(session)
                            .bind(monitor)
                            .bind(test)
                            .execute(&mut *tx)
                            .await?,
                        None => sqlx::query("UPDATE alarms SET cleared_t = t WHERE session = $1 AND cleared_t IS NULL")
                            .bind(session)
                            .execute(&mut *tx)
                            .await?,
                    };
                    done[index] = Some(Done::Cleared);
                }
            }
        }
        insert_rows!(tx, rows, done);
        // Every write was answered above (fenced, inserted or cleared); one that was not
        // rolls the group back rather than be answered with a guess.
        let done = done
            .into_iter()
            .collect::<Option<Vec<Done>>>()
            .ok_or_else(|| sqlx::Error::Protocol("an alarm write went unanswered".into()))?;
        tx.commit().await?;
        Ok(done)
    })
}
