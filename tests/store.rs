//! The store's round trips on each backend: SQLite always, Postgres too when
//! `NAVGUARD_TEST_POSTGRES` names a server (tests/common: `store_for`). The same
//! assertions run on both, through the public `Store` API only.

mod common;

use std::collections::{HashMap, HashSet};
use std::path::PathBuf;
use std::sync::Arc;

use navguard::service::store::{
    AckOutcome, Acquire, AlarmAck, AlarmKey, AlarmQuery, AuditEntry, AuditQuery, Checkpoint, Fence,
    RecordedFrame, Retention, SessionPattern, Store, StoreError, StoredModel, StoredSession,
};
use navguard::service::wire::{AlarmRecord, Severity};
use navguard_core::detect::Health;

/// The stores to run on: a SQLite file, and a Postgres schema when the variable is set.
async fn backends(dir: &tempfile::TempDir, name: &str) -> Vec<(&'static str, PathBuf)> {
    let path = dir.path().join(format!("{name}.db"));
    let mut out = vec![("sqlite", path.clone())];
    if std::env::var(common::POSTGRES_VAR).is_ok_and(|v| !v.is_empty()) {
        out.push(("postgres", common::store_for(&path).await));
    } else {
        eprintln!(
            "{name}: skipping the Postgres backend ({} is not set); SQLite only",
            common::POSTGRES_VAR
        );
    }
    out
}

/// Values whose f64 must come back bit for bit.
// (-0.0 is not among them: SQLite stores it as 0.)
const AWKWARD: [f64; 6] = [
    0.1 + 0.2,
    1e-300,
    5e-324,
    -1.5e-7,
    1.7976931348623157e308,
    9.5495,
];

fn alarm(session: &str, t: f64, statistic: f64) -> AlarmRecord {
    AlarmRecord {
        id: 0,
        severity: Severity::Alarm,
        session: session.into(),
        monitor: "m".into(),
        test: "residual".into(),
        state: Health::Isolated,
        t,
        statistic,
        threshold: 20.0,
        dof: 3,
        test_ratio: statistic / 20.0,
        delay_s: 0.25,
        raised_at_ms: 1_000 + t as i64,
        cleared_t: None,
    }
}

fn all(limit: i64) -> AlarmQuery {
    AlarmQuery {
        limit,
        ..AlarmQuery::default()
    }
}

// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sessions_alarms_and_models_round_trip_and_survive_reopening() {
    let dir = tempfile::tempdir().unwrap();
    for (backend, db) in backends(&dir, "rt").await {
        let store = Store::open(&db).await.unwrap();
        // Sessions: put, replace, list oldest first, delete.
        let mut s1 = StoredSession {
            id: "s1".into(),
            echo: true,
            monitors: vec![],
            created_at_ms: 20,
            record: Some(true),
            alarm_level: None,
        };
        let s0 = StoredSession {
            id: "s0".into(),
            created_at_ms: 10,
            record: None,
            ..s1.clone()
        };
        store.put_session(&s1, None).await.unwrap();
        store.put_session(&s0, None).await.unwrap();
        s1.echo = false;
        store.put_session(&s1, None).await.unwrap();
        assert_eq!(
            store.sessions().await.unwrap(),
            vec![s0.clone(), s1.clone()],
            "{backend}"
        );

        // Alarms: ids in order, f64 bit for bit, filters, cursors, clearing.
        let mut ids = Vec::new();
        for (k, x) in AWKWARD.iter().enumerate() {
            let session = if k % 2 == 0 { "a" } else { "b" };
            let mut a = alarm(session, k as f64, *x);
            if k == 5 {
                a.severity = Severity::Warning;
            }
            ids.push(
                store
                    .insert_alarm(a, AlarmKey::default(), None)
                    .await
                    .unwrap()
                    .id,
            );
        }
        assert!(ids.windows(2).all(|w| w[0] < w[1]), "{backend}: {ids:?}");
        let got = store.alarms(&all(100)).await.unwrap();
        assert_eq!(got.len(), 6, "{backend}");
        let stats: Vec<u64> = got.iter().rev().map(|a| a.statistic.to_bits()).collect();
        let want: Vec<u64> = AWKWARD.iter().map(|x| x.to_bits()).collect();
        assert_eq!(stats, want, "{backend}: f64 bit for bit");
        assert_eq!(
            got[5],
            AlarmRecord {
                id: ids[0],
                ..alarm("a", 0.0, AWKWARD[0])
            }
        );
        let a_only = store
            .alarms(&AlarmQuery {
                session: Some("a".into()),
                ..all(100)
            })
            .await
            .unwrap();
        assert_eq!(
            a_only.iter().map(|a| a.t).collect::<Vec<_>>(),
            [4.0, 2.0, 0.0]
        );
        let page = store
            .alarms(&AlarmQuery {
                before_id: Some(ids[4]),
                after_id: Some(ids[0]),
                monitor: Some("m".into()),
                ..all(2)
            })
            .await
            .unwrap();
        assert_eq!(
            page.iter().map(|a| a.t).collect::<Vec<_>>(),
            [3.0, 2.0],
            "{backend}"
        );
        let warnings = store
            .alarms(&AlarmQuery {
                severity: Some(Severity::Warning),
                ..all(100)
            })
            .await
            .unwrap();
        assert_eq!(warnings.iter().map(|a| a.t).collect::<Vec<_>>(), [5.0]);
        let timed = store
            .alarms(&AlarmQuery {
                since_ms: Some(1_001),
                until_ms: Some(1_003),
                ..all(100)
            })
            .await
            .unwrap();
        assert_eq!(timed.iter().map(|a| a.t).collect::<Vec<_>>(), [2.0, 1.0]);
        store
            .clear_alarms("a", "m", "residual", Some(9.5), None)
            .await
            .unwrap();
        store
            .clear_alarms("b", "m", "residual", None, None)
            .await
            .unwrap();
        let cleared: Vec<_> = store
            .alarms(&all(100))
            .await
            .unwrap()
            .iter()
            .map(|a| a.cleared_t)
            .collect();
        assert_eq!(
            cleared,
            [
                Some(5.0),
                Some(9.5),
                Some(3.0),
                Some(9.5),
                Some(1.0),
                Some(9.5)
            ],
            "{backend}"
        );
        let late = store
            .insert_alarm(alarm("a", 7.0, 30.0), AlarmKey::default(), None)
            .await
            .unwrap();
        store.clear_session_alarms("a", None).await.unwrap();

        // Models: insert, finish, fail, delete.
        let model = |id: &str, created_ms| StoredModel {
            id: id.into(),
            name: Some("label ünïcode".into()),
            kind: "lssvm".into(),
            status: "training".into(),
            params: "{}".into(),
            n: 10,
            dim: 2,
            metrics: None,
            error: None,
            model: None,
            created_ms,
            finished_ms: None,
        };
        for (id, t) in [("m-a", 1), ("m-b", 2), ("m-c", 3), ("m-d", 4)] {
            store.insert_model(&model(id, t)).await.unwrap();
        }
        assert!(
            store
                .finish_model_ready("m-a", "{\"g\":1}", "{}", "MODEL", 7)
                .await
                .unwrap()
        );
        assert!(store.finish_model_failed("m-b", "bad", 8).await.unwrap());
        assert!(!store.finish_model_failed("m-a", "late", 9).await.unwrap());
        assert!(store.delete_model("m-d").await.unwrap());
        assert!(!store.delete_model("m-d").await.unwrap());
        assert!(store.delete_session("s0", None).await.unwrap());
        assert!(!store.delete_session("s0", None).await.unwrap());
        store.close().await;

        // Reopened (the migrations again, applied once): everything is there.
        let store = Store::open(&db).await.unwrap();
        assert_eq!(
            store.sessions().await.unwrap(),
            vec![s1.clone()],
            "{backend}"
        );
        let after = store.alarms(&all(100)).await.unwrap();
        assert_eq!(after.len(), 7, "{backend}");
        assert_eq!(after[0].id, late.id);
        assert_eq!(after[0].cleared_t, Some(7.0));
        assert_eq!(store.fail_interrupted_models(10).await.unwrap(), 1);
        let models = store.models().await.unwrap();
        let summary: Vec<_> = models
            .iter()
            .map(|m| (m.id.as_str(), m.status.as_str(), m.finished_ms))
            .collect();
        assert_eq!(
            summary,
            [
                ("m-a", "ready", Some(7)),
                ("m-b", "failed", Some(8)),
                ("m-c", "failed", Some(10))
            ],
            "{backend}"
        );
        assert_eq!(models[0].model.as_deref(), Some("MODEL"));
        assert_eq!(models[0].name.as_deref(), Some("label ünïcode"));
        // A new alarm after reopening still gets a larger id.
        let newest = store
            .insert_alarm(alarm("c", 8.0, 1.0), AlarmKey::default(), None)
            .await
            .unwrap();
        assert!(newest.id > late.id, "{backend}");
        store.close().await;
    }
}

fn frame(session: &str, stream: u64, first_epoch: u64, bytes: usize) -> RecordedFrame {
    RecordedFrame {
        session: session.into(),
        stream,
        first_epoch,
        epochs: 2,
        recorded_at_ms: navguard::service::now_ms(),
        frame: Arc::from(format!(
            "{{\"t\":{first_epoch},\"pad\":\"{}\"}}",
            "x".repeat(bytes)
        )),
        events: "[]".into(),
    }
}

// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn recordings_page_summarise_and_evict_oldest_first() {
    let dir = tempfile::tempdir().unwrap();
    for (backend, db) in backends(&dir, "rec").await {
        let retention = Retention {
            session_bytes: 5_000,
            total_bytes: 8_000,
            max_age_ms: 3_600_000,
        };
        let store = Store::open_with(&db, retention).await.unwrap();
        for k in 0..4 {
            store.record_frame(frame("a", 100, 2 * k, 200), None).await;
        }
        store.record_frame(frame("a", 200, 0, 200), None).await;
        store.flush_recordings().await;
        let page = store.recording_page("a", 100, 0, 3).await.unwrap();
        assert_eq!(
            page.iter().map(|(_, f)| f.first_epoch).collect::<Vec<_>>(),
            [0, 2, 4],
            "{backend}"
        );
        assert_eq!(
            page[1].1,
            frame("a", 100, 2, 200).clone_with(page[1].1.recorded_at_ms)
        );
        let rest = store.recording_page("a", 100, page[2].0, 10).await.unwrap();
        assert_eq!(
            rest.iter().map(|(_, f)| f.first_epoch).collect::<Vec<_>>(),
            [6]
        );
        let streams = store.recording_streams("a").await.unwrap();
        assert_eq!(
            streams
                .iter()
                .map(|s| (s.stream, s.frames, s.epochs))
                .collect::<Vec<_>>(),
            [(100, 4, 8), (200, 1, 2)],
            "{backend}"
        );
        let one = frame("a", 100, 0, 200).frame.len() as u64;
        assert_eq!(streams[0].bytes, 4 * one);
        assert!(store.recording_streams("nobody").await.unwrap().is_empty());

        // Over the session limit: the oldest frames of that session go first.
        for k in 0..30 {
            store.record_frame(frame("b", 300, k, 200), None).await;
        }
        store.flush_recordings().await;
        let b = store.recording_streams("b").await.unwrap();
        assert!(b[0].bytes <= 5_000, "{backend}: {b:?}");
        assert!(
            b[0].bytes + one > 5_000,
            "{backend}: kept as much as fits: {b:?}"
        );
        let kept = store.recording_page("b", 300, 0, 100).await.unwrap();
        assert_eq!(
            kept.last().unwrap().1.first_epoch,
            29,
            "{backend}: newest kept"
        );
        // Over the total limit: the oldest frames of all (session a's) go.
        for k in 0..20 {
            store.record_frame(frame("c", 400, k, 200), None).await;
        }
        store.flush_recordings().await;
        let mut sum = 0;
        for s in ["a", "b", "c"] {
            sum += store
                .recording_streams(s)
                .await
                .unwrap()
                .iter()
                .map(|x| x.bytes)
                .sum::<u64>();
        }
        assert!(sum <= 8_000, "{backend}: {sum}");
        assert!(
            store.recording_streams("a").await.unwrap().is_empty(),
            "{backend}: the oldest session's frames went first"
        );
        store.close().await;
        // The writer starts from the stored sizes after reopening.
        let store = Store::open_with(&db, retention).await.unwrap();
        store.record_frame(frame("c", 400, 99, 200), None).await;
        store.flush_recordings().await;
        let c = store.recording_page("c", 400, 0, 100).await.unwrap();
        assert_eq!(c.last().unwrap().1.first_epoch, 99, "{backend}");
        store.close().await;
    }
}

trait CloneWith {
    fn clone_with(&self, recorded_at_ms: i64) -> Self;
}

impl CloneWith for RecordedFrame {
    fn clone_with(&self, recorded_at_ms: i64) -> Self {
        RecordedFrame {
            recorded_at_ms,
            ..self.clone()
        }
    }
}

#[tokio::test]
async fn a_bad_or_unreachable_postgres_url_is_a_clear_error() {
    // Port 1 on loopback: nothing listens (connection refused at once).
    let err = Store::open(std::path::Path::new(
        "postgres://navguard:s3cret@127.0.0.1:1/navguard",
    ))
    .await
    .unwrap_err()
    .to_string();
    assert!(
        err.starts_with("connecting to postgres://navguard@127.0.0.1:1/navguard: "),
        "{err}"
    );
    assert!(
        !err.contains("s3cret"),
        "the password stays out of messages: {err}"
    );
    assert!(!err.contains('\n'), "{err}");
    let err = Store::open(std::path::Path::new("postgresql://u@127.0.0.1:port/db"))
        .await
        .unwrap_err()
        .to_string();
    assert!(err.contains("port"), "{err}");
    assert_eq!(
        navguard::service::store::display_db(std::path::Path::new("postgres://u:pw@h:5/d?x=1")),
        "postgres://u@h:5/d?x=1"
    );
    assert_eq!(
        navguard::service::store::display_db(std::path::Path::new("dir/nav.db")),
        "dir/nav.db"
    );
}

fn session(id: &str) -> StoredSession {
    StoredSession {
        id: id.into(),
        echo: false,
        monitors: vec![],
        created_at_ms: 1,
        record: None,
        alarm_level: None,
    }
}

fn checkpoint(session: &str, lease_epoch: i64, version: i64) -> Checkpoint {
    Checkpoint {
        session: session.into(),
        lease_epoch,
        version,
        epochs: version * 10,
        t: Some(version as f64),
        taken_at_ms: 5,
        state: vec![lease_epoch as u8, version as u8, 0xff],
    }
}

/// docs/deployment.md: a lease is taken once, free or expired; every acquisition raises
/// the epoch; the holder of an old epoch can write nothing more for the session; a
/// release lets the next node in at once.
// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn leases_fence_every_write_of_a_node_that_lost_its_session() {
    let dir = tempfile::tempdir().unwrap();
    for (backend, db) in backends(&dir, "lease").await {
        let store = Store::open(&db).await.unwrap();
        store.put_session(&session("s"), None).await.unwrap();
        assert!(
            store
                .create_lease("s", "a", "http://a", 10_000)
                .await
                .unwrap()
        );
        assert!(
            !store
                .create_lease("s", "b", "http://b", 10_000)
                .await
                .unwrap(),
            "{backend}: the id is taken"
        );
        let a = Fence {
            session: "s".into(),
            owner: "a".into(),
            epoch: 1,
        };
        // b cannot take a live lease, but can once it expired (now = 10_000).
        match store
            .acquire_lease("s", "b", "http://b", 9_999, 20_000, false)
            .await
            .unwrap()
        {
            Acquire::Held(l) => assert_eq!(
                (l.owner.as_str(), l.epoch, l.address.as_str()),
                ("a", 1, "http://a")
            ),
            taken => panic!("{backend}: took a live lease: {taken:?}"),
        }
        let Acquire::Taken(epoch) = store
            .acquire_lease("s", "b", "http://b", 10_000, 20_000, false)
            .await
            .unwrap()
        else {
            panic!("{backend}: an expired lease is free");
        };
        assert_eq!(epoch, 2);
        let b = Fence {
            session: "s".into(),
            owner: "b".into(),
            epoch,
        };
        // a is fenced on every kind of write; b is not.
        let fenced = |r: Result<(), StoreError>| matches!(r, Err(StoreError::Fenced(_)));
        assert!(
            fenced(store.put_session(&session("s"), Some(&a)).await),
            "{backend}"
        );
        assert!(fenced(
            store.clear_alarms("s", "m", "t", None, Some(&a)).await
        ));
        assert!(fenced(store.clear_session_alarms("s", Some(&a)).await));
        assert!(fenced(
            store.put_checkpoint(&a, &checkpoint("s", 1, 1)).await
        ));
        assert!(matches!(
            store
                .insert_alarm(
                    alarm("s", 1.0, 30.0),
                    AlarmKey {
                        stream: 7,
                        epoch_index: 1
                    },
                    Some(&a)
                )
                .await,
            Err(StoreError::Fenced(_))
        ));
        assert!(matches!(
            store.delete_session("s", Some(&a)).await,
            Err(StoreError::Fenced(_))
        ));
        assert!(
            !store.release_lease(&a).await.unwrap(),
            "{backend}: only the holder releases"
        );
        store.put_session(&session("s"), Some(&b)).await.unwrap();
        store
            .put_checkpoint(&b, &checkpoint("s", 2, 1))
            .await
            .unwrap();
        // Renewal answers what b still holds; a holds nothing.
        assert_eq!(
            store.renew_leases("b", 30_000).await.unwrap(),
            vec![("s".to_owned(), 2)]
        );
        assert!(store.renew_leases("a", 30_000).await.unwrap().is_empty());
        // A release lets c in at once, long before the expiry.
        assert!(store.release_lease(&b).await.unwrap());
        assert!(
            store.renew_leases("b", 40_000).await.unwrap().is_empty(),
            "a released lease is not renewed"
        );
        let Acquire::Taken(3) = store
            .acquire_lease("s", "c", "http://c", 11_000, 21_000, false)
            .await
            .unwrap()
        else {
            panic!("{backend}: a released lease is free");
        };
        // force takes a live lease (its owner is known to be gone).
        let Acquire::Taken(4) = store
            .acquire_lease("s", "d", "http://d", 11_000, 21_000, true)
            .await
            .unwrap()
        else {
            panic!("{backend}: force takes it");
        };
        // The checkpoint is b's; deleting the session takes its lease and checkpoint along.
        assert_eq!(store.checkpoint("s").await.unwrap().unwrap().lease_epoch, 2);
        let d = Fence {
            session: "s".into(),
            owner: "d".into(),
            epoch: 4,
        };
        assert!(store.delete_session("s", Some(&d)).await.unwrap());
        assert!(store.lease("s").await.unwrap().is_none());
        assert!(store.checkpoint("s").await.unwrap().is_none());
        store.close().await;
    }
}

/// An older checkpoint written late never replaces a newer one, and a new owner's first
/// checkpoint replaces the old owner's last.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn checkpoints_only_move_forward() {
    let dir = tempfile::tempdir().unwrap();
    for (backend, db) in backends(&dir, "ckpt").await {
        let store = Store::open(&db).await.unwrap();
        store.put_session(&session("s"), None).await.unwrap();
        assert!(store.create_lease("s", "a", "", i64::MAX).await.unwrap());
        let a = Fence {
            session: "s".into(),
            owner: "a".into(),
            epoch: 1,
        };
        store
            .put_checkpoint(&a, &checkpoint("s", 1, 5))
            .await
            .unwrap();
        store
            .put_checkpoint(&a, &checkpoint("s", 1, 4))
            .await
            .unwrap();
        assert_eq!(
            store.checkpoint("s").await.unwrap(),
            Some(checkpoint("s", 1, 5)),
            "{backend}"
        );
        let Acquire::Taken(2) = store
            .acquire_lease("s", "b", "", 0, i64::MAX, true)
            .await
            .unwrap()
        else {
            panic!("{backend}");
        };
        let b = Fence {
            session: "s".into(),
            owner: "b".into(),
            epoch: 2,
        };
        store
            .put_checkpoint(&b, &checkpoint("s", 2, 1))
            .await
            .unwrap();
        assert_eq!(
            store.checkpoint("s").await.unwrap(),
            Some(checkpoint("s", 2, 1)),
            "{backend}"
        );
        // Written at once (one group commit, several versions of one session, and the
        // old owner's among them): the newest of b's wins, a's are refused.
        let writes: Vec<_> = (2..40)
            .map(|v| {
                let (store, a, b) = (store.clone(), a.clone(), b.clone());
                tokio::spawn(async move {
                    let old = store.put_checkpoint(&a, &checkpoint("s", 1, 100 + v)).await;
                    assert!(matches!(old, Err(StoreError::Fenced(_))), "{old:?}");
                    store.put_checkpoint(&b, &checkpoint("s", 2, v)).await
                })
            })
            .collect();
        for w in writes {
            w.await.unwrap().unwrap();
        }
        assert_eq!(
            store.checkpoint("s").await.unwrap(),
            Some(checkpoint("s", 2, 39)),
            "{backend}"
        );
        store.close().await;
    }
}

/// The same transition raised again on the same stream and epoch (the epochs after a
/// checkpoint, replayed after a failover) is one log entry; its id is answered again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_replayed_alarm_is_one_log_entry() {
    let dir = tempfile::tempdir().unwrap();
    for (backend, db) in backends(&dir, "once").await {
        let store = Store::open(&db).await.unwrap();
        let key = AlarmKey {
            stream: 1_700_000_000_000,
            epoch_index: 42,
        };
        let first = store
            .insert_alarm(alarm("s", 4.2, 30.0), key, None)
            .await
            .unwrap();
        let again = store
            .insert_alarm(alarm("s", 4.2, 30.0), key, None)
            .await
            .unwrap();
        assert_eq!(first.id, again.id, "{backend}");
        // Another epoch, another severity, another stream, or unkeyed: new entries.
        let other_epoch = AlarmKey {
            epoch_index: 43,
            ..key
        };
        let other_stream = AlarmKey {
            stream: key.stream + 1,
            ..key
        };
        let mut warning = alarm("s", 4.2, 30.0);
        warning.severity = Severity::Warning;
        let ids = [
            store
                .insert_alarm(alarm("s", 4.3, 30.0), other_epoch, None)
                .await
                .unwrap()
                .id,
            store.insert_alarm(warning, key, None).await.unwrap().id,
            store
                .insert_alarm(alarm("s", 4.2, 30.0), other_stream, None)
                .await
                .unwrap()
                .id,
            store
                .insert_alarm(alarm("s", 4.2, 30.0), AlarmKey::default(), None)
                .await
                .unwrap()
                .id,
            store
                .insert_alarm(alarm("s", 4.2, 30.0), AlarmKey::default(), None)
                .await
                .unwrap()
                .id,
        ];
        let mut distinct = ids.to_vec();
        distinct.push(first.id);
        distinct.sort_unstable();
        distinct.dedup();
        assert_eq!(distinct.len(), 6, "{backend}: {ids:?}");
        assert_eq!(store.alarms(&all(100)).await.unwrap().len(), 6, "{backend}");
        store.close().await;
    }
}

/// A burst goes in as multi-row inserts whose `RETURNING` rows are matched back to their
/// callers: each caller gets the id of its own entry (checked against what is stored
/// under that id), identical unkeyed entries distinct ids, and a keyed entry raised
/// again — in a later burst, or twice in the same one — the first one's id.
// Over 80 lines: one scenario in the order it happens; its steps share its state.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_entry_of_a_burst_gets_its_own_id() {
    // Entry `k` of a burst. k % 3 == 0: keyed (stream 7, epoch k / 6, so k and k + 3 share
    // a key; t and statistic follow the key). k % 3 == 1: unkeyed and all identical.
    // k % 3 == 2: unkeyed, each its own (t = −0 once, which SQLite gives back as +0).
    let entry = |k: usize| match k % 3 {
        0 => {
            let e = k / 6;
            let key = AlarmKey {
                stream: 7,
                epoch_index: e as u64,
            };
            (
                alarm(&format!("s{}", e % 10), e as f64, 30.0 + e as f64),
                key,
            )
        }
        1 => (alarm("same", 5.0, 50.0), AlarmKey::default()),
        _ => {
            let t = if k == 5 { -0.0 } else { k as f64 };
            let a = alarm(&format!("s{}", k % 10), t, 30.0 + k as f64);
            (a, AlarmKey::default())
        }
    };
    let dir = tempfile::tempdir().unwrap();
    for (backend, db) in backends(&dir, "burst").await {
        let store = Store::open(&db).await.unwrap();
        let burst = |range: std::ops::Range<usize>| {
            let tasks: Vec<_> = range
                .map(|k| {
                    let store = store.clone();
                    let (a, key) = entry(k);
                    tokio::spawn(
                        async move { (k, store.insert_alarm(a, key, None).await.unwrap()) },
                    )
                })
                .collect();
            async move {
                let mut out = Vec::new();
                for t in tasks {
                    out.push(t.await.unwrap());
                }
                out
            }
        };
        let first = burst(0..600).await;
        // The same keyed entries again with new ones: a replay after a failover.
        let second = burst(300..900).await;
        let stored: HashMap<i64, AlarmRecord> = store
            .alarms(&all(2000))
            .await
            .unwrap()
            .into_iter()
            .map(|a| (a.id, a))
            .collect();
        let mut by_key: HashMap<(String, u64), i64> = HashMap::new();
        let mut unkeyed = HashSet::new();
        for (k, got) in first.iter().chain(&second) {
            let (a, key) = entry(*k);
            let row = &stored[&got.id];
            assert_eq!(
                (&row.session, row.t, row.statistic),
                (&a.session, a.t, a.statistic),
                "{backend}: entry {k} got id {} of another entry",
                got.id
            );
            if key.stream > 0 {
                let first_id = *by_key
                    .entry((a.session.clone(), key.epoch_index))
                    .or_insert(got.id);
                assert_eq!(got.id, first_id, "{backend}: entry {k}: a key is one entry");
            } else {
                assert!(
                    unkeyed.insert(got.id),
                    "{backend}: entry {k}: id given twice"
                );
            }
        }
        // 1,200 calls: 400 keyed ones naming 150 keys (0..100, then 50..150), 800 unkeyed.
        assert_eq!(by_key.len(), 150, "{backend}");
        assert_eq!(unkeyed.len(), 800, "{backend}");
        assert_eq!(stored.len(), 150 + 800, "{backend}");
        store.close().await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sqlite_copies_its_wal_into_the_file_from_a_task_of_its_own() {
    // A few entries are a few WAL pages, far below SQLite's automatic checkpoint (1,000
    // pages, run inside a commit, which the store turns off): only the store's own
    // checkpoint task moves them into the database file, within about half a second.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("wal.db");
    let store = Store::open(&path).await.unwrap();
    let file_len = || std::fs::metadata(&path).map(|m| m.len()).unwrap();
    let before = file_len();
    for k in 0..200 {
        let stored = store
            .insert_alarm(
                alarm(&format!("s{}", k % 50), k as f64, 30.0),
                AlarmKey::default(),
                None,
            )
            .await
            .unwrap();
        assert!(stored.id > 0);
    }
    let wal = dir.path().join("wal.db-wal");
    assert!(
        std::fs::metadata(&wal).unwrap().len() > 0,
        "the commits are in the WAL"
    );
    let mut grown = file_len() > before;
    for _ in 0..100 {
        if grown {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        grown = file_len() > before;
    }
    assert!(grown, "the database file is still {before} bytes after 5 s");
    // Everything committed is there after a reopen.
    store.close().await;
    let reopened = Store::open(&path).await.unwrap();
    let page = reopened
        .alarms(&AlarmQuery {
            limit: 500,
            ..AlarmQuery::default()
        })
        .await
        .unwrap();
    assert_eq!(page.len(), 200);
}

fn audit_entry(actor: &str, session: Option<&str>, at_ms: i64) -> AuditEntry {
    AuditEntry {
        id: 0,
        at_ms,
        actor: actor.into(),
        client: Some("127.0.0.1:40000".into()),
        forwarded_for: None,
        method: "PUT".into(),
        route: "/api/v1/sessions/{id}/monitors/{name}/threshold".into(),
        path: format!(
            "/api/v1/sessions/{}/monitors/m/threshold",
            session.unwrap_or("-")
        ),
        session: session.map(str::to_owned),
        reason: Some("é and \"quotes\"".into()),
        previous: serde_json::json!({"p_fa": 0.001, "tests": {}}),
        new: serde_json::json!({"p_fa": 1e-5, "awkward": AWKWARD}),
    }
}

/// The audit log and acknowledgements on each backend: entries come back as written,
/// newest first, filtered by session, actor, time and the sessions a token may see (a
/// prefix holding `_`, a LIKE wildcard, matches only itself); an entry is acknowledged
/// once, and only in its own session.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn audit_entries_and_acknowledgements_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    for (backend, db) in backends(&dir, "audit").await {
        let store = Store::open(&db).await.unwrap();
        let written = [
            audit_entry("ops", Some("veh_1"), 10),
            audit_entry("analyst", Some("vehx1"), 20),
            audit_entry("ops", None, 30),
            audit_entry("analyst", Some("car-1"), 40),
        ];
        let mut ids = Vec::new();
        for e in &written {
            ids.push(store.insert_audit(e).await.unwrap());
        }
        assert!(ids.windows(2).all(|w| w[0] < w[1]), "{backend}");
        let q = |f: fn(&mut AuditQuery)| {
            let mut q = AuditQuery {
                limit: 10,
                ..Default::default()
            };
            f(&mut q);
            q
        };
        let everything = store.audit(&q(|_| {})).await.unwrap();
        let expected: Vec<AuditEntry> = written
            .iter()
            .zip(&ids)
            .rev()
            .map(|(e, id)| AuditEntry {
                id: *id,
                ..e.clone()
            })
            .collect();
        assert_eq!(everything, expected, "{backend}");
        let sessions = |entries: Vec<AuditEntry>| -> Vec<Option<String>> {
            entries.into_iter().map(|e| e.session).collect()
        };
        let by_actor = store
            .audit(&q(|q| q.actor = Some("ops".into())))
            .await
            .unwrap();
        assert_eq!(
            sessions(by_actor),
            [None, Some("veh_1".into())],
            "{backend}"
        );
        let by_session = store
            .audit(&q(|q| q.session = Some("car-1".into())))
            .await
            .unwrap();
        assert_eq!(by_session.len(), 1, "{backend}");
        let since = store.audit(&q(|q| q.since_ms = Some(20))).await.unwrap();
        assert_eq!(since.len(), 3, "{backend}");
        let page = store
            .audit(&q(|q| {
                q.before_id = Some(i64::MAX);
                q.limit = 1;
            }))
            .await
            .unwrap();
        let older = store
            .audit(&AuditQuery {
                before_id: Some(page[0].id),
                limit: 10,
                ..Default::default()
            })
            .await
            .unwrap();
        assert_eq!(older.len(), 3, "{backend}");
        let visible = store
            .audit(&q(|q| {
                q.visible = Some(vec![
                    SessionPattern::Prefix("veh_".into()),
                    SessionPattern::Exact("car-1".into()),
                ])
            }))
            .await
            .unwrap();
        assert_eq!(
            sessions(visible),
            [Some("car-1".into()), Some("veh_1".into())],
            "{backend}"
        );
        let none = store.audit(&q(|q| q.visible = Some(vec![]))).await.unwrap();
        assert!(none.is_empty(), "{backend}");

        let raised = store
            .insert_alarm(alarm("car-1", 1.0, 30.0), AlarmKey::default(), None)
            .await
            .unwrap();
        let ack = AlarmAck {
            acked_by: "analyst".into(),
            acked_at_ms: 50,
            ack_comment: "multipath near the quay".into(),
        };
        assert_eq!(
            store.ack_alarm("veh_1", raised.id, &ack).await.unwrap(),
            AckOutcome::Missing,
            "{backend}"
        );
        let AckOutcome::Acked(entry) = store.ack_alarm("car-1", raised.id, &ack).await.unwrap()
        else {
            panic!("{backend}: the first acknowledgement takes");
        };
        assert_eq!(entry.record, raised, "{backend}");
        assert_eq!(
            (
                entry.acked_by.as_deref(),
                entry.acked_at_ms,
                entry.ack_comment.as_deref()
            ),
            (Some("analyst"), Some(50), Some("multipath near the quay")),
            "{backend}"
        );
        let again = AlarmAck {
            acked_by: "ops".into(),
            ..ack
        };
        assert_eq!(
            store.ack_alarm("car-1", raised.id, &again).await.unwrap(),
            AckOutcome::Already(entry.clone()),
            "{backend}"
        );
        let log = store.alarm_log(&all(10)).await.unwrap();
        assert_eq!(log, vec![entry], "{backend}");
        store.close().await;
    }
}

/// A store at the schema before the audit log (version 2: the migrations as the previous
/// server applied them, with an alarm and a session in it) opens on each backend at the
/// current version with its data: the alarm reads unacknowledged and can be
/// acknowledged, the session loads, and the audit log takes entries.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_store_at_the_previous_schema_opens_migrated_with_its_data() {
    const ALARM: &str = "INSERT INTO alarms (session, monitor, test, state, t, statistic, threshold, dof, delay_s, raised_at_ms, severity) VALUES ('old', 'm', 'residual', 'isolated', 1.0, 30.0, 20.0, 1, 0.0, 5, 'alarm')";
    const SESSION: &str = r#"INSERT INTO sessions (id, spec, created_at_ms) VALUES ('old', '{"format":1,"id":"old","echo":false,"monitors":[],"created_at_ms":7}', 7)"#;
    const VERSIONS: &str = "INSERT INTO schema_version (version, name, applied_at_ms) VALUES (1, 'initial', 0), (2, 'cluster', 0)";
    const VERSION_TABLE: &str = "CREATE TABLE schema_version (version BIGINT PRIMARY KEY, name TEXT NOT NULL, applied_at_ms BIGINT NOT NULL)";
    let dir = tempfile::tempdir().unwrap();
    for (backend, db) in backends(&dir, "v2").await {
        let url = db.to_str().unwrap().to_owned();
        if backend == "sqlite" {
            let pool = sqlx::SqlitePool::connect(&format!("sqlite://{url}?mode=rwc"))
                .await
                .unwrap();
            let sql = [
                include_str!("../src/service/store/migrations/sqlite/0001_initial.sql"),
                "ALTER TABLE alarms ADD COLUMN severity TEXT NOT NULL DEFAULT 'alarm';",
                include_str!("../src/service/store/migrations/sqlite/0002_cluster.sql"),
                &format!("{VERSION_TABLE}; {VERSIONS}; {ALARM}; {SESSION};"),
            ];
            for s in sql {
                sqlx::raw_sql(s).execute(&pool).await.unwrap();
            }
            pool.close().await;
        } else {
            let pool = sqlx::PgPool::connect(&url).await.unwrap();
            let sql = [
                include_str!("../src/service/store/migrations/postgres/0001_initial.sql"),
                include_str!("../src/service/store/migrations/postgres/0002_cluster.sql"),
                &format!("{VERSION_TABLE}; {VERSIONS}; {ALARM}; {SESSION};"),
            ];
            for s in sql {
                sqlx::raw_sql(s).execute(&pool).await.unwrap();
            }
            pool.close().await;
        }
        let store = Store::open(&db).await.unwrap();
        let sessions = store.sessions().await.unwrap();
        assert_eq!(sessions.len(), 1, "{backend}");
        let log = store.alarm_log(&all(10)).await.unwrap();
        assert_eq!(log.len(), 1, "{backend}");
        assert_eq!(log[0].acked_by, None, "{backend}");
        let ack = AlarmAck {
            acked_by: "ops".into(),
            acked_at_ms: 9,
            ack_comment: "seen".into(),
        };
        let outcome = store
            .ack_alarm("old", log[0].record.id, &ack)
            .await
            .unwrap();
        assert!(matches!(outcome, AckOutcome::Acked(_)), "{backend}");
        store
            .insert_audit(&audit_entry("ops", Some("old"), 10))
            .await
            .unwrap();
        assert_eq!(
            store
                .audit(&AuditQuery {
                    limit: 10,
                    ..Default::default()
                })
                .await
                .unwrap()
                .len(),
            1,
            "{backend}"
        );
        store.close().await;
        // Opened again, nothing is applied twice.
        let store = Store::open(&db).await.unwrap();
        assert_eq!(
            store.alarm_log(&all(10)).await.unwrap()[0]
                .acked_by
                .as_deref(),
            Some("ops"),
            "{backend}"
        );
        store.close().await;
    }
}
