//! Alarms an operator can live with (docs/methods.md §M23, §M24): the `federated`
//! monitor under counters at a `p_fa` (default 1e-3) over fault-free ship runs (several
//! seeds) and the real RTK track, counting per hour of fault-free time the *alarms* and
//! *warnings* of every test of the session — the aids' χ² tests, their drift and stuck
//! tests — as the server logs them: each run goes through the session core, whose rule
//! makes entering `isolated` an alarm and entering `suspect` a warning under the default
//! alarm level, every change a warning while the monitor converges, and raises a test
//! standing in `isolated` as an alarm when it has converged (docs/architecture.md §A2).
//! On the same scenarios with seed 004's faults injected, it checks that every fault still
//! raises an alarm (an alarm entry of a test of the faulted aid while the fault lasts).
//! HPL above the HAL is integrity availability, not an alarm (docs/methods.md §M24); the
//! epochs spent converging and unavailable are reported beside.
//!
//! Each configuration is run as given: the monitor's defaults, and the same with the drift
//! test on for every aid (the evidence behind the default of docs/methods.md §M23).

use std::fmt::Write as _;

use super::{ExperimentError, MonitorRun, fault_windows};
use crate::{Scenario, Track};
use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::epoch::Aid;
use navguard_core::monitor::federated::{CnsNoise, DvlNoise, FederatedConfigWire, GnssNoise};
use navguard_core::monitor::guards::{DriftConfigWire, StuckConfigWire};
use navguard_core::monitor::{self, MonitorConfig, MonitorKind, MonitorSpec};
use navguard_core::session::Severity;

/// The target: at most this many alarms per fault-free hour per session.
pub const TARGET_ALARMS_PER_HOUR: f64 = 1.0;

/// Which monitor configuration a row is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AlarmsConfig {
    /// The federated config's defaults (`gnss.drift`, `dvl.drift` and every `stuck` on).
    Defaults,
    /// The per-epoch χ² tests alone (every drift and stuck test off): the baseline.
    ChiSquareOnly,
    /// The defaults with `drift` on for every aid (CNS too).
    EveryDrift,
}

impl AlarmsConfig {
    /// The row label.
    pub fn label(self) -> &'static str {
        match self {
            AlarmsConfig::Defaults => "defaults",
            AlarmsConfig::ChiSquareOnly => "χ² tests only",
            AlarmsConfig::EveryDrift => "drift on every aid",
        }
    }

    /// `config` as this configuration asks.
    fn apply(self, mut config: FederatedConfigWire) -> FederatedConfigWire {
        let (drift, stuck) = match self {
            AlarmsConfig::Defaults => return config,
            AlarmsConfig::ChiSquareOnly => (
                Some(DriftConfigWire::disabled()),
                Some(StuckConfigWire::disabled()),
            ),
            AlarmsConfig::EveryDrift => (Some(DriftConfigWire::default()), None),
        };
        let gnss = config.gnss.get_or_insert_with(GnssNoise::default);
        (gnss.drift, gnss.stuck) = (drift.clone(), stuck.clone());
        let dvl = config.dvl.get_or_insert_with(DvlNoise::default);
        (dvl.drift, dvl.stuck) = (drift.clone(), stuck.clone());
        let cns = config.cns.get_or_insert_with(CnsNoise::default);
        (cns.drift, cns.stuck) = (drift, stuck);
        config
    }
}

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct AlarmsParams {
    /// Ship seeds.
    pub seeds: Vec<u64>,
    /// Ship run length, s.
    pub duration_s: f64,
    /// The real track (`None`: ship only) and its seed.
    pub track: Option<(Track, u64)>,
    /// False-alarm probability of every test under the monitor's spec.
    pub p_fa: f64,
    /// Counters' N1 and N2.
    pub policy: PolicyConfig,
    /// The configurations.
    pub configs: Vec<AlarmsConfig>,
}

impl Default for AlarmsParams {
    fn default() -> Self {
        AlarmsParams {
            seeds: (1..=5).collect(),
            duration_s: crate::SHIP_DURATION_S,
            track: None,
            p_fa: 1e-3,
            policy: PolicyConfig::counters_default(),
            configs: vec![
                AlarmsConfig::Defaults,
                AlarmsConfig::ChiSquareOnly,
                AlarmsConfig::EveryDrift,
            ],
        }
    }
}

/// One test of one session: its alarm and warning entries outside faults.
#[derive(Debug, Clone, PartialEq)]
pub struct TestAlarms {
    /// Test name.
    pub test: String,
    /// Alarm entries at a clear epoch.
    pub alarms: usize,
    /// Warning entries at a clear epoch.
    pub warnings: usize,
    /// Clear hours of the test.
    pub hours: f64,
}

/// One injected fault: when it first raised a warning and an alarm.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultAlarm {
    /// The faulted aid.
    pub aid: Aid,
    /// Onset, s.
    pub start_s: f64,
    /// End, s (infinite: to the end of the run).
    pub end_s: f64,
    /// Seconds from onset to the first log entry (warning or alarm) of one of the aid's
    /// tests inside the fault (`None`: none).
    pub warning_s: Option<f64>,
    /// Seconds from onset to the first alarm entry of one of the aid's tests inside the
    /// fault.
    pub alarm_s: Option<f64>,
}

/// One session (a scenario under a configuration).
#[derive(Debug, Clone, PartialEq)]
pub struct SessionAlarms {
    /// `ship seed 1`, `track seed 1 + seed 004 faults`, …
    pub scenario: String,
    /// The configuration.
    pub config: AlarmsConfig,
    /// Per test.
    pub tests: Vec<TestAlarms>,
    /// Per injected fault window (merged per aid).
    pub faults: Vec<FaultAlarm>,
    /// INS epochs reported converging, available, unavailable.
    pub integrity: [usize; 3],
}

impl SessionAlarms {
    /// Fault-free hours of the session: the least over the aids' χ² tests (which run from
    /// the first epoch; faults and recovery tails left out).
    pub fn hours(&self) -> f64 {
        self.tests
            .iter()
            .filter(|t| !t.test.contains('.'))
            .map(|t| t.hours)
            .fold(f64::INFINITY, f64::min)
    }

    /// Every test's alarms, per fault-free hour.
    pub fn alarms_per_hour(&self) -> f64 {
        self.tests.iter().map(|t| t.alarms).sum::<usize>() as f64 / self.hours().max(1e-9)
    }

    /// Every test's warnings, per fault-free hour.
    pub fn warnings_per_hour(&self) -> f64 {
        self.tests.iter().map(|t| t.warnings).sum::<usize>() as f64 / self.hours().max(1e-9)
    }

    /// Every test's alarms.
    pub fn alarms(&self) -> usize {
        self.tests.iter().map(|t| t.alarms).sum()
    }

    /// True when the session raised at most [`TARGET_ALARMS_PER_HOUR`] alarms in each of its
    /// fault-free hours, counting a started hour as one (a single alarm in a 57-minute run
    /// is one alarm in one hour, not 1.05 per hour).
    pub fn within_target(&self) -> bool {
        self.alarms() as f64 <= TARGET_ALARMS_PER_HOUR * self.hours().ceil().max(1.0)
    }

    /// True when every injected fault raised an alarm.
    pub fn every_fault_alarmed(&self) -> bool {
        self.faults.iter().all(|f| f.alarm_s.is_some())
    }
}

/// The experiment's rows.
#[derive(Debug, Clone, PartialEq)]
pub struct AlarmsResult {
    /// The parameters (without the track's fixes).
    pub p_fa: f64,
    /// One row per scenario and configuration.
    pub sessions: Vec<SessionAlarms>,
}

impl AlarmsResult {
    /// The sessions of `config`.
    fn of(&self, config: AlarmsConfig) -> impl Iterator<Item = &SessionAlarms> {
        self.sessions.iter().filter(move |s| s.config == config)
    }

    /// Alarms per fault-free hour over every session of `config` (all alarms over all
    /// fault-free hours).
    pub fn pooled_rate(&self, config: AlarmsConfig) -> f64 {
        let (alarms, hours) = self
            .of(config)
            .fold((0, 0.0), |(a, h), s| (a + s.alarms(), h + s.hours()));
        alarms as f64 / f64::max(hours, 1e-9)
    }

    /// True when every session of `config` is within the target
    /// ([`SessionAlarms::within_target`]).
    pub fn within_target(&self, config: AlarmsConfig) -> bool {
        self.of(config).all(SessionAlarms::within_target)
    }

    /// True when every injected fault of every session of `config` raised an alarm.
    pub fn every_fault_alarmed(&self, config: AlarmsConfig) -> bool {
        self.of(config).all(SessionAlarms::every_fault_alarmed)
    }
}

/// The aid a test belongs to (`gnss.drift` → gnss).
fn aid_of(test: &str) -> Option<Aid> {
    let name = test.split('.').next()?;
    [Aid::Gnss, Aid::Dvl, Aid::Cns]
        .into_iter()
        .find(|a| a.as_str() == name)
}

/// The time of the first log entry of any of `aid`'s tests at or after `from` and before
/// `to` whose severity `counts` accepts.
fn first_entry(
    run: &MonitorRun,
    aid: Aid,
    from: f64,
    to: f64,
    counts: impl Fn(Severity) -> bool,
) -> Option<f64> {
    run.aid_entries(aid.as_str())
        .into_iter()
        .find(|&(t, severity)| counts(severity) && t >= from && t < to)
        .map(|(t, _)| t)
}

/// Scores one run.
fn score(
    scenario: &Scenario,
    label: String,
    config: AlarmsConfig,
    run: &MonitorRun,
) -> SessionAlarms {
    let tests = run
        .tests
        .keys()
        .map(|test| {
            let faults = aid_of(test)
                .map(|a| fault_windows(&scenario.faults, a))
                .unwrap_or_default();
            let card = run.scorecard(test, "", &faults, None);
            TestAlarms {
                test: test.clone(),
                alarms: card.clear_alarms,
                warnings: card.clear_warnings,
                hours: card.clear_hours,
            }
        })
        .collect();
    let faults = [Aid::Gnss, Aid::Dvl, Aid::Cns]
        .into_iter()
        .flat_map(|aid| {
            fault_windows(&scenario.faults, aid)
                .into_iter()
                .map(move |w| (aid, w))
        })
        .map(|(aid, w)| FaultAlarm {
            aid,
            start_s: w.start,
            end_s: w.end,
            warning_s: first_entry(run, aid, w.start, w.end, |_| true).map(|t| t - w.start),
            alarm_s: first_entry(run, aid, w.start, w.end, |s| s == Severity::Alarm)
                .map(|t| t - w.start),
        })
        .collect();
    SessionAlarms {
        scenario: label,
        config,
        tests,
        faults,
        integrity: run.integrity_counts,
    }
}

/// The monitor spec of `config` on `scenario`.
fn spec(
    scenario: &Scenario,
    config: AlarmsConfig,
    params: &AlarmsParams,
) -> Result<MonitorSpec, ExperimentError> {
    let wire = config.apply(scenario.monitor_config());
    let value = serde_json::to_value(&wire)
        .map_err(|e| monitor::BuildError::from(monitor::ConfigError::new("", e.to_string())))?;
    Ok(MonitorSpec {
        kind: MonitorKind::Federated,
        config: MonitorConfig::parse(MonitorKind::Federated, &value)
            .map_err(monitor::BuildError::from)?,
        policy: params.policy,
        threshold: ThresholdSpec::PFa(params.p_fa),
    })
}

/// Runs every scenario under every configuration.
pub fn run(params: AlarmsParams) -> Result<AlarmsResult, ExperimentError> {
    let mut scenarios: Vec<(String, Scenario)> = Vec::new();
    for &seed in &params.seeds {
        scenarios.push((
            format!("ship seed {seed}"),
            crate::ship_with(seed, Vec::new(), params.duration_s)?,
        ));
    }
    if let Some((track, seed)) = &params.track {
        scenarios.push((
            format!("track seed {seed}"),
            crate::track_scenario(track, *seed, Vec::new())?,
        ));
    }
    for &seed in &params.seeds {
        scenarios.push((
            format!("ship seed {seed} + seed 004 faults"),
            crate::ship_with(seed, crate::ship_faults(), params.duration_s)?,
        ));
    }
    if let Some((track, seed)) = &params.track {
        scenarios.push((
            format!("track seed {seed} + seed 004 faults"),
            crate::track_scenario(track, *seed, crate::ship_faults())?,
        ));
    }
    let mut sessions = Vec::new();
    for config in &params.configs {
        for (label, scenario) in &scenarios {
            let run = super::run_monitor(scenario, &spec(scenario, *config, &params)?)?;
            sessions.push(score(scenario, label.clone(), *config, &run));
        }
    }
    Ok(AlarmsResult {
        p_fa: params.p_fa,
        sessions,
    })
}

fn secs(v: Option<f64>) -> String {
    v.map_or_else(|| "none".to_owned(), |v| format!("{v:.0} s"))
}

/// The text report.
pub fn render(r: &AlarmsResult) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "alarms — federated monitor, counters N1 = 10, N2 = 5, p_fa = {} for every test under the monitor's spec (stuck tests: their own 1e-6).\n\
         alarms and warnings as the server logs them (entering isolated an alarm, entering suspect a warning, warnings while converging, standing alarms at convergence),\n\
         of any test of the session, outside faults and recovery tails, per fault-free hour;\n\
         HPL above the HAL is integrity (INS epochs converging / available / unavailable), not an alarm. Target: ≤ {} alarm per hour per session,\n\
         and every injected fault raising one.\n",
        r.p_fa, TARGET_ALARMS_PER_HOUR
    );
    let _ = writeln!(
        s,
        "{:<20} {:<36} {:>6} {:>9} {:>8}  {:<34} integrity conv/avail/unavail",
        "config", "session", "hours", "alarms/h", "warn/h", "alarming tests (alarms, warnings)"
    );
    for x in &r.sessions {
        let noisy: Vec<String> = x
            .tests
            .iter()
            .filter(|t| t.alarms + t.warnings > 0)
            .map(|t| format!("{} {}/{}", t.test, t.alarms, t.warnings))
            .collect();
        let _ = writeln!(
            s,
            "{:<20} {:<36} {:>6.2} {:>9.2} {:>8.2}  {:<34} {}/{}/{}",
            x.config.label(),
            x.scenario,
            x.hours(),
            x.alarms_per_hour(),
            x.warnings_per_hour(),
            if noisy.is_empty() {
                "—".to_owned()
            } else {
                noisy.join(", ")
            },
            x.integrity[0],
            x.integrity[1],
            x.integrity[2]
        );
    }
    render_faults(&mut s, r);
    render_verdicts(&mut s, r);
    s
}

/// The injected faults' first warning and alarm, per session.
fn render_faults(s: &mut String, r: &AlarmsResult) {
    let _ = writeln!(
        s,
        "\ninjected faults (first warning / first alarm after onset, any test of the faulted aid):"
    );
    for x in r.sessions.iter().filter(|x| !x.faults.is_empty()) {
        let faults: Vec<String> = x
            .faults
            .iter()
            .map(|f| {
                let end = if f.end_s.is_finite() {
                    format!("{:.0}", f.end_s)
                } else {
                    "end".to_owned()
                };
                format!(
                    "{} [{:.0}, {end}): {} / {}",
                    f.aid.as_str(),
                    f.start_s,
                    secs(f.warning_s),
                    secs(f.alarm_s)
                )
            })
            .collect();
        let _ = writeln!(
            s,
            "  {:<20} {:<36} {}",
            x.config.label(),
            x.scenario,
            faults.join("; ")
        );
    }
}

/// One line per configuration: the pooled rate and whether the targets hold.
fn render_verdicts(s: &mut String, r: &AlarmsResult) {
    for config in [
        AlarmsConfig::Defaults,
        AlarmsConfig::ChiSquareOnly,
        AlarmsConfig::EveryDrift,
    ] {
        if r.of(config).next().is_some() {
            let yes = |b: bool| if b { "yes" } else { "NO" };
            let _ = writeln!(
                s,
                "{}: {:.2} alarms per fault-free hour over all sessions; every session ≤ {} alarm in each started hour: {}; every fault alarmed: {}",
                config.label(),
                r.pooled_rate(config),
                TARGET_ALARMS_PER_HOUR,
                yes(r.within_target(config)),
                yes(r.every_fault_alarmed(config))
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Fault;
    use crate::scenario::{ScenarioParams, ship_params};

    #[test]
    fn a_short_ship_counts_alarms_per_test_and_alarms_the_seed_004_jump() {
        let truth = crate::ship_trajectory()
            .unwrap()
            .sample(1.0, 1300.0)
            .unwrap();
        let faults: Vec<Fault> = crate::ship_faults()
            .into_iter()
            .filter(|f| f.channel == crate::Channel::Position)
            .collect();
        let scenario = crate::simulate(
            ScenarioParams {
                ins_rate_hz: 1.0,
                ..ship_params(1, faults)
            },
            truth,
        )
        .unwrap();
        let params = AlarmsParams::default();
        let run = super::super::run_monitor(
            &scenario,
            &spec(&scenario, AlarmsConfig::Defaults, &params).unwrap(),
        )
        .unwrap();
        assert_eq!(
            run.integrity_counts.iter().sum::<usize>(),
            scenario.epochs.len()
        );
        let x = score(&scenario, "ship".into(), AlarmsConfig::Defaults, &run);
        let names: Vec<&str> = x.tests.iter().map(|t| t.test.as_str()).collect();
        assert!(
            names.contains(&"gnss.drift") && names.contains(&"dvl"),
            "{names:?}"
        );
        assert_eq!(x.faults.len(), 1);
        let jump = &x.faults[0];
        assert!(jump.warning_s.unwrap() <= 2.0, "{jump:?}");
        assert!(jump.alarm_s.unwrap() <= 10.0, "{jump:?}");
        assert!(x.every_fault_alarmed());
        assert!(x.hours() > 0.25 && x.hours() < 1300.0 / 3600.0);
        let text = render(&AlarmsResult {
            p_fa: 1e-3,
            sessions: vec![x],
        });
        assert!(text.contains("gnss [1080, 1200)"), "{text}");
        assert_eq!(aid_of("gnss.stuck"), Some(Aid::Gnss));
        assert_eq!(aid_of("residual"), None);
    }
}
