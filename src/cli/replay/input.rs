//! The replayed file: a first pass that counts its epochs and notes which blocks
//! occur (for the summary's progress and a new session's monitor), then the epochs
//! one at a time as the stream sends them. One epoch per line, each an object with
//! a numeric `t`; blank lines are skipped.

use std::io::BufRead;
use std::path::Path;

use anyhow::{Context, bail};
use serde::Deserialize;
use serde::de::IgnoredAny;
use tokio::io::AsyncBufReadExt;

/// What a first pass over the file found.
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct FileScan {
    /// Epoch lines.
    pub epochs: u64,
    /// `t` of the first epoch.
    pub first_t: f64,
    /// `t` of the last epoch.
    pub last_t: f64,
    /// Some epoch has an `ins` block.
    pub ins: bool,
    /// Some epoch has a `gnss` block.
    pub gnss: bool,
    /// Some epoch has a `dvl` block.
    pub dvl: bool,
    /// Some epoch has a `cns` block.
    pub cns: bool,
    /// Some epoch has `z`.
    pub z: bool,
    /// Some epoch has a `gnss_raw` block (pseudoranges).
    pub gnss_raw: bool,
    /// Some epoch has an `imu` block (raw IMU).
    pub imu: bool,
}

#[derive(Debug, Deserialize)]
struct Peek {
    t: f64,
    #[serde(default)]
    ins: Option<IgnoredAny>,
    #[serde(default)]
    gnss: Option<IgnoredAny>,
    #[serde(default)]
    dvl: Option<IgnoredAny>,
    #[serde(default)]
    cns: Option<IgnoredAny>,
    #[serde(default)]
    z: Option<IgnoredAny>,
    #[serde(default)]
    gnss_raw: Option<IgnoredAny>,
    #[serde(default)]
    imu: Option<IgnoredAny>,
}

fn peek(line: &str, number: usize) -> anyhow::Result<Peek> {
    serde_json::from_str(line).with_context(|| {
        format!("line {number}: not an epoch object with a numeric `t` (one epoch per line)")
    })
}

/// Reads the file once: epoch count, time span, which blocks occur.
pub(super) fn scan(path: &Path) -> anyhow::Result<FileScan> {
    let file = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut out = FileScan::default();
    for (i, line) in std::io::BufReader::new(file).lines().enumerate() {
        let line = line.with_context(|| format!("reading {}", path.display()))?;
        if line.trim().is_empty() {
            continue;
        }
        let p = peek(&line, i + 1)?;
        if out.epochs == 0 {
            out.first_t = p.t;
        }
        out.last_t = p.t;
        out.epochs += 1;
        out.ins |= p.ins.is_some();
        out.gnss |= p.gnss.is_some();
        out.dvl |= p.dvl.is_some();
        out.cns |= p.cns.is_some();
        out.z |= p.z.is_some();
        out.gnss_raw |= p.gnss_raw.is_some();
        out.imu |= p.imu.is_some();
    }
    if out.epochs == 0 {
        bail!("{} holds no epochs", path.display());
    }
    Ok(out)
}

/// The file's epoch lines as the stream reads them, with their line numbers for
/// the error a bad line gets.
pub(super) struct EpochLines {
    lines: tokio::io::Lines<tokio::io::BufReader<tokio::fs::File>>,
    number: usize,
}

impl EpochLines {
    /// Opens the file at its first line.
    pub(super) async fn open(path: &Path) -> anyhow::Result<Self> {
        let file = tokio::fs::File::open(path)
            .await
            .with_context(|| format!("opening {}", path.display()))?;
        Ok(Self {
            lines: tokio::io::BufReader::new(file).lines(),
            number: 0,
        })
    }

    /// The next epoch's `t` and line; `None` at the end of the file.
    pub(super) async fn next(&mut self) -> anyhow::Result<Option<(f64, String)>> {
        loop {
            self.number += 1;
            let Some(line) = self.lines.next_line().await? else {
                return Ok(None);
            };
            if line.trim().is_empty() {
                continue;
            }
            let t = peek(&line, self.number)?.t;
            return Ok(Some((t, line)));
        }
    }
}
