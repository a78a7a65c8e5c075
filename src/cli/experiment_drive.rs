//! `navguard experiment drive`: reads the shared car drive (IMU CSV on GPS time through
//! its time tag, the RTK `.pos`) with the converter's readers and runs
//! [`navguard_sim::experiment::drive`] on it; prints its tables and writes its figures.

use std::path::{Path, PathBuf};

use anyhow::Context;
use nalgebra::Vector3;
use navguard::service::wire::{self, epoch_to_wire};
use navguard_core::epoch::Epoch;
use navguard_formats::rtklib_pos;
use navguard_sim::experiment::drive;

use super::convert_drive::{DriveArgs as ReadArgs, read_imu};
use super::experiment::Experiment;

/// `navguard experiment drive` flags.
#[derive(Debug, clap::Args)]
pub(crate) struct DriveArgs {
    /// The folder holding the drive (`imu_1934.csv`, its `.tag`, `gnss_1934_sf.pos`).
    #[arg(long, default_value = "tests/data/drive")]
    pub data: PathBuf,
    /// Noise seeds of the fault-free runs (the fault runs use the first two).
    #[arg(long, value_delimiter = ',', default_value = "1,2,3")]
    pub seeds: Vec<u64>,
    /// False-alarm probability of every test.
    #[arg(long, default_value_t = 1e-3)]
    pub p_fa: f64,
    /// Horizontal σ of the 1 Hz aid, m.
    #[arg(long, default_value_t = 1.5)]
    pub sigma_h: f64,
    /// A `federated` monitor config (JSON file) to run instead of the drive's own
    /// (`navguard_sim::drive_config::drive_config`).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Also write the fault-free run of the first seed for `navguard replay`: its epochs
    /// (`drive.jsonl`) and the session body (`drive-session.json`), into this folder.
    #[arg(long)]
    pub write_epochs: Option<PathBuf>,
    /// Directory for the figures.
    #[arg(long, default_value = "target/experiments/drive")]
    pub out_dir: PathBuf,
}

/// Epochs through the ingest wire format and back: what a server gets from `replay`.
fn through_the_wire(epochs: Vec<Epoch>) -> Result<Vec<Epoch>, String> {
    wire::through_the_wire(&epochs).map_err(|e| e.message)
}

/// Writes the fault-free run of `seed` and its session body into `dir`.
fn write_epochs(
    dir: &Path,
    data: &drive::DriveData,
    params: &drive::DriveParams,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let seed = params.seeds.first().copied().unwrap_or(1);
    // As built: the experiment reads them back through the wire once, as a server does.
    let epochs = drive::free_epochs(data, params, seed, &|e| Ok(e))?;
    let mut text = String::with_capacity(epochs.len() * 120);
    for e in &epochs {
        text.push_str(&epoch_to_wire(e).map_err(|e| anyhow::anyhow!(e.message))?);
        text.push('\n');
    }
    let path = dir.join("drive.jsonl");
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    let spec = drive::monitor_spec(params)?;
    let body = serde_json::json!({
        "id": "drive",
        "monitors": [{
            "name": "nav",
            "type": "federated",
            "config": params.config,
            "policy": spec.policy,
            "p_fa": params.p_fa,
        }],
    });
    let path = dir.join("drive-session.json");
    std::fs::write(&path, serde_json::to_string_pretty(&body)?)
        .with_context(|| format!("writing {}", path.display()))?;
    eprintln!(
        "wrote the fault-free run of seed {seed} and its session to {}",
        dir.display()
    );
    Ok(())
}

/// The drive's IMU epochs (the logger's 0.125 s latency removed) and its RTK reference.
pub(crate) fn read_drive(dir: &Path) -> anyhow::Result<drive::DriveData> {
    let read = ReadArgs {
        imu: Some(dir.join("imu_1934.csv")),
        tag: Some(dir.join("imu_1934.csv.tag")),
        imu_time_offset: -0.125,
        ..ReadArgs::default()
    };
    let imu = read_imu(&read)?;
    let pos = dir.join("gnss_1934_sf.pos");
    let fixes = rtklib_pos::read_pos(&pos).with_context(|| format!("reading {}", pos.display()))?;
    let reference = fixes
        .iter()
        .map(|f| drive::RefFix {
            t: f.t,
            lla: f.lla,
            vel: Vector3::from(f.vel.unwrap_or_default()),
        })
        .collect();
    Ok(drive::DriveData { imu, reference })
}

impl Experiment for DriveArgs {
    type Output = drive::DriveResult;
    const TITLE: &'static str = "drive";

    fn run(&self) -> anyhow::Result<Self::Output> {
        let data = read_drive(&self.data)?;
        let noise = drive::AidNoise {
            pos_sigma_h_m: self.sigma_h,
            ..drive::AidNoise::default()
        };
        let config = match &self.config {
            Some(path) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("reading {}", path.display()))?;
                serde_json::from_str(&text)
                    .with_context(|| format!("{} is not JSON", path.display()))?
            }
            None => drive::drive_config(&noise),
        };
        let params = drive::DriveParams {
            seeds: self.seeds.clone(),
            noise,
            config,
            p_fa: self.p_fa,
            ..drive::DriveParams::default()
        };
        if let Some(dir) = &self.write_epochs {
            write_epochs(dir, &data, &params)?;
        }
        let result = drive::run(&data, &params, &through_the_wire, |done, total| {
            eprint!("\rdrive: run {done}/{total}");
        })?;
        eprintln!();
        Ok(result)
    }

    fn render(output: &Self::Output) -> String {
        drive::render(output)
    }

    fn plots(output: &Self::Output) -> Vec<(String, String)> {
        drive::plots(output)
    }

    fn out_dir(&self) -> Option<&Path> {
        Some(&self.out_dir)
    }
}
