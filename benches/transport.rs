//! Criterion bench: how close one navguard session comes to the bare WebSocket transport,
//! at 1, 10, 100 and 1000 epochs per frame, both measured in the same run on the same
//! frames (the simulated ship of seed 004 as `loadgen` sends it, 10 Hz INS with GNSS, DVL
//! and CNS). An iteration is one frame sent and answered; throughput is in epochs.
//!
//! - `transport/ceiling/batch_N`: a bare axum WebSocket route that only parses each frame
//!   with serde into a minimal typed epoch (the blocks' numbers, no validation) and
//!   acknowledges the frame with one short message.
//! - `transport/navguard/batch_N`: navguard's ingest socket, one session running the
//!   `federated` monitor (counters policy), `echo: true`: every epoch parsed, validated,
//!   stepped, recorded and answered with its `result` frame.
//!
//! The ratio navguard / ceiling of the two `thrpt` figures at the same batch is the share
//! of the transport's ceiling that the service reaches (docs/performance.md). Frames are
//! pipelined: the client keeps sending while a reader counts answers. The scenario is
//! replayed in passes on a fresh socket (a new stream restarts filter time); reconnecting
//! is not timed.
//!
//! Run: `cargo bench --bench transport`

// criterion_group! defines a public function it cannot document.
#![allow(missing_docs)]

use std::time::{Duration, Instant};

use axum::Router;
use axum::extract::ws::{Message as AxumMessage, WebSocket, WebSocketUpgrade};
use axum::routing::get;
use axum::serve::ListenerExt;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use futures_util::{SinkExt, StreamExt};
use navguard::service::wire::epoch_to_wire;
use navguard_core::detect::PolicyConfig;
use navguard_core::monitor::MonitorKind;
use navguard_sim as sim;
use serde::Deserialize;
use tokio::net::TcpStream;
use tokio::runtime::Runtime;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

mod common;

type Socket = WebSocketStream<MaybeTlsStream<TcpStream>>;

/// Epochs per pass: 2,000 s of the ship at 10 Hz.
const PASS_EPOCHS: usize = 20_000;
const BATCHES: [usize; 4] = [1, 10, 100, 1000];

/// What the ceiling parses an epoch into: its numbers, nothing checked.
#[derive(Deserialize)]
#[allow(dead_code)] // parsed to be dropped: the fields are the cost being measured
struct BareEpoch {
    t: f64,
    ins: Option<BareIns>,
    gnss: Option<BareGnss>,
    dvl: Option<BareDvl>,
    cns: Option<BareCns>,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct BareIns {
    lat: f64,
    lon: f64,
    h: f64,
    vel: [f64; 3],
    att: [f64; 3],
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct BareGnss {
    lat: f64,
    lon: f64,
    h: f64,
    vel: Option<[f64; 3]>,
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct BareDvl {
    vel_b: [f64; 3],
}

#[derive(Deserialize)]
#[allow(dead_code)]
struct BareCns {
    lat: f64,
    lon: f64,
}

/// Epochs in a frame (one object or an array), 0 if it does not parse.
fn bare_parse(text: &str) -> usize {
    let parsed = if text.trim_start().starts_with('[') {
        serde_json::from_str::<Vec<BareEpoch>>(text).map(|e| e.len())
    } else {
        serde_json::from_str::<BareEpoch>(text).map(|_| 1)
    };
    parsed.unwrap_or(0)
}

/// The ceiling: parse with serde, acknowledge the frame.
async fn ceiling_socket(mut socket: WebSocket) {
    while let Some(Ok(message)) = socket.recv().await {
        let AxumMessage::Text(text) = message else {
            continue;
        };
        let epochs = bare_parse(&text);
        let ack = format!(r#"{{"type":"ack","epochs":{epochs}}}"#);
        if socket.send(AxumMessage::Text(ack.into())).await.is_err() {
            return;
        }
    }
}

/// A server under test: where to connect, and which text messages answer a frame.
struct Target {
    url: String,
    /// How many epochs one answer stands for (`None`: not an answer).
    answer: fn(&str) -> Option<usize>,
}

fn ceiling_answer(text: &str) -> Option<usize> {
    let rest = text.strip_prefix(r#"{"type":"ack","epochs":"#)?;
    rest.trim_end_matches('}').parse().ok()
}

fn navguard_answer(text: &str) -> Option<usize> {
    text.starts_with(r#"{"type":"result""#).then_some(1)
}

async fn connect(target: &Target) -> Socket {
    let (mut socket, _) = tokio_tungstenite::connect_async(target.url.as_str())
        .await
        .expect("connect");
    if target.url.ends_with("/ingest") {
        // navguard greets a stream with `ready` before it takes frames.
        let ready = socket.next().await.expect("ready").expect("ready message");
        assert!(
            ready.to_text().expect("text").contains("ready"),
            "{ready:?}"
        );
    }
    socket
}

async fn close(socket: Socket) {
    let (mut sink, mut stream) = socket.split();
    let _ = sink.close().await;
    while let Some(Ok(_)) = stream.next().await {}
}

/// Sends `frames` (each of `batch` epochs) pipelined and waits for every epoch's answer.
async fn send_and_count(
    socket: Socket,
    target: &Target,
    frames: &[String],
    batch: usize,
) -> Socket {
    let (mut sink, mut stream) = socket.split();
    let expected = frames.len() * batch;
    let reader = async {
        let mut answered = 0;
        while answered < expected {
            match stream.next().await {
                Some(Ok(Message::Text(text))) => {
                    if text.contains(r#""type":"error""#) {
                        panic!("the server refused a frame: {text}");
                    }
                    answered += (target.answer)(&text).unwrap_or(0);
                }
                Some(Ok(_)) => {}
                other => panic!("socket ended: {other:?}"),
            }
        }
    };
    let writer = async {
        for frame in frames {
            sink.feed(Message::Text(frame.clone().into()))
                .await
                .expect("send");
        }
        sink.flush().await.expect("flush");
    };
    tokio::join!(reader, writer);
    sink.reunite(stream).expect("same socket")
}

fn bench_target(
    c: &mut Criterion,
    runtime: &Runtime,
    name: &str,
    target: &Target,
    lines: &[String],
) {
    let mut group = c.benchmark_group("transport");
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(2));
    group.measurement_time(Duration::from_secs(5));
    for batch in BATCHES {
        let frames: Vec<String> = lines
            .chunks(batch)
            .map(|c| {
                if batch == 1 {
                    c[0].clone()
                } else {
                    format!("[{}]", c.join(","))
                }
            })
            .collect();
        let mut socket = Some(runtime.block_on(connect(target)));
        let mut next = 0;
        group.throughput(Throughput::Elements(batch as u64));
        group.bench_function(format!("{name}/batch_{batch}"), |b| {
            b.iter_custom(|iters| {
                let mut left = iters as usize;
                let mut timed = Duration::ZERO;
                while left > 0 {
                    if next == frames.len() {
                        let old = socket.take().expect("socket");
                        socket = Some(runtime.block_on(async {
                            close(old).await;
                            connect(target).await
                        }));
                        next = 0;
                    }
                    let n = left.min(frames.len() - next);
                    let chunk = &frames[next..next + n];
                    let open = socket.take().expect("socket");
                    let start = Instant::now();
                    socket = Some(runtime.block_on(send_and_count(open, target, chunk, batch)));
                    timed += start.elapsed();
                    next += n;
                    left -= n;
                }
                timed
            })
        });
        runtime.block_on(close(socket.take().expect("socket")));
    }
    group.finish();
}

fn bench(c: &mut Criterion) {
    let runtime = common::runtime();
    let duration = (PASS_EPOCHS - 1) as f64 / sim::SHIP_INS_RATE_HZ;
    let scenario = sim::ship_with(4, Vec::new(), duration).expect("ship scenario");
    let lines: Vec<String> = scenario
        .epochs
        .iter()
        .map(|e| epoch_to_wire(&e.epoch).expect("wire line"))
        .collect();
    assert_eq!(lines.len(), PASS_EPOCHS);
    assert_eq!(bare_parse(&format!("[{}]", lines[..10].join(","))), 10);

    // The ceiling server.
    let listener = runtime
        .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
        .expect("bind");
    let ceiling_addr = listener.local_addr().expect("address");
    // TCP_NODELAY on accepted sockets, as navguard's own server sets it.
    let listener = listener.tap_io(|tcp| {
        let _ = tcp.set_nodelay(true);
    });
    let app = Router::new().route(
        "/ws",
        get(|ws: WebSocketUpgrade| async move { ws.on_upgrade(ceiling_socket) }),
    );
    runtime.spawn(async move { axum::serve(listener, app).await });
    let ceiling = Target {
        url: format!("ws://{ceiling_addr}/ws"),
        answer: ceiling_answer,
    };

    // navguard, with one federated session on the same ship.
    let (server, _dir) = common::server_with_echo_session(
        &runtime,
        "federated",
        MonitorKind::Federated,
        serde_json::to_value(scenario.monitor_config()).expect("config"),
        PolicyConfig::Counters { n1: 10, n2: 5 },
    );
    let addr = server.addr;
    let navguard = Target {
        url: format!("ws://{addr}/api/v1/sessions/bench/ingest"),
        answer: navguard_answer,
    };

    bench_target(c, &runtime, "ceiling", &ceiling, &lines);
    bench_target(c, &runtime, "navguard", &navguard, &lines);
    runtime.block_on(server.shutdown());
}

criterion_group!(benches, bench);
criterion_main!(benches);
