//! Detectors: the χ² core, test statistics and the decision policies that turn
//! statistics into health states. Sits between the filters (which yield
//! innovations) and the monitors (which wire filters and detectors together).

pub mod chi2;
pub mod hpl;
pub mod parity;
pub mod policy;
pub mod statistic;
pub mod ta;

pub use policy::{Decision, Health, PolicyConfig, PolicyError, PolicyState};
pub use statistic::{Statistic, ThresholdError, ThresholdSpec};
pub use ta::{TaError, TaParams, TaStatistic};
