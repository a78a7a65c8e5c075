//! Criterion bench: WebSocket ingest end to end for one session running the
//! `linear` monitor (4 states, 2 measurements), batches of 100 epochs per frame,
//! `echo: true`; an iteration is one batch sent and its 100 results received.
//! Frames are pipelined: the client keeps sending while a reader counts results.
//!
//! Run: `cargo bench --bench ingest`

// criterion_group! defines a public function it cannot document.
#![allow(missing_docs)]

use std::time::{Duration, Instant};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use futures_util::{SinkExt, StreamExt};
use navguard_core::detect::PolicyConfig;
use navguard_core::monitor::MonitorKind;
use navguard_core::monitor::linear::LinearConfigWire;
use serde_json::json;

mod common;
use tokio_tungstenite::tungstenite::Message;

const BATCH: usize = 100;

/// The benched model: 2-D constant velocity, 1 s steps, seeing x and y with
/// correlated noise; typed, so a renamed config field fails to compile.
fn model() -> LinearConfigWire {
    let q = 0.05;
    let (a, b) = (q / 3.0, q / 2.0);
    LinearConfigWire {
        f: vec![
            vec![1.0, 1.0, 0.0, 0.0],
            vec![0.0, 1.0, 0.0, 0.0],
            vec![0.0, 0.0, 1.0, 1.0],
            vec![0.0, 0.0, 0.0, 1.0],
        ],
        h: vec![vec![1.0, 0.0, 0.0, 0.0], vec![0.0, 0.0, 1.0, 0.0]],
        q: vec![
            vec![a, b, 0.0, 0.0],
            vec![b, q, 0.0, 0.0],
            vec![0.0, 0.0, a, b],
            vec![0.0, 0.0, b, q],
        ],
        r: vec![vec![1.0, 0.3], vec![0.3, 2.0]],
        x0: vec![0.0, 1.0, 0.0, -1.0],
        p0: vec![
            vec![5.0, 0.0, 0.0, 0.0],
            vec![0.0, 5.0, 0.0, 0.0],
            vec![0.0, 0.0, 5.0, 0.0],
            vec![0.0, 0.0, 0.0, 5.0],
        ],
        b: None,
        drift: None,
        stuck: None,
    }
}

fn bench(c: &mut Criterion) {
    let runtime = common::runtime();
    let (server, _dir) = common::server_with_echo_session(
        &runtime,
        "track",
        MonitorKind::Linear,
        serde_json::to_value(model()).expect("config"),
        PolicyConfig::Classic,
    );
    let addr = server.addr;
    let (socket, _) = runtime
        .block_on(tokio_tungstenite::connect_async(format!(
            "ws://{addr}/api/v1/sessions/bench/ingest"
        )))
        .expect("connect");
    let (mut sink, mut stream) = socket.split();
    runtime
        .block_on(stream.next())
        .expect("ready")
        .expect("ready message");
    let mut t = 0u64;

    let mut group = c.benchmark_group("ingest");
    group.throughput(Throughput::Elements(BATCH as u64));
    group.measurement_time(Duration::from_secs(10));
    group.bench_function("one_session_linear_batches_of_100", |bencher| {
        bencher.iter_custom(|iters| {
            let frames: Vec<String> = (0..iters)
                .map(|_| {
                    let epochs: Vec<_> = (0..BATCH)
                        .map(|_| {
                            t += 1;
                            let k = t as f64;
                            json!({"t": k, "z": [k + 0.3, -k - 0.2]})
                        })
                        .collect();
                    serde_json::Value::Array(epochs).to_string()
                })
                .collect();
            runtime.block_on(async {
                let start = Instant::now();
                let expected = iters as usize * BATCH;
                let reader = async {
                    let mut results = 0;
                    while results < expected {
                        match stream.next().await {
                            Some(Ok(Message::Text(text)))
                                if text.starts_with(r#"{"type":"result""#) =>
                            {
                                results += 1
                            }
                            Some(Ok(_)) => {}
                            other => panic!("socket ended: {other:?}"),
                        }
                    }
                };
                let writer = async {
                    for frame in frames {
                        sink.send(Message::Text(frame.into())).await.expect("send");
                    }
                };
                tokio::join!(reader, writer);
                start.elapsed()
            })
        })
    });
    group.finish();
    runtime.block_on(server.shutdown());
}

criterion_group!(benches, bench);
criterion_main!(benches);
