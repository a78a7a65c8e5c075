//! Criterion bench: one epoch of a `channel` monitor with one scalar channel (embedding 5,
//! batch-means T_a over windows 1 and 10, the stuck test, classic policy), the residual
//! raw and over its predictive σ (docs/performance.md, "The channel step"):
//!
//! - `channel_monitor/online_w60_{raw,predictive}`: an online LS-SVM, window 60, γ 30,
//!   σ² 9 (its update and, under `predictive`, its variance term);
//! - `channel_monitor/batch_n200_{raw,predictive}` and `batch_n500_…`: a stored batch
//!   LS-SVM (γ 30, σ² 9 raw) trained on a separate fault-free draw of 200 or 500 samples
//!   (seed 000's training flights give 195), whose variance term costs O(N²).
//!
//! The stream is `experiment coloured`'s signal (two tones, AR(1) φ 0.9, Gauss–Markov
//! wander; seed 1, 12,000 epochs, built before the bench); it restarts on a fresh
//! monitor at its end (not timed), so the warm-up is in the figure at its share.
//!
//! Run: `cargo bench --bench channel_step`
//!
//! Instruction counts (docs/performance.md): with `NAVGUARD_BENCH_STEPS=<case>:N` (a case
//! named as above without the group, e.g. `online_w60_raw:12000`) the binary skips
//! criterion and steps that case's monitor exactly `N` times over the same stream, so
//! callgrind's inclusive count of `<ChannelMonitor as Monitor>::step` divided by `N` is
//! repeatable.

// criterion_group! defines a public function it cannot document.
#![allow(missing_docs)]

use std::collections::HashMap;
use std::hint::black_box;
use std::sync::Arc;
use std::time::{Duration, Instant};

use criterion::{Criterion, Throughput, criterion_group};
use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::epoch::Epoch;
use navguard_core::learn::AnyModel;
use navguard_core::learn::online::OnlineParams;
use navguard_core::monitor::channel::{ChannelConfigWire, PredictorWire, ResidualScale, Toggle};
use navguard_core::monitor::{self, Monitor, MonitorConfig, MonitorKind, MonitorSpec};
use navguard_sim::experiment::coloured::{self, ColouredParams, Form};
use navguard_sim::experiment::coloured_grid::{self, GridCell, GridParams, GridPredictor};
use navguard_sim::experiment::seed000::scalar_channel;

const EPOCHS: usize = 12_000;

type Models = HashMap<String, Arc<AnyModel>>;

/// The grid's cell for `predictor` and `scale` on the default signal (φ 0.9, all parts).
fn cell(predictor: GridPredictor, scale: ResidualScale) -> GridCell {
    GridCell {
        phi: 0.9,
        form: coloured_grid::FORMS[0],
        predictor,
        scale,
    }
}

/// The online channel: window 60 (the grid's is 40).
fn online(scale: ResidualScale) -> ChannelConfigWire {
    let params = OnlineParams {
        window: 60,
        gamma: 30.0,
        sigma2: 9.0,
        refresh: 1000,
    };
    let mut channel = scalar_channel(
        coloured::CHANNEL,
        5,
        navguard_core::detect::ta::DEFAULT_N,
        PredictorWire::Online(params),
    );
    channel.residual_scale = Some(scale);
    channel.stuck = Some(Toggle::On(true));
    ChannelConfigWire {
        channels: vec![channel],
    }
}

/// A batch channel and its model, trained on a fault-free draw of `train` epochs.
fn batch(scale: ResidualScale, train: usize) -> (ChannelConfigWire, Models) {
    let grid = GridParams {
        train_epochs: train,
        ..GridParams::default()
    };
    let c = cell(GridPredictor::Batch, scale);
    let config = coloured_grid::cell_config(&grid.base, &c, false).expect("config");
    (
        config,
        coloured_grid::cell_models(&grid, &c, 1).expect("model"),
    )
}

fn spec(config: ChannelConfigWire) -> MonitorSpec {
    MonitorSpec {
        kind: MonitorKind::Channel,
        config: MonitorConfig::Channel(config),
        policy: PolicyConfig::Classic,
        threshold: ThresholdSpec::PFa(0.002),
    }
}

/// Times `iters` steps over `stream`, a fresh monitor (untimed) at each restart.
fn timed_steps(
    iters: u64,
    fresh: &dyn Fn() -> Box<dyn Monitor>,
    state: &mut (Box<dyn Monitor>, usize),
    stream: &[Epoch],
) -> Duration {
    let mut busy = Duration::ZERO;
    let mut left = iters as usize;
    while left > 0 {
        if state.1 == stream.len() {
            *state = (fresh(), 0);
        }
        let n = left.min(stream.len() - state.1);
        let started = Instant::now();
        for e in &stream[state.1..state.1 + n] {
            black_box(state.0.step(black_box(e)).expect("step"));
        }
        busy += started.elapsed();
        (state.1, left) = (state.1 + n, left - n);
    }
    busy
}

/// The stream: `experiment coloured`'s signal, seed 1.
fn stream() -> Vec<Epoch> {
    let p = ColouredParams {
        epochs: EPOCHS,
        ..ColouredParams::default()
    };
    coloured::epochs(&coloured::signal_with(
        &p,
        0.9,
        Form::TONES_WANDER,
        1,
        |_| 0.0,
    ))
}

/// Every benched case: name, channel config and models.
fn cases() -> Vec<(String, ChannelConfigWire, Models)> {
    let mut cases = Vec::new();
    for (name, scale) in [
        ("raw", ResidualScale::Raw),
        ("predictive", ResidualScale::Predictive),
    ] {
        cases.push((format!("online_w60_{name}"), online(scale), Models::new()));
        for n in [200, 500] {
            let (config, models) = batch(scale, n + 5);
            cases.push((format!("batch_n{n}_{name}"), config, models));
        }
    }
    cases
}

fn bench(c: &mut Criterion) {
    let stream = stream();
    let mut group = c.benchmark_group("channel_monitor");
    group.throughput(Throughput::Elements(1));
    group.measurement_time(Duration::from_secs(4));
    for (name, config, models) in &cases() {
        let spec = spec(config.clone());
        let fresh = || monitor::build(&spec, models).expect("monitor");
        let mut state = (fresh(), 0);
        group.bench_function(name.as_str(), |b| {
            b.iter_custom(|iters| timed_steps(iters, &fresh, &mut state, &stream))
        });
    }
    group.finish();
}

/// `NAVGUARD_BENCH_STEPS=<case>:N`: `N` steps of that case's monitor, nothing timed.
fn count_steps(spec_text: &str) {
    let parsed = spec_text
        .split_once(':')
        .and_then(|(name, n)| Some((name, n.parse::<u64>().ok()?)));
    let Some((name, n)) = parsed else {
        panic!("NAVGUARD_BENCH_STEPS is <case>:N, not {spec_text:?}");
    };
    let all = cases();
    let Some((_, config, models)) = all.iter().find(|(c, ..)| c == name) else {
        panic!("no case {name:?}");
    };
    let spec = spec(config.clone());
    let fresh = || monitor::build(&spec, models).expect("monitor");
    let mut state = (fresh(), 0);
    timed_steps(n, &fresh, &mut state, &stream());
}

criterion_group!(benches, bench);

/// `criterion_main!`, unless `NAVGUARD_BENCH_STEPS` asks for a fixed number of steps.
fn main() {
    if let Ok(spec) = std::env::var("NAVGUARD_BENCH_STEPS") {
        count_steps(&spec);
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
