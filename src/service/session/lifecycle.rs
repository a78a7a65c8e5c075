//! A session's lifecycle on this node, in one place: its actor started (a new session, one
//! restored at boot, one whose lease this node takes), registered, and its spec stored,
//! each step undone when a later one is refused, so no half-started session stays behind.
//! The REST handlers, the start-up and the cluster call these and stay thin.

use std::sync::atomic::Ordering;

use super::actor::{self, ActorDeps};
use super::{Registry, SessionError, SessionHandle};
use crate::service::store::{Checkpoint, Fence, StoredSession};

/// Why a started actor was not registered (it has been stopped).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refused {
    /// The id is running here already.
    Duplicate,
    /// The node holds its limit of sessions.
    Full,
    /// It was registered, and removed again (deleted) before it could be read back.
    Gone,
}

/// Registers a started actor, or stops it and says why not.
pub async fn register(
    registry: &Registry,
    handle: SessionHandle,
    max_sessions: usize,
) -> Result<SessionHandle, Refused> {
    let id = handle.id().to_owned();
    if let Err((handle, duplicate)) = registry.try_insert(handle, max_sessions) {
        handle.shutdown().await;
        return Err(if duplicate {
            Refused::Duplicate
        } else {
            Refused::Full
        });
    }
    // The registered actor (a concurrent delete may have removed it: then it is gone).
    registry.get(&id).ok_or(Refused::Gone)
}

/// Creates a new session: its actor (which builds every monitor, so a bad spec is refused
/// here), on a cluster node the session's first lease (its claim on the id in the whole
/// cluster), registered, then its spec stored by the actor itself, in its own order with
/// any change that reached it first. A refusal at any step undoes the steps before it.
pub async fn create(
    deps: ActorDeps,
    registry: &Registry,
    max_sessions: usize,
    stored: StoredSession,
) -> Result<SessionHandle, SessionError> {
    let id = stored.id.clone();
    let handle = match deps.cluster.clone() {
        None => actor::spawn(stored, deps).await?,
        Some(cluster) => {
            if cluster.draining() {
                return Err(SessionError::Unavailable(
                    "this node is draining: create the session on another node".into(),
                ));
            }
            let fence = Fence {
                session: id.clone(),
                owner: cluster.node_id().to_owned(),
                epoch: 1,
            };
            let store = deps.store.clone();
            let handle = actor::spawn_owned(stored, deps, fence, None).await?;
            let config = &cluster.config;
            let created = store
                .create_lease(&id, cluster.node_id(), &config.advertise, cluster.expiry())
                .await;
            match created {
                Ok(true) => {
                    cluster
                        .counters
                        .leases_acquired
                        .fetch_add(1, Ordering::Relaxed);
                    handle
                }
                Ok(false) => {
                    handle.shutdown().await;
                    return Err(SessionError::Exists(id));
                }
                Err(e) => {
                    handle.shutdown().await;
                    return Err(SessionError::Store(e.to_string()));
                }
            }
        }
    };
    let handle =
        register(registry, handle, max_sessions)
            .await
            .map_err(|refused| match refused {
                Refused::Duplicate => SessionError::Exists(id.clone()),
                Refused::Full => SessionError::TooLarge(format!(
                    "the server holds its limit of {max_sessions} sessions"
                )),
                Refused::Gone => SessionError::Stopped(id.clone()),
            })?;
    if let Err(e) = handle.persist().await {
        if let Some(h) = registry.remove(&id) {
            h.shutdown().await;
        }
        return Err(e);
    }
    Ok(handle)
}

/// Starts a session this node has just taken the lease of (`fence`), its state restored
/// from `checkpoint`, and registers it.
pub async fn take(
    deps: ActorDeps,
    registry: &Registry,
    max_sessions: usize,
    stored: StoredSession,
    fence: Fence,
    checkpoint: Option<Checkpoint>,
) -> Result<SessionHandle, SessionError> {
    let id = stored.id.clone();
    let handle = actor::spawn_owned(stored, deps, fence, checkpoint).await?;
    register(registry, handle, max_sessions)
        .await
        .map_err(|refused| match refused {
            Refused::Gone => SessionError::Stopped(id),
            Refused::Duplicate | Refused::Full => SessionError::Unavailable(format!(
                "the node holds its limit of {max_sessions} sessions"
            )),
        })
}

/// Restarts a stored session at boot (a single node); a duplicate id is refused.
pub async fn restart(
    deps: ActorDeps,
    registry: &Registry,
    stored: StoredSession,
) -> Result<SessionHandle, SessionError> {
    let id = stored.id.clone();
    let handle = actor::spawn(stored, deps).await?;
    register(registry, handle, usize::MAX)
        .await
        .map_err(|_| SessionError::Exists(id))
}
