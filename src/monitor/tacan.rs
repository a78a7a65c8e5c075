//! The `tacan` monitor: TACAN range anomalies: window features against the INS-derived range, one-class SVM (DESIGN §3.8, seed 003).
//! (Stub: not built yet.)

use super::{BuildError, ModelSource, Monitor, MonitorSpec};

/// Builds a `tacan` monitor from its spec.
pub fn build(
    _spec: &MonitorSpec,
    _models: &dyn ModelSource,
) -> Result<Box<dyn Monitor>, BuildError> {
    Err(BuildError::Unsupported("tacan"))
}
