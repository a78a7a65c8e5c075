//! Scoped tokens (docs/architecture.md §A5) against a real server: every route of
//! `ROUTES` under every scope, the route table against the scopes the OpenAPI contract
//! declares, session-limited tokens, expiry, the tokens file read again when it
//! changes, and `--token` keeping every scope.

mod common;

use std::path::{Path, PathBuf};
use std::time::Duration;

use common::*;
use navguard::service::access::{Access, ROUTE_ACCESS};
use navguard::service::app::ROUTES;
use navguard::service::tokens::{hash_secret, to_hex};
use navguard::service::{self, Server, ServiceConfig};
use serde_json::{Value, json};

/// The secret `--token` is given in these tests.
const DEFAULT: &str = "s3cret-default";

/// One token per scope: (secret, scope).
const PER_SCOPE: [(&str, &str); 4] = [
    ("sec-ingest", "ingest"),
    ("sec-read", "read"),
    ("sec-operate", "operate"),
    ("sec-admin", "admin"),
];

fn entry(name: &str, secret: &str, scopes: &[&str]) -> Value {
    json!({"name": name, "hash": to_hex(&hash_secret(secret)), "scopes": scopes})
}

fn write_tokens(path: &Path, entries: &[Value]) {
    std::fs::write(path, json!({ "tokens": entries }).to_string()).unwrap();
}

async fn start_with(dir: &Path, token: Option<&str>, tokens_file: Option<PathBuf>) -> Server {
    let db = store_for(&dir.join("t.db")).await;
    let mut config = ServiceConfig::new("127.0.0.1:0".parse().unwrap(), db);
    config.token = token.map(str::to_owned);
    config.tokens_file = tokens_file;
    service::start(config).await.expect("server starts")
}

/// `(status, JSON body or null)` of `method url`, with `secret` as the bearer token.
async fn call(method: &str, url: &str, secret: Option<&str>, body: Option<&Value>) -> (u16, Value) {
    let mut req = client().request(method.parse().unwrap(), url);
    if let Some(s) = secret {
        req = req.bearer_auth(s);
    }
    if let Some(b) = body {
        req = req.json(b);
    }
    let resp = req.send().await.unwrap();
    let status = resp.status().as_u16();
    (status, resp.json().await.unwrap_or(Value::Null))
}

fn assert_forbidden(answer: &(u16, Value), scope: &str, what: &str) {
    assert_eq!(answer.0, 403, "{what}: {}", answer.1);
    assert_eq!(
        answer.1["error"]["code"], "forbidden",
        "{what}: {}",
        answer.1
    );
    assert_eq!(answer.1["error"]["scope"], scope, "{what}: {}", answer.1);
}

fn contract() -> Value {
    serde_yaml_ng::from_str(include_str!("../openapi/openapi.yaml")).unwrap()
}

/// What the contract says `method path` needs: `public`, `authenticated` or a scope.
fn declared_scope(doc: &Value, path: &str, method: &str) -> String {
    let op = &doc["paths"][path][method.to_lowercase()];
    op["x-navguard-scope"]
        .as_str()
        .unwrap_or_else(|| panic!("{method} {path} declares no x-navguard-scope"))
        .to_owned()
}

/// The server against the contract (not against the code's own table, which
/// `the_contract_declares_the_scope_the_route_table_gives` compares with the contract).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_route_answers_every_scope_as_the_contract_says() {
    let doc = contract();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("tokens.json");
    let entries: Vec<Value> = PER_SCOPE
        .iter()
        .map(|(secret, scope)| entry(&format!("only-{scope}"), secret, &[scope]))
        .collect();
    write_tokens(&file, &entries);
    let server = start_with(dir.path(), Some(DEFAULT), Some(file)).await;
    let base = http(&server);
    for (path, methods) in ROUTES {
        for method in *methods {
            let needs = declared_scope(&doc, path, method);
            let url = format!("{base}{}", concrete(path, "x"));
            let what = format!("{method} {path}");
            let anonymous = call(method, &url, None, None).await;
            if needs == "public" {
                assert!(![401, 403].contains(&anonymous.0), "{what} is public");
                continue;
            }
            assert_eq!(anonymous.0, 401, "{what} without a token");
            let wrong = call(method, &url, Some("not-a-token"), None).await;
            assert_eq!(wrong.0, 401, "{what} with an unknown token");
            let default = call(method, &url, Some(DEFAULT), None).await;
            assert!(
                ![401, 403].contains(&default.0),
                "{what} with --token: {default:?}"
            );
            for (secret, scope) in PER_SCOPE {
                let answer = call(method, &url, Some(secret), None).await;
                let allowed = needs == "authenticated" || needs == scope || scope == "admin";
                let what = format!("{what} with the {scope} token");
                if allowed {
                    assert!(![401, 403].contains(&answer.0), "{what}: {answer:?}");
                } else {
                    assert_forbidden(&answer, &needs, &what);
                }
            }
        }
    }
    server.shutdown().await;
}

#[test]
fn the_contract_declares_the_scope_the_route_table_gives() {
    let doc = contract();
    for (path, method, needs, _) in ROUTE_ACCESS {
        let op = &doc["paths"][path][method.to_lowercase()];
        let what = format!("{method} {path}");
        assert_eq!(
            op["x-navguard-scope"].as_str(),
            Some(needs.as_str()),
            "{what}: x-navguard-scope"
        );
        let public = op["security"].as_array().is_some_and(Vec::is_empty);
        assert_eq!(public, *needs == Access::Public, "{what}: security");
        let forbidden = &op["responses"]["403"]["$ref"];
        match needs {
            Access::Scope(_) => assert_eq!(
                forbidden, "#/components/responses/Forbidden",
                "{what}: declares its 403"
            ),
            _ => assert!(forbidden.is_null(), "{what}: no 403"),
        }
    }
    // And no operation of the contract is missing from the table.
    for (path, item) in doc["paths"].as_object().unwrap() {
        for (method, _) in item.as_object().unwrap() {
            if method == "parameters" {
                continue;
            }
            let upper = method.to_uppercase();
            assert!(
                ROUTE_ACCESS
                    .iter()
                    .any(|(p, m, _, _)| p == path && *m == upper),
                "{upper} {path} is in the contract but not in ROUTE_ACCESS"
            );
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refusal_is_the_same_whether_the_session_exists_or_not() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("tokens.json");
    write_tokens(&file, &[entry("reader", "r", &["read"])]);
    let server = start_with(dir.path(), Some(DEFAULT), Some(file)).await;
    let base = http(&server);
    let created = call(
        "POST",
        &format!("{base}/api/v1/sessions"),
        Some(DEFAULT),
        Some(&cart("c1")),
    )
    .await;
    assert_eq!(created.0, 201, "{}", created.1);
    for id in ["c1", "nope"] {
        let del = call(
            "DELETE",
            &format!("{base}/api/v1/sessions/{id}"),
            Some("r"),
            None,
        )
        .await;
        assert_forbidden(&del, "admin", id);
        assert_eq!(
            del.1["error"]["message"],
            "token 'reader' lacks the scope 'admin'"
        );
        let url = format!("{base}/api/v1/sessions/{id}/monitors/position/threshold");
        let put = call("PUT", &url, Some("r"), Some(&json!({"p_fa": 0.1}))).await;
        assert_forbidden(&put, "operate", id);
    }
    let (status, whoami) = call("GET", &format!("{base}/api/v1/whoami"), Some("r"), None).await;
    assert_eq!(status, 200);
    assert_eq!(
        whoami,
        json!({"name": "reader", "scopes": ["read"], "sessions": null, "expires_ms": null})
    );
    let (status, _) = call(
        "GET",
        &format!("{base}/api/v1/sessions/c1"),
        Some("r"),
        None,
    )
    .await;
    assert_eq!(status, 200, "the session survived");
    server.shutdown().await;
}

/// Opens a socket; `Err(status)` when the handshake is refused.
async fn try_connect(url: &str) -> Result<Socket, u16> {
    match tokio_tungstenite::connect_async(url).await {
        Ok((socket, _)) => Ok(socket),
        Err(tokio_tungstenite::tungstenite::Error::Http(resp)) => Err(resp.status().as_u16()),
        Err(e) => panic!("{url}: {e}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_session_limited_token_reaches_only_its_sessions() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("tokens.json");
    let mut vehicle = entry("vehicle", "v", &["ingest", "read"]);
    vehicle["sessions"] = json!(["veh-*", "cart-1"]);
    write_tokens(&file, &[vehicle]);
    let server = start_with(dir.path(), Some(DEFAULT), Some(file)).await;
    let base = http(&server);
    for id in ["veh-1", "cart-1", "cart-10", "car-2"] {
        let created = call(
            "POST",
            &format!("{base}/api/v1/sessions"),
            Some(DEFAULT),
            Some(&cart(id)),
        )
        .await;
        assert_eq!(created.0, 201, "{}", created.1);
    }
    let session = |id: &str| format!("{base}/api/v1/sessions/{id}");
    for id in ["veh-1", "cart-1"] {
        assert_eq!(
            call("GET", &session(id), Some("v"), None).await.0,
            200,
            "{id}"
        );
    }
    // Inside the allowance but missing: the handler's 404.
    assert_eq!(
        call("GET", &session("veh-none"), Some("v"), None).await.0,
        404
    );
    // Outside it: 403, whether the session exists or not.
    for id in ["cart-10", "car-2", "nowhere"] {
        let answer = call("GET", &format!("{}/stats", session(id)), Some("v"), None).await;
        assert_forbidden(&answer, "read", id);
        assert_eq!(
            answer.1["error"]["message"],
            format!("token 'vehicle' may not use session '{id}'")
        );
    }
    // The list shows its sessions only; the alarm log wants one of them named.
    let (status, list) = call("GET", &format!("{base}/api/v1/sessions"), Some("v"), None).await;
    assert_eq!(status, 200);
    let ids: Vec<&str> = list["sessions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["id"].as_str().unwrap())
        .collect();
    assert_eq!(ids, ["cart-1", "veh-1"]);
    let alarms = format!("{base}/api/v1/alarms");
    assert_forbidden(
        &call("GET", &alarms, Some("v"), None).await,
        "read",
        "no session",
    );
    let one = call("GET", &format!("{alarms}?session=veh-1"), Some("v"), None).await;
    assert_eq!(one.0, 200, "{}", one.1);
    let other = call(
        "GET",
        &format!("{alarms}?session=veh-1&session=car-2"),
        Some("v"),
        None,
    )
    .await;
    assert_forbidden(&other, "read", "another session");
    // The ingest socket, with the query token: its own session streams, another is refused.
    let ws_url = |id: &str| format!("{}/api/v1/sessions/{id}/ingest?token=v", ws(&server));
    let mut socket = try_connect(&ws_url("veh-1")).await.expect("veh-1 streams");
    assert_eq!(recv(&mut socket).await["type"], "ready");
    assert_eq!(try_connect(&ws_url("car-2")).await.err(), Some(403));
    assert_eq!(try_connect(&ws_url("nowhere")).await.err(), Some(403));
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_expired_token_gets_401_and_one_in_date_passes() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("tokens.json");
    let mut old = entry("old", "o", &["read"]);
    old["expires"] = json!("2001-01-01T00:00:00Z");
    let mut current = entry("current", "c", &["read"]);
    current["expires"] = json!("2999-01-01T00:00:00+02:00");
    write_tokens(&file, &[old, current]);
    let server = start_with(dir.path(), None, Some(file)).await;
    let url = format!("{}/api/v1/whoami", http(&server));
    let (status, body) = call("GET", &url, Some("o"), None).await;
    assert_eq!(
        (status, &body["error"]["code"]),
        (401, &json!("unauthorized"))
    );
    let (status, body) = call("GET", &url, Some("c"), None).await;
    assert_eq!(status, 200);
    assert_eq!(body["expires_ms"], json!(32_472_136_800_000_i64));
    server.shutdown().await;
}

/// Calls `whoami` with `secret` until it answers `status` (the file is looked at once
/// a second), at most 10 s.
async fn eventually(url: &str, secret: &str, status: u16) {
    for _ in 0..100 {
        if call("GET", url, Some(secret), None).await.0 == status {
            return;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    panic!("{secret} never got {status}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_tokens_file_is_read_again_when_it_changes() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("tokens.json");
    write_tokens(&file, &[entry("first", "one", &["read"])]);
    let server = start_with(dir.path(), None, Some(file.clone())).await;
    let url = format!("{}/api/v1/whoami", http(&server));
    assert_eq!(call("GET", &url, Some("one"), None).await.0, 200);
    assert_eq!(call("GET", &url, Some("two"), None).await.0, 401);
    // Rotation: a second token added, then the first revoked.
    write_tokens(
        &file,
        &[
            entry("first", "one", &["read"]),
            entry("second", "two", &["admin"]),
        ],
    );
    eventually(&url, "two", 200).await;
    write_tokens(&file, &[entry("second", "two", &["admin"])]);
    eventually(&url, "one", 401).await;
    // A broken file is refused and the tokens read before stay.
    std::fs::write(&file, "{\"tokens\": [{\"name\": ").unwrap();
    tokio::time::sleep(Duration::from_millis(1200)).await;
    let (status, body) = call("GET", &url, Some("two"), None).await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(body["name"], "second");
    // Fixed again: read again.
    write_tokens(&file, &[entry("third", "three", &["read"])]);
    eventually(&url, "three", 200).await;
    eventually(&url, "two", 401).await;
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_single_token_keeps_every_scope_beside_a_tokens_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("tokens.json");
    write_tokens(&file, &[entry("reader", "r", &["read"])]);
    let server = start_with(dir.path(), Some(DEFAULT), Some(file)).await;
    let base = http(&server);
    let (status, whoami) = call("GET", &format!("{base}/api/v1/whoami"), Some(DEFAULT), None).await;
    assert_eq!(status, 200);
    assert_eq!(whoami["name"], "default");
    assert_eq!(
        whoami["scopes"],
        json!(["ingest", "read", "operate", "admin"])
    );
    let sessions = format!("{base}/api/v1/sessions");
    assert_eq!(
        call("POST", &sessions, Some(DEFAULT), Some(&cart("d1")))
            .await
            .0,
        201
    );
    let threshold = format!("{sessions}/d1/monitors/position/threshold");
    let put = call(
        "PUT",
        &threshold,
        Some(DEFAULT),
        Some(&json!({"p_fa": 0.001})),
    )
    .await;
    assert_eq!(put.0, 200, "{}", put.1);
    let mut socket = try_connect(&format!(
        "{}/api/v1/sessions/d1/ingest?token={DEFAULT}",
        ws(&server)
    ))
    .await
    .expect("ingest with --token");
    assert_eq!(recv(&mut socket).await["type"], "ready");
    drop(socket);
    assert_eq!(
        call("DELETE", &format!("{sessions}/d1"), Some(DEFAULT), None)
            .await
            .0,
        204
    );
    server.shutdown().await;
    // Alone, as before: every scope, and whoami names it.
    let server = start(
        &dir.path().join("alone.db"),
        Some(DEFAULT),
        Default::default(),
    )
    .await;
    let (status, whoami) = call(
        "GET",
        &format!("{}/api/v1/whoami", http(&server)),
        Some(DEFAULT),
        None,
    )
    .await;
    assert_eq!((status, &whoami["name"]), (200, &json!("default")));
    assert_eq!(
        call(
            "GET",
            &format!("{}/api/v1/whoami", http(&server)),
            Some("r"),
            None
        )
        .await
        .0,
        401
    );
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bad_tokens_file_stops_the_start_and_a_file_alone_opens_other_addresses() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("tokens.json");
    std::fs::write(
        &file,
        "{\"tokens\": [{\"name\": \"a\", \"hash\": \"00\", \"scopes\": [\"read\"]}]}",
    )
    .unwrap();
    let mut config = ServiceConfig::new("127.0.0.1:0".parse().unwrap(), dir.path().join("x.db"));
    config.tokens_file = Some(file.clone());
    let err = service::start(config).await.unwrap_err().to_string();
    assert!(err.contains("tokens[0].hash"), "{err}");
    let mut config = ServiceConfig::new("127.0.0.1:0".parse().unwrap(), dir.path().join("x.db"));
    config.tokens_file = Some(dir.path().join("missing.json"));
    assert!(service::start(config).await.is_err());
    // A tokens file counts as a token for a non-loopback address.
    write_tokens(&file, &[entry("a", "a", &["read"])]);
    let mut config = ServiceConfig::new("0.0.0.0:0".parse().unwrap(), dir.path().join("y.db"));
    config.tokens_file = Some(file);
    let server = service::start(config)
        .await
        .expect("starts with a tokens file");
    server.shutdown().await;
}
