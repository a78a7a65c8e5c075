//! navguard: a navigation integrity-monitoring service. Vehicles stream
//! navigation measurements over a WebSocket; per session navguard runs Kalman
//! filters and fault detectors, decides which sensors can be trusted, raises
//! alarms, and shows statistics on a browser dashboard.
//!
//! # Layout
//!
//! Data flows one way; the folders follow it. Everything above `service` is a
//! pure core: no async, no I/O, usable as a library. A module may use the ones
//! listed before it, never one after it (`tests/layering.rs` checks this for
//! production code; tests may cross layers).
//!
//! - [`simd`]: whether the hot kernels run their AVX2 builds (`NAVGUARD_NO_AVX2`): a
//!   leaf that every layer may use.
//! - [`epoch`]: the domain epoch (sensor blocks in SI units and radians) and the
//!   federated aids: a leaf that every layer may use.
//! - [`geo`]: WGS84 geodesy (frames, radii, Earth and transport rates).
//! - [`detect`]: χ² thresholds and the non-central χ², test statistics, and the
//!   decision policies (`classic`, `counters`) that turn statistics into health.
//! - [`filter`]: the generic Kalman filter (fixed- and dynamic-size), and the
//!   INS error model and federated fusion built on it.
//! - [`learn`]: kernels, LS-SVM and SVM models (for the learned detectors).
//! - [`features`]: time-domain and wavelet-packet features.
//! - [`monitor`]: the `Monitor` trait and one monitor per sensor set; each
//!   wires filters and detectors and yields tests and outputs per epoch.
//! - [`session`]: the session core: the roster, the alarm rule, thresholds, statistics
//!   and history of one session; it commits stepped epochs into ordered effects that
//!   the server carries out and the experiments count.
//! - [`sim`]: trajectories, sensors, faults and the papers' experiments.
//! - [`service`]: the async edge: sockets and REST (axum), one actor task per
//!   session, the SQLite store, auth and limits.

pub mod detect;
pub mod epoch;
pub mod features;
pub mod filter;
pub mod geo;
pub mod learn;
pub mod monitor;
pub mod service;
pub mod session;
pub mod sim;
pub mod simd;
