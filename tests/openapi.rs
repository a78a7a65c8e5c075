//! Keeps the OpenAPI contract (`openapi/openapi.yaml`) in step with the router:
//! the spec names exactly the routes of `ROUTES`, the router answers exactly
//! those, every `$ref` resolves, and real REST answers and socket messages
//! validate against the schemas the spec gives them.

mod common;

use std::collections::BTreeSet;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::body::Body;
use axum::http::{Request, header};
use futures_util::{SinkExt, StreamExt};
use navguard::service::ServiceConfig;
use navguard::service::app::{AppState, ROUTES, app};
use navguard::service::metrics::Metrics;
use navguard::service::session::Registry;
use navguard::service::store::Store;
use navguard::service::train::Models;

use common::concrete;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::{self, Message};
use tower::ServiceExt;

const SPEC: &str = include_str!("../openapi/openapi.yaml");

/// The methods checked against every path (HEAD and OPTIONS are axum's business).
const METHODS: [&str; 5] = ["GET", "POST", "PUT", "DELETE", "PATCH"];
const SPEC_METHODS: [&str; 8] = [
    "get", "put", "post", "delete", "options", "head", "patch", "trace",
];

fn spec() -> Value {
    serde_yaml_ng::from_str(SPEC)
        .expect("openapi.yaml parses, with string keys only (quote status codes)")
}

async fn state(dir: &Path, token: Option<&str>) -> AppState {
    state_with(dir, token, None).await
}

async fn state_with(dir: &Path, token: Option<&str>, tokens_file: Option<&Path>) -> AppState {
    let mut config = ServiceConfig::new("127.0.0.1:0".parse().unwrap(), dir.join("t.db"));
    config.token = token.map(str::to_owned);
    let store = Store::open(&config.db_path).await.unwrap();
    AppState {
        models: Arc::new(Models::new(store.clone(), &config.limits)),
        store,
        registry: Arc::new(Registry::default()),
        metrics: Arc::new(Metrics::default()),
        tokens: Arc::new(navguard::service::tokens::Tokens::new(token, tokens_file).unwrap()),
        config: Arc::new(config),
        shutdown: tokio::sync::watch::channel(false).1,
        compute: navguard::service::compute::ComputePool::new(2),
        cluster: None,
    }
}

struct Answer {
    status: u16,
    content_type: String,
    www_authenticate: Option<String>,
    body: Vec<u8>,
}

impl Answer {
    fn json(&self) -> Option<Value> {
        serde_json::from_slice(&self.body).ok()
    }

    /// `(code, message)` of a JSON error body.
    fn error(&self) -> Option<(String, String)> {
        let v = self.json()?;
        Some((
            v["error"]["code"].as_str()?.to_owned(),
            v["error"]["message"].as_str()?.to_owned(),
        ))
    }

    fn is_router_fallback(&self) -> bool {
        self.status == 404 && self.error() == Some(("not_found".into(), "no such route".into()))
    }
}

async fn send(
    router: &Router,
    method: &str,
    uri: &str,
    headers: &[(&str, &str)],
    body: Option<String>,
) -> Answer {
    let mut request = Request::builder().method(method).uri(uri);
    for (name, value) in headers {
        request = request.header(*name, *value);
    }
    let request = request
        .body(body.map_or_else(Body::empty, Body::from))
        .unwrap();
    let response = router.clone().oneshot(request).await.unwrap();
    let text = |name| {
        response
            .headers()
            .get(name)
            .and_then(|v| v.to_str().ok())
            .map(str::to_owned)
    };
    let content_type = text(header::CONTENT_TYPE).unwrap_or_default();
    let www_authenticate = text(header::WWW_AUTHENTICATE);
    let status = response.status().as_u16();
    let body = axum::body::to_bytes(response.into_body(), usize::MAX)
        .await
        .unwrap()
        .to_vec();
    Answer {
        status,
        content_type,
        www_authenticate,
        body,
    }
}

fn spec_routes(doc: &Value) -> BTreeSet<(String, String)> {
    let paths = doc["paths"].as_object().expect("spec has paths");
    paths
        .iter()
        .flat_map(|(path, item)| {
            SPEC_METHODS
                .iter()
                .filter(|m| item.get(**m).is_some())
                .map(move |m| (path.clone(), m.to_uppercase()))
        })
        .collect()
}

fn table_routes() -> BTreeSet<(String, String)> {
    ROUTES
        .iter()
        .flat_map(|(path, methods)| {
            methods
                .iter()
                .map(move |m| (path.to_string(), m.to_string()))
        })
        .collect()
}

fn operation<'a>(doc: &'a Value, template: &str, method: &str) -> &'a Value {
    let op = &doc["paths"][template][method.to_lowercase()];
    assert!(op.is_object(), "spec has no {method} {template}");
    op
}

// ------------------------------------------------------------ JSON Schema validation

/// Validates values against the spec's schemas with the `jsonschema` crate.
/// OpenAPI 3.1 schemas are JSON Schema 2020-12 (no `nullable`: the spec writes
/// `type: [string, 'null']`), so the only conversion is the references: a schema
/// taken out of the document is compiled as `allOf: [schema]` beside `$defs`
/// holding every `components/schemas` entry, with `#/components/schemas/X`
/// rewritten to `#/$defs/X`. Every keyword of the dialect is enforced, `pattern`
/// included; `format` stays an annotation, as 2020-12 has it.
struct Checker<'a> {
    doc: &'a Value,
    /// `components/schemas` with their references rewritten.
    defs: Value,
}

/// Rewrites `#/components/schemas/…` references to `#/$defs/…`, in place.
fn rebase_refs(v: &mut Value) {
    match v {
        Value::Object(map) => {
            for (key, child) in map.iter_mut() {
                if let (true, Value::String(r)) = (key == "$ref", &*child)
                    && let Some(name) = r.strip_prefix("#/components/schemas/")
                {
                    *child = Value::String(format!("#/$defs/{name}"));
                } else {
                    rebase_refs(child);
                }
            }
        }
        Value::Array(items) => items.iter_mut().for_each(rebase_refs),
        _ => {}
    }
}

impl<'a> Checker<'a> {
    fn new(doc: &'a Value) -> Self {
        let mut defs = doc["components"]["schemas"].clone();
        assert!(defs.is_object(), "spec has components/schemas");
        rebase_refs(&mut defs);
        Checker { doc, defs }
    }

    fn pointer(&self, reference: &str) -> &'a Value {
        reference
            .strip_prefix('#')
            .and_then(|p| self.doc.pointer(p))
            .unwrap_or_else(|| panic!("unresolved $ref {reference}"))
    }

    fn schema(&self, name: &str) -> &'a Value {
        self.pointer(&format!("#/components/schemas/{name}"))
    }

    /// `schema` (a node of the spec) compiled with the spec's definitions.
    fn validator(&self, schema: &Value) -> jsonschema::Validator {
        let mut schema = schema.clone();
        rebase_refs(&mut schema);
        let root = json!({
            "$schema": "https://json-schema.org/draft/2020-12/schema",
            "$defs": self.defs,
            "allOf": [schema],
        });
        jsonschema::options()
            .with_draft(jsonschema::Draft::Draft202012)
            .build(&root)
            .unwrap_or_else(|e| panic!("the spec's schema does not compile: {e}\n{schema}"))
    }

    fn check(&self, schema: &Value, value: &Value) -> Vec<String> {
        self.validator(schema)
            .iter_errors(value)
            .map(|e| format!("${}: {e}", e.instance_path()))
            .collect()
    }

    fn matches(&self, schema: &Value, value: &Value) -> bool {
        self.validator(schema).is_valid(value)
    }

    fn assert_valid(&self, schema: &Value, value: &Value, what: &str) {
        let errors = self.check(schema, value);
        assert!(
            errors.is_empty(),
            "{what} does not match its schema:\n  {}\nvalue: {value}",
            errors.join("\n  ")
        );
    }
}

// ------------------------------------------------------------ REST against the spec

/// A router plus the spec: every call asserts that its status is declared for
/// the operation and that its body matches the declared schema.
struct Contract {
    router: Router,
    doc: Value,
}

impl Contract {
    async fn call(&self, method: &str, template: &str, uri: &str, body: Option<&Value>) -> Value {
        let headers: &[(&str, &str)] = if body.is_some() {
            &[("content-type", "application/json")]
        } else {
            &[]
        };
        let answer = send(
            &self.router,
            method,
            uri,
            headers,
            body.map(Value::to_string),
        )
        .await;
        self.verify(method, template, uri, &answer)
    }

    fn verify(&self, method: &str, template: &str, uri: &str, answer: &Answer) -> Value {
        let checker = Checker::new(&self.doc);
        let op = operation(&self.doc, template, method);
        let status = answer.status.to_string();
        let declared = op["responses"].get(&status).unwrap_or_else(|| {
            panic!(
                "{method} {uri} answered {status}, not declared for {method} {template}: {}",
                answer_text(answer)
            )
        });
        let response = match declared.get("$ref").and_then(Value::as_str) {
            Some(r) => checker.pointer(r),
            None => declared,
        };
        let Some(content) = response.get("content").and_then(Value::as_object) else {
            assert!(
                answer.body.is_empty(),
                "{method} {uri} {status}: the spec declares no body"
            );
            return Value::Null;
        };
        let media = answer
            .content_type
            .split(';')
            .next()
            .unwrap_or_default()
            .trim();
        let declared_media = content.get(media).unwrap_or_else(|| {
            panic!(
                "{method} {uri} {status}: content type {media:?} not among {:?}",
                content.keys().collect::<Vec<_>>()
            )
        });
        if media != "application/json" {
            return Value::Null;
        }
        let value = answer.json().expect("a JSON body");
        checker.assert_valid(
            &declared_media["schema"],
            &value,
            &format!("{method} {uri} {status}"),
        );
        value
    }
}

fn answer_text(answer: &Answer) -> String {
    String::from_utf8_lossy(&answer.body).into_owned()
}

fn linear_config() -> Value {
    json!({
        "f": [[1.0, 1.0], [0.0, 1.0]],
        "h": [[1.0, 0.0]],
        "q": [[0.25, 0.5], [0.5, 1.0]],
        "r": [[1.0]],
        "x0": [0.0, 0.0],
        "p0": [[10.0, 0.0], [0.0, 10.0]]
    })
}

fn session_body(id: &str, echo: bool) -> Value {
    let monitor = json!({"name": "cv", "type": "linear", "config": linear_config()});
    json!({"id": id, "echo": echo, "monitors": [monitor]})
}

// ------------------------------------------------------------ the tests

#[test]
fn spec_declares_openapi_3_1() {
    let doc = spec();
    let version = doc["openapi"].as_str().expect("`openapi` is a string");
    assert!(version.starts_with("3.1."), "openapi: {version}");
    assert!(doc["info"]["title"].is_string() && doc["info"]["version"].is_string());
}

#[test]
fn spec_lists_exactly_the_routes_in_the_table() {
    let (spec, table) = (spec_routes(&spec()), table_routes());
    let missing: Vec<_> = table.difference(&spec).collect();
    let extra: Vec<_> = spec.difference(&table).collect();
    assert!(
        missing.is_empty(),
        "routes in ROUTES missing from openapi.yaml: {missing:?}"
    );
    assert!(
        extra.is_empty(),
        "routes in openapi.yaml the router lacks: {extra:?}"
    );
}

#[test]
fn every_ref_in_the_spec_resolves() {
    fn walk(doc: &Value, v: &Value, at: &str, bad: &mut Vec<String>) {
        match v {
            Value::Object(map) => {
                for (k, child) in map {
                    let here = format!("{at}/{k}");
                    let is_mapping = at.ends_with("/mapping");
                    if let (true, Value::String(r)) = (k == "$ref" || is_mapping, child)
                        && r.strip_prefix('#').and_then(|p| doc.pointer(p)).is_none()
                    {
                        bad.push(format!("{here}: {r}"));
                    }
                    walk(doc, child, &here, bad);
                }
            }
            Value::Array(items) => {
                for (i, child) in items.iter().enumerate() {
                    walk(doc, child, &format!("{at}/{i}"), bad);
                }
            }
            _ => {}
        }
    }
    let doc = spec();
    let mut bad = Vec::new();
    walk(&doc, &doc, "#", &mut bad);
    assert!(bad.is_empty(), "unresolved references:\n{}", bad.join("\n"));
}

#[test]
fn every_path_parameter_is_declared_and_required() {
    let doc = spec();
    let checker = Checker::new(&doc);
    for (path, item) in doc["paths"].as_object().unwrap() {
        let names: BTreeSet<&str> = path
            .split('{')
            .skip(1)
            .filter_map(|s| s.split('}').next())
            .collect();
        for method in SPEC_METHODS.iter().filter(|m| item.get(**m).is_some()) {
            let declared: Vec<&Value> = [&item["parameters"], &item[*method]["parameters"]]
                .into_iter()
                .filter_map(Value::as_array)
                .flatten()
                .map(|p| {
                    p.get("$ref")
                        .and_then(Value::as_str)
                        .map_or(p, |r| checker.pointer(r))
                })
                .filter(|p| p["in"] == "path")
                .collect();
            let got: BTreeSet<&str> = declared.iter().filter_map(|p| p["name"].as_str()).collect();
            assert_eq!(got, names, "{method} {path}: path parameters");
            assert!(
                declared.iter().all(|p| p["required"] == true),
                "{method} {path}: path parameters must be required"
            );
        }
    }
}

#[tokio::test]
async fn an_unknown_path_gets_the_router_fallback() {
    let dir = tempfile::tempdir().unwrap();
    let router = app(state(dir.path(), None).await);
    let answer = send(&router, "GET", "/api/v1/nothing-here", &[], None).await;
    assert!(
        answer.is_router_fallback(),
        "{} {}",
        answer.status,
        answer_text(&answer)
    );
}

#[tokio::test]
async fn router_answers_every_route_in_the_table() {
    let dir = tempfile::tempdir().unwrap();
    let router = app(state(dir.path(), None).await);
    let contract = Contract {
        router: router.clone(),
        doc: spec(),
    };
    for (path, methods) in ROUTES {
        for method in *methods {
            let uri = concrete(path, "x");
            let answer = send(&router, method, &uri, &[], None).await;
            assert_ne!(
                answer.status,
                405,
                "{method} {uri}: {}",
                answer_text(&answer)
            );
            assert!(
                !answer.is_router_fallback(),
                "{method} {uri} fell through to the router's fallback"
            );
            // Whatever a bare request gets (a socket route: 400, not an upgrade) is declared too.
            contract.verify(method, path, &uri, &answer);
        }
    }
}

#[tokio::test]
async fn router_refuses_every_method_the_table_does_not_list() {
    let dir = tempfile::tempdir().unwrap();
    let router = app(state(dir.path(), None).await);
    for (path, methods) in ROUTES {
        for method in METHODS.iter().filter(|m| !methods.contains(m)) {
            let uri = concrete(path, "x");
            let answer = send(&router, method, &uri, &[], None).await;
            assert_eq!(
                answer.status,
                405,
                "{method} {uri}: {}",
                answer_text(&answer)
            );
            assert_eq!(
                answer.error().map(|e| e.0).as_deref(),
                Some("method_not_allowed"),
                "{method} {uri}"
            );
        }
    }
}

#[tokio::test]
async fn token_guards_exactly_the_operations_the_spec_secures() {
    let doc = spec();
    let dir = tempfile::tempdir().unwrap();
    let router = app(state(dir.path(), Some("s3cret")).await);
    let contract = Contract {
        router: router.clone(),
        doc: doc.clone(),
    };
    for (path, methods) in ROUTES {
        for method in *methods {
            let op = operation(&doc, path, method);
            let public = op
                .get("security")
                .and_then(Value::as_array)
                .is_some_and(Vec::is_empty);
            let uri = concrete(path, "x");
            let anonymous = send(&router, method, &uri, &[], None).await;
            if public {
                assert_ne!(
                    anonymous.status, 401,
                    "{method} {path} is public in the spec"
                );
                continue;
            }
            assert_eq!(
                anonymous.status, 401,
                "{method} {path} is secured in the spec"
            );
            assert_eq!(anonymous.www_authenticate.as_deref(), Some("Bearer"));
            contract.verify(method, path, &uri, &anonymous);
            let bearer = send(
                &router,
                method,
                &uri,
                &[("authorization", "Bearer s3cret")],
                None,
            )
            .await;
            assert_ne!(bearer.status, 401, "{method} {path} with the token");
        }
    }
}

#[tokio::test]
async fn forbidden_answers_and_whoami_match_their_schemas() {
    use navguard::service::tokens::{hash_secret, to_hex};
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("tokens.json");
    let scopes = ["ingest", "read", "operate"];
    let tokens: Vec<Value> = scopes
        .iter()
        .map(|s| json!({"name": s, "hash": to_hex(&hash_secret(s)), "scopes": [s]}))
        .collect();
    std::fs::write(&file, json!({ "tokens": tokens }).to_string()).unwrap();
    let router = app(state_with(dir.path(), None, Some(&file)).await);
    let contract = Contract {
        router: router.clone(),
        doc: spec(),
    };
    let mut refused = 0;
    for (path, methods) in ROUTES {
        for method in *methods {
            let uri = concrete(path, "x");
            for secret in scopes {
                let bearer = format!("Bearer {secret}");
                let answer = send(&router, method, &uri, &[("authorization", &bearer)], None).await;
                if answer.status == 403 {
                    refused += 1;
                    contract.verify(method, path, &uri, &answer);
                }
            }
        }
    }
    assert!(refused > 20, "{refused} refusals");
    let answer = send(
        &router,
        "GET",
        "/api/v1/whoami",
        &[("authorization", "Bearer read")],
        None,
    )
    .await;
    let me = contract.verify("GET", "/api/v1/whoami", "/api/v1/whoami", &answer);
    assert_eq!(me["scopes"], json!(["read"]));
}

// Over 80 lines: a table of cases checked one after another.
#[tokio::test]
async fn rest_answers_match_their_schemas() {
    let dir = tempfile::tempdir().unwrap();
    let app_state = state(dir.path(), None).await;
    let store = app_state.store.clone();
    let c = Contract {
        router: app(app_state),
        doc: spec(),
    };
    let sessions = "/api/v1/sessions";
    let session = "/api/v1/sessions/{id}";
    let threshold = "/api/v1/sessions/{id}/monitors/{name}/threshold";

    c.call("GET", "/", "/", None).await;
    c.call("GET", "/metrics", "/metrics", None).await;
    c.call("GET", "/healthz", "/healthz", None).await;
    let me = c
        .call("GET", "/api/v1/whoami", "/api/v1/whoami", None)
        .await;
    assert_eq!(me["name"], "anonymous");

    let created = c
        .call("POST", sessions, sessions, Some(&session_body("s1", false)))
        .await;
    assert_eq!(created["id"], "s1");
    let conflict = c
        .call("POST", sessions, sessions, Some(&session_body("s1", false)))
        .await;
    assert_eq!(conflict["error"]["code"], "conflict");
    let mut bad = session_body("s2", false);
    bad["monitors"][0]["config"]["r"] = json!([[0.0]]);
    let invalid = c.call("POST", sessions, sessions, Some(&bad)).await;
    assert_eq!(invalid["error"]["field"], "monitors[0].config.r");
    bad = session_body("s2", false);
    bad["monitors"][0]["type"] = json!("tacan");
    bad["monitors"][0]["config"] = json!({
        "station": {"lat": 34.0, "lon": 108.0, "h": 0.0},
        "model": "m-0123456789abcdef"
    });
    let no_model = c.call("POST", sessions, sessions, Some(&bad)).await;
    assert_eq!(no_model["error"]["field"], "monitors[0].config.model");
    let no_type = send(
        &c.router,
        "POST",
        sessions,
        &[],
        Some(session_body("s2", false).to_string()),
    )
    .await;
    assert_eq!(
        c.verify("POST", sessions, sessions, &no_type)["error"]["code"],
        "unsupported_media_type"
    );
    let syntax = send(
        &c.router,
        "POST",
        sessions,
        &[("content-type", "application/json")],
        Some("{".into()),
    )
    .await;
    assert_eq!(
        c.verify("POST", sessions, sessions, &syntax)["error"]["code"],
        "bad_request"
    );

    c.call("GET", sessions, sessions, None).await;
    c.call("GET", session, "/api/v1/sessions/s1", None).await;
    c.call("GET", session, "/api/v1/sessions/nope", None).await;
    c.call(
        "GET",
        "/api/v1/sessions/{id}/stats",
        "/api/v1/sessions/s1/stats",
        None,
    )
    .await;

    let uri = "/api/v1/sessions/s1/monitors/cv/threshold";
    let view = c.call("GET", threshold, uri, None).await;
    assert!(
        view["threshold"].is_null() && view["p_fa"] == 0.002,
        "{view}"
    );
    c.call(
        "GET",
        threshold,
        "/api/v1/sessions/s1/monitors/nope/threshold",
        None,
    )
    .await;
    let view = c
        .call(
            "PUT",
            threshold,
            uri,
            Some(&json!({"threshold": 20.0, "policy": {"kind": "counters"}})),
        )
        .await;
    assert_eq!(
        view["policy"],
        json!({"kind": "counters", "n1": 10, "n2": 5})
    );
    c.call("PUT", threshold, uri, Some(&json!({}))).await;
    c.call(
        "PUT",
        threshold,
        uri,
        Some(&json!({"p_fa": 0.01, "threshold": 3.0})),
    )
    .await;
    let stored = c.call("GET", session, "/api/v1/sessions/s1", None).await;
    assert_eq!(stored["monitors"][0]["threshold"], 20.0);

    let chi2 = "/api/v1/chi2/threshold";
    c.call("GET", chi2, "/api/v1/chi2/threshold?dof=1&p_fa=0.002", None)
        .await;
    c.call("GET", chi2, "/api/v1/chi2/threshold?dof=0&p_fa=0.002", None)
        .await;
    c.call("GET", chi2, "/api/v1/chi2/threshold?p_fa=0.002", None)
        .await;
    let md = "/api/v1/chi2/missed-detection";
    c.call(
        "GET",
        md,
        "/api/v1/chi2/missed-detection?dof=2&p_fa=0.01&noncentrality=10",
        None,
    )
    .await;
    c.call(
        "GET",
        md,
        "/api/v1/chi2/missed-detection?dof=2&threshold=13&p_md=0.1",
        None,
    )
    .await;
    c.call(
        "GET",
        md,
        "/api/v1/chi2/missed-detection?dof=2&noncentrality=10",
        None,
    )
    .await;

    c.call(
        "GET",
        "/api/v1/alarms",
        "/api/v1/alarms?session=s1&limit=10",
        None,
    )
    .await;
    c.call("GET", "/api/v1/alarms", "/api/v1/alarms?limit=0", None)
        .await;
    c.call("GET", "/api/v1/alarms", "/api/v1/alarms?since=soon", None)
        .await;

    // An acknowledgement, the log entry with it, the refusals; the audit log.
    let alarm = navguard::service::wire::AlarmRecord {
        id: 0,
        severity: navguard::service::wire::Severity::Alarm,
        session: "s1".into(),
        monitor: "cv".into(),
        test: "residual".into(),
        state: navguard_core::detect::Health::Isolated,
        t: 3.0,
        statistic: 30.0,
        threshold: 20.0,
        dof: 1,
        test_ratio: 1.5,
        delay_s: 0.0,
        raised_at_ms: 5,
        cleared_t: None,
    };
    let id = store
        .insert_alarm(alarm, navguard::service::store::AlarmKey::default(), None)
        .await
        .unwrap()
        .id;
    let ack = "/api/v1/sessions/{id}/alarms/{alarm_id}/ack";
    let uri = format!("/api/v1/sessions/s1/alarms/{id}/ack");
    let comment = json!({"comment": "checked"});
    let acked = c.call("POST", ack, &uri, Some(&comment)).await;
    assert_eq!(acked["acked_by"], "anonymous");
    let again = c.call("POST", ack, &uri, Some(&comment)).await;
    assert_eq!(again["error"]["code"], "conflict");
    let blank = c
        .call("POST", ack, &uri, Some(&json!({"comment": ""})))
        .await;
    assert_eq!(blank["error"]["field"], "comment");
    let unknown = "/api/v1/sessions/s1/alarms/99999/ack";
    c.call("POST", ack, unknown, Some(&comment)).await;
    let log = c
        .call("GET", "/api/v1/alarms", "/api/v1/alarms?session=s1", None)
        .await;
    assert_eq!(log["alarms"][0]["ack_comment"], "checked");
    let audit = c
        .call("GET", "/api/v1/audit", "/api/v1/audit?session=s1", None)
        .await;
    assert_eq!(audit["entries"].as_array().unwrap().len(), 3, "{audit}");
    c.call("GET", "/api/v1/audit", "/api/v1/audit?limit=0", None)
        .await;
    c.call("GET", "/api/v1/audit", "/api/v1/audit?before=x", None)
        .await;

    c.call("DELETE", session, "/api/v1/sessions/s1", None).await;
    c.call("DELETE", session, "/api/v1/sessions/s1", None).await;
}

#[tokio::test]
async fn spec_examples_are_accepted_by_the_server() {
    let doc = spec();
    let checker = Checker::new(&doc);
    let dir = tempfile::tempdir().unwrap();
    let c = Contract {
        router: app(state(dir.path(), None).await),
        doc: doc.clone(),
    };

    let create =
        &operation(&doc, "/api/v1/sessions", "POST")["requestBody"]["content"]["application/json"];
    for (name, example) in create["examples"].as_object().unwrap() {
        checker.assert_valid(checker.schema("CreateSession"), &example["value"], name);
        let created = c
            .call(
                "POST",
                "/api/v1/sessions",
                "/api/v1/sessions",
                Some(&example["value"]),
            )
            .await;
        assert!(
            created["id"].is_string(),
            "example {name} was refused: {created}"
        );
    }
    let id = doc["paths"]["/api/v1/sessions"]["post"]["requestBody"]["content"]["application/json"]
        ["examples"]["constantVelocity"]["value"]["id"]
        .as_str()
        .unwrap();
    let template = "/api/v1/sessions/{id}/monitors/{name}/threshold";
    let put = &operation(&doc, template, "PUT")["requestBody"]["content"]["application/json"];
    for (name, example) in put["examples"].as_object().unwrap() {
        checker.assert_valid(checker.schema("ThresholdUpdate"), &example["value"], name);
        let uri = format!("/api/v1/sessions/{id}/monitors/cv/threshold");
        let view = c.call("PUT", template, &uri, Some(&example["value"])).await;
        assert_eq!(view["monitor"], "cv", "example {name} was refused: {view}");
    }
    for example in checker.schema("Epoch")["examples"].as_array().unwrap() {
        checker.assert_valid(checker.schema("IngestFrame"), example, "Epoch example");
        navguard::service::wire::parse_frame(&example.to_string(), 10)
            .expect("the Epoch example parses");
    }
}

// Over 80 lines: a table of cases checked one after another.
#[test]
fn schema_checker_rejects_what_the_spec_forbids() {
    let doc = spec();
    let c = Checker::new(&doc);
    let alarm = json!({
        "type": "alarm", "id": 1, "severity": "alarm", "session": "s", "monitor": "m",
        "test": "residual", "state": "isolated", "t": 1.0, "statistic": 30.0, "threshold": 9.5, "dof": 1,
        "test_ratio": 3.1, "delay_s": 0.0, "raised_at_ms": 1, "cleared_t": null
    });
    let mut alarm_plus = alarm.clone();
    alarm_plus["surprise"] = json!(1);
    let mut both = json!({"name": "m", "type": "linear", "config": linear_config()});
    both["p_fa"] = json!(0.1);
    both["threshold"] = json!(3.0);
    let bad_ins = json!({"lat": 0, "lon": 0, "h": 0, "vel": [1, 2], "att": [0, 0, 0]});
    let cases = [
        (
            "Error",
            json!({"error": {"code": "invalid", "message": "m", "field": "f"}}),
            true,
        ),
        (
            "Error",
            json!({"error": {"code": "nope", "message": "m"}}),
            false,
        ),
        ("Error", json!({"error": {"code": "invalid"}}), false),
        (
            "Error",
            json!({"error": {"code": "invalid", "message": "m", "extra": 1}}),
            false,
        ),
        (
            "MonitorSpec",
            json!({"name": "m", "type": "linear", "config": linear_config()}),
            true,
        ),
        (
            "MonitorSpec",
            json!({"name": "m", "type": "linear", "config": {"f": [[1.0]]}}),
            false,
        ),
        ("MonitorSpec", both, false),
        ("Policy", json!({"kind": "counters", "n1": 0}), false),
        ("Policy", json!({"kind": "counters"}), true),
        ("IngestFrame", json!([]), false),
        ("Epoch", json!({"t": 0, "ins": bad_ins}), false),
        ("AlarmMessage", alarm.clone(), true),
        ("AlarmMessage", alarm_plus, false),
        ("AlarmRecord", alarm.clone(), false),
        // Entries carry their severity.
        (
            "AlarmMessage",
            {
                let mut a = alarm.clone();
                a.as_object_mut().unwrap().remove("severity");
                a
            },
            false,
        ),
        (
            "TestThresholdSpec",
            json!({"p_fa": 0.01, "threshold": 3.0}),
            false,
        ),
        ("TestThresholdSpec", json!({}), false),
        ("TestThresholdSpec", json!({"threshold": 3.0}), true),
        // `pattern` is enforced (the hand-written checker this replaced ignored it).
        ("Name", json!("ok_id-1.2"), true),
        ("Name", json!("has space"), false),
        ("Name", json!("x".repeat(65)), false),
        ("CreateSession", session_body("s/1", false), false),
        ("CreateSession", session_body("s.1", false), true),
    ];
    for (name, value, valid) in cases {
        assert_eq!(
            c.matches(c.schema(name), &value),
            valid,
            "{name} on {value}"
        );
    }
}

async fn next_json<S>(socket: &mut S) -> Value
where
    S: futures_util::Stream<Item = Result<Message, tungstenite::Error>> + Unpin,
{
    loop {
        let message = tokio::time::timeout(Duration::from_secs(10), socket.next())
            .await
            .expect("a message within 10 s")
            .expect("the socket is open")
            .expect("a valid message");
        if let Message::Text(text) = message {
            return serde_json::from_str(&text).expect("server messages are JSON");
        }
    }
}

// Over 80 lines: a table of cases checked one after another.
#[tokio::test]
async fn socket_messages_match_their_schemas() {
    let doc = spec();
    let checker = Checker::new(&doc);
    let x_websocket = |path: &str, side: &str| &operation(&doc, path, "GET")["x-websocket"][side];
    let ingest_path = "/api/v1/sessions/{id}/ingest";
    let events_path = "/api/v1/sessions/{id}/events";
    let (ingest_schema, events_schema) = (
        x_websocket(ingest_path, "server"),
        x_websocket(events_path, "server"),
    );
    let client_schema = x_websocket(ingest_path, "client");
    assert!(ingest_schema.is_object() && events_schema.is_object() && client_schema.is_object());

    let dir = tempfile::tempdir().unwrap();
    let server = navguard::service::start(ServiceConfig::new(
        "127.0.0.1:0".parse().unwrap(),
        dir.path().join("t.db"),
    ))
    .await
    .unwrap();
    let addr = server.addr;
    let created = reqwest::Client::new()
        .post(format!("http://{addr}/api/v1/sessions"))
        .json(&session_body("ws", true))
        .send()
        .await
        .unwrap();
    assert_eq!(created.status(), 201);

    // Events first, and wait for its first `stats` so it is subscribed before any alarm.
    let (mut events, _) =
        tokio_tungstenite::connect_async(format!("ws://{addr}/api/v1/sessions/ws/events"))
            .await
            .unwrap();
    let first = next_json(&mut events).await;
    assert_eq!(first["type"], "stats");
    checker.assert_valid(events_schema, &first, "first events message");

    let (mut ingest, _) =
        tokio_tungstenite::connect_async(format!("ws://{addr}/api/v1/sessions/ws/ingest"))
            .await
            .unwrap();
    // (frame, whether it fits the client schema, messages it yields): an outlier
    // isolates, bad frames are refused, a quiet epoch heals.
    let script: [(Value, bool, usize); 5] = [
        (
            json!([{"t": 0.0, "z": [0.1]}, {"t": 1.0, "z": [100.0]}]),
            true,
            4,
        ),
        (json!({"t": 0.5, "z": [0.0]}), true, 1),
        (json!([{"t": 2.0}, {"t": 3.0, "lidar": 1}]), false, 1),
        (json!({"t": 2.0, "z": [1.0, 2.0]}), true, 1),
        (json!({"t": 2.0, "z": [0.0]}), true, 2),
    ];
    let mut seen = vec![next_json(&mut ingest).await];
    for (frame, fits, replies) in &script {
        assert_eq!(
            checker.matches(client_schema, frame),
            *fits,
            "client schema on {frame}"
        );
        ingest
            .send(Message::Text(frame.to_string().into()))
            .await
            .unwrap();
        for _ in 0..*replies {
            seen.push(next_json(&mut ingest).await);
        }
    }
    for message in &seen {
        checker.assert_valid(ingest_schema, message, "ingest message");
    }
    let types: Vec<&str> = seen.iter().filter_map(|m| m["type"].as_str()).collect();
    assert_eq!(
        types,
        [
            "ready", "result", "result", "state", "alarm", "error", "error", "error", "result",
            "state"
        ]
    );
    let codes: Vec<&str> = seen
        .iter()
        .filter(|m| m["type"] == "error")
        .filter_map(|m| m["code"].as_str())
        .collect();
    assert_eq!(codes, ["time_backwards", "unknown_input", "wrong_length"]);

    let mut observed = BTreeSet::new();
    while !(observed.contains("alarm") && observed.contains("state")) {
        let message = next_json(&mut events).await;
        checker.assert_valid(events_schema, &message, "events message");
        observed.insert(message["type"].as_str().unwrap_or_default().to_owned());
    }

    // Handshake refusals are declared too.
    let refusal = |uri: String| async move {
        match tokio_tungstenite::connect_async(uri).await {
            Err(tungstenite::Error::Http(response)) => response.status().as_u16().to_string(),
            other => panic!("expected an HTTP refusal, got {:?}", other.map(|_| ())),
        }
    };
    let second = refusal(format!("ws://{addr}/api/v1/sessions/ws/ingest")).await;
    assert_eq!(second, "409");
    assert!(
        operation(&doc, ingest_path, "GET")["responses"]
            .get(&second)
            .is_some()
    );
    let missing = refusal(format!("ws://{addr}/api/v1/sessions/nope/events")).await;
    assert_eq!(missing, "404");
    assert!(
        operation(&doc, events_path, "GET")["responses"]
            .get(&missing)
            .is_some()
    );

    let _ = ingest.close(None).await;
    let _ = events.close(None).await;
    server.shutdown().await;
}

// Over 80 lines: a table of cases checked one after another.
#[tokio::test]
async fn model_and_feature_answers_match_their_schemas() {
    let doc = spec();
    let dir = tempfile::tempdir().unwrap();
    let c = Contract {
        router: app(state(dir.path(), None).await),
        doc: doc.clone(),
    };
    let models = "/api/v1/models";
    let model = "/api/v1/models/{id}";
    let predict = "/api/v1/models/{id}/predict";

    // Every example of the spec is accepted (202) and becomes a record.
    let train = &operation(&doc, models, "POST")["requestBody"]["content"]["application/json"];
    let checker = Checker::new(&doc);
    let mut ids = Vec::new();
    for (name, example) in train["examples"].as_object().unwrap() {
        checker.assert_valid(checker.schema("TrainRequest"), &example["value"], name);
        let record = c
            .call("POST", models, models, Some(&example["value"]))
            .await;
        assert_eq!(record["status"], "training", "example {name}: {record}");
        ids.push(record["id"].as_str().unwrap().to_owned());
    }
    let bad = json!({"kind": "svr", "data": {"x": [[1.0]]}});
    let refused = c.call("POST", models, models, Some(&bad)).await;
    assert_eq!(refused["error"]["field"], "kind");
    let ragged = json!({"kind": "ocsvm", "data": {"x": [[1.0], [1.0, 2.0]]}});
    let refused = c.call("POST", models, models, Some(&ragged)).await;
    assert_eq!(refused["error"]["field"], "data.x[1]");

    let listed = c.call("GET", models, models, None).await;
    assert_eq!(listed["models"].as_array().unwrap().len(), ids.len());
    // A model id is held to its pattern.
    let mut forged = listed["models"][0].clone();
    assert!(checker.matches(checker.schema("ModelRecord"), &forged));
    forged["id"] = json!("m-NOT-HEX");
    assert!(!checker.matches(checker.schema("ModelRecord"), &forged));
    // Wait for each job to end (ready or failed, whatever the learners can do).
    for id in &ids {
        let uri = format!("{models}/{id}");
        let mut record = c.call("GET", model, &uri, None).await;
        for _ in 0..500 {
            if record["status"] != "training" {
                break;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
            record = c.call("GET", model, &uri, None).await;
        }
        assert_ne!(record["status"], "training", "{record}");
        let x = json!({"x": vec![vec![0.5; record["dim"].as_u64().unwrap() as usize]]});
        let answer = c
            .call("POST", predict, &format!("{uri}/predict"), Some(&x))
            .await;
        if record["status"] == "ready" {
            assert!(
                answer["y"].is_array() || answer["decision"].is_array(),
                "{answer}"
            );
            let wrong = json!({"x": [vec![0.5; 7]]});
            let refused = c
                .call("POST", predict, &format!("{uri}/predict"), Some(&wrong))
                .await;
            assert_eq!(refused["error"]["field"], "x");
        } else {
            assert_eq!(answer["error"]["code"], "conflict", "{answer}");
        }
    }
    let unknown = "/api/v1/models/m-0000000000000000";
    c.call("GET", model, unknown, None).await;
    c.call(
        "POST",
        predict,
        &format!("{unknown}/predict"),
        Some(&json!({"x": [[1.0]]})),
    )
    .await;
    c.call("DELETE", model, &format!("{models}/{}", ids[0]), None)
        .await;
    let gone = c
        .call("DELETE", model, &format!("{models}/{}", ids[0]), None)
        .await;
    assert_eq!(gone["error"]["code"], "not_found");

    let features = "/api/v1/features";
    let wavelet = json!({"kind": "wavelet-packet", "signal": [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0],
                         "wavelet": "db1", "level": 1, "normalize": false});
    checker.assert_valid(
        checker.schema("FeaturesRequest"),
        &wavelet,
        "wavelet request",
    );
    c.call("POST", features, features, Some(&wavelet)).await;
    let tacan = json!({"kind": "tacan-window", "ins_range_m": [1.0, 2.0, 3.0, 4.0],
                       "tacan_range_m": [1.0, 2.5, 3.0, 4.5], "window": 2, "crest": false});
    checker.assert_valid(checker.schema("FeaturesRequest"), &tacan, "tacan request");
    c.call("POST", features, features, Some(&tacan)).await;
    let unknown_kind = c
        .call("POST", features, features, Some(&json!({"kind": "fft"})))
        .await;
    assert_eq!(unknown_kind["error"]["field"], "kind");
}

#[test]
fn learned_monitor_outputs_match_the_result_schema() {
    use navguard_core::monitor::Outputs;
    let doc = spec();
    let c = Checker::new(&doc);
    let outputs = [
        Outputs::Channel {
            prediction: [("h".into(), vec![1.0])].into(),
            residual: [("h".into(), vec![0.5])].into(),
        },
        Outputs::Rimu {
            parity: Some(vec![0.1]),
            flagged: vec![2],
            isolated: vec![2],
            omega: Some([0.0, 0.1, 0.2]),
        },
        Outputs::Rimu {
            parity: None,
            flagged: vec![],
            isolated: vec![],
            omega: None,
        },
        Outputs::Tacan {
            features: Some(vec![0.1, 0.2, 0.3]),
            decision: Some(-0.4),
        },
        Outputs::Tacan {
            features: None,
            decision: None,
        },
    ];
    for o in outputs {
        let mut v = serde_json::to_value(&o).unwrap();
        v["tests"] = json!({});
        c.assert_valid(c.schema("MonitorResult"), &v, "monitor result");
    }
}

#[test]
fn gnss_outputs_and_snapshot_match_their_schemas() {
    use navguard_core::detect::Health;
    use navguard_core::monitor::Outputs;
    use navguard_core::monitor::gnss::GnssOutputs;
    use navguard_core::monitor::gnss::outputs::{Dops, GnssPosition, SatOutput};
    use navguard_core::session::stats::GnssSnapshot;
    let doc = spec();
    let c = Checker::new(&doc);
    let sat = |id: &str, el: Option<f64>, used: bool, health: Health| SatOutput {
        id: id.to_owned(),
        el,
        az: el.map(|e| e + 100.0),
        residual: el.map(|_| 1.5),
        w: el.map(|_| -0.5),
        used,
        health,
    };
    let fix = GnssOutputs {
        position: Some(GnssPosition {
            lat: 37.69,
            lon: -122.09,
            h: 21.0,
        }),
        clocks: [("G".to_owned(), 20.9), ("R".to_owned(), 19.8)].into(),
        dop: Some(Dops {
            gdop: 2.0,
            pdop: 1.7,
            hdop: 0.9,
            vdop: 1.4,
        }),
        hpl: Some(48.0),
        vpl: Some(63.4),
        hal: 40.0,
        val: Some(50.0),
        hpe: Some(2.9),
        vpe: None,
        satellites: vec![
            sat("G10", Some(63.8), false, Health::Suspect),
            sat("R24", Some(30.0), true, Health::Healthy),
        ],
        excluded: vec!["G10".to_owned()],
    };
    let bare =
        GnssOutputs::without_solution(40.0, None, vec![sat("E07", None, false, Health::Isolated)]);
    for o in [fix, bare] {
        let o = std::sync::Arc::new(o);
        let mut v = serde_json::to_value(Outputs::Gnss(o.clone())).unwrap();
        v["tests"] = json!({"raim": {"statistic": 11.4, "threshold": 34.1, "dof": 14,
                                     "test_ratio": 0.33, "state": "healthy"}});
        c.assert_valid(c.schema("MonitorResult"), &v, "gnss result");
        let snapshot = serde_json::to_value(GnssSnapshot {
            t: 12.0,
            outputs: o,
        })
        .unwrap();
        c.assert_valid(c.schema("GnssSnapshot"), &snapshot, "gnss snapshot");
        let mut bad = snapshot.clone();
        bad["satellites"][0]["health"] = json!("sick");
        assert!(!c.matches(c.schema("GnssSnapshot"), &bad), "{bad}");
        bad = snapshot.clone();
        bad.as_object_mut().unwrap().remove("t");
        assert!(!c.matches(c.schema("GnssSnapshot"), &bad), "{bad}");
    }
}

// Over 80 lines: a table of cases checked one after another.
#[tokio::test]
async fn federated_stats_with_a_track_match_their_schemas() {
    use navguard::service::wire::epoch_to_wire;
    use navguard_sim::scenario::ship_with;
    let doc = spec();
    let checker = Checker::new(&doc);
    let events_schema =
        &operation(&doc, "/api/v1/sessions/{id}/events", "GET")["x-websocket"]["server"];

    let dir = tempfile::tempdir().unwrap();
    let server = navguard::service::start(ServiceConfig::new(
        "127.0.0.1:0".parse().unwrap(),
        dir.path().join("t.db"),
    ))
    .await
    .unwrap();
    let addr = server.addr;
    let scenario = ship_with(2, vec![], 1.0).unwrap();
    let created = reqwest::Client::new()
        .post(format!("http://{addr}/api/v1/sessions"))
        .json(&json!({"id": "fed", "monitors": [{
            "name": "nav", "type": "federated", "config": scenario.default_monitor_config()
        }]}))
        .send()
        .await
        .unwrap();
    assert_eq!(created.status(), 201);
    let stats_url = format!("http://{addr}/api/v1/sessions/fed/stats");
    let get_stats = || async {
        reqwest::Client::new()
            .get(&stats_url)
            .send()
            .await
            .unwrap()
            .json::<Value>()
            .await
            .unwrap()
    };
    // Without a track (no epoch yet), then with one.
    let before = get_stats().await;
    assert!(before["monitors"]["nav"].get("track").is_none(), "{before}");
    checker.assert_valid(
        checker.schema("SessionStats"),
        &before,
        "stats before any epoch",
    );

    let (mut ingest, _) =
        tokio_tungstenite::connect_async(format!("ws://{addr}/api/v1/sessions/fed/ingest"))
            .await
            .unwrap();
    assert_eq!(next_json(&mut ingest).await["type"], "ready");
    let epochs: Vec<String> = scenario
        .epochs
        .iter()
        .map(|e| epoch_to_wire(&e.epoch).unwrap())
        .collect();
    let n = epochs.len() as u64;
    ingest
        .send(Message::Text(format!("[{}]", epochs.join(",")).into()))
        .await
        .unwrap();
    let mut after = get_stats().await;
    for _ in 0..500 {
        if after["epochs"].as_u64() == Some(n) {
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
        after = get_stats().await;
    }
    assert!(after["monitors"]["nav"]["track"].is_object(), "{after}");
    checker.assert_valid(checker.schema("SessionStats"), &after, "stats with a track");

    let (mut events, _) =
        tokio_tungstenite::connect_async(format!("ws://{addr}/api/v1/sessions/fed/events"))
            .await
            .unwrap();
    // The first message is the latest publication (≤ 20 a second), which may predate
    // the frame's end by up to 50 ms: read until the track is in.
    let mut first = next_json(&mut events).await;
    for _ in 0..20 {
        if first["monitors"]["nav"]["track"].is_object() {
            break;
        }
        first = next_json(&mut events).await;
    }
    assert!(first["monitors"]["nav"]["track"].is_object(), "{first}");
    checker.assert_valid(events_schema, &first, "stats message with a track");
    // The schema holds the track to its shape.
    let mut bad = after.clone();
    bad["monitors"]["nav"]["track"]["solution"]["vel"] = json!([0.0, 0.0, 0.0]);
    assert!(!checker.matches(checker.schema("SessionStats"), &bad));

    let _ = ingest.close(None).await;
    let _ = events.close(None).await;
    server.shutdown().await;
}

/// The spec and the server agree on the cases that are easy to get wrong:
/// integral floats are integers, `null` is refused where the spec has no
/// null, `.` and `..` are not names, the `tacan-window` window minimum, the
/// "exactly one of" rules of the missed-detection query, and a params schema
/// chosen by the model `kind`. Each case is checked against the spec's schema
/// and then against the server.
// Over 80 lines: a table of cases checked one after another.
#[tokio::test]
async fn spec_and_server_agree_on_integers_nulls_names_and_exclusive_parameters() {
    let doc = spec();
    let checker = Checker::new(&doc);
    let dir = tempfile::tempdir().unwrap();
    let c = Contract {
        router: app(state(dir.path(), None).await),
        doc: doc.clone(),
    };
    let sessions = "/api/v1/sessions";
    let create = checker.schema("CreateSession");

    // Integral floats: integers for the spec (JSON Schema) and the server.
    let mut body = session_body("ints", false);
    body["monitors"][0]["policy"] = json!({"kind": "counters", "n1": 10.0, "n2": 5e0});
    checker.assert_valid(create, &body, "integral floats");
    let created = c.call("POST", sessions, sessions, Some(&body)).await;
    assert_eq!(created["monitors"][0]["policy"]["n1"], 10, "{created}");
    assert_eq!(
        created["monitors"][0]["config"],
        linear_config(),
        "the config is stored as sent"
    );
    let template = "/api/v1/sessions/{id}/monitors/{name}/threshold";
    let uri = "/api/v1/sessions/ints/monitors/cv/threshold";
    let update = json!({"policy": {"kind": "counters", "n1": 3.0, "n2": 97619.0}});
    checker.assert_valid(checker.schema("ThresholdUpdate"), &update, "PUT");
    let view = c.call("PUT", template, uri, Some(&update)).await;
    assert_eq!(view["policy"]["n2"], 97619, "{view}");
    let chi2 = "/api/v1/chi2/threshold";
    let answer = c
        .call("GET", chi2, &format!("{chi2}?dof=2.0&p_fa=0.01"), None)
        .await;
    assert_eq!(answer["dof"], 2, "{answer}");
    let alarms = "/api/v1/alarms";
    let page = c
        .call(
            "GET",
            alarms,
            &format!("{alarms}?limit=10.0&after=0.0"),
            None,
        )
        .await;
    assert!(page["alarms"].is_array(), "{page}");
    let page = c
        .call("GET", alarms, &format!("{alarms}?limit=1.5"), None)
        .await;
    assert_eq!(page["error"]["code"], "bad_request", "{page}");

    // `null` where the spec has none: refused by both, naming the field.
    for (key, value) in [("threshold", json!(null)), ("p_fa", json!(null))] {
        let mut body = session_body("nulls", false);
        body["monitors"][0][key] = value;
        assert!(
            !checker.matches(create, &body),
            "the spec refuses {key}: null"
        );
        let refused = c.call("POST", sessions, sessions, Some(&body)).await;
        assert_eq!(refused["error"]["field"], format!("monitors[0].{key}"));
    }
    let mut body = session_body("nulls", false);
    body["id"] = json!(null);
    let refused = c.call("POST", sessions, sessions, Some(&body)).await;
    assert_eq!(refused["error"]["field"], "id", "{refused}");
    let refused = c
        .call("PUT", template, uri, Some(&json!({"p_fa": null})))
        .await;
    assert_eq!(refused["error"]["field"], "p_fa", "{refused}");
    // Policy keys the spec forbids (`additionalProperties: false`).
    let update = json!({"threshold": 20.0, "policy": {"kind": "classic", "n1": 4}});
    assert!(!checker.matches(checker.schema("ThresholdUpdate"), &update));
    let refused = c.call("PUT", template, uri, Some(&update)).await;
    assert_eq!(refused["error"]["field"], "policy", "{refused}");

    // `.` and `..`: not names for either.
    for id in [".", ".."] {
        assert!(!checker.matches(checker.schema("Name"), &json!(id)));
        let refused = c
            .call("POST", sessions, sessions, Some(&session_body(id, false)))
            .await;
        assert_eq!(refused["error"]["field"], "id", "{id}: {refused}");
    }

    // The tacan-window minimum is the same: 2.
    let features = checker.schema("FeaturesRequest");
    let ranges = json!([1000.0, 1001.0, 1002.5, 1003.0]);
    for (window, ok) in [(json!(1), false), (json!(2), true), (json!(2.0), true)] {
        let body = json!({"kind": "tacan-window", "ins_range_m": ranges,
                          "tacan_range_m": ranges, "window": window});
        assert_eq!(
            checker.matches(features, &body),
            ok,
            "spec, window {window}"
        );
        let answer = c
            .call("POST", "/api/v1/features", "/api/v1/features", Some(&body))
            .await;
        assert_eq!(
            answer["features"].is_array(),
            ok,
            "server, window {window}: {answer}"
        );
    }

    // Values whose features overflow: a 422, not `null` features (which the
    // response schema forbids).
    let huge = json!([1e200, -1e200, 1e200, -1e200]);
    let body =
        json!({"kind": "tacan-window", "ins_range_m": huge, "tacan_range_m": ranges, "window": 2});
    let refused = c
        .call("POST", "/api/v1/features", "/api/v1/features", Some(&body))
        .await;
    assert_eq!(refused["error"]["code"], "invalid", "{refused}");
    let body = json!({"kind": "wavelet-packet", "signal": [1e200, 1e200, -1e200, 1e200], "level": 1, "wavelet": "db1"});
    let refused = c
        .call("POST", "/api/v1/features", "/api/v1/features", Some(&body))
        .await;
    assert_eq!(refused["error"]["field"], "signal", "{refused}");

    // Exactly one of threshold | p_fa and of noncentrality | p_md: the spec's
    // query object and the server agree on every combination.
    let md = "/api/v1/chi2/missed-detection";
    let op = operation(&doc, md, "GET");
    let query_schema = &op["parameters"][0]["schema"];
    for threshold in [None, Some(("threshold", 9.0)), Some(("p_fa", 0.01))] {
        for fault in [None, Some(("noncentrality", 4.0)), Some(("p_md", 0.1))] {
            for both in [false, true] {
                let mut query = json!({"dof": 1});
                let mut pairs = vec!["dof=1".to_owned()];
                for (k, v) in threshold.into_iter().chain(fault) {
                    query[k] = json!(v);
                    pairs.push(format!("{k}={v}"));
                }
                // Both of the threshold pair (the one missing is added).
                if both {
                    for (k, v) in [("threshold", 9.0), ("p_fa", 0.02)] {
                        if query.get(k).is_none() {
                            query[k] = json!(v);
                            pairs.push(format!("{k}={v}"));
                        }
                    }
                }
                let spec_ok = checker.matches(query_schema, &query);
                let answer = c
                    .call("GET", md, &format!("{md}?{}", pairs.join("&")), None)
                    .await;
                let server_ok = answer["p_md"].is_number();
                assert_eq!(spec_ok, server_ok, "{query}: {answer}");
            }
        }
    }

    // The params schema follows `kind`: `nu` is an ocsvm parameter, not lssvm's.
    let train = checker.schema("TrainRequest");
    let data = json!({"x": [[0.0], [1.0], [2.0]], "y": [0.0, 1.0, 2.0]});
    let lssvm_nu = json!({"kind": "lssvm", "params": {"nu": 0.1}, "data": data});
    assert!(!checker.matches(train, &lssvm_nu));
    let models = "/api/v1/models";
    let refused = c.call("POST", models, models, Some(&lssvm_nu)).await;
    assert_eq!(refused["error"]["field"], "params.nu", "{refused}");
    let aliases =
        json!({"kind": "lssvm", "params": {"reg": 1.0, "gamma": 1.0, "sigma2": 1.0}, "data": data});
    assert!(!checker.matches(train, &aliases), "reg and its alias gamma");
    let refused = c.call("POST", models, models, Some(&aliases)).await;
    assert_eq!(refused["error"]["field"], "params.gamma", "{refused}");
    let widths = json!({"kind": "svm", "params": {"sigma2": 1.0, "kernel_gamma": 1.0},
                        "data": {"x": [[0.0], [1.0]], "y": [-1, 1]}});
    assert!(!checker.matches(train, &widths), "sigma2 and kernel_gamma");
    let refused = c.call("POST", models, models, Some(&widths)).await;
    assert_eq!(refused["error"]["code"], "invalid", "{refused}");
    let folds = json!({"kind": "lssvm", "params": {"reg": 1.0, "sigma2": 1.0},
                       "cv": {"folds": 2.0, "seed": 1.0}, "data": data});
    assert!(checker.matches(train, &folds));
    let record = c.call("POST", models, models, Some(&folds)).await;
    assert_eq!(record["status"], "training", "{record}");
}
