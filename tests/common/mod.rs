//! Shared harness for the integration tests: a real server on port 0 with a
//! temporary SQLite file (or, with `NAVGUARD_TEST_POSTGRES` set, a Postgres schema of
//! its own: [`store_for`]), a real WebSocket client, and a seeded Gaussian source.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use navguard::service::{self, Limits, Server, ServiceConfig};
use serde_json::{Value, json};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

/// A client socket.
pub(crate) type Socket = WebSocketStream<MaybeTlsStream<TcpStream>>;

/// The variable naming a Postgres server for the tests: an admin URL such as
/// `postgres://postgres@127.0.0.1:55432/postgres`. Unset: the tests use SQLite files.
pub(crate) const POSTGRES_VAR: &str = "NAVGUARD_TEST_POSTGRES";

/// The store a test server uses for the SQLite path `db`: the path itself, or with
/// [`POSTGRES_VAR`] set, a URL to a Postgres schema named after the path, created here
/// (empty the first time). The same path gives the same schema, so a test that restarts
/// its server on the same path reopens the same store; paths under a fresh temporary
/// folder give every test a store of its own.
pub(crate) async fn store_for(db: &Path) -> PathBuf {
    let Some(admin) = std::env::var(POSTGRES_VAR).ok().filter(|v| !v.is_empty()) else {
        return db.to_path_buf();
    };
    use sqlx::Connection as _;
    use std::hash::{Hash, Hasher};
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    db.hash(&mut hasher);
    let schema = format!("ng_{:016x}", hasher.finish());
    let mut conn = sqlx::PgConnection::connect(&admin)
        .await
        .unwrap_or_else(|e| panic!("{POSTGRES_VAR}={admin}: {e}"));
    sqlx::query(&format!("CREATE SCHEMA IF NOT EXISTS {schema}"))
        .execute(&mut conn)
        .await
        .expect("create the test schema");
    let _ = conn.close().await;
    let sep = if admin.contains('?') { '&' } else { '?' };
    PathBuf::from(format!("{admin}{sep}options=-c%20search_path%3D{schema}"))
}

/// Starts a server on 127.0.0.1:0 with the given store ([`store_for`]), token and limits.
pub(crate) async fn start(db: &Path, token: Option<&str>, limits: Limits) -> Server {
    let mut config = ServiceConfig::new("127.0.0.1:0".parse().unwrap(), store_for(db).await);
    config.token = token.map(str::to_owned);
    config.limits = limits;
    service::start(config).await.expect("server starts")
}

/// A plain HTTP client.
pub(crate) fn client() -> reqwest::Client {
    reqwest::Client::new()
}

/// GETs `url`: the status and the JSON body (`null` when the body is not JSON).
pub(crate) async fn get_json(url: &str) -> (u16, Value) {
    let resp = reqwest::get(url).await.unwrap();
    let status = resp.status().as_u16();
    (status, resp.json().await.unwrap_or(Value::Null))
}

/// GETs `url` and returns its body as text (asserting a 200).
pub(crate) async fn get_text(url: &str) -> String {
    let resp = reqwest::get(url).await.unwrap();
    assert_eq!(resp.status(), 200, "GET {url}");
    resp.text().await.unwrap()
}

/// Seed 004's ship at a 1 Hz INS rate: the same route, sensors, aid rates and faults as
/// the 10 Hz scenario with one prediction per second, which keeps every property the
/// tests assert while a debug build runs it ten times faster.
pub(crate) fn ship_1hz(
    seed: u64,
    faults: Vec<navguard_sim::Fault>,
    duration_s: f64,
) -> navguard_sim::Scenario {
    let truth = navguard_sim::ship_trajectory()
        .unwrap()
        .sample(1.0, duration_s)
        .unwrap();
    let params = navguard_sim::scenario::ScenarioParams {
        ins_rate_hz: 1.0,
        ..navguard_sim::scenario::ship_params(seed, faults)
    };
    navguard_sim::simulate(params, truth).unwrap()
}

/// `http://addr`
pub(crate) fn http(server: &Server) -> String {
    format!("http://{}", server.addr)
}

/// `ws://addr`
pub(crate) fn ws(server: &Server) -> String {
    format!("ws://{}", server.addr)
}

/// Opens a WebSocket.
pub(crate) async fn connect(url: &str) -> Socket {
    tokio_tungstenite::connect_async(url)
        .await
        .expect("socket connects")
        .0
}

/// Receives the next text message as JSON (10 s timeout).
pub(crate) async fn recv(socket: &mut Socket) -> Value {
    loop {
        let msg = tokio::time::timeout(Duration::from_secs(10), socket.next())
            .await
            .expect("a message within 10 s")
            .expect("socket open")
            .expect("no socket error");
        match msg {
            Message::Text(text) => return serde_json::from_str(&text).expect("server sends JSON"),
            Message::Close(frame) => panic!("socket closed: {frame:?}"),
            _ => continue,
        }
    }
}

/// Receives messages until one satisfies `pred`, returning it and everything before.
pub(crate) async fn recv_until(
    socket: &mut Socket,
    pred: impl Fn(&Value) -> bool,
) -> (Value, Vec<Value>) {
    let mut seen = Vec::new();
    loop {
        let v = recv(socket).await;
        if pred(&v) {
            return (v, seen);
        }
        seen.push(v);
    }
}

/// Sends a JSON value as one text frame.
pub(crate) async fn send(socket: &mut Socket, value: &Value) {
    socket
        .send(Message::Text(value.to_string().into()))
        .await
        .expect("send");
}

/// Sends raw text as one frame.
pub(crate) async fn send_text(socket: &mut Socket, text: &str) {
    socket
        .send(Message::Text(text.to_owned().into()))
        .await
        .expect("send");
}

/// Opens the ingest socket of `session` and waits for its `ready` message.
pub(crate) async fn ingest(server: &Server, session: &str) -> Socket {
    let mut socket = connect(&format!("{}/api/v1/sessions/{session}/ingest", ws(server))).await;
    let ready = recv(&mut socket).await;
    assert_eq!(ready["type"], "ready", "{ready}");
    socket
}

/// Opens the ingest socket of `session` again right after the client dropped its
/// previous one. The server notices the old stream's close asynchronously and
/// answers 409 until then, so this retries as a reconnecting client would.
pub(crate) async fn reingest(server: &Server, session: &str) -> Socket {
    let url = format!("{}/api/v1/sessions/{session}/ingest", ws(server));
    for _ in 0..250 {
        if let Ok((mut socket, _)) = tokio_tungstenite::connect_async(&url).await {
            let ready = recv(&mut socket).await;
            assert_eq!(ready["type"], "ready", "{ready}");
            return socket;
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    panic!("the ingest socket of {session} stayed taken for 5 s after its client left");
}

/// SplitMix64 with Box–Muller: a small, seeded, dependency-free Gaussian source.
pub(crate) struct Gauss {
    state: u64,
    spare: Option<f64>,
}

impl Gauss {
    /// A source seeded with `seed`.
    pub(crate) fn new(seed: u64) -> Self {
        Gauss {
            state: seed,
            spare: None,
        }
    }

    fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in (0, 1).
    pub(crate) fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// Standard normal.
    pub(crate) fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        let (u1, u2) = (self.uniform(), self.uniform());
        let r = (-2.0 * u1.ln()).sqrt();
        let theta = 2.0 * std::f64::consts::PI * u2;
        self.spare = Some(r * theta.sin());
        r * theta.cos()
    }
}

/// The 1-D constant-velocity model used across the tests: dt = 1 s, white
/// acceleration density `q`, position measured with standard deviation `sigma`.
pub(crate) struct CvModel {
    pub q: f64,
    pub sigma: f64,
    pub p0: f64,
}

impl CvModel {
    /// Q for dt = 1: q·[[1/3, 1/2], [1/2, 1]].
    pub(crate) fn q_matrix(&self) -> [[f64; 2]; 2] {
        [[self.q / 3.0, self.q / 2.0], [self.q / 2.0, self.q]]
    }

    /// The `linear` monitor config.
    pub(crate) fn config(&self) -> Value {
        let q = self.q_matrix();
        json!({
            "f": [[1.0, 1.0], [0.0, 1.0]],
            "h": [[1.0, 0.0]],
            "q": [[q[0][0], q[0][1]], [q[1][0], q[1][1]]],
            "r": [[self.sigma * self.sigma]],
            "x0": [0.0, 0.0],
            "p0": [[self.p0, 0.0], [0.0, self.p0]]
        })
    }

    /// Measurements z_k from a truth drawn from the model itself (x0 ~ N(0, P0),
    /// w ~ N(0, Q)), with `step(k)` added to measurement k.
    pub(crate) fn measurements(
        &self,
        n: usize,
        seed: u64,
        step: impl Fn(usize) -> f64,
    ) -> Vec<f64> {
        let mut g = Gauss::new(seed);
        let mut x = [self.p0.sqrt() * g.normal(), self.p0.sqrt() * g.normal()];
        // Cholesky of Q = q[[1/3,1/2],[1/2,1]].
        let l00 = (self.q / 3.0).sqrt();
        let l10 = (self.q / 2.0) / l00;
        let l11 = (self.q - l10 * l10).sqrt();
        (0..n)
            .map(|k| {
                let (w0, w1) = (g.normal(), g.normal());
                x = [x[0] + x[1] + l00 * w0, x[1] + l10 * w0 + l11 * w1];
                x[0] + self.sigma * g.normal() + step(k)
            })
            .collect()
    }
}

/// A session body with one `linear` monitor named `cv`.
pub(crate) fn cv_session(
    id: &str,
    model: &CvModel,
    policy: Value,
    threshold: Value,
    echo: bool,
) -> Value {
    let mut monitor =
        json!({"name": "cv", "type": "linear", "config": model.config(), "policy": policy});
    for (k, v) in threshold.as_object().expect("threshold object") {
        monitor[k] = v.clone();
    }
    json!({"id": id, "echo": echo, "monitors": [monitor]})
}

/// POSTs a session and asserts 201.
pub(crate) async fn create_session(
    client: &reqwest::Client,
    server: &Server,
    body: &Value,
) -> Value {
    let resp = client
        .post(format!("{}/api/v1/sessions", http(server)))
        .json(body)
        .send()
        .await
        .unwrap();
    let status = resp.status();
    let text = resp.text().await.unwrap();
    assert_eq!(status, 201, "{text}");
    serde_json::from_str(&text).unwrap()
}

/// Epoch frames for measurements starting at time index `from`.
pub(crate) fn epochs(z: &[f64], from: usize) -> Vec<Value> {
    z.iter()
        .enumerate()
        .map(|(i, z)| json!({"t": (from + i) as f64, "z": [z]}))
        .collect()
}

/// `/api/v1/sessions/{id}` → `/api/v1/sessions/x`.
pub(crate) fn concrete(template: &str, value: &str) -> String {
    let mut out = String::new();
    let mut in_param = false;
    for c in template.chars() {
        match c {
            '{' => {
                in_param = true;
                out.push_str(value);
            }
            '}' => in_param = false,
            _ if in_param => {}
            _ => out.push(c),
        }
    }
    out
}

/// The README's cart, with `p_fa` 1e-5.
pub(crate) fn cart(id: &str) -> Value {
    json!({"id": id, "monitors": [{
        "name": "position", "type": "linear",
        "config": {"f": [[1, 1], [0, 1]], "h": [[1, 0]], "q": [[0.0033, 0.005], [0.005, 0.01]],
                   "r": [[1]], "x0": [0, 1], "p0": [[10, 0], [0, 10]]},
        "policy": {"kind": "classic"}, "p_fa": 0.00001}]})
}
