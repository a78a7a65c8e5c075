//! Seed 001's experiment (§4, Table 1, Figs. 2–3) on the `imu-channel` scenario
//! ([`crate::imu_channel`]): 135 gyro samples, embedding 5, γ = 30, σ = 3 (σ² = 9,
//! raw °/s units, as the paper's online model has no standardisation).
//!
//! 1. **Prediction** (Table 1): one-step predictions from sample `m + N` on by the
//!    online recursive LS-SVM (window N, O(N²) updates), a batch re-solve of the same
//!    window every step (O(N³)), and a global LS-SVM trained once on the first N samples;
//!    RMSE against the true rate and wall time per prediction (update included; the mean
//!    over `reps` repetitions of the whole record).
//! 2. **Faults** (Figs. 2–3): stuck, gain, bias and failure from k = 80, through the
//!    `channel` monitor with the online predictor and T_a (classic policy): detection
//!    delay in samples (first flagged sample at or after 80, minus 80) and the scorecard.
//! 3. **Outliers**: spikes every 15 samples; RMSE of the online predictions against the
//!    true rate with and without the seed 001 §2.2.1 outlier filter in front of the window.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::time::Instant;

use serde_json::json;

use super::ExperimentError;
use super::scorecard::{self, FaultWindow, Scorecard};
use super::seed000::{run_channel_with, scalar_channel};
use crate::faults::FaultKind;
use crate::imu_channel::{self, FAULT_K, SAMPLES};
use navguard_core::detect::{Health, PolicyConfig};
use navguard_core::learn::lssvm::LsSvmModel;
use navguard_core::learn::online::{OnlineLsSvm, OnlineParams};
use navguard_core::learn::outlier::OutlierFilter;
use navguard_core::learn::{Dataset, LearnError, ModelKind, ModelParams};
use navguard_core::monitor::channel::{
    ChannelConfigWire, DEFAULT_GUARD, DEFAULT_MAX_FREEZE, PredictorWire, ResidualScale, Toggle,
    VarianceKind,
};

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct Seed001Params {
    /// Scenario seed.
    pub seed: u64,
    /// Samples in the record.
    pub samples: usize,
    /// Online window N (the paper does not give it).
    pub window: usize,
    /// Regularisation γ.
    pub gamma: f64,
    /// RBF width σ², raw units.
    pub sigma2: f64,
    /// Embedding m.
    pub embedding: usize,
    /// Repetitions of part 1 for the timings.
    pub reps: usize,
    /// False-alarm probability of T_a.
    pub p_fa: f64,
    /// T_a window n (default 1: seed 001 compares each residual with a threshold, its
    /// step 8; with the short, still-learning window a 10-residual mean turns the online
    /// model's slowly varying prediction error into false alarms).
    pub n: usize,
    /// Outlier filter factor c.
    pub c: f64,
    /// Fault-free samples before the paper's record in part 2 (the calibrated tests need
    /// a healthy history: the online window fills at sample m + N = 45, the batch-means
    /// variance then takes 100 healthy residuals and the stuck test 50 differences).
    pub lead_in: usize,
    /// Noise draws in part 2 (seeds `seed`, `seed + 1`, …).
    pub seeds: usize,
}

impl Default for Seed001Params {
    fn default() -> Self {
        Seed001Params {
            seed: 1,
            samples: SAMPLES,
            window: 40,
            gamma: 30.0,
            sigma2: 9.0,
            embedding: 5,
            reps: 20,
            p_fa: 0.002,
            n: 1,
            c: 3.0,
            lead_in: 300,
            seeds: 20,
        }
    }
}

/// One predictor's figures in part 1.
#[derive(Debug, Clone, PartialEq)]
pub struct PredictorRow {
    /// Method label.
    pub method: &'static str,
    /// RMSE against the true rate, °/s.
    pub rmse: f64,
    /// Wall time per prediction (update included), s.
    pub time_s: f64,
}

/// One configuration of the channel in part 2.
#[derive(Debug, Clone, PartialEq)]
pub struct Seed001Case {
    /// Label in the tables.
    pub label: &'static str,
    /// T_a's variance.
    pub variance: VarianceKind,
    /// T_a's (long) window.
    pub n: usize,
    /// Whether the `gyro.stuck` test runs.
    pub stuck: bool,
    /// Guard after a non-healthy epoch, epochs.
    pub guard: usize,
    /// Decision policy.
    pub policy: PolicyConfig,
    /// Longest freeze of the online predictor, epochs (0: never relearn).
    pub max_freeze: usize,
    /// How the residual is scaled before the tests (`None`: the channel's default, raw).
    pub residual_scale: Option<ResidualScale>,
}

/// Part 2's configurations: the paper's (each residual against a threshold, the
/// successive-difference variance, learning whenever the test passes), then the
/// calibrated monitor's defaults (windows 1 and 10 by batch means, the stuck test, guard
/// 10) under the classic and the counters policy, counters with the guard and without the
/// freeze limit, and the classic and counters defaults with the residual over its
/// predictive σ (docs/methods.md §M9a).
pub fn cases(p: &Seed001Params) -> Vec<Seed001Case> {
    let (classic, counters) = (PolicyConfig::Classic, PolicyConfig::counters_default());
    let f = DEFAULT_MAX_FREEZE;
    let calibrated = |label, guard, policy, max_freeze| Seed001Case {
        label,
        variance: VarianceKind::BatchMeans,
        n: navguard_core::detect::ta::DEFAULT_N,
        stuck: true,
        guard,
        policy,
        max_freeze,
        residual_scale: None,
    };
    let predictive = |case: Seed001Case, label| Seed001Case {
        label,
        residual_scale: Some(ResidualScale::Predictive),
        ..case
    };
    vec![
        Seed001Case {
            label: "paper: SD n=1",
            variance: VarianceKind::SuccessiveDifference,
            n: p.n,
            stuck: false,
            guard: 0,
            policy: PolicyConfig::Classic,
            max_freeze: 0,
            residual_scale: Some(ResidualScale::Raw),
        },
        calibrated("BM classic", DEFAULT_GUARD, classic, f),
        calibrated("BM counters", DEFAULT_GUARD, counters, f),
        calibrated("BM counters g10", 10, counters, f),
        calibrated("BM counters f∞", DEFAULT_GUARD, counters, 0),
        predictive(calibrated("", DEFAULT_GUARD, classic, f), "BM classic pred"),
        predictive(
            calibrated("", DEFAULT_GUARD, counters, f),
            "BM counters pred",
        ),
    ]
}

/// One fault mode's figures in part 2 under one configuration, over every noise draw.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultRow {
    /// Fault mode (`none` for the fault-free record).
    pub fault: &'static str,
    /// The configuration's label.
    pub case: &'static str,
    /// First flagged sample at or after the onset, minus the onset, on the first draw.
    pub delay_samples: Option<usize>,
    /// The same per draw.
    pub delays: Vec<Option<usize>>,
    /// First sample the `gyro.stuck` test flags at or after the onset, minus the onset,
    /// per draw (`None`: never, or no stuck test).
    pub stuck_delays: Vec<Option<usize>>,
    /// Flagged samples before the onset (lead-in included), all draws.
    pub false_alarms: usize,
    /// Samples the `gyro.stuck` test flags before the onset (the whole record when
    /// fault-free), all draws.
    pub stuck_false_alarms: usize,
    /// The channel's scorecard (flagged = any of its tests not healthy), draws laid end
    /// to end; `t` = sample index.
    pub card: Scorecard,
    /// `(k, T_a)` of the first draw.
    pub statistic: Vec<(f64, f64)>,
}

/// Everything the experiment measured.
#[derive(Debug, Clone, PartialEq)]
pub struct Seed001Result {
    /// The parameters.
    pub params: Seed001Params,
    /// Part 1: online, batch re-solve, global.
    pub predictors: Vec<PredictorRow>,
    /// Part 2: per case (in [`cases`] order), the fault-free record then every fault.
    pub faults: Vec<FaultRow>,
    /// Part 3: RMSE with spikes, without and with the filter, °/s.
    pub outlier_rmse: (f64, f64),
    /// Part 3: values the filter replaced.
    pub replaced: u64,
    /// Part 3: spikes injected.
    pub spikes: usize,
}

/// The online window's parameters, through their wire form (so field changes in
/// `learn::online` cannot break this file silently).
fn online_params(p: &Seed001Params) -> Result<OnlineParams, LearnError> {
    serde_json::from_value(json!({"window": p.window, "gamma": p.gamma, "sigma2": p.sigma2}))
        .map_err(|e| LearnError::params("online", e.to_string()))
}

fn batch_fit(p: &Seed001Params, x: &[Vec<f64>], y: &[f64]) -> Result<LsSvmModel, LearnError> {
    let params = ModelParams::from_json(
        ModelKind::LsSvm,
        &json!({"gamma": p.gamma, "sigma2": p.sigma2, "standardize": false}),
    )?;
    let ModelParams::LsSvm(params) = params else {
        return Err(LearnError::params("kind", "expected lssvm params"));
    };
    params.fit(&Dataset::new(x, Some(y))?)
}

fn rmse(pairs: &[(f64, f64)]) -> f64 {
    let n = pairs.len().max(1) as f64;
    (pairs.iter().map(|(a, b)| (a - b).powi(2)).sum::<f64>() / n).sqrt()
}

/// Part 1.
pub fn predictors(p: &Seed001Params) -> Result<Vec<PredictorRow>, ExperimentError> {
    let run = imu_channel::simulate(p.seed, p.samples, None, false)?;
    let (y, m, n) = (&run.measured, p.embedding, p.window);
    let start = m + n;
    if y.len() <= start {
        return Err(LearnError::params("window", "longer than the record").into());
    }
    let input = |k: usize| y[k - m..k].to_vec();
    let (mut t_online, mut t_batch, mut t_global) = (0.0, 0.0, 0.0);
    let (mut e_online, mut e_batch, mut e_global) = (Vec::new(), Vec::new(), Vec::new());
    for rep in 0..p.reps.max(1) {
        let record = rep == 0;
        // Online: fill the window with the first N pairs, then predict-and-update.
        let mut online = OnlineLsSvm::new(online_params(p)?)?;
        for (k, &yk) in y.iter().enumerate().take(start).skip(m) {
            online.push(&input(k), yk)?;
        }
        let began = Instant::now();
        for (k, &yk) in y.iter().enumerate().skip(start) {
            let x = input(k);
            let yhat = online.predict(&x).unwrap_or(f64::NAN);
            online.push(&x, yk)?;
            if record {
                e_online.push((yhat, run.truth[k]));
            }
        }
        t_online += began.elapsed().as_secs_f64();
        // Batch: re-solve the last N pairs every step.
        let began = Instant::now();
        for k in start..y.len() {
            let xs: Vec<Vec<f64>> = (k - n..k).map(input).collect();
            let model = batch_fit(p, &xs, &y[k - n..k])?;
            let yhat = model.predict_one(&input(k));
            if record {
                e_batch.push((yhat, run.truth[k]));
            }
        }
        t_batch += began.elapsed().as_secs_f64();
        // Global: trained once on the first N pairs.
        let xs: Vec<Vec<f64>> = (m..start).map(input).collect();
        let model = batch_fit(p, &xs, &y[m..start])?;
        let began = Instant::now();
        for k in start..y.len() {
            let yhat = model.predict_one(&input(k));
            if record {
                e_global.push((yhat, run.truth[k]));
            }
        }
        t_global += began.elapsed().as_secs_f64();
    }
    let per = (p.reps.max(1) * (y.len() - start)) as f64;
    Ok(vec![
        PredictorRow {
            method: "online recursive",
            rmse: rmse(&e_online),
            time_s: t_online / per,
        },
        PredictorRow {
            method: "batch re-solve",
            rmse: rmse(&e_batch),
            time_s: t_batch / per,
        },
        PredictorRow {
            method: "global LS-SVM",
            rmse: rmse(&e_global),
            time_s: t_global / per,
        },
    ])
}

/// The channel of part 2 under `case`.
fn case_config(p: &Seed001Params, case: &Seed001Case) -> Result<ChannelConfigWire, LearnError> {
    let mut channel = scalar_channel(
        imu_channel::CHANNEL,
        p.embedding,
        case.n,
        PredictorWire::Online(online_params(p)?),
    );
    channel.variance = Some(case.variance);
    channel.stuck = Some(Toggle::On(case.stuck));
    channel.guard = Some(case.guard);
    channel.max_freeze = Some(case.max_freeze);
    channel.residual_scale = case.residual_scale;
    Ok(ChannelConfigWire {
        channels: vec![channel],
    })
}

/// First flagged sample at or after `onset`, minus `onset`.
fn first_flag(trace: &[(f64, Health)], onset: usize) -> Option<usize> {
    trace
        .iter()
        .find(|&&(t, h)| t >= onset as f64 && h != Health::Healthy)
        .map(|&(t, _)| t as usize - onset)
}

/// Part 2 under one configuration: the fault-free record and every fault mode through
/// the channel monitor with the online predictor, each over `p.seeds` noise draws.
pub fn faults_case(
    p: &Seed001Params,
    case: &Seed001Case,
) -> Result<Vec<FaultRow>, ExperimentError> {
    let config = case_config(p, case)?;
    let mut modes: Vec<(&'static str, Option<FaultKind>)> = vec![("none", None)];
    modes.extend(imu_channel::fault_modes().map(|(n, k)| (n, Some(k))));
    let mut rows = Vec::new();
    for (name, kind) in modes {
        let (mut delays, mut stuck_delays, mut false_alarms) = (Vec::new(), Vec::new(), 0);
        let mut stuck_false_alarms = 0;
        let (mut pooled, mut windows, mut statistic) = (Vec::new(), Vec::new(), Vec::new());
        let (mut busy, mut epochs) = (0.0, 0usize);
        for draw in 0..p.seeds.max(1) {
            let seed = p.seed + draw as u64;
            let run = imu_channel::simulate_with_lead_in(seed, p.lead_in, p.samples, kind, false)?;
            let trace = run_channel_with(
                config.clone(),
                &HashMap::new(),
                case.policy,
                p.p_fa,
                &run.epochs(),
            )?;
            let onset = run.fault_k;
            delays.push(first_flag(&trace.channel, onset).filter(|_| kind.is_some()));
            let stuck: Vec<(f64, Health)> = trace
                .tests
                .get(&format!("{}.stuck", imu_channel::CHANNEL))
                .map(|v| v.iter().map(|&(t, _, h)| (t, h)).collect())
                .unwrap_or_default();
            stuck_delays.push(first_flag(&stuck, onset).filter(|_| kind.is_some()));
            let onset_or_end = if kind.is_some() { onset } else { usize::MAX };
            stuck_false_alarms += stuck
                .iter()
                .filter(|&&(t, h)| t < onset_or_end as f64 && h != Health::Healthy)
                .count();
            false_alarms += trace
                .channel
                .iter()
                .filter(|&&(t, h)| t < onset as f64 && h != Health::Healthy)
                .count();
            let off = (draw * (run.measured.len() + 100)) as f64;
            pooled.extend(trace.channel.iter().map(|&(t, h)| (t + off, h)));
            if kind.is_some() {
                windows.push(FaultWindow {
                    start: onset as f64 + off,
                    end: run.measured.len() as f64 + off,
                });
            }
            if draw == 0 {
                statistic = trace.samples.iter().map(|&(t, v, _)| (t, v)).collect();
            }
            busy += trace.busy_s;
            epochs += trace.epochs;
        }
        let card = scorecard::score(
            imu_channel::CHANNEL,
            case.label,
            &pooled,
            &windows,
            Some(busy / epochs.max(1) as f64),
        )
        .with_p_fa(p.p_fa);
        rows.push(FaultRow {
            fault: name,
            case: case.label,
            delay_samples: delays.first().copied().flatten(),
            delays,
            stuck_delays,
            false_alarms,
            stuck_false_alarms,
            card,
            statistic,
        });
    }
    Ok(rows)
}

/// Part 2: every configuration of [`cases`].
pub fn faults(p: &Seed001Params) -> Result<Vec<FaultRow>, ExperimentError> {
    let mut rows = Vec::new();
    for case in cases(p) {
        rows.extend(faults_case(p, &case)?);
    }
    Ok(rows)
}

/// Part 3: online predictions on a spiky record, without and with the outlier filter.
/// Returns (RMSE without, RMSE with, values replaced, spikes).
pub fn outliers(p: &Seed001Params) -> Result<(f64, f64, u64, usize), ExperimentError> {
    let run = imu_channel::simulate(p.seed, p.samples, None, true)?;
    let m = p.embedding;
    let mut result = [0.0; 2];
    let mut replaced = 0;
    for (i, filtered) in [false, true].into_iter().enumerate() {
        let mut filter = OutlierFilter::new(p.c);
        let mut online = OnlineLsSvm::new(online_params(p)?)?;
        let mut history: Vec<f64> = Vec::with_capacity(run.measured.len());
        let mut errors = Vec::new();
        for (k, &raw) in run.measured.iter().enumerate() {
            let value = if filtered { filter.filter(raw).0 } else { raw };
            if k >= m {
                let x = &history[k - m..k];
                if k >= m + p.window {
                    errors.push((online.predict(x).unwrap_or(f64::NAN), run.truth[k]));
                }
                online.push(x, value)?;
            }
            history.push(value);
        }
        result[i] = rmse(&errors);
        if filtered {
            replaced = filter.replaced();
        }
    }
    Ok((result[0], result[1], replaced, run.spikes.len()))
}

/// Runs the three parts.
pub fn run(params: Seed001Params) -> Result<Seed001Result, ExperimentError> {
    let predictors = predictors(&params)?;
    let faults = faults(&params)?;
    let (without, with, replaced, spikes) = outliers(&params)?;
    Ok(Seed001Result {
        params,
        predictors,
        faults,
        outlier_rmse: (without, with),
        replaced,
        spikes,
    })
}

/// The text report.
pub fn render(r: &Seed001Result) -> String {
    let p = &r.params;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Seed 001 — imu-channel, {} samples, embedding {}, window N = {}, γ = {}, σ² = {} (raw °/s), p_fa = {}\n",
        p.samples, p.embedding, p.window, p.gamma, p.sigma2, p.p_fa
    );
    let _ = writeln!(
        s,
        "1. One-step prediction from sample {} on (RMSE against the true rate)",
        p.embedding + p.window
    );
    let _ = writeln!(
        s,
        "{:<18} {:>12} {:>16}",
        "method", "RMSE °/s", "µs/prediction"
    );
    for row in &r.predictors {
        let _ = writeln!(
            s,
            "{:<18} {:>12.4} {:>16.2}",
            row.method,
            row.rmse,
            row.time_s * 1e6
        );
    }
    render_faults(&mut s, r);
    let _ = writeln!(
        s,
        "\n3. Outliers: {} spikes of ±{} °/s; online RMSE against the true rate: {:.4} without the filter, {:.4} with it ({} values replaced)\n",
        r.spikes,
        imu_channel::SPIKE_DPS,
        r.outlier_rmse.0,
        r.outlier_rmse.1,
        r.replaced
    );
    let _ = writeln!(
        s,
        "Scorecard (docs/methods.md §M19) of the channel (any of its tests), draws pooled, t = sample index:"
    );
    let cards: Vec<Scorecard> = r
        .faults
        .iter()
        .map(|f| {
            let mut card = f.card.clone();
            card.detector = f.fault.to_owned();
            card.recovery_s.clear();
            card
        })
        .collect();
    s.push_str(&scorecard::render(&cards));
    s
}

fn delays_text(delays: &[Option<usize>]) -> String {
    let hit: Vec<usize> = delays.iter().flatten().copied().collect();
    if hit.is_empty() {
        return "missed".to_owned();
    }
    let mean = hit.iter().sum::<usize>() as f64 / hit.len() as f64;
    let max = hit.iter().max().copied().unwrap_or(0);
    let missed = delays.len() - hit.len();
    if missed > 0 {
        format!("{mean:.1}/{max} ({missed} missed)")
    } else {
        format!("{mean:.1}/{max}")
    }
}

/// Part 2's table: per configuration and fault, the share of fault epochs flagged, the
/// delays, the false alarms before the onset.
fn render_faults(s: &mut String, r: &Seed001Result) {
    let p = &r.params;
    let _ = writeln!(
        s,
        "\n2. Faults from k = {FAULT_K} of the record, after a lead-in of {} fault-free samples (onset at sample {}), {} noise draws (seeds {}…{}); \
         online predictor; flagged = any test of the channel (gyro, gyro.stuck) not healthy",
        p.lead_in,
        p.lead_in + FAULT_K,
        p.seeds.max(1),
        p.seed,
        p.seed + p.seeds.max(1) as u64 - 1
    );
    let _ = writeln!(
        s,
        "{:<16} {:<8} {:>9} {:>18} {:>18} {:>12} {:>10} {:>9}",
        "case",
        "fault",
        "flagged",
        "delay mean/max",
        "stuck mean/max",
        "FAR/p_fa",
        "FA before",
        "stuck FA"
    );
    for f in &r.faults {
        let stuck = if f.stuck_delays.iter().all(Option::is_none) {
            "—".to_owned()
        } else {
            delays_text(&f.stuck_delays)
        };
        let (tpr, delay) = if f.fault == "none" {
            ("—".to_owned(), "—".to_owned())
        } else {
            (
                f.card
                    .true_positive_rate
                    .map_or_else(|| "—".to_owned(), |v| format!("{:.1} %", 100.0 * v)),
                delays_text(&f.delays),
            )
        };
        let _ = writeln!(
            s,
            "{:<16} {:<8} {:>9} {:>18} {:>18} {:>12} {:>10} {:>9}",
            f.case,
            f.fault,
            tpr,
            delay,
            stuck,
            f.card
                .far_over_p_fa()
                .map_or_else(|| "—".to_owned(), |v| format!("{v:.2}×")),
            f.false_alarms,
            f.stuck_false_alarms,
        );
    }
}

/// The figure: T_a against the sample index for each fault mode.
pub fn plots(r: &Seed001Result) -> Vec<(String, String)> {
    use crate::plot::{Chart, Series};
    let threshold = navguard_core::detect::chi2::threshold(1, r.params.p_fa).unwrap_or(f64::NAN);
    let mut chart = Chart::new(
        "T_a of the gyro channel, faults from k = 80 (seed 001 Figs. 2–3)",
        "sample k",
        "T_a",
    )
    .with_threshold(threshold, format!("T_D = {threshold:.2}"))
    .with_log_y(true);
    // The calibrated classic case, first draw (the chart's k is the record's sample).
    let lead = r.params.lead_in as f64;
    for f in r
        .faults
        .iter()
        .filter(|f| f.case == "BM classic" && f.fault != "none")
    {
        let points = f
            .statistic
            .iter()
            .map(|&(k, v)| (k - lead, v.max(1e-3)))
            .collect();
        chart = chart.with_series(Series::new(f.fault, points));
    }
    vec![("ta_faults.svg".to_owned(), chart.to_svg())]
}
