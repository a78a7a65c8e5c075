//! GNSS positioning and integrity from pseudoranges (docs/methods.md §M20–§M22):
//! corrections, weighted least squares with one clock per constellation, RAIM fault
//! detection and exclusion, and protection levels (slope RAIM and ARAIM). Pure
//! functions on one epoch's measurements; the `gnss` monitor keeps the state between
//! epochs.

pub mod araim;
