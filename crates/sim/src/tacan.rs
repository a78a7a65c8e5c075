//! The `tacan` scenario (docs/methods.md §M19, seed 003 §4): an aircraft flying around a
//! TACAN station at 25 Hz, with an INS-derived slant range carrying a small slowly
//! varying INS error and a measured range with white noise N(0, σ²) and random
//! jumps. Feeds the `tacan` monitor ([`navguard_core::monitor::tacan`]) and the seed 003
//! experiment; pure and deterministic from a seed.
//!
//! # Model
//! - **Flight**: in the station's local ENU plane, starting 30–120 km away on a
//!   random bearing at 3–8 km height, 150–250 m/s, random heading; every 30–90 s
//!   a new turn rate in ±2 °/s (straight 40 % of the time) and climb rate in
//!   ±5 m/s; beyond 150 km from the station it turns back at 2 °/s. ENU is
//!   converted to WGS84 exactly (`geo::enu_to_ecef`).
//! - **INS error**: per ENU axis a first-order Gauss–Markov position error with
//!   standard deviation `ins_sigma_m` (default 5 m) and correlation time
//!   `ins_tau_s` (default 300 s) — "small" as for an INS with an external
//!   position reset, far below the paper's free-inertial 0.8 nmi/h, which would
//!   otherwise swamp the mean feature (the paper does not say how its INS was held).
//! - **TACAN range**: true slant range (ECEF distance) + N(0, σ²) per sample.
//! - **Jumps** (test flights): `jumps` events; the flight is cut into `jumps`
//!   equal slots and each slot holds one jump at a uniformly drawn start, so no
//!   sliding window of `window` samples ever holds two jumps. A jump adds a
//!   constant offset of uniform magnitude in [150, 300] m ("> 150 m", seed 003 §4)
//!   with a random sign to `1..=max_jump_samples` consecutive samples (uniform;
//!   default up to 5, i.e. 40–200 ms at 25 Hz: a short glitch, as a TACAN
//!   mis-lock or multipath spike, not a lasting offset).
//!
//! Randomness: the trajectory, INS error and jumps come from streams of `seed`
//! only; the range noise from its own stream as N(0, 1) draws scaled by σ, so
//! flights at 5, 10 and 20 m² share their path, INS error and jumps.

use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

use super::{SimError, check_non_negative, check_positive};
use navguard_core::epoch::Epoch;
use navguard_core::epoch::InsBlock;
use navguard_core::geo::{self, Lla};
use navguard_core::monitor::tacan::slant_range_m;

/// Default station: latitude 34.25°, longitude 108.95°, 400 m (an arbitrary inland site).
pub fn default_station() -> Lla {
    Lla {
        lat: 34.25f64.to_radians(),
        lon: 108.95f64.to_radians(),
        h: 400.0,
    }
}

/// What to simulate.
#[derive(Debug, Clone, PartialEq)]
pub struct TacanFlightParams {
    /// Seed of the flight (path, INS error, jumps, noise).
    pub seed: u64,
    /// Flight length, s.
    pub duration_s: f64,
    /// Sample rate, Hz (seed 003: 25).
    pub rate_hz: f64,
    /// Range noise variance σ², m² (seed 003: 5, 10, 20).
    pub noise_var_m2: f64,
    /// Number of jumps (0 for a training flight; seed 003: 200 per test flight).
    pub jumps: usize,
    /// Smallest jump magnitude, m.
    pub jump_min_m: f64,
    /// Largest jump magnitude, m.
    pub jump_max_m: f64,
    /// Longest jump, samples.
    pub max_jump_samples: usize,
    /// Feature window the jumps are kept apart for, samples.
    pub window: usize,
    /// INS position error, 1σ per axis, m.
    pub ins_sigma_m: f64,
    /// INS error correlation time, s.
    pub ins_tau_s: f64,
    /// The station.
    pub station: Lla,
}

impl Default for TacanFlightParams {
    fn default() -> Self {
        TacanFlightParams {
            seed: 3,
            duration_s: 600.0,
            rate_hz: 25.0,
            noise_var_m2: 20.0,
            jumps: 200,
            jump_min_m: 150.0,
            jump_max_m: 300.0,
            max_jump_samples: 5,
            window: 10,
            ins_sigma_m: 5.0,
            ins_tau_s: 300.0,
            station: default_station(),
        }
    }
}

/// One injected jump.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Jump {
    /// First sample.
    pub start: usize,
    /// Samples affected.
    pub len: usize,
    /// Offset added to the measured range, m.
    pub offset_m: f64,
}

/// A simulated flight.
#[derive(Debug, Clone, PartialEq)]
pub struct TacanFlight {
    /// The epochs (`ins` and `tacan` blocks), as a client would stream them.
    pub epochs: Vec<Epoch>,
    /// INS-derived range per sample, m (what the monitor computes from `ins`).
    pub ins_range_m: Vec<f64>,
    /// Measured range per sample, m.
    pub tacan_range_m: Vec<f64>,
    /// True slant range per sample, m.
    pub true_range_m: Vec<f64>,
    /// The jumps, in time order.
    pub jumps: Vec<Jump>,
    /// Per sample: true when a jump affects it.
    pub jumped: Vec<bool>,
}

impl TacanFlight {
    /// Per sliding window (step 1, `window` samples, the `i`-th ending at sample
    /// `i + window − 1`): true when it holds a jumped sample.
    pub fn window_truth(&self, window: usize) -> Vec<bool> {
        if window == 0 || self.jumped.len() < window {
            return Vec::new();
        }
        self.jumped
            .windows(window)
            .map(|w| w.iter().any(|&j| j))
            .collect()
    }
}

/// Random stream `id` of flight `seed` (independent of the federated scenario's streams).
fn stream(seed: u64, id: u64) -> StdRng {
    StdRng::seed_from_u64(seed ^ (0x7ACA_0000_0000_0000 | id.wrapping_mul(0x9E37_79B9)))
}

impl TacanFlightParams {
    /// Validates the parameters, naming the field.
    pub fn check(&self) -> Result<(), SimError> {
        check_positive("duration_s", self.duration_s)?;
        check_positive("rate_hz", self.rate_hz)?;
        check_non_negative("noise_var_m2", self.noise_var_m2)?;
        check_positive("jump_min_m", self.jump_min_m)?;
        check_positive("jump_max_m", self.jump_max_m)?;
        check_non_negative("ins_sigma_m", self.ins_sigma_m)?;
        check_positive("ins_tau_s", self.ins_tau_s)?;
        if self.jump_max_m < self.jump_min_m {
            return Err(SimError::param("jump_max_m", "must be ≥ jump_min_m"));
        }
        if self.max_jump_samples == 0 {
            return Err(SimError::param("max_jump_samples", "must be ≥ 1"));
        }
        if self.window < 2 {
            return Err(SimError::param("window", "must be ≥ 2"));
        }
        let n = self.samples();
        if n < self.window {
            return Err(SimError::param("duration_s", "shorter than one window"));
        }
        if self.jumps > 0 && n / self.jumps < self.max_jump_samples + self.window {
            return Err(SimError::param(
                "jumps",
                format!(
                    "{} jumps do not fit {} samples with a window of {} between them",
                    self.jumps, n, self.window
                ),
            ));
        }
        Ok(())
    }

    /// Number of samples.
    pub fn samples(&self) -> usize {
        (self.duration_s * self.rate_hz).round() as usize
    }
}

/// The aircraft's path in the station's ENU plane (module doc, "Flight").
struct FlightPath {
    pos: Vector3<f64>,
    speed: f64,
    heading: f64,
    turn: f64,
    climb: f64,
    next_change: f64,
}

impl FlightPath {
    /// A random start 30–120 km from the station.
    fn start(rng: &mut StdRng) -> Self {
        let bearing: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let dist: f64 = rng.random_range(30e3..120e3);
        let pos = Vector3::new(
            dist * bearing.sin(),
            dist * bearing.cos(),
            rng.random_range(3e3..8e3),
        );
        let speed: f64 = rng.random_range(150.0..250.0);
        let heading: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        FlightPath {
            pos,
            speed,
            heading,
            turn: 0.0,
            climb: 0.0,
            next_change: 0.0,
        }
    }

    /// Draws a new turn and climb rate when the current ones have run out.
    fn manoeuvre(&mut self, t: f64, rng: &mut StdRng) {
        if t >= self.next_change {
            self.next_change = t + rng.random_range(30.0..90.0);
            self.turn = if rng.random_bool(0.4) {
                0.0
            } else {
                rng.random_range(-2.0f64..2.0).to_radians()
            };
            self.climb = rng.random_range(-5.0..5.0);
        }
    }

    fn velocity(&self) -> Vector3<f64> {
        Vector3::new(
            self.speed * self.heading.sin(),
            self.speed * self.heading.cos(),
            self.climb,
        )
    }

    /// Moves on by `dt`, turning back towards the station when far out and
    /// heading away.
    fn advance(&mut self, vel: &Vector3<f64>, dt: f64) {
        let horizontal = Vector3::new(self.pos.x, self.pos.y, 0.0);
        let rate = if horizontal.norm() > 150e3 && horizontal.dot(vel) > 0.0 {
            2f64.to_radians()
        } else {
            self.turn
        };
        self.pos += vel * dt;
        self.pos.z = self.pos.z.clamp(1e3, 10e3);
        self.heading = (self.heading + rate * dt).rem_euclid(std::f64::consts::TAU);
    }
}

/// Gauss–Markov INS error: e_{k+1} = a e_k + σ √(1 − a²) w, per ENU axis.
struct InsError {
    err: Vector3<f64>,
    a: f64,
    q: f64,
}

impl InsError {
    fn start(p: &TacanFlightParams, dt: f64, rng: &mut StdRng) -> Self {
        let a = (-dt / p.ins_tau_s).exp();
        InsError {
            err: Vector3::from_fn(|_, _| p.ins_sigma_m * rng.sample::<f64, _>(StandardNormal)),
            a,
            q: p.ins_sigma_m * (1.0 - a * a).sqrt(),
        }
    }

    fn step(&mut self, rng: &mut StdRng) {
        for i in 0..3 {
            self.err[i] = self.a * self.err[i] + self.q * rng.sample::<f64, _>(StandardNormal);
        }
    }
}

/// Places the jumps, one per slot and a window apart (module doc): records them
/// in `flight` and returns the range offset of every sample.
fn place_jumps(
    p: &TacanFlightParams,
    n: usize,
    rng: &mut StdRng,
    flight: &mut TacanFlight,
) -> Vec<f64> {
    let mut offset = vec![0.0; n];
    if let Some(slot) = n.checked_div(p.jumps) {
        for j in 0..p.jumps {
            let len = rng.random_range(1..=p.max_jump_samples);
            let start = j * slot + rng.random_range(0..=slot - len - p.window);
            let mag = rng.random_range(p.jump_min_m..=p.jump_max_m);
            let offset_m = if rng.random_bool(0.5) { mag } else { -mag };
            offset[start..start + len].fill(offset_m);
            flight.jumped[start..start + len].fill(true);
            flight.jumps.push(Jump {
                start,
                len,
                offset_m,
            });
        }
    }
    offset
}

/// Simulates one flight.
pub fn simulate_flight(p: &TacanFlightParams) -> Result<TacanFlight, SimError> {
    p.check()?;
    let n = p.samples();
    let dt = 1.0 / p.rate_hz;
    let mut path_rng = stream(p.seed, 1);
    let mut ins_rng = stream(p.seed, 2);
    let mut jump_rng = stream(p.seed, 3);
    let mut noise_rng = stream(p.seed, 4);
    let mut path = FlightPath::start(&mut path_rng);
    let mut ins = InsError::start(p, dt, &mut ins_rng);
    let sigma = p.noise_var_m2.sqrt();
    let mut flight = TacanFlight {
        epochs: Vec::with_capacity(n),
        ins_range_m: Vec::with_capacity(n),
        tacan_range_m: Vec::with_capacity(n),
        true_range_m: Vec::with_capacity(n),
        jumps: Vec::with_capacity(p.jumps),
        jumped: vec![false; n],
    };
    let offset = place_jumps(p, n, &mut jump_rng, &mut flight);
    let station_ecef = geo::lla_to_ecef(&p.station);
    for (k, &jump) in offset.iter().enumerate() {
        let t = k as f64 * dt;
        path.manoeuvre(t, &mut path_rng);
        let vel = path.velocity();
        let truth = geo::ecef_to_lla(&geo::enu_to_ecef(&path.pos, &p.station));
        let ins_pos = geo::ecef_to_lla(&geo::enu_to_ecef(&(path.pos + ins.err), &p.station));
        let true_range = (geo::lla_to_ecef(&truth) - station_ecef).norm();
        let ins_range = slant_range_m(&ins_pos, &station_ecef);
        let noise: f64 = noise_rng.sample(StandardNormal);
        let tacan = true_range + sigma * noise + jump;
        flight.true_range_m.push(true_range);
        flight.ins_range_m.push(ins_range);
        flight.tacan_range_m.push(tacan);
        flight.epochs.push(Epoch {
            t,
            ins: Some(InsBlock {
                lat: ins_pos.lat,
                lon: ins_pos.lon,
                h: ins_pos.h,
                vel: [vel.x, vel.y, vel.z],
                att: [0.0, (path.climb / path.speed).atan(), path.heading],
                f_b: None,
            }),
            tacan_range_m: Some(tacan),
            ..Epoch::default()
        });
        path.advance(&vel, dt);
        ins.step(&mut ins_rng);
    }
    Ok(flight)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn short(jumps: usize) -> TacanFlightParams {
        TacanFlightParams {
            duration_s: 40.0,
            jumps,
            ..TacanFlightParams::default()
        }
    }

    #[test]
    fn a_flight_is_deterministic_and_noise_levels_share_the_path() {
        let a = simulate_flight(&short(20)).unwrap();
        let b = simulate_flight(&short(20)).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.epochs.len(), 1000);
        let quiet = simulate_flight(&TacanFlightParams {
            noise_var_m2: 5.0,
            ..short(20)
        })
        .unwrap();
        assert_eq!(quiet.ins_range_m, a.ins_range_m);
        assert_eq!(quiet.jumps, a.jumps);
        // Same N(0, 1) draws scaled by σ: the noise ratio is √(20/5) = 2 off the jumps.
        let k = (0..1000).find(|&k| !a.jumped[k]).unwrap();
        let r = (a.tacan_range_m[k] - a.true_range_m[k])
            / (quiet.tacan_range_m[k] - quiet.true_range_m[k]);
        assert!((r - 2.0).abs() < 1e-6, "{r}");
    }

    #[test]
    fn jumps_are_large_short_and_a_window_apart() {
        let f = simulate_flight(&short(20)).unwrap();
        assert_eq!(f.jumps.len(), 20);
        for w in f.jumps.windows(2) {
            assert!(w[1].start >= w[0].start + w[0].len + 10);
        }
        for j in &f.jumps {
            assert!((150.0..=300.0).contains(&j.offset_m.abs()));
            assert!((1..=5).contains(&j.len));
            let k = j.start;
            let residual = f.tacan_range_m[k] - f.true_range_m[k] - j.offset_m;
            assert!(residual.abs() < 6.0 * 20f64.sqrt());
        }
        let jumped = f.jumped.iter().filter(|&&j| j).count();
        assert_eq!(jumped, f.jumps.iter().map(|j| j.len).sum::<usize>());
        let truth = f.window_truth(10);
        assert_eq!(truth.len(), 1000 - 9);
        // Each jump of length L lies in L + 9 windows.
        let bad = truth.iter().filter(|&&b| b).count();
        assert_eq!(bad, f.jumps.iter().map(|j| j.len + 9).sum::<usize>());
    }

    #[test]
    fn ins_range_stays_within_the_ins_error_of_the_truth() {
        let f = simulate_flight(&short(0)).unwrap();
        assert!(f.jumps.is_empty());
        for k in 0..f.ins_range_m.len() {
            // |Δd| ≤ ‖δp‖, and ‖δp‖ of three 5 m Gauss–Markov axes is well under 40 m.
            assert!((f.ins_range_m[k] - f.true_range_m[k]).abs() < 40.0);
            assert!(f.true_range_m[k] > 1e3);
        }
        // The range changes by at most the speed per sample (250 m/s over 40 ms, plus climb).
        for w in f.true_range_m.windows(2) {
            assert!((w[1] - w[0]).abs() <= 10.3);
        }
    }

    #[test]
    fn impossible_jump_counts_are_refused_naming_the_field() {
        let e = simulate_flight(&TacanFlightParams {
            jumps: 500,
            ..short(0)
        })
        .unwrap_err();
        assert!(matches!(e, SimError::InvalidParameter { ref field, .. } if field == "jumps"));
        let e = simulate_flight(&TacanFlightParams {
            noise_var_m2: -1.0,
            ..short(0)
        })
        .unwrap_err();
        assert!(
            matches!(e, SimError::InvalidParameter { ref field, .. } if field == "noise_var_m2")
        );
    }
}
