//! Training jobs and the model cache. `POST /api/v1/models` hands a validated
//! job to [`Models::start`]; the job waits for a training slot (stage `queued`),
//! trains on the blocking pool (docs/architecture.md §A11) publishing its progress to its
//! [`Job`], and when done stores the model, then puts it in the cache, then
//! marks it ready. The cache is the [`ModelSource`] the session monitors build
//! from, so ingest never waits on training: actors only read an `Arc<AnyModel>`.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use serde::Serialize;
use serde_json::Value;
use tokio::sync::Semaphore;

use crate::service::config::Limits;
use crate::service::error::ApiError;
use crate::service::now_ms;
use crate::service::store::models::RESTARTED;
use crate::service::store::{Store, StoreError, StoredModel};
use navguard_core::learn::cv::CvParams;
use navguard_core::learn::{self, AnyModel, Dataset, LearnError, ModelKind, ModelParams, Progress};
use navguard_core::monitor::ModelSource;

/// Where a model is in its life.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelStatus {
    /// Queued or training.
    Training,
    /// Trained and stored; predicts.
    Ready,
    /// Training failed; `error` says why.
    Failed,
}

impl ModelStatus {
    /// The wire (and stored) name.
    pub fn as_str(self) -> &'static str {
        match self {
            ModelStatus::Training => "training",
            ModelStatus::Ready => "ready",
            ModelStatus::Failed => "failed",
        }
    }
}

/// A training job's progress, as the model record shows it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct JobProgress {
    /// Fraction done, 0 to 1.
    pub fraction: f64,
    /// Current stage, e.g. `queued`, `cv fold 2/5`.
    pub stage: String,
}

/// One running job: its progress (a short mutex, written by the training thread,
/// read by `GET`) and its cancellation flag (set by `DELETE` or shutdown).
#[derive(Debug)]
pub struct Job {
    progress: Mutex<JobProgress>,
    cancelled: AtomicBool,
}

impl Job {
    fn new() -> Self {
        Job {
            progress: Mutex::new(JobProgress {
                fraction: 0.0,
                stage: "queued".into(),
            }),
            cancelled: AtomicBool::new(false),
        }
    }

    /// The latest progress.
    pub fn progress(&self) -> JobProgress {
        self.progress
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// Asks the training loop to stop.
    pub fn cancel(&self) {
        self.cancelled.store(true, Ordering::Relaxed);
    }
}

impl Progress for Job {
    fn report(&self, fraction: f64, stage: &str) {
        let mut p = self.progress.lock().unwrap_or_else(|p| p.into_inner());
        // Clamp what the learner reports so the record always shows 0..1.
        p.fraction = if fraction.is_finite() {
            fraction.clamp(0.0, 1.0)
        } else {
            p.fraction
        };
        if p.stage != stage {
            p.stage = stage.to_owned();
        }
    }

    fn cancelled(&self) -> bool {
        self.cancelled.load(Ordering::Relaxed)
    }
}

/// A model as the API shows it (`ModelRecord` in the OpenAPI spec).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModelRecord {
    /// `m-` + 16 hex digits.
    pub id: String,
    /// The user's label.
    pub name: Option<String>,
    /// Model kind.
    pub kind: ModelKind,
    /// Status.
    pub status: ModelStatus,
    /// Parameters, defaults filled in (and CV's choice once ready).
    pub params: Value,
    /// Training samples.
    pub n: usize,
    /// Input dimension.
    pub dim: usize,
    /// While training.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub progress: Option<JobProgress>,
    /// When ready: `TrainingMetrics`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub metrics: Option<Value>,
    /// When failed: the reason.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// Creation time, Unix ms.
    pub created_ms: i64,
    /// End of training, Unix ms (null while training).
    pub finished_ms: Option<i64>,
}

/// A model in the cache: its record (progress read live from the job) and, when
/// ready, the model the monitors and `predict` use.
#[derive(Debug)]
struct Entry {
    record: ModelRecord,
    job: Option<Arc<Job>>,
    model: Option<Arc<AnyModel>>,
}

impl Entry {
    fn view(&self) -> ModelRecord {
        let mut record = self.record.clone();
        if record.status == ModelStatus::Training {
            record.progress = self.job.as_ref().map(|j| j.progress());
        }
        record
    }
}

/// A validated training request.
#[derive(Debug, Clone)]
pub struct TrainJob {
    /// The user's label.
    pub name: Option<String>,
    /// Checked parameters.
    pub params: ModelParams,
    /// Cross-validation block.
    pub cv: Option<CvParams>,
    /// Checked training set.
    pub data: Dataset,
}

/// Every model the server knows (training, ready, failed), the training slots,
/// and the store the models persist in. The service's [`ModelSource`].
#[derive(Debug)]
pub struct Models {
    entries: Mutex<HashMap<String, Entry>>,
    slots: Arc<Semaphore>,
    max_queued: usize,
    store: Store,
}

/// `m-` + 16 hex digits from the thread RNG.
fn new_id() -> String {
    format!("m-{:016x}", rand::random::<u64>())
}

fn parse_kind(kind: &str) -> Option<ModelKind> {
    serde_json::from_value(Value::String(kind.to_owned())).ok()
}

impl Models {
    /// An empty cache with the training slots of `limits`.
    pub fn new(store: Store, limits: &Limits) -> Self {
        Models {
            entries: Mutex::default(),
            slots: Arc::new(Semaphore::new(limits.max_concurrent_trainings.max(1))),
            max_queued: limits.max_queued_trainings.max(1),
            store,
        }
    }

    /// Loads the stored models: rows a stopped server left `training` become
    /// failed ("server restarted during training"); ready models are read into
    /// the cache (a row this build cannot read is shown as failed, and kept).
    pub async fn load(store: Store, limits: &Limits) -> Result<Self, StoreError> {
        store.fail_interrupted_models(now_ms()).await?;
        let models = Models::new(store.clone(), limits);
        let mut entries = HashMap::new();
        for row in store.models().await? {
            let entry = entry_from_row(row)?;
            entries.insert(entry.record.id.clone(), entry);
        }
        *models.lock() = entries;
        Ok(models)
    }

    fn lock(&self) -> MutexGuard<'_, HashMap<String, Entry>> {
        // Every operation is a single insert, remove or field update: poisoning
        // cannot leave the map half-changed.
        self.entries.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Every model, newest first.
    pub fn list(&self) -> Vec<ModelRecord> {
        let mut all: Vec<ModelRecord> = self.lock().values().map(Entry::view).collect();
        all.sort_by(|a, b| b.created_ms.cmp(&a.created_ms).then(b.id.cmp(&a.id)));
        all
    }

    /// One model's record.
    pub fn record(&self, id: &str) -> Result<ModelRecord, ApiError> {
        self.lock()
            .get(id)
            .map(Entry::view)
            .ok_or_else(|| not_found(id))
    }

    /// The model `id` if ready; 404 unknown, 409 training or failed.
    pub fn ready(&self, id: &str) -> Result<Arc<AnyModel>, ApiError> {
        let map = self.lock();
        let entry = map.get(id).ok_or_else(|| not_found(id))?;
        match (&entry.model, entry.record.status) {
            (Some(m), ModelStatus::Ready) => Ok(m.clone()),
            (_, status) => Err(ApiError::Conflict(format!(
                "model '{id}' is {}, not ready",
                status.as_str()
            ))),
        }
    }

    /// Deletes model `id`, cancelling its job if it is training. Sessions
    /// already built from it keep their copy.
    pub async fn delete(&self, id: &str) -> Result<(), ApiError> {
        let entry = self.lock().remove(id).ok_or_else(|| not_found(id))?;
        if let Some(job) = &entry.job {
            job.cancel();
        }
        self.store.delete_model(id).await?;
        Ok(())
    }

    /// Cancels every running job (server shutdown). Their rows stay `training`
    /// and become failed at the next start.
    pub fn cancel_all(&self) {
        for entry in self.lock().values() {
            if let Some(job) = &entry.job {
                job.cancel();
            }
        }
    }

    /// Registers and persists a job, then trains it in the background; answers at once.
    pub async fn start(self: &Arc<Self>, job: TrainJob) -> Result<ModelRecord, ApiError> {
        let record = ModelRecord {
            id: new_id(),
            name: job.name.clone(),
            kind: job.params.kind(),
            status: ModelStatus::Training,
            params: job.params.to_json(),
            n: job.data.n(),
            dim: job.data.dim(),
            progress: None,
            metrics: None,
            error: None,
            created_ms: now_ms(),
            finished_ms: None,
        };
        let handle = Arc::new(Job::new());
        {
            let mut map = self.lock();
            let running = map
                .values()
                .filter(|e| e.record.status == ModelStatus::Training)
                .count();
            if running >= self.max_queued {
                return Err(ApiError::Unavailable(format!(
                    "{running} training jobs are running or queued, the limit is {}; retry later",
                    self.max_queued
                )));
            }
            map.insert(
                record.id.clone(),
                Entry {
                    record: record.clone(),
                    job: Some(handle.clone()),
                    model: None,
                },
            );
        }
        let row = StoredModel {
            id: record.id.clone(),
            name: record.name.clone(),
            kind: record.kind.as_str().to_owned(),
            status: record.status.as_str().to_owned(),
            params: record.params.to_string(),
            n: record.n as i64,
            dim: record.dim as i64,
            metrics: None,
            error: None,
            model: None,
            created_ms: record.created_ms,
            finished_ms: None,
        };
        if let Err(e) = self.store.insert_model(&row).await {
            self.lock().remove(&record.id);
            return Err(e.into());
        }
        // The answer is the record as registered (`training`, `queued`), taken
        // before the job can move on.
        let answer = self.record(&record.id).unwrap_or(record);
        let models = self.clone();
        let id = answer.id.clone();
        tokio::spawn(async move { models.run(id, handle, job).await });
        Ok(answer)
    }

    /// The job's life: wait for a slot, train on the blocking pool, store, cache, announce.
    async fn run(self: Arc<Self>, id: String, handle: Arc<Job>, job: TrainJob) {
        let Ok(_permit) = self.slots.clone().acquire_owned().await else {
            return; // the semaphore is never closed
        };
        if handle.cancelled() {
            return self.finish(&id, Err(LearnError::Cancelled)).await;
        }
        handle.report(0.0, "starting");
        let progress = handle.clone();
        let outcome = tokio::task::spawn_blocking(move || {
            learn::train(&job.params, job.cv.as_ref(), &job.data, &*progress)
        })
        .await
        .unwrap_or_else(|e| {
            tracing::error!(model = %id, error = %e, "training task panicked");
            Err(LearnError::Numerical(
                "training stopped unexpectedly".into(),
            ))
        });
        self.finish(&id, outcome).await;
    }

    async fn finish(&self, id: &str, outcome: Result<learn::Trained, LearnError>) {
        let finished = now_ms();
        match outcome {
            Ok(trained) => {
                let params = trained.params.to_json();
                let metrics = serde_json::to_value(&trained.metrics).unwrap_or(Value::Null);
                let stored = self
                    .store
                    .finish_model_ready(
                        id,
                        &params.to_string(),
                        &metrics.to_string(),
                        &trained.model.to_stored_json(),
                        finished,
                    )
                    .await;
                match stored {
                    Ok(true) => {}
                    Ok(false) => return, // deleted meanwhile
                    Err(e) => {
                        tracing::error!(model = %id, error = %e, "storing a trained model failed");
                        let reason = "the trained model could not be stored";
                        return self.fail(id, reason.into(), finished, false).await;
                    }
                }
                let model = Arc::new(trained.model);
                let present = {
                    let mut map = self.lock();
                    match map.get_mut(id) {
                        Some(entry) => {
                            // Cache first, then the status that announces it.
                            entry.model = Some(model);
                            let r = &mut entry.record;
                            (r.params, r.metrics, r.finished_ms) =
                                (params, Some(metrics), Some(finished));
                            r.status = ModelStatus::Ready;
                            entry.job = None;
                            true
                        }
                        None => false,
                    }
                };
                if !present {
                    // Deleted between the store update and now: drop the row too.
                    let _ = self.store.delete_model(id).await;
                }
            }
            Err(LearnError::Cancelled) => {
                // Deleted: the entry and row are gone. Shutdown: the row stays
                // `training` and fails at the next start with RESTARTED.
                self.fail(id, RESTARTED.into(), finished, true).await;
            }
            Err(e) => self.fail(id, reason(&e), finished, false).await,
        }
    }

    async fn fail(&self, id: &str, reason: String, finished: i64, memory_only: bool) {
        if !memory_only && let Err(e) = self.store.finish_model_failed(id, &reason, finished).await
        {
            tracing::error!(model = %id, error = %e, "storing a training failure failed");
        }
        if let Some(entry) = self.lock().get_mut(id) {
            entry.record.status = ModelStatus::Failed;
            entry.record.error = Some(reason);
            entry.record.finished_ms = Some(finished);
            entry.job = None;
        }
    }
}

impl ModelSource for Models {
    fn model(&self, id: &str) -> Option<Arc<AnyModel>> {
        let map = self.lock();
        let entry = map.get(id)?;
        (entry.record.status == ModelStatus::Ready)
            .then(|| entry.model.clone())
            .flatten()
    }
}

/// The request path of the field a learning error names: `params.<f>` (or
/// `cv.<f>` as given), `data.<f>`; `None` for numerical failures and cancellation.
pub fn error_field(e: &LearnError) -> Option<String> {
    match e {
        LearnError::InvalidParams { field, .. } if field.starts_with("cv.") || field == "cv" => {
            Some(field.clone())
        }
        LearnError::InvalidParams { field, .. } if field.is_empty() => Some("params".into()),
        LearnError::InvalidParams { field, .. } => Some(format!("params.{field}")),
        LearnError::InvalidData { field, .. } if field.is_empty() => Some("data".into()),
        LearnError::InvalidData { field, .. } => Some(format!("data.{field}")),
        LearnError::Numerical(_) | LearnError::Cancelled => None,
    }
}

/// A failed job's reason: the error with its field as the request names it.
fn reason(e: &LearnError) -> String {
    match (e, error_field(e)) {
        (
            LearnError::InvalidParams { reason, .. } | LearnError::InvalidData { reason, .. },
            Some(field),
        ) => format!("{field}: {reason}"),
        _ => e.to_string(),
    }
}

fn not_found(id: &str) -> ApiError {
    ApiError::NotFound(format!("no model '{id}'"))
}

fn entry_from_row(row: StoredModel) -> Result<Entry, StoreError> {
    let corrupt = |what: &str| StoreError::Corrupt(format!("model '{}': {what}", row.id));
    let kind = parse_kind(&row.kind).ok_or_else(|| corrupt("unknown kind"))?;
    let json =
        |text: &str| serde_json::from_str::<Value>(text).map_err(|e| corrupt(&e.to_string()));
    let mut record = ModelRecord {
        id: row.id.clone(),
        name: row.name.clone(),
        kind,
        status: ModelStatus::Failed,
        params: json(&row.params)?,
        n: row.n.max(0) as usize,
        dim: row.dim.max(0) as usize,
        progress: None,
        metrics: row.metrics.as_deref().map(json).transpose()?,
        error: row.error.clone(),
        created_ms: row.created_ms,
        finished_ms: row.finished_ms,
    };
    let mut model = None;
    if row.status == "ready" {
        match row.model.as_deref().map(AnyModel::from_stored_json) {
            Some(Ok(m)) => {
                record.status = ModelStatus::Ready;
                model = Some(Arc::new(m));
            }
            Some(Err(e)) => record.error = Some(format!("stored model unreadable: {e}")),
            None => record.error = Some("stored model missing".into()),
        }
        if record.status != ModelStatus::Ready {
            record.metrics = None;
        }
    }
    Ok(Entry {
        record,
        job: None,
        model,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn job_progress_is_clamped_and_cancellation_is_seen() {
        let job = Job::new();
        assert_eq!(job.progress().stage, "queued");
        job.report(1.7, "cv fold 2/5");
        assert_eq!(
            job.progress(),
            JobProgress {
                fraction: 1.0,
                stage: "cv fold 2/5".into()
            }
        );
        job.report(f64::NAN, "solve");
        assert_eq!(job.progress().fraction, 1.0);
        assert!(!Progress::cancelled(&job));
        job.cancel();
        assert!(Progress::cancelled(&job));
    }

    #[test]
    fn ids_are_m_and_16_hex_digits() {
        let id = new_id();
        assert_eq!(id.len(), 18);
        assert!(id.starts_with("m-"));
        assert!(id[2..].bytes().all(|c| c.is_ascii_hexdigit()));
    }
}
