//! The `rimu` monitor: Redundant gyros: parity space, windowed χ² (FSS) test, SVM isolation and output reconstruction (DESIGN §3.7, seed 002).
//! (Stub: not built yet.)

use super::{BuildError, ModelSource, Monitor, MonitorSpec};

/// Builds a `rimu` monitor from its spec.
pub fn build(
    _spec: &MonitorSpec,
    _models: &dyn ModelSource,
) -> Result<Box<dyn Monitor>, BuildError> {
    Err(BuildError::Unsupported("rimu"))
}
