//! The end of a replay: the session's `/stats`, polled until the server has dealt
//! with every frame sent and the socket has delivered the alarms the stats count.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{Context, bail};
use navguard_core::session::SessionStats;
use tokio::time::Instant;

use super::stream::Sent;
use super::summary::Tally;
use crate::cli::http::Endpoint;

/// Longest the server may go without processing a frame while we wait for
/// the last ones.
const DRAIN_STALL: Duration = Duration::from_secs(30);
/// Longest wait for alarms the stats count but the socket has not delivered.
const ALARM_GRACE: Duration = Duration::from_secs(5);
/// On an echoing session, how long the socket may go without a new `result` before the
/// ones still missing are given up.
const RESULT_QUIET: Duration = Duration::from_secs(2);

/// The session's `/stats` (`path` is `/api/v1/sessions/{id}`).
pub(super) async fn stats(endpoint: &Endpoint, path: &str) -> anyhow::Result<SessionStats> {
    let (status, body) = endpoint.call("GET", &format!("{path}/stats")).await?;
    if status != 200 {
        bail!("GET {path}/stats: HTTP {status}: {body}");
    }
    parse_stats(&body)
}

fn parse_stats(body: &str) -> anyhow::Result<SessionStats> {
    serde_json::from_str(body).context("the stats do not have the session stats' shape")
}

/// Waits until the server has dealt with every frame sent (accepted ones
/// counted in `/stats`, refused ones answered with an `error`) and the socket
/// has delivered the alarms the stats count. Returns the final stats.
pub(super) async fn drain(
    endpoint: &Endpoint,
    path: &str,
    baseline: &SessionStats,
    sent: &Sent,
    tally: &Arc<Mutex<Tally>>,
) -> anyhow::Result<SessionStats> {
    let base_frames = baseline.frames;
    let base_alarms = baseline.alarms();
    let mut last_progress = (Instant::now(), u64::MAX);
    loop {
        let current = stats(endpoint, path).await?;
        let (errors, numerical, closed) = {
            let t = tally.lock().unwrap_or_else(|p| p.into_inner());
            (t.error_total, t.numerical, t.closed.clone())
        };
        // A frame refused for a numerical failure was counted as accepted too.
        let handled = current.frames.saturating_sub(base_frames) + errors - numerical;
        if handled >= sent.frames {
            break;
        }
        if let Some(reason) = closed {
            bail!(
                "the server closed the ingest socket before handling every frame ({handled} of {}): {reason}",
                sent.frames
            );
        }
        if handled != last_progress.1 {
            last_progress = (Instant::now(), handled);
        } else if last_progress.0.elapsed() > DRAIN_STALL {
            bail!(
                "the server handled {handled} of {} frames and then nothing for {} s",
                sent.frames,
                DRAIN_STALL.as_secs()
            );
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let deadline = Instant::now() + ALARM_GRACE;
    loop {
        let current = stats(endpoint, path).await?;
        let want = current.alarms().saturating_sub(base_alarms);
        let got = tally.lock().unwrap_or_else(|p| p.into_inner()).alarm_total;
        if got >= want {
            await_results(tally, sent.epochs).await;
            return Ok(current);
        }
        if Instant::now() > deadline {
            eprintln!("warning: the stats count {want} alarms, the socket delivered {got}");
            return Ok(current);
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// On an echoing session (some `result` came back), waits until a result per epoch sent
/// has arrived or none has for [`RESULT_QUIET`]: the server has handled every frame, but
/// its last results may still be on the socket (`--messages` copies them all).
async fn await_results(tally: &Arc<Mutex<Tally>>, epochs: u64) {
    let count = || tally.lock().unwrap_or_else(|p| p.into_inner()).results();
    let mut last = (Instant::now(), count());
    while last.1 > 0 && last.1 < epochs && last.0.elapsed() < RESULT_QUIET {
        tokio::time::sleep(Duration::from_millis(20)).await;
        let now = count();
        if now != last.1 {
            last = (Instant::now(), now);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use navguard_core::monitor::MonitorKind;
    use navguard_core::session::stats::TestStats;

    #[test]
    fn stats_are_read_as_the_services_session_stats() {
        let test = |alarms: u64| {
            let mut t = TestStats::new(1, 10.0);
            t.alarms = alarms;
            t
        };
        let body = serde_json::json!({"session": "s", "connected": true, "frames": 4,
            "epochs": 8, "frame_errors": 0, "last_t": 0.8, "last_frame_at_ms": null,
            "published_at_ms": 0, "epochs_per_s": 0.0,
            "monitors": {"a": {"type": "linear", "epochs": 8, "worst_test_ratio": null,
                               "tests": {"x": test(2), "y": test(1)}},
                         "b": {"type": "federated", "epochs": 8, "worst_test_ratio": 0.5,
                               "tests": {"z": test(4)}}}});
        let stats = parse_stats(&body.to_string()).unwrap();
        assert_eq!((stats.frames, stats.alarms()), (4, 7));
        assert_eq!(stats.monitors["b"].kind, MonitorKind::Federated);
        assert!(parse_stats("{}").is_err());
    }
}
