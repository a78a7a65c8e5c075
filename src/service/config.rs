//! Service configuration: where to listen, where to store, the token, and the limits.

use std::net::SocketAddr;
use std::path::PathBuf;

/// Limits on what a client may send (DESIGN §4.5). Over a limit: 413 or an `error` event.
#[derive(Debug, Clone)]
pub struct Limits {
    /// Largest ingest frame, bytes (default 1 MiB).
    pub max_frame_bytes: usize,
    /// Most epochs in one batch frame (default 10,000).
    pub max_batch_epochs: usize,
    /// Most sessions (default 10,000).
    pub max_sessions: usize,
    /// Most monitors in one session (default 16).
    pub max_monitors_per_session: usize,
    /// Largest REST request body, bytes (default 16 MiB).
    pub max_body_bytes: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_frame_bytes: 1 << 20,
            max_batch_epochs: 10_000,
            max_sessions: 10_000,
            max_monitors_per_session: 16,
            max_body_bytes: 16 << 20,
        }
    }
}

/// Everything the server needs to start.
#[derive(Debug, Clone)]
pub struct ServiceConfig {
    /// Listen address (default 127.0.0.1:8080; port 0 picks a free port).
    pub bind: SocketAddr,
    /// SQLite file (default `navguard.db`).
    pub db_path: PathBuf,
    /// Bearer token required on every `/api` route and socket, when set.
    pub token: Option<String>,
    /// Request limits.
    pub limits: Limits,
}

impl ServiceConfig {
    /// A config with defaults for the given address and database file.
    pub fn new(bind: SocketAddr, db_path: impl Into<PathBuf>) -> Self {
        ServiceConfig {
            bind,
            db_path: db_path.into(),
            token: None,
            limits: Limits::default(),
        }
    }
}
