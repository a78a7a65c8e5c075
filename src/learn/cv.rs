//! Hyper-parameter tuning as LS-SVMlab's `tunelssvm` does it: k-fold
//! cross-validation over a log-spaced grid of `gamma` and `sigma2`, optionally
//! refined around the best pair, deterministic for a seed.
//! (Stub: filled in by the LS-SVM work.)

use serde::{Deserialize, Serialize};

use super::LearnError;

/// A hyper-parameter given as a number or `"auto"` (chosen by cross-validation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Hyper {
    /// A fixed value.
    Value(f64),
    /// Chosen by cross-validation.
    Auto,
}

impl Hyper {
    /// The value, or `None` for `Auto`.
    pub fn value(self) -> Option<f64> {
        match self {
            Hyper::Value(v) => Some(v),
            Hyper::Auto => None,
        }
    }
}

impl Serialize for Hyper {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Hyper::Value(v) => s.serialize_f64(*v),
            Hyper::Auto => s.serialize_str("auto"),
        }
    }
}

impl<'de> Deserialize<'de> for Hyper {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Num(f64),
            Text(String),
        }
        match Raw::deserialize(d)? {
            Raw::Num(v) => Ok(Hyper::Value(v)),
            Raw::Text(t) if t == "auto" => Ok(Hyper::Auto),
            Raw::Text(t) => Err(serde::de::Error::custom(format!(
                "expected a number or \"auto\", got \"{t}\""
            ))),
        }
    }
}

/// The `cv` block of `POST /api/v1/models`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CvParams {
    /// Number of folds (≥ 2).
    #[serde(default = "default_folds")]
    pub folds: usize,
    /// Seed of the fold shuffle.
    #[serde(default)]
    pub seed: u64,
}

fn default_folds() -> usize {
    5
}

impl Default for CvParams {
    fn default() -> Self {
        CvParams {
            folds: default_folds(),
            seed: 0,
        }
    }
}

impl CvParams {
    /// Validates the block; errors are named `cv.<field>`.
    pub fn check(&self) -> Result<(), LearnError> {
        if self.folds < 2 {
            return Err(LearnError::params("cv.folds", "must be at least 2"));
        }
        Ok(())
    }
}

/// What cross-validation chose and measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CvReport {
    /// Folds used.
    pub folds: usize,
    /// Chosen `gamma`.
    pub gamma: f64,
    /// Chosen `sigma2` (absent for the linear kernel).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma2: Option<f64>,
    /// Mean squared CV error of the chosen pair (regression) or CV misclassification rate.
    pub error: f64,
    /// Grid points evaluated.
    pub evaluated: usize,
}
