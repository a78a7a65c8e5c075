//! The drive's tables (text) and figures (SVG): the fault-free errors per seed, the error
//! at the end of each outage, the attitude beside the GNSS course, alarms per hour, the
//! faults' delays; the trajectory, the error against time with the outages shaded, and
//! the GNSS test statistics.

use std::fmt::Write as _;

use super::{DriveResult, DriveRun, ErrSample, FaultRow};
use crate::plot::{Chart, Series};
use navguard_core::session::Severity;

/// Seconds after alignment left out of the error statistics (the filter converging).
pub const SETTLE_S: f64 = 30.0;
/// Speed above which the yaw is compared with the GNSS course, m/s.
const COURSE_SPEED_MPS: f64 = 5.0;

/// Root mean square (0 for none).
fn rms(v: impl Iterator<Item = f64>) -> f64 {
    let (n, s) = v.fold((0usize, 0.0), |(n, s), x| (n + 1, s + x * x));
    if n == 0 { 0.0 } else { (s / n as f64).sqrt() }
}

/// A wrapped angle difference a − b in (−180, 180], degrees.
fn wrap_deg(d: f64) -> f64 {
    let w = (d + 180.0).rem_euclid(360.0) - 180.0;
    if w == -180.0 { 180.0 } else { w }
}

/// The fault-free figures of one run (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FreeStats {
    /// Horizontal error RMS and max outside outages (after settling), m.
    pub h_rms: f64,
    /// Max.
    pub h_max: f64,
    /// Vertical RMS, m.
    pub v_rms: f64,
    /// Velocity error RMS and max, m/s.
    pub vel_rms: f64,
    /// Max.
    pub vel_max: f64,
    /// Yaw − course (speed > 5 m/s): mean and standard deviation, degrees.
    pub yaw_course: (f64, f64),
    /// Mean pitch and roll, degrees.
    pub pitch_roll: (f64, f64),
    /// Alarms and warnings per hour of drive.
    pub per_hour: (f64, f64),
}

/// The figures of a fault-free run with `outages` of `outage_s`.
pub fn free_stats(run: &DriveRun, outages: &[f64], outage_s: f64) -> FreeStats {
    let settle = run.aligned_at.unwrap_or(0.0) + SETTLE_S;
    let in_outage = |t: f64| outages.iter().any(|&s| (s..s + outage_s).contains(&t));
    let kept: Vec<&ErrSample> = run
        .errors
        .iter()
        .filter(|s| s.t >= settle && !in_outage(s.t))
        .collect();
    let moving: Vec<f64> = kept
        .iter()
        .filter(|s| s.course.1 > COURSE_SPEED_MPS)
        .map(|s| wrap_deg(s.att[2] - s.course.0))
        .collect();
    let n = moving.len().max(1) as f64;
    let mean = moving.iter().sum::<f64>() / n;
    let std = (moving.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / n).sqrt();
    let m = kept.len().max(1) as f64;
    let hours = run.duration_s / 3600.0;
    let count = |sev: Severity| run.entries.iter().filter(|e| e.severity == sev).count() as f64;
    FreeStats {
        h_rms: rms(kept.iter().map(|s| s.horizontal())),
        h_max: kept.iter().map(|s| s.horizontal()).fold(0.0, f64::max),
        v_rms: rms(kept.iter().map(|s| s.pos[2])),
        vel_rms: rms(kept.iter().map(|s| s.vel)),
        vel_max: kept.iter().map(|s| s.vel).fold(0.0, f64::max),
        yaw_course: (mean, std),
        pitch_roll: (
            kept.iter().map(|s| s.att[1]).sum::<f64>() / m,
            kept.iter().map(|s| s.att[0]).sum::<f64>() / m,
        ),
        per_hour: (
            count(Severity::Alarm) / hours,
            count(Severity::Warning) / hours,
        ),
    }
}

/// Per outage: the horizontal error at its end and the largest within it, m.
pub fn outage_growth(run: &DriveRun, outages: &[f64], outage_s: f64) -> Vec<(f64, f64, f64)> {
    outages
        .iter()
        .map(|&s| {
            let inside: Vec<&ErrSample> = run
                .errors
                .iter()
                .filter(|e| (s..s + outage_s).contains(&e.t))
                .collect();
            let end = inside.last().map_or(f64::NAN, |e| e.horizontal());
            let max = inside.iter().map(|e| e.horizontal()).fold(0.0, f64::max);
            (s, end, max)
        })
        .collect()
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("—".into(), |x| format!("{x:.digits$}"))
}

/// The tables.
pub fn render(r: &DriveResult) -> String {
    let p = &r.params;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "GNSS aid: {} Hz, σ {} m horizontal, {} m vertical, {} m/s; outages of {} s at {:?} s; p_fa {}",
        p.noise.rate_hz,
        p.noise.pos_sigma_h_m,
        p.noise.pos_sigma_v_m,
        p.noise.vel_sigma_mps,
        p.outage_s,
        p.outages,
        p.p_fa
    );
    let _ = writeln!(
        s,
        "\nFault-free, against the RTK reference (outside outages, from {SETTLE_S} s after alignment):"
    );
    let _ = writeln!(
        s,
        "seed | aligned at s | horiz RMS m | horiz max m | vert RMS m | vel RMS m/s | vel max m/s | yaw−course ° (mean ± sd) | pitch ° | roll ° | alarms/h | warnings/h | converging/available/unavailable epochs"
    );
    for row in &r.free {
        let f = free_stats(&row.run, &p.outages, p.outage_s);
        let c = row.run.integrity_counts;
        let _ = writeln!(
            s,
            "{} | {} | {:.2} | {:.2} | {:.2} | {:.3} | {:.3} | {:+.2} ± {:.2} | {:+.2} | {:+.2} | {:.1} | {:.1} | {}/{}/{}",
            row.seed,
            opt(row.run.aligned_at, 2),
            f.h_rms,
            f.h_max,
            f.v_rms,
            f.vel_rms,
            f.vel_max,
            f.yaw_course.0,
            f.yaw_course.1,
            f.pitch_roll.0,
            f.pitch_roll.1,
            f.per_hour.0,
            f.per_hour.1,
            c[0],
            c[1],
            c[2]
        );
    }
    let _ = writeln!(
        s,
        "\nHorizontal error over each {} s outage (end / max, m):",
        p.outage_s
    );
    let _ = writeln!(
        s,
        "seed | {}",
        p.outages
            .iter()
            .map(|o| format!("from {o} s"))
            .collect::<Vec<_>>()
            .join(" | ")
    );
    for row in &r.free {
        let g = outage_growth(&row.run, &p.outages, p.outage_s);
        let cells: Vec<String> = g
            .iter()
            .map(|(_, end, max)| format!("{end:.2} / {max:.2}"))
            .collect();
        let _ = writeln!(s, "{} | {}", row.seed, cells.join(" | "));
    }
    render_faults(&mut s, &r.faults, p.fault_s);
    s
}

/// The faults table: one row per fault, start and seed.
fn render_faults(s: &mut String, faults: &[FaultRow], fault_s: f64) {
    let _ = writeln!(
        s,
        "\nInjected GNSS faults ({fault_s} s each, no outages; delays in s from the fault's start, — for none within it):"
    );
    let _ = writeln!(
        s,
        "fault | start s | seed | rejected s | isolated s | gnss.stuck s | injected error at rejection m | at isolation m | worst solution error m | alarms"
    );
    for f in faults {
        let _ = writeln!(
            s,
            "{} | {} | {} | {} | {} | {} | {} | {} | {:.2} | {}",
            f.kind.label(),
            f.start,
            f.seed,
            opt(f.rejected_s, 2),
            opt(f.isolated_s, 2),
            opt(f.stuck_s, 2),
            opt(f.injected_at_rejection_m, 2),
            opt(f.injected_at_isolation_m, 2),
            f.worst_error_m,
            f.alarms
        );
    }
}

/// The figures of the first fault-free run: trajectory, error against time with the
/// outages shaded, and the `gnss` test's statistic against its threshold.
pub fn plots(r: &DriveResult) -> Vec<(String, String)> {
    let Some(row) = r.free.first() else {
        return Vec::new();
    };
    let p = &r.params;
    let run = &row.run;
    let bands: Vec<(f64, f64)> = p.outages.iter().map(|&s| (s, s + p.outage_s)).collect();
    let track = Chart::new(
        "The drive: solution track (antenna), east/north from the start",
        "east, m",
        "north, m",
    )
    .with_series(Series::new(
        "solution",
        run.errors
            .iter()
            .map(|e| (e.track[0], e.track[1]))
            .collect(),
    ));
    let horizontal = Chart::new(
        format!(
            "Horizontal error against the RTK reference (seed {}; outages shaded)",
            row.seed
        ),
        "t, s from the start",
        "error, m",
    )
    .with_bands(bands.clone())
    .with_series(Series::new(
        "horizontal",
        run.errors.iter().map(|e| (e.t, e.horizontal())).collect(),
    ))
    .with_series(Series::new(
        "vertical |up|",
        run.errors.iter().map(|e| (e.t, e.pos[2].abs())).collect(),
    ));
    let gnss: Vec<(f64, f64)> = run
        .tests
        .iter()
        .filter(|t| t.name == "gnss")
        .map(|t| (t.t, t.statistic))
        .collect();
    let threshold = run
        .tests
        .iter()
        .find(|t| t.name == "gnss")
        .map_or(f64::NAN, |t| t.threshold);
    let stats = Chart::new(
        "The gnss test's λ (dof 6) on the fault-free drive",
        "t, s from the start",
        "λ",
    )
    .with_bands(bands)
    .with_log_y(true)
    .with_series(Series::new("gnss λ", gnss))
    .with_threshold(threshold, format!("threshold {threshold:.1}"));
    vec![
        ("drive_track.svg".into(), track.to_svg()),
        ("drive_error.svg".into(), horizontal.to_svg()),
        ("drive_gnss_test.svg".into(), stats.to_svg()),
    ]
}
