//! Wavelet packet energies (DESIGN §3.7, seed 002): Daubechies db1–db4,
//! periodization, full decomposition to `level`, energies of the `2^level`
//! terminal nodes in natural order. (Stub: filled in by the rimu work.)

use serde::{Deserialize, Serialize};

use super::FeatureError;

/// The Daubechies wavelets available.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Wavelet {
    /// Haar.
    Db1,
    /// Daubechies 2.
    Db2,
    /// Daubechies 3.
    Db3,
    /// Daubechies 4.
    Db4,
}

/// Parameters of the packet energies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WaveletPacketParams {
    /// Wavelet (default db1... set by the rimu work).
    pub wavelet: Wavelet,
    /// Decomposition level (default 3).
    pub level: usize,
    /// Normalise the energies to sum 1 (default true).
    pub normalize: bool,
}

/// The `2^level` terminal-node energies of `signal` in natural order.
pub fn packet_energies(
    _signal: &[f64],
    _params: &WaveletPacketParams,
) -> Result<Vec<f64>, FeatureError> {
    Err(FeatureError::new(
        "signal",
        "wavelet packets are not implemented yet",
    ))
}
