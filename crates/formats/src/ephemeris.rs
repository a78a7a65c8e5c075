//! Broadcast ephemerides: the middle of every reader that has no satellite positions
//! of its own (RINEX, GnssLogger). A navigation file's Kepler elements become the
//! satellite's ECEF position at transmit time and its clock correction, as a
//! receiver computes them (IS-GPS-200 §20.3.3.3.3 and §20.3.3.4.3).
//!
//! # Orbit (IS-GPS-200 Table 20-IV)
//! `A = (√A)²`, `n = √(μ/A³) + Δn`, `t_k = t − t_oe` (wrapped into ±302 400 s, the
//! week crossover), `M = M₀ + n·t_k`, Kepler's equation `E = M + e·sin E` iterated to
//! 1e-13 rad, `ν = atan2(√(1−e²)·sin E, cos E − e)`, `Φ = ν + ω`, the harmonic
//! corrections `δu = C_us sin 2Φ + C_uc cos 2Φ` (same for r with C_rs/C_rc and i with
//! C_is/C_ic), `r = A(1 − e cos E) + δr`, `i = i₀ + δi + IDOT·t_k`,
//! `Ω = Ω₀ + (Ω̇ − Ω̇_E)·t_k − Ω̇_E·t_oe` and the rotation of the orbital-plane position
//! `(r cos u, r sin u)` by i and Ω. The result is in the ECEF frame of the instant
//! `t` (the transmit time): the Earth-rotation (Sagnac) correction over the signal's
//! flight is left to the user, as [`navguard_core::epoch::SatObs::pos`] says.
//!
//! # Clock (IS-GPS-200 §20.3.3.3.3.1–2)
//! `Δt_sv = a_f0 + a_f1·(t − t_oc) + a_f2·(t − t_oc)² + Δt_r`, with the relativistic
//! term `Δt_r = F·e·√A·sin E`, `F = −2√μ/c² = −4.442807633e-10 s/√m`. An L1 single-
//! frequency user subtracts the group delay: `Δt_sv,L1 = Δt_sv − T_GD`. The broadcast
//! clock refers to the iono-free P1/P2 combination, so for that combination T_GD
//! cancels and is not applied ([`ClockFor::IonoFree`]).
//!
//! # Transmit time (IS-GPS-200 §20.3.3.3.3.1)
//! The receiver's tag t_rx minus the pseudorange's flight time is the satellite's own
//! clock reading `t_sv = t_rx − PR/c`; system time is `t = t_sv − Δt_sv(t)`, solved by
//! two fixed-point rounds (Δt_sv changes by < 1e-12 s per second).
//!
//! # Galileo (OS SIS ICD §5.1.1–5.1.5)
//! The same Kepler model and clock polynomial with Galileo's μ = 3.986004418e14 m³/s²
//! and F = −4.442807309e-10 s/√m, and the same Ω̇_E. Times are GST, taken as GPS
//! seconds: RINEX gives the week as GPS-aligned (GST week + 1024), and the GST − GPST
//! offset (GGTO, a few ns) is left to the receiver's clock per constellation. The
//! broadcast clock refers to the iono-free combination of its message: E1/E5b for
//! I/NAV, E1/E5a for F/NAV. An E1 single-frequency user subtracts that message's
//! group delay, `Δt_sv,E1 = Δt_sv − BGD(E1,E5b)` (I/NAV) or `− BGD(E1,E5a)` (F/NAV)
//! (§5.1.5); the E1/E5a combination ([`ClockFor::IonoFree`]) takes an I/NAV clock across
//! with `Δt_sv,E1E5a = Δt_sv − BGD(E1,E5b) + BGD(E1,E5a)`, both being the same E1 clock.

use std::collections::BTreeMap;

use navguard_core::epoch::{Constellation, SatId};

use crate::gpstime::{WEEK_S, wrap_half_week};

/// Speed of light in vacuum, m/s (IS-GPS-200 §20.3.4.3).
pub const C_LIGHT: f64 = 299_792_458.0;
/// WGS-84 Earth rotation rate used by the GPS navigation message, rad/s.
pub const OMEGA_E_DOT: f64 = 7.292_115_146_7e-5;
/// How far from t_oe an ephemeris is used: the 4-hour fit interval's half.
pub const MAX_AGE_S: f64 = 7_200.0;

/// The physical constants of one constellation's broadcast orbit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Constants {
    /// Earth's gravitational parameter μ, m³/s².
    pub mu: f64,
    /// Relativistic clock constant F, s/√m.
    pub f_rel: f64,
}

impl Constants {
    /// GPS (IS-GPS-200 Table 20-IV).
    pub const GPS: Constants = Constants {
        mu: 3.986_005e14,
        f_rel: -4.442_807_633e-10,
    };
    /// Galileo (OS SIS ICD §5.1.1).
    pub const GALILEO: Constants = Constants {
        mu: 3.986_004_418e14,
        f_rel: -4.442_807_309e-10,
    };

    /// The constants of a constellation with a Kepler broadcast orbit, if we know them.
    pub fn of(c: Constellation) -> Option<Constants> {
        match c {
            Constellation::Gps | Constellation::Qzss => Some(Constants::GPS),
            Constellation::Galileo => Some(Constants::GALILEO),
            _ => None,
        }
    }
}

/// One broadcast ephemeris (subframes 1–3), times as GPS seconds since 1980-01-06.
#[derive(Debug, Clone, PartialEq)]
pub struct Ephemeris {
    /// The satellite.
    pub sat: SatId,
    /// Clock reference time t_oc, GPS s.
    pub toc: f64,
    /// Clock bias a_f0, s.
    pub af0: f64,
    /// Clock drift a_f1, s/s.
    pub af1: f64,
    /// Clock drift rate a_f2, s/s².
    pub af2: f64,
    /// Issue of data (ephemeris).
    pub iode: f64,
    /// Orbit radius sine correction C_rs, m.
    pub crs: f64,
    /// Mean motion difference Δn, rad/s.
    pub delta_n: f64,
    /// Mean anomaly at t_oe M₀, rad.
    pub m0: f64,
    /// Argument of latitude cosine correction C_uc, rad.
    pub cuc: f64,
    /// Eccentricity e.
    pub e: f64,
    /// Argument of latitude sine correction C_us, rad.
    pub cus: f64,
    /// Square root of the semi-major axis √A, √m.
    pub sqrt_a: f64,
    /// Ephemeris reference time t_oe, GPS s (week and seconds of week combined).
    pub toe: f64,
    /// Inclination cosine correction C_ic, rad.
    pub cic: f64,
    /// Longitude of the ascending node at the week's start Ω₀, rad.
    pub omega0: f64,
    /// Inclination sine correction C_is, rad.
    pub cis: f64,
    /// Inclination at t_oe i₀, rad.
    pub i0: f64,
    /// Orbit radius cosine correction C_rc, m.
    pub crc: f64,
    /// Argument of perigee ω, rad.
    pub omega: f64,
    /// Rate of right ascension Ω̇, rad/s.
    pub omega_dot: f64,
    /// Rate of inclination IDOT, rad/s.
    pub idot: f64,
    /// GPS week of t_oe (continuous, not modulo 1024).
    pub week: i64,
    /// SV health word; 0 is healthy (Galileo: every signal's health and validity bits).
    pub health: f64,
    /// Group delay T_GD, s (Galileo: BGD(E1,E5a), as RINEX's field in that place).
    pub tgd: f64,
    /// Galileo's message, group delays and accuracy; `None` for GPS and QZSS.
    pub galileo: Option<GalileoNav>,
}

/// The Galileo navigation message a record was decoded from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GalileoMessage {
    /// I/NAV (E1-B, E5b-I): the clock refers to E1/E5b.
    INav,
    /// F/NAV (E5a-I): the clock refers to E1/E5a.
    FNav,
}

/// What a Galileo record adds to the Kepler elements (RINEX 3.04 Table A8).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GalileoNav {
    /// The message the clock came from.
    pub message: GalileoMessage,
    /// BGD(E1,E5a), s.
    pub bgd_e1_e5a: f64,
    /// BGD(E1,E5b), s (F/NAV does not carry it: 0 there).
    pub bgd_e1_e5b: f64,
    /// Signal-in-space accuracy, m.
    pub sisa_m: f64,
    /// RINEX's data-source bits, as read.
    pub data_sources: u32,
}

/// Which signal the clock correction is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClockFor {
    /// L1 C/A or P1 alone: T_GD subtracted.
    L1,
    /// The iono-free P1/P2 combination: T_GD cancels.
    IonoFree,
}

/// A satellite's state at transmit time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SatState {
    /// ECEF position in the frame of the transmit time, m.
    pub pos: [f64; 3],
    /// Clock correction c·Δt_sv, m (relativity included, T_GD as asked): added to PR.
    pub clk_m: f64,
    /// Transmit time in GPS system time, GPS s.
    pub t_tx: f64,
}

impl Ephemeris {
    fn constants(&self) -> Constants {
        Constants::of(self.sat.constellation).unwrap_or(Constants::GPS)
    }

    /// Eccentric anomaly E at GPS time `t` (Kepler's equation, Table 20-IV).
    pub fn eccentric_anomaly(&self, t: f64) -> f64 {
        let k = self.constants();
        let a = self.sqrt_a * self.sqrt_a;
        let n = (k.mu / (a * a * a)).sqrt() + self.delta_n;
        let m = self.m0 + n * wrap_half_week(t - self.toe);
        let mut e_anom = m;
        for _ in 0..30 {
            let next = m + self.e * e_anom.sin();
            let done = (next - e_anom).abs() < 1e-13;
            e_anom = next;
            if done {
                break;
            }
        }
        e_anom
    }

    /// Satellite ECEF position at GPS time `t`, in the Earth-fixed frame of `t`, m.
    pub fn position(&self, t: f64) -> [f64; 3] {
        let tk = wrap_half_week(t - self.toe);
        let e_anom = self.eccentric_anomaly(t);
        let a = self.sqrt_a * self.sqrt_a;
        let nu = ((1.0 - self.e * self.e).sqrt() * e_anom.sin()).atan2(e_anom.cos() - self.e);
        let phi = nu + self.omega;
        let (s2, c2) = (2.0 * phi).sin_cos();
        let u = phi + self.cus * s2 + self.cuc * c2;
        let r = a * (1.0 - self.e * e_anom.cos()) + self.crs * s2 + self.crc * c2;
        let i = self.i0 + self.cis * s2 + self.cic * c2 + self.idot * tk;
        let (xp, yp) = (r * u.cos(), r * u.sin());
        let toe_sow = self.toe - self.week as f64 * WEEK_S;
        let big_omega = self.omega0 + (self.omega_dot - OMEGA_E_DOT) * tk - OMEGA_E_DOT * toe_sow;
        let (so, co) = big_omega.sin_cos();
        let (si, ci) = i.sin_cos();
        [xp * co - yp * ci * so, xp * so + yp * ci * co, yp * si]
    }

    /// Satellite clock correction Δt_sv at GPS time `t`, s (§20.3.3.3.3.1).
    pub fn clock_s(&self, t: f64, for_signal: ClockFor) -> f64 {
        let dt = wrap_half_week(t - self.toc);
        let rel = self.constants().f_rel * self.e * self.sqrt_a * self.eccentric_anomaly(t).sin();
        self.af0 + self.af1 * dt + self.af2 * dt * dt + rel - self.group_delay_s(for_signal)
    }

    /// What is subtracted from this record's clock for `for_signal`: T_GD for GPS L1;
    /// for Galileo the message's BGD for E1, and for E1/E5a the step from the I/NAV
    /// clock's E1/E5b reference (module docs).
    pub fn group_delay_s(&self, for_signal: ClockFor) -> f64 {
        match (self.galileo, for_signal) {
            (None, ClockFor::L1) => self.tgd,
            (None, ClockFor::IonoFree) => 0.0,
            (Some(g), ClockFor::L1) => match g.message {
                GalileoMessage::INav => g.bgd_e1_e5b,
                GalileoMessage::FNav => g.bgd_e1_e5a,
            },
            (Some(g), ClockFor::IonoFree) => match g.message {
                GalileoMessage::INav => g.bgd_e1_e5b - g.bgd_e1_e5a,
                GalileoMessage::FNav => 0.0,
            },
        }
    }

    /// The group delay an L1 (E1) user subtracts from a precise clock that refers to the
    /// IGS's iono-free combination (GPS P1/P2, Galileo E1/E5a): T_GD or BGD(E1,E5a).
    pub fn precise_group_delay_s(&self) -> f64 {
        self.galileo.map_or(self.tgd, |g| g.bgd_e1_e5a)
    }

    /// The state at the transmit time of a signal whose satellite clock read `t_sv`
    /// (GPS s): `t = t_sv − Δt_sv(t)` by fixed-point iteration.
    pub fn at_satellite_time(&self, t_sv: f64, for_signal: ClockFor) -> SatState {
        let mut t = t_sv;
        for _ in 0..3 {
            t = t_sv - self.clock_s(t, for_signal);
        }
        SatState {
            pos: self.position(t),
            clk_m: C_LIGHT * self.clock_s(t, for_signal),
            t_tx: t,
        }
    }

    /// The state for a pseudorange `pr_m` received at receiver time `t_rx` (GPS s):
    /// `t_sv = t_rx − PR/c`.
    pub fn at_reception(&self, t_rx: f64, pr_m: f64, for_signal: ClockFor) -> SatState {
        self.at_satellite_time(t_rx - pr_m / C_LIGHT, for_signal)
    }
}

/// The ephemerides of a navigation file, by satellite, in t_oe order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Ephemerides {
    by_sat: BTreeMap<SatId, Vec<Ephemeris>>,
}

impl Ephemerides {
    /// Collects ephemerides (any order).
    pub fn new(all: impl IntoIterator<Item = Ephemeris>) -> Self {
        let mut by_sat: BTreeMap<SatId, Vec<Ephemeris>> = BTreeMap::new();
        for e in all {
            by_sat.entry(e.sat).or_default().push(e);
        }
        for v in by_sat.values_mut() {
            v.sort_by(|a, b| a.toe.total_cmp(&b.toe));
        }
        Ephemerides { by_sat }
    }

    /// How many records are held.
    pub fn len(&self) -> usize {
        self.by_sat.values().map(Vec::len).sum()
    }

    /// Whether no record is held.
    pub fn is_empty(&self) -> bool {
        self.by_sat.is_empty()
    }

    /// The records of one satellite, in t_oe order.
    pub fn of(&self, sat: SatId) -> &[Ephemeris] {
        self.by_sat.get(&sat).map_or(&[], Vec::as_slice)
    }

    /// The healthy ephemeris of `sat` with t_oe nearest `t`, if one is within
    /// [`MAX_AGE_S`] (the earlier one on a tie). Galileo prefers I/NAV records (the E1
    /// message) and takes an F/NAV one only when no I/NAV record is within reach.
    pub fn select(&self, sat: SatId, t: f64) -> Option<&Ephemeris> {
        let usable = |e: &&Ephemeris| e.health == 0.0 && (t - e.toe).abs() <= MAX_AGE_S;
        let nearest = |inav_only: bool| {
            self.of(sat)
                .iter()
                .filter(usable)
                .filter(|e| {
                    !inav_only || e.galileo.is_some_and(|g| g.message == GalileoMessage::INav)
                })
                .min_by(|a, b| (t - a.toe).abs().total_cmp(&(t - b.toe).abs()))
        };
        if sat.constellation == Constellation::Galileo {
            nearest(true).or_else(|| nearest(false))
        } else {
            nearest(false)
        }
    }
}
