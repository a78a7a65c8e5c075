//! Online sliding-window LS-SVM (seed 001 §2.2, DESIGN §3.5): O(N²) add and
//! remove updates of `H⁻¹`, re-factorised every `refresh` updates.
//! (Stub: filled in by the LS-SVM work.)

use serde::{Deserialize, Serialize};

use super::LearnError;

/// Parameters of the online window (raw units: no standardisation).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OnlineParams {
    /// Window length N.
    pub window: usize,
    /// Regularisation γ.
    pub gamma: f64,
    /// RBF width σ².
    pub sigma2: f64,
    /// Re-factorise from scratch every this many updates (default 1000).
    #[serde(default = "default_refresh")]
    pub refresh: usize,
}

fn default_refresh() -> usize {
    1000
}

impl OnlineParams {
    /// Validates the parameters.
    pub fn check(&self) -> Result<(), LearnError> {
        Ok(())
    }
}

/// The sliding-window model.
#[derive(Debug, Clone)]
pub struct OnlineLsSvm {
    params: OnlineParams,
}

impl OnlineLsSvm {
    /// An empty window.
    pub fn new(params: OnlineParams) -> Result<Self, LearnError> {
        params.check()?;
        Ok(OnlineLsSvm { params })
    }

    /// The parameters.
    pub fn params(&self) -> &OnlineParams {
        &self.params
    }

    /// Adds a sample; once the window is full the oldest leaves.
    pub fn push(&mut self, _x: &[f64], _y: f64) -> Result<(), LearnError> {
        Err(LearnError::Numerical(
            "online lssvm is not implemented yet".into(),
        ))
    }

    /// Samples in the window.
    pub fn len(&self) -> usize {
        0
    }

    /// True when the window holds no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// `f(x)`, or `None` until the window holds at least two samples.
    pub fn predict(&self, _x: &[f64]) -> Option<f64> {
        None
    }
}
