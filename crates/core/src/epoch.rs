//! The domain epoch: one instant of sensor data, already validated at the edge
//! (finite numbers, SI units, radians), and the aids a federated filter fuses.
//! A leaf of the crate: every layer may use it, it uses none of them. Monitors
//! read the blocks they need; the simulator produces epochs; the wire parses them.

/// INS solution (navigation frame ENU). Angles in radians.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct InsBlock {
    /// Geodetic latitude, rad.
    pub lat: f64,
    /// Longitude, rad.
    pub lon: f64,
    /// Ellipsoidal height, m.
    pub h: f64,
    /// Velocity east, north, up, m/s.
    pub vel: [f64; 3],
    /// Roll, pitch, yaw, rad.
    pub att: [f64; 3],
    /// Specific force in the body frame, m/s², when the INS reports it.
    pub f_b: Option<[f64; 3]>,
}

/// GNSS fix. Angles in radians.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GnssBlock {
    /// Latitude, rad.
    pub lat: f64,
    /// Longitude, rad.
    pub lon: f64,
    /// Ellipsoidal height, m.
    pub h: f64,
    /// Velocity east, north, up, m/s, when reported.
    pub vel: Option<[f64; 3]>,
}

/// Celestial fix: latitude and longitude, rad.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CnsBlock {
    /// Latitude, rad.
    pub lat: f64,
    /// Longitude, rad.
    pub lon: f64,
}

/// Air-data block.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AdsBlock {
    /// Barometric height, m.
    pub baro_h: f64,
    /// True airspeed, m/s.
    pub tas: Option<f64>,
}

/// One epoch of sensor data. Every block is optional; `t` orders epochs.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Epoch {
    /// Time, s; non-decreasing within a session.
    pub t: f64,
    /// INS solution.
    pub ins: Option<InsBlock>,
    /// GNSS fix.
    pub gnss: Option<GnssBlock>,
    /// DVL velocity in the body frame, m/s.
    pub dvl_vel_b: Option<[f64; 3]>,
    /// CNS fix.
    pub cns: Option<CnsBlock>,
    /// Air data.
    pub ads: Option<AdsBlock>,
    /// TACAN slant range, m.
    pub tacan_range_m: Option<f64>,
    /// Redundant gyro outputs, rad/s.
    pub gyros: Option<Vec<f64>>,
    /// Named channels, each a scalar or a vector.
    pub channels: Option<Vec<(String, Vec<f64>)>>,
    /// Measurement vector for the `linear` monitor.
    pub z: Option<Vec<f64>>,
    /// Control input for the `linear` monitor (with its `b` matrix).
    pub u: Option<Vec<f64>>,
}

/// An aid of the federated filter (also the simulator's aid sensors).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Aid {
    /// GNSS position (and velocity when reported).
    Gnss,
    /// Doppler velocity log, body-frame velocity.
    Dvl,
    /// Celestial fix, latitude and longitude.
    Cns,
}

impl Aid {
    /// The wire name, also the test name.
    pub fn as_str(self) -> &'static str {
        match self {
            Aid::Gnss => "gnss",
            Aid::Dvl => "dvl",
            Aid::Cns => "cns",
        }
    }

    /// The aid named `s` on the wire, if any.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "gnss" => Some(Aid::Gnss),
            "dvl" => Some(Aid::Dvl),
            "cns" => Some(Aid::Cns),
            _ => None,
        }
    }
}
