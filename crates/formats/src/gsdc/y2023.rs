//! GSDC 2023 `device_gnss.csv` (one signal per row) and its `ground_truth.csv`.
//!
//! Rows with an empty `SignalType` carry no position or pseudorange and are skipped.
//! `pr = RawPseudorangeMeters − IsrbMeters`, `clk = SvClockBiasMeters`,
//! `iono = IonosphericDelayMeters`, `tropo = TroposphericDelayMeters`,
//! σ = `RawPseudorangeUncertaintyMeters`, `Cn0DbHz`, `SvElevationDegrees`,
//! `SvAzimuthDegrees`. The epoch is `utcTimeMillis` (UTC); GPST − UTC is read from the
//! file itself, as the whole seconds between `ArrivalTimeNanosSinceGpsEpoch` and
//! `utcTimeMillis` (18 s in 2023).

use std::path::Path;

use navguard_core::epoch::{Epoch, SatObs};

use super::{Band, Columns, SatColumns, Truths, android_sat, push_sat, read_csv, read_truths};
use crate::error::{FormatError, missing};
use crate::gpstime::unix_ms_utc_to_gps;

/// Seconds from the Unix epoch to the GPS epoch.
const GPS_EPOCH_UNIX_S: f64 = 315_964_800.0;

/// Reads `ground_truth.csv`: `UnixTimeMillis` → lat, lon (rad), `AltitudeMeters`.
pub fn read_truth(path: &Path) -> Result<Truths, FormatError> {
    read_truths(
        path,
        [
            "UnixTimeMillis",
            "LatitudeDegrees",
            "LongitudeDegrees",
            "AltitudeMeters",
        ],
        0.0,
    )
}

/// Reads `device_gnss.csv` into epochs, keeping `band`, with truths by `utcTimeMillis`.
pub fn read(path: &Path, band: Band, truth: Option<&Truths>) -> Result<Vec<Epoch>, FormatError> {
    let file = path.display().to_string();
    let (headers, rows) = read_csv(path)?;
    let c = Columns {
        file: &file,
        headers: &headers,
    };
    let i = |n: &str| c.idx(n);
    let (utc, sig, cons, svid) = (
        i("utcTimeMillis")?,
        i("SignalType")?,
        i("ConstellationType")?,
        i("Svid")?,
    );
    let cols = SatColumns {
        raw: i("RawPseudorangeMeters")?,
        unc: i("RawPseudorangeUncertaintyMeters")?,
        isrb: i("IsrbMeters")?,
        clk: i("SvClockBiasMeters")?,
        iono: i("IonosphericDelayMeters")?,
        tropo: i("TroposphericDelayMeters")?,
        pos: [
            i("SvPositionXEcefMeters")?,
            i("SvPositionYEcefMeters")?,
            i("SvPositionZEcefMeters")?,
        ],
    };
    let (el, az, cn0) = (
        i("SvElevationDegrees")?,
        i("SvAzimuthDegrees")?,
        i("Cn0DbHz")?,
    );
    let arrival = i("ArrivalTimeNanosSinceGpsEpoch")?;
    let mut leap: Option<f64> = None;
    let mut epochs: Vec<(i64, Epoch)> = Vec::new();
    for row in &rows {
        let signal = row.1.get(sig).map_or("", |s| s.trim());
        if signal.is_empty() || Band::of_signal(signal) != Some(band) {
            continue;
        }
        let Some(id) = android_sat(c.req(row, cons)? as i64, c.req(row, svid)? as i64) else {
            continue;
        };
        let ms = c.req(row, utc)? as i64;
        if leap.is_none() {
            let gps_s = c.req(row, arrival)? * 1e-9;
            leap = Some((gps_s - (ms as f64 / 1000.0 - GPS_EPOCH_UNIX_S)).round());
        }
        let t = unix_ms_utc_to_gps(ms, leap.unwrap_or(0.0));
        let truth = truth.and_then(|tr| tr.get(&ms).copied());
        let sat = SatObs {
            cn0: c.num(row, cn0)?,
            el: c.num(row, el)?.map(f64::to_radians),
            az: c.num(row, az)?.map(f64::to_radians),
            ..cols.obs(&c, row, id)?
        };
        push_sat(&mut epochs, ms, t, truth, sat);
    }
    if epochs.is_empty() {
        return Err(missing(&file, "no usable rows"));
    }
    Ok(epochs.into_iter().map(|(_, e)| e).collect())
}
