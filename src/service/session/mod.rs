//! Sessions: one actor task per session owns its monitors and counters
//! (`actor`); everyone else holds a cheap `SessionHandle` (`handle`); the
//! `registry` maps ids to handles; `spec` validates what a user asks for.

pub mod actor;
pub mod error;
pub mod handle;
pub mod history;
pub mod registry;
pub mod spec;
pub mod stats;

pub use error::SessionError;
pub use handle::{ControlCommand, FrameCommand, SessionHandle};
pub use registry::Registry;
pub use spec::{build_monitors, validate_session};
pub use stats::SessionStats;
