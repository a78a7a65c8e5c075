//! The application state and the router. `app(state)` builds every route from
//! the `ROUTES` table, so tests can list the routes the server really has.

use std::sync::Arc;

use axum::Router;
use axum::extract::DefaultBodyLimit;
use axum::middleware;
use axum::routing::{MethodRouter, get, post};
use tokio::sync::watch;

use super::api::{
    alarms, audit, chi2, features, health, models, recording, sessions, thresholds, whoami,
};
use super::cluster::Cluster;
use super::compute::ComputePool;
use super::config::ServiceConfig;
use super::error::ApiError;
use super::metrics::Metrics;
use super::session::Registry;
use super::session::actor::ActorDeps;
use super::store::Store;
use super::tokens::Tokens;
use super::train::Models;
use super::{auth, events, ingest};

/// Shared state of every handler. Cheap to clone.
#[derive(Debug, Clone)]
pub struct AppState {
    /// The SQLite store.
    pub store: Store,
    /// Live sessions.
    pub registry: Arc<Registry>,
    /// Process-wide counters for `/metrics`.
    pub metrics: Arc<Metrics>,
    /// Listen address, token and limits.
    pub config: Arc<ServiceConfig>,
    /// The tokens the server accepts, with their scopes (`--token`, `--tokens-file`).
    pub tokens: Arc<Tokens>,
    /// Flips to `true` when the server shuts down; sockets close on it.
    pub shutdown: watch::Receiver<bool>,
    /// Trained models and training jobs; the monitors' model source.
    pub models: Arc<Models>,
    /// The threads session actors step their monitors on (docs/architecture.md §A3).
    pub compute: Arc<ComputePool>,
    /// This node's cluster membership (`--nats`), if any (docs/deployment.md).
    pub cluster: Option<Arc<Cluster>>,
}

impl AppState {
    /// What a session actor needs.
    pub fn actor_deps(&self) -> ActorDeps {
        ActorDeps {
            store: self.store.clone(),
            metrics: self.metrics.clone(),
            models: self.models.clone(),
            compute: self.compute.clone(),
            record_default: self.config.record_default,
            history_samples: (f64::from(self.config.history_s)
                / navguard_core::session::history::PERIOD_S) as usize,
            cluster: self.cluster.clone(),
        }
    }
}

/// Every route: path and methods. `app` builds the router from this table and
/// the OpenAPI test checks the spec against it (and the router against it). What each
/// needs (public, a token, a scope) is `access::ROUTE_ACCESS`.
pub const ROUTES: &[(&str, &[&str])] = &[
    ("/", &["GET"]),
    ("/static/{file}", &["GET"]),
    ("/healthz", &["GET"]),
    ("/metrics", &["GET"]),
    ("/api/v1/whoami", &["GET"]),
    ("/api/v1/sessions", &["GET", "POST"]),
    ("/api/v1/sessions/{id}", &["GET", "DELETE"]),
    ("/api/v1/sessions/{id}/stats", &["GET"]),
    ("/api/v1/sessions/{id}/history", &["GET"]),
    ("/api/v1/sessions/{id}/recording", &["GET"]),
    ("/api/v1/sessions/{id}/calibration", &["GET"]),
    (
        "/api/v1/sessions/{id}/monitors/{name}/threshold",
        &["GET", "PUT"],
    ),
    ("/api/v1/sessions/{id}/ingest", &["GET"]),
    ("/api/v1/sessions/{id}/events", &["GET"]),
    ("/api/v1/chi2/threshold", &["GET"]),
    ("/api/v1/chi2/missed-detection", &["GET"]),
    ("/api/v1/alarms", &["GET"]),
    ("/api/v1/sessions/{id}/alarms/{alarm_id}/ack", &["POST"]),
    ("/api/v1/audit", &["GET"]),
    ("/api/v1/models", &["GET", "POST"]),
    ("/api/v1/models/{id}", &["GET", "DELETE"]),
    ("/api/v1/models/{id}/predict", &["POST"]),
    ("/api/v1/features", &["POST"]),
];

fn handlers(path: &str) -> MethodRouter<AppState> {
    match path {
        "/" => get(health::index),
        "/static/{file}" => get(health::asset),
        "/healthz" => get(health::healthz),
        "/metrics" => get(health::metrics),
        "/api/v1/whoami" => get(whoami::whoami),
        "/api/v1/sessions" => get(sessions::list).post(sessions::create),
        "/api/v1/sessions/{id}" => get(sessions::get).delete(sessions::delete),
        "/api/v1/sessions/{id}/stats" => get(sessions::stats),
        "/api/v1/sessions/{id}/history" => get(recording::history),
        "/api/v1/sessions/{id}/recording" => get(recording::recording),
        "/api/v1/sessions/{id}/calibration" => get(recording::calibration),
        "/api/v1/sessions/{id}/monitors/{name}/threshold" => {
            get(thresholds::get).put(thresholds::put)
        }
        "/api/v1/sessions/{id}/ingest" => get(ingest::ingest),
        "/api/v1/sessions/{id}/events" => get(events::events),
        "/api/v1/chi2/threshold" => get(chi2::threshold),
        "/api/v1/chi2/missed-detection" => get(chi2::missed_detection),
        "/api/v1/alarms" => get(alarms::list),
        "/api/v1/sessions/{id}/alarms/{alarm_id}/ack" => post(alarms::ack),
        "/api/v1/audit" => get(audit::list),
        "/api/v1/models" => get(models::list).post(models::create),
        "/api/v1/models/{id}" => get(models::get).delete(models::delete),
        "/api/v1/models/{id}/predict" => post(models::predict),
        "/api/v1/features" => post(features::compute),
        // Unreachable while ROUTES and this match agree; a unit test walks ROUTES.
        _ => MethodRouter::new(),
    }
}

async fn not_found() -> ApiError {
    ApiError::NotFound("no such route".into())
}

/// Builds the router.
pub fn app(state: AppState) -> Router {
    let mut public = Router::new();
    let mut api = Router::new();
    for &(path, allowed) in ROUTES {
        let mut methods =
            handlers(path).fallback(move || async move { ApiError::MethodNotAllowed(allowed) });
        if path == "/api/v1/models" {
            // Training sets are larger than other bodies (30,000 × 3 is ~2 MiB of JSON).
            methods = methods.layer(DefaultBodyLimit::max(
                state.config.limits.max_training_body_bytes,
            ));
        }
        if path.starts_with("/api/") {
            api = api.route(path, methods);
        } else {
            public = public.route(path, methods);
        }
    }
    // Auth and scopes run first (the outer layer), then a cluster node finds the
    // session's owner, then the node that runs the handler records a change in the
    // audit log.
    let api = api
        .route_layer(middleware::from_fn_with_state(
            state.clone(),
            super::audit::record,
        ))
        .route_layer(middleware::from_fn_with_state(
            state.clone(),
            super::cluster::own::route,
        ))
        .route_layer(middleware::from_fn_with_state(
            state.clone(),
            auth::authorize,
        ));
    public
        .merge(api)
        .fallback(not_found)
        .layer(DefaultBodyLimit::max(state.config.limits.max_body_bytes))
        .layer(tower_http::trace::TraceLayer::new_for_http().make_span_with(request_span))
        .with_state(state)
}

/// The span around every request, as tower-http's default (`request`, at
/// debug level, with method, target and version) but with the `token` query
/// parameter redacted: at `RUST_LOG=debug` the default logs the full target.
pub fn request_span<B>(req: &axum::http::Request<B>) -> tracing::Span {
    tracing::debug_span!(
        "request",
        method = %req.method(),
        uri = %auth::redacted_uri(req.uri()),
        version = ?req.version(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_request_span_never_shows_the_token() {
        let req = axum::http::Request::get("/api/v1/sessions/a/events?token=s3cret")
            .body(())
            .unwrap();
        let uri = auth::redacted_uri(req.uri());
        assert_eq!(uri, "/api/v1/sessions/a/events?token=REDACTED");
        // The span itself is built from the same function (checked end to end,
        // log output included, in tests/hardening.rs).
        let _span = request_span(&req);
    }

    #[test]
    fn every_route_in_the_table_has_handlers() {
        for (path, methods) in ROUTES {
            assert!(!methods.is_empty(), "{path}");
            // An empty MethodRouter would answer every method with 405.
            assert!(
                format!("{:?}", handlers(path)).len()
                    > format!("{:?}", MethodRouter::<AppState>::new()).len(),
                "{path}"
            );
        }
    }
}
