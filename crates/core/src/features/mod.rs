//! Features: wavelet-packet energies (redundant gyros, docs/methods.md §M16) and the TACAN
//! window features (docs/methods.md §M18), computed from raw series before the learned
//! detectors. Sits between the epochs and `learn/` in the flow; the monitors and
//! `POST /api/v1/features` compute the same vectors. Pure: no I/O.

pub mod tacan;
pub mod wavelet;

/// Why features could not be computed; `field` names the offending input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {reason}")]
pub struct FeatureError {
    /// Dotted path of the input, e.g. `signal`, `level`, `tacan[3]`.
    pub field: String,
    /// Why it was refused.
    pub reason: String,
}

impl FeatureError {
    /// Builds an error for `field`.
    pub fn new(field: impl Into<String>, reason: impl Into<String>) -> Self {
        FeatureError {
            field: field.into(),
            reason: reason.into(),
        }
    }
}
