//! Where a reader gets satellite states: the one door between the observation readers
//! and the two orbit sources, broadcast ephemerides ([`crate::ephemeris`]) or precise SP3
//! orbits and clocks ([`crate::sp3`]). Both give a [`SatState`] at transmit time, so the
//! conversion after it does not know which was used.

use navguard_core::epoch::SatId;

use crate::ephemeris::{C_LIGHT, ClockFor, Ephemerides, SatState};
use crate::sp3::Sp3Orbits;

/// The source of satellite positions and clocks.
#[derive(Debug, Clone, Copy)]
pub enum OrbitSource<'a> {
    /// The broadcast message: the healthy record nearest in t_oe, within 2 h.
    Broadcast(&'a Ephemerides),
    /// SP3 precise orbits and clocks. A single-frequency signal takes its group delay
    /// (T_GD, BGD) from the broadcast record, when one is given; without one, only the
    /// iono-free combination has states.
    Precise {
        /// The interpolated SP3 samples.
        sp3: &'a Sp3Orbits,
        /// Broadcast records for the group delays, if any.
        broadcast: Option<&'a Ephemerides>,
    },
}

impl OrbitSource<'_> {
    /// The state of `sat` for a pseudorange `pr_m` received at receiver time `t_rx`
    /// (GPS s), the clock correction for `for_signal`; `None` when the source has none
    /// (no healthy record within 2 h, outside the SP3 data or a sample absent, or a
    /// single-frequency signal without a broadcast record for its group delay).
    pub fn at_reception(
        &self,
        sat: SatId,
        t_rx: f64,
        pr_m: f64,
        for_signal: ClockFor,
    ) -> Option<SatState> {
        match *self {
            OrbitSource::Broadcast(eph) => eph
                .select(sat, t_rx)
                .map(|e| e.at_reception(t_rx, pr_m, for_signal)),
            OrbitSource::Precise { sp3, broadcast } => {
                let group_delay = match for_signal {
                    ClockFor::IonoFree => 0.0,
                    ClockFor::L1 => broadcast?.select(sat, t_rx)?.precise_group_delay_s(),
                };
                sp3.at_satellite_time(sat, t_rx - pr_m / C_LIGHT, group_delay)
            }
        }
    }
}
