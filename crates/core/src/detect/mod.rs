//! Detectors: the χ² core, test statistics and the decision policies that turn
//! statistics into health states. Sits between the filters (which yield
//! innovations) and the monitors (which wire filters and detectors together).

pub mod chi2;
pub mod consistency;
pub mod f_law;
pub mod hpl;
pub mod parity;
pub mod policy;
pub mod statistic;
pub mod stuck;
pub mod ta;
pub mod window;

pub use policy::{Decision, Health, PolicyConfig, PolicyError, PolicyState};
pub use statistic::{Statistic, ThresholdError, ThresholdSpec};
pub use ta::{TaError, TaParams, TaStatistic};
