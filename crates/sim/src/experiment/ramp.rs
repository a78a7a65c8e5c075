//! The ramp benchmark (docs/methods.md §M19, §M23): a slow GNSS position drift — the
//! spoofing-like fault integrity users most often report missed — of 0.5, 1, 2 and 5 m/s
//! from a fixed onset, through the `federated` monitor under each case (policy, threshold,
//! and whether the `gnss.drift` test runs beside the per-epoch χ²), on several seeds.
//! Scored per seed, then as the mean and the worst over the seeds, on
//! - the seconds from onset to the GNSS aid's first warning (first epoch on which any of its
//!   tests is not healthy; at a low threshold this may be a chance exceedance rather than a
//!   detection of the drift) and to its first alarm (first entry of one of its tests into
//!   `isolated`);
//! - the seconds to *exclusion*: the start of the non-healthy stretch of the aid that
//!   lasts to the end of the run (under classic the drift is let back in whenever λ dips
//!   below the threshold, so exclusion comes later than the first alarm), and the drift
//!   injected by then;
//! - the corrected solution's horizontal error: at its worst before exclusion (what the
//!   drift did to the user) and over the whole watch window;
//! - beside each rate, the theoretical floor of a matched test: a known-onset ramp GLR on
//!   the raw GNSS fixes (noise σ per axis, one fix every Δt) has non-centrality
//!   `λ_n = v² Σ_{k≤n} (kΔt)² / σ² ≈ v² n³ Δt² / (3σ²)` after `n` fixes, so it reaches the
//!   `λ` that gives a 50 % detection at the χ²(1) threshold of `p_fa` after
//!   `n = (3σ²λ / (v²Δt²))^{1/3}` fixes, a drift of `d = v n Δt = (3σ²λ v Δt)^{1/3}`;
//! - and, for every case, the fault-free GNSS rates on the fault-free ship (same seeds,
//!   3600 s): the share of GNSS epochs not healthy against the nominal `p_fa`, and
//!   alarms and warnings per hour: the GNSS tests' log entries as the session core writes
//!   them (the server's rule).
//!
//! The drift is horizontal, split equally between east and north (rate/√2 each, like seed
//! 004's jump in both latitude and longitude), from [`RampParams::onset_s`] to the end of
//! the run; the run ends [`RampParams::window_s`] after onset, and a drift not excluded by
//! then is reported as missed.

use std::fmt::Write as _;

use super::{ExperimentError, MonitorRun, run_monitor};
use crate::{Channel, Fault, FaultKind, Scenario, SimError};
use navguard_core::detect::{Health, PolicyConfig, ThresholdSpec, chi2};
use navguard_core::epoch::Aid;
use navguard_core::monitor::federated::{CnsNoise, DvlNoise, FederatedConfigWire, GnssNoise};
use navguard_core::monitor::guards::{DriftConfigWire, StuckConfigWire};
use navguard_core::monitor::{MonitorConfig, MonitorKind, MonitorSpec};

/// The drift rates, m/s.
pub const RATES_MPS: [f64; 4] = [0.5, 1.0, 2.0, 5.0];

/// The false-alarm probability of the target cases (the server setting they target).
pub const TARGET_P_FA: f64 = 1e-3;

/// One configuration of the monitor.
#[derive(Debug, Clone, PartialEq)]
pub struct RampCase {
    /// The policy.
    pub policy: PolicyConfig,
    /// The threshold of every test (a raw one as seed 004's, or a `p_fa`).
    pub threshold: ThresholdSpec,
    /// The `gnss.drift` block, the other aids' drift and stuck tests at their defaults
    /// (`None`: the per-epoch χ² tests alone, every drift and stuck test off).
    pub drift: Option<DriftConfigWire>,
}

impl RampCase {
    /// `classic T=20`, `counters p_fa=0.001 +drift[12]`, …
    pub fn label(&self) -> String {
        let threshold = match self.threshold {
            ThresholdSpec::Threshold(t) => format!("T={t}"),
            ThresholdSpec::PFa(p) => format!("p_fa={p}"),
        };
        let drift = match &self.drift {
            Some(d) => {
                let w: Vec<String> = d.windows.iter().map(ToString::to_string).collect();
                format!(" +drift[{}]", w.join(","))
            }
            None => String::new(),
        };
        format!("{} {threshold}{drift}", self.policy.kind_name())
    }

    /// The monitor spec on `scenario`: its federated config with the guards the case asks
    /// for (field doc of [`RampCase::drift`]).
    pub fn spec(&self, scenario: &Scenario) -> Result<MonitorSpec, ExperimentError> {
        let mut config: FederatedConfigWire = scenario.monitor_config();
        match &self.drift {
            Some(d) => config.gnss.get_or_insert_with(GnssNoise::default).drift = Some(d.clone()),
            None => {
                let (off, no_stuck) = (
                    || Some(DriftConfigWire::disabled()),
                    || Some(StuckConfigWire::disabled()),
                );
                let g = config.gnss.get_or_insert_with(GnssNoise::default);
                (g.drift, g.stuck) = (off(), no_stuck());
                let d = config.dvl.get_or_insert_with(DvlNoise::default);
                (d.drift, d.stuck) = (off(), no_stuck());
                let c = config.cns.get_or_insert_with(CnsNoise::default);
                (c.drift, c.stuck) = (off(), no_stuck());
            }
        }
        let value = serde_json::to_value(&config).map_err(|e| {
            navguard_core::monitor::BuildError::from(navguard_core::monitor::ConfigError::new(
                "",
                e.to_string(),
            ))
        })?;
        Ok(MonitorSpec {
            kind: MonitorKind::Federated,
            config: MonitorConfig::parse(MonitorKind::Federated, &value)
                .map_err(navguard_core::monitor::BuildError::from)?,
            policy: self.policy,
            threshold: self.threshold,
        })
    }
}

/// The default cases: seed 004's thresholds under classic and counters (per-epoch χ²
/// only), then the target server setting (counters, p_fa 1e-3) without and with the
/// drift test.
pub fn default_cases() -> Vec<RampCase> {
    let mut cases = Vec::new();
    for t in super::seed004::THRESHOLDS {
        for policy in [PolicyConfig::Classic, PolicyConfig::counters_default()] {
            cases.push(RampCase {
                policy,
                threshold: ThresholdSpec::Threshold(t),
                drift: None,
            });
        }
    }
    for drift in [None, Some(DriftConfigWire::default())] {
        cases.push(RampCase {
            policy: PolicyConfig::counters_default(),
            threshold: ThresholdSpec::PFa(TARGET_P_FA),
            drift,
        });
    }
    cases
}

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct RampParams {
    /// Scenario seeds.
    pub seeds: Vec<u64>,
    /// Drift onset, s.
    pub onset_s: f64,
    /// Observation window after onset, s.
    pub window_s: f64,
    /// Start of the fault-free reference error, s (after the initial convergence).
    pub settle_s: f64,
    /// Drift rates, m/s.
    pub rates_mps: Vec<f64>,
    /// The monitor configurations.
    pub cases: Vec<RampCase>,
    /// Length of the fault-free runs, s (0: none).
    pub fault_free_s: f64,
}

impl Default for RampParams {
    fn default() -> Self {
        RampParams {
            seeds: (1..=5).collect(),
            onset_s: 1000.0,
            window_s: 600.0,
            settle_s: super::seed004::SETTLE_S,
            rates_mps: RATES_MPS.to_vec(),
            cases: default_cases(),
            fault_free_s: crate::SHIP_DURATION_S,
        }
    }
}

/// One drift, one case, one seed.
#[derive(Debug, Clone, PartialEq)]
pub struct RampRun {
    /// The seed.
    pub seed: u64,
    /// Seconds from onset to the aid's first non-healthy epoch (`None`: none).
    pub warning_s: Option<f64>,
    /// Seconds from onset to the aid's first isolated epoch (`None`: none).
    pub alarm_s: Option<f64>,
    /// Seconds from onset to the exclusion (module doc; `None`: not excluded by the end).
    pub excluded_s: Option<f64>,
    /// Drift injected by the exclusion, m (rate × seconds).
    pub drift_at_exclusion_m: Option<f64>,
    /// Largest horizontal error from onset to the exclusion (or the end), m.
    pub max_error_before_exclusion_m: f64,
    /// Largest horizontal error from onset to the end of the run, m.
    pub max_error_window_m: f64,
    /// Largest horizontal error from settling to onset, m (the fault-free level).
    pub max_error_before_onset_m: f64,
}

/// One drift rate under one case, over the seeds.
#[derive(Debug, Clone, PartialEq)]
pub struct RampRow {
    /// Drift rate, m/s.
    pub rate_mps: f64,
    /// The case.
    pub case: RampCase,
    /// One run per seed.
    pub runs: Vec<RampRun>,
}

/// Mean and largest of some values (`None` for none).
fn mean_max(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let v: Vec<f64> = values.collect();
    (!v.is_empty()).then(|| {
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        (mean, v.iter().copied().fold(f64::MIN, f64::max))
    })
}

impl RampRow {
    /// `classic T=20`, `counters p_fa=0.001 +drift[12]`, …
    pub fn label(&self) -> String {
        self.case.label()
    }

    /// Runs in which the drift was excluded.
    pub fn excluded(&self) -> usize {
        self.runs.iter().filter(|r| r.excluded_s.is_some()).count()
    }

    /// Mean and worst drift at exclusion over the seeds, m; `None` unless every seed
    /// excluded it (a missed seed makes the worst case unbounded).
    pub fn drift_at_exclusion_m(&self) -> Option<(f64, f64)> {
        if self.excluded() < self.runs.len() {
            return None;
        }
        mean_max(self.runs.iter().filter_map(|r| r.drift_at_exclusion_m))
    }

    /// Mean and latest first warning, s (over the seeds that warned).
    pub fn warning_s(&self) -> Option<(f64, f64)> {
        mean_max(self.runs.iter().filter_map(|r| r.warning_s))
    }

    /// Mean and latest first alarm, s (over the seeds that alarmed).
    pub fn alarm_s(&self) -> Option<(f64, f64)> {
        mean_max(self.runs.iter().filter_map(|r| r.alarm_s))
    }

    /// Runs that raised an alarm.
    pub fn alarmed(&self) -> usize {
        self.runs.iter().filter(|r| r.alarm_s.is_some()).count()
    }

    /// Mean and latest exclusion, s (over the seeds that excluded).
    pub fn excluded_s(&self) -> Option<(f64, f64)> {
        mean_max(self.runs.iter().filter_map(|r| r.excluded_s))
    }

    /// Mean and largest of the worst horizontal error before exclusion, m.
    pub fn max_error_before_exclusion_m(&self) -> Option<(f64, f64)> {
        mean_max(self.runs.iter().map(|r| r.max_error_before_exclusion_m))
    }
}

/// A case's fault-free GNSS rates over the fault-free seeds.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultFreeRow {
    /// The case.
    pub case: RampCase,
    /// The nominal per-epoch false-alarm probability of each GNSS test (the `p_fa`, or the
    /// χ²(6) tail at a raw threshold).
    pub p_fa: f64,
    /// GNSS epochs (over the seeds).
    pub epochs: usize,
    /// Share of them on which the χ² test `gnss` is not healthy.
    pub chi2_far: f64,
    /// Share of them on which the aid (any GNSS test) is not healthy.
    pub aid_far: f64,
    /// Entries of the aid into `isolated`, per hour.
    pub alarms_per_hour: f64,
    /// Entries of the aid into `suspect`, per hour.
    pub warnings_per_hour: f64,
    /// The nominal rate of such entries, per hour: `p_fa` per GNSS epoch for each GNSS test
    /// under the monitor's spec (the χ² test, and the drift test when it runs; the stuck
    /// test's 1e-6 is left out).
    pub nominal_per_hour: f64,
}

impl FaultFreeRow {
    /// Entries into `suspect` or `isolated` per hour as a multiple of the nominal rate.
    pub fn events_over_nominal(&self) -> f64 {
        (self.alarms_per_hour + self.warnings_per_hour) / self.nominal_per_hour
    }
}

/// The benchmark's rows.
#[derive(Debug, Clone, PartialEq)]
pub struct RampResult {
    /// The parameters.
    pub params: RampParams,
    /// One row per rate and case.
    pub rows: Vec<RampRow>,
    /// One row per case (empty with `fault_free_s = 0`).
    pub fault_free: Vec<FaultFreeRow>,
    /// GNSS position noise per axis of the scenario, m, and its fix interval, s (the floor's
    /// σ and Δt).
    pub gnss_sigma_m: f64,
    /// GNSS fix interval, s.
    pub gnss_interval_s: f64,
}

/// The matched-test floor (module doc): the drift at which a known-onset ramp GLR on raw
/// fixes with noise `sigma_m` every `interval_s` reaches a 50 % detection at the χ²(1)
/// threshold of `p_fa`, m.
pub fn matched_floor_m(rate_mps: f64, sigma_m: f64, interval_s: f64, p_fa: f64) -> f64 {
    let lambda = chi2::threshold(1, p_fa)
        .and_then(|t| chi2::noncentrality_for_missed_detection(1, t, 0.5))
        .unwrap_or(f64::NAN);
    (3.0 * sigma_m * sigma_m * lambda * rate_mps * interval_s).cbrt()
}

/// The faults of one drift rate.
pub fn ramp_faults(rate_mps: f64, onset_s: f64) -> Vec<Fault> {
    let per_axis = rate_mps / std::f64::consts::SQRT_2;
    (0..2)
        .map(|component| Fault {
            aid: Aid::Gnss,
            channel: Channel::Position,
            component,
            kind: FaultKind::Ramp { rate: per_axis },
            start_s: onset_s,
            end_s: None,
        })
        .collect()
}

/// Runs every rate under every case on the 10 Hz `ship` of each seed.
pub fn run(params: RampParams) -> Result<RampResult, ExperimentError> {
    run_with(params, crate::ship_with)
}

/// Scores one run of one drift (module doc).
fn score_run(run: &MonitorRun, seed: u64, rate: f64, params: &RampParams) -> RampRun {
    let gnss = run.aid_health_trace("gnss");
    let onset = params.onset_s;
    let first = |bad: &dyn Fn(Health) -> bool| {
        gnss.iter()
            .find(|(t, h)| *t >= onset && bad(*h))
            .map(|&(t, _)| t - onset)
    };
    let warning_s = first(&|h| h != Health::Healthy);
    let alarm_s = first(&|h| h == Health::Isolated);
    // The last healthy GNSS epoch; exclusion starts at the next one.
    let excluded = match gnss.iter().rposition(|(_, h)| *h == Health::Healthy) {
        Some(i) => gnss.get(i + 1).map(|s| s.0),
        None => gnss.first().map(|s| s.0),
    }
    .filter(|&t| t >= onset);
    let max_between = |a: f64, b: f64| {
        run.errors
            .iter()
            .filter(|e| e.t >= a && e.t < b)
            .map(|e| e.horizontal_m())
            .fold(0.0, f64::max)
    };
    let excluded_s = excluded.map(|t| t - onset);
    RampRun {
        seed,
        warning_s,
        alarm_s,
        excluded_s,
        drift_at_exclusion_m: excluded_s.map(|d| d * rate),
        max_error_before_exclusion_m: max_between(onset, excluded.unwrap_or(f64::INFINITY)),
        max_error_window_m: max_between(onset, f64::INFINITY),
        max_error_before_onset_m: max_between(params.settle_s, onset),
    }
}

/// A case's fault-free GNSS rates over `scenarios`.
fn fault_free_row(
    case: &RampCase,
    scenarios: &[Scenario],
) -> Result<FaultFreeRow, ExperimentError> {
    let p_fa = case
        .threshold
        .p_fa(6)
        .map_err(navguard_core::monitor::BuildError::from)?;
    let (mut epochs, mut chi2_bad, mut aid_bad) = (0usize, 0usize, 0usize);
    let (mut hours, mut alarms, mut warnings) = (0.0, 0usize, 0usize);
    for scenario in scenarios {
        let run = run_monitor(scenario, &case.spec(scenario)?)?;
        let chi2 = run.health_trace("gnss");
        let aid = run.aid_health_trace("gnss");
        epochs += aid.len();
        chi2_bad += chi2.iter().filter(|(_, h)| *h != Health::Healthy).count();
        aid_bad += aid.iter().filter(|(_, h)| *h != Health::Healthy).count();
        let card = run.aid_scorecard("gnss", &case.label(), &[]);
        hours += card.clear_hours;
        alarms += card.clear_alarms;
        warnings += card.clear_warnings;
    }
    let share = |n: usize| n as f64 / epochs.max(1) as f64;
    let per_hour = |n: usize| if hours > 0.0 { n as f64 / hours } else { 0.0 };
    let epochs_per_hour = 3600.0 * epochs as f64
        / scenarios
            .iter()
            .map(Scenario::duration_s)
            .sum::<f64>()
            .max(1.0);
    let tests = 1.0 + f64::from(u8::from(case.drift.is_some()));
    Ok(FaultFreeRow {
        case: case.clone(),
        p_fa,
        epochs,
        chi2_far: share(chi2_bad),
        aid_far: share(aid_bad),
        alarms_per_hour: per_hour(alarms),
        warnings_per_hour: per_hour(warnings),
        nominal_per_hour: p_fa * epochs_per_hour * tests,
    })
}

/// Runs every rate under every case on the scenarios `build` makes from a seed, a fault
/// list and a duration (tests use a cheaper INS rate).
pub fn run_with(
    params: RampParams,
    build: impl Fn(u64, Vec<Fault>, f64) -> Result<Scenario, SimError>,
) -> Result<RampResult, ExperimentError> {
    let mut rows: Vec<RampRow> = Vec::new();
    let mut sigma = (10.0, 1.0);
    for &rate in &params.rates_mps {
        let mut by_case: Vec<RampRow> = params
            .cases
            .iter()
            .map(|case| RampRow {
                rate_mps: rate,
                case: case.clone(),
                runs: Vec::new(),
            })
            .collect();
        for &seed in &params.seeds {
            let scenario = build(
                seed,
                ramp_faults(rate, params.onset_s),
                params.onset_s + params.window_s,
            )?;
            if let Some(g) = scenario.sensors.gnss {
                sigma = (g.pos_sigma_m, 1.0 / g.rate_hz);
            }
            for row in &mut by_case {
                let run = run_monitor(&scenario, &row.case.spec(&scenario)?)?;
                row.runs.push(score_run(&run, seed, rate, &params));
            }
        }
        rows.extend(by_case);
    }
    let mut fault_free = Vec::new();
    if params.fault_free_s > 0.0 {
        let scenarios = params
            .seeds
            .iter()
            .map(|&seed| build(seed, Vec::new(), params.fault_free_s))
            .collect::<Result<Vec<_>, _>>()?;
        for case in &params.cases {
            fault_free.push(fault_free_row(case, &scenarios)?);
        }
    }
    Ok(RampResult {
        params,
        rows,
        fault_free,
        gnss_sigma_m: sigma.0,
        gnss_interval_s: sigma.1,
    })
}

fn pair(v: Option<(f64, f64)>, digits: usize) -> String {
    v.map_or_else(
        || "—".to_owned(),
        |(mean, max)| format!("{mean:.digits$} / {max:.digits$}"),
    )
}

/// The text table: each drift case against the matched-filter floor, then, when
/// they ran, the fault-free runs' rates of non-healthy epochs, alarms and warnings.
pub fn render(r: &RampResult) -> String {
    let mut s = String::new();
    render_drifts(&mut s, r);
    if !r.fault_free.is_empty() {
        render_fault_free(&mut s, r);
    }
    s
}

/// The drift table: its legend, then one row per rate and case.
fn render_drifts(s: &mut String, r: &RampResult) {
    let p = &r.params;
    let _ = writeln!(
        s,
        "ramp — ship scenario, seeds {:?}: GNSS horizontal position drift from {:.0} s (NE, rate/√2 per axis), watched for {:.0} s",
        p.seeds, p.onset_s, p.window_s
    );
    let _ = writeln!(
        s,
        "per case: mean / worst over the seeds. warning = onset → the GNSS aid's first non-healthy epoch (any of its tests); alarm = onset →\n\
         its first isolated epoch (alarmed: seeds that raised one); excluded = onset → start of the aid's non-healthy stretch lasting to the end;\n\
         drift = rate × seconds at exclusion (— : a seed never excluded it);\n\
         err before = the corrected solution's largest horizontal error before exclusion. floor = a matched known-onset ramp GLR on the raw\n\
         fixes (σ = {} m per axis, one fix every {} s) at 50 % detection, χ²(1) threshold of p_fa = {}: (3σ²λvΔt)^(1/3)\n",
        r.gnss_sigma_m, r.gnss_interval_s, TARGET_P_FA
    );
    let _ = writeln!(
        s,
        "{:>8} {:>8}  {:<32} {:>11} {:>11} {:>8} {:>11} {:>13} {:>13} {:>9}",
        "rate m/s",
        "floor m",
        "case",
        "warning s",
        "alarm s",
        "alarmed",
        "excluded s",
        "drift m",
        "err before m",
        "vs floor"
    );
    for row in &r.rows {
        let floor = matched_floor_m(row.rate_mps, r.gnss_sigma_m, r.gnss_interval_s, TARGET_P_FA);
        let drift = row.drift_at_exclusion_m();
        let versus = drift.map_or_else(
            || format!("{}/{} excl.", row.excluded(), row.runs.len()),
            |(mean, _)| format!("{:+.1} m", mean - floor),
        );
        let _ = writeln!(
            s,
            "{:>8} {:>8.1}  {:<32} {:>11} {:>11} {:>8} {:>11} {:>13} {:>13} {:>9}",
            row.rate_mps,
            floor,
            row.label(),
            pair(row.warning_s(), 0),
            pair(row.alarm_s(), 0),
            format!("{}/{}", row.alarmed(), row.runs.len()),
            pair(row.excluded_s(), 0),
            pair(drift, 1),
            pair(row.max_error_before_exclusion_m(), 1),
            versus
        );
    }
}

/// The fault-free table: its legend, then one row per case.
fn render_fault_free(s: &mut String, r: &RampResult) {
    let p = &r.params;
    let _ = writeln!(
        s,
        "\nfault-free ship, same seeds, {:.0} s each: GNSS epochs not healthy (χ² test alone; the aid, any GNSS test) as a share and\n\
         as a multiple of the nominal p_fa per test; alarms and warnings = the GNSS tests' log entries as the server writes them, per fault-free hour;\n\
         events ÷ nominal = (alarms + warnings) per hour over p_fa × GNSS epochs per hour × GNSS tests under the monitor's spec",
        p.fault_free_s
    );
    let _ = writeln!(
        s,
        "{:<34} {:>9} {:>8} {:>16} {:>16} {:>9} {:>9} {:>16}",
        "case",
        "p_fa",
        "epochs",
        "χ² not healthy",
        "aid not healthy",
        "alarms/h",
        "warn/h",
        "events ÷ nominal"
    );
    for f in &r.fault_free {
        let _ = writeln!(
            s,
            "{:<34} {:>9.2e} {:>8} {:>16} {:>16} {:>9.2} {:>9.2} {:>15.2}×",
            f.case.label(),
            f.p_fa,
            f.epochs,
            format!("{:.3} % {:.1}×", 100.0 * f.chi2_far, f.chi2_far / f.p_fa),
            format!("{:.3} % {:.1}×", 100.0 * f.aid_far, f.aid_far / f.p_fa),
            f.alarms_per_hour,
            f.warnings_per_hour,
            f.events_over_nominal()
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::{ScenarioParams, ship_params};

    /// The ship at a 1 Hz INS rate: cheap enough for a unit test.
    fn ship_1hz(seed: u64, faults: Vec<Fault>, duration_s: f64) -> Result<Scenario, SimError> {
        let truth = crate::ship_trajectory()?.sample(1.0, duration_s)?;
        let params = ScenarioParams {
            ins_rate_hz: 1.0,
            ..ship_params(seed, faults)
        };
        crate::simulate(params, truth)
    }

    #[test]
    fn a_fast_drift_is_excluded_by_every_case_and_rendered() {
        let params = RampParams {
            seeds: vec![1, 2],
            onset_s: 400.0,
            window_s: 60.0,
            rates_mps: vec![5.0],
            fault_free_s: 500.0,
            ..RampParams::default()
        };
        let r = run_with(params, ship_1hz).unwrap();
        assert_eq!(r.rows.len(), 6);
        for row in &r.rows {
            assert_eq!(row.runs.len(), 2);
            for run in &row.runs {
                // 5 m/s against 10 m GNSS noise: λ passes 20 within about ten seconds.
                let excluded = run.excluded_s.unwrap();
                assert!((0.0..30.0).contains(&excluded), "{} {run:?}", row.label());
                assert!(run.warning_s.unwrap() <= excluded);
                assert!(run.alarm_s.unwrap() >= run.warning_s.unwrap());
                assert_eq!(run.drift_at_exclusion_m, Some(5.0 * excluded));
                assert!(run.max_error_window_m >= run.max_error_before_exclusion_m);
            }
            let (mean, worst) = row.drift_at_exclusion_m().unwrap();
            assert!(mean <= worst);
        }
        assert_eq!(r.fault_free.len(), 6);
        assert!(r.fault_free.iter().all(|f| f.epochs > 900));
        let text = render(&r);
        for label in [
            "classic T=20",
            "counters T=13",
            "counters p_fa=0.001 +drift[12]",
        ] {
            assert!(text.contains(label), "{label}: {text}");
        }
    }

    #[test]
    fn the_floor_is_the_cube_root_formula() {
        // λ for a 50 % detection at χ²(1)'s 1e-3 threshold (10.83) is about 10.8.
        let lambda =
            chi2::noncentrality_for_missed_detection(1, chi2::threshold(1, 1e-3).unwrap(), 0.5)
                .unwrap();
        assert!((lambda - 10.8).abs() < 0.3, "{lambda}");
        let d = matched_floor_m(1.0, 10.0, 1.0, 1e-3);
        assert!((d - (300.0 * lambda).cbrt()).abs() < 1e-9);
        // The target's 11–18 m at 0.5 to 2 m/s.
        assert!((11.0..12.5).contains(&matched_floor_m(0.5, 10.0, 1.0, 1e-3)));
        assert!((17.5..19.5).contains(&matched_floor_m(2.0, 10.0, 1.0, 1e-3)));
    }

    #[test]
    fn ramp_faults_drift_horizontally_at_the_rate() {
        let f = ramp_faults(2.0, 1000.0);
        assert_eq!(f.len(), 2);
        let rates: Vec<f64> = f
            .iter()
            .map(|f| match f.kind {
                FaultKind::Ramp { rate } => rate,
                _ => f64::NAN,
            })
            .collect();
        assert!((rates[0].hypot(rates[1]) - 2.0).abs() < 1e-12);
        assert!(f.iter().all(|f| f.start_s == 1000.0 && f.end_s.is_none()));
        assert_eq!((f[0].component, f[1].component), (0, 1));
    }
}
