//! TACAN window features (DESIGN §3.8, seed 003): per window of `K` samples,
//! mean, variance, shape factor and crest factor of the centred window for the
//! INS-derived and the measured range; `X = |X_ins − X_tacan|`.
//! (Stub: filled in by the tacan work.)

use serde::{Deserialize, Serialize};

use super::FeatureError;

/// Parameters of the window features.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TacanFeatureParams {
    /// Window length K (default 10).
    pub window: usize,
    /// Include the crest factor (default false: mean, variance, shape factor).
    pub crest: bool,
}

/// The feature vector of one window (raw, not standardised).
pub fn window_features(
    _ins_range_m: &[f64],
    _tacan_range_m: &[f64],
    _params: &TacanFeatureParams,
) -> Result<Vec<f64>, FeatureError> {
    Err(FeatureError::new(
        "tacan",
        "tacan features are not implemented yet",
    ))
}

/// Feature vectors of every sliding window (step 1) over two equally long series.
pub fn series_features(
    _ins_range_m: &[f64],
    _tacan_range_m: &[f64],
    _params: &TacanFeatureParams,
) -> Result<Vec<Vec<f64>>, FeatureError> {
    Err(FeatureError::new(
        "tacan",
        "tacan features are not implemented yet",
    ))
}
