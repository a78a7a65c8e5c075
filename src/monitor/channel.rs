//! The `channel` monitor: LS-SVM channel prediction with the T_a test (DESIGN §3.5, seeds 000 and 001).
//! (Stub: not built yet.)

use super::{BuildError, ModelSource, Monitor, MonitorSpec};

/// Builds a `channel` monitor from its spec.
pub fn build(
    _spec: &MonitorSpec,
    _models: &dyn ModelSource,
) -> Result<Box<dyn Monitor>, BuildError> {
    Err(BuildError::Unsupported("channel"))
}
