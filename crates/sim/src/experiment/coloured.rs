//! The coloured-residual calibration experiment (docs/methods.md §M20):
//! is T_a's false-alarm rate what its `p_fa` says when the channel's residual is not
//! white? A slow two-tone signal with AR(1) noise and a slow Gauss–Markov wander is
//! predicted by the `channel` monitor's online LS-SVM (seed 001's predictor), and its
//! fault-free false-alarm rate is measured with the successive-difference variance of
//! seed 000 eq. 16 beside the batch-means one, over several seeds; then a step of 4
//! residual standard deviations checks that the calibrated test still flags at once.
//!
//! Signal, per epoch k (1 s): `y_k = 3 sin(2πk/173) + 1.5 sin(2πk/61 + 0.4) + w_k + e_k`,
//! with `e` AR(1), `e_k = φ e_{k−1} + σ_e √(1 − φ²) ε_k` (σ_e = 0.3, φ = 0.9 or 0 for
//! white), and `w` first-order Gauss–Markov, σ_w = 1, τ = 300 s (the two tone periods are
//! not multiples of any window, so nothing aliases with the blocks).

use std::collections::HashMap;
use std::fmt::Write as _;

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};
use serde_json::json;

use super::ExperimentError;
use super::scorecard::{self, FaultWindow, Scorecard};
use super::seed000::{ChannelTrace, run_channel_with, scalar_channel};
use navguard_core::detect::{Health, PolicyConfig};
use navguard_core::epoch::Epoch;
use navguard_core::learn::LearnError;
use navguard_core::learn::online::OnlineParams;
use navguard_core::monitor::channel::{
    ChannelConfigWire, PredictorWire, ResidualScale, Toggle, VarianceKind,
};

/// The channel's name.
pub const CHANNEL: &str = "y";

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct ColouredParams {
    /// First seed; draw i uses `seed + i`.
    pub seed: u64,
    /// Noise draws per case.
    pub seeds: usize,
    /// Epochs per run.
    pub epochs: usize,
    /// AR(1) coefficient of the noise (the white case uses 0).
    pub phi: f64,
    /// Stationary σ of the AR(1) noise.
    pub noise_sigma: f64,
    /// Gauss–Markov wander σ.
    pub wander_sigma: f64,
    /// Gauss–Markov correlation time, epochs.
    pub wander_tau: f64,
    /// T_a's false-alarm probability.
    pub p_fa: f64,
    /// T_a's long window.
    pub n: usize,
    /// Step size in residual standard deviations.
    pub step_sigmas: f64,
    /// Step onsets per run (spread over the second half).
    pub steps: usize,
}

impl Default for ColouredParams {
    fn default() -> Self {
        ColouredParams {
            seed: 1,
            seeds: 5,
            epochs: 12_000,
            phi: 0.9,
            noise_sigma: 0.3,
            wander_sigma: 1.0,
            wander_tau: 300.0,
            p_fa: 0.002,
            n: navguard_core::detect::ta::DEFAULT_N,
            step_sigmas: 4.0,
            steps: 10,
        }
    }
}

/// One configuration of the channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColouredCase {
    /// Label in the table.
    pub label: &'static str,
    /// AR(1) coefficient of this case's noise.
    pub phi: f64,
    /// T_a's variance.
    pub variance: VarianceKind,
    /// Guard, epochs.
    pub guard: usize,
    /// Longest freeze of the predictor, epochs (0: never relearn).
    pub max_freeze: usize,
    /// How the residual is scaled before the tests (`None`: the channel's default, raw).
    pub residual_scale: Option<ResidualScale>,
}

/// The cases: both variances on AR(1) and on white noise, the calibrated one with the
/// guard and other freeze limits, and the batch-means ones with the residual over its
/// predictive σ (docs/methods.md §M9a).
pub fn cases(p: &ColouredParams) -> Vec<ColouredCase> {
    let c = |label, phi, variance, guard, max_freeze| ColouredCase {
        label,
        phi,
        variance,
        guard,
        max_freeze,
        residual_scale: None,
    };
    let predictive = |case: ColouredCase, label| ColouredCase {
        label,
        residual_scale: Some(ResidualScale::Predictive),
        ..case
    };
    let (g, f) = (
        navguard_core::monitor::channel::DEFAULT_GUARD,
        navguard_core::monitor::channel::DEFAULT_MAX_FREEZE,
    );
    use VarianceKind::{BatchMeans as BM, SuccessiveDifference as SD};
    vec![
        c("AR(1) SD", p.phi, SD, g, f),
        c("AR(1) BM", p.phi, BM, g, f),
        c("AR(1) BM g10", p.phi, BM, 10, f),
        c("AR(1) BM f50", p.phi, BM, g, 50),
        c("AR(1) BM f∞", p.phi, BM, g, 0),
        c("AR(1) SD f∞", p.phi, SD, g, 0),
        c("white SD", 0.0, SD, g, f),
        c("white BM", 0.0, BM, g, f),
        predictive(c("", p.phi, BM, g, f), "AR(1) BM pred"),
        predictive(c("", p.phi, BM, g, 0), "AR(1) BM f∞ pred"),
        predictive(c("", 0.0, BM, g, f), "white BM pred"),
    ]
}

/// One case's figures over every draw.
#[derive(Debug, Clone, PartialEq)]
pub struct ColouredRow {
    /// The case.
    pub case: ColouredCase,
    /// Scorecard of the main test on the fault-free runs, draws pooled.
    pub main: Scorecard,
    /// Scorecard of the channel (any test) on the same runs.
    pub channel: Scorecard,
    /// Scorecard of the main test on the runs with steps.
    pub steps: Scorecard,
    /// Step size used per draw (the healthy residual's RMS × `step_sigmas`).
    pub step_size: Vec<f64>,
}

/// Everything the experiment measured.
#[derive(Debug, Clone, PartialEq)]
pub struct ColouredResult {
    /// The parameters.
    pub params: ColouredParams,
    /// One row per case.
    pub rows: Vec<ColouredRow>,
}

/// The signal of draw `seed` with noise coefficient `phi`, plus `step(k)`.
pub fn signal(p: &ColouredParams, phi: f64, seed: u64, step: impl Fn(usize) -> f64) -> Vec<f64> {
    signal_with(p, phi, Form::TONES_WANDER, seed, step)
}

/// Which parts of the signal are present beside the AR(1) noise.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Form {
    /// The two tones.
    pub tones: bool,
    /// The Gauss–Markov wander.
    pub wander: bool,
}

impl Form {
    /// Tones, wander and noise: the signal of the default cases.
    pub const TONES_WANDER: Form = Form {
        tones: true,
        wander: true,
    };
}

/// The signal of draw `seed` with noise coefficient `phi` and the parts `form`, plus
/// `fault(k)`. A part left out draws its random numbers all the same, so the noise of
/// draw `seed` is the same in every form.
pub fn signal_with(
    p: &ColouredParams,
    phi: f64,
    form: Form,
    seed: u64,
    fault: impl Fn(usize) -> f64,
) -> Vec<f64> {
    use std::f64::consts::TAU;
    let mut rng = StdRng::seed_from_u64(seed);
    let mut n = || -> f64 { StandardNormal.sample(&mut rng) };
    let g = (1.0 - phi * phi).sqrt();
    let a = (-1.0 / p.wander_tau).exp();
    let q = (1.0 - a * a).sqrt();
    let (mut e, mut w) = (p.noise_sigma * n(), p.wander_sigma * n());
    (0..p.epochs)
        .map(|k| {
            e = phi * e + p.noise_sigma * g * n();
            w = a * w + p.wander_sigma * q * n();
            let kf = k as f64;
            let tones = 3.0 * (TAU * kf / 173.0).sin() + 1.5 * (TAU * kf / 61.0 + 0.4).sin();
            let on = |b: bool| if b { 1.0 } else { 0.0 };
            on(form.tones) * tones + on(form.wander) * w + e + fault(k)
        })
        .collect()
}

/// One epoch per value of `series`, 1 s apart, the value on channel [`CHANNEL`].
pub fn epochs(series: &[f64]) -> Vec<Epoch> {
    series
        .iter()
        .enumerate()
        .map(|(k, &v)| Epoch {
            t: k as f64,
            channels: Some(vec![(CHANNEL.to_owned(), vec![v])]),
            ..Default::default()
        })
        .collect()
}

fn config(p: &ColouredParams, case: &ColouredCase) -> Result<ChannelConfigWire, LearnError> {
    let online: OnlineParams =
        serde_json::from_value(json!({"window": 40, "gamma": 30.0, "sigma2": 9.0}))
            .map_err(|e| LearnError::params("online", e.to_string()))?;
    let mut channel = scalar_channel(CHANNEL, 5, p.n, PredictorWire::Online(online));
    channel.variance = Some(case.variance);
    channel.guard = Some(case.guard);
    channel.max_freeze = Some(case.max_freeze);
    channel.residual_scale = case.residual_scale;
    channel.stuck = Some(Toggle::On(true));
    Ok(ChannelConfigWire {
        channels: vec![channel],
    })
}

/// Step onsets of a run: `steps` onsets spread over the second half, 200 epochs apart.
fn onsets(p: &ColouredParams) -> Vec<usize> {
    (0..p.steps).map(|i| p.epochs / 2 + 200 * i).collect()
}

/// Each step lasts this many epochs.
pub const STEP_LEN: usize = 20;

fn pool(traces: &[(f64, Vec<(f64, Health)>)]) -> Vec<(f64, Health)> {
    traces
        .iter()
        .flat_map(|(off, t)| t.iter().map(move |&(k, h)| (k + off, h)))
        .collect()
}

/// Runs one case over every draw.
pub fn run_case(p: &ColouredParams, case: &ColouredCase) -> Result<ColouredRow, ExperimentError> {
    let config = config(p, case)?;
    let run = |series: &[f64]| -> Result<ChannelTrace, ExperimentError> {
        run_channel_with(
            config.clone(),
            &HashMap::new(),
            PolicyConfig::Classic,
            p.p_fa,
            &epochs(series),
        )
    };
    let (mut main, mut channel, mut steps, mut windows) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut step_size = Vec::new();
    let span = (p.epochs + 1000) as f64;
    let (mut busy, mut stepped) = (0.0, 0usize);
    for draw in 0..p.seeds.max(1) {
        let seed = p.seed + draw as u64;
        let off = draw as f64 * span;
        let clean = run(&signal(p, case.phi, seed, |_| 0.0))?;
        busy += clean.busy_s;
        stepped += clean.epochs;
        // The healthy residual's RMS: what "4σ" means for this draw.
        let residuals = clean_residual_rms(&clean);
        let size = p.step_sigmas * residuals;
        step_size.push(size);
        let at = onsets(p);
        let faulty = run(&signal(p, case.phi, seed, |k| {
            if at.iter().any(|&a| (a..a + STEP_LEN).contains(&k)) {
                size
            } else {
                0.0
            }
        }))?;
        main.push((off, clean.main_health()));
        channel.push((off, clean.channel.clone()));
        steps.push((off, faulty.main_health()));
        windows.extend(at.iter().map(|&a| FaultWindow {
            start: a as f64 + off,
            end: (a + STEP_LEN) as f64 + off,
        }));
    }
    let per_epoch = Some(busy / stepped.max(1) as f64);
    let card = |trace: &[(f64, Vec<(f64, Health)>)], w: &[FaultWindow]| {
        scorecard::score(CHANNEL, case.label, &pool(trace), w, per_epoch).with_p_fa(p.p_fa)
    };
    Ok(ColouredRow {
        case: *case,
        main: card(&main, &[]),
        channel: card(&channel, &[]),
        steps: card(&steps, &windows),
        step_size,
    })
}

/// RMS of the residual over the run's tested epochs (fault-free): the σ a step is
/// measured in.
pub fn clean_residual_rms(trace: &ChannelTrace) -> f64 {
    let r = &trace.residuals;
    let n = r.len().max(1) as f64;
    (r.iter().map(|v| v * v).sum::<f64>() / n).sqrt()
}

/// Runs every case.
pub fn run(params: ColouredParams) -> Result<ColouredResult, ExperimentError> {
    let rows = cases(&params)
        .iter()
        .map(|c| run_case(&params, c))
        .collect::<Result<_, _>>()?;
    Ok(ColouredResult { params, rows })
}

fn times(v: Option<f64>) -> String {
    v.map_or_else(|| "—".to_owned(), |v| format!("{v:.2}×"))
}

/// The text report.
pub fn render(r: &ColouredResult) -> String {
    let p = &r.params;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Coloured residuals — online LS-SVM (window 40, γ 30, σ² 9, embedding 5) on a slow two-tone signal, \
         AR(1) noise σ {} φ {} (or white), Gauss–Markov wander σ {} τ {} s; {} epochs × {} seeds ({}…{}); \
         T_a windows 1 and {}, classic, p_fa {}\n",
        p.noise_sigma,
        p.phi,
        p.wander_sigma,
        p.wander_tau,
        p.epochs,
        p.seeds.max(1),
        p.seed,
        p.seed + p.seeds.max(1) as u64 - 1,
        p.n,
        p.p_fa
    );
    let _ = writeln!(
        s,
        "{:<14} {:>10} {:>10} {:>11} {:>10} {:>12} {:>14} {:>14}",
        "case",
        "main FAR",
        "FAR/p_fa",
        "channel FA",
        "alarms/h",
        "step σ_r×4",
        "step detected",
        "delay mean/max"
    );
    for row in &r.rows {
        let size = row.step_size.iter().sum::<f64>() / row.step_size.len().max(1) as f64;
        let _ = writeln!(
            s,
            "{:<14} {:>10} {:>10} {:>11} {:>10} {:>12.3} {:>14} {:>14}",
            row.case.label,
            row.main
                .false_alarm_rate
                .map_or_else(|| "—".to_owned(), |v| format!("{:.3} %", 100.0 * v)),
            times(row.main.far_over_p_fa()),
            times(row.channel.far_over_p_fa()),
            row.main
                .alarms_per_hour()
                .map_or_else(|| "—".to_owned(), |v| format!("{v:.2}")),
            size,
            format!("{}/{}", row.steps.detected, row.steps.faults),
            format!(
                "{}/{}",
                row.steps
                    .mean_delay_s
                    .map_or_else(|| "—".to_owned(), |v| format!("{v:.2}")),
                row.steps
                    .max_delay_s
                    .map_or_else(|| "—".to_owned(), |v| format!("{v:.0}"))
            ),
        );
    }
    let _ = writeln!(
        s,
        "\n(main FAR: the main test's non-healthy share of fault-free epochs after warm-up; channel FA: any test of the channel, \
         main or stuck; steps of {} residual σ over {STEP_LEN} epochs at {} onsets per run, delay in epochs)\n",
        p.step_sigmas, p.steps
    );
    let _ = writeln!(s, "Scorecards (docs/methods.md §M19), fault-free runs:");
    let cards: Vec<Scorecard> = r.rows.iter().map(|row| row.main.clone()).collect();
    s.push_str(&scorecard::render(&cards));
    s
}
