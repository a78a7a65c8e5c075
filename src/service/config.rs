//! Service configuration: where to listen, where to store, the tokens, and the limits.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use super::store::Retention;

/// Limits on what a client may send (docs/architecture.md §A5). Over a limit: 413 or an `error` event.
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
    /// Largest `POST /api/v1/models` body, bytes (default 64 MiB: a 30,000 × 3
    /// training set is about 2 MiB of JSON, so this leaves room for much larger sets).
    pub max_training_body_bytes: usize,
    /// Most samples in a training set or a predict request (default 50,000).
    pub max_training_samples: usize,
    /// Most numbers in a training set (`n × dim`) or a features request (default 2,000,000).
    pub max_training_values: usize,
    /// Most samples for the LS-SVM kinds (`lssvm`, `lw-lssvm`), which solve dense
    /// `n × n` systems: 5,000 samples is a 200 MB matrix (default 5,000).
    pub max_lssvm_samples: usize,
    /// Training jobs that run at once on the blocking pool; the others wait with
    /// stage `queued` (default 1, so training never takes both cores from ingest).
    pub max_concurrent_trainings: usize,
    /// Training jobs running or queued at once; one more gets 503 (default 16).
    pub max_queued_trainings: usize,
    /// Largest state of a user-defined model (`linear`'s n; default 128: a tightly
    /// coupled INS/GNSS filter with per-satellite ambiguities has a few dozen). One
    /// epoch costs O(n³), so this bounds the compute one frame can ask for.
    pub max_state_dim: usize,
    /// Largest measurement vector of a user-defined model (`linear`'s m, a `channel`'s
    /// `dim`; default 128).
    pub max_measurement_dim: usize,
    /// Open TCP connections, WebSockets included; one more is answered 503
    /// `too_many_connections` and closed (default 16,384: room for 10,000
    /// sessions' ingest sockets plus 6,000 observers and REST callers; each
    /// connection is a file descriptor, so `ulimit -n` must be higher, which
    /// the server checks at start, docs/architecture.md §A13).
    pub max_connections: usize,
    /// Time a client has to send a complete request head (request line and
    /// headers) from connecting, and between two requests on a kept-alive
    /// connection; a silent or trickling connection is closed (default 10 s).
    pub header_timeout: Duration,
    /// Longest pause within a request body; the request then fails (400) and
    /// its connection closes (default 30 s).
    pub idle_timeout: Duration,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_frame_bytes: 1 << 20,
            max_batch_epochs: 10_000,
            max_sessions: 10_000,
            max_monitors_per_session: 16,
            max_body_bytes: 16 << 20,
            max_training_body_bytes: 64 << 20,
            max_training_samples: 50_000,
            max_training_values: 2_000_000,
            max_lssvm_samples: 5_000,
            max_concurrent_trainings: 1,
            max_queued_trainings: 16,
            max_state_dim: 128,
            max_measurement_dim: 128,
            max_connections: 16_384,
            header_timeout: Duration::from_secs(10),
            idle_timeout: Duration::from_secs(30),
        }
    }
}

/// Everything the server needs to start.
#[derive(Debug, Clone)]
pub struct ServiceConfig {
    /// Listen address (default 127.0.0.1:8080; port 0 picks a free port).
    pub bind: SocketAddr,
    /// SQLite file (default `navguard.db`), or a `postgres://` / `postgresql://` URL
    /// (`store::postgres_url`).
    pub db_path: PathBuf,
    /// Bearer token with every scope (named `default`), when set.
    pub token: Option<String>,
    /// The tokens file (`--tokens-file`): named tokens with scopes, read again when it
    /// changes (service/tokens.rs).
    pub tokens_file: Option<PathBuf>,
    /// Request limits.
    pub limits: Limits,
    /// Sessions record their frames unless they say `"record": false` (default off:
    /// only sessions that ask record).
    pub record_default: bool,
    /// Retention limits of the recordings.
    pub retention: Retention,
    /// Seconds of 1 Hz statistics history kept per session for the dashboard
    /// (`GET …/history`, default 900).
    pub history_s: u32,
    /// Join a cluster (docs/deployment.md); `None`: a single node.
    pub cluster: Option<crate::service::cluster::ClusterConfig>,
}

impl ServiceConfig {
    /// A config with defaults for the given address and database file.
    pub fn new(bind: SocketAddr, db_path: impl Into<PathBuf>) -> Self {
        ServiceConfig {
            bind,
            db_path: db_path.into(),
            token: None,
            tokens_file: None,
            limits: Limits::default(),
            record_default: false,
            retention: Retention::default(),
            history_s: 900,
            cluster: None,
        }
    }
}
