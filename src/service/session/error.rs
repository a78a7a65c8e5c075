//! Why a session operation failed, with typed causes. The session actor, its handle and
//! spec validation return these; handlers turn them into an [`ApiError`] through `From`
//! (in `service/error.rs`), so HTTP statuses are decided in one place.
//!
//! [`ApiError`]: crate::service::error::ApiError

use navguard_core::monitor::BuildError;

/// A session operation that failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SessionError {
    /// Monitor `index` of the session's spec could not be built.
    #[error("monitors[{index}]: {source}")]
    Build {
        /// Position of the monitor in the spec.
        index: usize,
        /// Why.
        #[source]
        source: BuildError,
    },
    /// A field of the request is invalid; `field` is its path in the request body.
    #[error("{reason}")]
    Invalid {
        /// Path of the field (`monitors[1].name`, `p_fa`), if one is to blame.
        field: Option<String>,
        /// Why.
        reason: String,
    },
    /// The request is over a configured limit.
    #[error("{0}")]
    TooLarge(String),
    /// A session of that id exists already.
    #[error("session '{0}' already exists")]
    Exists(String),
    /// This node cannot run the session now (it drains, or holds its limit); retry, the
    /// load balancer sends the request to another node.
    #[error("{0}")]
    Unavailable(String),
    /// The session already has an ingest stream attached.
    #[error("session '{0}' already has an ingest stream attached")]
    AlreadyAttached(String),
    /// The session has no monitor of that name.
    #[error("session '{session}' has no monitor '{monitor}'")]
    NoMonitor {
        /// Session id.
        session: String,
        /// Monitor name asked for.
        monitor: String,
    },
    /// The session's actor has stopped.
    #[error("session '{0}' has stopped")]
    Stopped(String),
    /// The session's actor did not answer in time.
    #[error("session '{0}' is busy")]
    Busy(String),
    /// The session moved to another node (its lease was taken or handed over); retry,
    /// the load balancer or the next request finds the new owner.
    #[error("session '{0}' moved to another node; retry")]
    Moved(String),
    /// The store refused to record the change; nothing was changed.
    #[error("store: {0}")]
    Store(String),
}

impl SessionError {
    /// An invalid request field.
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        SessionError::Invalid {
            field: Some(field.into()),
            reason: reason.into(),
        }
    }

    /// True when the session could not be built because a model it names is gone
    /// (what start-up skips rather than refusing to start).
    pub fn is_missing_model(&self) -> bool {
        matches!(
            self,
            SessionError::Build {
                source: BuildError::ModelNotFound { .. },
                ..
            }
        )
    }
}

impl From<navguard_core::session::ThresholdRefusal> for SessionError {
    fn from(e: navguard_core::session::ThresholdRefusal) -> Self {
        SessionError::Invalid {
            field: e.field,
            reason: e.reason,
        }
    }
}
