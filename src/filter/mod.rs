//! Filters: the generic Kalman filter every monitor uses (and, with the
//! federated monitor, the INS error model, aiding models and federated fusion).

pub mod kalman;
