//! Locally weighted LS-SVM (seed 000 §1.2, made precise in DESIGN §3.5).
//! (Stub: filled in by the LS-SVM work.)

use serde::{Deserialize, Serialize};

use super::cv::{CvParams, Hyper};
use super::model::Trained;
use super::{Dataset, LearnError, Progress};

/// `params` of an `lw-lssvm` model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LwLsSvmParams {
    /// Regularisation γ (> 0) or `"auto"`.
    pub gamma: Hyper,
    /// Base RBF width σ² (> 0) or `"auto"`.
    pub sigma2: Hyper,
    /// Neighbours per query (default 30).
    #[serde(default = "default_k")]
    pub k: usize,
}

fn default_k() -> usize {
    30
}

impl LwLsSvmParams {
    /// Validates the parameters.
    pub fn check(&self) -> Result<(), LearnError> {
        Ok(())
    }
}

/// A locally weighted LS-SVM: the training set, predicting by a local fit per query.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LwLsSvmModel {
    dim: usize,
}

impl LwLsSvmModel {
    /// Input dimension.
    pub fn input_dim(&self) -> usize {
        self.dim
    }

    /// `f(x)` in original units.
    pub fn predict_one(&self, _x: &[f64]) -> f64 {
        f64::NAN
    }
}

/// Training job entry point for `lw-lssvm`.
pub fn train(
    _params: &LwLsSvmParams,
    _cv: Option<&CvParams>,
    _data: &Dataset,
    _progress: &dyn Progress,
) -> Result<Trained, LearnError> {
    Err(LearnError::Numerical(
        "lw-lssvm is not implemented yet".into(),
    ))
}
