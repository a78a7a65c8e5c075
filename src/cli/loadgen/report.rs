//! The report of `navguard loadgen`: latency percentiles, the figures it
//! prints, and their text table (`--json` prints the struct).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::Serialize;

use crate::cli::thousands;

/// Latency percentiles, microseconds.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub(super) struct Percentiles {
    /// Observations.
    pub count: u64,
    /// Median.
    pub p50_us: u32,
    /// 99th percentile.
    pub p99_us: u32,
    /// 99.9th percentile.
    pub p999_us: u32,
    /// Largest.
    pub max_us: u32,
}

/// Nearest-rank percentiles of `samples` (sorted in place).
pub(super) fn percentiles(samples: &mut [u32]) -> Percentiles {
    if samples.is_empty() {
        return Percentiles::default();
    }
    samples.sort_unstable();
    let n = samples.len();
    let rank = |p: f64| samples[((p * n as f64).ceil() as usize).clamp(1, n) - 1];
    Percentiles {
        count: n as u64,
        p50_us: rank(0.50),
        p99_us: rank(0.99),
        p999_us: rank(0.999),
        max_us: samples[n - 1],
    }
}

/// CPU spent over the stream, in cores (CPU seconds / wall seconds): the
/// server's and the load generator's own, which shares the machine in a
/// same-host run.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub(super) struct CpuShare {
    /// Server cores (`process_cpu_seconds_total`); `None` if it does not export it.
    pub server_cores: Option<f64>,
    /// Load generator cores (its `/proc/self/stat`); `None` off Linux.
    pub loadgen_cores: Option<f64>,
    /// loadgen / (server + loadgen), when both are known.
    pub loadgen_fraction: Option<f64>,
}

impl CpuShare {
    pub(super) fn new(server_cores: Option<f64>, loadgen_cores: Option<f64>) -> Self {
        let loadgen_fraction = match (server_cores, loadgen_cores) {
            (Some(s), Some(l)) if s + l > 0.0 => Some(l / (s + l)),
            _ => None,
        };
        CpuShare {
            server_cores,
            loadgen_cores,
            loadgen_fraction,
        }
    }
}

/// The server's own time to commit the log entries raised during the stream, from the
/// difference of its `navguard_alarm_commit_seconds` histogram before and after: the wait
/// in the alarm writer's queue and the shared transaction, which every alarm pays before
/// it is announced. Percentiles are the upper bounds of the buckets they fall in.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub(super) struct CommitShare {
    /// Entries committed over the stream.
    pub count: u64,
    /// The median is at most this, ms (`None` past the last finite bucket).
    pub p50_le_ms: Option<f64>,
    /// The 99th percentile is at most this, ms (`None` past the last finite bucket).
    pub p99_le_ms: Option<f64>,
}

impl CommitShare {
    /// From the cumulative buckets `(upper bound s, count)` read before and after the
    /// stream (the same bounds, `+Inf` last); `None` when the server has no such histogram
    /// or the two readings do not line up.
    pub(super) fn between(before: &[(f64, u64)], after: &[(f64, u64)]) -> Option<Self> {
        if after.is_empty() || before.len() != after.len() {
            return None;
        }
        let diff: Vec<(f64, u64)> = before
            .iter()
            .zip(after)
            .map(|(&(b, n0), &(a, n1))| (b == a).then(|| (a, n1.saturating_sub(n0))))
            .collect::<Option<_>>()?;
        let count = diff.last().map_or(0, |&(_, n)| n);
        // None with nothing counted, or when the rank lies past the last finite bound.
        let bound = |q: f64| {
            let rank = (q * count as f64).ceil() as u64;
            diff.iter()
                .find(|&&(_, n)| count > 0 && n >= rank)
                .and_then(|&(b, _)| b.is_finite().then_some(b * 1e3))
        };
        Some(CommitShare {
            count,
            p50_le_ms: bound(0.50),
            p99_le_ms: bound(0.99),
        })
    }
}

/// The report (`--json` prints it as is).
#[derive(Debug, Clone, Serialize)]
pub(super) struct Report {
    /// Server URL.
    pub url: String,
    /// Monitor type.
    pub monitor: String,
    /// Sessions streamed.
    pub sessions: u64,
    /// Frames per second per session (`null` for max).
    pub rate_hz: Option<f64>,
    /// Epochs per frame.
    pub batch: u64,
    /// Seconds from the first send to the last answer.
    pub wall_s: f64,
    /// Epochs sent.
    pub epochs_sent: u64,
    /// Frames sent.
    pub frames_sent: u64,
    /// `result` messages received.
    pub results: u64,
    /// Results whose `t` was not the next epoch sent.
    pub out_of_order: u64,
    /// Frames without an answer when the tool gave up waiting.
    pub unanswered_frames: u64,
    /// Sockets opened (one per session per pass over the workload).
    pub passes: u64,
    /// Results per second over `wall_s`.
    pub epochs_per_s: f64,
    /// Answered frames per second over `wall_s`.
    pub frames_per_s: f64,
    /// Frame sent → result of its last epoch.
    pub frame_latency: Percentiles,
    /// Frame holding the alarm's epoch sent → alarm received.
    pub alarm_latency: Percentiles,
    /// The server's commit of the log entries before announcing them (its part of the
    /// alarm latency); `None` for a server without the histogram.
    pub alarm_commit: Option<CommitShare>,
    /// Alarms received.
    pub alarms: u64,
    /// State changes received.
    pub state_changes: u64,
    /// Error events by code.
    pub errors: BTreeMap<String, u64>,
    /// Sessions that failed (connection refused, socket dropped), up to five.
    pub failures: Vec<String>,
    /// Server RSS before creating the sessions, bytes.
    pub rss_baseline_bytes: Option<u64>,
    /// Server RSS with the sessions created and idle, bytes.
    pub rss_idle_bytes: Option<u64>,
    /// Server RSS at the end of the stream, bytes.
    pub rss_loaded_bytes: Option<u64>,
    /// (idle − baseline) / sessions, bytes.
    pub idle_bytes_per_session: Option<f64>,
    /// (loaded − baseline) / sessions, bytes: memory per streaming session.
    pub loaded_bytes_per_session: Option<f64>,
    /// CPU over the stream.
    pub cpu: CpuShare,
}

pub(super) fn ms(us: u32) -> String {
    format!("{:.3}", f64::from(us) / 1000.0)
}

/// `10 Hz`, or `max` for a run as fast as the server takes frames.
pub(super) fn rate_label(rate_hz: Option<f64>) -> String {
    rate_hz.map_or("max".into(), |hz| format!("{hz} Hz"))
}

pub(super) fn mib(bytes: Option<u64>) -> String {
    bytes.map_or("-".into(), |b| format!("{:.1} MiB", b as f64 / 1048576.0))
}

/// One row of the table: the label padded to a column, then the value.
fn row(out: &mut String, k: &str, v: String) {
    let _ = writeln!(out, "  {k:<28} {v}");
}

/// The report as a text table: the run, its throughput, its latencies, what came
/// back, what the server used, then any failures.
pub(super) fn render(r: &Report) -> String {
    let mut out = String::new();
    let rate = rate_label(r.rate_hz);
    let _ = writeln!(
        out,
        "loadgen → {}: {} × {} session(s), rate {rate}, batch {}",
        r.url, r.monitor, r.sessions, r.batch
    );
    render_throughput(&mut out, r);
    render_latency(&mut out, r);
    render_answers(&mut out, r);
    render_resources(&mut out, r);
    for f in &r.failures {
        row(&mut out, "failure", f.clone());
    }
    out
}

/// Wall time, epochs and frames sent and answered, and their rates.
fn render_throughput(out: &mut String, r: &Report) {
    row(out, "wall time", format!("{:.2} s", r.wall_s));
    row(
        out,
        "epochs sent / results",
        format!("{} / {}", thousands(r.epochs_sent), thousands(r.results)),
    );
    row(out, "frames sent", thousands(r.frames_sent));
    row(
        out,
        "epochs/s (results)",
        thousands(r.epochs_per_s.round() as u64),
    );
    row(
        out,
        "frames/s (answered)",
        thousands(r.frames_per_s.round() as u64),
    );
}

/// `p50 …  p99 …  p99.9 …  max … ms  (n = …)`, or `-` with no observation.
fn percentiles_text(p: &Percentiles) -> String {
    if p.count == 0 {
        "-".to_owned()
    } else {
        format!(
            "p50 {}  p99 {}  p99.9 {}  max {} ms  (n = {})",
            ms(p.p50_us),
            ms(p.p99_us),
            ms(p.p999_us),
            ms(p.max_us),
            thousands(p.count)
        )
    }
}

/// Frame and alarm latencies, and the server's commit share of the alarm's.
fn render_latency(out: &mut String, r: &Report) {
    row(
        out,
        "frame → result latency",
        percentiles_text(&r.frame_latency),
    );
    row(
        out,
        "alarm → event latency",
        percentiles_text(&r.alarm_latency),
    );
    if let Some(c) = r.alarm_commit.filter(|c| c.count > 0) {
        let le = |v: Option<f64>| v.map_or("over the last bucket".into(), |v| format!("≤ {v}"));
        row(
            out,
            "  of which server commit",
            format!(
                "p50 {}  p99 {} ms  (n = {})",
                le(c.p50_le_ms),
                le(c.p99_le_ms),
                thousands(c.count)
            ),
        );
    }
}

/// Alarms and state changes, errors by code, ordering and unanswered frames, sockets.
fn render_answers(out: &mut String, r: &Report) {
    row(
        out,
        "alarms / state changes",
        format!("{} / {}", r.alarms, r.state_changes),
    );
    let errors = if r.errors.is_empty() {
        "none".to_owned()
    } else {
        r.errors
            .iter()
            .map(|(code, n)| format!("{code} {n}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    row(out, "errors", errors);
    row(
        out,
        "out of order / unanswered",
        format!("{} / {}", r.out_of_order, r.unanswered_frames),
    );
    row(out, "sockets (passes)", thousands(r.passes));
}

/// The server's memory (total and per session) and the CPU of both processes.
fn render_resources(out: &mut String, r: &Report) {
    row(
        out,
        "server RSS base/idle/loaded",
        format!(
            "{} / {} / {}",
            mib(r.rss_baseline_bytes),
            mib(r.rss_idle_bytes),
            mib(r.rss_loaded_bytes)
        ),
    );
    let kib = |b: Option<f64>| b.map_or("-".into(), |b| format!("{:.1} KiB", b / 1024.0));
    row(
        out,
        "memory per session idle/loaded",
        format!(
            "{} / {}",
            kib(r.idle_bytes_per_session),
            kib(r.loaded_bytes_per_session)
        ),
    );
    let cores = |c: Option<f64>| c.map_or("-".into(), |c| format!("{c:.2}"));
    row(
        out,
        "CPU cores server/loadgen",
        format!(
            "{} / {}{}",
            cores(r.cpu.server_cores),
            cores(r.cpu.loadgen_cores),
            r.cpu.loadgen_fraction.map_or(String::new(), |f| format!(
                "  (loadgen {:.0} % of the two)",
                100.0 * f
            ))
        ),
    );
}
