//! Seed 004's experiment (§3, Tables 1–3, Figs. 3–10): the `ship` scenario
//! through the `federated` monitor under the classic residual χ² test and the
//! counter policy (N1 = 10, N2 = 5), each at raw thresholds 13 and 20. Per
//! case: the latitude, longitude (as metres) and east/north velocity errors of
//! the corrected solution against the truth (mean |e|, std of e, max |e| over
//! the whole run), the scorecard of every test, and the figures (errors and
//! the GNSS test's λ against time with the threshold).

use std::fmt::Write as _;

use super::plot::{Chart, Series};
use super::scorecard::{self, FaultWindow, Scorecard};
use super::{ErrorStats, ExperimentError, MonitorRun, fault_windows, run_monitor};
use crate::detect::{PolicyConfig, ThresholdSpec};
use crate::epoch::Aid;
use crate::monitor::{MonitorKind, MonitorSpec};
use crate::sim::{self, Scenario};

/// Seed 004's two thresholds.
pub const THRESHOLDS: [f64; 2] = [13.0, 20.0];

/// The paper's headline figures at threshold 20 (seed 004 abstract and §3).
pub mod paper {
    /// Counters' latitude error as a share of the classic test's (Table 1).
    pub const MEAN_RATIO: f64 = 0.18;
    /// Latitude error fluctuation, classic, m (Table 2).
    pub const CLASSIC_STD_M: f64 = 4.15;
    /// Latitude error fluctuation, counters, m (Table 2).
    pub const COUNTERS_STD_M: f64 = 0.57;
    /// Fluctuation ratio (Table 2).
    pub const STD_RATIO: f64 = 0.14;
    /// Counters' largest position error stays below this, m (Table 3).
    pub const COUNTERS_MAX_BELOW_M: f64 = 5.0;
    /// The classic test's smallest maximum position error, m (Table 3).
    pub const CLASSIC_MAX_AT_LEAST_M: f64 = 16.36;
    /// Maximum-error ratio (abstract).
    pub const MAX_RATIO: f64 = 0.13;
}

/// The default start of the statistics, s: the filter's convergence from the
/// 10 m / 0.1 m/s / 30″ initial errors takes about 150 s and is the same in
/// every case, so it is left out (as the paper's tables, which compare the
/// policies, evidently do: their counters' maximum is below the initial error).
pub const SETTLE_S: f64 = 300.0;

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct Seed004Params {
    /// Scenario seed.
    pub seed: u64,
    /// Run length, s (the paper's figures span 3600 s).
    pub duration_s: f64,
    /// Error statistics use epochs from this time on, s.
    pub settle_s: f64,
    /// Raw thresholds, each run under both policies.
    pub thresholds: Vec<f64>,
    /// Counters' N1.
    pub n1: u32,
    /// Counters' N2.
    pub n2: u32,
}

impl Default for Seed004Params {
    fn default() -> Self {
        Seed004Params {
            seed: 1,
            duration_s: sim::SHIP_DURATION_S,
            settle_s: SETTLE_S,
            thresholds: THRESHOLDS.to_vec(),
            n1: 10,
            n2: 5,
        }
    }
}

/// One policy at one threshold.
#[derive(Debug, Clone, PartialEq)]
pub struct CaseResult {
    /// The policy.
    pub policy: PolicyConfig,
    /// The raw threshold.
    pub threshold: f64,
    /// Latitude error, m.
    pub lat: ErrorStats,
    /// Longitude error, m.
    pub lon: ErrorStats,
    /// East velocity error, m/s.
    pub ve: ErrorStats,
    /// North velocity error, m/s.
    pub vn: ErrorStats,
    /// One scorecard per test.
    pub scorecards: Vec<Scorecard>,
    /// The full run (series for the plots).
    pub run: MonitorRun,
}

impl CaseResult {
    /// `classic T=20`, `counters T=13`, …
    pub fn label(&self) -> String {
        format!("{} T={}", self.policy.kind_name(), self.threshold)
    }

    /// The larger of the latitude and longitude maxima, m.
    pub fn max_position_m(&self) -> f64 {
        self.lat.max.max(self.lon.max)
    }

    fn is_counters(&self) -> bool {
        matches!(self.policy, PolicyConfig::Counters { .. })
    }
}

/// The four cases.
#[derive(Debug, Clone, PartialEq)]
pub struct Seed004Result {
    /// The parameters.
    pub params: Seed004Params,
    /// The GNSS fault windows the scorecards use.
    pub gnss_faults: Vec<FaultWindow>,
    /// Classic and counters at each threshold, in that order.
    pub cases: Vec<CaseResult>,
}

/// Counters over classic at one threshold, latitude (the paper's figures).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ratios {
    /// Mean |latitude error| ratio.
    pub mean: f64,
    /// Latitude error std ratio.
    pub std: f64,
    /// Max position error ratio.
    pub max: f64,
}

impl Seed004Result {
    /// The case with the given policy kind and threshold.
    pub fn case(&self, counters: bool, threshold: f64) -> Option<&CaseResult> {
        self.cases
            .iter()
            .find(|c| c.is_counters() == counters && c.threshold == threshold)
    }

    /// Counters / classic at `threshold`.
    pub fn ratios(&self, threshold: f64) -> Option<Ratios> {
        let (k, c) = (self.case(true, threshold)?, self.case(false, threshold)?);
        Some(Ratios {
            mean: k.lat.mean / c.lat.mean,
            std: k.lat.std / c.lat.std,
            max: k.max_position_m() / c.max_position_m(),
        })
    }

    /// True when, at `threshold`, the counter policy's latitude and longitude
    /// errors are below the classic policy's in mean, std and max.
    pub fn counters_beat_classic(&self, threshold: f64) -> bool {
        let (Some(k), Some(c)) = (self.case(true, threshold), self.case(false, threshold)) else {
            return false;
        };
        let below =
            |a: &ErrorStats, b: &ErrorStats| a.mean < b.mean && a.std < b.std && a.max < b.max;
        below(&k.lat, &c.lat) && below(&k.lon, &c.lon)
    }
}

/// The monitor spec of one case: the scenario's federated config (its sensor
/// noise and IMU), the policy, a raw threshold.
pub fn spec(
    scenario: &Scenario,
    policy: PolicyConfig,
    threshold: f64,
) -> Result<MonitorSpec, crate::monitor::ConfigError> {
    Ok(MonitorSpec {
        kind: MonitorKind::Federated,
        config: crate::monitor::MonitorConfig::parse(
            MonitorKind::Federated,
            &scenario.default_monitor_config(),
        )?,
        policy,
        threshold: ThresholdSpec::Threshold(threshold),
    })
}

/// Runs the four cases on the `ship` scenario.
pub fn run(params: Seed004Params) -> Result<Seed004Result, ExperimentError> {
    let scenario = sim::ship_with(params.seed, sim::ship_faults(), params.duration_s)?;
    run_on(&scenario, params)
}

/// Runs the four cases on a given scenario (tests use shorter ones).
pub fn run_on(
    scenario: &Scenario,
    params: Seed004Params,
) -> Result<Seed004Result, ExperimentError> {
    let gnss_faults = fault_windows(&scenario.faults, Aid::Gnss);
    let policies = [
        PolicyConfig::Classic,
        PolicyConfig::Counters {
            n1: params.n1,
            n2: params.n2,
        },
    ];
    let mut cases = Vec::new();
    for &threshold in &params.thresholds {
        for policy in policies {
            let spec =
                spec(scenario, policy, threshold).map_err(crate::monitor::BuildError::from)?;
            let run = run_monitor(scenario, &spec)?;
            let settled = || run.errors.iter().filter(|e| e.t >= params.settle_s);
            let mut case = CaseResult {
                policy,
                threshold,
                lat: ErrorStats::of(settled().map(|e| e.north_m)),
                lon: ErrorStats::of(settled().map(|e| e.east_m)),
                ve: ErrorStats::of(settled().map(|e| e.ve_mps)),
                vn: ErrorStats::of(settled().map(|e| e.vn_mps)),
                scorecards: Vec::new(),
                run,
            };
            let label = case.label();
            case.scorecards = case
                .run
                .tests
                .keys()
                .map(|test| {
                    let faults: &[FaultWindow] = if test == "gnss" { &gnss_faults } else { &[] };
                    scorecard::score(
                        test,
                        &label,
                        &case.run.health_trace(test),
                        faults,
                        Some(case.run.time_per_epoch_s),
                    )
                })
                .collect();
            cases.push(case);
        }
    }
    Ok(Seed004Result {
        params,
        gnss_faults,
        cases,
    })
}

fn stats_cells(s: &ErrorStats, digits: usize) -> String {
    format!(
        "{:>7.digits$} {:>7.digits$} {:>7.digits$}",
        s.mean, s.std, s.max
    )
}

/// The text report: the table, the ratios beside the paper's, the scorecards.
// Over 80 lines: one report written top to bottom, a straight run of table rows;
// split, the table would be scattered across functions that each print a few lines.
pub fn render(r: &Seed004Result) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "seed 004 — ship scenario, seed {}, {:.0} s, federated INS/GNSS/DVL/CNS; counters N1 = {}, N2 = {}",
        r.params.seed, r.params.duration_s, r.params.n1, r.params.n2
    );
    let _ = writeln!(
        s,
        "errors of the corrected solution against the truth from {:.0} s (after the initial convergence) to the end:\n\
         mean = mean |e| (Table 1, precision), std = std of the signed e (Table 2, stability), max = max |e| (Table 3)\n",
        r.params.settle_s
    );
    let _ = writeln!(
        s,
        "{:<15} {:^23}   {:^23}   {:^23}   {:^23}",
        "", "latitude (m)", "longitude (m)", "east vel (m/s)", "north vel (m/s)"
    );
    let head = format!("{:>7} {:>7} {:>7}", "mean", "std", "max");
    let _ = writeln!(s, "{:<15} {head}   {head}   {head}   {head}", "case");
    for c in &r.cases {
        let _ = writeln!(
            s,
            "{:<15} {}   {}   {}   {}",
            c.label(),
            stats_cells(&c.lat, 2),
            stats_cells(&c.lon, 2),
            stats_cells(&c.ve, 3),
            stats_cells(&c.vn, 3)
        );
    }
    let _ = writeln!(s);
    for &threshold in &r.params.thresholds {
        let (Some(k), Some(c), Some(q)) = (
            r.case(true, threshold),
            r.case(false, threshold),
            r.ratios(threshold),
        ) else {
            continue;
        };
        let _ = writeln!(
            s,
            "counters / classic at T = {threshold:<4}  {:<28} paper (T = 20)",
            "here"
        );
        let rows = [
            (
                "latitude error, mean",
                q.mean,
                format!("{:.2} / {:.2} m", k.lat.mean, c.lat.mean),
                format!("{:.0} %", 100.0 * paper::MEAN_RATIO),
            ),
            (
                "latitude error, std",
                q.std,
                format!("{:.2} / {:.2} m", k.lat.std, c.lat.std),
                format!(
                    "{:.0} %  ({} / {} m)",
                    100.0 * paper::STD_RATIO,
                    paper::COUNTERS_STD_M,
                    paper::CLASSIC_STD_M
                ),
            ),
            (
                "max position error",
                q.max,
                format!("{:.2} / {:.2} m", k.max_position_m(), c.max_position_m()),
                format!(
                    "{:.0} %  (< {} / ≥ {} m)",
                    100.0 * paper::MAX_RATIO,
                    paper::COUNTERS_MAX_BELOW_M,
                    paper::CLASSIC_MAX_AT_LEAST_M
                ),
            ),
        ];
        for (what, ratio, values, theirs) in rows {
            let here = format!("{:>3.0} %  ({values})", 100.0 * ratio);
            let _ = writeln!(s, "  {what:<29} {here:<28} {theirs}");
        }
        let _ = writeln!(
            s,
            "  counters below classic in mean, std and max of latitude and longitude: {}\n",
            if r.counters_beat_classic(threshold) {
                "yes"
            } else {
                "NO"
            }
        );
    }
    let _ = writeln!(
        s,
        "scorecard (GNSS faults {}; TPR/FAR/MDR per epoch, delay from onset to the first non-healthy epoch):",
        r.gnss_faults
            .iter()
            .map(|w| if w.end.is_finite() {
                format!("[{:.0}, {:.0}) s", w.start, w.end)
            } else {
                format!("from {:.0} s", w.start)
            })
            .collect::<Vec<_>>()
            .join(", ")
    );
    let cards: Vec<Scorecard> = r.cases.iter().flat_map(|c| c.scorecards.clone()).collect();
    s.push_str(&scorecard::render(&cards));
    s
}

/// The SVG figures, as `(file name, document)`: the four errors against time
/// for the four cases (seed 004 Figs. 3–6) and the GNSS test's λ with its
/// threshold for each case (Figs. 7–10).
pub fn plots(r: &Seed004Result) -> Vec<(String, String)> {
    type Pick = fn(&super::NavError) -> f64;
    let panels: [(&str, &str, &str, Pick); 4] = [
        ("lat_error.svg", "Latitude error", "error, m", |e| e.north_m),
        ("lon_error.svg", "Longitude error", "error, m", |e| e.east_m),
        ("ve_error.svg", "East velocity error", "error, m/s", |e| {
            e.ve_mps
        }),
        ("vn_error.svg", "North velocity error", "error, m/s", |e| {
            e.vn_mps
        }),
    ];
    let mut out = Vec::new();
    for (file, title, unit, pick) in panels {
        let mut chart = Chart::new(
            format!("{title} (seed 004 ship, seed {})", r.params.seed),
            "t, s",
            unit,
        );
        for c in &r.cases {
            chart = chart.with_series(Series::new(
                c.label(),
                c.run.errors.iter().map(|e| (e.t, pick(e))).collect(),
            ));
        }
        out.push((file.to_owned(), chart.to_svg()));
    }
    for c in &r.cases {
        let points: Vec<(f64, f64)> = c
            .run
            .tests
            .get("gnss")
            .map(|s| s.iter().map(|x| (x.t, x.statistic)).collect())
            .unwrap_or_default();
        let chart = Chart::new(format!("GNSS residual χ² λ, {}", c.label()), "t, s", "λ")
            .with_series(Series::new("λ (gnss)", points))
            .with_threshold(c.threshold, format!("T_D = {}", c.threshold))
            .with_log_y(true);
        let file = format!("lambda_{}.svg", c.label().replace([' ', '='], "_"));
        out.push((file, chart.to_svg()));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::scenario::{ScenarioParams, ship_params};

    /// 1500 s of the ship at a 1 Hz INS rate with seed 004's position jump.
    fn short_ship() -> Scenario {
        let truth = sim::ship_trajectory()
            .and_then(|t| t.sample(1.0, 1500.0))
            .unwrap();
        let faults = sim::ship_faults()
            .into_iter()
            .filter(|f| f.channel == sim::Channel::Position)
            .collect();
        let params = ScenarioParams {
            ins_rate_hz: 1.0,
            ..ship_params(1, faults)
        };
        sim::simulate(params, truth).unwrap()
    }

    #[test]
    fn four_cases_with_scorecards_table_and_figures() {
        let r = run_on(&short_ship(), Seed004Params::default()).unwrap();
        let labels: Vec<String> = r.cases.iter().map(CaseResult::label).collect();
        assert_eq!(
            labels,
            [
                "classic T=13",
                "counters T=13",
                "classic T=20",
                "counters T=20"
            ]
        );
        assert_eq!(
            r.gnss_faults,
            vec![FaultWindow {
                start: 1080.0,
                end: 1200.0
            }]
        );
        for c in &r.cases {
            // One scorecard per test; the jump is detected by every case.
            let tests: Vec<&str> = c.scorecards.iter().map(|s| s.detector.as_str()).collect();
            assert_eq!(tests, ["cns", "dvl", "gnss", "hpl"]);
            let gnss = &c.scorecards[2];
            assert_eq!((gnss.faults, gnss.detected), (1, 1), "{}", c.label());
            assert!(c.lat.max >= c.lat.mean && c.lat.mean > 0.0);
        }
        // The ratios are the counters' figures over the classic ones.
        let q = r.ratios(20.0).unwrap();
        let (k, c) = (r.case(true, 20.0).unwrap(), r.case(false, 20.0).unwrap());
        assert!((q.mean - k.lat.mean / c.lat.mean).abs() < 1e-12);
        let text = render(&r);
        assert!(text.contains("counters / classic at T = 20"), "{text}");
        let figures = plots(&r);
        assert_eq!(figures.len(), 8);
        let names: Vec<&str> = figures.iter().map(|(n, _)| n.as_str()).collect();
        let lambda = figures
            .iter()
            .find(|(name, _)| name == "lambda_counters_T_20.svg")
            .map(|(_, svg)| svg)
            .unwrap_or_else(|| panic!("no λ figure among {names:?}"));
        assert!(lambda.contains("T_D = "), "no threshold label: {lambda}");
    }
}
