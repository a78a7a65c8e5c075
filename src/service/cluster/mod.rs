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
//! - **Drain.** On SIGTERM a node refuses new streams and leases, closes its events
//!   sockets and hands every session over (its stream told `moved`, a final checkpoint, the
//!   lease released, so the next node resumes exactly where it stopped) while `/healthz`
//!   still answers 200; then `/healthz` answers 503 for `--drain-wait-ms`, so the load
//!   balancer marks the node down only once its sockets have closed.

pub mod bus;
pub mod own;
pub mod rpc;

use std::collections::HashMap;
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
    /// The NATS server, `nats://host:port`.
    pub nats_url: String,
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
            lease: Duration::from_secs(5),
            checkpoint_interval: Duration::from_secs(1),
            drain_wait: Duration::from_secs(2),
        }
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
        let nats = async_nats::ConnectOptions::new()
            .name(format!("navguard {}", config.node_id))
            .connection_timeout(Duration::from_secs(5))
            .event_callback(|event| async move {
                tracing::info!(%event, "nats");
            })
            .connect(config.nats_url.as_str())
            .await
            .map_err(|e| ClusterError::Nats(config.nats_url.clone(), e.to_string()))?;
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
        tokio::spawn(bus::publisher(cluster.nats.clone(), rx));
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
