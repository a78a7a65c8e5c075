//! `navguard loadgen --ramp`: how far one node goes. Steps of ordinary loadgen
//! runs, each with `--ramp` more sessions than the last (the earlier sessions are
//! kept and streamed again), until the frame-to-result p99 reaches the limit, a
//! frame goes unanswered or a session fails, or `--ramp-max` sessions have been
//! streamed. Reports every step, the largest session count within the limit and
//! the memory per streaming session there, and draws the curve (sessions against
//! p50 and p99) as an SVG.

use std::sync::Arc;

use anyhow::Context;
use navguard_sim::plot::{Chart, Series};
use serde::Serialize;

use super::report::{Report, ms, rate_label};
use super::{
    LoadgenArgs, Workload, create_sessions, delete_sessions, measure, server_sample, session_ids,
    workload_label,
};
use crate::cli::http::Endpoint;
use crate::cli::thousands;

/// One step of a ramp: its run's report and whether it stayed within the limit.
#[derive(Debug, Clone, Serialize)]
struct Step {
    /// p99 under the limit, every frame answered, no session failed.
    within_limit: bool,
    /// The step's run (sessions, latency, memory, CPU).
    #[serde(flatten)]
    report: Report,
}

/// The ramp's report (`--json` prints it as is).
#[derive(Debug, Clone, Serialize)]
struct RampReport {
    /// Server URL.
    url: String,
    /// Monitor type.
    monitor: String,
    /// Frames per second per session (`null` for max).
    rate_hz: Option<f64>,
    /// Epochs per frame.
    batch: u64,
    /// Seconds each step streams.
    step_duration_s: f64,
    /// The frame-to-result p99 limit, ms.
    p99_limit_ms: f64,
    /// The largest session count of the steps within the limit before the first
    /// that was not (`null` if the first step was not).
    largest_within_limit: Option<u64>,
    /// (loaded RSS − RSS before the ramp) / sessions at that step, bytes.
    loaded_bytes_per_session: Option<f64>,
    /// Why the ramp stopped.
    stopped: String,
    /// Every step, in order.
    steps: Vec<Step>,
}

/// Whether a step's run stayed within `limit_ms`.
fn within_limit(report: &Report, limit_ms: f64) -> bool {
    report.failures.is_empty()
        && report.unanswered_frames == 0
        && report.frame_latency.count > 0
        && f64::from(report.frame_latency.p99_us) < limit_ms * 1000.0
}

/// The last step of the leading run of steps within the limit.
fn largest_within(steps: &[Step]) -> Option<&Step> {
    steps.iter().take_while(|s| s.within_limit).last()
}

/// Why a ramp stops after `step`, or `None` to go on.
fn stop_reason(step: &Step, limit_ms: f64, max: u64) -> Option<String> {
    let r = &step.report;
    if !r.failures.is_empty() {
        Some(format!(
            "{} session(s) failed at {} sessions",
            r.failures.len(),
            r.sessions
        ))
    } else if r.unanswered_frames > 0 {
        Some(format!(
            "{} frame(s) unanswered at {} sessions",
            r.unanswered_frames, r.sessions
        ))
    } else if !step.within_limit {
        Some(format!(
            "p99 {} ms ≥ {limit_ms} ms at {} sessions",
            ms(r.frame_latency.p99_us),
            r.sessions
        ))
    } else if r.sessions >= max {
        Some(format!("reached --ramp-max {max} within the limit"))
    } else {
        None
    }
}

/// Runs the ramp: first step `args.sessions`, then `step` more each time.
pub(super) async fn run(
    args: &LoadgenArgs,
    step: u64,
    endpoint: &Arc<Endpoint>,
    work: &Arc<Workload>,
) -> anyhow::Result<()> {
    let baseline = server_sample(endpoint).await?;
    let mut ids: Vec<String> = Vec::new();
    let mut steps: Vec<Step> = Vec::new();
    let mut target = args.sessions.min(args.ramp_max);
    let outcome = loop {
        let more = session_ids(ids.len() as u64..target);
        let created = create_sessions(endpoint, &work.spec, &more).await;
        ids.extend(more);
        if let Err(e) = created {
            break Err(e.context(format!("creating sessions for the step of {target}")));
        }
        let report = match measure(args, endpoint, work, &ids, baseline.clone()).await {
            Ok(report) => report,
            Err(e) => break Err(e),
        };
        let within_limit = within_limit(&report, args.ramp_p99_ms);
        let done = Step {
            within_limit,
            report,
        };
        if !args.json {
            eprintln!("{}", step_line(&done));
        }
        let stop = stop_reason(&done, args.ramp_p99_ms, args.ramp_max);
        steps.push(done);
        if let Some(reason) = stop {
            break Ok(reason);
        }
        target = (target + step).min(args.ramp_max);
    };
    let undeleted = delete_sessions(endpoint, ids).await;
    if undeleted > 0 {
        eprintln!("warning: {undeleted} sessions could not be deleted");
    }
    let stopped = outcome?;
    let best = largest_within(&steps);
    let report = RampReport {
        url: args.url.clone(),
        monitor: workload_label(args),
        rate_hz: args.rate.hz(),
        batch: args.batch,
        step_duration_s: args.duration,
        p99_limit_ms: args.ramp_p99_ms,
        largest_within_limit: best.map(|s| s.report.sessions),
        loaded_bytes_per_session: best.and_then(|s| s.report.loaded_bytes_per_session),
        stopped,
        steps,
    };
    if let Some(path) = &args.svg {
        std::fs::write(path, curve(&report).to_svg())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", render(&report));
    }
    Ok(())
}

/// One step as a progress line on stderr.
fn step_line(step: &Step) -> String {
    let r = &step.report;
    format!(
        "step {:>6} sessions: p50 {} ms, p99 {} ms, {} epochs/s{}",
        thousands(r.sessions),
        ms(r.frame_latency.p50_us),
        ms(r.frame_latency.p99_us),
        thousands(r.epochs_per_s.round() as u64),
        if step.within_limit { "" } else { "  (over)" }
    )
}

/// The ramp as a text table.
fn render(r: &RampReport) -> String {
    let rate = rate_label(r.rate_hz);
    let mut out = format!(
        "loadgen ramp → {}: {}, rate {rate}, batch {}, {} s a step, p99 limit {} ms\n",
        r.url, r.monitor, r.batch, r.step_duration_s, r.p99_limit_ms
    );
    out.push_str(
        "  sessions   p50 ms   p99 ms  p99.9 ms   epochs/s  MiB loaded  KiB/session  \
         cores srv/gen\n",
    );
    let or_dash = |v: Option<f64>, f: &dyn Fn(f64) -> String| v.map_or("-".into(), f);
    for step in &r.steps {
        let s = &step.report;
        out.push_str(&format!(
            "  {:>8} {:>8} {:>8} {:>9} {:>10} {:>11} {:>12}  {} / {}{}\n",
            thousands(s.sessions),
            ms(s.frame_latency.p50_us),
            ms(s.frame_latency.p99_us),
            ms(s.frame_latency.p999_us),
            thousands(s.epochs_per_s.round() as u64),
            or_dash(s.rss_loaded_bytes.map(|b| b as f64), &|b| format!(
                "{:.1}",
                b / 1048576.0
            )),
            or_dash(s.loaded_bytes_per_session, &|b| format!(
                "{:.1}",
                b / 1024.0
            )),
            or_dash(s.cpu.server_cores, &|c| format!("{c:.2}")),
            or_dash(s.cpu.loadgen_cores, &|c| format!("{c:.2}")),
            if step.within_limit { "" } else { "  over" }
        ));
    }
    let largest = r
        .largest_within_limit
        .map_or("none".into(), |n| format!("{} sessions", thousands(n)));
    out.push_str(&format!(
        "  largest within the limit: {largest}; memory per streaming session there: {}\n",
        r.loaded_bytes_per_session
            .map_or("-".into(), |b| format!("{:.1} KiB", b / 1024.0))
    ));
    out.push_str(&format!("  stopped: {}\n", r.stopped));
    out
}

/// Sessions against frame-to-result p50 and p99 (log ms) with the limit drawn.
fn curve(r: &RampReport) -> Chart {
    let points = |pick: fn(&Report) -> u32| {
        r.steps
            .iter()
            .map(|s| {
                (
                    s.report.sessions as f64,
                    f64::from(pick(&s.report)) / 1000.0,
                )
            })
            .collect::<Vec<_>>()
    };
    let rate = rate_label(r.rate_hz);
    Chart::new(
        format!(
            "loadgen ramp: {} sessions at {rate}, batch {}, {} s a step",
            r.monitor, r.batch, r.step_duration_s
        ),
        "sessions",
        "frame → result latency (ms)",
    )
    .with_series(Series::new("p50", points(|r| r.frame_latency.p50_us)))
    .with_series(Series::new("p99", points(|r| r.frame_latency.p99_us)))
    .with_threshold(r.p99_limit_ms, format!("p99 limit {} ms", r.p99_limit_ms))
    .with_log_y(true)
}

#[cfg(test)]
mod tests {
    use super::super::report::{CpuShare, Percentiles};
    use super::*;

    fn step(sessions: u64, p50_us: u32, p99_us: u32, unanswered: u64) -> Step {
        let report = Report {
            url: "ws://x".into(),
            monitor: "federated".into(),
            sessions,
            rate_hz: Some(10.0),
            batch: 1,
            wall_s: 10.0,
            epochs_sent: 100 * sessions,
            frames_sent: 100 * sessions,
            results: 100 * sessions,
            out_of_order: 0,
            unanswered_frames: unanswered,
            passes: sessions,
            epochs_per_s: 10.0 * sessions as f64,
            frames_per_s: 10.0 * sessions as f64,
            frame_latency: Percentiles {
                count: 100 * sessions,
                p50_us,
                p99_us,
                p999_us: p99_us,
                max_us: p99_us,
            },
            alarm_latency: Percentiles::default(),
            alarm_commit: None,
            alarms: 0,
            state_changes: 0,
            errors: Default::default(),
            failures: Vec::new(),
            rss_baseline_bytes: Some(1 << 20),
            rss_idle_bytes: Some(2 << 20),
            rss_loaded_bytes: Some((1 << 20) + sessions * 10_240),
            idle_bytes_per_session: None,
            loaded_bytes_per_session: Some(10_240.0),
            cpu: CpuShare::new(Some(1.5), Some(0.5)),
        };
        Step {
            within_limit: within_limit(&report, 5.0),
            report,
        }
    }

    #[test]
    fn the_limit_is_strict_and_needs_every_frame_answered() {
        assert!(step(500, 400, 4_999, 0).within_limit);
        assert!(!step(500, 400, 5_000, 0).within_limit);
        assert!(!step(500, 400, 1_000, 3).within_limit);
    }

    #[test]
    fn the_largest_count_is_the_last_of_the_leading_steps_within() {
        let steps = vec![
            step(250, 300, 1_000, 0),
            step(500, 400, 3_000, 0),
            step(750, 600, 7_000, 0),
            // A later step back under the limit does not count: the ramp stopped before.
            step(1000, 500, 4_000, 0),
        ];
        assert_eq!(largest_within(&steps).map(|s| s.report.sessions), Some(500));
        assert!(largest_within(&steps[2..]).is_none());
    }

    #[test]
    fn a_ramp_stops_over_the_limit_on_a_lost_frame_or_at_the_maximum() {
        assert_eq!(stop_reason(&step(500, 400, 3_000, 0), 5.0, 1000), None);
        let over = stop_reason(&step(750, 600, 7_000, 0), 5.0, 1000).unwrap();
        assert_eq!(over, "p99 7.000 ms ≥ 5 ms at 750 sessions");
        let lost = stop_reason(&step(750, 600, 3_000, 2), 5.0, 1000).unwrap();
        assert!(lost.starts_with("2 frame(s) unanswered"), "{lost}");
        let max = stop_reason(&step(1000, 600, 3_000, 0), 5.0, 1000).unwrap();
        assert!(max.contains("--ramp-max 1000"), "{max}");
    }

    #[test]
    fn the_curve_has_one_point_per_step_in_ms_and_the_limit() {
        let report = RampReport {
            url: "ws://x".into(),
            monitor: "linear".into(),
            rate_hz: Some(10.0),
            batch: 1,
            step_duration_s: 10.0,
            p99_limit_ms: 5.0,
            largest_within_limit: Some(500),
            loaded_bytes_per_session: Some(10_240.0),
            stopped: "test".into(),
            steps: vec![step(250, 300, 1_000, 0), step(500, 400, 3_000, 0)],
        };
        let chart = curve(&report);
        assert_eq!(chart.series[0].points, vec![(250.0, 0.3), (500.0, 0.4)]);
        assert_eq!(chart.series[1].points, vec![(250.0, 1.0), (500.0, 3.0)]);
        assert_eq!(chart.threshold.as_ref().map(|t| t.y), Some(5.0));
        assert!(chart.log_y);
        let svg = chart.to_svg();
        assert!(
            svg.starts_with("<svg") && svg.contains("p99 limit 5 ms"),
            "{svg}"
        );
        let table = render(&report);
        assert!(
            table.contains("largest within the limit: 500 sessions"),
            "{table}"
        );
        assert!(table.contains("10.0 KiB"), "{table}");
    }
}
