//! `/api/v1/sessions`: create, list, get, delete, and statistics.

use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::{Extension, Json};
use serde::Serialize;
use serde_json::{Value, json};

use crate::service::api::thresholds::check_policy_keys;
use crate::service::app::AppState;
use crate::service::audit::Change;
use crate::service::error::ApiError;
use crate::service::extract::{JsonBody, from_value, integral_numbers, refuse_nulls};
use crate::service::now_ms;
use crate::service::session::lifecycle;
use crate::service::session::{SessionHandle, validate_session};
use crate::service::store::StoredSession;
use crate::service::tokens::Principal;
use crate::service::wire::{CreateSession, MonitorSpecWire};
use navguard_core::detect::{Health, ThresholdSpec};
use navguard_core::session::SessionStats;

/// A test's effective threshold and current state, in a session view.
#[derive(Debug, Serialize)]
pub struct TestView {
    dof: u32,
    threshold: f64,
    state: Health,
}

/// A monitor in a session view: its spec plus its tests.
#[derive(Debug, Serialize)]
pub struct MonitorView {
    #[serde(flatten)]
    spec: MonitorSpecWire,
    tests: std::collections::BTreeMap<navguard_core::monitor::TestName, TestView>,
}

/// A session as the API shows it.
#[derive(Debug, Serialize)]
pub struct SessionView {
    id: String,
    echo: bool,
    created_at_ms: i64,
    connected: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    alarm_level: Option<crate::service::wire::AlarmLevel>,
    record: bool,
    monitors: Vec<MonitorView>,
    /// The node running it (cluster nodes only).
    #[serde(skip_serializing_if = "Option::is_none")]
    node: Option<String>,
}

/// The view of a session another node runs (or nobody does yet): its spec, without the
/// live test states, which only its owner has (`GET …/{id}` is forwarded there).
fn view_stored(stored: StoredSession, record_default: bool, node: Option<String>) -> SessionView {
    SessionView {
        id: stored.id,
        echo: stored.echo,
        created_at_ms: stored.created_at_ms,
        connected: false,
        alarm_level: stored.alarm_level,
        record: stored.record.unwrap_or(record_default),
        monitors: stored
            .monitors
            .into_iter()
            .map(|spec| MonitorView {
                spec,
                tests: Default::default(),
            })
            .collect(),
        node,
    }
}

fn view(handle: &SessionHandle, record_default: bool) -> SessionView {
    let stored = handle.stored();
    let stats = handle.stats_watch().borrow().clone();
    let monitors = stored
        .monitors
        .into_iter()
        .map(|spec| {
            let tests = stats
                .monitors
                .get(&spec.name)
                .map(|m| {
                    m.tests
                        .iter()
                        .map(|(name, t)| {
                            (
                                name.clone(),
                                TestView {
                                    dof: t.dof,
                                    threshold: t.threshold,
                                    state: t.state,
                                },
                            )
                        })
                        .collect()
                })
                .unwrap_or_default();
            MonitorView { spec, tests }
        })
        .collect();
    SessionView {
        id: stored.id,
        echo: stored.echo,
        created_at_ms: stored.created_at_ms,
        connected: stats.connected,
        alarm_level: stored.alarm_level,
        record: stored.record.unwrap_or(record_default),
        monitors,
        node: None,
    }
}

/// A fresh id: time and a process-wide counter, base 36.
fn new_id() -> String {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let mut v = (now_ms() as u64) << 16 | (n & 0xffff);
    let mut s = Vec::new();
    while v > 0 {
        s.push(b"0123456789abcdefghijklmnopqrstuvwxyz"[(v % 36) as usize]);
        v /= 36;
    }
    s.reverse();
    format!("s-{}", String::from_utf8_lossy(&s))
}

/// The create body: `null` refused and integral floats read as integers
/// (`n1: 10.0`) as for every session body, except inside each monitor's
/// `config`, which is stored exactly as sent (docs/architecture.md §A4) and
/// read the same way when the monitor is built (`session::spec`).
fn parse_create(mut body: Value) -> Result<CreateSession, ApiError> {
    refuse_nulls(&body)?;
    if let Some(monitors) = body.get("monitors").and_then(Value::as_array) {
        for (i, monitor) in monitors.iter().enumerate() {
            check_policy_keys(monitor.get("policy"), &format!("monitors[{i}].policy"))?;
        }
    }
    let mut configs = Vec::new();
    if let Some(monitors) = body.get_mut("monitors").and_then(Value::as_array_mut) {
        for monitor in monitors.iter_mut().filter_map(Value::as_object_mut) {
            configs.push(monitor.remove("config"));
        }
    }
    integral_numbers(&mut body);
    if let Some(monitors) = body.get_mut("monitors").and_then(Value::as_array_mut) {
        let objects = monitors.iter_mut().filter_map(Value::as_object_mut);
        for (monitor, config) in objects.zip(configs) {
            if let Some(config) = config {
                monitor.insert("config".into(), config);
            }
        }
    }
    from_value(body)
}

/// `POST /api/v1/sessions` → 201 with the session view.
pub async fn create(
    State(state): State<AppState>,
    JsonBody(body): JsonBody,
) -> Result<(StatusCode, Extension<Change>, Json<SessionView>), ApiError> {
    let req = parse_create(body)?;
    validate_session(&req, &state.config.limits)?;
    let mut monitors = req.monitors;
    // State the default threshold explicitly so every view shows what is in force.
    for m in &mut monitors {
        if m.p_fa.is_none() && m.threshold.is_none() {
            m.p_fa = ThresholdSpec::default().p_fa_part();
        }
    }
    let stored = StoredSession {
        id: req.id.clone().unwrap_or_else(new_id),
        echo: req.echo,
        monitors,
        created_at_ms: now_ms(),
        record: req.record,
        alarm_level: req.alarm_level,
    };
    let limit = state.config.limits.max_sessions;
    let change = Change {
        session: Some(stored.id.clone()),
        previous: Value::Null,
        new: json!(stored),
    };
    let handle = lifecycle::create(state.actor_deps(), &state.registry, limit, stored).await?;
    Ok((
        StatusCode::CREATED,
        Extension(change),
        Json(view(&handle, state.config.record_default)),
    ))
}

/// The list answer.
#[derive(Debug, Serialize)]
pub struct SessionList {
    sessions: Vec<SessionView>,
}

/// `GET /api/v1/sessions`: on a cluster node, every stored session (those another node
/// runs with their spec and owner, without live test states). A token limited to some
/// sessions sees only those.
pub async fn list(
    State(state): State<AppState>,
    principal: Option<Extension<Principal>>,
) -> Result<Json<SessionList>, ApiError> {
    let visible = |id: &str| principal.as_ref().is_none_or(|p| p.allows_session(id));
    let record_default = state.config.record_default;
    let Some(cluster) = &state.cluster else {
        return Ok(Json(SessionList {
            sessions: state
                .registry
                .list()
                .iter()
                .filter(|h| visible(h.id()))
                .map(|h| view(h, record_default))
                .collect(),
        }));
    };
    let mut sessions = Vec::new();
    for stored in state.store.sessions().await? {
        if !visible(&stored.id) {
            continue;
        }
        match state.registry.get(&stored.id) {
            Some(h) => {
                let mut v = view(&h, record_default);
                v.node = Some(cluster.node_id().to_owned());
                sessions.push(v);
            }
            None => {
                let now = now_ms();
                let node = state
                    .store
                    .lease(&stored.id)
                    .await?
                    .filter(|l| l.live(now))
                    .map(|l| l.owner);
                sessions.push(view_stored(stored, record_default, node));
            }
        }
    }
    sessions.sort_by(|a, b| a.id.cmp(&b.id));
    Ok(Json(SessionList { sessions }))
}

fn lookup(state: &AppState, id: &str) -> Result<SessionHandle, ApiError> {
    state
        .registry
        .get(id)
        .ok_or_else(|| ApiError::NotFound(format!("no session '{id}'")))
}

/// `GET /api/v1/sessions/{id}`
pub async fn get(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<SessionView>, ApiError> {
    Ok(Json(view(
        &lookup(&state, &id)?,
        state.config.record_default,
    )))
}

/// `DELETE /api/v1/sessions/{id}` → 204. The session's alarms stay in the log.
pub async fn delete(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<(StatusCode, Extension<Change>), ApiError> {
    let handle = lookup(&state, &id)?;
    let change = Change {
        session: Some(id.clone()),
        previous: json!(handle.stored()),
        new: Value::Null,
    };
    // The actor deletes the row after every change it acknowledged before, then stops:
    // a 204 is final (docs/architecture.md §A4).
    handle.delete().await?;
    state.registry.remove(&id);
    Ok((StatusCode::NO_CONTENT, Extension(change)))
}

/// `GET /api/v1/sessions/{id}/stats`
pub async fn stats(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<SessionStats>, ApiError> {
    Ok(Json(lookup(&state, &id)?.stats().await?))
}
