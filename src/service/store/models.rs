//! Persistence of trained models (docs/architecture.md §A4): one row per model with its
//! status, parameters, training metrics or failure reason, and the model itself
//! as versioned JSON (`AnyModel::to_stored_json`). Rows are written when a job
//! starts and again when it ends; a row left `training` by a stopped server is
//! marked failed at the next start.

use super::{Store, StoreError};

/// Why a row is marked failed when the server starts.
pub const RESTARTED: &str = "server restarted during training";

/// A stored model row. `model` is the stored JSON, present only when ready. Read from
/// either backend by column name (`sqlx::FromRow`).
#[derive(Debug, Clone, PartialEq, sqlx::FromRow)]
pub struct StoredModel {
    /// `m-` + 16 hex digits.
    pub id: String,
    /// The user's label.
    pub name: Option<String>,
    /// Wire name of the kind (`lssvm`, `lw-lssvm`, `svm`, `ocsvm`).
    pub kind: String,
    /// `training`, `ready` or `failed`.
    pub status: String,
    /// Parameters as JSON text (effective ones once ready).
    pub params: String,
    /// Training samples.
    pub n: i64,
    /// Input dimension.
    pub dim: i64,
    /// Training metrics as JSON text (ready).
    pub metrics: Option<String>,
    /// Failure reason (failed).
    pub error: Option<String>,
    /// The model, `AnyModel::to_stored_json` (ready).
    pub model: Option<String>,
    /// Creation time, Unix ms.
    pub created_ms: i64,
    /// End of training, Unix ms.
    pub finished_ms: Option<i64>,
}

impl Store {
    /// Inserts a new model row (a job that just started).
    pub async fn insert_model(&self, m: &StoredModel) -> Result<(), StoreError> {
        with_pool!(&self.pool, p => sqlx::query(
            "INSERT INTO models (id, name, kind, status, params, n, dim, metrics, error, model, created_ms, finished_ms)
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12)",
        )
        .bind(&m.id)
        .bind(&m.name)
        .bind(&m.kind)
        .bind(&m.status)
        .bind(&m.params)
        .bind(m.n)
        .bind(m.dim)
        .bind(&m.metrics)
        .bind(&m.error)
        .bind(&m.model)
        .bind(m.created_ms)
        .bind(m.finished_ms)
        .execute(p)
        .await?.rows_affected());
        Ok(())
    }

    /// Marks a training row ready with its model. False when the row is gone or
    /// no longer training (the model was deleted meanwhile).
    pub async fn finish_model_ready(
        &self,
        id: &str,
        params: &str,
        metrics: &str,
        model: &str,
        finished_ms: i64,
    ) -> Result<bool, StoreError> {
        let done = with_pool!(&self.pool, p => sqlx::query(
            "UPDATE models SET status = 'ready', params = $1, metrics = $2, model = $3, finished_ms = $4
             WHERE id = $5 AND status = 'training'",
        )
        .bind(params)
        .bind(metrics)
        .bind(model)
        .bind(finished_ms)
        .bind(id)
        .execute(p)
        .await?
        .rows_affected());
        Ok(done > 0)
    }

    /// Marks a training row failed with `error`. False when the row is gone.
    pub async fn finish_model_failed(
        &self,
        id: &str,
        error: &str,
        finished_ms: i64,
    ) -> Result<bool, StoreError> {
        let done = with_pool!(&self.pool, p => sqlx::query(
            "UPDATE models SET status = 'failed', error = $1, finished_ms = $2
             WHERE id = $3 AND status = 'training'",
        )
        .bind(error)
        .bind(finished_ms)
        .bind(id)
        .execute(p)
        .await?
        .rows_affected());
        Ok(done > 0)
    }

    /// Deletes a model row; true if it existed.
    pub async fn delete_model(&self, id: &str) -> Result<bool, StoreError> {
        let done = with_pool!(&self.pool, p => sqlx::query("DELETE FROM models WHERE id = $1")
            .bind(id)
            .execute(p)
            .await?
            .rows_affected());
        Ok(done > 0)
    }

    /// Marks every row still `training` as failed ([`RESTARTED`]): its job died
    /// with the previous process. Returns how many.
    pub async fn fail_interrupted_models(&self, finished_ms: i64) -> Result<u64, StoreError> {
        let done = with_pool!(&self.pool, p => sqlx::query(
            "UPDATE models SET status = 'failed', error = $1, finished_ms = $2 WHERE status = 'training'",
        )
        .bind(RESTARTED)
        .bind(finished_ms)
        .execute(p)
        .await?
        .rows_affected());
        Ok(done)
    }

    /// Every model row, oldest first, with the model text of ready ones.
    pub async fn models(&self) -> Result<Vec<StoredModel>, StoreError> {
        let rows: Vec<StoredModel> = with_pool!(&self.pool, p => sqlx::query_as(
            "SELECT id, name, kind, status, params, n, dim, metrics, error, model, created_ms, finished_ms
             FROM models ORDER BY created_ms, id",
        )
        .fetch_all(p)
        .await?);
        Ok(rows)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(id: &str, created_ms: i64) -> StoredModel {
        StoredModel {
            id: id.into(),
            name: Some("label".into()),
            kind: "lssvm".into(),
            status: "training".into(),
            params: "{}".into(),
            n: 10,
            dim: 2,
            metrics: None,
            error: None,
            model: None,
            created_ms,
            finished_ms: None,
        }
    }

    #[tokio::test]
    async fn rows_left_training_fail_on_restart_and_finished_rows_survive() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.db");
        {
            let store = Store::open(&path).await.unwrap();
            for (id, t) in [("m-a", 1), ("m-b", 2), ("m-c", 3)] {
                store.insert_model(&row(id, t)).await.unwrap();
            }
            assert!(
                store
                    .finish_model_ready("m-a", "{\"gamma\":1}", "{}", "MODEL", 7)
                    .await
                    .unwrap()
            );
            assert!(store.finish_model_failed("m-b", "bad", 8).await.unwrap());
            // A finished row is not finished twice.
            assert!(!store.finish_model_failed("m-a", "late", 9).await.unwrap());
            store.close().await;
        }
        let store = Store::open(&path).await.unwrap();
        assert_eq!(store.fail_interrupted_models(10).await.unwrap(), 1);
        let rows = store.models().await.unwrap();
        let got: Vec<_> = rows
            .iter()
            .map(|m| (m.id.as_str(), m.status.as_str(), m.error.as_deref()))
            .collect();
        assert_eq!(
            got,
            [
                ("m-a", "ready", None),
                ("m-b", "failed", Some("bad")),
                ("m-c", "failed", Some(RESTARTED))
            ]
        );
        assert_eq!(rows[0].model.as_deref(), Some("MODEL"));
        assert_eq!(rows[0].params, "{\"gamma\":1}");
        assert_eq!(rows[0].finished_ms, Some(7));
        assert!(store.delete_model("m-a").await.unwrap());
        assert!(!store.delete_model("m-a").await.unwrap());
        assert!(
            !store
                .finish_model_ready("m-a", "{}", "{}", "M", 11)
                .await
                .unwrap()
        );
    }
}
