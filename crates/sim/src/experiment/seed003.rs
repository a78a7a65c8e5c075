//! Seed 003's experiment (§4, Figs. 3–6): one-class SVM detection of TACAN range
//! jumps. Per noise variance (5, 10, 20 m²): simulate training flights (no jumps),
//! compute the window features ([`navguard_core::features::tacan`]), subsample them, train an
//! `ocsvm` model, then run every test flight (with jumps) through the `tacan` monitor
//! in-process and score each window.
//!
//! # Figures
//! A window is *anomalous* when it holds a jumped sample. Per test flight `i`:
//! - detection probability `p_i` = anomalous windows the `range` test flags /
//!   anomalous windows (seed 003's `p_i = n_i/N_i`; its wording is garbled, so we
//!   take the usual meaning P(detect | anomaly));
//! - false-alarm rate = clean windows flagged / clean windows;
//! - accuracy = correctly classified windows / windows;
//! - jumps detected = jumps with at least one flagged window that holds them.
//!
//! `P = mean(p_i)` is set beside the paper's (100 %, 99.99 %, lowest flight
//! 97.97 % and mean > 99 % at 20 m²). The scorecard (docs/methods.md §M19) scores the
//! `range` test's health trace under the classic and the counters policy, with
//! each jump's fault window running from its first sample to the last window that
//! holds it, flights laid end to end; its recovery column shows the longest
//! recovery over all jumps ("never": some window stayed flagged until the next jump).
//!
//! # Training size
//! Ten 20-minute flights at 25 Hz give 299,910 windows; training is on every
//! `stride`-th window (`stride = ⌈total / train_samples⌉`, default 30,000 samples,
//! docs/performance.md's 30,000 × 3 benchmark size): consecutive windows share 9 of 10
//! samples, so the subsample loses little.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::sync::Arc;
use std::time::Instant;

use serde_json::json;

use super::ExperimentError;
use super::scorecard::{self, FaultWindow, Scorecard};
use crate::plot::{Chart, Series};

/// The one-class model's ν (the paper's choice): the share of training windows left
/// outside the boundary, so the nominal rate of flagged clean windows.
const NU: f64 = 0.002;
use crate::tacan::{TacanFlight, TacanFlightParams, default_station, simulate_flight};
use navguard_core::detect::{Health, PolicyConfig, ThresholdSpec};
use navguard_core::features::tacan::{TacanFeatureParams, series_features};
use navguard_core::geo::Lla;
use navguard_core::learn::{self, AnyModel, Dataset, ModelKind, ModelParams, NoProgress};
use navguard_core::monitor::{self, MonitorKind, MonitorSpec};

/// The paper's figures (seed 003 §4, Fig. 6).
pub mod paper {
    /// Detection probability at noise variance 5 m².
    pub const P_VAR5: f64 = 1.0;
    /// Detection probability at 10 m².
    pub const P_VAR10: f64 = 0.9999;
    /// Lowest flight at 20 m² (flight 10).
    pub const P_VAR20_MIN: f64 = 0.9797;
    /// Mean at 20 m² is above this.
    pub const P_VAR20_MEAN_ABOVE: f64 = 0.99;
}

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct Seed003Params {
    /// Base seed; flight `i` of the training set uses `seed·1000 + i`, of the test set
    /// `seed·1000 + 500 + i`.
    pub seed: u64,
    /// Range noise variances, m².
    pub noise_vars_m2: Vec<f64>,
    /// Training flights.
    pub train_flights: usize,
    /// Length of a training flight, s.
    pub train_duration_s: f64,
    /// Test flights.
    pub test_flights: usize,
    /// Length of a test flight, s.
    pub test_duration_s: f64,
    /// Jumps per test flight.
    pub jumps: usize,
    /// Training windows kept after subsampling (at most).
    pub train_samples: usize,
    /// Window length and feature selection.
    pub features: TacanFeatureParams,
    /// The `ocsvm` params (JSON as `POST /api/v1/models` takes them).
    pub model_params: serde_json::Value,
    /// INS position error, 1σ per axis, m (the scenario's default 5 m).
    pub ins_sigma_m: f64,
    /// INS error correlation time, s (default 300 s). The mean feature follows the
    /// INS radial error, so the training flights must see as much of its variety as
    /// the test flights: runs with much shorter flights scale this down with them.
    pub ins_tau_s: f64,
    /// The station.
    pub station: Lla,
}

impl Default for Seed003Params {
    fn default() -> Self {
        Seed003Params {
            seed: 3,
            noise_vars_m2: vec![5.0, 10.0, 20.0],
            train_flights: 10,
            train_duration_s: 1200.0,
            test_flights: 10,
            test_duration_s: 600.0,
            jumps: 200,
            train_samples: 30_000,
            features: TacanFeatureParams::default(),
            model_params: default_model_params(),
            ins_sigma_m: TacanFlightParams::default().ins_sigma_m,
            ins_tau_s: TacanFlightParams::default().ins_tau_s,
            station: default_station(),
        }
    }
}

/// The default one-class model: ν = 0.002 (at most 0.2 % of the clean training
/// windows outside), σ² = 10 on standardised features. A kernel wider than
/// scikit-learn's `gamma="scale"` (σ² = 3 for 3 unit-variance features) draws a
/// smoother boundary that carries over to flight geometries the training flights
/// did not see (on the default run: false alarms 0.18 % against 0.27 % with σ² = 3,
/// detection unchanged).
pub fn default_model_params() -> serde_json::Value {
    json!({"nu": NU, "sigma2": 10.0})
}

/// One test flight's figures.
#[derive(Debug, Clone, PartialEq)]
pub struct FlightResult {
    /// Anomalous windows.
    pub anomalous: usize,
    /// Of those, flagged.
    pub detected: usize,
    /// Clean windows.
    pub clean: usize,
    /// Of those, flagged.
    pub false_alarms: usize,
    /// Jumps.
    pub jumps: usize,
    /// Jumps with a flagged window.
    pub jumps_detected: usize,
}

impl FlightResult {
    /// Detection probability `p_i`.
    pub fn detection_probability(&self) -> f64 {
        ratio(self.detected, self.anomalous)
    }

    /// False-alarm rate.
    pub fn false_alarm_rate(&self) -> f64 {
        ratio(self.false_alarms, self.clean)
    }

    /// Accuracy over all windows.
    pub fn accuracy(&self) -> f64 {
        ratio(
            self.detected + self.clean - self.false_alarms,
            self.anomalous + self.clean,
        )
    }
}

fn ratio(a: usize, n: usize) -> f64 {
    if n == 0 { 1.0 } else { a as f64 / n as f64 }
}

/// The first 30 s of a test flight: `(t, d_tacan − d_ins)` and `(t, decision)`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trace {
    /// Range difference, m.
    pub range_diff: Vec<(f64, f64)>,
    /// One-class decision.
    pub decision: Vec<(f64, f64)>,
}

/// One noise level's results.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseResult {
    /// Noise variance, m².
    pub noise_var_m2: f64,
    /// Windows trained on.
    pub train_n: usize,
    /// Windows available before subsampling.
    pub train_total: usize,
    /// Training wall time, s.
    pub train_seconds: f64,
    /// Support vectors of the model.
    pub support_vectors: Option<usize>,
    /// Per test flight.
    pub flights: Vec<FlightResult>,
    /// Scorecards of the `range` test (classic, counters).
    pub scorecards: Vec<Scorecard>,
    /// First 30 s of test flight 1, for the figures.
    pub trace: Trace,
}

impl NoiseResult {
    /// Mean detection probability `P`.
    pub fn mean_detection(&self) -> f64 {
        let n = self.flights.len().max(1) as f64;
        self.flights
            .iter()
            .map(FlightResult::detection_probability)
            .sum::<f64>()
            / n
    }

    /// Lowest per-flight detection probability.
    pub fn min_detection(&self) -> f64 {
        self.flights
            .iter()
            .map(FlightResult::detection_probability)
            .fold(1.0, f64::min)
    }

    /// Pooled figures over every flight.
    pub fn pooled(&self) -> FlightResult {
        let mut p = FlightResult {
            anomalous: 0,
            detected: 0,
            clean: 0,
            false_alarms: 0,
            jumps: 0,
            jumps_detected: 0,
        };
        for f in &self.flights {
            p.anomalous += f.anomalous;
            p.detected += f.detected;
            p.clean += f.clean;
            p.false_alarms += f.false_alarms;
            p.jumps += f.jumps;
            p.jumps_detected += f.jumps_detected;
        }
        p
    }
}

/// The experiment's result.
#[derive(Debug, Clone, PartialEq)]
pub struct Seed003Result {
    /// What ran.
    pub params: Seed003Params,
    /// One entry per noise variance.
    pub levels: Vec<NoiseResult>,
}

/// A model trained for one noise level, with what training took.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainedLevel {
    /// The one-class model.
    pub model: AnyModel,
    /// Windows trained on.
    pub train_n: usize,
    /// Windows available before subsampling.
    pub train_total: usize,
    /// Training wall time, s.
    pub seconds: f64,
    /// Support vectors.
    pub support_vectors: Option<usize>,
}

/// Trains the one-class model on the training flights' windows at one noise level.
pub fn train_model(p: &Seed003Params, noise_var_m2: f64) -> Result<TrainedLevel, ExperimentError> {
    let mut all = Vec::new();
    for i in 0..p.train_flights {
        let f = simulate_flight(&TacanFlightParams {
            seed: p.seed * 1000 + i as u64,
            duration_s: p.train_duration_s,
            noise_var_m2,
            jumps: 0,
            window: p.features.window,
            ins_sigma_m: p.ins_sigma_m,
            ins_tau_s: p.ins_tau_s,
            station: p.station,
            ..TacanFlightParams::default()
        })?;
        all.extend(series_features(
            &f.ins_range_m,
            &f.tacan_range_m,
            &p.features,
        )?);
    }
    let total = all.len();
    let stride = total.div_ceil(p.train_samples.max(1)).max(1);
    let rows: Vec<Vec<f64>> = all.into_iter().step_by(stride).collect();
    let data = Dataset::new(&rows, None)?;
    let params = ModelParams::from_json(ModelKind::OcSvm, &p.model_params)?;
    let started = Instant::now();
    let trained = learn::train(&params, None, &data, &NoProgress)?;
    let seconds = started.elapsed().as_secs_f64();
    Ok(TrainedLevel {
        model: trained.model,
        train_n: rows.len(),
        train_total: total,
        seconds,
        support_vectors: trained.metrics.support_vectors,
    })
}

/// Per-window flags, `(t, decision)` and the total monitor step time (s) of one test flight.
type FlightRun = (Vec<Health>, Vec<(f64, f64)>, f64);

/// Runs one test flight through the `tacan` monitor under `policy`; returns the
/// per-window health (window `i` ends at sample `i + K − 1`) and the decisions.
fn run_flight(
    flight: &TacanFlight,
    spec: &MonitorSpec,
    models: &HashMap<String, Arc<AnyModel>>,
) -> Result<FlightRun, ExperimentError> {
    let mut monitor = monitor::build(spec, models)?;
    let mut healths = Vec::with_capacity(flight.epochs.len());
    let mut decisions = Vec::with_capacity(flight.epochs.len());
    let mut busy = 0.0;
    for e in &flight.epochs {
        let started = Instant::now();
        let report = monitor
            .step(e)
            .map_err(|source| ExperimentError::Step { t: e.t, source })?;
        busy += started.elapsed().as_secs_f64();
        if let Some(o) = report.tests.first() {
            healths.push(o.decision.health);
        }
        if let monitor::Outputs::Tacan {
            decision: Some(g), ..
        } = report.outputs
        {
            decisions.push((e.t, g));
        }
    }
    Ok((healths, decisions, busy))
}

fn spec(p: &Seed003Params, policy: PolicyConfig) -> MonitorSpec {
    MonitorSpec {
        kind: MonitorKind::Tacan,
        config: navguard_core::monitor::MonitorConfig::Tacan(
            navguard_core::monitor::tacan::TacanConfigWire {
                station: Some(navguard_core::monitor::tacan::StationWire {
                    lat: p.station.lat.to_degrees(),
                    lon: p.station.lon.to_degrees(),
                    h: p.station.h,
                }),
                window: p.features.window,
                crest: p.features.crest,
                model: Some("seed003".to_owned()),
                ..Default::default()
            },
        ),
        policy,
        threshold: ThresholdSpec::default(),
    }
}

/// Runs the experiment.
pub fn run(p: Seed003Params) -> Result<Seed003Result, ExperimentError> {
    let levels = p
        .noise_vars_m2
        .iter()
        .map(|&var| run_level(&p, var))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Seed003Result { params: p, levels })
}

/// Test flight `i` at noise variance `var`.
fn test_flight(p: &Seed003Params, var: f64, i: usize) -> Result<TacanFlight, ExperimentError> {
    Ok(simulate_flight(&TacanFlightParams {
        seed: p.seed * 1000 + 500 + i as u64,
        duration_s: p.test_duration_s,
        noise_var_m2: var,
        jumps: p.jumps,
        window: p.features.window,
        ins_sigma_m: p.ins_sigma_m,
        ins_tau_s: p.ins_tau_s,
        station: p.station,
        ..TacanFlightParams::default()
    })?)
}

/// Trains at one noise level and runs every test flight under both policies.
fn run_level(p: &Seed003Params, var: f64) -> Result<NoiseResult, ExperimentError> {
    let k = p.features.window;
    let trained = train_model(p, var)?;
    let models: HashMap<String, Arc<AnyModel>> =
        HashMap::from([("seed003".to_owned(), Arc::new(trained.model))]);
    let mut flights = Vec::new();
    let mut traces: Vec<Vec<(f64, Health)>> = vec![Vec::new(), Vec::new()];
    let mut faults = Vec::new();
    let mut trace = Trace::default();
    let policies = [PolicyConfig::Classic, PolicyConfig::counters_default()];
    let (mut busy_s, mut epochs) = ([0.0; 2], [0usize; 2]);
    let dt = 1.0 / TacanFlightParams::default().rate_hz;
    for i in 0..p.test_flights {
        let flight = test_flight(p, var, i)?;
        let truth = flight.window_truth(k);
        let offset = i as f64 * (p.test_duration_s + 60.0);
        for (pi, &policy) in policies.iter().enumerate() {
            let (healths, decisions, busy) = run_flight(&flight, &spec(p, policy), &models)?;
            let flags: Vec<bool> = healths.iter().map(|&h| h != Health::Healthy).collect();
            busy_s[pi] += busy;
            epochs[pi] += flight.epochs.len();
            for (w, &h) in healths.iter().enumerate() {
                traces[pi].push((offset + (w + k - 1) as f64 * dt, h));
            }
            if pi != 0 {
                continue;
            }
            let at = FlightOffset { k, offset, dt };
            flights.push(score_flight(&flight, &truth, &flags, at, &mut faults));
            if i == 0 {
                trace = first_seconds(&flight, decisions, dt);
            }
        }
    }
    Ok(NoiseResult {
        noise_var_m2: var,
        train_n: trained.train_n,
        train_total: trained.train_total,
        train_seconds: trained.seconds,
        support_vectors: trained.support_vectors,
        flights,
        scorecards: level_scorecards(&traces, &faults, busy_s, epochs),
        trace,
    })
}

/// Where a test flight's windows sit on the laid-out time axis.
#[derive(Clone, Copy)]
struct FlightOffset {
    /// Window length, samples.
    k: usize,
    /// Start of this flight on the axis, s.
    offset: f64,
    /// Sample period, s.
    dt: f64,
}

/// Counts one flight's detections and false alarms (classic policy) and pushes
/// its jumps' fault windows.
fn score_flight(
    flight: &TacanFlight,
    truth: &[bool],
    flags: &[bool],
    at: FlightOffset,
    faults: &mut Vec<FaultWindow>,
) -> FlightResult {
    let FlightOffset { k, offset, dt } = at;
    let mut r = FlightResult {
        anomalous: 0,
        detected: 0,
        clean: 0,
        false_alarms: 0,
        jumps: flight.jumps.len(),
        jumps_detected: 0,
    };
    for (&bad, &flag) in truth.iter().zip(flags) {
        match (bad, flag) {
            (true, f) => {
                r.anomalous += 1;
                r.detected += usize::from(f);
            }
            (false, f) => {
                r.clean += 1;
                r.false_alarms += usize::from(f);
            }
        }
    }
    // Windows holding jump j: those ending at samples start ..= start + len + K − 2.
    for j in &flight.jumps {
        let first = j.start.saturating_sub(k - 1);
        let last = (j.start + j.len - 1).min(flags.len().saturating_sub(1));
        if flags
            .get(first..=last)
            .is_some_and(|w| w.iter().any(|&f| f))
        {
            r.jumps_detected += 1;
        }
        faults.push(FaultWindow {
            start: offset + j.start as f64 * dt,
            end: offset + (j.start + j.len + k - 1) as f64 * dt,
        });
    }
    r
}

/// The first 30 s of a flight for the figure: range difference and decisions.
fn first_seconds(flight: &TacanFlight, decisions: Vec<(f64, f64)>, dt: f64) -> Trace {
    let mut trace = Trace::default();
    let n = flight.epochs.len().min((30.0 / dt) as usize);
    trace.range_diff = (0..n)
        .map(|s| {
            (
                s as f64 * dt,
                flight.tacan_range_m[s] - flight.ins_range_m[s],
            )
        })
        .collect();
    trace.decision = decisions.into_iter().filter(|(t, _)| *t < 30.0).collect();
    trace
}

/// One scorecard per policy over every test flight of a level. Fault windows
/// are pushed once per flight (classic pass); dedupe is not needed.
fn level_scorecards(
    traces: &[Vec<(f64, Health)>],
    faults: &[FaultWindow],
    busy_s: [f64; 2],
    epochs: [usize; 2],
) -> Vec<Scorecard> {
    let labels = ["classic", "counters N1=10 N2=5"];
    traces
        .iter()
        .zip(labels)
        .enumerate()
        .map(|(pi, (t, label))| {
            let per_epoch = busy_s[pi] / epochs[pi].max(1) as f64;
            // Flights are laid end to end, 60 s apart: a recovery is looked for in its
            // own flight (the monitor starts afresh with the next).
            let starts: Vec<f64> = flight_starts(t);
            let card = scorecard::score_runs("range", label, t, faults, Some(per_epoch), &starts);
            // One figure instead of 2,000: the longest recovery (recoveries the next
            // jump cut short are counted apart). The one-class boundary's nominal rate
            // of flagged clean windows is ν.
            let longest = card.max_recovery_s();
            Scorecard {
                recovery_s: vec![longest],
                ..card
            }
            .with_p_fa(NU)
        })
        .collect()
}

/// The start times of the flights of a trace laid end to end: every epoch after a
/// gap longer than a second.
fn flight_starts(trace: &[(f64, Health)]) -> Vec<f64> {
    trace
        .windows(2)
        .filter(|w| w[1].0 - w[0].0 > 1.0)
        .map(|w| w[1].0)
        .chain(trace.first().map(|&(t, _)| t))
        .collect()
}

fn pct(v: f64) -> String {
    format!("{:.2} %", 100.0 * v)
}

/// Renders the tables: per-flight detection probabilities, the summary beside the
/// paper's figures, and the scorecards.
pub fn render(r: &Seed003Result) -> String {
    let mut s = String::new();
    render_flights(&mut s, r);
    render_summary(&mut s, r);
    for l in &r.levels {
        let _ = writeln!(
            s,
            "\nscorecard, σ² = {} m² (range test, flights end to end; delay/recovery in s)",
            l.noise_var_m2
        );
        s.push_str(&scorecard::render(&l.scorecards));
    }
    s
}

/// The setup, then each noise level's detection probability per test flight.
fn render_flights(s: &mut String, r: &Seed003Result) {
    let p = &r.params;
    let _ = writeln!(
        s,
        "seed 003 — TACAN range jumps, one-class SVM {}; window {}, features {}",
        p.model_params,
        p.features.window,
        if p.features.crest {
            "mean, variance, shape, crest"
        } else {
            "mean, variance, shape"
        }
    );
    let _ = writeln!(
        s,
        "training: {} flights × {:.0} s at 25 Hz (no jumps); test: {} flights × {:.0} s with {} jumps (150–300 m, 1–5 samples) each\n",
        p.train_flights, p.train_duration_s, p.test_flights, p.test_duration_s, p.jumps
    );
    let _ = write!(s, "{:<12}", "σ² (m²)");
    for i in 0..p.test_flights {
        let _ = write!(s, " {:>7}", format!("p_{}", i + 1));
    }
    let _ = writeln!(s);
    for l in &r.levels {
        let _ = write!(s, "{:<12}", l.noise_var_m2);
        for f in &l.flights {
            let _ = write!(s, " {:>7.2}", 100.0 * f.detection_probability());
        }
        let _ = writeln!(s);
    }
    let _ = writeln!(s, "(per-flight detection probability p_i, %)\n");
}

/// One row per noise level: detection, accuracy and false alarms pooled over the
/// flights, the training set and the support vectors, beside the paper's figure.
fn render_summary(s: &mut String, r: &Seed003Result) {
    let _ = writeln!(
        s,
        "{:<8} {:>9} {:>9} {:>9} {:>9} {:>9} {:>11} {:>15} {:>8} {:>5}  paper",
        "σ² (m²)",
        "mean P",
        "min p_i",
        "accuracy",
        "TPR",
        "FAR",
        "jumps det.",
        "train n/total",
        "train s",
        "SVs",
    );
    for l in &r.levels {
        let pooled = l.pooled();
        let paper = if l.noise_var_m2 == 5.0 {
            "P = 100 %"
        } else if l.noise_var_m2 == 10.0 {
            "P = 99.99 %"
        } else if l.noise_var_m2 == 20.0 {
            "P > 99 %, lowest flight 97.97 %"
        } else {
            "—"
        };
        let _ = writeln!(
            s,
            "{:<8} {:>9} {:>9} {:>9} {:>9} {:>9} {:>11} {:>15} {:>8.2} {:>5}  {}",
            l.noise_var_m2,
            pct(l.mean_detection()),
            pct(l.min_detection()),
            pct(pooled.accuracy()),
            pct(pooled.detection_probability()),
            pct(pooled.false_alarm_rate()),
            format!("{}/{}", pooled.jumps_detected, pooled.jumps),
            format!("{}/{}", l.train_n, l.train_total),
            l.train_seconds,
            l.support_vectors.map_or("—".to_owned(), |n| n.to_string()),
            paper
        );
    }
    let _ = writeln!(
        s,
        "\nP = mean of p_i = flagged / anomalous windows per flight; accuracy, TPR, FAR pooled over windows;\n\
         a window is anomalous when it holds a jumped sample. Training on every ⌈total/n⌉-th window."
    );
}

/// The figures: per-flight detection probability per noise level (the paper's
/// Fig. 6), and for each level the first 30 s of test flight 1: range difference
/// (Figs. 3–5) and the one-class decision.
pub fn plots(r: &Seed003Result) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut chart = Chart::new(
        "Detection probability per test flight (seed 003 Fig. 6)",
        "flight",
        "p_i, %",
    );
    for l in &r.levels {
        chart = chart.with_series(Series::new(
            format!("N(0, {})", l.noise_var_m2),
            l.flights
                .iter()
                .enumerate()
                .map(|(i, f)| ((i + 1) as f64, 100.0 * f.detection_probability()))
                .collect(),
        ));
    }
    out.push(("detection_probability.svg".to_owned(), chart.to_svg()));
    for l in &r.levels {
        let v = l.noise_var_m2;
        let c = Chart::new(
            format!("TACAN − INS range, test flight 1, noise N(0, {v})"),
            "t, s",
            "d_tacan − d_ins, m",
        )
        .with_series(Series::new("range difference", l.trace.range_diff.clone()));
        out.push((format!("range_diff_var{v}.svg"), c.to_svg()));
        let c = Chart::new(
            format!("One-class decision, test flight 1, noise N(0, {v})"),
            "t, s",
            "decision (≥ 0 normal)",
        )
        .with_series(Series::new("decision", l.trace.decision.clone()))
        .with_threshold(0.0, "boundary");
        out.push((format!("decision_var{v}.svg"), c.to_svg()));
    }
    out
}
