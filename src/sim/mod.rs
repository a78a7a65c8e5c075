//! Simulation: trajectories, sensor models, fault injection, the papers'
//! scenarios and experiment scorecards. Pure: produces epochs and truth.

pub mod experiment;
