//! navguard-core: the pure core of navguard (filters, detectors, learned models,
//! monitors and the session core): no async, no I/O, no plotting.
//!
//! # Layout
//!
//! Data flows one way; the folders follow it. This crate is the pure core: no async,
//! no I/O, usable as a library. A module may use the ones listed before it, never one
//! after it (the workspace root's `tests/layering.rs` checks this for production code;
//! tests may cross layers).
//!
//! - [`simd`]: whether the hot kernels run their AVX2 builds (`NAVGUARD_NO_AVX2`): a
//!   leaf that every layer may use.
//! - [`epoch`]: the domain epoch (sensor blocks in SI units and radians) and the
//!   federated aids: a leaf that every layer may use.
//! - [`geo`]: WGS84 geodesy (frames, radii, Earth and transport rates).
//! - [`detect`]: χ² thresholds and the non-central χ², test statistics, and the
//!   decision policies (`classic`, `counters`) that turn statistics into health.
//! - [`gnss`]: pseudorange corrections, weighted least squares, RAIM fault detection
//!   and exclusion, and protection levels (slope RAIM, ARAIM) for one epoch.
//! - [`strapdown`]: the strapdown inertial mechanization (attitude, velocity, position
//!   from IMU increments) and coarse alignment.
//! - [`filter`]: the generic Kalman filter (fixed- and dynamic-size), and the
//!   INS error model and federated fusion built on it.
//! - [`learn`]: kernels, LS-SVM and SVM models (for the learned detectors).
//! - [`features`]: time-domain and wavelet-packet features.
//! - [`monitor`]: the `Monitor` trait and one monitor per sensor set; each
//!   wires filters and detectors and yields tests and outputs per epoch.
//! - [`session`]: the session core: the roster, the alarm rule, thresholds, statistics
//!   and history of one session; it commits stepped epochs into ordered effects that
//!   the server carries out and the experiments count.
//!
//! Then, in their own crates: `navguard-sim` (trajectories, sensors, faults and the
//! papers' experiments) and the `navguard` package (the async service and the CLI).

pub mod detect;
pub mod epoch;
pub mod features;
pub mod filter;
pub mod geo;
pub mod gnss;
pub mod learn;
pub mod monitor;
pub mod session;
pub mod simd;
pub mod strapdown;
