//! REST handlers, one file per route group. Handlers validate, call the
//! session handle or the store, and shape the response; no algorithm lives here.

pub mod alarms;
pub mod audit;
pub mod chi2;
pub mod features;
pub mod health;
pub mod models;
pub mod recording;
pub mod sessions;
pub mod thresholds;
pub mod whoami;
