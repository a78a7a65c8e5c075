//! Geodesy (WGS84, LLA ↔ ECEF ↔ ENU, radii of curvature, Earth and transport
//! rates): the bottom of the core, used by the INS filters and the simulator.
//! Filled in with the federated monitor.
