//! GSDC 2021 `*_derived.csv` and its `*_ground_truth.csv`, with the competition
//! hosts' corrections (as gnss_lib_py's `AndroidDerived2021` applies them):
//! 1. each `millisSinceGpsEpoch` belongs to the previous distinct one in the file; the
//!    first epoch has none and is dropped;
//! 2. rows whose (mapped) `millisSinceGpsEpoch − receivedSvTimeInGpsNanos/1e6` is
//!    outside (0, 300) ms are dropped;
//! 3. the truth's `heightAboveWgs84EllipsoidM` is 61 m too high: 61 m are subtracted.
//!
//! `pr = rawPrM − isrbM`, `clk = satClkBiasM`, `iono = ionoDelayM`,
//! `tropo = tropoDelayM`, σ = `rawPrUncM`. Times are GPS already.

use std::path::Path;

use navguard_core::epoch::Epoch;

use super::{Band, Columns, SatColumns, Truths, android_sat, push_sat, read_csv, read_truths};
use crate::error::{FormatError, missing};

/// The published error of the 2021 truth heights, m (subtracted).
pub const TRUTH_HEIGHT_ERROR_M: f64 = 61.0;

/// Reads `*_ground_truth.csv`: `millisSinceGpsEpoch` → lat, lon (rad), height − 61 m.
pub fn read_truth(path: &Path) -> Result<Truths, FormatError> {
    read_truths(
        path,
        [
            "millisSinceGpsEpoch",
            "latDeg",
            "lngDeg",
            "heightAboveWgs84EllipsoidM",
        ],
        TRUTH_HEIGHT_ERROR_M,
    )
}

/// Reads a `*_derived.csv` into epochs, keeping `band`, with truths by the mapped time.
pub fn read(path: &Path, band: Band, truth: Option<&Truths>) -> Result<Vec<Epoch>, FormatError> {
    let file = path.display().to_string();
    let (headers, rows) = read_csv(path)?;
    let c = Columns {
        file: &file,
        headers: &headers,
    };
    let i = |n: &str| c.idx(n);
    let (ms_i, sig, cons, svid, rx) = (
        i("millisSinceGpsEpoch")?,
        i("signalType")?,
        i("constellationType")?,
        i("svid")?,
        i("receivedSvTimeInGpsNanos")?,
    );
    let cols = SatColumns {
        raw: i("rawPrM")?,
        unc: i("rawPrUncM")?,
        isrb: i("isrbM")?,
        clk: i("satClkBiasM")?,
        iono: i("ionoDelayM")?,
        tropo: i("tropoDelayM")?,
        pos: [i("xSatPosM")?, i("ySatPosM")?, i("zSatPosM")?],
    };
    // Quirk 1: the distinct times in file order, each mapped to the one before.
    let mut stamps: Vec<i64> = Vec::new();
    for row in &rows {
        let ms = c.req(row, ms_i)? as i64;
        if stamps.last() != Some(&ms) {
            stamps.push(ms);
        }
    }
    let mut epochs: Vec<(i64, Epoch)> = Vec::new();
    for row in &rows {
        let ms = c.req(row, ms_i)? as i64;
        let Some(k) = stamps.iter().position(|s| *s == ms).filter(|k| *k > 0) else {
            continue;
        };
        let mapped = stamps[k - 1];
        // Quirk 2: the signal's flight time must be in (0, 300) ms.
        let flight_ms = mapped as f64 - c.req(row, rx)? / 1e6;
        if !(flight_ms > 0.0 && flight_ms < 300.0) {
            continue;
        }
        let signal = row.1.get(sig).map_or("", |s| s.trim());
        if Band::of_signal(signal) != Some(band) {
            continue;
        }
        let Some(id) = android_sat(c.req(row, cons)? as i64, c.req(row, svid)? as i64) else {
            continue;
        };
        let t = mapped as f64 / 1000.0;
        let truth = truth.and_then(|tr| tr.get(&mapped).copied());
        push_sat(&mut epochs, mapped, t, truth, cols.obs(&c, row, id)?);
    }
    if epochs.is_empty() {
        return Err(missing(&file, "no usable rows after the 2021 corrections"));
    }
    Ok(epochs.into_iter().map(|(_, e)| e).collect())
}
