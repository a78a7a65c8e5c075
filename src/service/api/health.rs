//! `/healthz`, `/metrics` and the dashboard page.

use axum::Json;
use axum::extract::State;
use axum::http::header;
use axum::response::{Html, IntoResponse};
use serde_json::{Value, json};

use crate::service::app::AppState;

/// `GET /healthz`: liveness, with the version and session count.
pub async fn healthz(State(state): State<AppState>) -> Json<Value> {
    Json(
        json!({"status": "ok", "version": env!("CARGO_PKG_VERSION"), "sessions": state.registry.len()}),
    )
}

/// `GET /metrics`: Prometheus text exposition.
pub async fn metrics(State(state): State<AppState>) -> impl IntoResponse {
    (
        [(
            header::CONTENT_TYPE,
            "text/plain; version=0.0.4; charset=utf-8",
        )],
        state.metrics.render(state.registry.len()),
    )
}

/// `GET /`: the dashboard (embedded at compile time; no build step).
pub async fn index() -> Html<&'static str> {
    Html(include_str!("../../../static/index.html"))
}
