//! Simulation: trajectories, sensor models, fault injection, the papers'
//! scenarios and experiment scorecards. Filled in with the federated monitor.
