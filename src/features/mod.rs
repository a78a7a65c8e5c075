//! Features: time-domain window features (TACAN) and wavelet-packet energies
//! (redundant gyros), computed from raw series before the learned detectors.
//! Filled in with the rimu and tacan monitors.
