//! Tests of `navguard_core` that need the simulator or the experiments (a crate cannot
//! dev-depend on a crate that depends on it without getting a second copy of its types).

mod checkpoint;
mod rimu;
mod tacan;
