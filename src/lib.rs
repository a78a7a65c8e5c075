//! navguard: a navigation integrity-monitoring service. Vehicles stream
//! navigation measurements over a WebSocket; per session navguard runs Kalman
//! filters and fault detectors, decides which sensors can be trusted, raises
//! alarms, and shows statistics on a browser dashboard.
//!
//! # Layout
//!
//! Data flows one way; the crates follow it (`tests/layering.rs` checks the layers
//! inside `navguard-core` and what each crate may name; tests may cross layers).
//!
//! - `navguard-core` (`crates/core`, [`navguard_core`]): the pure core, no async and no
//!   I/O, in layers `simd`, `epoch`, `geo`, `detect`, `gnss`, `filter`, `learn`,
//!   `features`, `monitor`, `session` (see its crate docs).
//! - `navguard-sim` (`crates/sim`, [`navguard_sim`]): trajectories, sensors, faults, SVG
//!   plots and the papers' experiments.
//! - `navguard-formats` (`crates/formats`): receiver files (RINEX, GnssLogger, GSDC) into
//!   epochs with raw pseudoranges, for `navguard convert` and `experiment raim`.
//! - [`service`]: the async edge: sockets and REST (axum), one actor task per
//!   session, the SQLite store, auth and limits.
//! - the `navguard` binary (`src/main.rs`, `src/cli/`): the CLI.

pub mod service;
