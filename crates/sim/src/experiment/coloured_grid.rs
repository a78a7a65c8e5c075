//! The coloured-residual grid (`experiment coloured --grid`): the signal of
//! [`super::coloured`] over AR(1) coefficients, signal forms, predictors and residual
//! scales, each cell scored against the channel targets: fault-free false alarms within
//! 3 × p_fa, a 4σ step flagged within 3 epochs, a 0.05 σ/epoch ramp within 60 epochs.
//!
//! Per cell and draw, three runs of the same noise: fault-free (false-alarm rate and
//! bursts, docs/methods.md §M19), with steps (as the default cases add them) and with
//! ramps, σ being the fault-free residual's RMS of that draw and cell. The batch
//! predictor is a stored `lssvm` model trained on a separate fault-free draw of the same
//! process (as seed 000 trains its models); the online predictor is the default cases'.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::sync::Arc;

use serde_json::json;

use super::ExperimentError;
use super::coloured::{self, CHANNEL, ColouredParams, Form, STEP_LEN};
use super::scorecard::{self, Scorecard};
use super::seed000::{ChannelTrace, run_channel_with, scalar_channel};
use navguard_core::detect::{Health, PolicyConfig};
use navguard_core::learn::online::OnlineParams;
use navguard_core::learn::{AnyModel, Dataset, LearnError, ModelKind, ModelParams};
use navguard_core::learn::{NoProgress, train};
use navguard_core::monitor::channel::{
    ChannelConfigWire, ModelIds, PredictorWire, ResidualScale, Toggle, embed_series,
};

/// Each ramp lasts this many epochs (the target asks for a flag within 60).
pub const RAMP_LEN: usize = 100;

/// Epochs between ramp onsets (the predictor has 200 epochs to recover).
const RAMP_SPACING: usize = 300;

/// The id of the stored batch model in the monitor's model map.
const BATCH_ID: &str = "batch";

/// The signal forms of the grid, in table order.
pub const FORMS: [(&str, Form); 4] = [
    ("tones+wander", Form::TONES_WANDER),
    (
        "tones",
        Form {
            tones: true,
            wander: false,
        },
    ),
    (
        "wander",
        Form {
            tones: false,
            wander: true,
        },
    ),
    (
        "noise",
        Form {
            tones: false,
            wander: false,
        },
    ),
];

/// Where the channel's predictions come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GridPredictor {
    /// The online LS-SVM of the default cases (window 40, γ 30, σ² 9 raw).
    Online,
    /// A stored batch LS-SVM (γ 30, σ² 9 raw, not standardised) trained on a separate
    /// fault-free draw of `train_epochs` epochs.
    Batch,
}

impl GridPredictor {
    fn label(self) -> &'static str {
        match self {
            GridPredictor::Online => "online",
            GridPredictor::Batch => "batch",
        }
    }
}

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct GridParams {
    /// Signal, test and step settings (its `phi` is replaced by each of `phis`).
    pub base: ColouredParams,
    /// AR(1) coefficients.
    pub phis: Vec<f64>,
    /// Signal forms (from [`FORMS`]).
    pub forms: Vec<(&'static str, Form)>,
    /// Predictors.
    pub predictors: Vec<GridPredictor>,
    /// Residual scales.
    pub scales: Vec<ResidualScale>,
    /// Ramp slope, residual σ per epoch.
    pub ramp_sigmas_per_epoch: f64,
    /// Ramp onsets per run (from the middle, [`RAMP_SPACING`] epochs apart).
    pub ramps: usize,
    /// Length of the batch model's training draw, epochs.
    pub train_epochs: usize,
    /// Worker threads over the cells.
    pub threads: usize,
    /// Run the channel's drift test (§M14, windows 30 and 60) beside T_a and score the
    /// channel's health (the worst of its tests) instead of the main test's.
    pub drift: bool,
}

impl Default for GridParams {
    fn default() -> Self {
        GridParams {
            base: ColouredParams::default(),
            phis: vec![0.5, 0.7, 0.9, 0.95],
            forms: FORMS.to_vec(),
            predictors: vec![GridPredictor::Online, GridPredictor::Batch],
            scales: vec![ResidualScale::Raw, ResidualScale::Predictive],
            ramp_sigmas_per_epoch: 0.05,
            ramps: 10,
            train_epochs: 500,
            threads: 2,
            drift: false,
        }
    }
}

/// One cell of the grid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridCell {
    /// AR(1) coefficient.
    pub phi: f64,
    /// Signal form label and parts.
    pub form: (&'static str, Form),
    /// Predictor.
    pub predictor: GridPredictor,
    /// Residual scale.
    pub scale: ResidualScale,
}

/// Every cell, φ-major, then form, predictor and scale.
pub fn cells(p: &GridParams) -> Vec<GridCell> {
    let mut out = Vec::new();
    for &phi in &p.phis {
        for &form in &p.forms {
            for &predictor in &p.predictors {
                for &scale in &p.scales {
                    out.push(GridCell {
                        phi,
                        form,
                        predictor,
                        scale,
                    });
                }
            }
        }
    }
    out
}

/// One cell's figures over every draw.
#[derive(Debug, Clone, PartialEq)]
pub struct GridRow {
    /// The cell.
    pub cell: GridCell,
    /// Scorecard of the main test on the fault-free runs, draws pooled.
    pub clear: Scorecard,
    /// Per step, epochs from onset to the main test's first flag inside it (`None`: missed).
    pub step_delays: Vec<Option<usize>>,
    /// Per ramp, epochs from onset to the first flag inside it (`None`: missed).
    pub ramp_delays: Vec<Option<usize>>,
    /// σ per draw: the fault-free residual's RMS.
    pub sigma: Vec<f64>,
}

/// Share of `delays` at most `within` epochs (`None` without faults).
pub fn share_within(delays: &[Option<usize>], within: usize) -> Option<f64> {
    let hit = delays.iter().flatten().filter(|&&d| d <= within).count();
    (!delays.is_empty()).then(|| hit as f64 / delays.len() as f64)
}

/// Mean of the detected delays (`None` when none was detected).
pub fn mean_delay(delays: &[Option<usize>]) -> Option<f64> {
    let d: Vec<usize> = delays.iter().flatten().copied().collect();
    (!d.is_empty()).then(|| d.iter().sum::<usize>() as f64 / d.len() as f64)
}

impl GridRow {
    /// Whether the cell meets the three targets: FAR ≤ 3 × p_fa, every step within 3
    /// epochs, every ramp within 60.
    pub fn meets(&self) -> [bool; 3] {
        [
            self.clear.far_over_p_fa().is_some_and(|v| v <= 3.0),
            share_within(&self.step_delays, 3) == Some(1.0),
            share_within(&self.ramp_delays, 60) == Some(1.0),
        ]
    }
}

/// Everything the grid measured.
#[derive(Debug, Clone, PartialEq)]
pub struct GridResult {
    /// The parameters.
    pub params: GridParams,
    /// One row per cell, in [`cells`] order.
    pub rows: Vec<GridRow>,
}

/// Onsets that fit in a run of `epochs`: `count` from the middle, `spacing` apart, each
/// followed by `len` fault epochs.
pub fn fault_onsets(epochs: usize, count: usize, spacing: usize, len: usize) -> Vec<usize> {
    (0..count)
        .map(|i| epochs / 2 + spacing * i)
        .filter(|&a| a + len <= epochs)
        .collect()
}

/// Per onset, epochs from the onset to the first non-healthy epoch of `health` inside
/// `[onset, onset + len)` (`None`: none).
pub fn first_flags(health: &[(f64, Health)], onsets: &[usize], len: usize) -> Vec<Option<usize>> {
    onsets
        .iter()
        .map(|&a| {
            let (start, end) = (a as f64, (a + len) as f64);
            health
                .iter()
                .find(|&&(t, h)| t >= start && t < end && h != Health::Healthy)
                .map(|&(t, _)| (t - start) as usize)
        })
        .collect()
}

/// The channel of `cell`: the default cases' settings with the cell's predictor and scale,
/// and with `drift` the drift test on.
pub fn cell_config(
    p: &ColouredParams,
    cell: &GridCell,
    drift: bool,
) -> Result<ChannelConfigWire, LearnError> {
    let predictor = match cell.predictor {
        GridPredictor::Online => PredictorWire::Online(
            serde_json::from_value::<OnlineParams>(
                json!({"window": 40, "gamma": 30.0, "sigma2": 9.0}),
            )
            .map_err(|e| LearnError::params("online", e.to_string()))?,
        ),
        GridPredictor::Batch => PredictorWire::Model(ModelIds::One(BATCH_ID.to_owned())),
    };
    let mut channel = scalar_channel(CHANNEL, 5, p.n, predictor);
    channel.residual_scale = Some(cell.scale);
    channel.stuck = Some(Toggle::On(true));
    if drift {
        channel.drift = Some(Toggle::On(true));
    }
    Ok(ChannelConfigWire {
        channels: vec![channel],
    })
}

/// The models a cell's monitor needs for draw `seed`: for the batch predictor, an
/// `lssvm` trained on a fault-free draw of `train_epochs` epochs with its own seed.
pub fn cell_models(
    p: &GridParams,
    cell: &GridCell,
    seed: u64,
) -> Result<HashMap<String, Arc<AnyModel>>, ExperimentError> {
    if cell.predictor != GridPredictor::Batch {
        return Ok(HashMap::new());
    }
    let draw = ColouredParams {
        epochs: p.train_epochs,
        ..p.base.clone()
    };
    let series = coloured::signal_with(&draw, cell.phi, cell.form.1, seed ^ 0x7EA1_0000, |_| 0.0);
    let (x, y) = embed_series(&series, 5);
    let data = Dataset::new(&x, Some(&y))?;
    let params = ModelParams::from_json(
        ModelKind::LsSvm,
        &json!({"gamma": 30.0, "sigma2": 9.0, "standardize": false}),
    )?;
    let model = train(&params, None, &data, &NoProgress)?.model;
    Ok(HashMap::from([(BATCH_ID.to_owned(), Arc::new(model))]))
}

/// One draw of a cell: the fault-free trace, then the step and ramp delays.
struct Draw {
    clear: ChannelTrace,
    steps: Vec<Option<usize>>,
    ramps: Vec<Option<usize>>,
    sigma: f64,
}

/// The health a run is scored on: the main test's, or with the drift test on the
/// channel's.
fn scored(p: &GridParams, trace: &ChannelTrace) -> Vec<(f64, Health)> {
    if p.drift {
        trace.channel.clone()
    } else {
        trace.main_health()
    }
}

fn run_draw(p: &GridParams, cell: &GridCell, seed: u64) -> Result<Draw, ExperimentError> {
    let b = &p.base;
    let config = cell_config(b, cell, p.drift)?;
    let models = cell_models(p, cell, seed)?;
    let run = |fault: &dyn Fn(usize) -> f64| {
        let series = coloured::signal_with(b, cell.phi, cell.form.1, seed, fault);
        let epochs = coloured::epochs(&series);
        run_channel_with(
            config.clone(),
            &models,
            PolicyConfig::Classic,
            b.p_fa,
            &epochs,
        )
    };
    let clear = run(&|_| 0.0)?;
    let sigma = coloured::clean_residual_rms(&clear);
    let steps = fault_onsets(b.epochs, b.steps, 200, STEP_LEN);
    let size = b.step_sigmas * sigma;
    let stepped = run(&|k| {
        let on = steps.iter().any(|&a| (a..a + STEP_LEN).contains(&k));
        if on { size } else { 0.0 }
    })?;
    let ramps = fault_onsets(b.epochs, p.ramps, RAMP_SPACING, RAMP_LEN);
    let slope = p.ramp_sigmas_per_epoch * sigma;
    let ramped = run(&|k| {
        ramps
            .iter()
            .find(|&&a| (a..a + RAMP_LEN).contains(&k))
            .map_or(0.0, |&a| slope * (k - a + 1) as f64)
    })?;
    Ok(Draw {
        steps: first_flags(&scored(p, &stepped), &steps, STEP_LEN),
        ramps: first_flags(&scored(p, &ramped), &ramps, RAMP_LEN),
        clear,
        sigma,
    })
}

/// Runs one cell over every draw.
pub fn run_cell(p: &GridParams, cell: &GridCell) -> Result<GridRow, ExperimentError> {
    let b = &p.base;
    let span = (b.epochs + 1000) as f64;
    let (mut pooled, mut busy, mut stepped) = (Vec::new(), 0.0, 0usize);
    let (mut step_delays, mut ramp_delays, mut sigma) = (Vec::new(), Vec::new(), Vec::new());
    for draw in 0..b.seeds.max(1) {
        let d = run_draw(p, cell, b.seed + draw as u64)?;
        // Draws laid end to end, as the default cases pool them.
        let off = draw as f64 * span;
        pooled.extend(scored(p, &d.clear).into_iter().map(|(t, h)| (t + off, h)));
        busy += d.clear.busy_s;
        stepped += d.clear.epochs;
        step_delays.extend(d.steps);
        ramp_delays.extend(d.ramps);
        sigma.push(d.sigma);
    }
    let per_epoch = Some(busy / stepped.max(1) as f64);
    Ok(GridRow {
        cell: *cell,
        clear: scorecard::score(CHANNEL, &label(cell), &pooled, &[], per_epoch).with_p_fa(b.p_fa),
        step_delays,
        ramp_delays,
        sigma,
    })
}

fn label(cell: &GridCell) -> String {
    let scale = match cell.scale {
        ResidualScale::Raw => "raw",
        ResidualScale::Predictive => "pred",
    };
    format!(
        "φ{} {} {} {scale}",
        cell.phi,
        cell.form.0,
        cell.predictor.label()
    )
}

/// Runs every cell, the cells split over `p.threads` (at most 8) scoped worker threads;
/// the first failure (or a panicked worker) fails the whole.
pub fn run(params: GridParams) -> Result<GridResult, ExperimentError> {
    let all = cells(&params);
    let threads = params.threads.clamp(1, 8);
    let chunk = all.len().div_ceil(threads).max(1);
    type Rows = Result<Vec<GridRow>, ExperimentError>;
    let p = &params;
    let parts: Vec<Option<Rows>> = std::thread::scope(|s| {
        let handles: Vec<_> = all
            .chunks(chunk)
            .map(|cells| s.spawn(move || cells.iter().map(|c| run_cell(p, c)).collect::<Rows>()))
            .collect();
        handles.into_iter().map(|h| h.join().ok()).collect()
    });
    let mut rows = Vec::with_capacity(all.len());
    for part in parts {
        let part =
            part.unwrap_or_else(|| Err(LearnError::Numerical("worker panicked".into()).into()));
        rows.extend(part?);
    }
    Ok(GridResult { params, rows })
}

fn pct(v: Option<f64>) -> String {
    v.map_or_else(|| "—".to_owned(), |v| format!("{:.0} %", 100.0 * v))
}

fn num(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "—".to_owned(), |v| format!("{v:.digits$}"))
}

/// The text report: one line per cell and a count of the cells meeting each target.
pub fn render(r: &GridResult) -> String {
    let (p, b) = (&r.params, &r.params.base);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Coloured grid — AR(1) σ {} over φ {:?}, tones (3 sin 2πk/173 + 1.5 sin(2πk/61 + 0.4)), wander (σ {} τ {} s); \
         online LS-SVM (window 40) or batch LS-SVM (trained on a {}-epoch fault-free draw), both γ 30, σ² 9 raw, embedding 5; \
         {} epochs × {} seeds ({}…{}); T_a windows 1 and {}, classic, p_fa {}; {} steps of {} σ × {STEP_LEN} epochs, \
         {} ramps of {} σ/epoch × {RAMP_LEN} epochs per run (σ = fault-free residual RMS of the draw)\n",
        b.noise_sigma,
        p.phis,
        b.wander_sigma,
        b.wander_tau,
        p.train_epochs,
        b.epochs,
        b.seeds.max(1),
        b.seed,
        b.seed + b.seeds.max(1) as u64 - 1,
        b.n,
        b.p_fa,
        b.steps,
        b.step_sigmas,
        p.ramps,
        p.ramp_sigmas_per_epoch,
    );
    let _ = writeln!(
        s,
        "{:<5} {:<13} {:<7} {:<5} {:>9} {:>11} {:>8} {:>9} {:>10} {:>8} {:>6}",
        "φ",
        "signal",
        "pred.",
        "scale",
        "FAR/p_fa",
        "burst m/p99",
        "step ≤3",
        "ramp ≤60",
        "ramp delay",
        "σ_r",
        "meets"
    );
    let mut met = [0usize; 3];
    for row in &r.rows {
        let m = row.meets();
        for (c, ok) in met.iter_mut().zip(m) {
            *c += usize::from(ok);
        }
        let c = &row.cell;
        let sigma = row.sigma.iter().sum::<f64>() / row.sigma.len().max(1) as f64;
        let _ = writeln!(
            s,
            "{:<5} {:<13} {:<7} {:<5} {:>9} {:>11} {:>8} {:>9} {:>10} {:>8.3} {:>6}",
            c.phi,
            c.form.0,
            c.predictor.label(),
            if c.scale == ResidualScale::Raw {
                "raw"
            } else {
                "pred"
            },
            num(row.clear.far_over_p_fa(), 2),
            format!(
                "{}/{}",
                num(row.clear.burst_mean(), 2),
                row.clear
                    .burst_p99()
                    .map_or("—".to_owned(), |v| v.to_string())
            ),
            pct(share_within(&row.step_delays, 3)),
            pct(share_within(&row.ramp_delays, 60)),
            num(mean_delay(&row.ramp_delays), 1),
            sigma,
            m.iter()
                .map(|&ok| if ok { '✓' } else { '✗' })
                .collect::<String>(),
        );
    }
    let _ = writeln!(
        s,
        "\n(meets: FAR ≤ 3 × p_fa, every step flagged within 3 epochs, every ramp within 60; \
         ramp delay: mean over ramps flagged within their {RAMP_LEN} epochs)\n\
         cells meeting FAR {} / step {} / ramp {} of {}",
        met[0],
        met[1],
        met[2],
        r.rows.len()
    );
    s
}

#[cfg(test)]
mod tests;
