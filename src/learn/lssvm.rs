//! Batch LS-SVM regression (seed 000 eq. 6, DESIGN §3.5): Cholesky of
//! `Ω + I/γ` and the two-solve trick. (Stub: filled in by the LS-SVM work.)

use serde::{Deserialize, Serialize};

use super::cv::{CvParams, Hyper};
use super::model::Trained;
use super::{Dataset, LearnError, Progress};

/// `params` of an `lssvm` model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LsSvmParams {
    /// Regularisation γ (> 0) or `"auto"`.
    pub gamma: Hyper,
    /// RBF width σ² (> 0) or `"auto"`.
    pub sigma2: Hyper,
    /// Standardise inputs and targets (default true).
    #[serde(default = "yes")]
    pub standardize: bool,
}

fn yes() -> bool {
    true
}

impl LsSvmParams {
    /// Validates the parameters.
    pub fn check(&self) -> Result<(), LearnError> {
        Ok(())
    }

    /// Fits on `data` (γ and σ² must be numbers).
    pub fn fit(&self, _data: &Dataset) -> Result<LsSvmModel, LearnError> {
        Err(LearnError::Numerical("lssvm is not implemented yet".into()))
    }
}

/// A trained batch LS-SVM.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LsSvmModel {
    dim: usize,
}

impl LsSvmModel {
    /// Input dimension.
    pub fn input_dim(&self) -> usize {
        self.dim
    }

    /// `f(x)` in original units.
    pub fn predict_one(&self, _x: &[f64]) -> f64 {
        f64::NAN
    }
}

/// Training job entry point for `lssvm` (cross-validation first when asked).
pub fn train(
    _params: &LsSvmParams,
    _cv: Option<&CvParams>,
    _data: &Dataset,
    _progress: &dyn Progress,
) -> Result<Trained, LearnError> {
    Err(LearnError::Numerical("lssvm is not implemented yet".into()))
}
