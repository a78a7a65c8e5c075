//! Set-up shared by the benches that run a real server (`ingest`, `transport`):
//! their runtime, and an in-process navguard on a temporary SQLite store with one
//! `echo` session.

use navguard::service::wire::{CreateSession, MonitorSpecWire};
use navguard::service::{self, ServiceConfig};
use navguard_core::detect::PolicyConfig;
use navguard_core::monitor::MonitorKind;
use serde_json::Value;
use tokio::runtime::Runtime;

/// The runtime the benches' servers and clients share: two workers, as on the
/// 2-core machine the figures are for.
pub(crate) fn runtime() -> Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime")
}

/// A server started on `runtime` with one session `bench` whose single monitor
/// (`name`, `kind`, `config`, `policy`) echoes every result. Keep the returned
/// directory alive as long as the server: it holds the store.
pub(crate) fn server_with_echo_session(
    runtime: &Runtime,
    name: &str,
    kind: MonitorKind,
    config: Value,
    policy: PolicyConfig,
) -> (service::Server, tempfile::TempDir) {
    let dir = tempfile::tempdir().expect("tempdir");
    let server = runtime
        .block_on(service::start(ServiceConfig::new(
            "127.0.0.1:0".parse().expect("address"),
            dir.path().join("bench.db"),
        )))
        .expect("server");
    let body = CreateSession {
        id: Some("bench".to_owned()),
        monitors: vec![MonitorSpecWire {
            name: name.to_owned(),
            kind,
            config,
            policy,
            p_fa: None,
            threshold: None,
            alarm_level: None,
            tests: Default::default(),
        }],
        echo: true,
        alarm_level: None,
        record: None,
    };
    let addr = server.addr;
    runtime.block_on(async {
        let resp = reqwest::Client::new()
            .post(format!("http://{addr}/api/v1/sessions"))
            .json(&body)
            .send()
            .await
            .expect("create session");
        assert_eq!(resp.status(), 201);
    });
    (server, dir)
}
