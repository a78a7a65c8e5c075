//! Experiments: the papers' experiments end to end, their scorecards and plots.
//! Sits at the end of the core's flow: a scenario from [`crate`] runs
//! through a monitor in-process ([`run_monitor`]); the result structs carry the
//! figures, the renderers turn them into the text tables and SVG plots the CLI
//! writes. No I/O here.
//!
//! - [`seed002`]: seed 002's redundant-gyro isolation (parity FSS test + wavelet-packet
//!   C-SVC) on the `rimu` scenario, with and without the classifier.
//! - [`seed003`]: seed 003's one-class SVM detection of TACAN range jumps at
//!   noise variances 5, 10, 20 m² (its Fig. 6).
//! - [`seed004`]: seed 004's comparison of the classic and counter policies at
//!   thresholds 13 and 20 on the `ship` scenario (its Tables 1–3, Figs. 3–10).
//! - [`seed000`]: seed 000's plain vs locally weighted LS-SVM channel prediction and
//!   missed-detection rates (its Fig. 3 and Table 2) on the `ads-gnss` scenario.
//! - [`seed001`]: seed 001's online vs batch vs global LS-SVM, IMU fault modes and
//!   outlier filter on the `imu-channel` scenario.
//! - [`ramp`]: docs/methods.md §M19's slow GNSS drift benchmark (with §M23's drift test).
//! - [`coloured`]: T_a's false-alarm rate on coloured residuals, old and calibrated variance.
//! - [`coloured_grid`]: the same signal over AR(1) coefficients, signal forms, predictors and
//!   residual scales, against the channel targets (false alarms, steps, ramps).
//! - [`alarms`]: alarms and warnings per fault-free hour of every test of a federated
//!   session (ship seeds and the real track), and every injected fault alarmed.
//! - [`guards`]: frozen GNSS fixes and small DVL biases, with and without the aids' drift
//!   and stuck tests.
//! - [`raim`]: the `gnss` monitor on real receiver data, fault-free and with injected
//!   pseudorange steps and ramps, the three exclusion methods side by side.
//! - [`drive`]: the federated monitor on the real car drive with its raw IMU (the
//!   service's strapdown mechanization), 1 Hz degraded GNSS, outages and injected faults.
//! - [`scorecard`]: the per-detector figures every experiment ends with.
//!
//! The figures are drawn by [`crate::plot`].

pub mod alarms;
pub mod coloured;
pub mod coloured_grid;
pub mod drive;
pub mod guards;
pub mod raim;
pub mod ramp;
pub mod scorecard;
pub mod seed000;
pub mod seed001;
pub mod seed002;
pub mod seed003;
pub mod seed004;

use std::collections::BTreeMap;
use std::time::Instant;

use serde_json::Value;

use super::{Fault, Scenario, SimError};
use navguard_core::detect::Health;
use navguard_core::epoch::Aid;
use navguard_core::features::FeatureError;
use navguard_core::geo::{self, Lla};
use navguard_core::learn::LearnError;
use navguard_core::monitor::{
    self, Availability, BuildError, MonitorReport, MonitorSpec, StepError,
};
use navguard_core::session::{AlarmLevel, Seat, SessionCore, Severity};
use scorecard::FaultWindow;

/// Why an experiment could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ExperimentError {
    /// The scenario could not be built.
    #[error("scenario: {0}")]
    Sim(#[from] SimError),
    /// Features could not be computed.
    #[error("features: {0}")]
    Features(#[from] FeatureError),
    /// A model could not be trained.
    #[error("training: {0}")]
    Learn(#[from] LearnError),
    /// The monitor could not be built from its spec.
    #[error("monitor: {0}")]
    Build(#[from] BuildError),
    /// The monitor failed on an epoch.
    #[error("monitor failed at t = {t} s: {source}")]
    Step {
        /// Epoch time, s.
        t: f64,
        /// The failure.
        source: StepError,
    },
    /// The epochs could not be prepared (e.g. written to the wire and read back).
    #[error("preparing the epochs: {0}")]
    Prepare(String),
    /// The monitor's outputs carry no corrected solution.
    #[error("the monitor reports no corrected `solution` (t = {0} s)")]
    NoSolution(f64),
}

/// The corrected solution's error against the truth at one epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavError {
    /// Epoch time, s.
    pub t: f64,
    /// Latitude error as metres north (solution − truth).
    pub north_m: f64,
    /// Longitude error as metres east.
    pub east_m: f64,
    /// Height error, m.
    pub up_m: f64,
    /// East velocity error, m/s.
    pub ve_mps: f64,
    /// North velocity error, m/s.
    pub vn_mps: f64,
}

impl NavError {
    /// Horizontal position error, m.
    pub fn horizontal_m(&self) -> f64 {
        self.east_m.hypot(self.north_m)
    }
}

/// One test's outcome at one epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TestSample {
    /// Epoch time, s.
    pub t: f64,
    /// The statistic (λ).
    pub statistic: f64,
    /// The threshold it was compared with.
    pub threshold: f64,
    /// Health after this epoch.
    pub health: Health,
}

/// What one monitor did over one scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct MonitorRun {
    /// Solution error at every epoch.
    pub errors: Vec<NavError>,
    /// Per test, every epoch on which it ran.
    pub tests: BTreeMap<String, Vec<TestSample>>,
    /// HPL at every epoch that reports one, `(t, m)`.
    pub hpl: Vec<(f64, f64)>,
    /// INS epochs whose integrity was converging, available, unavailable
    /// (docs/methods.md §M24).
    pub integrity_counts: [usize; 3],
    /// Mean wall-clock time of one monitor step, s.
    pub time_per_epoch_s: f64,
    /// The alarm-log entries the session core wrote, in order (the server's rule).
    pub entries: Vec<LogEntry>,
}

/// One alarm-log entry of a run, as the session core wrote it.
#[derive(Debug, Clone, PartialEq)]
pub struct LogEntry {
    /// Epoch time, s.
    pub t: f64,
    /// Test name.
    pub test: String,
    /// The state entered.
    pub state: Health,
    /// Alarm or warning.
    pub severity: Severity,
}

impl MonitorRun {
    /// The log entries `(t, severity)` of the tests `keep` accepts, in order.
    pub fn entries_where(&self, keep: impl Fn(&str) -> bool) -> Vec<(f64, Severity)> {
        self.entries
            .iter()
            .filter(|e| keep(&e.test))
            .map(|e| (e.t, e.severity))
            .collect()
    }

    /// The log entries `(t, severity)` of one test.
    pub fn entries_of(&self, test: &str) -> Vec<(f64, Severity)> {
        self.entries_where(|name| name == test)
    }

    /// The log entries `(t, severity)` of an aid's tests: its χ² test `aid` and its guards
    /// `aid.*`.
    pub fn aid_entries(&self, aid: &str) -> Vec<(f64, Severity)> {
        self.entries_where(|name| name.split('.').next() == Some(aid))
    }

    /// The scorecard of one test: rates from its health trace, alarms and warnings from
    /// the entries the session core logged for it.
    pub fn scorecard(
        &self,
        test: &str,
        policy: &str,
        faults: &[FaultWindow],
        time_per_epoch_s: Option<f64>,
    ) -> scorecard::Scorecard {
        let (trace, entries) = (self.health_trace(test), self.entries_of(test));
        let run = scorecard::TestRun {
            trace: &trace,
            entries: &entries,
            run_starts: &[],
        };
        scorecard::score_test(test, policy, run, faults, time_per_epoch_s)
    }

    /// The scorecard of an aid: rates from its combined trace ([`MonitorRun::aid_health_trace`]),
    /// alarms and warnings from the entries of all its tests.
    pub fn aid_scorecard(
        &self,
        aid: &str,
        policy: &str,
        faults: &[FaultWindow],
    ) -> scorecard::Scorecard {
        let (trace, entries) = (self.aid_health_trace(aid), self.aid_entries(aid));
        let run = scorecard::TestRun {
            trace: &trace,
            entries: &entries,
            run_starts: &[],
        };
        scorecard::score_test(aid, policy, run, faults, None)
    }

    /// The `(t, health)` trace of a test, for [`scorecard::score`].
    pub fn health_trace(&self, test: &str) -> Vec<(f64, Health)> {
        self.tests
            .get(test)
            .map(|s| s.iter().map(|x| (x.t, x.health)).collect())
            .unwrap_or_default()
    }

    /// The combined `(t, health)` trace of an aid (docs/methods.md §M23): at every epoch on
    /// which its χ² test `aid` ran, the worst health of that test and of its guards
    /// (`aid.drift`, `aid.stuck`, each at its last reported health) — the health its local
    /// filter followed.
    pub fn aid_health_trace(&self, aid: &str) -> Vec<(f64, Health)> {
        let prefix = format!("{aid}.");
        let guards: Vec<&Vec<TestSample>> = self
            .tests
            .iter()
            .filter(|(name, _)| name.starts_with(&prefix))
            .map(|(_, samples)| samples)
            .collect();
        let mut cursors = vec![0usize; guards.len()];
        let mut last = vec![Health::Healthy; guards.len()];
        let Some(main) = self.tests.get(aid) else {
            return Vec::new();
        };
        main.iter()
            .map(|s| {
                let mut h = s.health;
                for (g, samples) in guards.iter().enumerate() {
                    while cursors[g] < samples.len() && samples[cursors[g]].t <= s.t {
                        last[g] = samples[cursors[g]].health;
                        cursors[g] += 1;
                    }
                    h = navguard_core::monitor::guards::worse(h, last[g]);
                }
                (s.t, h)
            })
            .collect()
    }

    /// The first epoch at or after `from` on which `test` is not healthy.
    pub fn first_alarm(&self, test: &str, from: f64) -> Option<f64> {
        self.tests
            .get(test)?
            .iter()
            .find(|s| s.t >= from && s.health != Health::Healthy)
            .map(|s| s.t)
    }
}

/// Reads `solution {lat, lon, h (°, °, m), vel [e, n, u]}` and `hpl` from a
/// monitor's outputs in their wire form (docs/architecture.md §A6), so the experiments rely
/// on the documented output shape only.
fn solution(outputs: &Value) -> Option<(Lla, [f64; 3], Option<f64>)> {
    let s = &outputs["solution"];
    let lla = Lla {
        lat: s["lat"].as_f64()?.to_radians(),
        lon: s["lon"].as_f64()?.to_radians(),
        h: s["h"].as_f64()?,
    };
    let v = s["vel"].as_array()?;
    let vel = [
        v.first()?.as_f64()?,
        v.get(1)?.as_f64()?,
        v.get(2)?.as_f64()?,
    ];
    Some((lla, vel, outputs["hpl"].as_f64()))
}

/// Runs `scenario` through the monitor `spec` describes, epoch by epoch, and
/// records the corrected solution's error against the truth and every test.
pub fn run_monitor(scenario: &Scenario, spec: &MonitorSpec) -> Result<MonitorRun, ExperimentError> {
    let seat = Seat {
        name: "experiment".into(),
        monitor: monitor::build(spec, &monitor::NoModels)?,
        alarm_level: AlarmLevel::default(),
    };
    // The server's session core, without history: it decides the log entries.
    let mut core = SessionCore::new("experiment", vec![seat], 0);
    let mut run = MonitorRun {
        errors: Vec::with_capacity(scenario.epochs.len()),
        tests: BTreeMap::new(),
        hpl: Vec::new(),
        integrity_counts: [0; 3],
        time_per_epoch_s: 0.0,
        entries: Vec::new(),
    };
    let mut busy = std::time::Duration::ZERO;
    let mut effects = Vec::new();
    for e in &scenario.epochs {
        let t = e.epoch.t;
        let started = Instant::now();
        let (reports, failure) = core.step(&e.epoch);
        busy += started.elapsed();
        if let Some((_, source)) = failure {
            return Err(ExperimentError::Step { t, source });
        }
        let Some(report) = reports.first().and_then(Option::as_ref) else {
            return Err(ExperimentError::NoSolution(t));
        };
        record(&mut run, report, e)?;
        core.commit(&e.epoch, &reports, &mut effects);
        run.entries.extend(effects.drain(..).filter_map(|x| {
            x.entry().map(|entry| LogEntry {
                t: entry.t,
                test: entry.test.clone(),
                state: entry.state,
                severity: entry.severity,
            })
        }));
    }
    let n = scenario.epochs.len().max(1) as f64;
    run.time_per_epoch_s = busy.as_secs_f64() / n;
    Ok(run)
}

/// Records one epoch's report: every test's sample, the integrity, the HPL and the
/// solution's error against the truth.
fn record(
    run: &mut MonitorRun,
    report: &MonitorReport,
    e: &crate::scenario::SimEpoch,
) -> Result<(), ExperimentError> {
    let t = e.epoch.t;
    for o in &report.tests {
        run.tests
            .entry(o.name.to_string())
            .or_default()
            .push(TestSample {
                t,
                statistic: o.statistic.value,
                threshold: o.statistic.threshold,
                health: o.decision.health,
            });
    }
    if let Some(i) = report.integrity {
        run.integrity_counts[integrity_slot(i.state)] += 1;
    }
    let outputs = serde_json::to_value(&report.outputs).unwrap_or(Value::Null);
    let (lla, vel, hpl) = solution(&outputs).ok_or(ExperimentError::NoSolution(t))?;
    if let Some(hpl) = hpl {
        run.hpl.push((t, hpl));
    }
    // ENU metres of solution − truth at the truth (small-offset form).
    let d = geo::local_offset(&lla, &e.truth.lla);
    run.errors.push(NavError {
        t,
        north_m: d.y,
        east_m: d.x,
        up_m: d.z,
        ve_mps: vel[0] - e.truth.vel.x,
        vn_mps: vel[1] - e.truth.vel.y,
    });
    Ok(())
}

/// The slot of an availability in the runs' `integrity_counts`: converging, available,
/// unavailable.
pub(crate) fn integrity_slot(state: Availability) -> usize {
    match state {
        Availability::Converging => 0,
        Availability::Available => 1,
        Availability::Unavailable => 2,
    }
}

/// The fault windows of a scenario that concern one aid's test, merged where
/// they overlap (e.g. seed 004's latitude and longitude jumps are one window).
pub fn fault_windows(faults: &[Fault], aid: Aid) -> Vec<FaultWindow> {
    let mut windows: Vec<FaultWindow> = faults
        .iter()
        .filter(|f| f.aid == aid)
        .map(|f| FaultWindow {
            start: f.start_s,
            end: f.end_s.unwrap_or(f64::INFINITY),
        })
        .collect();
    windows.sort_by(|a, b| a.start.total_cmp(&b.start));
    let mut merged: Vec<FaultWindow> = Vec::new();
    for w in windows {
        match merged.last_mut() {
            Some(last) if w.start <= last.end => last.end = last.end.max(w.end),
            _ => merged.push(w),
        }
    }
    merged
}

/// Mean, standard deviation and maximum of an error series.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorStats {
    /// Mean of the absolute error (seed 004 Table 1, "precision").
    pub mean: f64,
    /// Standard deviation of the signed error (Table 2, "stability": its fluctuation).
    pub std: f64,
    /// Largest absolute error (Table 3, "maximum").
    pub max: f64,
}

impl ErrorStats {
    /// The statistics of `values` (all zero for an empty series).
    pub fn of(values: impl IntoIterator<Item = f64>) -> Self {
        let (mut n, mut sum_abs, mut sum, mut sum_sq, mut max) = (0usize, 0.0, 0.0, 0.0, 0.0f64);
        for v in values {
            n += 1;
            sum_abs += v.abs();
            sum += v;
            sum_sq += v * v;
            max = max.max(v.abs());
        }
        if n == 0 {
            return ErrorStats {
                mean: 0.0,
                std: 0.0,
                max: 0.0,
            };
        }
        let nf = n as f64;
        let mean_signed = sum / nf;
        ErrorStats {
            mean: sum_abs / nf,
            std: (sum_sq / nf - mean_signed * mean_signed).max(0.0).sqrt(),
            max,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn error_stats_are_mean_abs_std_signed_and_max_abs() {
        let s = ErrorStats::of([1.0, -1.0, 3.0, -3.0]);
        assert_eq!(s.mean, 2.0);
        // Signed mean 0, mean square 5.
        assert!((s.std - 5f64.sqrt()).abs() < 1e-15);
        assert_eq!(s.max, 3.0);
        let s = ErrorStats::of([2.0, 2.0]);
        assert_eq!((s.mean, s.std, s.max), (2.0, 0.0, 2.0));
        assert_eq!(ErrorStats::of([]).max, 0.0);
    }

    #[test]
    fn ship_faults_make_two_gnss_windows_and_none_elsewhere() {
        let faults = crate::ship_faults();
        let w = fault_windows(&faults, Aid::Gnss);
        assert_eq!(
            w,
            vec![
                FaultWindow {
                    start: 1080.0,
                    end: 1200.0
                },
                FaultWindow {
                    start: 1800.0,
                    end: f64::INFINITY
                },
            ]
        );
        assert!(fault_windows(&faults, Aid::Dvl).is_empty());
    }

    #[test]
    fn solution_is_read_from_the_wire_shape_in_degrees() {
        let v = json!({"solution": {"lat": 30.0, "lon": -114.5, "h": 3.0, "vel": [1.0, 2.0, 0.5]},
                       "hpl": 12.5, "isolated": []});
        let (lla, vel, hpl) = solution(&v).unwrap();
        assert!((lla.lat - 30f64.to_radians()).abs() < 1e-15);
        assert!((lla.lon + 114.5f64.to_radians()).abs() < 1e-15);
        assert_eq!((lla.h, vel, hpl), (3.0, [1.0, 2.0, 0.5], Some(12.5)));
        assert!(solution(&json!({"x": [1.0]})).is_none());
    }
}
