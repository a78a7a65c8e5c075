//! Process-wide counters exported at `/metrics` in Prometheus text format.

use std::fmt::Write;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// Upper bounds of the frame-latency histogram buckets, seconds.
const LATENCY_BUCKETS_S: [f64; 12] = [
    1e-5, 2.5e-5, 5e-5, 1e-4, 2.5e-4, 5e-4, 1e-3, 2.5e-3, 5e-3, 1e-2, 5e-2, 0.25,
];

/// Counters shared by every socket and session.
#[derive(Debug, Default)]
pub struct Metrics {
    /// Ingest frames accepted.
    pub frames: AtomicU64,
    /// Epochs processed.
    pub epochs: AtomicU64,
    /// Frames refused with an `error` event.
    pub frame_errors: AtomicU64,
    /// Alarms raised.
    pub alarms: AtomicU64,
    /// Open ingest sockets.
    pub ingest_sockets: AtomicU64,
    /// Open event sockets.
    pub event_sockets: AtomicU64,
    latency_buckets: [AtomicU64; LATENCY_BUCKETS_S.len()],
    latency_count: AtomicU64,
    latency_sum_ns: AtomicU64,
}

impl Metrics {
    /// Records the time from a frame's arrival to the end of its processing.
    pub fn observe_frame_latency(&self, elapsed: Duration) {
        let s = elapsed.as_secs_f64();
        if let Some(i) = LATENCY_BUCKETS_S.iter().position(|&b| s <= b) {
            self.latency_buckets[i].fetch_add(1, Ordering::Relaxed);
        }
        self.latency_count.fetch_add(1, Ordering::Relaxed);
        self.latency_sum_ns
            .fetch_add(elapsed.as_nanos() as u64, Ordering::Relaxed);
    }

    /// Renders the Prometheus text exposition.
    // Over 80 lines: the exposition's metrics one after another (HELP, TYPE, value),
    // in the order Prometheus shows them; no branch worth a function of its own.
    pub fn render(&self, sessions: usize) -> String {
        let mut out = String::with_capacity(2048);
        let counter = |out: &mut String, name: &str, help: &str, v: u64| {
            let _ = writeln!(
                out,
                "# HELP {name} {help}\n# TYPE {name} counter\n{name} {v}"
            );
        };
        let gauge = |out: &mut String, name: &str, help: &str, v: f64| {
            let _ = writeln!(out, "# HELP {name} {help}\n# TYPE {name} gauge\n{name} {v}");
        };
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        counter(
            &mut out,
            "navguard_frames_total",
            "Ingest frames accepted.",
            get(&self.frames),
        );
        counter(
            &mut out,
            "navguard_epochs_total",
            "Epochs processed.",
            get(&self.epochs),
        );
        counter(
            &mut out,
            "navguard_frame_errors_total",
            "Ingest frames refused with an error event.",
            get(&self.frame_errors),
        );
        counter(
            &mut out,
            "navguard_alarms_total",
            "Alarms raised.",
            get(&self.alarms),
        );
        gauge(
            &mut out,
            "navguard_sessions",
            "Sessions defined.",
            sessions as f64,
        );
        gauge(
            &mut out,
            "navguard_ingest_sockets",
            "Open ingest sockets.",
            get(&self.ingest_sockets) as f64,
        );
        gauge(
            &mut out,
            "navguard_event_sockets",
            "Open event sockets.",
            get(&self.event_sockets) as f64,
        );
        let name = "navguard_frame_latency_seconds";
        let _ = writeln!(
            out,
            "# HELP {name} Frame arrival to end of processing.\n# TYPE {name} histogram"
        );
        let mut cumulative = 0;
        for (bound, bucket) in LATENCY_BUCKETS_S.iter().zip(&self.latency_buckets) {
            cumulative += get(bucket);
            let _ = writeln!(out, "{name}_bucket{{le=\"{bound}\"}} {cumulative}");
        }
        let count = get(&self.latency_count);
        let _ = writeln!(out, "{name}_bucket{{le=\"+Inf\"}} {count}");
        let _ = writeln!(
            out,
            "{name}_sum {}",
            get(&self.latency_sum_ns) as f64 * 1e-9
        );
        let _ = writeln!(out, "{name}_count {count}");
        if let Some(rss) = resident_memory_bytes() {
            gauge(
                &mut out,
                "process_resident_memory_bytes",
                "Resident set size.",
                rss as f64,
            );
        }
        out
    }
}

/// Resident set size from `/proc/self/statm` (Linux); `None` elsewhere.
fn resident_memory_bytes() -> Option<u64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4096)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_is_cumulative_and_counts_every_observation() {
        let m = Metrics::default();
        m.observe_frame_latency(Duration::from_micros(20));
        m.observe_frame_latency(Duration::from_millis(2));
        m.observe_frame_latency(Duration::from_secs(1));
        let text = m.render(3);
        assert!(
            text.contains("navguard_frame_latency_seconds_bucket{le=\"0.000025\"} 1"),
            "{text}"
        );
        assert!(
            text.contains("navguard_frame_latency_seconds_bucket{le=\"0.0025\"} 2"),
            "{text}"
        );
        assert!(
            text.contains("navguard_frame_latency_seconds_bucket{le=\"+Inf\"} 3"),
            "{text}"
        );
        assert!(text.contains("navguard_sessions 3"));
    }
}
