//! Sessions on the server: one actor task per session runs its session core
//! (`navguard_core::session`) and carries out what it decides (`actor`); everyone else holds
//! a cheap `SessionHandle` (`handle`); the `registry` maps ids to handles; `lifecycle`
//! starts, registers and rolls back sessions; `spec` validates what a user asks for.

pub mod actor;
pub mod error;
pub mod handle;
pub mod lifecycle;
pub mod registry;
pub mod spec;

pub use error::SessionError;
pub use handle::{ControlCommand, FrameCommand, SessionHandle};
pub use registry::Registry;
pub use spec::{build_monitors, validate_session};
