//! Criterion bench: a burst of alarms committed together, the store's share of
//! alarm-to-event latency (docs/performance.md). `N` sessions each hand
//! one log entry to the store at the same moment, as when every session fails the same
//! epoch; the bench times the burst until the last entry is committed (every entry is
//! committed before it is announced). SQLite in a temporary directory, WAL, as
//! `navguard` runs by default; the entries are keyed as the session actor keys them.
//!
//! - `alarm_burst/keyed/N` for N = 100 and 1,000.
//!
//! Run: `cargo bench --bench alarm_commit`

// criterion_group! defines a public function it cannot document.
#![allow(missing_docs)]

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use navguard::service::store::{AlarmKey, Store};
use navguard::service::wire::{AlarmRecord, Severity};
use navguard_core::detect::Health;

/// Session `s`'s entry at epoch `epoch` of stream 1.
fn entry(s: usize, epoch: u64) -> (AlarmRecord, AlarmKey) {
    let alarm = AlarmRecord {
        id: 0,
        severity: Severity::Alarm,
        session: format!("session-{s}"),
        monitor: "nav".into(),
        test: "gnss".into(),
        state: Health::Suspect,
        t: epoch as f64 * 0.1,
        statistic: 31.5,
        threshold: 22.46,
        dof: 6,
        test_ratio: 31.5 / 22.46,
        delay_s: 0.0,
        raised_at_ms: 1_700_000_000_000 + epoch as i64,
        cleared_t: None,
    };
    let key = AlarmKey {
        stream: 1,
        epoch_index: epoch,
    };
    (alarm, key)
}

fn bench(c: &mut Criterion) {
    // Two workers, as on the 2-core machine the figures are for (no server here, so not
    // benches/common, whose set-up starts one).
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    let dir = tempfile::tempdir().expect("tempdir");
    let store = runtime
        .block_on(Store::open(&dir.path().join("alarms.db")))
        .expect("store");
    let mut group = c.benchmark_group("alarm_burst");
    let mut epoch = 0;
    for n in [100usize, 1000] {
        group.throughput(Throughput::Elements(n as u64));
        group.bench_with_input(BenchmarkId::new("keyed", n), &n, |b, &n| {
            b.iter(|| {
                epoch += 1;
                runtime.block_on(async {
                    let tasks: Vec<_> = (0..n)
                        .map(|s| {
                            let store = store.clone();
                            let (alarm, key) = entry(s, epoch);
                            tokio::spawn(async move { store.insert_alarm(alarm, key, None).await })
                        })
                        .collect();
                    for t in tasks {
                        t.await.expect("task").expect("committed");
                    }
                })
            })
        });
    }
    group.finish();
    runtime.block_on(store.close());
}

criterion_group!(benches, bench);
criterion_main!(benches);
