//! The ramp benchmark (docs/methods.md §M19): a slow GNSS position drift — the
//! spoofing-like fault integrity users most often report missed — of 0.5, 1, 2
//! and 5 m/s from a fixed onset, through the `federated` monitor under each
//! policy and threshold. Scored on
//! - the seconds from onset to the GNSS test's first alarm (first non-healthy
//!   epoch) and the drift injected by then: at a low threshold this first alarm
//!   may be a chance exceedance rather than a detection of the drift;
//! - the seconds to *exclusion*: the start of the non-healthy stretch that lasts
//!   to the end of the run (under classic the drift is let back in whenever λ
//!   dips below the threshold, so exclusion comes later than the first alarm);
//! - the corrected solution's horizontal error: at its worst before exclusion
//!   (what the drift did to the user) and over the whole watch window.
//!
//! The drift is horizontal, split equally between east and north (rate/√2
//! each, like seed 004's jump in both latitude and longitude), from
//! [`RampParams::onset_s`] to the end of the run; the run ends
//! [`RampParams::window_s`] after onset, and a drift not alarmed by then is
//! reported as missed.

use std::fmt::Write as _;

use super::{ExperimentError, run_monitor};
use crate::detect::{Health, PolicyConfig};
use crate::epoch::Aid;
use crate::sim::{self, Channel, Fault, FaultKind, Scenario, SimError};

/// The drift rates, m/s.
pub const RATES_MPS: [f64; 4] = [0.5, 1.0, 2.0, 5.0];

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct RampParams {
    /// Scenario seed.
    pub seed: u64,
    /// Drift onset, s.
    pub onset_s: f64,
    /// Observation window after onset, s.
    pub window_s: f64,
    /// Start of the fault-free reference error, s (after the initial convergence).
    pub settle_s: f64,
    /// Drift rates, m/s.
    pub rates_mps: Vec<f64>,
    /// Raw thresholds (seed 004's 13 and 20).
    pub thresholds: Vec<f64>,
    /// Counters' N1 and N2.
    pub n1: u32,
    /// Counters' N2.
    pub n2: u32,
}

impl Default for RampParams {
    fn default() -> Self {
        RampParams {
            seed: 1,
            onset_s: 1000.0,
            window_s: 600.0,
            settle_s: super::seed004::SETTLE_S,
            rates_mps: RATES_MPS.to_vec(),
            thresholds: super::seed004::THRESHOLDS.to_vec(),
            n1: 10,
            n2: 5,
        }
    }
}

/// One drift under one policy and threshold.
#[derive(Debug, Clone, PartialEq)]
pub struct RampRow {
    /// Drift rate, m/s.
    pub rate_mps: f64,
    /// The policy.
    pub policy: PolicyConfig,
    /// The raw threshold.
    pub threshold: f64,
    /// Seconds from onset to the GNSS test's first non-healthy epoch (`None`: none).
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

impl RampRow {
    /// `classic T=20`, `counters T=13`, …
    pub fn label(&self) -> String {
        format!("{} T={}", self.policy.kind_name(), self.threshold)
    }
}

/// The benchmark's rows.
#[derive(Debug, Clone, PartialEq)]
pub struct RampResult {
    /// The parameters.
    pub params: RampParams,
    /// One row per rate, policy and threshold.
    pub rows: Vec<RampRow>,
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

/// Runs every rate under every policy and threshold on the 10 Hz `ship`.
pub fn run(params: RampParams) -> Result<RampResult, ExperimentError> {
    let seed = params.seed;
    run_with(params, move |faults, duration_s| {
        sim::ship_with(seed, faults, duration_s)
    })
}

/// Runs every rate under every policy and threshold on the scenarios `build`
/// makes from a fault list and a duration (tests use a cheaper INS rate).
pub fn run_with(
    params: RampParams,
    build: impl Fn(Vec<Fault>, f64) -> Result<Scenario, SimError>,
) -> Result<RampResult, ExperimentError> {
    let policies = [
        PolicyConfig::Classic,
        PolicyConfig::Counters {
            n1: params.n1,
            n2: params.n2,
        },
    ];
    let mut rows = Vec::new();
    for &rate in &params.rates_mps {
        let scenario = build(
            ramp_faults(rate, params.onset_s),
            params.onset_s + params.window_s,
        )?;
        for &threshold in &params.thresholds {
            for policy in policies {
                let spec = super::seed004::spec(&scenario, policy, threshold)
                    .map_err(crate::monitor::BuildError::from)?;
                let run = run_monitor(&scenario, &spec)?;
                let gnss = run.tests.get("gnss").map(Vec::as_slice).unwrap_or(&[]);
                let alarm = run.first_alarm("gnss", params.onset_s);
                // The last healthy GNSS epoch after onset; exclusion starts at the next one.
                let excluded = match gnss.iter().rposition(|s| s.health == Health::Healthy) {
                    Some(i) => gnss.get(i + 1).map(|s| s.t),
                    None => gnss.first().map(|s| s.t),
                }
                .filter(|&t| t >= params.onset_s);
                let max_between = |a: f64, b: f64| {
                    run.errors
                        .iter()
                        .filter(|e| e.t >= a && e.t < b)
                        .map(|e| e.horizontal_m())
                        .fold(0.0, f64::max)
                };
                let excluded_s = excluded.map(|t| t - params.onset_s);
                rows.push(RampRow {
                    rate_mps: rate,
                    policy,
                    threshold,
                    alarm_s: alarm.map(|t| t - params.onset_s),
                    excluded_s,
                    drift_at_exclusion_m: excluded_s.map(|d| d * rate),
                    max_error_before_exclusion_m: max_between(
                        params.onset_s,
                        excluded.unwrap_or(f64::INFINITY),
                    ),
                    max_error_window_m: max_between(params.onset_s, f64::INFINITY),
                    max_error_before_onset_m: max_between(params.settle_s, params.onset_s),
                });
            }
        }
    }
    Ok(RampResult { params, rows })
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "—".to_owned(), |v| format!("{v:.digits$}"))
}

/// The text table.
pub fn render(r: &RampResult) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "ramp — ship scenario, seed {}: GNSS horizontal position drift from {:.0} s (NE, rate/√2 per axis), watched for {:.0} s",
        r.params.seed, r.params.onset_s, r.params.window_s
    );
    let _ = writeln!(
        s,
        "alarm = onset → first non-healthy GNSS epoch; excluded = onset → start of the non-healthy stretch lasting to the end;\n\
         drift = rate × seconds; errors = corrected solution, horizontal; fault-free level = max error from {:.0} s to onset\n",
        r.params.settle_s
    );
    let _ = writeln!(
        s,
        "{:>8}  {:<15} {:>7} {:>10} {:>9} {:>15} {:>13} {:>12}",
        "rate m/s",
        "policy",
        "alarm s",
        "excluded s",
        "drift m",
        "max err before",
        "max err all",
        "fault-free"
    );
    for row in &r.rows {
        let _ = writeln!(
            s,
            "{:>8}  {:<15} {:>7} {:>10} {:>9} {:>15.2} {:>13.2} {:>12.2}",
            row.rate_mps,
            row.label(),
            opt(row.alarm_s, 0),
            opt(row.excluded_s, 0),
            opt(row.drift_at_exclusion_m, 1),
            row.max_error_before_exclusion_m,
            row.max_error_window_m,
            row.max_error_before_onset_m
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::scenario::{ScenarioParams, ship_params};

    /// The ship at a 1 Hz INS rate: cheap enough for a unit test.
    fn ship_1hz(faults: Vec<Fault>, duration_s: f64) -> Result<Scenario, SimError> {
        let truth = sim::ship_trajectory()?.sample(1.0, duration_s)?;
        let params = ScenarioParams {
            ins_rate_hz: 1.0,
            ..ship_params(1, faults)
        };
        sim::simulate(params, truth)
    }

    #[test]
    fn a_fast_drift_is_excluded_by_both_policies_and_rendered() {
        let params = RampParams {
            onset_s: 400.0,
            window_s: 60.0,
            rates_mps: vec![5.0],
            thresholds: vec![20.0],
            ..RampParams::default()
        };
        let r = run_with(params, ship_1hz).unwrap();
        assert_eq!(r.rows.len(), 2);
        for row in &r.rows {
            // 5 m/s against 10 m GNSS noise: λ passes 20 within about ten seconds.
            let excluded = row.excluded_s.unwrap();
            assert!((0.0..30.0).contains(&excluded), "{row:?}");
            assert!(row.alarm_s.unwrap() <= excluded);
            assert_eq!(row.drift_at_exclusion_m, Some(5.0 * excluded));
            assert!(row.max_error_window_m >= row.max_error_before_exclusion_m);
        }
        let text = render(&r);
        assert!(
            text.contains("classic T=20") && text.contains("counters T=20"),
            "{text}"
        );
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
