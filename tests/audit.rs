//! The audit log and alarm acknowledgements against a real server (docs/architecture.md
//! §A5): every change route of `ROUTES` writes one entry with the right actor, route,
//! session and reason (a new change route without a case here, or whose handler says
//! nothing of its change, fails); a refused request writes none; the filters and a
//! session-limited token's view; acknowledging an alarm; and an alarm traced to the
//! threshold change in force when it was raised.

mod common;

use std::path::Path;

use common::{CvModel, cart, client, epochs, http, recv_until, send, store_for};
use navguard::service::access::{Access, ROUTE_ACCESS};
use navguard::service::app::ROUTES;
use navguard::service::audit::{UNAUDITED, audited};
use navguard::service::store::AlarmKey;
use navguard::service::tokens::{hash_secret, to_hex};
use navguard::service::wire::{AlarmRecord, Severity};
use navguard::service::{self, Server, ServiceConfig};
use navguard_core::detect::Health;
use serde_json::{Value, json};

const OPS: &str = "sec-ops";
const ANALYST: &str = "sec-analyst";
const READER: &str = "sec-reader";
const VEHICLES: &str = "sec-vehicles";

/// A server with four tokens: `ops` (admin), `analyst` (read, operate), `reader` (read)
/// and `vehicles` (read, limited to `veh-*`).
async fn start(dir: &Path) -> Server {
    let entry = |name: &str, secret: &str, scopes: &[&str]| json!({"name": name, "hash": to_hex(&hash_secret(secret)), "scopes": scopes});
    let mut vehicles = entry("vehicles", VEHICLES, &["read"]);
    vehicles["sessions"] = json!(["veh-*"]);
    let file = dir.join("tokens.json");
    let tokens = [
        entry("ops", OPS, &["admin"]),
        entry("analyst", ANALYST, &["read", "operate"]),
        entry("reader", READER, &["read"]),
        vehicles,
    ];
    std::fs::write(&file, json!({ "tokens": tokens }).to_string()).unwrap();
    let db = store_for(&dir.join("audit.db")).await;
    let mut config = ServiceConfig::new("127.0.0.1:0".parse().unwrap(), db);
    config.tokens_file = Some(file);
    service::start(config).await.expect("server starts")
}

/// `(status, JSON body or null)` of `method url` with `secret`, an optional reason and body.
async fn call(
    method: &str,
    url: &str,
    secret: Option<&str>,
    reason: Option<&str>,
    body: Option<&Value>,
) -> (u16, Value) {
    let mut req = client().request(method.parse().unwrap(), url);
    if let Some(s) = secret {
        req = req.bearer_auth(s);
    }
    if let Some(r) = reason {
        req = req.header("X-Navguard-Reason", r);
    }
    if let Some(b) = body {
        req = req.json(b);
    }
    let resp = req.send().await.unwrap();
    let status = resp.status().as_u16();
    (status, resp.json().await.unwrap_or(Value::Null))
}

/// The audit log as `ops` reads it with `query` (newest first).
async fn audit(server: &Server, query: &str) -> Vec<Value> {
    let url = format!("{}/api/v1/audit?limit=1000&{query}", http(server));
    let (status, page) = call("GET", &url, Some(OPS), None, None).await;
    assert_eq!(status, 200, "{page}");
    page["entries"].as_array().unwrap().clone()
}

/// Commits an alarm-log entry for `session` straight to the store (what an actor does).
async fn raise(server: &Server, session: &str) -> i64 {
    let alarm = AlarmRecord {
        id: 0,
        severity: Severity::Alarm,
        session: session.into(),
        monitor: "position".into(),
        test: "residual".into(),
        state: Health::Isolated,
        t: 12.0,
        statistic: 40.0,
        threshold: 19.5,
        dof: 1,
        test_ratio: 40.0 / 19.5,
        delay_s: 0.0,
        raised_at_ms: navguard::service::now_ms(),
        cleared_t: None,
    };
    let stored = server
        .state()
        .store
        .insert_alarm(alarm, AlarmKey::default(), None)
        .await
        .unwrap();
    stored.id
}

/// One case of the change-route walk: the concrete path, the body, the session the entry
/// must name, and a check of its previous and new values.
struct Case {
    path: String,
    body: Option<Value>,
    session: Option<String>,
    check: fn(&Value, &Value),
}

/// The order the change routes run in (a session and a model are created before they are
/// changed and deleted); unlisted routes run last, and fail.
const ORDER: [(&str, &str); 8] = [
    ("/api/v1/sessions", "POST"),
    ("/api/v1/sessions/{id}/monitors/{name}/threshold", "PUT"),
    ("/api/v1/sessions/{id}/alarms/{alarm_id}/ack", "POST"),
    ("/api/v1/sessions/{id}", "DELETE"),
    ("/api/v1/models", "POST"),
    ("/api/v1/models/{id}/predict", "POST"),
    ("/api/v1/features", "POST"),
    ("/api/v1/models/{id}", "DELETE"),
];

/// The valid request of change route `method path`, given the model id created so far.
fn case(path: &str, method: &str, alarm: i64, model: &str) -> Case {
    let none = |_: &Value, _: &Value| {};
    match (path, method) {
        ("/api/v1/sessions", "POST") => Case {
            path: path.into(),
            body: Some(cart("a-1")),
            session: Some("a-1".into()),
            check: |prev, new| {
                assert!(prev.is_null());
                assert_eq!(new["id"], "a-1");
                assert_eq!(new["monitors"][0]["p_fa"], 1e-5);
            },
        },
        ("/api/v1/sessions/{id}/monitors/{name}/threshold", "PUT") => Case {
            path: "/api/v1/sessions/a-1/monitors/position/threshold".into(),
            body: Some(json!({"p_fa": 1e-4})),
            session: Some("a-1".into()),
            check: |prev, new| {
                assert_eq!(prev["p_fa"], 1e-5);
                assert_eq!(new["p_fa"], 1e-4);
                let (before, after) = (
                    prev["tests"]["residual"]["threshold"].as_f64().unwrap(),
                    new["tests"]["residual"]["threshold"].as_f64().unwrap(),
                );
                assert!(after < before, "{before} → {after}");
            },
        },
        ("/api/v1/sessions/{id}/alarms/{alarm_id}/ack", "POST") => Case {
            path: format!("/api/v1/sessions/a-1/alarms/{alarm}/ack"),
            body: Some(json!({"comment": "checked"})),
            session: Some("a-1".into()),
            check: |prev, new| {
                assert!(prev["acked_by"].is_null());
                assert_eq!(new["acked_by"], "ops");
                assert_eq!(new["ack_comment"], "checked");
                assert_eq!(prev["id"], new["id"]);
            },
        },
        ("/api/v1/sessions/{id}", "DELETE") => Case {
            path: "/api/v1/sessions/a-1".into(),
            body: None,
            session: Some("a-1".into()),
            check: |prev, new| {
                assert_eq!(prev["id"], "a-1");
                assert_eq!(prev["monitors"][0]["p_fa"], 1e-4, "the spec as changed");
                assert!(new.is_null());
            },
        },
        ("/api/v1/models", "POST") => Case {
            path: path.into(),
            body: Some(json!({"kind": "lssvm", "name": "square",
                "params": {"reg": 1000, "sigma2": 1},
                "data": {"x": [[0], [0.5], [1], [1.5], [2]], "y": [0, 0.25, 1, 2.25, 4]}})),
            session: None,
            check: |prev, new| {
                assert!(prev.is_null());
                assert_eq!(new["name"], "square");
                assert_eq!(new["kind"], "lssvm");
            },
        },
        ("/api/v1/models/{id}/predict", "POST") => Case {
            path: format!("/api/v1/models/{model}/predict"),
            body: Some(json!({"x": [[0.6]]})),
            session: None,
            check: none,
        },
        ("/api/v1/features", "POST") => Case {
            path: path.into(),
            body: Some(
                json!({"kind": "wavelet-packet", "signal": [1, 2, 3, 4, 5, 6, 7, 8],
                "wavelet": "db1", "level": 2}),
            ),
            session: None,
            check: none,
        },
        ("/api/v1/models/{id}", "DELETE") => Case {
            path: format!("/api/v1/models/{model}"),
            body: None,
            session: None,
            check: |prev, new| {
                assert_eq!(prev["name"], "square");
                assert!(new.is_null());
            },
        },
        _ => panic!(
            "{method} {path} is a change route with no case in tests/audit.rs: add one, and have \
             its handler leave an audit::Change in its answer (or list it in audit::UNAUDITED \
             if it changes nothing)"
        ),
    }
}

/// Waits until model `id` is no longer training.
async fn trained(server: &Server, id: &str) {
    let url = format!("{}/api/v1/models/{id}", http(server));
    for _ in 0..200 {
        let (_, record) = call("GET", &url, Some(OPS), None, None).await;
        if record["status"] != "training" {
            assert_eq!(record["status"], "ready", "{record}");
            return;
        }
        tokio::time::sleep(std::time::Duration::from_millis(25)).await;
    }
    panic!("model {id} still training after 5 s");
}

// Over 80 lines: one walk over the route table; its steps share the server and ids.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_change_route_writes_one_entry_with_actor_route_session_and_reason() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path()).await;
    let base = http(&server);
    let mut changes: Vec<(&str, &str)> = ROUTES
        .iter()
        .flat_map(|(path, methods)| methods.iter().map(move |m| (*path, *m)))
        .filter(|(_, m)| *m != "GET")
        .collect();
    changes.sort_by_key(|r| ORDER.iter().position(|o| o == r).unwrap_or(ORDER.len()));
    // Every change route needs a scope beyond `read` or is a listed computation.
    for (path, method) in &changes {
        let (_, _, access, _) = ROUTE_ACCESS
            .iter()
            .find(|(p, m, _, _)| p == path && m == method)
            .unwrap();
        let computes = UNAUDITED.contains(&(*path, *method));
        assert_eq!(
            computes,
            *access == Access::Scope(navguard::service::tokens::Scope::Read),
            "{method} {path}: a route that changes nothing needs `read`, a change more"
        );
    }
    let alarm = raise(&server, "a-1").await;
    let mut model = String::new();
    for (path, method) in changes {
        let c = case(path, method, alarm, &model);
        let reason = format!("reason for {method} {path} — ünïcode");
        let before = audit(&server, "").await;
        let url = format!("{base}{}", c.path);
        let (status, answer) = call(
            method,
            &url,
            Some(OPS),
            Some(reason.as_str()),
            c.body.as_ref(),
        )
        .await;
        assert!(
            (200..300).contains(&status),
            "{method} {path}: {status} {answer}"
        );
        if path == "/api/v1/models" {
            model = answer["id"].as_str().unwrap().to_owned();
            trained(&server, &model).await;
        }
        let after = audit(&server, "").await;
        let method_parsed: axum::http::Method = method.parse().unwrap();
        if !audited(path, &method_parsed) {
            assert_eq!(after, before, "{method} {path} changes nothing: no entry");
            continue;
        }
        assert_eq!(after.len(), before.len() + 1, "{method} {path}: one entry");
        let e = &after[0];
        assert_eq!(e["actor"], "ops", "{e}");
        assert_eq!(e["method"], method, "{e}");
        assert_eq!(e["route"], path, "{e}");
        assert_eq!(e["path"], c.path, "{e}");
        assert_eq!(e["session"], json!(c.session), "{e}");
        assert_eq!(e["reason"], reason, "{e}");
        assert!(
            e["client"].as_str().unwrap().starts_with("127.0.0.1:"),
            "{e}"
        );
        assert!(
            !(e["previous"].is_null() && e["new"].is_null()),
            "{method} {path}: the handler says what it changed: {e}"
        );
        (c.check)(&e["previous"], &e["new"]);
    }
    server.shutdown().await;
}

/// A request that must be refused: method, URL, token, reason, body, the status expected.
type Refusal<'a> = (
    &'a str,
    String,
    Option<&'a str>,
    Option<&'a str>,
    Option<Value>,
    u16,
);

// Over 80 lines: a table of refusals checked one after another.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refused_change_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path()).await;
    let base = http(&server);
    let sessions = format!("{base}/api/v1/sessions");
    let (status, _) = call("POST", &sessions, Some(OPS), None, Some(&cart("b-1"))).await;
    assert_eq!(status, 201);
    let alarm = raise(&server, "b-1").await;
    let before = audit(&server, "").await;
    assert_eq!(before.len(), 1);
    let threshold = format!("{base}/api/v1/sessions/b-1/monitors/position/threshold");
    let ack = format!("{base}/api/v1/sessions/b-1/alarms/{alarm}/ack");
    let long = "x".repeat(501);
    let long = long.as_str();
    let mut bad = cart("b-2");
    bad["monitors"][0]["config"]["r"] = json!([[0.0]]);
    let refusals: Vec<Refusal<'_>> = vec![
        ("POST", sessions.clone(), Some(OPS), None, Some(bad), 422),
        (
            "POST",
            sessions.clone(),
            Some(OPS),
            None,
            Some(cart("b-1")),
            409,
        ),
        ("POST", sessions.clone(), None, None, Some(cart("b-3")), 401),
        (
            "POST",
            sessions.clone(),
            Some(ANALYST),
            None,
            Some(cart("b-3")),
            403,
        ),
        (
            "POST",
            sessions.clone(),
            Some(OPS),
            Some(long),
            Some(cart("b-3")),
            422,
        ),
        (
            "DELETE",
            format!("{sessions}/nope"),
            Some(OPS),
            None,
            None,
            404,
        ),
        (
            "DELETE",
            format!("{sessions}/b-1"),
            Some(OPS),
            Some(long),
            None,
            422,
        ),
        (
            "PUT",
            threshold.clone(),
            Some(READER),
            None,
            Some(json!({"p_fa": 1e-3})),
            403,
        ),
        (
            "PUT",
            threshold.clone(),
            Some(ANALYST),
            None,
            Some(json!({"p_fa": 2.0})),
            422,
        ),
        (
            "PUT",
            threshold.replace("position", "nope"),
            Some(ANALYST),
            None,
            Some(json!({"p_fa": 1e-3})),
            404,
        ),
        (
            "PUT",
            threshold.clone(),
            Some(ANALYST),
            Some(long),
            Some(json!({"p_fa": 1e-3})),
            422,
        ),
        (
            "POST",
            ack.clone(),
            Some(READER),
            None,
            Some(json!({"comment": "x"})),
            403,
        ),
        (
            "POST",
            ack.clone(),
            Some(ANALYST),
            None,
            Some(json!({"comment": " "})),
            422,
        ),
        (
            "POST",
            ack.clone(),
            Some(ANALYST),
            Some(long),
            Some(json!({"comment": "x"})),
            422,
        ),
        (
            "DELETE",
            format!("{base}/api/v1/models/m-0123456789abcdef"),
            Some(OPS),
            None,
            None,
            404,
        ),
        (
            "POST",
            format!("{base}/api/v1/models"),
            Some(OPS),
            None,
            Some(json!({"kind": "nope"})),
            422,
        ),
    ];
    for (method, url, secret, reason, body, expected) in refusals {
        let (status, answer) = call(method, &url, secret, reason, body.as_ref()).await;
        assert_eq!(status, expected, "{method} {url}: {answer}");
        assert!(
            answer["error"]["code"].is_string(),
            "{method} {url}: {answer}"
        );
        if status == 422 && reason.is_some() {
            assert_eq!(answer["error"]["field"], "X-Navguard-Reason", "{answer}");
        }
    }
    assert_eq!(
        audit(&server, "").await,
        before,
        "no refusal wrote an entry"
    );
    // The refused long reasons changed nothing either.
    let (status, view) = call("GET", &threshold, Some(READER), None, None).await;
    assert_eq!((status, &view["p_fa"]), (200, &json!(1e-5)));
    let (status, _) = call("GET", &format!("{sessions}/b-3"), Some(OPS), None, None).await;
    assert_eq!(status, 404);
    let (status, _) = call("GET", &format!("{sessions}/b-1"), Some(OPS), None, None).await;
    assert_eq!(status, 200);
    server.shutdown().await;
}

// Over 80 lines: one scenario; its filters share the entries it writes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_audit_log_filters_pages_and_shows_a_limited_token_only_its_sessions() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path()).await;
    let base = http(&server);
    let sessions = format!("{base}/api/v1/sessions");
    for id in ["veh-1", "vehx", "car-1"] {
        let (status, _) = call("POST", &sessions, Some(OPS), None, Some(&cart(id))).await;
        assert_eq!(status, 201);
    }
    // A millisecond of its own between the creations and the changes.
    tokio::time::sleep(std::time::Duration::from_millis(5)).await;
    let mid = navguard::service::now_ms();
    tokio::time::sleep(std::time::Duration::from_millis(5)).await;
    for id in ["veh-1", "car-1"] {
        // As through HAProxy: the client's own line, then the proxy's.
        let resp = client()
            .put(format!("{sessions}/{id}/monitors/position/threshold"))
            .bearer_auth(ANALYST)
            .header("X-Navguard-Reason", "tuning")
            .header("X-Forwarded-For", "10.9.9.9")
            .header("X-Forwarded-For", "192.0.2.7")
            .json(&json!({"threshold": 25.0}))
            .send()
            .await
            .unwrap();
        assert_eq!(resp.status(), 200);
    }
    let (status, _) = call(
        "POST",
        &format!("{base}/api/v1/models"),
        Some(OPS),
        None,
        Some(&json!({"kind": "ocsvm", "data": {"x": [[0, 0], [0.1, 0], [0, 0.1], [0.1, 0.1]]}})),
    )
    .await;
    assert_eq!(status, 202);

    let all = audit(&server, "").await;
    assert_eq!(all.len(), 6);
    let ids: Vec<i64> = all.iter().map(|e| e["id"].as_i64().unwrap()).collect();
    assert!(ids.windows(2).all(|w| w[0] > w[1]), "newest first: {ids:?}");
    let session_of = |e: &Value| e["session"].as_str().map(str::to_owned);
    let veh = audit(&server, "session=veh-1").await;
    assert_eq!(veh.len(), 2);
    assert!(
        veh.iter()
            .all(|e| session_of(e).as_deref() == Some("veh-1"))
    );
    let analyst = audit(&server, "actor=analyst").await;
    assert_eq!(analyst.len(), 2);
    assert!(analyst.iter().all(|e| e["reason"] == "tuning"));
    assert!(
        analyst
            .iter()
            .all(|e| e["forwarded_for"] == "10.9.9.9, 192.0.2.7"),
        "{analyst:?}"
    );
    assert!(
        all.iter()
            .all(|e| e["actor"] == "analyst" || e["forwarded_for"].is_null())
    );
    let since = audit(&server, &format!("since={mid}")).await;
    assert_eq!(since.len(), 3);
    assert!(since.iter().all(|e| e["at_ms"].as_i64().unwrap() >= mid));

    // Pages of two, following next_before, give the whole log in order.
    let mut paged = Vec::new();
    let mut cursor: Option<i64> = None;
    loop {
        let mut url = format!("{base}/api/v1/audit?limit=2");
        if let Some(c) = cursor {
            url.push_str(&format!("&before={c}"));
        }
        let (status, page) = call("GET", &url, Some(READER), None, None).await;
        assert_eq!(status, 200, "{page}");
        paged.extend(page["entries"].as_array().unwrap().iter().cloned());
        match page["next_before"].as_i64() {
            Some(c) => cursor = Some(c),
            None => break,
        }
    }
    assert_eq!(paged, all);
    for bad in ["limit=0", "limit=1001"] {
        let url = format!("{base}/api/v1/audit?{bad}");
        let (status, answer) = call("GET", &url, Some(READER), None, None).await;
        assert_eq!((status, &answer["error"]["field"]), (422, &json!("limit")));
    }
    let (status, _) = call(
        "GET",
        &format!("{base}/api/v1/audit?since=soon"),
        Some(READER),
        None,
        None,
    )
    .await;
    assert_eq!(status, 400);

    // The token limited to veh-* sees the entries about veh-1 only: not vehx, not the
    // other sessions, not the model.
    let url = format!("{base}/api/v1/audit");
    let (status, page) = call("GET", &url, Some(VEHICLES), None, None).await;
    assert_eq!(status, 200, "{page}");
    let seen: Vec<Option<String>> = page["entries"]
        .as_array()
        .unwrap()
        .iter()
        .map(session_of)
        .collect();
    assert_eq!(seen, [Some("veh-1".to_owned()), Some("veh-1".to_owned())]);
    let (status, answer) = call(
        "GET",
        &format!("{url}?session=car-1"),
        Some(VEHICLES),
        None,
        None,
    )
    .await;
    assert_eq!(
        (status, &answer["error"]["code"]),
        (403, &json!("forbidden"))
    );
    let (status, page) = call(
        "GET",
        &format!("{url}?session=veh-1"),
        Some(VEHICLES),
        None,
        None,
    )
    .await;
    assert_eq!(
        (status, page["entries"].as_array().unwrap().len()),
        (200, 2)
    );
    server.shutdown().await;
}

// Over 80 lines: one scenario in the order it happens.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_alarm_is_acknowledged_once_with_who_when_and_why() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path()).await;
    let base = http(&server);
    let (status, _) = call(
        "POST",
        &format!("{base}/api/v1/sessions"),
        Some(OPS),
        None,
        Some(&cart("c-1")),
    )
    .await;
    assert_eq!(status, 201);
    let first = raise(&server, "c-1").await;
    let second = raise(&server, "c-1").await;
    let elsewhere = raise(&server, "c-2").await;
    let ack = |id: i64| format!("{base}/api/v1/sessions/c-1/alarms/{id}/ack");
    let comment = json!({"comment": "  multipath near the quay  "});

    let (status, answer) = call("POST", &ack(first), Some(READER), None, Some(&comment)).await;
    assert_eq!(
        (status, &answer["error"]["scope"]),
        (403, &json!("operate")),
        "{answer}"
    );
    let t0 = navguard::service::now_ms();
    let (status, entry) = call(
        "POST",
        &ack(first),
        Some(ANALYST),
        Some("shift check"),
        Some(&comment),
    )
    .await;
    assert_eq!(status, 200, "{entry}");
    assert_eq!(entry["id"], first);
    assert_eq!(entry["acked_by"], "analyst");
    assert_eq!(entry["ack_comment"], "multipath near the quay");
    assert!(entry["acked_at_ms"].as_i64().unwrap() >= t0);

    // In the alarm log: the acknowledged entry with its acknowledgement, the other with nulls.
    let (_, page) = call(
        "GET",
        &format!("{base}/api/v1/alarms?session=c-1"),
        Some(READER),
        None,
        None,
    )
    .await;
    let log = page["alarms"].as_array().unwrap();
    assert_eq!(log.len(), 2);
    assert_eq!(
        log[1], entry,
        "the log shows what the acknowledgement answered"
    );
    assert_eq!(log[0]["id"], second);
    for field in ["acked_by", "acked_at_ms", "ack_comment"] {
        assert!(log[0][field].is_null(), "{field}: {}", log[0]);
    }

    // In the audit log, once.
    let entries = audit(&server, "session=c-1&actor=analyst").await;
    assert_eq!(entries.len(), 1);
    let e = &entries[0];
    assert_eq!(e["route"], "/api/v1/sessions/{id}/alarms/{alarm_id}/ack");
    assert_eq!(e["reason"], "shift check");
    assert_eq!(e["new"], entry);
    assert!(e["previous"]["acked_by"].is_null());

    // Twice: 409, nothing changed, nothing written.
    let other = json!({"comment": "again"});
    let (status, answer) = call("POST", &ack(first), Some(OPS), None, Some(&other)).await;
    assert_eq!(
        (status, &answer["error"]["code"]),
        (409, &json!("conflict")),
        "{answer}"
    );
    assert!(
        answer["error"]["message"]
            .as_str()
            .unwrap()
            .contains("analyst")
    );
    let (_, page) = call(
        "GET",
        &format!("{base}/api/v1/alarms?session=c-1"),
        Some(READER),
        None,
        None,
    )
    .await;
    assert_eq!(page["alarms"][1], entry);
    assert_eq!(
        audit(&server, "session=c-1").await.len(),
        2,
        "the create and one ack"
    );

    // Unknown ids, another session's entry, bad bodies.
    for id in ["999999", "abc", &elsewhere.to_string(), "-1"] {
        let url = format!("{base}/api/v1/sessions/c-1/alarms/{id}/ack");
        let (status, answer) = call("POST", &url, Some(ANALYST), None, Some(&comment)).await;
        assert_eq!(
            (status, &answer["error"]["code"]),
            (404, &json!("not_found")),
            "{id}: {answer}"
        );
    }
    let long = json!({"comment": "x".repeat(501)});
    for (body, field) in [
        (json!({}), None),
        (json!({"comment": ""}), Some("comment")),
        (json!({"comment": null}), None),
        (json!({"comment": 3}), None),
        (long, Some("comment")),
        (json!({"comment": "ok", "extra": 1}), None),
    ] {
        let (status, answer) = call("POST", &ack(second), Some(ANALYST), None, Some(&body)).await;
        assert_eq!(status, 422, "{body}: {answer}");
        if let Some(f) = field {
            assert_eq!(answer["error"]["field"], f, "{answer}");
        }
    }
    let resp = client()
        .post(ack(second))
        .bearer_auth(ANALYST)
        .header("content-type", "application/json")
        .body("{")
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 400);
    server.shutdown().await;
}

/// Streams `z` (from time index `from`) into the open ingest socket and returns the first
/// `alarm` message.
async fn alarm_after(socket: &mut common::Socket, z: &[f64], from: usize) -> Value {
    send(socket, &Value::Array(epochs(z, from))).await;
    recv_until(socket, |m| m["type"] == "alarm").await.0
}

// Over 80 lines: one scenario in the order it happens.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_alarm_is_traced_to_the_threshold_change_in_force_when_it_was_raised() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path()).await;
    let base = http(&server);
    let model = CvModel {
        q: 0.01,
        sigma: 1.0,
        p0: 10.0,
    };
    let body = common::cv_session(
        "d-1",
        &model,
        json!({"kind": "classic"}),
        json!({"threshold": 50.0}),
        false,
    );
    let (status, answer) = call(
        "POST",
        &format!("{base}/api/v1/sessions"),
        Some(OPS),
        None,
        Some(&body),
    )
    .await;
    assert_eq!(status, 201, "{answer}");
    // Faults of 30 σ on epochs 60–62 and 160–162; everything else fault-free.
    let z = model.measurements(220, 7, |k| {
        if (60..63).contains(&k) || (160..163).contains(&k) {
            30.0
        } else {
            0.0
        }
    });
    let threshold = format!("{base}/api/v1/sessions/d-1/monitors/cv/threshold");
    let put = |value: f64| {
        let threshold = threshold.clone();
        async move {
            let body = json!({"threshold": value});
            let (status, view) = call(
                "PUT",
                &threshold,
                Some(ANALYST),
                Some("retuned"),
                Some(&body),
            )
            .await;
            assert_eq!(status, 200, "{view}");
        }
    };
    put(25.0).await;
    let url = format!(
        "{}/api/v1/sessions/d-1/ingest?token={OPS}",
        common::ws(&server)
    );
    let mut socket = common::connect(&url).await;
    let ready = common::recv(&mut socket).await;
    assert_eq!(ready["type"], "ready");
    alarm_after(&mut socket, &z[..120], 0).await;
    put(40.0).await;
    alarm_after(&mut socket, &z[120..], 120).await;
    drop(socket);

    let (_, page) = call(
        "GET",
        &format!("{base}/api/v1/alarms?session=d-1&severity=alarm"),
        Some(READER),
        None,
        None,
    )
    .await;
    let alarms = page["alarms"].as_array().unwrap().clone();
    assert_eq!(alarms.len(), 2, "{page}");
    let changes: Vec<Value> = audit(&server, "session=d-1")
        .await
        .into_iter()
        .filter(|e| e["route"] == "/api/v1/sessions/{id}/monitors/{name}/threshold")
        .collect();
    assert_eq!(changes.len(), 2);
    let mut found = Vec::new();
    for alarm in &alarms {
        let raised = alarm["raised_at_ms"].as_i64().unwrap();
        // The audit log is newest first: the first change at or before the alarm.
        let change = changes
            .iter()
            .find(|e| {
                let monitor = format!("/monitors/{}/threshold", alarm["monitor"].as_str().unwrap());
                e["at_ms"].as_i64().unwrap() <= raised
                    && e["path"].as_str().unwrap().ends_with(&monitor)
            })
            .unwrap_or_else(|| panic!("no threshold change before {alarm}"));
        let in_force = &change["new"]["tests"][alarm["test"].as_str().unwrap()]["threshold"];
        assert_eq!(alarm["threshold"], *in_force, "{alarm} under {change}");
        found.push(in_force.as_f64().unwrap());
    }
    assert_eq!(
        found,
        [40.0, 25.0],
        "newest alarm first, each under its own change"
    );
    server.shutdown().await;
}
