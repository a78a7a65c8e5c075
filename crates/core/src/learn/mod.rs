//! Learning: kernels, LS-SVM regression (batch, locally weighted, online),
//! C-SVC and one-class SVM by SMO, cross-validation. Sits beside `detect/` in
//! the flow: the channel, rimu and tacan monitors predict with these models, and
//! the service trains them on its blocking pool ([`model::train`]). Pure: no I/O,
//! no async.
//!
//! Every algorithm has linfa's shape (docs/architecture.md §A11): `XParams` (what a REST body
//! deserialises into) → `check()` → `ValidXParams` → `fit(&Dataset)` → `XModel`
//! (serde, with a format version) → `predict`. `XParams::fit` is the shortcut
//! `check()?.fit(..)`. Only [`model`] wraps an algorithm's own model into the stored
//! [`AnyModel`]; the algorithms never import it.

pub mod cv;
pub mod dataset;
pub mod kernel;
pub mod local;
pub mod lssvm;
pub mod lssvm_exact;
pub mod lssvm_solve;
pub mod metrics;
pub mod model;
pub mod online;
pub mod outlier;
pub mod scale;
pub mod svm;
pub mod variance;

pub use dataset::Dataset;
pub use kernel::{Kernel, KernelKind};
pub use metrics::{Fitted, TrainingMetrics};
pub use model::{AnyModel, ModelKind, ModelParams, Prediction, Trained, train};
pub use scale::Standardizer;

/// Why a model could not be trained or used. `InvalidParams` and `InvalidData` are the
/// user's to fix (the service answers 422 naming `field`); the others are reported as
/// the reason a training job failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LearnError {
    /// A parameter is out of range or of the wrong type. `field` is its name inside
    /// `params` (or `cv.…` for the cross-validation block).
    #[error("{field}: {reason}")]
    InvalidParams {
        /// Dotted path, e.g. `sigma2`, `cv.folds`.
        field: String,
        /// Why it was refused.
        reason: String,
    },
    /// The training or prediction data cannot be used. `field` is its path inside
    /// `data` (e.g. `x[3]`, `y`).
    #[error("{field}: {reason}")]
    InvalidData {
        /// Dotted path, e.g. `x[3][1]`, `y`.
        field: String,
        /// Why it was refused.
        reason: String,
    },
    /// A numerical step failed (e.g. a Cholesky factorisation of an indefinite matrix,
    /// or a solver that did not converge within its iteration limit).
    #[error("numerical failure: {0}")]
    Numerical(String),
    /// The job was cancelled (the model was deleted while training).
    #[error("training cancelled")]
    Cancelled,
}

impl LearnError {
    /// An [`LearnError::InvalidParams`] for `field`.
    pub fn params(field: impl Into<String>, reason: impl Into<String>) -> Self {
        LearnError::InvalidParams {
            field: field.into(),
            reason: reason.into(),
        }
    }

    /// The field an `InvalidParams` or `InvalidData` names (`None` for the others).
    pub fn field(&self) -> Option<&str> {
        match self {
            LearnError::InvalidParams { field, .. } | LearnError::InvalidData { field, .. } => {
                Some(field)
            }
            LearnError::Numerical(_) | LearnError::Cancelled => None,
        }
    }

    /// An [`LearnError::InvalidData`] for `field`.
    pub fn data(field: impl Into<String>, reason: impl Into<String>) -> Self {
        LearnError::InvalidData {
            field: field.into(),
            reason: reason.into(),
        }
    }
}

/// Where a training job reports its progress, and learns that it should stop.
/// Implemented by the service's job record; [`NoProgress`] for library use.
pub trait Progress: Sync {
    /// Reports the fraction done in `[0, 1]` and the current stage, e.g.
    /// `"cv fold 3/5"` or `"smo"`. Called at most every few milliseconds.
    fn report(&self, fraction: f64, stage: &str);

    /// True when the job should stop; long loops check it and return
    /// [`LearnError::Cancelled`].
    fn cancelled(&self) -> bool {
        false
    }
}

/// A [`Progress`] that ignores reports and never cancels.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn report(&self, _fraction: f64, _stage: &str) {}
}
