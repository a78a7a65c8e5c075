//! C-SVC and one-class SVM (SVDD / ν-OCSVM) trained by SMO (seeds 002 and 003,
//! DESIGN §3.7–3.8). (Stub: filled in by the SVM work.)

use serde::{Deserialize, Serialize};

use super::cv::CvParams;
use super::model::Trained;
use super::{Dataset, LearnError, Progress};

/// `params` of an `svm` model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SvcParams {
    /// Box constraint C (> 0).
    #[serde(rename = "C", default = "one")]
    pub c: f64,
}

/// `params` of an `ocsvm` model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OcSvmParams {
    /// ν in (0, 1].
    #[serde(default = "tenth")]
    pub nu: f64,
}

fn one() -> f64 {
    1.0
}

fn tenth() -> f64 {
    0.1
}

impl SvcParams {
    /// Validates the parameters.
    pub fn check(&self) -> Result<(), LearnError> {
        Ok(())
    }
}

impl OcSvmParams {
    /// Validates the parameters.
    pub fn check(&self) -> Result<(), LearnError> {
        Ok(())
    }
}

/// A trained C-SVC.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SvcModel {
    dim: usize,
}

impl SvcModel {
    /// Input dimension.
    pub fn input_dim(&self) -> usize {
        self.dim
    }

    /// Decision value; ≥ 0 means the positive class.
    pub fn decision_one(&self, _x: &[f64]) -> f64 {
        f64::NAN
    }
}

/// A trained one-class SVM.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OcSvmModel {
    dim: usize,
}

impl OcSvmModel {
    /// Input dimension.
    pub fn input_dim(&self) -> usize {
        self.dim
    }

    /// Decision value; ≥ 0 means inside the boundary (normal).
    pub fn decision_one(&self, _x: &[f64]) -> f64 {
        f64::NAN
    }
}

/// Training job entry point for `svm`.
pub fn train_svc(
    _params: &SvcParams,
    _cv: Option<&CvParams>,
    _data: &Dataset,
    _progress: &dyn Progress,
) -> Result<Trained, LearnError> {
    Err(LearnError::Numerical("svm is not implemented yet".into()))
}

/// Training job entry point for `ocsvm`.
pub fn train_ocsvm(
    _params: &OcSvmParams,
    _cv: Option<&CvParams>,
    _data: &Dataset,
    _progress: &dyn Progress,
) -> Result<Trained, LearnError> {
    Err(LearnError::Numerical("ocsvm is not implemented yet".into()))
}
