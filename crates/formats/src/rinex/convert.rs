//! RINEX observation + navigation → domain epochs: picks the code, computes each
//! satellite's position and clock at transmit time from the broadcast ephemeris
//! ([`crate::ephemeris`]) or precise SP3 orbits ([`crate::sp3`], through
//! [`OrbitSource`]) and, for a single-frequency code, Klobuchar's delay at the header's
//! approximate position.
//!
//! Codes: single frequency uses L1 C/A (Galileo E1), with T_GD (BGD) applied and the
//! Klobuchar delay in `iono` (E1 shares L1's frequency; Galileo's NeQuick-G is not
//! computed). Iono-free uses `PR_IF = (f1²·P1 − f2²·P2)/(f1² − f2²)` with no group delay
//! and `iono` absent: GPS L1/L2 (f1 = 1575.42, f2 = 1227.60 MHz), Galileo E1/E5a (f1 =
//! 1575.42, f2 = 1176.45 MHz). Each satellite takes the first of these codes that it has
//! a value for (a code in the header but blank for a satellite falls through):
//!
//! | role | RINEX 2 | RINEX 3 GPS | RINEX 3 Galileo |
//! |---|---|---|---|
//! | single frequency | C1, P1 | C1C, C1W, C1P | C1C, C1X |
//! | iono-free 1 | C1, P1 | C1W, C1P, C1C | C1C, C1X |
//! | iono-free 2 | P2, C2 | C2W, C2P | C5Q, C5X, C5I |
//!
//! RINEX 3 prefers the P(Y) code C1W for the GPS iono-free pair, since the broadcast
//! clock refers to P1/P2; where C1C stands in (and always in RINEX 2, as before), the
//! C1/P1 bias (decimetres) stays in the combination. L2C (C2L, C2S, C2X) and L5 are not
//! used: their inter-signal corrections are not in the RINEX 2 ephemeris we keep.
//! Galileo's E1/E5a clock is the F/NAV one, or the I/NAV one moved across by its two
//! BGDs ([`crate::ephemeris`]). `tropo` is left to the monitor's model; `sigma` to its
//! σ model.

use navguard_core::epoch::{Constellation, Epoch, GnssRawBlock, SatObs};

use super::nav::NavFile;
use super::obs::{ObsEpoch, ObsFile, ObsValue};
use crate::ephemeris::ClockFor;
use crate::error::FormatError;
use crate::geometry::Station;
use crate::klobuchar::Klobuchar;
use crate::orbits::OrbitSource;

/// GPS L1 frequency, Hz.
pub const F_L1: f64 = 1_575.42e6;
/// GPS L2 frequency, Hz.
pub const F_L2: f64 = 1_227.60e6;
/// Galileo E5a frequency, Hz (E1 is [`F_L1`]).
pub const F_E5A: f64 = 1_176.45e6;

/// Single-frequency L1 codes, in order of preference (RINEX 2, then RINEX 3 names;
/// a file has only one kind).
pub const SINGLE_L1: [&str; 5] = ["C1", "P1", "C1C", "C1W", "C1P"];
/// Iono-free L1 codes, in order of preference.
pub const IF_L1: [&str; 5] = ["C1", "P1", "C1W", "C1P", "C1C"];
/// Iono-free L2 codes, in order of preference.
pub const IF_L2: [&str; 4] = ["P2", "C2", "C2W", "C2P"];
/// Galileo E1 codes (single frequency and iono-free), in order of preference.
pub const GAL_E1: [&str; 2] = ["C1C", "C1X"];
/// Galileo E5a codes for the iono-free pair, in order of preference.
pub const GAL_E5A: [&str; 3] = ["C5Q", "C5X", "C5I"];

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
    /// Satellite observations dropped: no usable code, or no state (no healthy
    /// ephemeris in ±2 h; with SP3, outside its data).
    pub dropped: usize,
}

/// The header columns of one constellation's codes and their frequencies.
struct Codes {
    /// Single-frequency or first iono-free code columns, in order of preference.
    c1: Vec<usize>,
    /// Second iono-free code columns, in order of preference.
    c2: Vec<usize>,
    /// The two frequencies, Hz.
    f1: f64,
    f2: f64,
}

impl Codes {
    fn of(obs: &ObsFile, c: Constellation, iono_free: bool) -> Codes {
        let types = obs.types_of(c);
        let cols = |names: &[&str]| -> Vec<usize> {
            names
                .iter()
                .filter_map(|n| types.iter().position(|t| t == n))
                .collect()
        };
        match c {
            Constellation::Galileo => Codes {
                c1: cols(&GAL_E1),
                c2: cols(&GAL_E5A),
                f1: F_L1,
                f2: F_E5A,
            },
            _ => Codes {
                c1: cols(if iono_free { &IF_L1 } else { &SINGLE_L1 }),
                c2: cols(&IF_L2),
                f1: F_L1,
                f2: F_L2,
            },
        }
    }

    /// Whether the header has what the conversion needs.
    fn usable(&self, iono_free: bool) -> bool {
        !self.c1.is_empty() && (!iono_free || !self.c2.is_empty())
    }

    /// The pseudorange of one satellite's values: its first nonzero code of each role,
    /// alone or combined.
    fn pseudorange(&self, v: &[Option<ObsValue>], iono_free: bool) -> Option<f64> {
        let code = |c: &[usize]| {
            c.iter().find_map(|&i| {
                v.get(i)
                    .copied()
                    .flatten()
                    .map(|o| o.value)
                    .filter(|x| *x != 0.0)
            })
        };
        if !iono_free {
            return code(&self.c1);
        }
        let (p1, p2) = (code(&self.c1)?, code(&self.c2)?);
        let (a, b) = (self.f1 * self.f1, self.f2 * self.f2);
        Some((a * p1 - b * p2) / (a - b))
    }
}

/// Converts a parsed observation file with its navigation file (broadcast orbits).
pub fn convert(
    obs: &ObsFile,
    nav: &NavFile,
    file: &str,
    p: RinexParams,
) -> Result<Conversion, FormatError> {
    let orbits = OrbitSource::Broadcast(&nav.ephemerides);
    convert_with(obs, orbits, nav.klobuchar, file, p)
}

/// Converts a parsed observation file with satellite states from `orbits` and, for
/// single frequency, the navigation header's Klobuchar coefficients.
pub fn convert_with(
    obs: &ObsFile,
    orbits: OrbitSource<'_>,
    klobuchar: Option<Klobuchar>,
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
    if !p.iono_free && (station.is_none() || klobuchar.is_none()) {
        return Err(crate::error::missing(
            file,
            "single-frequency conversion needs APPROX POSITION XYZ and the nav header's ION ALPHA/BETA (or use the iono-free option)",
        ));
    }
    let gps = Codes::of(obs, Constellation::Gps, p.iono_free);
    let gal = Codes::of(obs, Constellation::Galileo, p.iono_free);
    if gps.c1.is_empty() && gal.c1.is_empty() {
        return Err(crate::error::missing(
            file,
            "no L1 code observations (C1 or P1; RINEX 3: C1C, C1W or C1P; Galileo C1C or C1X)",
        ));
    }
    if p.iono_free && !gps.usable(true) && !gal.usable(true) {
        return Err(crate::error::missing(
            file,
            "iono-free needs L2 P-code observations (P2 or C2; RINEX 3: C2W or C2P) or Galileo E5a (C5Q, C5X or C5I)",
        ));
    }
    let ctx = Context {
        orbits,
        klobuchar,
        station,
        gps,
        gal,
        p,
    };
    let mut out = Conversion::default();
    for e in &obs.epochs {
        let sats = ctx.epoch_sats(e, &mut out.dropped);
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

/// What every epoch's conversion uses.
struct Context<'a> {
    orbits: OrbitSource<'a>,
    klobuchar: Option<Klobuchar>,
    station: Option<Station>,
    gps: Codes,
    gal: Codes,
    p: RinexParams,
}

impl Context<'_> {
    /// The satellites of one epoch that have a code and a state.
    fn epoch_sats(&self, e: &ObsEpoch, dropped: &mut usize) -> Vec<SatObs> {
        let for_signal = if self.p.iono_free {
            ClockFor::IonoFree
        } else {
            ClockFor::L1
        };
        let mut sats = Vec::with_capacity(e.sats.len());
        for (id, values) in &e.sats {
            let codes = match id.constellation {
                Constellation::Galileo => &self.gal,
                _ => &self.gps,
            };
            let pr = codes.pseudorange(values, self.p.iono_free);
            let state = pr.and_then(|pr| self.orbits.at_reception(*id, e.t, pr, for_signal));
            let (Some(pr), Some(s)) = (pr, state) else {
                *dropped += 1;
                continue;
            };
            let look = self.station.map(|st| st.look_angles(s.pos));
            let iono = match (self.p.iono_free, self.station, look, self.klobuchar) {
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
}
