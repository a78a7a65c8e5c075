//! Scale-out (docs/deployment.md): several nodes on one shared store (Postgres), with
//! NATS between them, behind a load balancer that pins each session to a node by its id.
//!
//! - **Ownership.** A node runs a session's actor only while it holds the session's lease
//!   ([`crate::service::store::cluster`]); every write it makes for the session carries
//!   the lease's fencing epoch. Leases are renewed every third of `--lease-ms`; a session
//!   missing from a renewal was taken by another node and its actor stops at once.
//! - **Placement** ([`own`]). A request for a session this node does not run finds the
//!   owner in the lease: REST is forwarded to it over NATS request/reply ([`rpc`]); an
//!   ingest socket asks the owner to hand the session over (granted unless a stream is
//!   attached there, else refused with `not_owner` and the owner's address). A lease that
//!   expired, was released, or whose owner has no NATS subscription any more (the process
//!   is gone) is taken over at once, and the new owner restores the last checkpoint.
//! - **Events** ([`bus`]). Every node publishes its sessions' `state`, `alarm`,
//!   `availability` (per-session subject, in order, with a sequence number) and decimated
//!   `stats`; an events socket on any node subscribes to them.
//! - **Trust** ([`mac`]). A node logs in to NATS with the credentials and TLS settings of
//!   [`NatsSecurity`]; with a cluster key every message it publishes carries an HMAC, and
//!   a message without a valid one is dropped and counted (`navguard_bus_rejected_total`).
//! - **Drain.** On SIGTERM a node refuses new streams and leases, closes its events
//!   sockets and hands every session over (its stream told `moved`, a final checkpoint, the
//!   lease released, so the next node resumes exactly where it stopped) while `/healthz`
//!   still answers 200; then `/healthz` answers 503 for `--drain-wait-ms`, so the load
//!   balancer marks the node down only once its sockets have closed.

pub mod bus;
pub mod mac;
pub mod own;
pub mod rpc;

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::{mpsc, watch};

/// Everything a node needs to join a cluster.
#[derive(Debug, Clone)]
pub struct ClusterConfig {
    /// This node's id (unique in the cluster; letters, digits, `_`, `-`, `.`).
    pub node_id: String,
    /// Where clients and other nodes reach this node directly (`http://host:port`).
    pub advertise: String,
    /// The NATS server, `nats://host:port` (`tls://host:port` for TLS).
    pub nats_url: String,
    /// How the node logs in to NATS and checks its certificate.
    pub nats_security: NatsSecurity,
    /// The cluster keys that sign and check every bus message; `None`: messages are
    /// neither signed nor checked (throw-away clusters only, docs/deployment.md).
    pub keyring: Option<Arc<mac::Keyring>>,
    /// How long a lease holds without renewal (default 5 s).
    pub lease: Duration,
    /// How often an owner checkpoints a session whose state changed (default 1 s).
    pub checkpoint_interval: Duration,
    /// On SIGTERM, once the sessions are handed over, how long `/healthz` answers 503
    /// before the node exits (default 2 s: time for the load balancer's two failed health
    /// checks).
    pub drain_wait: Duration,
}

impl ClusterConfig {
    /// A config with the default lease, checkpoint interval and drain wait.
    pub fn new(
        node_id: impl Into<String>,
        advertise: impl Into<String>,
        nats_url: impl Into<String>,
    ) -> Self {
        ClusterConfig {
            node_id: node_id.into(),
            advertise: advertise.into(),
            nats_url: nats_url.into(),
            nats_security: NatsSecurity::default(),
            keyring: None,
            lease: Duration::from_secs(5),
            checkpoint_interval: Duration::from_secs(1),
            drain_wait: Duration::from_secs(2),
        }
    }
}

/// How a node logs in to NATS.
#[derive(Clone, Default)]
pub enum NatsLogin {
    /// No credentials (or those in the URL's `user:password@`).
    #[default]
    None,
    /// A user and password (the server's `authorization { users = [...] }`).
    UserPassword {
        /// User name.
        user: String,
        /// Password.
        password: String,
    },
    /// A token (the server's `authorization { token = ... }`).
    Token(String),
    /// A `.creds` file (a user JWT and its NKey seed, from `nsc`).
    CredsFile(PathBuf),
    /// A file holding an NKey seed (`SU…`, from `nk -gen user`).
    NkeyFile(PathBuf),
}

impl std::fmt::Debug for NatsLogin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NatsLogin::None => f.write_str("None"),
            NatsLogin::UserPassword { user, .. } => {
                write!(f, "UserPassword {{ user: {user:?}, password: REDACTED }}")
            }
            NatsLogin::Token(_) => f.write_str("Token(REDACTED)"),
            NatsLogin::CredsFile(p) => write!(f, "CredsFile({p:?})"),
            NatsLogin::NkeyFile(p) => write!(f, "NkeyFile({p:?})"),
        }
    }
}

/// The NATS login and TLS settings of a node.
#[derive(Debug, Clone, Default)]
pub struct NatsSecurity {
    /// The credentials.
    pub login: NatsLogin,
    /// CA certificates (PEM) the server's certificate must chain to, added to the system's.
    pub tls_ca: Option<PathBuf>,
    /// The client certificate and its key (PEM), for a server that verifies clients.
    pub tls_client: Option<(PathBuf, PathBuf)>,
    /// Refuse a server that does not offer TLS.
    pub require_tls: bool,
}

impl NatsSecurity {
    /// The connect options these settings make.
    async fn options(&self) -> Result<async_nats::ConnectOptions, String> {
        let mut options = async_nats::ConnectOptions::new();
        options = match &self.login {
            NatsLogin::None => options,
            NatsLogin::UserPassword { user, password } => {
                options.user_and_password(user.clone(), password.clone())
            }
            NatsLogin::Token(token) => options.token(token.clone()),
            NatsLogin::CredsFile(path) => options
                .credentials_file(path)
                .await
                .map_err(|e| format!("NATS credentials file {}: {e}", path.display()))?,
            NatsLogin::NkeyFile(path) => {
                let seed = std::fs::read_to_string(path)
                    .map_err(|e| format!("NATS NKey seed file {}: {e}", path.display()))?;
                // The client decodes the seed as it connects: a wrong file fails the start.
                options.nkey(seed.trim().to_owned())
            }
        };
        if let Some(ca) = &self.tls_ca {
            options = options.add_root_certificates(ca.clone());
        }
        if let Some((cert, key)) = &self.tls_client {
            options = options.add_client_certificate(cert.clone(), key.clone());
        }
        Ok(options.require_tls(self.require_tls))
    }
}

/// `url` for logs: any `user:password@` or `token@` in it replaced by `***@`.
pub fn redacted_url(url: &str) -> String {
    match url
        .split_once("://")
        .map(|(s, rest)| (s, rest.rsplit_once('@')))
    {
        Some((scheme, Some((_, host)))) => format!("{scheme}://***@{host}"),
        _ => url.to_owned(),
    }
}

/// Why a node could not join its cluster.
#[derive(Debug, thiserror::Error)]
pub enum ClusterError {
    /// The NATS server could not be reached.
    #[error("connecting to NATS at {0}: {1}")]
    Nats(String, String),
    /// A setting is unusable.
    #[error("{0}")]
    Config(String),
}

/// Counters for `/metrics` (docs/deployment.md, What to monitor).
#[derive(Debug, Default)]
pub struct ClusterCounters {
    /// Leases taken (new sessions, takeovers, handovers in).
    pub leases_acquired: AtomicU64,
    /// Of which taken from an owner presumed gone or after expiry (failovers).
    pub takeovers: AtomicU64,
    /// Leases found taken by another node (this node was fenced).
    pub leases_lost: AtomicU64,
    /// Leases given up (drain, handover out).
    pub leases_released: AtomicU64,
    /// REST requests forwarded to another node.
    pub forwarded: AtomicU64,
    /// Event messages published to NATS.
    pub published: AtomicU64,
    /// Event messages dropped because the publisher queue was full.
    pub publish_dropped: AtomicU64,
    /// Checkpoints committed.
    pub checkpoints: AtomicU64,
    /// Checkpoints refused or failed.
    pub checkpoint_failures: AtomicU64,
    /// Events sockets that closed on a gap in a session's sequence (missed messages).
    pub event_gaps: AtomicU64,
    /// Bus messages dropped for a missing, wrong or stale MAC.
    pub bus_rejected: AtomicU64,
}

/// A node's membership in the cluster: its config, its NATS client and publisher queue,
/// whether it drains, and the per-session locks that keep two requests on this node
/// from taking the same lease twice.
#[derive(Debug)]
pub struct Cluster {
    /// The node's settings.
    pub config: ClusterConfig,
    nats: async_nats::Client,
    outgoing: mpsc::Sender<bus::Outgoing>,
    /// True once the node drains: new streams, sessions and leases are refused, and events
    /// sockets close (they wait on it).
    draining: watch::Sender<bool>,
    /// True once the drained node has handed its sessions over: `/healthz` answers 503.
    leaving: AtomicBool,
    locks: Mutex<HashMap<String, Arc<tokio::sync::Mutex<()>>>>,
    /// Counters for `/metrics`.
    pub counters: ClusterCounters,
}

impl Cluster {
    /// Connects to NATS and starts the publisher task.
    pub async fn connect(config: ClusterConfig) -> Result<Arc<Self>, ClusterError> {
        if !crate::service::session::spec::valid_name(&config.node_id) {
            return Err(ClusterError::Config(format!(
                "--node-id '{}': use 1–64 letters, digits, '_', '-' or '.'",
                config.node_id
            )));
        }
        if config.lease < Duration::from_millis(300) {
            return Err(ClusterError::Config(
                "--lease-ms must be at least 300 (renewed every third of it)".into(),
            ));
        }
        let url = redacted_url(&config.nats_url);
        let options = config
            .nats_security
            .options()
            .await
            .map_err(|e| ClusterError::Nats(url.clone(), e))?;
        let nats = options
            .name(format!("navguard {}", config.node_id))
            .connection_timeout(Duration::from_secs(5))
            .event_callback(|event| async move {
                tracing::info!(%event, "nats");
            })
            .connect(config.nats_url.as_str())
            .await
            .map_err(|e| ClusterError::Nats(url.clone(), e.to_string()))?;
        if config.keyring.is_none() {
            tracing::warn!(
                "no cluster key: bus messages are neither signed nor checked, so anyone who can \
                 publish on NATS can send events to this node's sockets (docs/deployment.md)"
            );
        }
        let (outgoing, rx) = mpsc::channel(bus::PUBLISH_QUEUE);
        let cluster = Arc::new(Cluster {
            config,
            nats,
            outgoing,
            draining: watch::Sender::new(false),
            leaving: AtomicBool::new(false),
            locks: Mutex::default(),
            counters: ClusterCounters::default(),
        });
        tokio::spawn(bus::publisher(
            cluster.nats.clone(),
            cluster.config.keyring.clone(),
            cluster.config.node_id.clone(),
            rx,
        ));
        Ok(cluster)
    }

    /// This node's id.
    pub fn node_id(&self) -> &str {
        &self.config.node_id
    }

    /// The NATS client.
    pub fn nats(&self) -> &async_nats::Client {
        &self.nats
    }

    /// True once the node drains (new streams, sessions and leases are refused).
    pub fn draining(&self) -> bool {
        *self.draining.borrow()
    }

    /// Starts draining.
    pub fn start_draining(&self) {
        self.draining.send_replace(true);
    }

    /// Turns true when the node starts draining (for the sockets that close then).
    pub fn drain_signal(&self) -> watch::Receiver<bool> {
        self.draining.subscribe()
    }

    /// True once the draining node has handed its sessions over (`/healthz` answers 503).
    pub fn leaving(&self) -> bool {
        self.leaving.load(Ordering::Relaxed)
    }

    /// Marks the sessions handed over: `/healthz` answers 503 from now on.
    pub fn start_leaving(&self) {
        self.leaving.store(true, Ordering::Relaxed);
    }

    /// The lock that serialises lease changes of `session` on this node.
    fn lock_for(&self, session: &str) -> Arc<tokio::sync::Mutex<()>> {
        let mut locks = self.locks.lock().unwrap_or_else(|p| p.into_inner());
        // Locks nobody waits on are dropped now and then, so the map stays small.
        if locks.len() > 4096 {
            locks.retain(|_, l| Arc::strong_count(l) > 1);
        }
        locks.entry(session.to_owned()).or_default().clone()
    }

    /// A lease expiry `lease` from now, Unix ms.
    pub fn expiry(&self) -> i64 {
        crate::service::now_ms() + self.config.lease.as_millis() as i64
    }

    /// The headers to send a message with: `headers` with the sender, time and MAC added
    /// when the node has a cluster key, else as they are.
    pub fn seal(
        &self,
        subject: &str,
        headers: Option<async_nats::HeaderMap>,
        payload: &[u8],
    ) -> Option<async_nats::HeaderMap> {
        mac::seal(
            self.config.keyring.as_deref(),
            self.node_id(),
            subject,
            headers,
            payload,
        )
    }

    /// Whether a received message may be used: always without a cluster key; with one,
    /// only with a valid MAC. A refused message is counted and logged (its subject, the
    /// reason and its claimed sender; never its payload).
    pub fn accept(&self, message: &async_nats::Message) -> bool {
        let Some(ring) = &self.config.keyring else {
            return true;
        };
        let verdict = ring.verify(
            message.subject.as_str(),
            message.headers.as_ref(),
            &message.payload,
            crate::service::now_ms(),
        );
        let Err(reason) = verdict else {
            return true;
        };
        let n = self.counters.bus_rejected.fetch_add(1, Ordering::Relaxed) + 1;
        // The first ten, then every power of two: a flood of forgeries shows in the
        // counter without flooding the log.
        if n <= 10 || n.is_power_of_two() {
            let sender = message
                .headers
                .as_ref()
                .and_then(|h| h.get(mac::SENDER_HEADER))
                .map(|v| v.as_str().to_owned());
            tracing::warn!(
                subject = %message.subject,
                %reason,
                claimed_sender = ?sender,
                rejected_total = n,
                "bus message dropped: not signed with the cluster key"
            );
        }
        false
    }

    /// Queues an event for NATS (dropped, and counted, if the queue is full: the
    /// subscribers see the gap in the sequence).
    pub fn publish(&self, message: bus::Outgoing) {
        match self.outgoing.try_send(message) {
            Ok(()) => {
                self.counters.published.fetch_add(1, Ordering::Relaxed);
            }
            Err(_) => {
                self.counters
                    .publish_dropped
                    .fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// The counters as Prometheus text lines.
    pub fn metrics_text(&self) -> String {
        let c = &self.counters;
        let lines = [
            (
                "navguard_leases_acquired_total",
                "Session leases taken by this node",
                &c.leases_acquired,
            ),
            (
                "navguard_lease_takeovers_total",
                "Leases taken from an expired or gone owner (failovers)",
                &c.takeovers,
            ),
            (
                "navguard_leases_lost_total",
                "Leases found taken by another node (fenced)",
                &c.leases_lost,
            ),
            (
                "navguard_leases_released_total",
                "Leases given up (drain, handover)",
                &c.leases_released,
            ),
            (
                "navguard_forwarded_requests_total",
                "REST requests forwarded to a session's owner",
                &c.forwarded,
            ),
            (
                "navguard_nats_published_total",
                "Event messages queued for NATS",
                &c.published,
            ),
            (
                "navguard_nats_dropped_total",
                "Event messages dropped: the NATS publisher queue was full",
                &c.publish_dropped,
            ),
            (
                "navguard_checkpoints_total",
                "Session checkpoints committed",
                &c.checkpoints,
            ),
            (
                "navguard_checkpoint_failures_total",
                "Session checkpoints refused (fenced) or failed",
                &c.checkpoint_failures,
            ),
            (
                "navguard_event_gaps_total",
                "Events sockets closed on a gap in a session's sequence",
                &c.event_gaps,
            ),
            (
                "navguard_bus_rejected_total",
                "Bus messages dropped for a missing, wrong or stale MAC",
                &c.bus_rejected,
            ),
        ];
        let mut out = String::new();
        for (name, help, value) in lines {
            out.push_str(&format!(
                "# HELP {name} {help}\n# TYPE {name} counter\n{name} {}\n",
                value.load(Ordering::Relaxed)
            ));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nats_urls_are_logged_without_their_credentials() {
        assert_eq!(
            redacted_url("nats://user:s3cret@nats.example:4222"),
            "nats://***@nats.example:4222"
        );
        assert_eq!(
            redacted_url("tls://tok@10.0.0.1:4222"),
            "tls://***@10.0.0.1:4222"
        );
        assert_eq!(
            redacted_url("nats://127.0.0.1:4222"),
            "nats://127.0.0.1:4222"
        );
        assert_eq!(redacted_url("no scheme@at all"), "no scheme@at all");
    }

    #[test]
    fn the_settings_print_without_the_password_token_or_key() {
        let mut config = ClusterConfig::new("n1", "http://a", "nats://h:1");
        config.nats_security.login = NatsLogin::UserPassword {
            user: "navguard-node".into(),
            password: "pw-0123456789".into(),
        };
        let key = "k".repeat(40);
        config.keyring = Some(Arc::new(mac::Keyring::parse(&key).unwrap()));
        let printed = format!("{config:?}");
        assert!(printed.contains("navguard-node"), "{printed}");
        assert!(!printed.contains("pw-0123456789"), "{printed}");
        assert!(!printed.contains(&key), "{printed}");
        let token = format!("{:?}", NatsLogin::Token("tok-0123456789".into()));
        assert!(!token.contains("tok-0123456789"), "{token}");
    }
}
