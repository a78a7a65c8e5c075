//! Process-wide counters exported at `/metrics` in Prometheus text format.

use std::fmt::Write;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// Upper bounds of the latency histograms' buckets, seconds.
const LATENCY_BUCKETS_S: [f64; 13] = [
    1e-5, 2.5e-5, 5e-5, 1e-4, 2.5e-4, 5e-4, 1e-3, 2.5e-3, 5e-3, 1e-2, 2.5e-2, 5e-2, 0.25,
];

/// A latency histogram over [`LATENCY_BUCKETS_S`] (relaxed atomics: observed from any
/// task without a lock).
#[derive(Debug, Default)]
struct Histogram {
    buckets: [AtomicU64; LATENCY_BUCKETS_S.len()],
    count: AtomicU64,
    sum_ns: AtomicU64,
}

impl Histogram {
    fn observe(&self, elapsed: Duration) {
        let s = elapsed.as_secs_f64();
        if let Some(i) = LATENCY_BUCKETS_S.iter().position(|&b| s <= b) {
            self.buckets[i].fetch_add(1, Ordering::Relaxed);
        }
        self.count.fetch_add(1, Ordering::Relaxed);
        self.sum_ns
            .fetch_add(elapsed.as_nanos() as u64, Ordering::Relaxed);
    }

    /// The Prometheus exposition of the histogram `name` (cumulative buckets, `+Inf`,
    /// sum in seconds, count).
    fn render(&self, out: &mut String, name: &str, help: &str) {
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        let _ = writeln!(out, "# HELP {name} {help}\n# TYPE {name} histogram");
        let mut cumulative = 0;
        for (bound, bucket) in LATENCY_BUCKETS_S.iter().zip(&self.buckets) {
            cumulative += get(bucket);
            let _ = writeln!(out, "{name}_bucket{{le=\"{bound}\"}} {cumulative}");
        }
        let count = get(&self.count);
        let _ = writeln!(out, "{name}_bucket{{le=\"+Inf\"}} {count}");
        let _ = writeln!(out, "{name}_sum {}", get(&self.sum_ns) as f64 * 1e-9);
        let _ = writeln!(out, "{name}_count {count}");
    }
}

/// What the sessions' latest statistics show, counted over every session for
/// `/metrics` (docs/methods.md §M22, §M24): tests by consistency flag and by state,
/// monitors by availability. Gathered when `/metrics` is read, not per epoch.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SessionGauges {
    /// Tests by consistency flag: ok, overconfident, underconfident, correlated,
    /// not yet judged.
    pub consistency: [u64; 5],
    /// Tests by state: healthy, suspect, isolated.
    pub states: [u64; 3],
    /// Monitors with a protection level by availability: converging, available,
    /// unavailable.
    pub availability: [u64; 3],
}

impl SessionGauges {
    /// Adds one session's statistics.
    pub fn add(&mut self, stats: &navguard_core::session::SessionStats) {
        use navguard_core::detect::Health;
        use navguard_core::detect::consistency::ConsistencyFlag;
        use navguard_core::monitor::Availability;
        for m in stats.monitors.values() {
            for t in m.tests.values() {
                // Tests fed no normalised innovation have no diagnostics to count.
                if let Some(c) = t.consistency {
                    self.consistency[match c.flag {
                        Some(ConsistencyFlag::Ok) => 0,
                        Some(ConsistencyFlag::Overconfident) => 1,
                        Some(ConsistencyFlag::Underconfident) => 2,
                        Some(ConsistencyFlag::Correlated) => 3,
                        None => 4,
                    }] += 1;
                }
                self.states[match t.state {
                    Health::Healthy => 0,
                    Health::Suspect => 1,
                    Health::Isolated => 2,
                }] += 1;
            }
            if let Some(i) = &m.integrity {
                self.availability[match i.state {
                    Availability::Converging => 0,
                    Availability::Available => 1,
                    Availability::Unavailable => 2,
                }] += 1;
            }
        }
    }
}

/// Counters shared by every socket and session.
#[derive(Debug, Default)]
pub struct Metrics {
    /// Ingest frames accepted.
    pub frames: AtomicU64,
    /// Epochs processed.
    pub epochs: AtomicU64,
    /// Frames refused with an `error` event.
    pub frame_errors: AtomicU64,
    /// Frames whose first slice was stepped on the compute pool while the frame before
    /// was still being committed (docs/architecture.md §A2).
    pub frames_prestepped: AtomicU64,
    /// Alarms raised.
    pub alarms: AtomicU64,
    /// Warnings raised (stored, announced as `state` events only).
    pub warnings: AtomicU64,
    /// Open ingest sockets.
    pub ingest_sockets: AtomicU64,
    /// Open event sockets.
    pub event_sockets: AtomicU64,
    frame_latency: Histogram,
    alarm_commit: Histogram,
}

impl Metrics {
    /// Records the time from a frame's arrival to the end of its processing.
    pub fn observe_frame_latency(&self, elapsed: Duration) {
        self.frame_latency.observe(elapsed);
    }

    /// Records the time one log entry (alarm or warning) took from its session handing it
    /// to the store to its commit: the wait in the alarm writer's queue and the shared
    /// transaction ([`crate::service::store`]'s group commit). An entry is announced
    /// only after it, so this is the store's share of alarm-to-event latency.
    pub fn observe_alarm_commit(&self, elapsed: Duration) {
        self.alarm_commit.observe(elapsed);
    }

    /// Renders the Prometheus text exposition: the counters, the sessions' gauges,
    /// the socket gauges, the latency histograms, then the process's own metrics.
    pub fn render(&self, sessions: usize, gauges: &SessionGauges) -> String {
        let mut out = String::with_capacity(2048);
        self.render_counters(&mut out);
        render_session_gauges(&mut out, gauges);
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
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
        self.frame_latency.render(
            &mut out,
            "navguard_frame_latency_seconds",
            "Frame arrival to end of processing.",
        );
        self.alarm_commit.render(
            &mut out,
            "navguard_alarm_commit_seconds",
            "Log entry handed to the store to its commit (queue and shared transaction).",
        );
        render_process(&mut out);
        out
    }

    /// The counters of frames, epochs, refusals, alarms and warnings.
    fn render_counters(&self, out: &mut String) {
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        counter(
            out,
            "navguard_frames_total",
            "Ingest frames accepted.",
            get(&self.frames),
        );
        counter(
            out,
            "navguard_epochs_total",
            "Epochs processed.",
            get(&self.epochs),
        );
        counter(
            out,
            "navguard_frame_errors_total",
            "Ingest frames refused with an error event.",
            get(&self.frame_errors),
        );
        counter(
            out,
            "navguard_frames_prestepped_total",
            "Ingest frames stepped while the frame before was committed.",
            get(&self.frames_prestepped),
        );
        counter(
            out,
            "navguard_alarms_total",
            "Alarms raised.",
            get(&self.alarms),
        );
        counter(
            out,
            "navguard_warnings_total",
            "Warnings raised (stored, announced as state events only).",
            get(&self.warnings),
        );
    }
}

/// A counter: HELP, TYPE and its value.
fn counter(out: &mut String, name: &str, help: &str, v: u64) {
    let _ = writeln!(
        out,
        "# HELP {name} {help}\n# TYPE {name} counter\n{name} {v}"
    );
}

/// A gauge: HELP, TYPE and its value.
fn gauge(out: &mut String, name: &str, help: &str, v: f64) {
    let _ = writeln!(out, "# HELP {name} {help}\n# TYPE {name} gauge\n{name} {v}");
}

/// The sessions' tests by consistency flag and by state, and their monitors by
/// availability.
fn render_session_gauges(out: &mut String, gauges: &SessionGauges) {
    labelled(
        out,
        "navguard_tests_by_consistency",
        "Tests by the consistency flag of their normalised innovation.",
        "flag",
        &[
            "ok",
            "overconfident",
            "underconfident",
            "correlated",
            "pending",
        ],
        &gauges.consistency,
    );
    labelled(
        out,
        "navguard_tests_by_state",
        "Tests by health state.",
        "state",
        &["healthy", "suspect", "isolated"],
        &gauges.states,
    );
    labelled(
        out,
        "navguard_monitors_by_availability",
        "Monitors with a protection level, by integrity availability.",
        "availability",
        &["converging", "available", "unavailable"],
        &gauges.availability,
    );
}

/// The process's resident memory and CPU time, where the platform tells them.
fn render_process(out: &mut String) {
    if let Some(rss) = resident_memory_bytes() {
        gauge(
            out,
            "process_resident_memory_bytes",
            "Resident set size.",
            rss as f64,
        );
    }
    if let Some(cpu) = process_cpu_seconds() {
        let name = "process_cpu_seconds_total";
        let _ = writeln!(
            out,
            "# HELP {name} User and system CPU time of the process.\n# TYPE {name} counter\n{name} {cpu}"
        );
    }
}

/// A gauge with one label, one sample per value.
fn labelled(
    out: &mut String,
    name: &str,
    help: &str,
    label: &str,
    values: &[&str],
    counts: &[u64],
) {
    let _ = writeln!(out, "# HELP {name} {help}\n# TYPE {name} gauge");
    for (v, n) in values.iter().zip(counts) {
        let _ = writeln!(out, "{name}{{{label}=\"{v}\"}} {n}");
    }
}

/// Resident set size from `/proc/self/statm` (Linux); `None` elsewhere.
fn resident_memory_bytes() -> Option<u64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4096)
}

/// Clock ticks per second of the times in `/proc/PID/stat` (`USER_HZ`, fixed at 100
/// by the Linux ABI whatever the kernel's own tick rate).
const USER_HZ: f64 = 100.0;

/// User plus system CPU time of this process, all threads, from `/proc/self/stat`
/// (Linux); `None` elsewhere. Also read by `navguard loadgen` for its own share.
pub fn process_cpu_seconds() -> Option<f64> {
    cpu_seconds_of_stat(&std::fs::read_to_string("/proc/self/stat").ok()?)
}

/// `utime + stime` of a `/proc/PID/stat` line, seconds. The command name (field 2)
/// may hold spaces and parentheses, so fields are counted after its last `)`.
fn cpu_seconds_of_stat(stat: &str) -> Option<f64> {
    let after_name = &stat[stat.rfind(')')? + 1..];
    // After the name come field 3 (state) onwards; utime and stime are fields 14, 15.
    let mut fields = after_name.split_whitespace().skip(11);
    let utime: u64 = fields.next()?.parse().ok()?;
    let stime: u64 = fields.next()?.parse().ok()?;
    Some((utime + stime) as f64 / USER_HZ)
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
        let gauges = SessionGauges {
            consistency: [4, 1, 0, 2, 3],
            ..SessionGauges::default()
        };
        let text = m.render(3, &gauges);
        assert!(
            text.contains("navguard_tests_by_consistency{flag=\"correlated\"} 2"),
            "{text}"
        );
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
        // No entry committed yet: an empty histogram, every bucket 0.
        assert!(text.contains("navguard_alarm_commit_seconds_bucket{le=\"+Inf\"} 0"));
        m.observe_alarm_commit(Duration::from_millis(12));
        m.observe_alarm_commit(Duration::from_millis(30));
        let text = m.render(3, &gauges);
        for (bound, n) in [("0.01", 0), ("0.025", 1), ("0.05", 2), ("+Inf", 2)] {
            let line = format!("navguard_alarm_commit_seconds_bucket{{le=\"{bound}\"}} {n}\n");
            assert!(text.contains(&line), "{line} in {text}");
        }
        assert!(
            text.contains("navguard_alarm_commit_seconds_sum 0.042\n"),
            "{text}"
        );
        assert!(
            text.contains("navguard_alarm_commit_seconds_count 2\n"),
            "{text}"
        );
        // The frame histogram is untouched by alarm commits.
        assert!(
            text.contains("navguard_frame_latency_seconds_count 3\n"),
            "{text}"
        );
    }

    #[test]
    fn cpu_time_is_utime_plus_stime_after_the_command_name() {
        // A real line from proc(5)'s layout; the name holds a space and a parenthesis.
        let stat = "4242 (nav guard)) S 1 4242 4242 0 -1 4194560 2870 0 0 0 \
                    1234 56 0 0 20 0 9 0 123456 987654321 4321 18446744073709551615";
        assert_eq!(cpu_seconds_of_stat(stat), Some(12.9));
        assert_eq!(cpu_seconds_of_stat("4242 (x) S 1"), None);
        assert_eq!(cpu_seconds_of_stat("no name here"), None);
    }
}
