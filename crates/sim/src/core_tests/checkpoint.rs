//! The unit tests of `navguard_core::monitor::checkpoint` (moved out of the core: most of
//! them step monitors on simulated scenarios).

#[allow(unused_imports)]
use navguard_core::monitor::MonitorKind;
#[allow(unused_imports)]
use navguard_core::monitor::checkpoint::*;

mod refusal_tests;
mod tests;
