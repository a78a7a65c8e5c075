//! The `navguard` binary: parses flags, opens the store and serves (thin; the
//! service lives in the library), or runs one of the tools in [`cli`]
//! (`simulate`, `convert`, `replay`, `loadgen`, `calibrate`, `experiment`). `anyhow` is used only here and in `cli/`.

mod cli;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};
use navguard::service::cluster::mac::Keyring;
use navguard::service::cluster::{NatsLogin, NatsSecurity};
use navguard::service::{self, Limits, ServiceConfig};

/// navguard: navigation integrity monitoring over WebSocket and REST.
#[derive(Debug, Parser)]
#[command(version, about, args_conflicts_with_subcommands = true)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    serve: ServeArgs,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Serve the API, sockets and dashboard (the default).
    Serve(Box<ServeArgs>),
    /// Write a simulated scenario as ingest frames, one epoch per JSON line.
    Simulate(cli::simulate::SimulateArgs),
    /// Convert real receiver files (RINEX, GnssLogger, GSDC) into ingest frames with raw pseudoranges.
    Convert(cli::convert::ConvertArgs),
    /// Stream a JSON-lines file of epochs into a session of a running server.
    Replay(cli::replay::ReplayArgs),
    /// Put simulated load on a running server: N sessions, a rate, a batch size; report throughput, latency and memory.
    Loadgen(cli::loadgen::LoadgenArgs),
    /// Propose per-test thresholds for a false-alarm rate from fault-free recorded epochs.
    Calibrate(cli::calibrate::CalibrateArgs),
    /// Issue tokens for the tokens file: hash a secret, or make a new one.
    #[command(subcommand)]
    Token(cli::token::TokenCommand),
    /// Rerun a paper's experiment in-process: print its table, write its figures.
    #[command(subcommand)]
    Experiment(cli::experiment::ExperimentCommand),
}

#[derive(Debug, Args)]
struct ServeArgs {
    /// Address to listen on. A non-loopback address requires a token.
    #[arg(long, env = "NAVGUARD_BIND", default_value = "127.0.0.1:8080")]
    bind: SocketAddr,
    /// SQLite database file (created if missing), or a Postgres URL `postgres://user[:password]@host[:port]/database`.
    #[arg(long, env = "NAVGUARD_DB", default_value = "navguard.db")]
    db: PathBuf,
    /// Bearer token with every scope (named "default"), required on every /api route and socket.
    #[arg(long, env = "NAVGUARD_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// Tokens file (JSON): named tokens with scopes, stored as SHA-256 hashes; read
    /// again when it changes and on SIGHUP (docs/deployment.md, Tokens and scopes).
    #[arg(long, env = "NAVGUARD_TOKENS_FILE")]
    tokens_file: Option<PathBuf>,
    /// Largest ingest frame, bytes.
    #[arg(long, env = "NAVGUARD_MAX_FRAME_BYTES", default_value_t = Limits::default().max_frame_bytes)]
    max_frame_bytes: usize,
    /// Most epochs in one batch frame.
    #[arg(long, env = "NAVGUARD_MAX_BATCH_EPOCHS", default_value_t = Limits::default().max_batch_epochs)]
    max_batch_epochs: usize,
    /// Most sessions.
    #[arg(long, env = "NAVGUARD_MAX_SESSIONS", default_value_t = Limits::default().max_sessions)]
    max_sessions: usize,
    /// Most monitors per session.
    #[arg(long, env = "NAVGUARD_MAX_MONITORS", default_value_t = Limits::default().max_monitors_per_session)]
    max_monitors: usize,
    /// Largest REST request body, bytes.
    #[arg(long, env = "NAVGUARD_MAX_BODY_BYTES", default_value_t = Limits::default().max_body_bytes)]
    max_body_bytes: usize,
    /// Largest `POST /api/v1/models` body (a training set), bytes.
    #[arg(long, env = "NAVGUARD_MAX_TRAINING_BODY_BYTES", default_value_t = Limits::default().max_training_body_bytes)]
    max_training_body_bytes: usize,
    /// Most samples in a training set or predict request.
    #[arg(long, env = "NAVGUARD_MAX_TRAINING_SAMPLES", default_value_t = Limits::default().max_training_samples)]
    max_training_samples: usize,
    /// Most numbers (samples × features) in a training set or features request.
    #[arg(long, env = "NAVGUARD_MAX_TRAINING_VALUES", default_value_t = Limits::default().max_training_values)]
    max_training_values: usize,
    /// Most samples for the dense LS-SVM kinds (lssvm, lw-lssvm).
    #[arg(long, env = "NAVGUARD_MAX_LSSVM_SAMPLES", default_value_t = Limits::default().max_lssvm_samples)]
    max_lssvm_samples: usize,
    /// Training jobs that run at once (the rest wait, stage "queued").
    #[arg(long, env = "NAVGUARD_TRAINING_JOBS", default_value_t = Limits::default().max_concurrent_trainings)]
    training_jobs: usize,
    /// Training jobs running or queued before POST /api/v1/models answers 503.
    #[arg(long, env = "NAVGUARD_MAX_QUEUED_TRAININGS", default_value_t = Limits::default().max_queued_trainings)]
    max_queued_trainings: usize,
    /// Largest state dimension of a user-defined model (linear's n).
    #[arg(long, env = "NAVGUARD_MAX_STATE_DIM", default_value_t = Limits::default().max_state_dim)]
    max_state_dim: usize,
    /// Largest measurement dimension of a user-defined model (linear's m, a channel's dim).
    #[arg(long, env = "NAVGUARD_MAX_MEASUREMENT_DIM", default_value_t = Limits::default().max_measurement_dim)]
    max_measurement_dim: usize,
    /// Record every session's frames unless it says "record": false (default: only sessions that ask).
    #[arg(long, env = "NAVGUARD_RECORD")]
    record: bool,
    /// Recording bytes kept per session, MiB (oldest frames dropped first).
    #[arg(long, env = "NAVGUARD_RECORDING_SESSION_MIB", default_value_t = 64)]
    recording_session_mib: u64,
    /// Recording bytes kept in all, MiB (oldest frames of all sessions dropped first).
    #[arg(long, env = "NAVGUARD_RECORDING_TOTAL_MIB", default_value_t = 1024)]
    recording_total_mib: u64,
    /// Recorded frames older than this are dropped, hours.
    #[arg(long, env = "NAVGUARD_RECORDING_MAX_AGE_H", default_value_t = 168)]
    recording_max_age_h: u64,
    /// Seconds of 1 Hz statistics history kept per session for the dashboard.
    #[arg(long, env = "NAVGUARD_HISTORY_S", default_value_t = 900)]
    history_s: u32,
    /// Open connections (WebSockets included); one more gets 503 too_many_connections.
    #[arg(long, env = "NAVGUARD_MAX_CONNECTIONS", default_value_t = Limits::default().max_connections as u64,
          value_parser = clap::value_parser!(u64).range(1..=1 << 20))]
    max_connections: u64,
    /// Milliseconds a client has to send a request's line and headers (from connecting, or between requests).
    #[arg(long, env = "NAVGUARD_HEADER_TIMEOUT_MS", default_value_t = Limits::default().header_timeout.as_millis() as u64,
          value_parser = clap::value_parser!(u64).range(1..))]
    header_timeout_ms: u64,
    /// Milliseconds a request body may stall before the request fails and its connection closes.
    #[arg(long, env = "NAVGUARD_IDLE_TIMEOUT_MS", default_value_t = Limits::default().idle_timeout.as_millis() as u64,
          value_parser = clap::value_parser!(u64).range(1..))]
    idle_timeout_ms: u64,
    /// Join a cluster through this NATS server (`nats://host:port`): sessions are owned
    /// through leases in the shared store (use a Postgres --db), events cross nodes
    /// (docs/deployment.md). Unset: a single node.
    #[arg(long, env = "NAVGUARD_NATS")]
    nats: Option<String>,
    /// NATS user (with --nats-password; the server's `authorization { users }`).
    #[arg(long, env = "NAVGUARD_NATS_USER", requires_all = ["nats", "nats_password"])]
    nats_user: Option<String>,
    /// NATS password of --nats-user (prefer the environment: a flag shows in `ps`).
    #[arg(
        long,
        env = "NAVGUARD_NATS_PASSWORD",
        hide_env_values = true,
        requires = "nats_user"
    )]
    nats_password: Option<String>,
    /// NATS token (the server's `authorization { token }`).
    #[arg(long, env = "NAVGUARD_NATS_TOKEN", hide_env_values = true, requires = "nats",
          conflicts_with_all = ["nats_user", "nats_creds", "nats_nkey"])]
    nats_token: Option<String>,
    /// NATS credentials file (`.creds`: a user JWT and its NKey seed, from `nsc`).
    #[arg(long, env = "NAVGUARD_NATS_CREDS", requires = "nats",
          conflicts_with_all = ["nats_user", "nats_nkey"])]
    nats_creds: Option<PathBuf>,
    /// File holding the node's NKey seed (`SU…`; the server lists its public key).
    #[arg(
        long,
        env = "NAVGUARD_NATS_NKEY",
        requires = "nats",
        conflicts_with = "nats_user"
    )]
    nats_nkey: Option<PathBuf>,
    /// CA certificates (PEM) the NATS server's certificate must chain to (with the system's).
    #[arg(long, env = "NAVGUARD_NATS_TLS_CA", requires = "nats")]
    nats_tls_ca: Option<PathBuf>,
    /// Client certificate (PEM) for a NATS server that verifies clients (with --nats-tls-key).
    #[arg(long, env = "NAVGUARD_NATS_TLS_CERT", requires_all = ["nats", "nats_tls_key"])]
    nats_tls_cert: Option<PathBuf>,
    /// The client certificate's private key (PEM).
    #[arg(long, env = "NAVGUARD_NATS_TLS_KEY", requires = "nats_tls_cert")]
    nats_tls_key: Option<PathBuf>,
    /// Refuse a NATS server that does not offer TLS (implied by a `tls://` URL).
    #[arg(long, env = "NAVGUARD_NATS_TLS", requires = "nats")]
    nats_tls: bool,
    /// The cluster key: every bus message is signed with it (HMAC-SHA256) and one without
    /// a valid signature is dropped. At least 32 characters; several, separated by
    /// whitespace, during a rotation (the first signs, each verifies). Unset: messages are
    /// neither signed nor checked (throw-away clusters only).
    #[arg(
        long,
        env = "NAVGUARD_CLUSTER_KEY",
        hide_env_values = true,
        requires = "nats",
        conflicts_with = "cluster_key_file"
    )]
    cluster_key: Option<String>,
    /// File holding the cluster key(s), one per line (like --cluster-key).
    #[arg(long, env = "NAVGUARD_CLUSTER_KEY_FILE", requires = "nats")]
    cluster_key_file: Option<PathBuf>,
    /// This node's id in the cluster (default: node-PORT).
    #[arg(long, env = "NAVGUARD_NODE_ID", requires = "nats")]
    node_id: Option<String>,
    /// The URL clients and other nodes reach this node at directly (default: http://BIND).
    #[arg(long, env = "NAVGUARD_ADVERTISE", requires = "nats")]
    advertise: Option<String>,
    /// Milliseconds a session lease holds without renewal (renewed every third of it).
    #[arg(long, env = "NAVGUARD_LEASE_MS", default_value_t = 5000,
          value_parser = clap::value_parser!(u64).range(300..=600_000))]
    lease_ms: u64,
    /// Milliseconds between two checkpoints of a session whose state changed.
    #[arg(long, env = "NAVGUARD_CHECKPOINT_MS", default_value_t = 1000,
          value_parser = clap::value_parser!(u64).range(10..=600_000))]
    checkpoint_ms: u64,
    /// On SIGTERM, milliseconds /healthz answers 503 after the sessions are handed over, before the node exits.
    #[arg(long, env = "NAVGUARD_DRAIN_WAIT_MS", default_value_t = 2000,
          value_parser = clap::value_parser!(u64).range(0..=600_000))]
    drain_wait_ms: u64,
}

impl ServeArgs {
    /// The NATS login and TLS settings of the flags.
    fn nats_security(&self) -> NatsSecurity {
        let login = if let (Some(user), Some(password)) = (&self.nats_user, &self.nats_password) {
            NatsLogin::UserPassword {
                user: user.clone(),
                password: password.clone(),
            }
        } else if let Some(token) = &self.nats_token {
            NatsLogin::Token(token.clone())
        } else if let Some(path) = &self.nats_creds {
            NatsLogin::CredsFile(path.clone())
        } else if let Some(path) = &self.nats_nkey {
            NatsLogin::NkeyFile(path.clone())
        } else {
            NatsLogin::None
        };
        NatsSecurity {
            login,
            tls_ca: self.nats_tls_ca.clone(),
            tls_client: self.nats_tls_cert.clone().zip(self.nats_tls_key.clone()),
            require_tls: self.nats_tls,
        }
    }

    /// The cluster keys of --cluster-key or --cluster-key-file, if either is given.
    fn keyring(&self) -> anyhow::Result<Option<Arc<Keyring>>> {
        let text = match (&self.cluster_key, &self.cluster_key_file) {
            (Some(key), _) => key.clone(),
            (None, Some(path)) => std::fs::read_to_string(path)
                .with_context(|| format!("reading --cluster-key-file {}", path.display()))?,
            (None, None) => return Ok(None),
        };
        let ring = Keyring::parse(&text).context("--cluster-key")?;
        Ok(Some(Arc::new(ring)))
    }

    fn into_config(self) -> anyhow::Result<ServiceConfig> {
        let keyring = self.keyring()?;
        let nats_security = self.nats_security();
        let cluster = self.nats.as_ref().map(|nats| {
            let mut c = navguard::service::cluster::ClusterConfig::new(
                self.node_id
                    .clone()
                    .unwrap_or_else(|| format!("node-{}", self.bind.port())),
                self.advertise
                    .clone()
                    .unwrap_or_else(|| format!("http://{}", self.bind)),
                nats.clone(),
            );
            c.lease = Duration::from_millis(self.lease_ms);
            c.checkpoint_interval = Duration::from_millis(self.checkpoint_ms);
            c.drain_wait = Duration::from_millis(self.drain_wait_ms);
            c.nats_security = nats_security;
            c.keyring = keyring;
            c
        });
        Ok(ServiceConfig {
            cluster,
            bind: self.bind,
            db_path: self.db,
            // A blank token is refused at start rather than read as "no token".
            token: self.token,
            tokens_file: self.tokens_file,
            limits: Limits {
                max_frame_bytes: self.max_frame_bytes,
                max_batch_epochs: self.max_batch_epochs,
                max_sessions: self.max_sessions,
                max_monitors_per_session: self.max_monitors,
                max_body_bytes: self.max_body_bytes,
                max_training_body_bytes: self.max_training_body_bytes,
                max_training_samples: self.max_training_samples,
                max_training_values: self.max_training_values,
                max_lssvm_samples: self.max_lssvm_samples,
                max_concurrent_trainings: self.training_jobs,
                max_queued_trainings: self.max_queued_trainings,
                max_state_dim: self.max_state_dim,
                max_measurement_dim: self.max_measurement_dim,
                max_connections: self.max_connections as usize,
                header_timeout: Duration::from_millis(self.header_timeout_ms),
                idle_timeout: Duration::from_millis(self.idle_timeout_ms),
            },
            record_default: self.record,
            retention: navguard::service::store::Retention {
                session_bytes: self.recording_session_mib << 20,
                total_bytes: self.recording_total_mib << 20,
                max_age_ms: (self.recording_max_age_h * 3600 * 1000) as i64,
            },
            history_s: self.history_s,
        })
    }
}

/// Ctrl-C or SIGTERM (what `kill`, systemd and container runtimes send).
async fn wait_for_stop() -> anyhow::Result<()> {
    #[cfg(unix)]
    {
        let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
            .context("installing the SIGTERM handler")?;
        tokio::select! {
            r = tokio::signal::ctrl_c() => r.context("waiting for Ctrl-C")?,
            _ = term.recv() => {}
        }
    }
    #[cfg(not(unix))]
    tokio::signal::ctrl_c()
        .await
        .context("waiting for Ctrl-C")?;
    Ok(())
}

/// SIGHUP reads the tokens file again (it is also read when its mtime changes).
fn reload_tokens_on_sighup(server: &service::Server) {
    #[cfg(unix)]
    {
        let tokens = server.state().tokens.clone();
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::hangup()) {
            Ok(mut hup) => {
                tokio::spawn(async move {
                    while hup.recv().await.is_some() {
                        tokens.reload();
                    }
                });
            }
            Err(e) => {
                tracing::warn!(error = %e, "no SIGHUP handler; the tokens file is still read when it changes")
            }
        }
    }
    #[cfg(not(unix))]
    let _ = server;
}

async fn serve(args: ServeArgs) -> anyhow::Result<()> {
    let config = args.into_config()?;
    let db = navguard::service::store::display_db(&config.db_path);
    let server = service::start(config).await.context("starting navguard")?;
    println!(
        "navguard listening on http://{} (store: {db}); dashboard at http://{}/",
        server.addr, server.addr
    );
    reload_tokens_on_sighup(&server);
    wait_for_stop().await?;
    println!(
        "shutting down: handing sessions over (cluster), closing sockets and flushing the store"
    );
    server.shutdown().await;
    Ok(())
}

#[tokio::main]
async fn main() -> std::process::ExitCode {
    match run().await {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            // One line with the cause chain (whatever RUST_BACKTRACE says),
            // skipping causes the message already quotes.
            let mut message = e.to_string();
            for cause in e.chain().skip(1) {
                let cause = cause.to_string();
                if !message.contains(&cause) {
                    message.push_str(": ");
                    message.push_str(&cause);
                }
            }
            eprintln!("error: {message}");
            std::process::ExitCode::FAILURE
        }
    }
}

async fn run() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| "navguard=info,tower_http=warn".into()),
        )
        .init();
    let cli = Cli::parse();
    match cli.command {
        Some(Command::Serve(args)) => serve(*args).await,
        Some(Command::Simulate(args)) => cli::simulate::run(args),
        Some(Command::Convert(args)) => cli::convert::run(args),
        Some(Command::Replay(args)) => cli::replay::run(args).await,
        Some(Command::Loadgen(args)) => cli::loadgen::run(args).await,
        Some(Command::Calibrate(args)) => cli::calibrate::run(args).await,
        Some(Command::Token(command)) => cli::token::run(command),
        Some(Command::Experiment(command)) => cli::experiment::run(command),
        None => serve(cli.serve).await,
    }
}
