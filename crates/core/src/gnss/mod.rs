//! GNSS positioning and integrity from pseudoranges (docs/methods.md §M26–§M28):
//! corrections, weighted least squares with one clock per constellation, RAIM fault
//! detection and exclusion, and protection levels (slope RAIM and ARAIM). Pure
//! functions on one epoch's measurements; the `gnss` monitor keeps the state between
//! epochs.
//!
//! - [`correct`]: Sagnac rotation, elevation/azimuth, Saastamoinen troposphere, the
//!   corrected pseudorange.
//! - [`wls`]: iterated weighted least squares (position and one clock per
//!   constellation), DOPs, residuals and their w-tests.
//! - [`raim`]: the residual χ² test, fault detection and exclusion, slope protection
//!   levels.
//! - [`araim`]: ARAIM by solution separation: fault modes, protection levels, the
//!   separation tests and exclusion.

pub mod araim;
pub mod correct;
pub mod raim;
pub mod wls;

#[cfg(test)]
mod raim_tests;
#[cfg(test)]
pub(crate) mod testdata;
#[cfg(test)]
mod wls_tests;
