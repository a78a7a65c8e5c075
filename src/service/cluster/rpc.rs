//! Node-to-node calls over NATS request/reply, on the subject `navguard.rpc.<node>`:
//!
//! - `http`: a REST request for a session this node owns, sent by the node the client
//!   reached; it is run through this node's own router (auth included) and the answer
//!   goes back as it is. The request carries `x-navguard-forwarded`, so it is never
//!   forwarded a second time.
//! - `release`: another node asks for a session because the load balancer sends its
//!   ingest stream there. Granted unless a stream is attached here: the actor writes a
//!   final checkpoint and releases the lease, and the asker takes it at once.
//!
//! With a cluster key, calls and answers are signed like events ([`super::mac`]): a node
//! ignores a call without a valid MAC (its caller times out), and a caller refuses such
//! an answer.
//!
//! A request to a node with no subscription (NATS answers "no responders" at once) means
//! the node's process is gone: the caller takes the session over without waiting for its
//! lease to expire (fencing keeps that safe even if the node were only cut off).

use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::body::Body;
use axum::http::{HeaderValue, Request, Response, StatusCode};
use bytes::Bytes;
use futures_util::StreamExt;
use serde::{Deserialize, Serialize};
use tower::ServiceExt;

use super::Cluster;
use crate::service::session::Registry;

/// The header a forwarded request carries (the forwarding node's id).
pub const FORWARDED_HEADER: &str = "x-navguard-forwarded";

/// How long a node waits for another node's answer.
pub const RPC_TIMEOUT: Duration = Duration::from_secs(6);

/// The subject a node serves its calls on.
pub fn subject(node: &str) -> String {
    format!("navguard.rpc.{}", super::bus::token(node))
}

/// A call.
#[derive(Debug, Serialize, Deserialize)]
#[serde(tag = "op", rename_all = "snake_case")]
pub enum Call {
    /// Run a REST request.
    Http {
        /// Method.
        method: String,
        /// Path and query.
        uri: String,
        /// The caller's `Authorization` header.
        authorization: Option<String>,
        /// The caller's `Content-Type` header.
        content_type: Option<String>,
        /// The caller's reason for a change (`X-Navguard-Reason`, decoded), for the audit
        /// log.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        reason: Option<String>,
        /// Where the request came from: its `X-Forwarded-For` list and the forwarding
        /// node's peer address, for the audit log.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        forwarded_for: Option<String>,
        /// The body (REST bodies are JSON text).
        body: String,
        /// The node forwarding it.
        from: String,
    },
    /// Hand session `session` over to the caller.
    Release {
        /// Session id.
        session: String,
    },
}

/// A REST answer.
#[derive(Debug, Serialize, Deserialize)]
pub struct HttpAnswer {
    /// Status code.
    pub status: u16,
    /// `Content-Type`.
    pub content_type: Option<String>,
    /// Body text.
    pub body: String,
}

/// The answer to `release`.
#[derive(Debug, Serialize, Deserialize)]
pub struct ReleaseAnswer {
    /// Granted: the lease is free now.
    pub released: bool,
    /// Why not.
    pub reason: Option<String>,
}

/// Why a call got no answer.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CallError {
    /// Nobody serves the node's subject: its process is gone.
    #[error("node '{0}' is gone (no NATS subscription)")]
    Gone(String),
    /// The node did not answer in time.
    #[error("node '{0}' did not answer within {1:?}")]
    Timeout(String, Duration),
    /// Anything else (NATS down, a garbled answer).
    #[error("calling node '{0}': {1}")]
    Failed(String, String),
}

/// Sends `call` to `node` and decodes its answer.
pub async fn call<T: for<'de> Deserialize<'de>>(
    cluster: &Cluster,
    node: &str,
    call: &Call,
) -> Result<T, CallError> {
    let payload =
        serde_json::to_vec(call).map_err(|e| CallError::Failed(node.into(), e.to_string()))?;
    let to = subject(node);
    let mut request = async_nats::Request::new().timeout(Some(RPC_TIMEOUT));
    if let Some(headers) = cluster.seal(&to, None, &payload) {
        request = request.headers(headers);
    }
    let request = request.payload(Bytes::from(payload));
    let answer = cluster
        .nats()
        .send_request(to, request)
        .await
        .map_err(|e| match e.kind() {
            async_nats::RequestErrorKind::NoResponders => CallError::Gone(node.into()),
            async_nats::RequestErrorKind::TimedOut => CallError::Timeout(node.into(), RPC_TIMEOUT),
            _ => CallError::Failed(node.into(), e.to_string()),
        })?;
    if !cluster.accept(&answer) {
        return Err(CallError::Failed(
            node.into(),
            "the answer is not signed with the cluster key".into(),
        ));
    }
    serde_json::from_slice(&answer.payload)
        .map_err(|e| CallError::Failed(node.into(), e.to_string()))
}

/// The headers of a forwarded REST request that travel with it.
#[derive(Debug, Default)]
pub struct Forwarded {
    /// `Authorization`.
    pub authorization: Option<String>,
    /// `Content-Type`.
    pub content_type: Option<String>,
    /// `X-Navguard-Reason`, decoded.
    pub reason: Option<String>,
    /// `X-Forwarded-For` with the caller's peer address appended.
    pub forwarded_for: Option<String>,
}

/// Forwards a REST request to `node`; its answer as a response.
pub async fn forward(
    cluster: &Cluster,
    node: &str,
    method: &str,
    uri: &str,
    headers: Forwarded,
    body: String,
) -> Result<Response<Body>, CallError> {
    let answer: HttpAnswer = call(
        cluster,
        node,
        &Call::Http {
            method: method.to_owned(),
            uri: uri.to_owned(),
            authorization: headers.authorization,
            content_type: headers.content_type,
            reason: headers.reason,
            forwarded_for: headers.forwarded_for,
            body,
            from: cluster.node_id().to_owned(),
        },
    )
    .await?;
    cluster
        .counters
        .forwarded
        .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let mut response = Response::new(Body::from(answer.body));
    *response.status_mut() = StatusCode::from_u16(answer.status).unwrap_or(StatusCode::BAD_GATEWAY);
    if let Some(ct) = answer
        .content_type
        .and_then(|c| HeaderValue::from_str(&c).ok())
    {
        response.headers_mut().insert("content-type", ct);
    }
    if let Ok(owner) = HeaderValue::from_str(node) {
        response.headers_mut().insert("x-navguard-owner", owner);
    }
    Ok(response)
}

/// Serves this node's calls until the NATS connection closes: each call in a task of its
/// own.
pub async fn serve(cluster: Arc<Cluster>, router: Router, registry: Arc<Registry>) {
    let mut calls = match cluster.nats().subscribe(subject(cluster.node_id())).await {
        Ok(s) => s,
        Err(e) => {
            tracing::error!(error = %e, "cannot serve node calls over NATS");
            return;
        }
    };
    while let Some(message) = calls.next().await {
        let Some(reply) = message.reply.clone() else {
            continue;
        };
        if !cluster.accept(&message) {
            continue;
        }
        let (cluster, router, registry) = (cluster.clone(), router.clone(), registry.clone());
        tokio::spawn(async move {
            let answer = match serde_json::from_slice::<Call>(&message.payload) {
                Ok(Call::Http {
                    method,
                    uri,
                    authorization,
                    content_type,
                    reason,
                    forwarded_for,
                    body,
                    from,
                }) => {
                    let headers = Forwarded {
                        authorization,
                        content_type,
                        reason,
                        forwarded_for,
                    };
                    let a = run_http(router, &method, &uri, headers, body, &from).await;
                    serde_json::to_vec(&a)
                }
                Ok(Call::Release { session }) => {
                    let a = release(&registry, &session).await;
                    serde_json::to_vec(&a)
                }
                Err(e) => serde_json::to_vec(&HttpAnswer {
                    status: 400,
                    content_type: None,
                    body: format!("bad node call: {e}"),
                }),
            };
            if let Ok(bytes) = answer {
                let sent = match cluster.seal(reply.as_str(), None, &bytes) {
                    Some(h) => {
                        cluster
                            .nats()
                            .publish_with_headers(reply, h, Bytes::from(bytes))
                            .await
                    }
                    None => cluster.nats().publish(reply, Bytes::from(bytes)).await,
                };
                if let Err(e) = sent {
                    tracing::warn!(error = %e, "nats: answering a node call failed");
                }
            }
        });
    }
}

async fn run_http(
    router: Router,
    method: &str,
    uri: &str,
    headers: Forwarded,
    body: String,
    from: &str,
) -> HttpAnswer {
    let mut builder = Request::builder()
        .method(method)
        .uri(uri)
        .header(FORWARDED_HEADER, from);
    if let Some(a) = headers.authorization {
        builder = builder.header("authorization", a);
    }
    if let Some(c) = headers.content_type {
        builder = builder.header("content-type", c);
    }
    // A reason is UTF-8 text; its bytes make a valid header value (obs-text), read back as
    // UTF-8 by the audit log.
    if let Some(r) = headers
        .reason
        .and_then(|r| HeaderValue::from_bytes(r.as_bytes()).ok())
    {
        builder = builder.header(crate::service::audit::REASON_HEADER, r);
    }
    if let Some(f) = headers.forwarded_for {
        builder = builder.header("x-forwarded-for", f);
    }
    let request = match builder.body(Body::from(body)) {
        Ok(r) => r,
        Err(e) => {
            return HttpAnswer {
                status: 400,
                content_type: None,
                body: e.to_string(),
            };
        }
    };
    let response = match router.oneshot(request).await {
        Ok(r) => r,
        Err(never) => match never {},
    };
    let status = response.status().as_u16();
    let content_type = response
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .map(str::to_owned);
    let body = axum::body::to_bytes(response.into_body(), usize::MAX)
        .await
        .map(|b| String::from_utf8_lossy(&b).into_owned())
        .unwrap_or_default();
    HttpAnswer {
        status,
        content_type,
        body,
    }
}

async fn release(registry: &Registry, session: &str) -> ReleaseAnswer {
    let Some(handle) = registry.get(session) else {
        // Not running here: nothing to hand over; the asker takes the lease if it is free.
        return ReleaseAnswer {
            released: true,
            reason: None,
        };
    };
    match handle.release(false).await {
        Ok(()) => {
            registry.remove_if_same(&handle);
            ReleaseAnswer {
                released: true,
                reason: None,
            }
        }
        Err(e) => ReleaseAnswer {
            released: false,
            reason: Some(e.to_string()),
        },
    }
}
