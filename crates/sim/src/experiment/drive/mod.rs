//! The federated monitor on a real car drive (docs/experiments.md, "The real car drive";
//! docs/methods.md §M30, §M31): the shared drive's 100 Hz MEMS IMU streamed raw into a
//! `federated` monitor with `input: imu` (the service's own strapdown mechanization,
//! alignment and closed loop), aided by GNSS derived from the drive's RTK solution —
//! decimated to 1 Hz, with single-point noise (seeded), 15 s outages — and measured
//! against the RTK solution itself:
//!
//! - fault-free, per seed: position and velocity errors outside outages, the error at the
//!   end of each outage, the attitude beside the GNSS course, alarms and warnings per hour
//!   as the session core logs them, and the integrity;
//! - with injected GNSS faults (a 10 m jump, 0.5–2 m/s ramps, a frozen receiver) at
//!   several start times and seeds: detection and exclusion delays, the injected error at
//!   exclusion, and the worst solution error while the fault lasts.
//!
//! The CLI reads the files (`navguard experiment drive`); this module takes the IMU
//! epochs and the reference as data, so tests can run it on a slice.

mod aid;
mod render;
mod run;

pub use crate::drive_config::{AidNoise, DRIVE_LEVER_ARM_M, DRIVE_MOUNTING_DEG, drive_config};
pub use aid::{AidPlan, FaultWindow, reference_at, with_aid};
pub use render::{FreeStats, SETTLE_S, free_stats, outage_growth, plots, render};
pub use run::{DriveRun, ErrSample, TestRow};

use nalgebra::Vector3;
use serde_json::Value;

use navguard_core::detect::{PolicyConfig, ThresholdSpec};
use navguard_core::epoch::Epoch;
use navguard_core::geo::Lla;
use navguard_core::monitor::{MonitorConfig, MonitorKind, MonitorSpec};
use navguard_core::session::Severity;

use super::ExperimentError;

/// One reference fix (the RTK solution at the antenna).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefFix {
    /// GPS seconds.
    pub t: f64,
    /// Position.
    pub lla: Lla,
    /// Velocity east, north, up, m/s.
    pub vel: Vector3<f64>,
}

/// An injected GNSS fault.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FaultKind {
    /// A position step east, m.
    Jump(f64),
    /// A position ramp east, m/s.
    Ramp(f64),
    /// The receiver repeats its last fix (position and velocity).
    Frozen,
}

impl FaultKind {
    /// The row label.
    pub fn label(&self) -> String {
        match self {
            FaultKind::Jump(m) => format!("{m} m jump"),
            FaultKind::Ramp(v) => format!("{v} m/s ramp"),
            FaultKind::Frozen => "frozen receiver".into(),
        }
    }
}

/// The drive's data: the IMU epochs (sensor frame, GPS time) and the RTK reference.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveData {
    /// One epoch per IMU sample, with `imu` only.
    pub imu: Vec<Epoch>,
    /// The reference fixes, in time order.
    pub reference: Vec<RefFix>,
}

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveParams {
    /// Noise seeds of the fault-free runs; the fault runs use the first two.
    pub seeds: Vec<u64>,
    /// The aid.
    pub noise: AidNoise,
    /// Outage starts, s from the drive's start.
    pub outages: Vec<f64>,
    /// Outage length, s.
    pub outage_s: f64,
    /// The faults injected.
    pub faults: Vec<FaultKind>,
    /// Fault starts, s from the drive's start.
    pub fault_starts: Vec<f64>,
    /// Fault length, s.
    pub fault_s: f64,
    /// The monitor's config (a `federated` config with `input: imu`).
    pub config: Value,
    /// False-alarm probability of every test.
    pub p_fa: f64,
}

impl Default for DriveParams {
    fn default() -> Self {
        let noise = AidNoise::default();
        DriveParams {
            seeds: vec![1, 2, 3],
            noise,
            outages: vec![150.0, 250.0, 350.0, 450.0],
            outage_s: 15.0,
            faults: vec![
                FaultKind::Jump(10.0),
                FaultKind::Ramp(0.5),
                FaultKind::Ramp(1.0),
                FaultKind::Ramp(2.0),
                FaultKind::Frozen,
            ],
            // 197 s: the car stands still (196.5–207 s), where a frozen receiver is right
            // until it moves again and only the stuck test can see it.
            fault_starts: vec![120.0, 197.0, 300.0, 420.0],
            fault_s: 60.0,
            config: drive_config(&noise),
            p_fa: 1e-3,
        }
    }
}

/// One fault-free run's figures.
#[derive(Debug, Clone, PartialEq)]
pub struct FreeRow {
    /// Noise seed.
    pub seed: u64,
    /// The run.
    pub run: DriveRun,
}

/// One faulted run's figures.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultRow {
    /// The fault.
    pub kind: FaultKind,
    /// Start, s from the drive's start.
    pub start: f64,
    /// Noise seed.
    pub seed: u64,
    /// Seconds from the start to the first fix a GNSS test finds unhealthy: from then on
    /// the fixes no longer update the filter (rejected) until the aid is healthy again.
    pub rejected_s: Option<f64>,
    /// Seconds to the aid's isolation (the alarm; left out of fusion).
    pub isolated_s: Option<f64>,
    /// Seconds to the `gnss.stuck` test's first unhealthy epoch.
    pub stuck_s: Option<f64>,
    /// The injected horizontal error at the first rejected fix, m.
    pub injected_at_rejection_m: Option<f64>,
    /// The injected horizontal error at the last fix before the isolation, m.
    pub injected_at_isolation_m: Option<f64>,
    /// Worst horizontal solution error while the fault lasts, m.
    pub worst_error_m: f64,
    /// Alarms logged while the fault lasts (any GNSS test).
    pub alarms: usize,
}

/// Everything the experiment measured.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveResult {
    /// The parameters.
    pub params: DriveParams,
    /// Fault-free runs, one per seed.
    pub free: Vec<FreeRow>,
    /// Faulted runs.
    pub faults: Vec<FaultRow>,
}

/// The monitor spec the drive runs: `params.config` under the counters policy at
/// `params.p_fa` (the CLI writes it for `navguard replay`).
pub fn monitor_spec(params: &DriveParams) -> Result<MonitorSpec, ExperimentError> {
    let config = MonitorConfig::parse(MonitorKind::Federated, &params.config)
        .map_err(|e| ExperimentError::Build(e.into()))?;
    Ok(MonitorSpec {
        kind: MonitorKind::Federated,
        config,
        policy: PolicyConfig::counters_default(),
        threshold: ThresholdSpec::PFa(params.p_fa),
    })
}

/// The antenna lever arm of `config`, body frame, m.
fn lever_arm(config: &Value) -> Vector3<f64> {
    let l = &config["strapdown"]["gnss_lever_arm_m"];
    Vector3::from_fn(|i, _| l[i].as_f64().unwrap_or(0.0))
}

/// How a run's epochs reach the monitor: as built, or (the CLI) through the ingest wire
/// format and back, exactly as `navguard replay` would stream them to a server.
pub type Prepare<'a> = &'a dyn Fn(Vec<Epoch>) -> Result<Vec<Epoch>, String>;

/// The epochs of the fault-free run of `seed` (outages as `params` says), prepared.
pub fn free_epochs(
    data: &DriveData,
    params: &DriveParams,
    seed: u64,
    prepare: Prepare<'_>,
) -> Result<Vec<Epoch>, ExperimentError> {
    let plan = AidPlan {
        noise: params.noise,
        outages: params.outages.clone(),
        outage_s: params.outage_s,
        fault: None,
        seed,
    };
    prepare(with_aid(&data.imu, &data.reference, &plan).0).map_err(ExperimentError::Prepare)
}

/// Runs the drive fault-free for every seed, then every fault at every start for the
/// first two seeds, each run's epochs through `prepare`; `progress` is called after each
/// run with (done, total).
pub fn run(
    data: &DriveData,
    params: &DriveParams,
    prepare: Prepare<'_>,
    mut progress: impl FnMut(usize, usize),
) -> Result<DriveResult, ExperimentError> {
    let spec = monitor_spec(params)?;
    let lever = lever_arm(&params.config);
    let fault_seeds: Vec<u64> = params.seeds.iter().copied().take(2).collect();
    let total =
        params.seeds.len() + params.faults.len() * params.fault_starts.len() * fault_seeds.len();
    let mut done = 0;
    let mut free = Vec::new();
    for &seed in &params.seeds {
        let epochs = free_epochs(data, params, seed, prepare)?;
        free.push(FreeRow {
            seed,
            run: run::run(&epochs, &data.reference, &spec, lever)?,
        });
        done += 1;
        progress(done, total);
    }
    let mut faults = Vec::new();
    for &kind in &params.faults {
        for &start in &params.fault_starts {
            for &seed in &fault_seeds {
                let case = (kind, start, seed);
                faults.push(fault_run(data, params, &spec, (lever, prepare), case)?);
                done += 1;
                progress(done, total);
            }
        }
    }
    Ok(DriveResult {
        params: params.clone(),
        free,
        faults,
    })
}

/// One faulted run (no outages) and its delays.
fn fault_run(
    data: &DriveData,
    params: &DriveParams,
    spec: &MonitorSpec,
    (lever, prepare): (Vector3<f64>, Prepare<'_>),
    (kind, start, seed): (FaultKind, f64, u64),
) -> Result<FaultRow, ExperimentError> {
    let window = FaultWindow {
        kind,
        start,
        duration: params.fault_s,
    };
    let plan = AidPlan {
        noise: params.noise,
        outages: Vec::new(),
        outage_s: params.outage_s,
        fault: Some(window),
        seed,
    };
    let (epochs, injected) = with_aid(&data.imu, &data.reference, &plan);
    let epochs = prepare(epochs).map_err(ExperimentError::Prepare)?;
    let r = run::run(&epochs, &data.reference, spec, lever)?;
    let end = start + params.fault_s;
    let t0 = data.imu.first().map_or(0.0, |e| e.t);
    let injected_at = |te: Option<f64>| {
        te.and_then(|te| {
            injected
                .iter()
                .rfind(|(i, _)| data.imu[*i].t - t0 <= te + 1e-6)
                .map(|(_, e)| e.xy().norm())
        })
    };
    let rejected = r.first_unhealthy(start, None).filter(|&t| t < end);
    let isolated = r.first_isolated(start).filter(|&t| t < end);
    let worst_error_m = r
        .errors
        .iter()
        .filter(|s| (start..end).contains(&s.t))
        .map(ErrSample::horizontal)
        .fold(0.0, f64::max);
    let alarms = r
        .entries
        .iter()
        .filter(|e| (start..end).contains(&e.t) && e.severity == Severity::Alarm)
        .count();
    let delay = |t: Option<f64>| t.filter(|&t| t < end).map(|t| t - start);
    Ok(FaultRow {
        kind,
        start,
        seed,
        rejected_s: rejected.map(|t| t - start),
        isolated_s: isolated.map(|t| t - start),
        stuck_s: delay(r.first_unhealthy(start, Some("gnss.stuck"))),
        injected_at_rejection_m: injected_at(rejected),
        injected_at_isolation_m: injected_at(isolated),
        worst_error_m,
        alarms,
    })
}
