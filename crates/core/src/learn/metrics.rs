//! What training measured: the figures `GET /api/v1/models/{id}` shows once a model
//! is ready. Its own module so every algorithm can fill it without importing
//! [`super::model`] (which wraps the algorithms' results, never the reverse).

use serde::{Deserialize, Serialize};

use super::cv::CvReport;

/// What training measured, shown by `GET /api/v1/models/{id}` when ready.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainingMetrics {
    /// Training samples.
    pub n: usize,
    /// Input dimension.
    pub dim: usize,
    /// Wall time of training, s (cross-validation included).
    pub seconds: f64,
    /// Regression: root-mean-square error on the training set, original units.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub train_rmse: Option<f64>,
    /// Classification: fraction of training labels reproduced.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub train_accuracy: Option<f64>,
    /// One-class: fraction of training samples outside the boundary.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outlier_fraction: Option<f64>,
    /// SVM kinds: number of support vectors.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub support_vectors: Option<usize>,
    /// SVM kinds: SMO iterations.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iterations: Option<usize>,
    /// SVM kinds: final dual objective.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub objective: Option<f64>,
    /// The cross-validation that chose the hyper-parameters, when it ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cv: Option<CvReport>,
}

/// What fitting with progress returns: the model, the parameters it was trained with
/// (defaults and cross-validated hyper-parameters filled in) and the training figures.
#[derive(Debug, Clone, PartialEq)]
pub struct Fitted<M, P> {
    /// The model.
    pub model: M,
    /// Effective parameters.
    pub params: P,
    /// Training figures.
    pub metrics: TrainingMetrics,
}
