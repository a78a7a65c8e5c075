//! One run of the drive through the session core: the epochs (IMU with the aid attached)
//! stepped as the server steps them, and what the experiment measures of it — the
//! solution against the RTK reference at 4 Hz, the GNSS tests, the isolation of the aid,
//! the alarm-log entries, the integrity, and the attitude beside the GNSS course.

use nalgebra::Vector3;
use serde_json::Value;

use navguard_core::detect::Health;
use navguard_core::epoch::Epoch;
use navguard_core::geo::{self, Lla};
use navguard_core::monitor::{self, MonitorReport, MonitorSpec};
use navguard_core::session::{AlarmLevel, Seat, SessionCore};

use super::RefFix;
use super::aid::reference_at;
use crate::experiment::{ExperimentError, LogEntry, integrity_slot};

/// IMU epochs between two error samples (4 Hz at 100 Hz).
const ERROR_EVERY: usize = 25;

/// The solution against the reference at one epoch (antenna positions, ENU).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrSample {
    /// Seconds from the drive's start.
    pub t: f64,
    /// Solution − reference, east, north, up, m.
    pub pos: [f64; 3],
    /// |velocity error|, m/s.
    pub vel: f64,
    /// The solution's east and north from the drive's first reference fix, m.
    pub track: [f64; 2],
    /// Roll, pitch, yaw of the solution, degrees.
    pub att: [f64; 3],
    /// The reference's course (degrees clockwise from north) and horizontal speed, m/s.
    pub course: (f64, f64),
}

impl ErrSample {
    /// Horizontal error, m.
    pub fn horizontal(&self) -> f64 {
        self.pos[0].hypot(self.pos[1])
    }
}

/// One GNSS test's outcome at one epoch.
#[derive(Debug, Clone, PartialEq)]
pub struct TestRow {
    /// Seconds from the drive's start.
    pub t: f64,
    /// `gnss`, `gnss.drift`, `gnss.stuck`.
    pub name: String,
    /// λ and its threshold.
    pub statistic: f64,
    /// Threshold.
    pub threshold: f64,
    /// Health after the epoch.
    pub health: Health,
}

/// What one run did.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveRun {
    /// When the front end was aligned, s from the start.
    pub aligned_at: Option<f64>,
    /// The solution's errors at 4 Hz once aligned.
    pub errors: Vec<ErrSample>,
    /// Every GNSS test outcome.
    pub tests: Vec<TestRow>,
    /// Times (s from the start) at which the aid went in and out of isolation.
    pub isolation: Vec<(f64, bool)>,
    /// The alarm-log entries (times from the start).
    pub entries: Vec<LogEntry>,
    /// IMU epochs converging, available, unavailable.
    pub integrity_counts: [usize; 3],
    /// The drive's length, s.
    pub duration_s: f64,
}

impl DriveRun {
    /// The first time at or after `from` when a GNSS test is not healthy (the aid's
    /// detection); with `name`, that test only.
    pub fn first_unhealthy(&self, from: f64, name: Option<&str>) -> Option<f64> {
        self.tests
            .iter()
            .filter(|r| name.is_none_or(|n| r.name == n))
            .find(|r| r.t >= from && r.health != Health::Healthy)
            .map(|r| r.t)
    }

    /// The first time at or after `from` when the aid is isolated (left out of fusion).
    pub fn first_isolated(&self, from: f64) -> Option<f64> {
        self.isolation
            .iter()
            .find(|&&(t, isolated)| t >= from && isolated)
            .map(|&(t, _)| t)
    }
}

/// A solution read from the outputs: position, ENU velocity (m/s), attitude (degrees).
type Solution = (Lla, Vector3<f64>, [f64; 3]);

/// The monitor's outputs in their wire shape (docs/architecture.md §A6): the solution
/// and whether `gnss` is isolated.
fn read_outputs(report: &MonitorReport) -> (Option<Solution>, bool) {
    let v = serde_json::to_value(&report.outputs).unwrap_or(Value::Null);
    let isolated = v["isolated"]
        .as_array()
        .is_some_and(|a| a.iter().any(|x| x == "gnss"));
    let s = &v["solution"];
    let num = |x: &Value| x.as_f64();
    let triple = |x: &Value| Some([num(&x[0])?, num(&x[1])?, num(&x[2])?]);
    let solution = (|| {
        let lla = Lla {
            lat: num(&s["lat"])?.to_radians(),
            lon: num(&s["lon"])?.to_radians(),
            h: num(&s["h"])?,
        };
        Some((lla, Vector3::from(triple(&s["vel"])?), triple(&s["att"])?))
    })();
    (solution, isolated)
}

/// Steps `epochs` through a session of the monitor `spec`, measuring against
/// `reference` with the antenna at `lever_b` (body, right/forward/up) from the IMU.
pub(super) fn run(
    epochs: &[Epoch],
    reference: &[RefFix],
    spec: &MonitorSpec,
    lever_b: Vector3<f64>,
) -> Result<DriveRun, ExperimentError> {
    let seat = Seat {
        name: "drive".into(),
        monitor: monitor::build(spec, &monitor::NoModels)?,
        alarm_level: AlarmLevel::default(),
    };
    let mut core = SessionCore::new("drive", vec![seat], 0);
    let t0 = epochs.first().map_or(0.0, |e| e.t);
    let Some(origin) = reference.first().map(|r| r.lla) else {
        return Err(ExperimentError::NoSolution(0.0));
    };
    let mut out = DriveRun {
        aligned_at: None,
        errors: Vec::new(),
        tests: Vec::new(),
        isolation: Vec::new(),
        entries: Vec::new(),
        integrity_counts: [0; 3],
        duration_s: epochs.last().map_or(0.0, |e| e.t - t0),
    };
    let mut effects = Vec::new();
    let mut was_isolated = false;
    for (k, e) in epochs.iter().enumerate() {
        let (reports, failure) = core.step(e);
        if let Some((_, source)) = failure {
            return Err(ExperimentError::Step { t: e.t, source });
        }
        let Some(report) = reports.first().and_then(Option::as_ref) else {
            return Err(ExperimentError::NoSolution(e.t));
        };
        let rel = e.t - t0;
        record_tests(&mut out, report, rel);
        let (solution, isolated) = read_outputs(report);
        if isolated != was_isolated {
            out.isolation.push((rel, isolated));
            was_isolated = isolated;
        }
        if let Some((lla, vel, att)) = solution {
            out.aligned_at.get_or_insert(rel);
            let sample = (k % ERROR_EVERY == 0)
                .then(|| error_sample(reference, e.t, rel, (lla, vel, att), &lever_b, &origin))
                .flatten();
            out.errors.extend(sample);
        }
        core.commit(e, &reports, &mut effects);
        out.entries.extend(effects.drain(..).filter_map(|x| {
            x.entry().map(|entry| LogEntry {
                t: entry.t - t0,
                test: entry.test.clone(),
                state: entry.state,
                severity: entry.severity,
            })
        }));
    }
    Ok(out)
}

/// The epoch's GNSS test outcomes and integrity into `out`.
fn record_tests(out: &mut DriveRun, report: &MonitorReport, rel: f64) {
    for o in &report.tests {
        out.tests.push(TestRow {
            t: rel,
            name: o.name.to_string(),
            statistic: o.statistic.value,
            threshold: o.statistic.threshold,
            health: o.decision.health,
        });
    }
    if let Some(i) = report.integrity {
        out.integrity_counts[integrity_slot(i.state)] += 1;
    }
}

/// The solution moved to the antenna (`p + C_bⁿ l`) against the reference at `t`.
fn error_sample(
    reference: &[RefFix],
    t: f64,
    rel: f64,
    (lla, vel, att): Solution,
    lever_b: &Vector3<f64>,
    origin: &Lla,
) -> Option<ErrSample> {
    let (ref_lla, ref_vel) = reference_at(reference, t)?;
    let [r, p, y] = att.map(f64::to_radians);
    let antenna = geo::apply_offset(&lla, &(geo::dcm_body_to_nav(r, p, y) * lever_b));
    let d = geo::local_offset(&antenna, &ref_lla);
    let track = geo::local_offset(&antenna, origin);
    let course = ref_vel.x.atan2(ref_vel.y).to_degrees().rem_euclid(360.0);
    Some(ErrSample {
        t: rel,
        pos: [d.x, d.y, d.z],
        vel: (vel - ref_vel).norm(),
        track: [track.x, track.y],
        att,
        course: (course, ref_vel.xy().norm()),
    })
}
