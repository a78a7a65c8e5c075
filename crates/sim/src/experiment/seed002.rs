//! Seed 002's experiment (§3, Table 1, Fig. 4): a C-SVC isolation classifier trained on
//! 400 normal and 288 fault windows of one gyro's steady output (wavelet-packet
//! energies), then the `rimu` monitor on the paper's two scenarios — steady 22–28 s with
//! faults from 25 s, manoeuvring 28–34 s with a climb from 30 s and faults from 31 s —
//! for every gyro × fault (5σ, 6σ bias; 3σ/s, 4σ/s drift), with and without the
//! classifier: detected?, isolated correctly?, detection and isolation delays, error of
//! the reconstructed ω; the docs/methods.md §M19 scorecards; the parity λ against T_D as SVG.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::sync::Arc;
use std::time::Instant;

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use serde_json::{Value, json};

use super::ExperimentError;
use super::scorecard::{self, FaultWindow, Scorecard};
use crate::plot::{Chart, Series};
use crate::rimu::{self as rsim, GyroFaultKind, RimuSimParams};
use navguard_core::detect::{Health, PolicyConfig, ThresholdSpec};
use navguard_core::epoch::Epoch;
use navguard_core::features::wavelet::{self, WaveletPacketParams};
use navguard_core::learn::{
    self, AnyModel, Dataset, LearnError, ModelKind, ModelParams, NoProgress,
};
use navguard_core::monitor::{self, MonitorKind, MonitorSpec, Outputs};

/// Seed 002's detection threshold T_D for the FSS test (l' = 6).
pub const T_D: f64 = 39.81;

/// The id the experiment stores its classifier under for `monitor::build`.
const MODEL_ID: &str = "seed002-svc";

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct Seed002Params {
    /// Seed of the training windows and of the first run.
    pub seed: u64,
    /// Normal training windows (paper: 400).
    pub n_normal: usize,
    /// Fault training windows (paper: 288).
    pub n_fault: usize,
    /// Runs per scenario × gyro × fault (different noise seeds).
    pub runs: usize,
    /// Feature window l (paper: 100; 96 here, a multiple of 2^level).
    pub feature_window: usize,
    /// Wavelet-packet parameters.
    pub wavelet: WaveletPacketParams,
    /// `params` of the `svm` model (paper: a linear SVM).
    pub svm: Value,
    /// T_I (paper: 0.1).
    pub t_i: f64,
    /// Pitch reached by the manoeuvring scenario's 4 s climb, degrees.
    pub climb_deg: f64,
}

impl Default for Seed002Params {
    fn default() -> Self {
        Seed002Params {
            seed: 1,
            n_normal: 400,
            n_fault: 288,
            runs: 20,
            feature_window: 96,
            wavelet: WaveletPacketParams::default(),
            svm: json!({"kernel": "linear", "C": 1.0}),
            t_i: 0.1,
            climb_deg: 5.0,
        }
    }
}

/// How the classifier was trained (seed 002: random 80/20 splits until the test part
/// has no error).
#[derive(Debug, Clone, PartialEq)]
pub struct TrainingSummary {
    /// Training windows used (80 %).
    pub n_train: usize,
    /// Held-out windows (20 %).
    pub n_test: usize,
    /// Splits tried.
    pub attempts: usize,
    /// Held-out accuracy of the split kept.
    pub test_accuracy: f64,
    /// Training accuracy.
    pub train_accuracy: Option<f64>,
    /// Support vectors.
    pub support_vectors: Option<usize>,
    /// Training time, s.
    pub seconds: f64,
}

/// Trains the isolation classifier on simulated windows (features by `wavelet`).
pub fn train_classifier(
    p: &Seed002Params,
) -> Result<(Arc<AnyModel>, TrainingSummary), ExperimentError> {
    let (windows, labels) = rsim::training_windows(
        p.seed,
        navguard_core::monitor::rimu::default_sigma(),
        p.feature_window,
        p.n_normal,
        p.n_fault,
    );
    let features = windows
        .iter()
        .map(|w| wavelet::packet_energies(w, &p.wavelet))
        .collect::<Result<Vec<_>, _>>()?;
    let params = ModelParams::from_json(ModelKind::Svm, &p.svm)?;
    let mut order: Vec<usize> = (0..features.len()).collect();
    let mut rng = StdRng::seed_from_u64(p.seed);
    let n_train = features.len() * 4 / 5;
    let mut best: Option<(Arc<AnyModel>, TrainingSummary)> = None;
    for attempt in 1..=20 {
        order.shuffle(&mut rng);
        let (tr, te) = order.split_at(n_train);
        let pick = |idx: &[usize]| -> (Vec<Vec<f64>>, Vec<f64>) {
            (
                idx.iter().map(|&i| features[i].clone()).collect(),
                idx.iter().map(|&i| labels[i]).collect(),
            )
        };
        let (xtr, ytr) = pick(tr);
        let (xte, yte) = pick(te);
        let started = Instant::now();
        let trained = learn::train(&params, None, &Dataset::new(&xtr, Some(&ytr))?, &NoProgress)?;
        let seconds = started.elapsed().as_secs_f64();
        let model = trained.model;
        let right = xte
            .iter()
            .zip(&yte)
            .filter(|(x, y)| (model.predict_one(x) >= 0.0) == (**y > 0.0))
            .count();
        let acc = if xte.is_empty() {
            1.0
        } else {
            right as f64 / xte.len() as f64
        };
        let summary = TrainingSummary {
            n_train: xtr.len(),
            n_test: xte.len(),
            attempts: attempt,
            test_accuracy: acc,
            train_accuracy: trained.metrics.train_accuracy,
            support_vectors: trained.metrics.support_vectors,
            seconds,
        };
        let better = best.as_ref().is_none_or(|(_, b)| acc > b.test_accuracy);
        if better {
            best = Some((Arc::new(model), summary));
        }
        if acc >= 1.0 {
            break;
        }
    }
    best.ok_or_else(|| LearnError::Numerical("no split trained".into()).into())
}

/// One scenario × gyro × fault, over `runs` noise seeds.
#[derive(Debug, Clone, PartialEq)]
pub struct CaseRow {
    /// `steady` or `manoeuvring`.
    pub scenario: &'static str,
    /// Faulty gyro (0-based).
    pub gyro: usize,
    /// The fault.
    pub fault: GyroFaultKind,
    /// Runs.
    pub runs: usize,
    /// Runs where the parity test fired after the onset.
    pub detected: usize,
    /// Runs where the faulty gyro, and only it, was isolated.
    pub isolated_correctly: usize,
    /// Runs where another gyro was isolated.
    pub isolated_wrong: usize,
    /// Mean detection delay over detected runs, s.
    pub detection_delay_s: Option<f64>,
    /// Mean isolation delay over correctly isolated runs, s.
    pub isolation_delay_s: Option<f64>,
    /// RMS of ‖ω̂ − ω‖ from the onset to the end of the run, in units of σ.
    pub omega_rms_sigma: f64,
}

/// The whole experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct Seed002Result {
    /// What ran.
    pub params: Seed002Params,
    /// The classifier's training.
    pub training: TrainingSummary,
    /// With the classifier.
    pub rows: Vec<CaseRow>,
    /// Parity test alone (no model in the config).
    pub rows_parity_only: Vec<CaseRow>,
    /// Scorecards: parity and isolation per scenario, with the classifier.
    pub scorecards: Vec<Scorecard>,
    /// λ against time for steady, gyro 1, bias 5σ, first run.
    pub lambda_trace: Vec<(f64, f64)>,
}

fn spec(p: &Seed002Params, with_model: bool) -> MonitorSpec {
    let config = navguard_core::monitor::rimu::RimuConfigWire {
        feature_window: p.feature_window,
        wavelet: p.wavelet.clone(),
        t_i: p.t_i,
        model: with_model.then(|| MODEL_ID.to_owned()),
        ..Default::default()
    };
    MonitorSpec {
        kind: MonitorKind::Rimu,
        config: navguard_core::monitor::MonitorConfig::Rimu(config),
        policy: PolicyConfig::Classic,
        threshold: ThresholdSpec::Threshold(T_D),
    }
}

/// What one run of one case gave.
#[derive(Debug, Clone, PartialEq)]
pub struct RunOutcome {
    /// First alarm at or after the onset, s.
    pub detected_at: Option<f64>,
    /// First epoch with a gyro isolated, and which.
    pub isolated: Option<(f64, Vec<usize>)>,
    /// Squared ω errors after the onset, rad²/s².
    pub omega_sq: Vec<f64>,
    /// `(t, health, λ)` of the parity test.
    pub trace: Vec<(f64, Health, f64)>,
    /// Mean wall-clock time per step, s.
    pub time_per_epoch_s: f64,
}

/// Runs one scenario through a monitor built from `spec` with `models`.
pub fn run_case(
    sim: &RimuSimParams,
    spec: &MonitorSpec,
    models: &dyn monitor::ModelSource,
) -> Result<RunOutcome, ExperimentError> {
    let run = rsim::simulate(sim)?;
    let mut m = monitor::build(spec, models)?;
    let onset = sim.fault.map_or(f64::INFINITY, |f| f.onset_s);
    let mut out = RunOutcome {
        detected_at: None,
        isolated: None,
        omega_sq: Vec::new(),
        trace: Vec::new(),
        time_per_epoch_s: 0.0,
    };
    let started = Instant::now();
    for s in &run.samples {
        let epoch = Epoch {
            t: s.t,
            gyros: Some(s.gyros.clone()),
            ..Default::default()
        };
        // Simulated gyros are finite and of the right length: a step cannot fail.
        let Ok(report) = m.step(&epoch) else { continue };
        for o in &report.tests {
            out.trace.push((s.t, o.decision.health, o.statistic.value));
            if s.t >= onset && out.detected_at.is_none() && o.decision.health != Health::Healthy {
                out.detected_at = Some(s.t);
            }
        }
        if let Outputs::Rimu {
            isolated, omega, ..
        } = &report.outputs
        {
            if out.isolated.is_none() && !isolated.is_empty() {
                out.isolated = Some((s.t, isolated.clone()));
            }
            if s.t >= onset
                && let Some(w) = omega
            {
                out.omega_sq
                    .push((0..3).map(|k| (w[k] - s.omega[k]).powi(2)).sum());
            }
        }
    }
    out.time_per_epoch_s = started.elapsed().as_secs_f64() / run.samples.len().max(1) as f64;
    Ok(out)
}

fn mean(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// A scenario builder of [`RimuSimParams`]: seed and fault → parameters.
type MakeScenario = fn(u64, Option<(usize, GyroFaultKind)>) -> RimuSimParams;

/// One scenario's runs with the classifier, laid end to end 100 s apart, for
/// its scorecards.
#[derive(Default)]
struct LaidRuns {
    parity_trace: Vec<(f64, Health)>,
    iso_trace: Vec<(f64, Health)>,
    windows: Vec<FaultWindow>,
    times: Vec<f64>,
}

impl LaidRuns {
    /// Appends one run whose fault on `gyro` starts at `onset` and lasts to `end_s`.
    fn lay(&mut self, out: &RunOutcome, gyro: usize, onset: f64, end_s: f64) {
        let offset = 100.0 * self.windows.len() as f64;
        let correct_at = match &out.isolated {
            Some((t, g)) if g == &vec![gyro] => *t,
            _ => f64::INFINITY,
        };
        for &(t, h, _) in &out.trace {
            self.parity_trace.push((t + offset, h));
            // The isolation "alarm" is the faulty gyro being isolated.
            let iso_health = if t >= correct_at {
                Health::Isolated
            } else {
                Health::Healthy
            };
            self.iso_trace.push((t + offset, iso_health));
        }
        self.windows.push(FaultWindow {
            start: onset + offset,
            end: end_s + offset,
        });
        self.times.push(out.time_per_epoch_s);
    }

    /// The parity and isolation scorecards of scenario `name`.
    fn scorecards(&self, name: &str) -> [Scorecard; 2] {
        let tpe = mean(&self.times);
        let label = format!("T_D={T_D} {name}");
        [
            ("parity", &self.parity_trace),
            ("isolation", &self.iso_trace),
        ]
        .map(|(detector, trace)| {
            let mut card = scorecard::score(detector, &label, trace, &self.windows, tpe);
            // Every fault lasts to the end of its run: there is no recovery to time
            // (the windows' ends only separate runs laid end to end).
            card.recovery_s.clear();
            card.recoveries_censored = 0;
            // The nominal per-epoch rate of T_D for the FSS window's χ²(l'·p): the
            // default four gyros have one parity equation, l' = 6.
            match navguard_core::detect::chi2::false_alarm_probability(6, T_D) {
                Ok(p) => card.with_p_fa(p),
                Err(_) => card,
            }
        })
    }
}

/// One row of the table: a scenario, gyro and fault kind over every run.
struct Case<'a> {
    params: &'a Seed002Params,
    spec: &'a MonitorSpec,
    models: &'a HashMap<String, Arc<AnyModel>>,
    name: &'static str,
    make: MakeScenario,
    gyro: usize,
    /// Index of the fault kind in [`GyroFaultKind::SEED002`].
    ki: usize,
    kind: GyroFaultKind,
}

impl Case<'_> {
    /// Runs every noise seed; with `laid`, lays each run out for the
    /// scorecards and keeps the λ trace of steady, gyro 1, bias 5σ, first run.
    fn run(
        &self,
        mut laid: Option<&mut LaidRuns>,
        lambda_trace: &mut Vec<(f64, f64)>,
    ) -> Result<CaseRow, ExperimentError> {
        let (params, gyro, kind) = (self.params, self.gyro, self.kind);
        let mut row = CaseRow {
            scenario: self.name,
            gyro,
            fault: kind,
            runs: params.runs,
            detected: 0,
            isolated_correctly: 0,
            isolated_wrong: 0,
            detection_delay_s: None,
            isolation_delay_s: None,
            omega_rms_sigma: 0.0,
        };
        let (mut det, mut iso, mut sq) = (Vec::new(), Vec::new(), Vec::new());
        for r in 0..params.runs {
            // Fresh noise for every run and case (not the same draws per gyro).
            let case = (gyro * 4 + self.ki) as u64;
            let seed = params.seed.wrapping_add(1 + r as u64 + 1000 * case);
            let mut sim = (self.make)(seed, Some((gyro, kind)));
            if let rsim::Flight::Climb { climb_deg, .. } = &mut sim.flight {
                *climb_deg = params.climb_deg;
            }
            let onset = sim.fault.map_or(0.0, |f| f.onset_s);
            let out = run_case(&sim, self.spec, self.models)?;
            if let Some(t) = out.detected_at {
                row.detected += 1;
                det.push(t - onset);
            }
            match &out.isolated {
                Some((t, g)) if g == &vec![gyro] => {
                    row.isolated_correctly += 1;
                    iso.push(t - onset);
                }
                Some(_) => row.isolated_wrong += 1,
                None => {}
            }
            sq.extend(out.omega_sq.iter().copied());
            if let Some(laid) = laid.as_deref_mut() {
                laid.lay(&out, gyro, onset, sim.end_s);
                if self.name == "steady" && gyro == 0 && kind == GyroFaultKind::Bias(5.0) && r == 0
                {
                    *lambda_trace = out.trace.iter().map(|&(t, _, l)| (t, l)).collect();
                }
            }
        }
        let sigma = navguard_core::monitor::rimu::default_sigma();
        row.detection_delay_s = mean(&det);
        row.isolation_delay_s = mean(&iso);
        row.omega_rms_sigma = mean(&sq).map_or(f64::NAN, |m| m.sqrt() / sigma);
        Ok(row)
    }
}

/// Runs the experiment.
pub fn run(params: Seed002Params) -> Result<Seed002Result, ExperimentError> {
    let (model, training) = train_classifier(&params)?;
    let models: HashMap<String, Arc<AnyModel>> = [(MODEL_ID.to_owned(), model)].into();
    let scenarios: [(&'static str, MakeScenario); 2] = [
        ("steady", RimuSimParams::steady),
        ("manoeuvring", RimuSimParams::manoeuvring),
    ];
    let mut rows = Vec::new();
    let mut rows_parity_only = Vec::new();
    let mut scorecards = Vec::new();
    let mut lambda_trace = Vec::new();
    for (name, make) in scenarios {
        let mut laid = LaidRuns::default();
        for with_model in [true, false] {
            let spec = spec(&params, with_model);
            for gyro in 0..4 {
                for (ki, kind) in GyroFaultKind::SEED002.into_iter().enumerate() {
                    let case = Case {
                        params: &params,
                        spec: &spec,
                        models: &models,
                        name,
                        make,
                        gyro,
                        ki,
                        kind,
                    };
                    if with_model {
                        rows.push(case.run(Some(&mut laid), &mut lambda_trace)?);
                    } else {
                        rows_parity_only.push(case.run(None, &mut lambda_trace)?);
                    }
                }
            }
        }
        scorecards.extend(laid.scorecards(name));
    }
    Ok(Seed002Result {
        params,
        training,
        rows,
        rows_parity_only,
        scorecards,
        lambda_trace,
    })
}

fn opt_s(v: Option<f64>) -> String {
    v.map_or_else(|| "—".to_owned(), |v| format!("{v:.2}"))
}

fn table(s: &mut String, rows: &[CaseRow]) {
    let _ = writeln!(
        s,
        "{:<12} {:>4} {:<12} {:>9} {:>9} {:>7} {:>9} {:>9} {:>10}",
        "scenario", "gyro", "fault", "detected", "isolated", "wrong", "det. s", "iso. s", "ω rms/σ"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:<12} {:>4} {:<12} {:>6}/{:<2} {:>6}/{:<2} {:>7} {:>9} {:>9} {:>10.2}",
            r.scenario,
            r.gyro + 1,
            r.fault.label(),
            r.detected,
            r.runs,
            r.isolated_correctly,
            r.runs,
            r.isolated_wrong,
            opt_s(r.detection_delay_s),
            opt_s(r.isolation_delay_s),
            r.omega_rms_sigma,
        );
    }
}

/// Totals `(detected, isolated correctly, wrong, runs)` of some rows.
pub fn totals<'a>(rows: impl IntoIterator<Item = &'a CaseRow>) -> (usize, usize, usize, usize) {
    rows.into_iter().fold((0, 0, 0, 0), |a, r| {
        (
            a.0 + r.detected,
            a.1 + r.isolated_correctly,
            a.2 + r.isolated_wrong,
            a.3 + r.runs,
        )
    })
}

/// √trace((HₕᵀHₕ)⁻¹): the RMS of ‖ω̂ − ω‖ in units of σ that noise alone gives the
/// least squares over the default gyros without gyro `out`.
pub fn noise_floor(out: Option<usize>) -> Option<f64> {
    let h = navguard_core::detect::parity::default_h();
    let mut a = nalgebra::Matrix3::<f64>::zeros();
    for i in (0..h.nrows()).filter(|&i| Some(i) != out) {
        let r = nalgebra::Vector3::new(h[(i, 0)], h[(i, 1)], h[(i, 2)]);
        a += r * r.transpose();
    }
    a.try_inverse().map(|inv| inv.trace().sqrt())
}

/// The text report.
pub fn render(r: &Seed002Result) -> String {
    let mut s = String::new();
    let t = &r.training;
    let _ = writeln!(
        s,
        "Seed 002: 4-gyro RIMU (3 orthogonal + 1 skewed), 100 Hz, ARW 0.5°/√h (σ = {:.4e} rad/s), \
         FSS l' = 6, T_D = {T_D}, l = {}, {:?} level {}, T_I = {}, {} runs per case",
        navguard_core::monitor::rimu::default_sigma(),
        r.params.feature_window,
        r.params.wavelet.wavelet,
        r.params.wavelet.level,
        r.params.t_i,
        r.params.runs,
    );
    let _ = writeln!(
        s,
        "classifier: svm {} on {} normal + {} fault windows; split 80/20 ({} train, {} test), \
         {} split(s) tried, held-out accuracy {:.1} %, train accuracy {}, {} support vectors, {:.3} s",
        r.params.svm,
        r.params.n_normal,
        r.params.n_fault,
        t.n_train,
        t.n_test,
        t.attempts,
        100.0 * t.test_accuracy,
        t.train_accuracy
            .map_or("—".into(), |a| format!("{:.1} %", 100.0 * a)),
        t.support_vectors.map_or("—".into(), |n| n.to_string()),
        t.seconds,
    );
    let floor = |out: Option<usize>| noise_floor(out).map_or("—".into(), |f| format!("{f:.2}"));
    let _ = writeln!(
        s,
        "ω noise floor (RMS ‖ω̂ − ω‖/σ of the WLS): all 4 gyros {}, gyro 1–3 out {}, gyro 4 out {}",
        floor(None),
        floor(Some(0)),
        floor(Some(3)),
    );
    let _ = writeln!(
        s,
        "\nWith the classifier (RAS); manoeuvring = 4 s climb to {}° from 30 s:",
        r.params.climb_deg
    );
    table(&mut s, &r.rows);
    let _ = writeln!(s, "\nParity test alone (no model):");
    table(&mut s, &r.rows_parity_only);
    let _ = writeln!(
        s,
        "\nTotals (detected / isolated correctly / isolated wrong / runs):"
    );
    for name in ["steady", "manoeuvring"] {
        for (label, rows) in [("RAS", &r.rows), ("parity only", &r.rows_parity_only)] {
            let (d, i, w, n) = totals(rows.iter().filter(|x| x.scenario == name));
            let _ = writeln!(s, "  {name:<12} {label:<12} {d}/{n} {i}/{n} {w}/{n}");
        }
    }
    let _ = writeln!(
        s,
        "paper (seed 002 §3, Table 1): RAS detects and isolates every injected fault in both \
         scenarios; parity (GLT/FSS) alone detects but cannot isolate with one redundant gyro."
    );
    let _ = writeln!(s);
    s.push_str(&scorecard::render(&r.scorecards));
    s
}

/// The parity statistic against T_D for steady flight, gyro 1, 5σ bias (cf. seed 002 Fig. 4).
pub fn plots(r: &Seed002Result) -> Vec<(String, String)> {
    let chart = Chart::new(
        "Parity FSS λ, steady flight, 5σ bias on gyro 1 from 25 s (seed 002)",
        "t, s",
        "λ",
    )
    .with_series(Series::new("λ (parity, dof 6)", r.lambda_trace.clone()))
    .with_threshold(T_D, format!("T_D = {T_D}"))
    .with_log_y(true);
    vec![("parity_lambda.svg".to_owned(), chart.to_svg())]
}
