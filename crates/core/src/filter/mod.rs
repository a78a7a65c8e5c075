//! Filters: the generic Kalman filter every monitor uses (and, with the
//! federated monitor, the INS error model, aiding models and federated fusion).
//!
//! Data flow inside the layer: [`ins`] linearises the INS error dynamics about each
//! INS epoch, [`aiding`] turns an aid's fix into an INS-minus-aid measurement `(z, H, R)`,
//! and [`federated`] runs one [`kalman`] filter per aid and fuses them.

pub mod aiding;
pub mod federated;
pub mod ins;
pub mod kalman;
