//! Receiver-to-satellite geometry shared by the readers that compute their own
//! corrections: look angles for Klobuchar and for [`SatObs`](navguard_core::epoch::SatObs)'s
//! `el`/`az`, and the truth as the epoch stores it.

use nalgebra::Vector3;
use navguard_core::geo::{Lla, ecef_to_enu_rotation, ecef_to_lla, lla_to_ecef};

/// A receiver's a-priori position, in both forms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Station {
    /// ECEF, m.
    pub ecef: [f64; 3],
    /// Geodetic, rad and m.
    pub lla: Lla,
}

impl Station {
    /// From ECEF metres.
    pub fn from_ecef(ecef: [f64; 3]) -> Self {
        let lla = ecef_to_lla(&Vector3::from(ecef));
        Station { ecef, lla }
    }

    /// From geodetic coordinates.
    pub fn from_lla(lla: Lla) -> Self {
        let r = lla_to_ecef(&lla);
        Station {
            ecef: [r.x, r.y, r.z],
            lla,
        }
    }

    /// `[lat, lon, h]` as [`GnssRawBlock::truth`](navguard_core::epoch::GnssRawBlock) holds it.
    pub fn as_truth(&self) -> [f64; 3] {
        [self.lla.lat, self.lla.lon, self.lla.h]
    }

    /// Elevation and azimuth (rad; azimuth clockwise from north in [0, 2π)) of a
    /// satellite at ECEF `sat` (the Earth rotation during the flight, < 0.01°, ignored).
    pub fn look_angles(&self, sat: [f64; 3]) -> (f64, f64) {
        let d = Vector3::from(sat) - Vector3::from(self.ecef);
        let enu = ecef_to_enu_rotation(self.lla.lat, self.lla.lon) * d;
        let el = enu.z.atan2(enu.x.hypot(enu.y));
        let az = enu.x.atan2(enu.y).rem_euclid(std::f64::consts::TAU);
        (el, az)
    }
}
