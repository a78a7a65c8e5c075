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
    /// Position 1-σ east, north, up, m, when the receiver reports it (an RTKLIB `.pos`
    /// file's sdn/sde/sdu, NMEA GST); absent means the monitor's configured σ.
    pub pos_sigma: Option<[f64; 3]>,
    /// Velocity 1-σ east, north, up, m/s, when reported; absent means the configured σ.
    pub vel_sigma: Option<[f64; 3]>,
}

/// One raw IMU sample in the sensor frame (docs/methods.md §M30): rates sampled at the
/// epoch's time, or increments over the interval that ends at it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ImuBlock {
    /// Specific force, m/s² (rates), or the velocity increment Δv, m/s (increments).
    pub accel: [f64; 3],
    /// Angular rate, rad/s (rates), or the angle increment Δθ, rad (increments).
    pub gyro: [f64; 3],
    /// `Some(Δt)`: `accel` and `gyro` are increments over `(t − Δt, t]`, s; `None`: rates.
    pub dt: Option<f64>,
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
    /// GNSS pseudoranges for the `gnss` monitor.
    pub gnss_raw: Option<GnssRawBlock>,
    /// Raw IMU sample for a `federated` monitor with `input: imu`.
    pub imu: Option<ImuBlock>,
}

/// A GNSS constellation, by its RINEX letter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Constellation {
    /// GPS (`G`).
    Gps,
    /// Galileo (`E`).
    Galileo,
    /// GLONASS (`R`).
    Glonass,
    /// BeiDou (`C`).
    Beidou,
    /// QZSS (`J`).
    Qzss,
    /// NavIC / IRNSS (`I`).
    Navic,
    /// SBAS (`S`).
    Sbas,
}

impl Constellation {
    /// Every constellation, in the order clocks are numbered.
    pub const ALL: [Constellation; 7] = [
        Constellation::Gps,
        Constellation::Galileo,
        Constellation::Glonass,
        Constellation::Beidou,
        Constellation::Qzss,
        Constellation::Navic,
        Constellation::Sbas,
    ];

    /// The RINEX letter.
    pub fn letter(self) -> char {
        match self {
            Constellation::Gps => 'G',
            Constellation::Galileo => 'E',
            Constellation::Glonass => 'R',
            Constellation::Beidou => 'C',
            Constellation::Qzss => 'J',
            Constellation::Navic => 'I',
            Constellation::Sbas => 'S',
        }
    }

    /// The constellation of RINEX letter `c`, if any.
    pub fn from_letter(c: char) -> Option<Self> {
        Constellation::ALL.into_iter().find(|k| k.letter() == c)
    }
}

/// A satellite: constellation and number (`G05`, `E11`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct SatId {
    /// Constellation.
    pub constellation: Constellation,
    /// PRN or slot number, 1–99.
    pub prn: u8,
}

impl SatId {
    /// Parses `G05`-style ids: a constellation letter and a number 1–99 (one or two digits).
    pub fn parse(s: &str) -> Result<Self, SatIdError> {
        let mut chars = s.chars();
        let letter = chars.next().ok_or(SatIdError::Malformed)?;
        let digits = chars.as_str();
        if !letter.is_ascii_alphabetic()
            || digits.is_empty()
            || digits.len() > 2
            || !digits.bytes().all(|b| b.is_ascii_digit())
        {
            return Err(SatIdError::Malformed);
        }
        let constellation =
            Constellation::from_letter(letter).ok_or(SatIdError::UnknownConstellation(letter))?;
        let prn: u8 = digits.parse().map_err(|_| SatIdError::Malformed)?;
        if prn == 0 {
            return Err(SatIdError::Malformed);
        }
        Ok(SatId { constellation, prn })
    }
}

impl std::fmt::Display for SatId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}{:02}", self.constellation.letter(), self.prn)
    }
}

/// Why a satellite id was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SatIdError {
    /// Not a letter followed by a number 1–99.
    #[error("a satellite id is a constellation letter and a number 1-99, e.g. G05")]
    Malformed,
    /// The letter is no constellation's.
    #[error("unknown constellation letter '{0}' (G, E, R, C, J, I or S)")]
    UnknownConstellation(char),
}

/// One satellite's pseudorange and what is needed to use it (docs/methods.md §M26).
/// The corrected pseudorange is `pr + clk − iono − tropo`.
#[derive(Debug, Clone, PartialEq)]
pub struct SatObs {
    /// The satellite.
    pub id: SatId,
    /// Pseudorange, m.
    pub pr: f64,
    /// Satellite position at transmit time, ECEF (the frame at transmit time), m.
    pub pos: [f64; 3],
    /// Satellite clock correction c·δt_sv, m (relativistic term and group delay
    /// included): added to the pseudorange.
    pub clk: f64,
    /// Ionospheric delay, m (subtracted); absent means none (e.g. an iono-free code).
    pub iono: Option<f64>,
    /// Tropospheric delay, m (subtracted); absent means the monitor's model.
    pub tropo: Option<f64>,
    /// Pseudorange 1-σ, m; absent means the monitor's σ model.
    pub sigma: Option<f64>,
    /// Carrier-to-noise density, dB-Hz.
    pub cn0: Option<f64>,
    /// Elevation, rad; computed from the position if absent.
    pub el: Option<f64>,
    /// Azimuth, rad, clockwise from north; computed from the position if absent.
    pub az: Option<f64>,
}

/// The pseudoranges of one epoch, and the true position when it is known (evaluation only:
/// the monitor never uses it to decide, it only reports the errors against it).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GnssRawBlock {
    /// One entry per satellite, no satellite twice.
    pub sats: Vec<SatObs>,
    /// True latitude, longitude (rad) and ellipsoidal height (m).
    pub truth: Option<[f64; 3]>,
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
