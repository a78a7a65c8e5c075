//! RINEX observation + navigation → domain epochs: picks the code, computes each
//! satellite's position and clock at transmit time from the broadcast ephemeris
//! ([`crate::ephemeris`]) and, for a single-frequency code, Klobuchar's delay at the
//! header's approximate position.
//!
//! Codes: single frequency uses L1 C/A, with T_GD applied and the Klobuchar delay in
//! `iono`. Iono-free uses `PR_IF = (f1²·L1 − f2²·L2)/(f1² − f2²)` with T_GD not
//! applied and `iono` absent. Each satellite takes the first of these codes that it
//! has a value for (a code in the header but blank for a satellite falls through):
//!
//! | role | RINEX 2 | RINEX 3 |
//! |---|---|---|
//! | single frequency | C1, P1 | C1C, C1W, C1P |
//! | iono-free L1 | C1, P1 | C1W, C1P, C1C |
//! | iono-free L2 | P2, C2 | C2W, C2P |
//!
//! RINEX 3 prefers the P(Y) code C1W for the iono-free pair, since the broadcast clock
//! refers to P1/P2; where C1C stands in (and always in RINEX 2, as before), the C1/P1
//! bias (decimetres) stays in the combination. L2C (C2L, C2S, C2X) and L5 are not
//! used: their inter-signal corrections are not in the RINEX 2 ephemeris we keep.
//! `tropo` is left to the monitor's model; `sigma` to its σ model.

use navguard_core::epoch::{Epoch, GnssRawBlock, SatObs};

use super::nav::NavFile;
use super::obs::{ObsEpoch, ObsFile};
use crate::ephemeris::ClockFor;
use crate::error::FormatError;
use crate::geometry::Station;

/// GPS L1 frequency, Hz.
pub const F_L1: f64 = 1_575.42e6;
/// GPS L2 frequency, Hz.
pub const F_L2: f64 = 1_227.60e6;

/// Single-frequency L1 codes, in order of preference (RINEX 2, then RINEX 3 names;
/// a file has only one kind).
pub const SINGLE_L1: [&str; 5] = ["C1", "P1", "C1C", "C1W", "C1P"];
/// Iono-free L1 codes, in order of preference.
pub const IF_L1: [&str; 5] = ["C1", "P1", "C1W", "C1P", "C1C"];
/// Iono-free L2 codes, in order of preference.
pub const IF_L2: [&str; 4] = ["P2", "C2", "C2W", "C2P"];

/// How to turn a RINEX pair into epochs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RinexParams {
    /// Use the iono-free L1/L2 combination (satellites without both are dropped).
    pub iono_free: bool,
    /// Put the header's `APPROX POSITION XYZ` in every epoch's `truth`.
    pub truth_approx_position: bool,
}

/// Epochs and what was left out.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Conversion {
    /// One epoch per receiver epoch with at least one satellite.
    pub epochs: Vec<Epoch>,
    /// Satellite observations dropped: no usable code or no healthy ephemeris in ±2 h.
    pub dropped: usize,
}

/// Converts a parsed observation file with its navigation file.
pub fn convert(
    obs: &ObsFile,
    nav: &NavFile,
    file: &str,
    p: RinexParams,
) -> Result<Conversion, FormatError> {
    let station = obs.approx_position.map(Station::from_ecef);
    if p.truth_approx_position && station.is_none() {
        return Err(crate::error::missing(
            file,
            "no APPROX POSITION XYZ for the truth",
        ));
    }
    if !p.iono_free && (station.is_none() || nav.klobuchar.is_none()) {
        return Err(crate::error::missing(
            file,
            "single-frequency conversion needs APPROX POSITION XYZ and the nav header's ION ALPHA/BETA (or use the iono-free option)",
        ));
    }
    // The header's columns of the codes of one role, in order of preference.
    let cols = |names: &[&str]| -> Vec<usize> {
        names
            .iter()
            .filter_map(|n| obs.types.iter().position(|t| t == n))
            .collect()
    };
    let c1 = if p.iono_free {
        cols(&IF_L1)
    } else {
        cols(&SINGLE_L1)
    };
    if c1.is_empty() {
        return Err(crate::error::missing(
            file,
            "no L1 code observations (C1 or P1; RINEX 3: C1C, C1W or C1P)",
        ));
    }
    let p2 = cols(&IF_L2);
    if p.iono_free && p2.is_empty() {
        return Err(crate::error::missing(
            file,
            "iono-free needs L2 P-code observations (P2 or C2; RINEX 3: C2W or C2P)",
        ));
    }
    let mut out = Conversion::default();
    for e in &obs.epochs {
        let sats = epoch_sats(e, nav, station, &c1, &p2, p, &mut out.dropped);
        if sats.is_empty() {
            continue;
        }
        let truth = if p.truth_approx_position {
            station.map(|s| s.as_truth())
        } else {
            None
        };
        out.epochs.push(Epoch {
            t: e.t,
            gnss_raw: Some(GnssRawBlock { sats, truth }),
            ..Epoch::default()
        });
    }
    Ok(out)
}

/// The satellites of one epoch that have a code and an ephemeris.
fn epoch_sats(
    e: &ObsEpoch,
    nav: &NavFile,
    station: Option<Station>,
    c1: &[usize],
    p2: &[usize],
    p: RinexParams,
    dropped: &mut usize,
) -> Vec<SatObs> {
    // The first of the columns `c` with a nonzero value.
    let code = |v: &[Option<super::obs::ObsValue>], c: &[usize]| {
        c.iter().find_map(|&i| {
            v.get(i)
                .copied()
                .flatten()
                .map(|o| o.value)
                .filter(|x| *x != 0.0)
        })
    };
    let mut sats = Vec::with_capacity(e.sats.len());
    for (id, values) in &e.sats {
        let pr = match (p.iono_free, code(values, c1), code(values, p2)) {
            (false, Some(c1), _) => Some(c1),
            (true, Some(c1), Some(p2)) => {
                let (a, b) = (F_L1 * F_L1, F_L2 * F_L2);
                Some((a * c1 - b * p2) / (a - b))
            }
            _ => None,
        };
        let (Some(pr), Some(eph)) = (pr, nav.ephemerides.select(*id, e.t)) else {
            *dropped += 1;
            continue;
        };
        let for_signal = if p.iono_free {
            ClockFor::IonoFree
        } else {
            ClockFor::L1
        };
        let s = eph.at_reception(e.t, pr, for_signal);
        let look = station.map(|st| st.look_angles(s.pos));
        let iono = match (p.iono_free, station, look, nav.klobuchar) {
            (false, Some(st), Some((el, az)), Some(k)) => {
                Some(k.delay_m(st.lla.lat, st.lla.lon, el, az, s.t_tx))
            }
            _ => None,
        };
        sats.push(SatObs {
            id: *id,
            pr,
            pos: s.pos,
            clk: s.clk_m,
            iono,
            tropo: None,
            sigma: None,
            cn0: None,
            el: look.map(|l| l.0),
            az: look.map(|l| l.1),
        });
    }
    sats
}
