//! Which node runs a session, and moving it (docs/deployment.md, Failover): finding the
//! owner, taking a lease over, asking an owner to hand a session over, renewing this
//! node's leases, draining, and the REST middleware that forwards a request to the owner.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::Cluster;
use super::rpc::{self, Call, CallError, ReleaseAnswer};
use crate::service::app::AppState;
use crate::service::audit;
use crate::service::error::ApiError;
use crate::service::now_ms;
use crate::service::session::{SessionHandle, lifecycle};
use crate::service::store::{Acquire, Fence, Lease, StoredSession};

/// Where a session runs.
#[derive(Debug)]
pub enum Owner {
    /// On this node.
    Local(SessionHandle),
    /// On another node, which holds its lease.
    Remote(Lease),
    /// No such session.
    Missing,
}

fn cluster(state: &AppState) -> Option<&Arc<Cluster>> {
    state.cluster.as_ref()
}

/// Finds session `id`: running here, owned by a live lease elsewhere, or neither, in
/// which case this node takes its lease (free, expired, or its own) and runs it,
/// restoring its last checkpoint.
pub async fn locate(state: &AppState, id: &str) -> Result<Owner, ApiError> {
    if let Some(h) = state.registry.get(id) {
        return Ok(Owner::Local(h));
    }
    let Some(cluster) = cluster(state) else {
        return Ok(Owner::Missing);
    };
    let lock = cluster.lock_for(id);
    let _guard = lock.lock().await;
    let stored = match settled(state, id).await? {
        Ok(stored) => stored,
        Err(owner) => return Ok(owner),
    };
    match state.store.lease(id).await? {
        Some(lease) if lease.live(now_ms()) && lease.owner != cluster.node_id() => {
            Ok(Owner::Remote(lease))
        }
        _ => take(state, cluster, stored, false).await,
    }
}

/// Under the session's lock: the session running here now (another request took it
/// meanwhile) or gone (`Err` with that answer), else its stored spec to take it with.
async fn settled(state: &AppState, id: &str) -> Result<Result<StoredSession, Owner>, ApiError> {
    if let Some(h) = state.registry.get(id) {
        return Ok(Err(Owner::Local(h)));
    }
    Ok(state.store.session(id).await?.ok_or(Owner::Missing))
}

/// Takes the lease of `id` whatever its state, because its owner released it or is gone.
async fn take_over(state: &AppState, id: &str, gone: bool) -> Result<Owner, ApiError> {
    let Some(cluster) = cluster(state) else {
        return Ok(Owner::Missing);
    };
    let lock = cluster.lock_for(id);
    let _guard = lock.lock().await;
    let stored = match settled(state, id).await? {
        Ok(stored) => stored,
        Err(owner) => return Ok(owner),
    };
    if gone {
        cluster.counters.takeovers.fetch_add(1, Ordering::Relaxed);
    }
    take(state, cluster, stored, true).await
}

/// Takes the lease (under the session's lock) and starts the actor from the checkpoint;
/// refused while the node drains (it would run the session only to hand it over again).
async fn take(
    state: &AppState,
    cluster: &Cluster,
    stored: StoredSession,
    force: bool,
) -> Result<Owner, ApiError> {
    if cluster.draining() {
        return Err(ApiError::Unavailable(
            "this node is draining: retry (the load balancer sends you to another node)".into(),
        ));
    }
    let id = stored.id.clone();
    let now = now_ms();
    let epoch = match state
        .store
        .acquire_lease(
            &id,
            cluster.node_id(),
            &cluster.config.advertise,
            now,
            cluster.expiry(),
            force,
        )
        .await?
    {
        Acquire::Taken(epoch) => epoch,
        Acquire::Held(lease) => return Ok(Owner::Remote(lease)),
    };
    cluster
        .counters
        .leases_acquired
        .fetch_add(1, Ordering::Relaxed);
    let fence = Fence {
        session: id.clone(),
        owner: cluster.node_id().to_owned(),
        epoch,
    };
    let checkpoint = state.store.checkpoint(&id).await?;
    let limit = state.config.limits.max_sessions;
    let handle = lifecycle::take(
        state.actor_deps(),
        &state.registry,
        limit,
        stored,
        fence,
        checkpoint,
    )
    .await?;
    tracing::info!(session = %id, epoch, "session lease taken");
    Ok(Owner::Local(handle))
}

/// The session for an ingest stream on this node: running here, or taken over (its lease
/// expired or was released, or its owner is gone), or handed over by its live owner
/// because the load balancer sends the stream here. Refused with `not_owner` when the
/// owner keeps it (a stream is attached there).
pub async fn claim(state: &AppState, id: &str, path: &str) -> Result<SessionHandle, ApiError> {
    let Some(cluster) = cluster(state).cloned() else {
        return state
            .registry
            .get(id)
            .ok_or_else(|| ApiError::NotFound(format!("no session '{id}'")));
    };
    if cluster.draining() {
        return Err(ApiError::Unavailable(
            "this node is draining: reconnect (the load balancer sends you to another node)".into(),
        ));
    }
    let deadline = tokio::time::Instant::now() + cluster.config.lease + Duration::from_secs(1);
    loop {
        let lease = match locate(state, id).await? {
            Owner::Local(h) => return Ok(h),
            Owner::Missing => return Err(ApiError::NotFound(format!("no session '{id}'"))),
            Owner::Remote(lease) => lease,
        };
        let asked: Result<ReleaseAnswer, CallError> = rpc::call(
            &cluster,
            &lease.owner,
            &Call::Release {
                session: id.to_owned(),
            },
        )
        .await;
        let owner = match asked {
            Ok(answer) if answer.released => take_over(state, id, false).await?,
            Ok(answer) => {
                return Err(ApiError::NotOwner {
                    message: format!(
                        "session '{id}' runs on node '{}', which keeps it: {}",
                        lease.owner,
                        answer.reason.unwrap_or_default()
                    ),
                    location: format!("{}{path}", lease.address),
                    owner: lease.owner,
                });
            }
            Err(CallError::Gone(node)) => {
                tracing::warn!(session = %id, %node, "owner gone; taking the session over");
                take_over(state, id, true).await?
            }
            Err(e) => {
                // Unreachable but maybe alive: wait for its lease to lapse.
                tracing::warn!(session = %id, error = %e, "owner does not answer; waiting for its lease");
                let lapse = lease.expires_ms - now_ms();
                let now = tokio::time::Instant::now();
                if now >= deadline {
                    return Err(ApiError::Unavailable(format!(
                        "session '{id}' is owned by node '{}', which does not answer: {e}",
                        lease.owner
                    )));
                }
                let wait = Duration::from_millis(lapse.clamp(50, 1000) as u64);
                tokio::time::sleep(wait.min(deadline - now)).await;
                continue;
            }
        };
        match owner {
            Owner::Local(h) => return Ok(h),
            Owner::Missing => return Err(ApiError::NotFound(format!("no session '{id}'"))),
            // Somebody else took it meanwhile: ask again.
            Owner::Remote(_) if tokio::time::Instant::now() < deadline => continue,
            Owner::Remote(lease) => {
                return Err(ApiError::NotOwner {
                    message: format!("session '{id}' moved to node '{}'", lease.owner),
                    location: format!("{}{path}", lease.address),
                    owner: lease.owner,
                });
            }
        }
    }
}

/// The session id of a session-specific REST path (`/api/v1/sessions/{id}` and below, not
/// the two sockets, which place themselves).
fn session_of(path: &str) -> Option<&str> {
    let rest = path.strip_prefix("/api/v1/sessions/")?;
    let (id, tail) = rest.split_once('/').unwrap_or((rest, ""));
    (!id.is_empty() && !matches!(tail, "ingest" | "events")).then_some(id)
}

/// Middleware on the `/api` routes of a cluster node: a request for a session another
/// node runs is forwarded to it over NATS and its answer returned as it is; a session
/// nobody runs is taken here first.
pub async fn route(State(state): State<AppState>, request: Request, next: Next) -> Response {
    let Some(cluster) = state.cluster.clone() else {
        return next.run(request).await;
    };
    let Some(id) = session_of(request.uri().path()).map(str::to_owned) else {
        return next.run(request).await;
    };
    let forwarded = request.headers().contains_key(rpc::FORWARDED_HEADER);
    let lease = match locate(&state, &id).await {
        Ok(Owner::Local(_) | Owner::Missing) => return next.run(request).await,
        Ok(Owner::Remote(lease)) => lease,
        Err(e) => return e.into_response(),
    };
    if forwarded {
        // Forwarded here, but the session moved on: never a second hop.
        return ApiError::Unavailable(format!(
            "session '{id}' moved to node '{}' meanwhile; retry",
            lease.owner
        ))
        .into_response();
    }
    let (parts, body) = request.into_parts();
    let limit = state.config.limits.max_body_bytes;
    let Ok(bytes) = axum::body::to_bytes(body, limit).await else {
        return ApiError::TooLarge(format!("the body is over {limit} bytes")).into_response();
    };
    let header = |name: &str| {
        parts
            .headers
            .get(name)
            .and_then(|v| v.to_str().ok())
            .map(str::to_owned)
    };
    let uri = parts
        .uri
        .path_and_query()
        .map_or_else(|| parts.uri.path().to_owned(), |pq| pq.as_str().to_owned());
    let text = String::from_utf8_lossy(&bytes).into_owned();
    let reason = match audit::reason(&parts.headers) {
        Ok(r) => r,
        Err(e) => return e.into_response(),
    };
    let headers = rpc::Forwarded {
        authorization: header("authorization"),
        content_type: header("content-type"),
        reason,
        forwarded_for: audit::forwarded_for_with_peer(&parts.headers, &parts.extensions),
    };
    match rpc::forward(
        &cluster,
        &lease.owner,
        parts.method.as_str(),
        &uri,
        headers,
        text,
    )
    .await
    {
        Ok(response) => response,
        Err(CallError::Gone(_)) => match take_over(&state, &id, true).await {
            Ok(_) => {
                next.run(Request::from_parts(parts, axum::body::Body::from(bytes)))
                    .await
            }
            Err(e) => e.into_response(),
        },
        Err(e) => ApiError::Unavailable(e.to_string()).into_response(),
    }
}

/// Renews this node's leases every third of the lease; a session whose lease another
/// node took is stopped here at once (it could not write anyway: fenced).
pub async fn renew(state: AppState, cluster: Arc<Cluster>) {
    let mut tick = tokio::time::interval(cluster.config.lease / 3);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut shutdown = state.shutdown.clone();
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            _ = shutdown.wait_for(|s| *s) => return,
        }
        // The sessions running before the renewal: one taken after it is not judged.
        let running = state.registry.list();
        let held: HashMap<String, i64> = match state
            .store
            .renew_leases(cluster.node_id(), cluster.expiry())
            .await
        {
            Ok(rows) => rows.into_iter().collect(),
            Err(e) => {
                tracing::error!(error = %e, "lease renewal failed");
                continue;
            }
        };
        for handle in running {
            let Some(epoch) = handle.lease_epoch() else {
                continue;
            };
            if held.get(handle.id()) != Some(&epoch) && state.registry.remove_if_same(&handle) {
                cluster.counters.leases_lost.fetch_add(1, Ordering::Relaxed);
                tracing::warn!(session = %handle.id(), epoch, "lease lost to another node; session stopped here");
                handle.shutdown().await;
            }
        }
    }
}

/// Drains this node (docs/deployment.md, Drain a node). First, while `/healthz` still
/// answers 200 and the load balancer still relays this node's WebSockets: new streams,
/// sessions and leases are refused (503), events sockets close (1001), and every session
/// is handed over (its ingest socket told `moved` and closed with 1000, a final
/// checkpoint written, the lease released). Then `/healthz` answers 503 for
/// `--drain-wait-ms`, so the load balancer marks the node down before it exits. In the
/// other order the load balancer would mark the node down first and cut its sockets
/// (`on-marked-down shutdown-sessions`) before they were told `moved`.
pub async fn drain(state: &AppState, cluster: &Cluster) {
    cluster.start_draining();
    let sessions = state.registry.list();
    let n = sessions.len();
    tracing::info!(sessions = n, "draining: handing the sessions over");
    for handle in sessions {
        if let Err(e) = handle.release(true).await {
            tracing::warn!(session = %handle.id(), error = %e, "handover failed; the lease will expire");
        }
        state.registry.remove_if_same(&handle);
    }
    cluster.start_leaving();
    tracing::info!(
        sessions = n,
        wait_ms = cluster.config.drain_wait.as_millis() as u64,
        "sessions handed over; /healthz answers 503 until the node exits"
    );
    tokio::time::sleep(cluster.config.drain_wait).await;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn session_paths_are_told_from_the_sockets_and_the_collection() {
        assert_eq!(session_of("/api/v1/sessions/a.b"), Some("a.b"));
        assert_eq!(session_of("/api/v1/sessions/a/stats"), Some("a"));
        assert_eq!(
            session_of("/api/v1/sessions/a/monitors/m/threshold"),
            Some("a")
        );
        assert_eq!(session_of("/api/v1/sessions/a/ingest"), None);
        assert_eq!(session_of("/api/v1/sessions/a/events"), None);
        assert_eq!(session_of("/api/v1/sessions"), None);
        assert_eq!(session_of("/api/v1/sessions/"), None);
        assert_eq!(session_of("/api/v1/alarms"), None);
    }
}
