//! GNSS fixes, the common output of the solution readers ([`rtklib_pos`](crate::rtklib_pos),
//! [`nmea`](crate::nmea), [`kfgins`](crate::kfgins)), and the σ policy that turns one into
//! a domain [`GnssBlock`]: the receiver's reported σ, or a σ by solution quality.
//!
//! # σ by quality (1-σ; horizontal applies to east and north, vertical to up)
//!
//! | quality | position h / v, m | velocity h / v, m/s |
//! |---|---|---|
//! | RTK fixed | 0.02 / 0.04 | 0.05 / 0.10 |
//! | RTK float | 0.5 / 1.0 | 0.05 / 0.10 |
//! | PPP | 0.1 / 0.2 | 0.05 / 0.10 |
//! | SBAS, DGPS | 1.0 / 2.0 | 0.10 / 0.20 |
//! | single | 3.0 / 6.0 | 0.20 / 0.40 |
//!
//! Position levels are the usual orders of magnitude of each solution type (carrier-phase
//! centimetres, float decimetres to a metre, code-differential about a metre, stand-alone
//! a few metres), vertical twice horizontal; Doppler velocity depends little on the
//! position's quality. Reported σ are floored at [`SigmaPolicy::floor_pos_m`] (0.01 m)
//! and [`SigmaPolicy::floor_vel_mps`] (0.01 m/s): an RTK engine's 0.0098 m is
//! optimistic, and a monitor must not weight a fix as if it were exact.

use navguard_core::epoch::{Epoch, GnssBlock};
use navguard_core::geo::Lla;

/// A solution's quality, RTKLIB's Q flag (NMEA GGA fix qualities map onto it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Quality {
    /// RTK with integer ambiguities fixed (Q 1, GGA 4).
    Fixed,
    /// RTK with float ambiguities (Q 2, GGA 5).
    Float,
    /// SBAS-corrected (Q 3).
    Sbas,
    /// Code-differential (Q 4, GGA 2).
    Dgps,
    /// Stand-alone (Q 5, GGA 1 and 3).
    Single,
    /// Precise point positioning (Q 6).
    Ppp,
}

impl Quality {
    /// RTKLIB's Q flag → quality (`None` for 0 or an unknown flag).
    pub fn from_rtklib_q(q: u32) -> Option<Quality> {
        match q {
            1 => Some(Quality::Fixed),
            2 => Some(Quality::Float),
            3 => Some(Quality::Sbas),
            4 => Some(Quality::Dgps),
            5 => Some(Quality::Single),
            6 => Some(Quality::Ppp),
            _ => None,
        }
    }

    /// The RTKLIB Q flag of this quality.
    pub fn rtklib_q(self) -> u32 {
        self as u32 + 1
    }

    /// Position σ (horizontal, vertical), m, of the module's table.
    pub fn pos_sigma_hv(self) -> [f64; 2] {
        match self {
            Quality::Fixed => [0.02, 0.04],
            Quality::Float => [0.5, 1.0],
            Quality::Ppp => [0.1, 0.2],
            Quality::Sbas | Quality::Dgps => [1.0, 2.0],
            Quality::Single => [3.0, 6.0],
        }
    }

    /// Velocity σ (horizontal, vertical), m/s, of the module's table.
    pub fn vel_sigma_hv(self) -> [f64; 2] {
        match self {
            Quality::Fixed | Quality::Float | Quality::Ppp => [0.05, 0.10],
            Quality::Sbas | Quality::Dgps => [0.10, 0.20],
            Quality::Single => [0.20, 0.40],
        }
    }
}

/// One GNSS solution, as a solution file gives it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssFix {
    /// 1-based line of the file where the fix starts.
    pub line: usize,
    /// GPS seconds since 1980-01-06 (or seconds of week, when the file has no week).
    pub t: f64,
    /// Latitude, longitude (rad) and ellipsoidal height (m).
    pub lla: Lla,
    /// The solution's quality, when the file says it.
    pub quality: Option<Quality>,
    /// Satellites used, when the file says it.
    pub ns: Option<u32>,
    /// Reported position 1-σ east, north, up, m (a component ≤ 0 means not reported).
    pub pos_sigma: Option<[f64; 3]>,
    /// Velocity east, north, up, m/s.
    pub vel: Option<[f64; 3]>,
    /// Reported velocity 1-σ east, north, up, m/s.
    pub vel_sigma: Option<[f64; 3]>,
}

/// Where a fix's σ comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SigmaSource {
    /// The file's σ (floored); the quality table where the file has none.
    #[default]
    Reported,
    /// The quality table; the file's σ where the file has no quality.
    Quality,
}

/// How a fix's σ are set when it becomes a [`GnssBlock`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SigmaPolicy {
    /// Reported σ or σ by quality.
    pub source: SigmaSource,
    /// Smallest position σ written, m.
    pub floor_pos_m: f64,
    /// Smallest velocity σ written, m/s.
    pub floor_vel_mps: f64,
}

impl Default for SigmaPolicy {
    fn default() -> Self {
        SigmaPolicy {
            source: SigmaSource::Reported,
            floor_pos_m: 0.01,
            floor_vel_mps: 0.01,
        }
    }
}

/// `[h, h, v]`: a horizontal/vertical pair as east, north, up.
fn enu(hv: [f64; 2]) -> [f64; 3] {
    [hv[0], hv[0], hv[1]]
}

/// Chooses between the reported σ (each component floored; a component ≤ 0 or not
/// finite counts as not reported) and the table's, by the policy's source.
fn choose(
    source: SigmaSource,
    reported: Option<[f64; 3]>,
    table: Option<[f64; 3]>,
    floor: f64,
) -> Option<[f64; 3]> {
    let reported = reported.filter(|s| s.iter().all(|x| x.is_finite() && *x > 0.0));
    let picked = match source {
        SigmaSource::Reported => reported.or(table),
        SigmaSource::Quality => table.or(reported),
    };
    picked.map(|s| s.map(|x| x.max(floor)))
}

impl SigmaPolicy {
    /// Position σ east, north, up, m, for `fix`.
    pub fn pos_sigma(&self, fix: &GnssFix) -> Option<[f64; 3]> {
        let table = fix.quality.map(|q| enu(q.pos_sigma_hv()));
        choose(self.source, fix.pos_sigma, table, self.floor_pos_m)
    }

    /// Velocity σ east, north, up, m/s, for `fix` (none without a velocity).
    pub fn vel_sigma(&self, fix: &GnssFix) -> Option<[f64; 3]> {
        fix.vel?;
        let table = fix.quality.map(|q| enu(q.vel_sigma_hv()));
        choose(self.source, fix.vel_sigma, table, self.floor_vel_mps)
    }

    /// The domain GNSS block of `fix`.
    pub fn block(&self, fix: &GnssFix) -> GnssBlock {
        GnssBlock {
            lat: fix.lla.lat,
            lon: fix.lla.lon,
            h: fix.lla.h,
            vel: fix.vel,
            pos_sigma: self.pos_sigma(fix),
            vel_sigma: self.vel_sigma(fix),
        }
    }

    /// An epoch at the fix's time holding only its GNSS block.
    pub fn epoch(&self, fix: &GnssFix) -> Epoch {
        Epoch {
            t: fix.t,
            gnss: Some(self.block(fix)),
            ..Epoch::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fix(quality: Option<Quality>, pos_sigma: Option<[f64; 3]>) -> GnssFix {
        GnssFix {
            line: 1,
            t: 0.0,
            lla: Lla {
                lat: 0.7,
                lon: -1.8,
                h: 1600.0,
            },
            quality,
            ns: None,
            pos_sigma,
            vel: Some([1.0, 0.0, 0.0]),
            vel_sigma: None,
        }
    }

    #[test]
    fn a_reported_sigma_below_the_floor_is_raised_to_it() {
        let f = fix(Some(Quality::Fixed), Some([0.0098995, 0.0098995, 0.01]));
        let s = SigmaPolicy::default().pos_sigma(&f).unwrap();
        assert_eq!(s, [0.01, 0.01, 0.01]);
    }

    #[test]
    fn the_quality_policy_replaces_reported_sigma_by_the_table() {
        let p = SigmaPolicy {
            source: SigmaSource::Quality,
            ..SigmaPolicy::default()
        };
        let f = fix(Some(Quality::Float), Some([0.01, 0.01, 0.02]));
        assert_eq!(p.pos_sigma(&f), Some([0.5, 0.5, 1.0]));
        assert_eq!(p.vel_sigma(&f), Some([0.05, 0.05, 0.1]));
        // Without a quality the file's σ stays.
        let f = fix(None, Some([0.01, 0.02, 0.03]));
        assert_eq!(p.pos_sigma(&f), Some([0.01, 0.02, 0.03]));
    }

    #[test]
    fn zero_reported_sigma_counts_as_not_reported() {
        let f = fix(Some(Quality::Single), Some([0.0, 0.0, 0.0]));
        assert_eq!(SigmaPolicy::default().pos_sigma(&f), Some([3.0, 3.0, 6.0]));
        assert_eq!(SigmaPolicy::default().pos_sigma(&fix(None, None)), None);
    }

    #[test]
    fn rtklib_flags_round_trip() {
        for q in 1..=6 {
            assert_eq!(Quality::from_rtklib_q(q).unwrap().rtklib_q(), q);
        }
        assert_eq!(Quality::from_rtklib_q(0), None);
    }
}
