//! `navguard experiment raim`: the `gnss` monitor on real receiver data (docs/experiments.md,
//! "RAIM on real data"), fault-free and with injected pseudorange faults, every fault-
//! exclusion method side by side. Each run goes through the session core, so alarms are
//! counted by the server's rule.
//!
//! Per data set: a fault-free run gives the σ scale the data needs
//! (`k = sqrt(Σ WSSR / Σ dof)`, the scale that makes the mean statistic its dof; what
//! `navguard calibrate` proposes), then every figure is measured under that scale:
//! - fault-free: false alarms of the `raim` test against `p_fa`, alarms per hour,
//!   exclusions (all wrong), availability (HPL ≤ HAL), HPE ≤ HPL, HPE percentiles;
//! - faulted (seeded draws of a satellite, or two, and a start epoch): steps and ramps
//!   on the pseudoranges from the start to the end of a window; detection, correct and
//!   wrong exclusions, misleading information (HPE > HPL and the `raim` test silent),
//!   hazardously misleading information (HPE > HAL while available), and for ramps the
//!   time until the satellite is out of the fix and whether its error passed the HPL
//!   before.
//!
//! The data sets arrive as epochs (the CLI reads the files with `navguard-formats`):
//! no I/O here.

mod inject;
mod render;
mod stanford;

use std::collections::BTreeMap;

use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::epoch::{Epoch, SatId};
use navguard_core::gnss::araim::AraimParams;
use navguard_core::monitor::{self, MonitorConfig, MonitorKind, MonitorSpec, Outputs};
use navguard_core::session::{AlarmLevel, Seat, SessionCore};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

pub use inject::{Fault, FaultKind};
pub use render::render;
pub use stanford::stanford_svg;

use super::ExperimentError;

/// One real data set.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// Short name for the tables (`geonet`, `gnsslogger`, …).
    pub name: String,
    /// Its epochs, in time order, each with a `gnss_raw` block and its truth.
    pub epochs: Vec<Epoch>,
    /// The σ model of the monitor's `config.sigma` for this data (`{"model": "given"}`
    /// for phones, `{"model": "elevation"}` for a geodetic receiver), before the scale.
    pub sigma: serde_json::Value,
}

/// The method name of solution separation under a threat model with pairs of satellite
/// faults monitored: `araim.p_sat` raised to [`PAIRS_P_SAT`], at which two simultaneous
/// faults among the 7–9 satellites of the geodetic receiver are more probable than
/// `P_THRES`, so ARAIM enumerates pairs as fault modes (in its protection levels and
/// as exclusion candidates).
pub const PAIRS: &str = "ss_pairs";

/// `araim.p_sat` of [`PAIRS`] (the ADD's default is 1e-5).
pub const PAIRS_P_SAT: f64 = 1e-4;

/// What to run.
#[derive(Debug, Clone)]
pub struct RaimParams {
    /// First seed; the draws of a case use seed, seed + 1, …
    pub seed: u64,
    /// Draws per fault case and method.
    pub draws: usize,
    /// Epochs per faulted draw (fewer where the data set is shorter).
    pub window: usize,
    /// False-alarm probability of the `raim` test.
    pub p_fa: f64,
    /// Horizontal alert limit, m.
    pub hal_m: f64,
    /// The fault cases.
    pub faults: Vec<Fault>,
    /// The exclusion methods compared: `rtklib`, `greedy`, `solution_separation` (the
    /// monitor's `fde.method`, default threat model) and [`PAIRS`].
    pub methods: Vec<&'static str>,
}

impl Default for RaimParams {
    fn default() -> Self {
        RaimParams {
            seed: 1,
            draws: 100,
            window: 20,
            p_fa: 1e-3,
            hal_m: 40.0,
            faults: Fault::standard_cases(),
            methods: vec!["rtklib", "greedy", "solution_separation", PAIRS],
        }
    }
}

/// One epoch's outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct EpochOutcome {
    /// The `raim` test exceeded its threshold.
    pub detected: bool,
    /// Satellites excluded by FDE this epoch.
    pub excluded: Vec<String>,
    /// Satellites used in the final fix.
    pub used: Vec<String>,
    /// Horizontal error and protection level, m (`None` without a fix).
    pub hpe_hpl: Option<(f64, f64)>,
    /// Integrity available.
    pub available: bool,
}

/// The figures of one fault-free run.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultFree {
    /// Epochs with a fix.
    pub epochs: usize,
    /// Epochs whose `raim` test exceeded.
    pub exceedances: usize,
    /// Satellite exclusions (every one is wrong on fault-free data).
    pub exclusions: usize,
    /// Alarm-log entries of the `raim` test (the server's rule, default alarm level).
    pub alarms: usize,
    /// Hours of data.
    pub hours: f64,
    /// Epochs with HPL ≤ HAL.
    pub available: usize,
    /// Epochs with HPE ≤ HPL.
    pub bounded: usize,
    /// HPE: mean, 95th percentile, max, m.
    pub hpe: [f64; 3],
    /// `(HPE, HPL)` of every epoch, for the Stanford diagram.
    pub points: Vec<(f64, f64)>,
}

/// The figures of one fault case under one method.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Faulted {
    /// Draws run.
    pub draws: usize,
    /// Draws skipped: the fault-free fix at the start used fewer than 6 satellites.
    pub skipped: usize,
    /// Draws detected on the fault's first epoch.
    pub detected_first: usize,
    /// Draws whose faulty satellites were all excluded on the first epoch.
    pub excluded_first: usize,
    /// Draws detected at some epoch.
    pub detected_any: usize,
    /// Faulted epochs with a fix.
    pub epochs: usize,
    /// Faulted epochs on which every faulty satellite was out of the fix.
    pub correct_out: usize,
    /// Exclusions of a satellite without a fault.
    pub wrong_exclusions: usize,
    /// Faulted epochs with HPE > HPL while the `raim` test was silent.
    pub mi: usize,
    /// Faulted epochs with HPE > HAL while available.
    pub hmi: usize,
    /// Ramps: seconds from the start until the faulty satellite is out, per draw that
    /// got it out.
    pub time_to_exclude_s: Vec<f64>,
    /// Ramps: draws whose HPE passed the HPL before the satellite was out.
    pub passed_hpl_before_out: usize,
    /// `(HPE, HPL)` of every faulted epoch.
    pub points: Vec<(f64, f64)>,
}

/// Everything measured on one data set.
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetResult {
    /// Its name.
    pub name: String,
    /// Epochs, and satellites per epoch (min, max).
    pub epochs: usize,
    /// Satellites per epoch, min and max.
    pub sats: (usize, usize),
    /// The σ scale the fault-free data need.
    pub sigma_scale: f64,
    /// Fault-free figures under the unit scale and under the data's scale.
    pub fault_free_unit: FaultFree,
    /// Fault-free figures under the data's scale, per method.
    pub fault_free: BTreeMap<&'static str, FaultFree>,
    /// Per fault case label, per method.
    pub faulted: BTreeMap<String, BTreeMap<&'static str, Faulted>>,
}

/// The whole experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct RaimResult {
    /// What ran.
    pub p_fa: f64,
    /// Alert limit, m.
    pub hal_m: f64,
    /// Draws per case.
    pub draws: usize,
    /// Per data set.
    pub datasets: Vec<DatasetResult>,
}

/// The monitor spec for `method` at σ scale `scale`.
fn spec(
    d: &Dataset,
    p: &RaimParams,
    method: &str,
    scale: f64,
) -> Result<MonitorSpec, ExperimentError> {
    let mut sigma = d.sigma.clone();
    sigma["scale"] = scale.into();
    let (fde, p_sat) = if method == PAIRS {
        ("solution_separation", PAIRS_P_SAT)
    } else {
        (method, AraimParams::default().p_sat)
    };
    let config = serde_json::json!({
        "elevation_mask_deg": 10.0,
        "sigma": sigma,
        "fde": {"method": fde, "max_exclusions": 2},
        "protection": "araim",
        "hal_m": p.hal_m,
        "araim": {"p_sat": p_sat},
    });
    Ok(MonitorSpec {
        kind: MonitorKind::Gnss,
        config: MonitorConfig::parse(MonitorKind::Gnss, &config)
            .map_err(|e| ExperimentError::Build(e.into()))?,
        policy: PolicyConfig::Classic,
        threshold: ThresholdSpec::PFa(p.p_fa),
    })
}

/// One run through the session core.
struct Run {
    /// Each epoch's outcome.
    outcomes: Vec<EpochOutcome>,
    /// Alarm-log entries written.
    alarms: usize,
    /// Σ WSSR and Σ dof of the `raim` test.
    sums: (f64, f64),
}

/// Runs `epochs` through a fresh monitor of `spec` in a session core.
fn run_epochs(spec: &MonitorSpec, epochs: &[Epoch]) -> Result<Run, ExperimentError> {
    let seat = Seat {
        name: "gnss".into(),
        monitor: monitor::build(spec, &monitor::NoModels)?,
        alarm_level: AlarmLevel::default(),
    };
    let mut core = SessionCore::new("raim", vec![seat], 0);
    let (mut out, mut alarms, mut sums) = (Vec::with_capacity(epochs.len()), 0, (0.0, 0.0));
    let mut effects = Vec::new();
    for e in epochs {
        let (reports, failure) = core.step(e);
        if let Some((_, source)) = failure {
            return Err(ExperimentError::Step { t: e.t, source });
        }
        let Some(report) = reports.first().and_then(Option::as_ref) else {
            return Err(ExperimentError::NoSolution(e.t));
        };
        let Outputs::Gnss(o) = &report.outputs else {
            return Err(ExperimentError::NoSolution(e.t));
        };
        let test = report.tests.first();
        if let Some(t) = test {
            sums.0 += t.statistic.value;
            sums.1 += f64::from(t.statistic.dof);
        }
        out.push(EpochOutcome {
            detected: test.is_some_and(|t| t.statistic.exceeds()),
            excluded: o.excluded.clone(),
            used: o
                .satellites
                .iter()
                .filter(|s| s.used)
                .map(|s| s.id.clone())
                .collect(),
            hpe_hpl: o.hpe.zip(o.hpl),
            available: report
                .integrity
                .is_some_and(|i| i.state == monitor::Availability::Available),
        });
        core.commit(e, &reports, &mut effects);
        alarms += effects.drain(..).filter(|x| x.entry().is_some()).count();
    }
    Ok(Run {
        outcomes: out,
        alarms,
        sums,
    })
}

/// Mean, 95th percentile and max of `v` (zeros when empty).
fn percentiles(mut v: Vec<f64>) -> [f64; 3] {
    if v.is_empty() {
        return [0.0; 3];
    }
    v.sort_by(f64::total_cmp);
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    let p95 = v[((v.len() as f64 * 0.95).ceil() as usize).clamp(1, v.len()) - 1];
    [mean, p95, v[v.len() - 1]]
}

fn fault_free(outcomes: &[EpochOutcome], alarms: usize, hours: f64) -> FaultFree {
    let fixed: Vec<&EpochOutcome> = outcomes.iter().filter(|o| o.hpe_hpl.is_some()).collect();
    let points: Vec<(f64, f64)> = fixed.iter().filter_map(|o| o.hpe_hpl).collect();
    FaultFree {
        epochs: fixed.len(),
        exceedances: outcomes.iter().filter(|o| o.detected).count(),
        exclusions: outcomes.iter().map(|o| o.excluded.len()).sum(),
        alarms,
        hours,
        available: fixed.iter().filter(|o| o.available).count(),
        bounded: points.iter().filter(|(e, l)| e <= l).count(),
        hpe: percentiles(points.iter().map(|p| p.0).collect()),
        points,
    }
}

/// Runs the experiment on `datasets`.
pub fn run(datasets: &[Dataset], p: &RaimParams) -> Result<RaimResult, ExperimentError> {
    let mut results = Vec::with_capacity(datasets.len());
    for d in datasets {
        results.push(run_dataset(d, p)?);
    }
    Ok(RaimResult {
        p_fa: p.p_fa,
        hal_m: p.hal_m,
        draws: p.draws,
        datasets: results,
    })
}

fn run_dataset(d: &Dataset, p: &RaimParams) -> Result<DatasetResult, ExperimentError> {
    let counts: Vec<usize> = d
        .epochs
        .iter()
        .map(|e| e.gnss_raw.as_ref().map_or(0, |b| b.sats.len()))
        .collect();
    let span = d
        .epochs
        .last()
        .zip(d.epochs.first())
        .map_or(0.0, |(b, a)| b.t - a.t);
    let step = if d.epochs.len() > 1 {
        span / (d.epochs.len() - 1) as f64
    } else {
        1.0
    };
    let hours = (span + step) / 3600.0;
    let unit = run_epochs(&spec(d, p, "greedy", 1.0)?, &d.epochs)?;
    let sums = unit.sums;
    let scale = if sums.1 > 0.0 {
        (sums.0 / sums.1).sqrt().max(1.0)
    } else {
        1.0
    };
    let mut fault_free_by = BTreeMap::new();
    let mut faulted = BTreeMap::new();
    for &method in &p.methods {
        let s = spec(d, p, method, scale)?;
        let run = run_epochs(&s, &d.epochs)?;
        fault_free_by.insert(method, fault_free(&run.outcomes, run.alarms, hours));
        for (case, fault) in p.faults.iter().enumerate() {
            let seed = p.seed + 1000 * case as u64;
            let f = run_faulted(d, &s, fault, p, seed, step, &run.outcomes)?;
            faulted
                .entry(fault.label())
                .or_insert_with(BTreeMap::new)
                .insert(method, f);
        }
    }
    Ok(DatasetResult {
        name: d.name.clone(),
        epochs: d.epochs.len(),
        sats: (
            counts.iter().copied().min().unwrap_or(0),
            counts.iter().copied().max().unwrap_or(0),
        ),
        sigma_scale: scale,
        fault_free_unit: fault_free(&unit.outcomes, unit.alarms, hours),
        fault_free: fault_free_by,
        faulted,
    })
}

/// The draws of one fault case under one spec: each picks a start epoch and the faulty
/// satellites among those the fault-free fix used there (`clean`; seeded), runs one
/// clean epoch before the start when there is one, and the window from the start with
/// the fault. A start whose fault-free fix used fewer than 6 satellites is skipped
/// (counted): with 5 a fault can be detected but not told apart.
fn run_faulted(
    d: &Dataset,
    s: &MonitorSpec,
    fault: &Fault,
    p: &RaimParams,
    seed: u64,
    step_s: f64,
    clean: &[EpochOutcome],
) -> Result<Faulted, ExperimentError> {
    let mut f = Faulted::default();
    let mut rng = StdRng::seed_from_u64(seed);
    let n = d.epochs.len();
    for _ in 0..p.draws {
        f.draws += 1;
        let start = rng.random_range(0..n);
        let end = (start + p.window).min(n);
        let in_view: Vec<SatId> = clean[start]
            .used
            .iter()
            .filter_map(|id| SatId::parse(id).ok())
            .collect();
        if in_view.len() < 6 {
            f.skipped += 1;
            continue;
        }
        let mut sats = Vec::new();
        while sats.len() < fault.satellites {
            let id = in_view[rng.random_range(0..in_view.len())];
            if !sats.contains(&id) {
                sats.push(id);
            }
        }
        let lead = start.saturating_sub(1);
        let epochs = inject::apply(&d.epochs[lead..end], fault, &sats, d.epochs[start].t);
        let run = run_epochs(s, &epochs)?;
        score_draw(
            &mut f,
            &run.outcomes[start - lead..],
            &sats,
            fault,
            p.hal_m,
            step_s,
        );
    }
    Ok(f)
}

/// Adds one draw's faulted epochs to the case's figures.
fn score_draw(
    f: &mut Faulted,
    out: &[EpochOutcome],
    sats: &[SatId],
    fault: &Fault,
    hal_m: f64,
    step_s: f64,
) {
    let ids: Vec<String> = sats.iter().map(SatId::to_string).collect();
    let out_of_fix = |o: &EpochOutcome| ids.iter().all(|id| !o.used.contains(id));
    if let Some(first) = out.first() {
        f.detected_first += usize::from(first.detected);
        f.excluded_first += usize::from(ids.iter().all(|id| first.excluded.contains(id)));
    }
    f.detected_any += usize::from(out.iter().any(|o| o.detected));
    let mut passed = false;
    let mut time_out = None;
    for (k, o) in out.iter().enumerate() {
        f.wrong_exclusions += o.excluded.iter().filter(|x| !ids.contains(x)).count();
        let Some((hpe, hpl)) = o.hpe_hpl else {
            continue;
        };
        f.epochs += 1;
        f.points.push((hpe, hpl));
        let out_now = out_of_fix(o);
        f.correct_out += usize::from(out_now);
        f.mi += usize::from(hpe > hpl && !o.detected);
        f.hmi += usize::from(hpe > hal_m && o.available);
        if out_now && time_out.is_none() {
            time_out = Some(k as f64 * step_s);
        }
        if time_out.is_none() && hpe > hpl {
            passed = true;
        }
    }
    if matches!(fault.kind, FaultKind::Ramp(_)) {
        f.time_to_exclude_s.extend(time_out);
        f.passed_hpl_before_out += usize::from(passed);
    }
}
