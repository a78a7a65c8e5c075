//! What the drift and stuck tests add on faults the per-epoch χ² misses (docs/methods.md
//! §M23): the `federated` monitor (counters, p_fa 1e-3) with and without each guard on
//! - a **frozen GNSS fix** (every position component held, [`crate::gnss_freeze`]) on the
//!   station-keeping ship ([`crate::station_keeping_with`]) while it is stationary, while it
//!   creeps at 0.5 m/s and while it sails at 10 m/s. A freeze makes `z = INS − GNSS` move
//!   with the vehicle: at 10 m/s that is a 10 m/s ramp in the innovation, which the χ²
//!   test catches within seconds; at rest or creeping the innovation's successive
//!   differences collapse, which only `gnss.stuck` sees (the χ² test then sees nothing:
//!   the filter follows the frozen fix);
//! - a **DVL bias** (a step on the forward axis for 400 s) of 0.1–0.3 m/s on the ship: too
//!   small for its χ² test (the known limit of docs/methods.md §M6), it pulls the fused
//!   solution tens of metres off; `dvl.drift` isolates it.
//!
//! Three configurations: the defaults, the faulted aid's drift test off (its stuck test
//! alone beside the χ²), and its χ² test alone.
//!
//! Per fault and configuration, over the seeds: the first warning and the first alarm of
//! the faulted aid after onset (and which of its tests raised it), and the corrected
//! solution's largest horizontal error while the fault lasts.

use std::fmt::Write as _;

use super::{ExperimentError, MonitorRun, run_monitor};
use crate::{Channel, Fault, FaultKind, Scenario};
use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::epoch::Aid;
use navguard_core::monitor::federated::{DvlNoise, FederatedConfigWire, GnssNoise};
use navguard_core::monitor::guards::{DriftConfigWire, StuckConfigWire};
use navguard_core::monitor::{self, MonitorConfig, MonitorKind, MonitorSpec};
use navguard_core::session::Severity;

/// A fault case of the experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct GuardCase {
    /// What the fault is (`GNSS fix frozen while stationary`, …).
    pub name: String,
    /// The faulted aid.
    pub aid: Aid,
    /// The faults.
    pub faults: Vec<Fault>,
    /// Fault interval `[start, end)`, s.
    pub window: (f64, f64),
    /// Run length, s.
    pub duration_s: f64,
    /// The station-keeping ship (else seed 004's ship).
    pub station_keeping: bool,
}

/// The default cases (module doc).
pub fn default_cases() -> Vec<GuardCase> {
    let mut cases = Vec::new();
    for (what, start) in [
        ("stationary", 700.0),
        ("creeping at 0.5 m/s", 1300.0),
        ("sailing at 10 m/s", 1900.0),
    ] {
        cases.push(GuardCase {
            name: format!("GNSS fix frozen, {what}"),
            aid: Aid::Gnss,
            faults: crate::gnss_freeze(start, start + 120.0),
            window: (start, start + 120.0),
            duration_s: start + 200.0,
            station_keeping: true,
        });
    }
    for bias in [0.1, 0.15, 0.2, 0.3] {
        cases.push(GuardCase {
            name: format!("DVL forward bias {bias} m/s"),
            aid: Aid::Dvl,
            faults: vec![Fault {
                aid: Aid::Dvl,
                channel: Channel::Velocity,
                component: 1,
                kind: FaultKind::Step { value: bias },
                start_s: 600.0,
                end_s: Some(1000.0),
            }],
            window: (600.0, 1000.0),
            duration_s: 1100.0,
            station_keeping: false,
        });
    }
    cases
}

/// Whether the faulted aid's guard runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Guarded {
    /// The monitor's defaults (`gnss.drift`, `dvl.drift`, every `stuck` on).
    Defaults,
    /// The faulted aid's drift test off, its stuck test on.
    NoDrift,
    /// The faulted aid's drift and stuck tests off (its χ² test alone).
    Off,
}

impl Guarded {
    fn label(self) -> &'static str {
        match self {
            Guarded::Defaults => "defaults",
            Guarded::NoDrift => "no drift",
            Guarded::Off => "χ² only",
        }
    }
}

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct GuardsParams {
    /// Seeds.
    pub seeds: Vec<u64>,
    /// The cases.
    pub cases: Vec<GuardCase>,
    /// False-alarm probability of the tests under the monitor's spec.
    pub p_fa: f64,
}

impl Default for GuardsParams {
    fn default() -> Self {
        GuardsParams {
            seeds: (1..=5).collect(),
            cases: default_cases(),
            p_fa: 1e-3,
        }
    }
}

/// One case, one configuration, one seed.
#[derive(Debug, Clone, PartialEq)]
pub struct GuardRun {
    /// Seconds from onset to the aid's first non-healthy epoch, and the test that was not
    /// healthy first.
    pub warning: Option<(f64, String)>,
    /// Seconds from onset to the aid's first isolated epoch, and the test isolated first.
    pub alarm: Option<(f64, String)>,
    /// Largest horizontal error of the corrected solution during the fault, m.
    pub max_error_m: f64,
}

/// One case under one configuration, over the seeds.
#[derive(Debug, Clone, PartialEq)]
pub struct GuardRow {
    /// The case.
    pub case: GuardCase,
    /// The configuration.
    pub guarded: Guarded,
    /// One run per seed.
    pub runs: Vec<GuardRun>,
}

/// The experiment's rows.
#[derive(Debug, Clone, PartialEq)]
pub struct GuardsResult {
    /// The parameters.
    pub params: GuardsParams,
    /// Per case, the defaults, the drift test off, then the χ² test alone.
    pub rows: Vec<GuardRow>,
}

/// The spec of `guarded` for `aid` on `scenario`.
fn spec(
    scenario: &Scenario,
    aid: Aid,
    guarded: Guarded,
    p_fa: f64,
) -> Result<MonitorSpec, ExperimentError> {
    let mut config: FederatedConfigWire = scenario.monitor_config();
    if guarded != Guarded::Defaults {
        let drift = Some(DriftConfigWire::disabled());
        let stuck = (guarded == Guarded::Off).then(StuckConfigWire::disabled);
        match aid {
            Aid::Gnss => {
                let g = config.gnss.get_or_insert_with(GnssNoise::default);
                (g.drift, g.stuck) = (drift, stuck);
            }
            Aid::Dvl => {
                let d = config.dvl.get_or_insert_with(DvlNoise::default);
                (d.drift, d.stuck) = (drift, stuck);
            }
            Aid::Cns => {}
        }
    }
    let value = serde_json::to_value(&config)
        .map_err(|e| monitor::BuildError::from(monitor::ConfigError::new("", e.to_string())))?;
    Ok(MonitorSpec {
        kind: MonitorKind::Federated,
        config: MonitorConfig::parse(MonitorKind::Federated, &value)
            .map_err(monitor::BuildError::from)?,
        policy: PolicyConfig::counters_default(),
        threshold: ThresholdSpec::PFa(p_fa),
    })
}

/// The first log entry in `[from, to)` of a test of `aid` whose severity `counts` accepts,
/// as seconds after `from`, with the test's name.
fn first(
    run: &MonitorRun,
    aid: Aid,
    (from, to): (f64, f64),
    counts: impl Fn(Severity) -> bool,
) -> Option<(f64, String)> {
    run.entries
        .iter()
        .filter(|e| e.test.split('.').next() == Some(aid.as_str()))
        .find(|e| e.t >= from && e.t < to && counts(e.severity))
        .map(|e| (e.t - from, e.test.clone()))
}

/// Runs every case under both configurations on every seed.
pub fn run(params: GuardsParams) -> Result<GuardsResult, ExperimentError> {
    let mut rows = Vec::new();
    for case in &params.cases {
        let mut by_config: Vec<GuardRow> = [Guarded::Defaults, Guarded::NoDrift, Guarded::Off]
            .into_iter()
            .map(|guarded| GuardRow {
                case: case.clone(),
                guarded,
                runs: Vec::new(),
            })
            .collect();
        for &seed in &params.seeds {
            let scenario = if case.station_keeping {
                crate::station_keeping_with(seed, case.faults.clone(), case.duration_s)?
            } else {
                crate::ship_with(seed, case.faults.clone(), case.duration_s)?
            };
            for row in &mut by_config {
                let spec = spec(&scenario, case.aid, row.guarded, params.p_fa)?;
                let run = run_monitor(&scenario, &spec)?;
                let (from, to) = case.window;
                row.runs.push(GuardRun {
                    warning: first(&run, case.aid, case.window, |_| true),
                    alarm: first(&run, case.aid, case.window, |s| s == Severity::Alarm),
                    max_error_m: run
                        .errors
                        .iter()
                        .filter(|e| e.t >= from && e.t < to)
                        .map(|e| e.horizontal_m())
                        .fold(0.0, f64::max),
                });
            }
        }
        rows.extend(by_config);
    }
    Ok(GuardsResult { params, rows })
}

/// `mean / worst s (tests)` of some first events, `n/N` when some seeds had none.
fn events(runs: &[GuardRun], pick: impl Fn(&GuardRun) -> Option<&(f64, String)>) -> String {
    let got: Vec<&(f64, String)> = runs.iter().filter_map(&pick).collect();
    if got.is_empty() {
        return "none".to_owned();
    }
    let mean = got.iter().map(|e| e.0).sum::<f64>() / got.len() as f64;
    let worst = got.iter().map(|e| e.0).fold(0.0, f64::max);
    let mut tests: Vec<&str> = got.iter().map(|e| e.1.as_str()).collect();
    tests.sort_unstable();
    tests.dedup();
    let missing = if got.len() < runs.len() {
        format!(" ({}/{} seeds)", got.len(), runs.len())
    } else {
        String::new()
    };
    format!("{mean:.0} / {worst:.0} s {}{missing}", tests.join("+"))
}

/// The text table.
pub fn render(r: &GuardsResult) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "guards — federated monitor, counters, p_fa = {}, seeds {:?}: faults the per-epoch χ² misses, with the faulted aid's\n\
         drift and stuck tests at their defaults and off. warning = onset → first non-healthy epoch of the aid, alarm = → first isolated\n\
         (mean / worst over the seeds, and the test that fired first); error = the corrected solution's largest horizontal error in the fault\n",
        r.params.p_fa, r.params.seeds
    );
    let _ = writeln!(
        s,
        "{:<36} {:<9} {:<34} {:<34} {:>13}",
        "fault", "config", "warning", "alarm", "error m"
    );
    for row in &r.rows {
        let errors: Vec<f64> = row.runs.iter().map(|r| r.max_error_m).collect();
        let mean = errors.iter().sum::<f64>() / errors.len().max(1) as f64;
        let worst = errors.iter().copied().fold(0.0, f64::max);
        let _ = writeln!(
            s,
            "{:<36} {:<9} {:<34} {:<34} {:>13}",
            row.case.name,
            row.guarded.label(),
            events(&row.runs, |r| r.warning.as_ref()),
            events(&row.runs, |r| r.alarm.as_ref()),
            format!("{mean:.1} / {worst:.1}")
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fix_frozen_at_rest_is_caught_by_the_guards_and_missed_by_the_chi2_test() {
        let case = GuardCase {
            name: "frozen".into(),
            aid: Aid::Gnss,
            faults: crate::gnss_freeze(700.0, 760.0),
            window: (700.0, 760.0),
            duration_s: 780.0,
            station_keeping: true,
        };
        let params = GuardsParams {
            seeds: vec![1],
            cases: vec![case],
            p_fa: 1e-3,
        };
        let r = run(params).unwrap();
        assert_eq!(r.rows.len(), 3);
        let (on, stuck, off) = (&r.rows[0].runs[0], &r.rows[1].runs[0], &r.rows[2].runs[0]);
        // The held fix repeats one noise draw: its differences collapse (gnss.stuck after
        // k = 8 differences) and its offset is a standing bias (gnss.drift may fire first).
        let (t, test) = on.warning.clone().unwrap();
        assert!(test == "gnss.stuck" || test == "gnss.drift", "{test}");
        assert!(t <= 10.0, "flagged after {t} s");
        assert!(on.alarm.is_some());
        // Alone, the stuck test flags it after k = 8 repeated differences.
        let (t, test) = stuck.warning.clone().unwrap();
        assert_eq!(test, "gnss.stuck");
        assert!(t <= 9.0, "stuck test after {t} s");
        assert!(off.alarm.is_none(), "the χ² test alone misses it: {off:?}");
        let text = render(&r);
        assert!(
            text.contains("frozen") && text.contains("χ² only"),
            "{text}"
        );
    }
}
