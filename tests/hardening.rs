//! The service edge under hostile-but-fair clients: slow and silent
//! connections, the connection limit, stalled bodies, tokens in query strings
//! and logs, blank tokens, messages over the socket cap, and the closing
//! handshake of both sockets.
//! Real server on port 0, raw TCP where a well-behaved client library would
//! not misbehave on purpose.

mod common;

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use common::*;
use futures_util::{SinkExt, StreamExt};
use navguard::service::{self, Limits, ServiceConfig, StartError};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::protocol::CloseFrame;
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;

/// How long any one wait in these tests may last before it counts as "never".
const PATIENCE: Duration = Duration::from_secs(15);

fn edge_limits(max_connections: usize, timeout_ms: u64) -> Limits {
    Limits {
        max_connections,
        header_timeout: Duration::from_millis(timeout_ms),
        idle_timeout: Duration::from_millis(timeout_ms),
        ..Limits::default()
    }
}

/// One request on a fresh connection (`Connection: close`): status and body,
/// or `None` if the server closed without an answer.
async fn raw_request(addr: SocketAddr, head: &str) -> Option<(u16, String)> {
    let mut stream = TcpStream::connect(addr).await.ok()?;
    stream.write_all(head.as_bytes()).await.ok()?;
    let mut answer = Vec::new();
    tokio::time::timeout(PATIENCE, stream.read_to_end(&mut answer))
        .await
        .expect("the server answers or closes")
        .ok()?;
    let text = String::from_utf8_lossy(&answer).into_owned();
    let status = text.split(' ').nth(1)?.parse().ok()?;
    let body = text.split_once("\r\n\r\n").map(|(_, b)| b.to_owned())?;
    Some((status, body))
}

async fn raw_get(addr: SocketAddr, path: &str) -> Option<(u16, String)> {
    raw_request(
        addr,
        &format!("GET {path} HTTP/1.1\r\nhost: navguard\r\nconnection: close\r\n\r\n"),
    )
    .await
}

/// Polls `GET /healthz` on fresh connections until it answers `want`.
async fn healthz_until(addr: SocketAddr, want: u16) -> String {
    let deadline = tokio::time::Instant::now() + PATIENCE;
    loop {
        if let Some((status, body)) = raw_get(addr, "/healthz").await
            && status == want
        {
            return body;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "/healthz never answered {want}"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// A slowloris client: sends a request head one byte every 20 ms and never
/// finishes it (`trickle`), or sends nothing at all. Returns once the server
/// has closed the connection; panics if it is still open after `PATIENCE`.
async fn slow_client(addr: SocketAddr, trickle: bool) {
    let mut stream = TcpStream::connect(addr).await.unwrap();
    let head = b"GET /healthz HTTP/1.1\r\nhost: navguard\r\nx-slow: ";
    let mut sent = 0usize;
    let mut buf = [0u8; 256];
    let closed = tokio::time::timeout(PATIENCE, async {
        loop {
            tokio::select! {
                read = stream.read(&mut buf) => match read {
                    Ok(0) | Err(_) => return,
                    Ok(_) => {} // whatever it says, the server must still close
                },
                _ = tokio::time::sleep(Duration::from_millis(20)), if trickle => {
                    let byte = head.get(sent).copied().unwrap_or(b'a');
                    if stream.write_all(&[byte]).await.is_err() {
                        return;
                    }
                    sent += 1;
                }
            }
        }
    })
    .await;
    assert!(
        closed.is_ok(),
        "a {} connection was still open after {PATIENCE:?}",
        if trickle { "trickling" } else { "silent" }
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn slow_and_silent_connections_are_closed_while_healthz_answers() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("s.db"), None, edge_limits(1000, 300)).await;
    let addr = server.addr;
    let attackers: Vec<_> = (0..200)
        .map(|i| tokio::spawn(slow_client(addr, i % 2 == 0)))
        .collect();
    // While 200 connections dawdle, a normal client is served at once.
    tokio::time::sleep(Duration::from_millis(100)).await;
    let (status, body) = raw_get(addr, "/healthz").await.expect("healthz answers");
    assert_eq!(status, 200, "{body}");
    for attacker in attackers {
        attacker
            .await
            .expect("every slow connection is closed by the server");
    }
    assert_eq!(raw_get(addr, "/healthz").await.unwrap().0, 200);
    server.shutdown().await;
}

/// Opens silent connections until the server refuses one: the ones returned
/// hold every slot (no other client runs meanwhile, so none is stolen).
async fn fill_the_limit(addr: SocketAddr) -> Vec<TcpStream> {
    let mut held = Vec::new();
    loop {
        let mut stream = TcpStream::connect(addr).await.unwrap();
        let mut buf = [0u8; 512];
        match tokio::time::timeout(Duration::from_millis(200), stream.read(&mut buf)).await {
            // Accepted and waiting for a request head.
            Err(_) => held.push(stream),
            Ok(Ok(n)) if n > 0 => {
                let text = String::from_utf8_lossy(&buf[..n]);
                assert!(text.starts_with("HTTP/1.1 503 "), "{text}");
                return held;
            }
            Ok(other) => panic!("a connection inside the limit was closed: {other:?}"),
        }
        assert!(held.len() < 100, "the server never refused a connection");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn connections_over_the_limit_get_a_json_503_and_websockets_hold_their_slot() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("l.db"), None, edge_limits(4, 3000)).await;
    let addr = server.addr;
    // Four silent connections fill the limit: one more is refused in JSON.
    let silent = fill_the_limit(addr).await;
    assert_eq!(silent.len(), 4);
    let (status, body) = raw_get(addr, "/healthz").await.unwrap();
    assert_eq!(status, 503, "{body}");
    let error: Value = serde_json::from_str(&body).expect("a JSON body");
    assert_eq!(error["error"]["code"], "too_many_connections", "{error}");
    assert!(error["error"]["message"].as_str().unwrap().contains('4'));
    // The header timeout closes them and frees their slots.
    for mut stream in silent {
        let mut buf = [0u8; 64];
        let read = tokio::time::timeout(PATIENCE, stream.read(&mut buf)).await;
        assert!(matches!(read, Ok(Ok(0) | Err(_))), "{read:?}");
    }
    healthz_until(addr, 200).await;

    // An upgraded socket keeps its slot for as long as it is open.
    let body = cv_session("lim", &MODEL, json!({"kind": "classic"}), json!({}), false).to_string();
    let (status, answer) = raw_request(
        addr,
        &format!(
            "POST /api/v1/sessions HTTP/1.1\r\nhost: navguard\r\ncontent-type: application/json\r\n\
             content-length: {}\r\nconnection: close\r\n\r\n{body}",
            body.len()
        ),
    )
    .await
    .unwrap();
    assert_eq!(status, 201, "{answer}");
    let url = format!("{}/api/v1/sessions/lim/events", ws(&server));
    let mut sockets = Vec::new();
    for _ in 0..4 {
        let mut socket = connect(&url).await;
        assert_eq!(recv(&mut socket).await["type"], "stats");
        sockets.push(socket);
    }
    assert_eq!(raw_get(addr, "/healthz").await.unwrap().0, 503);
    drop(sockets.pop());
    healthz_until(addr, 200).await;
    for socket in &mut sockets {
        socket.send(Message::Ping(vec![1].into())).await.unwrap();
        loop {
            match tokio::time::timeout(PATIENCE, socket.next()).await {
                Ok(Some(Ok(Message::Pong(_)))) => break,
                Ok(Some(Ok(_))) => continue,
                other => panic!("a socket inside the limit stays open: {other:?}"),
            }
        }
    }
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stalled_request_body_is_cut_off_after_the_idle_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("b.db"), None, edge_limits(1000, 300)).await;
    // Ten bytes of a hundred, then nothing.
    let answer = raw_request(
        server.addr,
        "POST /api/v1/sessions HTTP/1.1\r\nhost: navguard\r\ncontent-type: application/json\r\n\
         content-length: 100\r\n\r\n{\"monitors",
    )
    .await;
    if let Some((status, body)) = answer {
        assert_eq!(status, 400, "{body}");
        let error: Value = serde_json::from_str(&body).unwrap();
        assert_eq!(error["error"]["code"], "bad_request");
    }
    assert_eq!(raw_get(server.addr, "/healthz").await.unwrap().0, 200);
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_still_closes_sockets_with_1001() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("g.db"), None, Limits::default()).await;
    create_session(
        &reqwest::Client::new(),
        &server,
        &cv_session("bye", &MODEL, json!({"kind": "classic"}), json!({}), false),
    )
    .await;
    let mut events = connect(&format!("{}/api/v1/sessions/bye/events", ws(&server))).await;
    assert_eq!(recv(&mut events).await["type"], "stats");
    let mut ingest = ingest(&server, "bye").await;
    let silent = tokio::spawn(slow_client(server.addr, false));
    tokio::time::sleep(Duration::from_millis(50)).await;
    server.shutdown().await;
    for socket in [&mut events, &mut ingest] {
        assert_eq!(close_code(socket).await, Some(CloseCode::Away));
    }
    silent.await.unwrap();
}

/// Reads until the server's close frame; its code, or `None` if the
/// connection ended without one.
async fn close_code(socket: &mut Socket) -> Option<CloseCode> {
    loop {
        match tokio::time::timeout(PATIENCE, socket.next())
            .await
            .expect("the server closes the socket")
        {
            Some(Ok(Message::Close(frame))) => return frame.map(|f| f.code),
            Some(Ok(_)) => continue,
            Some(Err(_)) | None => return None,
        }
    }
}

/// Closes with `code` as a client does when it is done, then reads until the connection
/// ends: the code of the server's answering Close frame (`None`: the connection ended
/// without one, what a client reports as 1006), and whether the connection then ended
/// cleanly rather than with an error.
async fn close_and_read_answer(socket: &mut Socket, code: CloseCode) -> (Option<CloseCode>, bool) {
    let frame = CloseFrame {
        code,
        reason: "done".into(),
    };
    socket
        .close(Some(frame))
        .await
        .expect("the client's Close frame is sent");
    let mut answer = None;
    loop {
        match tokio::time::timeout(PATIENCE, socket.next())
            .await
            .expect("the server ends the connection")
        {
            Some(Ok(Message::Close(frame))) => answer = frame.map(|f| f.code),
            Some(Ok(_)) => continue,
            Some(Err(_)) => return (answer, false),
            None => return (answer, true),
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_close_is_answered_with_its_code_on_both_sockets() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("c.db"), None, Limits::default()).await;
    create_session(
        &reqwest::Client::new(),
        &server,
        &cv_session("done", &MODEL, json!({"kind": "classic"}), json!({}), true),
    )
    .await;
    let mut events = connect(&format!("{}/api/v1/sessions/done/events", ws(&server))).await;
    assert_eq!(recv(&mut events).await["type"], "stats");
    let mut socket = ingest(&server, "done").await;
    send(&mut socket, &json!({"t": 0.0, "z": [0.5]})).await;
    let (result, _) = recv_until(&mut socket, |v| v["type"] == "result").await;
    assert_eq!(result["t"], 0.0);
    // RFC 6455 §5.5.1: the endpoint that receives a Close answers with a Close, usually
    // echoing the code, and then the connection ends.
    assert_eq!(
        close_and_read_answer(&mut socket, CloseCode::Normal).await,
        (Some(CloseCode::Normal), true),
        "ingest socket"
    );
    assert_eq!(
        close_and_read_answer(&mut events, CloseCode::Normal).await,
        (Some(CloseCode::Normal), true),
        "events socket"
    );
    // Another code is echoed as it came, and the stream's slot is free again.
    let mut socket = reingest(&server, "done").await;
    assert_eq!(
        close_and_read_answer(&mut socket, CloseCode::Away).await,
        (Some(CloseCode::Away), true)
    );
    let _ = reingest(&server, "done").await;
    server.shutdown().await;
}

// ------------------------------------------------------------ tokens

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_query_token_opens_only_real_handshakes_of_the_socket_routes() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(&dir.path().join("t.db"), Some("s3cret"), Limits::default()).await;
    let base = http(&server);
    let c = reqwest::Client::new();
    let resp = c
        .post(format!("{base}/api/v1/sessions"))
        .bearer_auth("s3cret")
        .json(&cv_session(
            "tok",
            &MODEL,
            json!({"kind": "classic"}),
            json!({}),
            false,
        ))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 201);
    // REST routes with the socket credentials and upgrade headers: 401.
    let handshake = "upgrade: websocket\r\nconnection: Upgrade\r\nsec-websocket-version: 13\r\n\
                     sec-websocket-key: dGhlIHNhbXBsZSBub25jZQ==\r\n";
    for (method, target, extra) in [
        ("DELETE", "/api/v1/sessions/tok?token=s3cret", ""),
        ("GET", "/api/v1/sessions?token=s3cret", ""),
        ("GET", "/api/v1/sessions/tok/stats?token=s3cret", ""),
        (
            "GET",
            "/api/v1/sessions",
            "sec-websocket-protocol: navguard, bearer.s3cret\r\n",
        ),
        // A socket route, but not a handshake: no upgrade headers, or not GET.
        ("GET", "/api/v1/sessions/tok/events?token=s3cret", "-"),
        ("POST", "/api/v1/sessions/tok/events?token=s3cret", ""),
    ] {
        let upgrade = if extra == "-" { "" } else { handshake };
        let extra = if extra == "-" { "" } else { extra };
        let head = format!(
            "{method} {target} HTTP/1.1\r\nhost: navguard\r\n{upgrade}{extra}\
             content-length: 0\r\nconnection: close\r\n\r\n"
        );
        let (status, body) = raw_request(server.addr, &head).await.unwrap();
        assert_eq!(status, 401, "{method} {target} {extra}: {body}");
    }
    let resp = c
        .get(format!("{base}/api/v1/sessions/tok"))
        .bearer_auth("s3cret")
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 200, "the session survived");
    // Real handshakes still take the query token and the subprotocol.
    let url = format!("{}/api/v1/sessions/tok/events", ws(&server));
    let mut socket = connect(&format!("{url}?token=s3cret")).await;
    assert_eq!(recv(&mut socket).await["type"], "stats");
    let mut socket = connect(&format!(
        "{}/api/v1/sessions/tok/ingest?x=1&token=s3cret",
        ws(&server)
    ))
    .await;
    assert_eq!(recv(&mut socket).await["type"], "ready");
    server.shutdown().await;
}

/// The real binary at `RUST_LOG=debug` with a token, its stdout and stderr
/// (where the log goes) collected by reader threads.
struct LoggingServer {
    child: std::process::Child,
    addr: SocketAddr,
    output: Arc<Mutex<String>>,
}

impl LoggingServer {
    fn start(db: &std::path::Path, token: &str, tokens_file: &std::path::Path) -> Self {
        use std::io::BufRead;
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_navguard"))
            .args(["--bind", "127.0.0.1:0", "--token", token, "--db"])
            .arg(db)
            .arg("--tokens-file")
            .arg(tokens_file)
            .env("RUST_LOG", "debug")
            .env("NO_COLOR", "1")
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let output = Arc::new(Mutex::new(String::new()));
        let (tx, rx) = std::sync::mpsc::channel();
        let stdout = child.stdout.take().unwrap();
        let stderr = child.stderr.take().unwrap();
        for (pipe, tx) in [
            (Box::new(stdout) as Box<dyn std::io::Read + Send>, Some(tx)),
            (Box::new(stderr), None),
        ] {
            let output = output.clone();
            std::thread::spawn(move || {
                for line in std::io::BufReader::new(pipe).lines() {
                    let Ok(line) = line else { break };
                    if let Some(tx) = &tx
                        && let Some(rest) = line.strip_prefix("navguard listening on http://")
                    {
                        let _ = tx.send(rest.split(' ').next().unwrap_or_default().to_owned());
                    }
                    output.lock().unwrap().push_str(&(line + "\n"));
                }
            });
        }
        let addr = rx
            .recv_timeout(PATIENCE)
            .expect("the server says where it listens")
            .parse()
            .unwrap();
        LoggingServer {
            child,
            addr,
            output,
        }
    }

    /// The output so far.
    fn text(&self) -> String {
        self.output.lock().unwrap().clone()
    }

    fn stop(mut self) -> String {
        let _ = self.child.kill();
        let _ = self.child.wait();
        // The reader threads end with the pipes; give them the last lines.
        std::thread::sleep(Duration::from_millis(100));
        self.output.lock().unwrap().clone()
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_token_never_reaches_the_debug_log() {
    let dir = tempfile::tempdir().unwrap();
    let token = "tok-9f8e7d6c";
    // A token of the tokens file, which may read but not create.
    let file_secret = "file-5b4a3c2d";
    let tokens = dir.path().join("tokens.json");
    let hash =
        navguard::service::tokens::to_hex(&navguard::service::tokens::hash_secret(file_secret));
    let entry = json!({"name": "reader", "hash": hash, "scopes": ["read"]});
    std::fs::write(&tokens, json!({"tokens": [entry]}).to_string()).unwrap();
    let server = LoggingServer::start(&dir.path().join("d.db"), token, &tokens);
    let base = format!("http://{}", server.addr);
    let c = reqwest::Client::new();
    let resp = c
        .post(format!("{base}/api/v1/sessions"))
        .bearer_auth(token)
        .json(&cv_session(
            "log",
            &MODEL,
            json!({"kind": "classic"}),
            json!({}),
            false,
        ))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 201);
    let url = format!(
        "ws://{}/api/v1/sessions/log/events?token={token}",
        server.addr
    );
    let mut socket = connect(&url).await;
    assert_eq!(recv(&mut socket).await["type"], "stats");
    drop(socket);
    // Refused requests are logged too.
    let resp = c
        .get(format!("{base}/api/v1/alarms?limit=2&token={token}"))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 401);
    assert_eq!(
        raw_get(server.addr, &format!("/api/v1/nowhere?token={token}"))
            .await
            .unwrap()
            .0,
        404
    );
    // The file's token: allowed, refused for its scope, on a socket, and unknown after a
    // SIGHUP has read the file again without it.
    let resp = c
        .get(format!("{base}/api/v1/whoami"))
        .bearer_auth(file_secret)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 200);
    let resp = c
        .delete(format!("{base}/api/v1/sessions/log"))
        .bearer_auth(file_secret)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 403);
    let url = format!(
        "ws://{}/api/v1/sessions/log/events?token={file_secret}",
        server.addr
    );
    let mut socket = connect(&url).await;
    assert_eq!(recv(&mut socket).await["type"], "stats");
    drop(socket);
    std::fs::write(&tokens, json!({"tokens": []}).to_string()).unwrap();
    let hup = std::process::Command::new("kill")
        .args(["-HUP", &server.child.id().to_string()])
        .status()
        .unwrap();
    assert!(hup.success());
    let deadline = std::time::Instant::now() + PATIENCE;
    while !server.text().contains("tokens file read") {
        assert!(
            std::time::Instant::now() < deadline,
            "SIGHUP read the file: {}",
            server.text()
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let resp = c
        .get(format!("{base}/api/v1/whoami?token={file_secret}"))
        .bearer_auth(file_secret)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 401, "revoked by the SIGHUP");
    let text = server.stop();
    assert!(
        text.contains("uri=/api/v1/sessions/log/events?token=REDACTED"),
        "the request span names the socket route: {text}"
    );
    assert!(
        text.contains("uri=/api/v1/alarms?limit=2&token=REDACTED"),
        "{text}"
    );
    assert!(
        !text.contains(token),
        "the token leaked into the log: {text}"
    );
    assert!(
        !text.contains(file_secret) && !text.contains(&hash),
        "a file token or its hash leaked into the log: {text}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn blank_or_padded_tokens_are_refused_at_start() {
    let dir = tempfile::tempdir().unwrap();
    for (bind, token) in [
        ("127.0.0.1:0", ""),
        ("127.0.0.1:0", "   "),
        ("0.0.0.0:0", " \t "),
        ("127.0.0.1:0", " s3cret"),
    ] {
        let mut config = ServiceConfig::new(bind.parse().unwrap(), dir.path().join("x.db"));
        config.token = Some(token.to_owned());
        let err = service::start(config).await.unwrap_err();
        assert!(matches!(err, StartError::BadToken(_)), "{token:?}: {err}");
        assert!(err.to_string().contains("--token"), "{err}");
    }
    // The binary says so, from the flag and from the environment alike.
    for (args, env) in [
        (vec!["--token", "  "], None),
        (vec!["--token", ""], None),
        (vec![], Some("\t")),
    ] {
        let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_navguard"));
        cmd.args(["--bind", "127.0.0.1:0", "--db"])
            .arg(dir.path().join("bin.db"))
            .args(&args)
            .env_remove("NAVGUARD_TOKEN");
        if let Some(value) = env {
            cmd.env("NAVGUARD_TOKEN", value);
        }
        let out = cmd.output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} {env:?} started");
        assert!(stderr.contains("blank"), "{args:?} {env:?}: {stderr}");
    }
}

// ------------------------------------------------------------ frames

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn messages_over_the_hard_cap_get_close_1009() {
    let dir = tempfile::tempdir().unwrap();
    let limits = Limits {
        max_frame_bytes: 1024,
        ..Limits::default()
    };
    let server = start(&dir.path().join("f.db"), None, limits).await;
    create_session(
        &reqwest::Client::new(),
        &server,
        &cv_session("cap", &MODEL, json!({"kind": "classic"}), json!({}), true),
    )
    .await;
    let mut socket = ingest(&server, "cap").await;
    // Between the limit and 16 × the limit: an error event, and the socket stays.
    send_text(
        &mut socket,
        &format!("[{}]", vec!["{\"t\":0}"; 1000].join(",")),
    )
    .await;
    let (error, _) = recv_until(&mut socket, |v| v["type"] == "error").await;
    assert_eq!(error["code"], "frame_too_large");
    // Beyond 16 × 1024 bytes: close 1009 before the connection goes.
    send_text(&mut socket, &"x".repeat(16 * 1024 + 1)).await;
    assert_eq!(close_code(&mut socket).await, Some(CloseCode::Size));
    // The session takes a new stream.
    let mut socket = reingest(&server, "cap").await;
    send(&mut socket, &json!({"t": 1.0, "z": [0.5]})).await;
    let (result, _) = recv_until(&mut socket, |v| v["type"] == "result").await;
    assert_eq!(result["t"], 1.0);
    // Observers have nothing to say: a large message closes theirs with 1009 too.
    let mut events = connect(&format!("{}/api/v1/sessions/cap/events", ws(&server))).await;
    send_text(&mut events, &"y".repeat(100 << 10)).await;
    assert_eq!(close_code(&mut events).await, Some(CloseCode::Size));
    server.shutdown().await;
}

/// The linear model of the other integration tests.
const MODEL: CvModel = CvModel {
    q: 0.01,
    sigma: 1.0,
    p0: 10.0,
};
