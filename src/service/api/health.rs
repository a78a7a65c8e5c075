//! `/healthz`, `/metrics` and the dashboard page.

use axum::Json;
use axum::extract::{Path, State};
use axum::http::{StatusCode, header};
use axum::response::{Html, IntoResponse};
use serde_json::{Value, json};

use crate::service::app::AppState;
use crate::service::error::ApiError;
use crate::service::metrics::SessionGauges;

/// `GET /healthz`: liveness, with the version and session count (and, on a cluster
/// node, its id); 503 `draining` once a draining node has handed its sessions over, so
/// the load balancer marks it down (and cuts what it still relays) only then.
pub async fn healthz(State(state): State<AppState>) -> (StatusCode, Json<Value>) {
    let mut body = json!({"status": "ok", "version": env!("CARGO_PKG_VERSION"), "sessions": state.registry.len()});
    let Some(cluster) = &state.cluster else {
        return (StatusCode::OK, Json(body));
    };
    body["node"] = json!(cluster.node_id());
    if cluster.leaving() {
        body["status"] = json!("draining");
        return (StatusCode::SERVICE_UNAVAILABLE, Json(body));
    }
    (StatusCode::OK, Json(body))
}

/// `GET /metrics`: Prometheus text exposition, with gauges gathered from every
/// session's latest published statistics.
pub async fn metrics(State(state): State<AppState>) -> impl IntoResponse {
    let mut gauges = SessionGauges::default();
    for handle in state.registry.list() {
        gauges.add(&handle.stats_watch().borrow());
    }
    (
        [(
            header::CONTENT_TYPE,
            "text/plain; version=0.0.4; charset=utf-8",
        )],
        {
            let mut text = state.metrics.render(state.registry.len(), &gauges);
            if let Some(cluster) = &state.cluster {
                text.push_str(&cluster.metrics_text());
            }
            text
        },
    )
}

/// `GET /`: the dashboard (embedded at compile time; no build step).
pub async fn index() -> Html<&'static str> {
    Html(include_str!("../../../static/index.html"))
}

/// The dashboard's scripts and style sheet, embedded at compile time: name,
/// content type, text. A flat list (no directories) so a path can never escape it.
const ASSETS: &[(&str, &str, &str)] = &[
    (
        "app.css",
        "text/css; charset=utf-8",
        include_str!("../../../static/app.css"),
    ),
    ("main.js", JS, include_str!("../../../static/main.js")),
    ("api.js", JS, include_str!("../../../static/api.js")),
    ("dom.js", JS, include_str!("../../../static/dom.js")),
    ("live.js", JS, include_str!("../../../static/live.js")),
    ("chart.js", JS, include_str!("../../../static/chart.js")),
    (
        "overview.js",
        JS,
        include_str!("../../../static/overview.js"),
    ),
    ("session.js", JS, include_str!("../../../static/session.js")),
    (
        "controls.js",
        JS,
        include_str!("../../../static/controls.js"),
    ),
    ("alarms.js", JS, include_str!("../../../static/alarms.js")),
    ("gnss.js", JS, include_str!("../../../static/gnss.js")),
    (
        "gnss-charts.js",
        JS,
        include_str!("../../../static/gnss-charts.js"),
    ),
    ("models.js", JS, include_str!("../../../static/models.js")),
    ("audit.js", JS, include_str!("../../../static/audit.js")),
];

const JS: &str = "text/javascript; charset=utf-8";

/// `GET /static/{file}`: one of the dashboard's embedded files.
pub async fn asset(Path(file): Path<String>) -> Result<impl IntoResponse, ApiError> {
    ASSETS
        .iter()
        .find(|(name, _, _)| *name == file)
        .map(|&(_, content_type, body)| {
            (
                [
                    (header::CONTENT_TYPE, content_type),
                    // Embedded in the binary: a new build is a new server, so revalidate.
                    (header::CACHE_CONTROL, "no-cache"),
                ],
                body,
            )
        })
        .ok_or_else(|| ApiError::NotFound(format!("no static file '{file}'")))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Names the page or a module loads: `static/NAME` in the HTML, `from "./NAME"` in JS.
    fn references(text: &str, marker: &str, end: char) -> Vec<String> {
        text.split(marker)
            .skip(1)
            .filter_map(|rest| rest.split(end).next())
            .map(str::to_owned)
            .collect()
    }

    #[test]
    fn every_file_the_dashboard_loads_is_embedded() {
        let html = include_str!("../../../static/index.html");
        let mut wanted = references(html, "\"static/", '"');
        for (_, _, body) in ASSETS {
            wanted.extend(references(body, "from \"./", '"'));
        }
        assert!(wanted.len() > ASSETS.len(), "{wanted:?}");
        for name in wanted {
            assert!(
                ASSETS.iter().any(|(n, _, _)| *n == name),
                "{name} is loaded but not in ASSETS"
            );
        }
    }
}
