//! The async edge: transport (axum), sessions (one actor each), persistence
//! (sqlx), auth and limits. It calls the pure core; no algorithm lives here.

pub mod access;
pub mod api;
pub mod app;
pub mod audit;
pub mod auth;
pub mod cluster;
pub mod compute;
pub mod config;
pub mod error;
pub mod events;
pub mod extract;
pub mod ingest;
pub mod metrics;
mod serve;
pub mod session;
pub mod store;
pub mod tokens;
pub mod train;
pub mod wire;

use std::net::SocketAddr;
use std::sync::Arc;

use tokio::net::TcpListener;
use tokio::sync::watch;
use tokio::task::JoinHandle;

pub use app::{AppState, app};
pub use config::{Limits, ServiceConfig};
pub use error::ApiError;

use session::Registry;
use store::{Store, StoreError};
use train::Models;

/// Wall-clock now, Unix milliseconds.
pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

/// Why the server could not start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    /// docs/architecture.md §A5: a non-loopback address needs a token.
    #[error(
        "refusing to bind {0} without a token: set --token (NAVGUARD_TOKEN) or --tokens-file (NAVGUARD_TOKENS_FILE), or bind a loopback address"
    )]
    OpenWithoutToken(SocketAddr),
    /// docs/architecture.md §A5: a token that is empty, only whitespace, or
    /// padded with whitespace (which a header could never carry) protects nothing.
    #[error(
        "the token (--token or NAVGUARD_TOKEN) is {0}: give a non-blank token without surrounding whitespace, or none"
    )]
    BadToken(&'static str),
    /// The tokens file could not be read or is invalid.
    #[error("tokens file: {0}")]
    Tokens(#[from] tokens::TokensError),
    /// The store could not be opened.
    #[error("store: {0}")]
    Store(#[from] StoreError),
    /// A stored session could not be restarted.
    #[error("stored session '{0}' is invalid: {1}")]
    StoredSession(String, String),
    /// The cluster could not be joined.
    #[error("cluster: {0}")]
    Cluster(#[from] cluster::ClusterError),
    /// The address could not be bound.
    #[error("bind {0}: {1}")]
    Bind(SocketAddr, std::io::Error),
}

/// A running server.
#[derive(Debug)]
pub struct Server {
    /// The bound address (useful with port 0).
    pub addr: SocketAddr,
    state: AppState,
    shutdown: watch::Sender<bool>,
    task: JoinHandle<std::io::Result<()>>,
}

/// Opens the store, restarts the stored sessions, binds and serves.
pub async fn start(config: ServiceConfig) -> Result<Server, StartError> {
    if let Some(token) = &config.token {
        if token.trim().is_empty() {
            return Err(StartError::BadToken("blank"));
        }
        if token.trim() != token {
            return Err(StartError::BadToken("padded with whitespace"));
        }
    }
    let tokens = Arc::new(tokens::Tokens::new(
        config.token.as_deref(),
        config.tokens_file.as_deref(),
    )?);
    if !config.bind.ip().is_loopback() && !tokens.required() {
        return Err(StartError::OpenWithoutToken(config.bind));
    }
    let store = Store::open_with(&config.db_path, config.retention).await?;
    // Models first: restored sessions may name one.
    let models = Arc::new(Models::load(store.clone(), &config.limits).await?);
    let cluster = match &config.cluster {
        Some(c) => Some(cluster::Cluster::connect(c.clone()).await?),
        None => None,
    };
    let (shutdown_tx, shutdown_rx) = watch::channel(false);
    let state = AppState {
        store: store.clone(),
        registry: Arc::new(Registry::default()),
        metrics: Arc::default(),
        config: Arc::new(config),
        tokens,
        shutdown: shutdown_rx,
        models,
        compute: compute::ComputePool::per_core(),
        cluster,
    };
    // Sessions, their monitors and thresholds persist; filter state starts afresh. A
    // cluster node starts none: it takes a session's lease when asked for it.
    let stored_sessions = if state.cluster.is_some() {
        Vec::new()
    } else {
        store.sessions().await?
    };
    for stored in stored_sessions {
        let id = stored.id.clone();
        let started = session::lifecycle::restart(state.actor_deps(), &state.registry, stored);
        match started.await {
            Ok(_) => {}
            // A model deleted while a live session used it: that session kept its
            // copy until now, but cannot be rebuilt. Skip it (its row stays) rather
            // than refuse to start.
            Err(e) if e.is_missing_model() => {
                tracing::warn!(session = %id, error = %e, "stored session names a deleted model; not restarted");
            }
            Err(session::SessionError::Exists(_)) => {
                return Err(StartError::StoredSession(id, "duplicate id".into()));
            }
            Err(e) => return Err(StartError::StoredSession(id, e.to_string())),
        }
    }
    let listener = TcpListener::bind(state.config.bind)
        .await
        .map_err(|e| StartError::Bind(state.config.bind, e))?;
    let addr = listener
        .local_addr()
        .map_err(|e| StartError::Bind(state.config.bind, e))?;
    let router = app(state.clone());
    if let Some(cluster) = &state.cluster {
        tokio::spawn(cluster::rpc::serve(
            cluster.clone(),
            router.clone(),
            state.registry.clone(),
        ));
        tokio::spawn(cluster::own::renew(state.clone(), cluster.clone()));
    }
    let edge = serve::EdgeLimits::from(&state.config.limits);
    let task = tokio::spawn(serve::serve(listener, router, edge, state.shutdown.clone()));
    tracing::info!(%addr, "navguard listening");
    Ok(Server {
        addr,
        state,
        shutdown: shutdown_tx,
        task,
    })
}

impl Server {
    /// The server's state (for tests).
    pub fn state(&self) -> &AppState {
        &self.state
    }

    /// Graceful shutdown: closes sockets, stops the session actors, waits for
    /// the HTTP server, and checkpoints and closes the store.
    pub async fn shutdown(self) {
        if let Some(cluster) = &self.state.cluster {
            // A cluster node hands its sessions over before it goes.
            cluster::own::drain(&self.state, cluster).await;
        }
        let _ = self.shutdown.send(true);
        // Running training jobs stop at their next progress check; their rows
        // stay `training` and are marked failed at the next start.
        self.state.models.cancel_all();
        for handle in self.state.registry.list() {
            handle.shutdown().await;
        }
        match tokio::time::timeout(std::time::Duration::from_secs(10), self.task).await {
            Ok(Ok(Err(e))) => tracing::error!(error = %e, "server error during shutdown"),
            Err(_) => tracing::warn!("connections still open after 10 s; closing anyway"),
            _ => {}
        }
        self.state.store.close().await;
    }
}
