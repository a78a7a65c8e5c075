//! The command-line tools beside `serve`: `simulate` writes a scenario as
//! ingest frames (JSON lines), `replay` streams such a file into a running
//! server, `loadgen` puts simulated load on one and measures it (DESIGN §5), and
//! `experiment` reruns the papers' experiments in-process.
//! Thin: parsing flags, files, sockets and printing; the algorithms live in
//! the library. `anyhow` is used here and in `main.rs` only.

pub mod experiment;
pub mod http;
pub mod loadgen;
pub mod progress;
pub mod replay;
pub mod simulate;
