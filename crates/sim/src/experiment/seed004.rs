//! Seed 004's experiment (§3, Tables 1–3, Figs. 3–10): the `ship` scenario
//! through the `federated` monitor under the paper's traditional ("no recursion")
//! method — the `traditional` policy: an exceeding sub-filter keeps filtering and is only
//! left out of the master fusion — the classic per-epoch gate, and the paper's improved
//! counter policy (N1 = 10, N2 = 5), each at raw thresholds 13 and 20, with the paper's
//! per-epoch residual χ² tests alone (the drift and stuck tests of docs/methods.md §M23
//! are off: this is the paper's method). The paper gives no end for its velocity fault,
//! so it runs in two variants: to the end of the run and for 120 s (like the position
//! jump). Per variant and case: the latitude, longitude (as metres) and east/north
//! velocity errors of the corrected solution against the truth (mean |e|, std of e, max
//! |e| from the settling time), the ratios counters / traditional beside the paper's,
//! the scorecard of every test, and the figures (errors and the GNSS test's λ against
//! time with the threshold, for the first variant).

use std::fmt::Write as _;

use super::scorecard::{self, FaultWindow, Scorecard};
use super::{ErrorStats, ExperimentError, MonitorRun, fault_windows, run_monitor};
use crate::plot::{Chart, Series};
use crate::{Channel, Fault, Scenario};
use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::epoch::Aid;
use navguard_core::monitor::federated::FederatedConfigWire;
use navguard_core::monitor::guards::{DriftConfigWire, StuckConfigWire};
use navguard_core::monitor::{MonitorKind, MonitorSpec};

/// Seed 004's two thresholds.
pub const THRESHOLDS: [f64; 2] = [13.0, 20.0];

/// The paper's headline figures at threshold 20 (seed 004 abstract and §3), counters against
/// its traditional method.
pub mod paper {
    /// Counters' latitude error as a share of the traditional method's (Table 1).
    pub const MEAN_RATIO: f64 = 0.18;
    /// Latitude error fluctuation, traditional, m (Table 2).
    pub const TRADITIONAL_STD_M: f64 = 4.15;
    /// Latitude error fluctuation, counters, m (Table 2).
    pub const COUNTERS_STD_M: f64 = 0.57;
    /// Fluctuation ratio (Table 2).
    pub const STD_RATIO: f64 = 0.14;
    /// Counters' largest position error stays below this, m (Table 3).
    pub const COUNTERS_MAX_BELOW_M: f64 = 5.0;
    /// The traditional method's smallest maximum position error, m (Table 3).
    pub const TRADITIONAL_MAX_AT_LEAST_M: f64 = 16.36;
    /// Maximum-error ratio (abstract).
    pub const MAX_RATIO: f64 = 0.13;
}

/// The default start of the statistics, s: the filter's convergence from the
/// 10 m / 0.1 m/s / 30″ initial errors takes about 150 s and is the same in
/// every case, so it is left out (as the paper's tables, which compare the
/// policies, evidently do: their counters' maximum is below the initial error).
pub const SETTLE_S: f64 = 300.0;

/// The velocity fault's length in the second variant, s (the position jump's).
pub const VELOCITY_FAULT_S: f64 = 120.0;

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct Seed004Params {
    /// Scenario seed.
    pub seed: u64,
    /// Run length, s (the paper's figures span 3600 s).
    pub duration_s: f64,
    /// Error statistics use epochs from this time on, s.
    pub settle_s: f64,
    /// Raw thresholds, each run under every policy.
    pub thresholds: Vec<f64>,
    /// Counters' N1.
    pub n1: u32,
    /// Counters' N2.
    pub n2: u32,
    /// The variants: how long the velocity fault from 1800 s lasts (`None`: to the end).
    pub velocity_fault_s: Vec<Option<f64>>,
}

impl Default for Seed004Params {
    fn default() -> Self {
        Seed004Params {
            seed: 1,
            duration_s: crate::SHIP_DURATION_S,
            settle_s: SETTLE_S,
            thresholds: THRESHOLDS.to_vec(),
            n1: 10,
            n2: 5,
            velocity_fault_s: vec![None, Some(VELOCITY_FAULT_S)],
        }
    }
}

impl Seed004Params {
    /// The policies compared: traditional, classic, counters.
    pub fn policies(&self) -> [PolicyConfig; 3] {
        [
            PolicyConfig::Traditional,
            PolicyConfig::Classic,
            PolicyConfig::Counters {
                n1: self.n1,
                n2: self.n2,
            },
        ]
    }
}

/// Seed 004's faults with the velocity fault lasting `velocity_s` (`None`: to the end).
pub fn faults(velocity_s: Option<f64>) -> Vec<Fault> {
    crate::ship_faults()
        .into_iter()
        .map(|f| match (f.channel, velocity_s) {
            (Channel::Velocity, Some(d)) => Fault {
                end_s: Some(f.start_s + d),
                ..f
            },
            _ => f,
        })
        .collect()
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
}

/// One variant of the faults: every policy at every threshold.
#[derive(Debug, Clone, PartialEq)]
pub struct Seed004Variant {
    /// How long the velocity fault lasts, s (`None`: to the end).
    pub velocity_fault_s: Option<f64>,
    /// The GNSS fault windows the scorecards use.
    pub gnss_faults: Vec<FaultWindow>,
    /// Traditional, classic and counters at each threshold, in that order.
    pub cases: Vec<CaseResult>,
}

/// Every variant.
#[derive(Debug, Clone, PartialEq)]
pub struct Seed004Result {
    /// The parameters.
    pub params: Seed004Params,
    /// One per entry of [`Seed004Params::velocity_fault_s`].
    pub variants: Vec<Seed004Variant>,
}

impl Seed004Result {
    /// The variant whose velocity fault lasts `velocity_s`.
    pub fn variant(&self, velocity_s: Option<f64>) -> Option<&Seed004Variant> {
        self.variants
            .iter()
            .find(|v| v.velocity_fault_s == velocity_s)
    }
}

/// Counters over a baseline policy at one threshold, latitude (the paper's figures).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ratios {
    /// Mean |latitude error| ratio.
    pub mean: f64,
    /// Latitude error std ratio.
    pub std: f64,
    /// Max position error ratio.
    pub max: f64,
}

impl Seed004Variant {
    /// The case with the given policy kind (`traditional`, `classic`, `counters`) and
    /// threshold.
    pub fn case(&self, kind: &str, threshold: f64) -> Option<&CaseResult> {
        self.cases
            .iter()
            .find(|c| c.policy.kind_name() == kind && c.threshold == threshold)
    }

    /// Counters / `baseline` (a policy kind) at `threshold`.
    pub fn ratios(&self, baseline: &str, threshold: f64) -> Option<Ratios> {
        let (k, c) = (
            self.case("counters", threshold)?,
            self.case(baseline, threshold)?,
        );
        Some(Ratios {
            mean: k.lat.mean / c.lat.mean,
            std: k.lat.std / c.lat.std,
            max: k.max_position_m() / c.max_position_m(),
        })
    }

    /// True when, at `threshold`, the counter policy's latitude and longitude errors are
    /// below the `baseline` policy's in mean, std and max.
    pub fn counters_beat(&self, baseline: &str, threshold: f64) -> bool {
        let (Some(k), Some(c)) = (
            self.case("counters", threshold),
            self.case(baseline, threshold),
        ) else {
            return false;
        };
        let below =
            |a: &ErrorStats, b: &ErrorStats| a.mean < b.mean && a.std < b.std && a.max < b.max;
        below(&k.lat, &c.lat) && below(&k.lon, &c.lon)
    }
}

/// The paper's method on `scenario`: its federated config (sensor noise and IMU) with the
/// per-epoch residual χ² tests alone — every drift and stuck test off.
pub fn paper_config(scenario: &Scenario) -> FederatedConfigWire {
    let mut config = scenario.monitor_config();
    let (drift, stuck) = (
        Some(DriftConfigWire::disabled()),
        Some(StuckConfigWire::disabled()),
    );
    if let Some(g) = &mut config.gnss {
        (g.drift, g.stuck) = (drift.clone(), stuck.clone());
    }
    if let Some(d) = &mut config.dvl {
        (d.drift, d.stuck) = (drift.clone(), stuck.clone());
    }
    if let Some(c) = &mut config.cns {
        (c.drift, c.stuck) = (drift, stuck);
    }
    config
}

/// The monitor spec of one case: [`paper_config`] on the scenario, the policy, a raw
/// threshold.
pub fn spec(
    scenario: &Scenario,
    policy: PolicyConfig,
    threshold: f64,
) -> Result<MonitorSpec, navguard_core::monitor::ConfigError> {
    let value = serde_json::to_value(paper_config(scenario))
        .map_err(|e| navguard_core::monitor::ConfigError::new("", e.to_string()))?;
    Ok(MonitorSpec {
        kind: MonitorKind::Federated,
        config: navguard_core::monitor::MonitorConfig::parse(MonitorKind::Federated, &value)?,
        policy,
        threshold: ThresholdSpec::Threshold(threshold),
    })
}

/// Runs every variant on the `ship` scenario.
pub fn run(params: Seed004Params) -> Result<Seed004Result, ExperimentError> {
    let variants = params
        .velocity_fault_s
        .iter()
        .map(|&v| {
            let scenario = crate::ship_with(params.seed, faults(v), params.duration_s)?;
            let mut variant = run_on(&scenario, &params)?;
            variant.velocity_fault_s = v;
            Ok(variant)
        })
        .collect::<Result<Vec<_>, ExperimentError>>()?;
    Ok(Seed004Result { params, variants })
}

/// Runs every policy at every threshold on a given scenario (tests use shorter ones); the
/// variant's `velocity_fault_s` is read from the scenario's GNSS velocity fault.
pub fn run_on(
    scenario: &Scenario,
    params: &Seed004Params,
) -> Result<Seed004Variant, ExperimentError> {
    let gnss_faults = fault_windows(&scenario.faults, Aid::Gnss);
    let velocity_fault_s = scenario
        .faults
        .iter()
        .find(|f| f.aid == Aid::Gnss && f.channel == Channel::Velocity)
        .and_then(|f| f.end_s.map(|e| e - f.start_s));
    let mut cases = Vec::new();
    for &threshold in &params.thresholds {
        for policy in params.policies() {
            let spec = spec(scenario, policy, threshold)
                .map_err(navguard_core::monitor::BuildError::from)?;
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
                    let per_epoch = Some(case.run.time_per_epoch_s);
                    case.run.scorecard(test, &label, faults, per_epoch)
                })
                .collect();
            cases.push(case);
        }
    }
    Ok(Seed004Variant {
        velocity_fault_s,
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

/// `to the end` or `120 s`.
fn velocity_label(v: Option<f64>) -> String {
    v.map_or_else(|| "to the end".to_owned(), |d| format!("{d:.0} s"))
}

/// The error table of one variant.
fn render_table(s: &mut String, v: &Seed004Variant) {
    let _ = writeln!(
        s,
        "{:<18} {:^23}   {:^23}   {:^23}   {:^23}",
        "", "latitude (m)", "longitude (m)", "east vel (m/s)", "north vel (m/s)"
    );
    let head = format!("{:>7} {:>7} {:>7}", "mean", "std", "max");
    let _ = writeln!(s, "{:<18} {head}   {head}   {head}   {head}", "case");
    for c in &v.cases {
        let _ = writeln!(
            s,
            "{:<18} {}   {}   {}   {}",
            c.label(),
            stats_cells(&c.lat, 2),
            stats_cells(&c.lon, 2),
            stats_cells(&c.ve, 3),
            stats_cells(&c.vn, 3)
        );
    }
    let _ = writeln!(s);
}

/// The ratios of one variant at one threshold: counters over traditional beside the
/// paper's, and over classic.
fn render_ratios(s: &mut String, v: &Seed004Variant, threshold: f64) {
    let (Some(k), Some(q)) = (
        v.case("counters", threshold),
        v.ratios("traditional", threshold),
    ) else {
        return;
    };
    let Some(t) = v.case("traditional", threshold) else {
        return;
    };
    let _ = writeln!(
        s,
        "counters / traditional at T = {threshold:<4}  {:<28} paper (T = 20)",
        "here"
    );
    let rows = [
        (
            "latitude error, mean",
            q.mean,
            format!("{:.2} / {:.2} m", k.lat.mean, t.lat.mean),
            format!("{:.0} %", 100.0 * paper::MEAN_RATIO),
        ),
        (
            "latitude error, std",
            q.std,
            format!("{:.2} / {:.2} m", k.lat.std, t.lat.std),
            format!(
                "{:.0} %  ({} / {} m)",
                100.0 * paper::STD_RATIO,
                paper::COUNTERS_STD_M,
                paper::TRADITIONAL_STD_M
            ),
        ),
        (
            "max position error",
            q.max,
            format!("{:.2} / {:.2} m", k.max_position_m(), t.max_position_m()),
            format!(
                "{:.0} %  (< {} / ≥ {} m)",
                100.0 * paper::MAX_RATIO,
                paper::COUNTERS_MAX_BELOW_M,
                paper::TRADITIONAL_MAX_AT_LEAST_M
            ),
        ),
    ];
    for (what, ratio, values, theirs) in rows {
        let here = format!("{:>3.0} %  ({values})", 100.0 * ratio);
        let _ = writeln!(s, "  {what:<29} {here:<28} {theirs}");
    }
    if let Some(c) = v.ratios("classic", threshold) {
        let _ = writeln!(
            s,
            "  counters / classic (the per-epoch gate): mean {:.0} %, std {:.0} %, max {:.0} %",
            100.0 * c.mean,
            100.0 * c.std,
            100.0 * c.max
        );
    }
    let yes = |b: bool| if b { "yes" } else { "NO" };
    let _ = writeln!(
        s,
        "  counters below traditional / classic in mean, std and max of latitude and longitude: {} / {}\n",
        yes(v.counters_beat("traditional", threshold)),
        yes(v.counters_beat("classic", threshold))
    );
}

/// The text report: per variant the table, the ratios beside the paper's, the scorecards.
pub fn render(r: &Seed004Result) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "seed 004 — ship scenario, seed {}, {:.0} s, federated INS/GNSS/DVL/CNS, per-epoch residual χ² tests only (the paper's method);\n\
         traditional = the paper's \"no recursion\" method (an exceeding sub-filter keeps filtering, left out of the master fusion),\n\
         classic = a per-epoch gate (no update, left out), counters N1 = {}, N2 = {} (the paper's improvement)",
        r.params.seed, r.params.duration_s, r.params.n1, r.params.n2
    );
    let _ = writeln!(
        s,
        "errors of the corrected solution against the truth from {:.0} s (after the initial convergence) to the end:\n\
         mean = mean |e| (Table 1, precision), std = std of the signed e (Table 2, stability), max = max |e| (Table 3)\n",
        r.params.settle_s
    );
    for v in &r.variants {
        let _ = writeln!(
            s,
            "— GNSS velocity fault from 1800 s lasting {} —\n",
            velocity_label(v.velocity_fault_s)
        );
        render_table(&mut s, v);
        for &threshold in &r.params.thresholds {
            render_ratios(&mut s, v, threshold);
        }
        let _ = writeln!(
            s,
            "scorecard (GNSS faults {}; TPR/FAR/MDR per epoch, delay from onset to the first non-healthy epoch):",
            v.gnss_faults
                .iter()
                .map(|w| if w.end.is_finite() {
                    format!("[{:.0}, {:.0}) s", w.start, w.end)
                } else {
                    format!("from {:.0} s", w.start)
                })
                .collect::<Vec<_>>()
                .join(", ")
        );
        let cards: Vec<Scorecard> = v.cases.iter().flat_map(|c| c.scorecards.clone()).collect();
        s.push_str(&scorecard::render(&cards));
        let _ = writeln!(s);
    }
    s
}

/// The SVG figures of the first variant, as `(file name, document)`: the four errors
/// against time for every case (seed 004 Figs. 3–6) and the GNSS test's λ with its
/// threshold for each case (Figs. 7–10).
pub fn plots(r: &Seed004Result) -> Vec<(String, String)> {
    let Some(v) = r.variants.first() else {
        return Vec::new();
    };
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
        for c in &v.cases {
            chart = chart.with_series(Series::new(
                c.label(),
                c.run.errors.iter().map(|e| (e.t, pick(e))).collect(),
            ));
        }
        out.push((file.to_owned(), chart.to_svg()));
    }
    for c in &v.cases {
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
    use crate::scenario::{ScenarioParams, ship_params};

    /// 1500 s of the ship at a 1 Hz INS rate with seed 004's position jump.
    fn short_ship() -> Scenario {
        let truth = crate::ship_trajectory()
            .and_then(|t| t.sample(1.0, 1500.0))
            .unwrap();
        let faults = crate::ship_faults()
            .into_iter()
            .filter(|f| f.channel == crate::Channel::Position)
            .collect();
        let params = ScenarioParams {
            ins_rate_hz: 1.0,
            ..ship_params(1, faults)
        };
        crate::simulate(params, truth).unwrap()
    }

    #[test]
    fn six_cases_per_variant_with_scorecards_table_and_figures() {
        let params = Seed004Params::default();
        let v = run_on(&short_ship(), &params).unwrap();
        let labels: Vec<String> = v.cases.iter().map(CaseResult::label).collect();
        assert_eq!(
            labels,
            [
                "traditional T=13",
                "classic T=13",
                "counters T=13",
                "traditional T=20",
                "classic T=20",
                "counters T=20"
            ]
        );
        assert_eq!(
            v.velocity_fault_s, None,
            "no velocity fault in the short ship"
        );
        assert_eq!(
            v.gnss_faults,
            vec![FaultWindow {
                start: 1080.0,
                end: 1200.0
            }]
        );
        for c in &v.cases {
            // One scorecard per test (the paper's χ² tests only); the jump is detected by
            // every case.
            let tests: Vec<&str> = c.scorecards.iter().map(|s| s.detector.as_str()).collect();
            assert_eq!(tests, ["cns", "dvl", "gnss"]);
            let gnss = &c.scorecards[2];
            assert_eq!((gnss.faults, gnss.detected), (1, 1), "{}", c.label());
            assert!(c.lat.max >= c.lat.mean && c.lat.mean > 0.0);
        }
        // The ratios are the counters' figures over the baseline's.
        let q = v.ratios("traditional", 20.0).unwrap();
        let (k, t) = (
            v.case("counters", 20.0).unwrap(),
            v.case("traditional", 20.0).unwrap(),
        );
        assert!((q.mean - k.lat.mean / t.lat.mean).abs() < 1e-12);
        // The traditional sub-filter keeps filtering the jump, so it is readmitted while the
        // fault lasts; counters keep it out until it ends.
        let excluded = |c: &CaseResult| {
            c.run.tests["gnss"]
                .iter()
                .filter(|s| {
                    (1080.0..1200.0).contains(&s.t)
                        && s.health != navguard_core::detect::Health::Healthy
                })
                .count()
        };
        assert!(
            excluded(t) < excluded(k),
            "{} vs {}",
            excluded(t),
            excluded(k)
        );
        let r = Seed004Result {
            params,
            variants: vec![v],
        };
        let text = render(&r);
        assert!(text.contains("counters / traditional at T = 20"), "{text}");
        assert!(text.contains("lasting to the end"), "{text}");
        let figures = plots(&r);
        assert_eq!(figures.len(), 10);
        let names: Vec<&str> = figures.iter().map(|(n, _)| n.as_str()).collect();
        let lambda = figures
            .iter()
            .find(|(name, _)| name == "lambda_traditional_T_20.svg")
            .map(|(_, svg)| svg)
            .unwrap_or_else(|| panic!("no λ figure among {names:?}"));
        assert!(lambda.contains("T_D = "), "no threshold label: {lambda}");
    }

    #[test]
    fn the_velocity_fault_lasts_to_the_end_or_120_s() {
        let f = faults(Some(VELOCITY_FAULT_S));
        let velocity: Vec<_> = f
            .iter()
            .filter(|f| f.channel == Channel::Velocity)
            .collect();
        assert_eq!(velocity.len(), 2);
        assert!(
            velocity
                .iter()
                .all(|f| f.start_s == 1800.0 && f.end_s == Some(1920.0))
        );
        assert_eq!(faults(None), crate::ship_faults());
    }
}
