//! TACAN window features (docs/methods.md §M18, seed 003 §1): per window of `K` samples,
//! mean, variance, shape factor and crest factor of the centred window for the
//! INS-derived and the measured range; `X = |X_ins − X_tacan|` (seed 003 eq. 6).
//! Computed here for the `tacan` monitor, the seed 003 experiment and
//! `POST /api/v1/features` alike, so all three see the same vectors.
//!
//! # Definitions
//! For a window `x₁…x_K` with mean `m` and centred values `c_i = x_i − m`:
//! - mean `m`;
//! - variance `(1/K) Σ c_i²` (the population form: the window is the whole
//!   sample being described, not an estimate of a wider one);
//! - shape factor `rms(c) / mean(|c|)` with `rms(c) = √((1/K) Σ c_i²)`;
//! - crest factor `max|c_i| / rms(c)`.
//!
//! Both factors are scale-free and at least 1 (Cauchy–Schwarz, and max ≥ rms).
//! **Degenerate window**: when every `c_i` is 0 (a constant window, e.g. a
//! stationary aircraft with a noise-free range) both ratios are 0/0; they are
//! defined as 1, their lower bound, reached by any two-level window `±a` — the
//! least peaked shape a non-constant window can have. The features stay finite
//! and a constant window never looks like a spike.
//!
//! # Standardisation
//! The vectors returned here are raw (metres, m², unitless). Standardisation
//! with the training set's mean and standard deviation (docs/methods.md §M18) is done by
//! the model: `learn`'s [`Standardizer`](crate::learn::Standardizer) is fitted
//! when the one-class model is trained (`"standardize": true`, the default) and
//! stored with it, so the monitor feeds these raw vectors to the model.

use serde::{Deserialize, Serialize};

use super::FeatureError;

/// Parameters of the window features.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TacanFeatureParams {
    /// Window length K (default 10, seed 003 §4).
    #[serde(default = "default_window")]
    pub window: usize,
    /// Include the crest factor (default false: mean, variance, shape factor, the
    /// paper's selection).
    #[serde(default)]
    pub crest: bool,
}

fn default_window() -> usize {
    10
}

impl Default for TacanFeatureParams {
    fn default() -> Self {
        TacanFeatureParams {
            window: default_window(),
            crest: false,
        }
    }
}

impl TacanFeatureParams {
    /// Number of features: 3, or 4 with the crest factor.
    pub fn dim(&self) -> usize {
        if self.crest { 4 } else { 3 }
    }

    /// Validates the parameters (`window` ≥ 2: one sample has no shape).
    pub fn check(&self) -> Result<(), FeatureError> {
        if self.window < 2 {
            return Err(FeatureError::new(
                "window",
                format!("must be at least 2, got {}", self.window),
            ));
        }
        Ok(())
    }
}

/// The time-domain features of one window: `[mean, variance, shape, (crest)]`.
fn describe(x: &[f64], crest: bool, out: &mut [f64]) {
    let k = x.len() as f64;
    let mean = x.iter().sum::<f64>() / k;
    let (mut sq, mut abs, mut peak) = (0.0, 0.0, 0.0f64);
    for &v in x {
        let c = v - mean;
        sq += c * c;
        abs += c.abs();
        peak = peak.max(c.abs());
    }
    let var = sq / k;
    let rms = var.sqrt();
    let mean_abs = abs / k;
    // Degenerate window (module doc): both ratios take their lower bound 1.
    let degenerate = !(rms > 0.0 && mean_abs > 0.0);
    out[0] = mean;
    out[1] = var;
    out[2] = if degenerate { 1.0 } else { rms / mean_abs };
    if crest {
        out[3] = if degenerate { 1.0 } else { peak / rms };
    }
}

/// Refuses a series with a non-finite sample, naming it (`ins_range_m[3]`).
fn check_finite(field: &str, x: &[f64], offset: usize) -> Result<(), FeatureError> {
    match x.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(FeatureError::new(
            format!("{field}[{}]", i + offset),
            "must be a finite number",
        )),
        None => Ok(()),
    }
}

/// Checks the pair of series: equal lengths, at least one window, finite.
fn check_series(
    ins: &[f64],
    tacan: &[f64],
    params: &TacanFeatureParams,
) -> Result<(), FeatureError> {
    params.check()?;
    if ins.len() != tacan.len() {
        return Err(FeatureError::new(
            "tacan_range_m",
            format!(
                "has {} samples, ins_range_m has {}: the series must be equally long",
                tacan.len(),
                ins.len()
            ),
        ));
    }
    if ins.len() < params.window {
        return Err(FeatureError::new(
            "ins_range_m",
            format!(
                "has {} samples, shorter than the window of {}",
                ins.len(),
                params.window
            ),
        ));
    }
    check_finite("ins_range_m", ins, 0)?;
    check_finite("tacan_range_m", tacan, 0)
}

/// `X = |X_ins − X_tacan|` of one window, written into `out` (length `params.dim()`).
/// Inputs are assumed checked.
fn window_into(ins: &[f64], tacan: &[f64], crest: bool, out: &mut [f64]) {
    let mut a = [0.0; 4];
    let mut b = [0.0; 4];
    describe(ins, crest, &mut a);
    describe(tacan, crest, &mut b);
    for (j, o) in out.iter_mut().enumerate() {
        // seed 003 eq. 6.
        *o = (a[j] - b[j]).abs();
    }
}

/// The feature vector of one window (raw, not standardised): both series must hold
/// exactly `params.window` finite samples.
pub fn window_features(
    ins_range_m: &[f64],
    tacan_range_m: &[f64],
    params: &TacanFeatureParams,
) -> Result<Vec<f64>, FeatureError> {
    check_series(ins_range_m, tacan_range_m, params)?;
    if ins_range_m.len() != params.window {
        return Err(FeatureError::new(
            "ins_range_m",
            format!(
                "has {} samples, a window holds exactly {}",
                ins_range_m.len(),
                params.window
            ),
        ));
    }
    let mut out = vec![0.0; params.dim()];
    window_into(ins_range_m, tacan_range_m, params.crest, &mut out);
    Ok(out)
}

/// Feature vectors of every sliding window (step 1, seed 003 eqs. 4–5) over two
/// equally long series: `n − K + 1` vectors, the `i`-th over samples `i..i+K`.
pub fn series_features(
    ins_range_m: &[f64],
    tacan_range_m: &[f64],
    params: &TacanFeatureParams,
) -> Result<Vec<Vec<f64>>, FeatureError> {
    check_series(ins_range_m, tacan_range_m, params)?;
    let k = params.window;
    Ok(ins_range_m
        .windows(k)
        .zip(tacan_range_m.windows(k))
        .map(|(a, b)| {
            let mut out = vec![0.0; params.dim()];
            window_into(a, b, params.crest, &mut out);
            out
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn params(window: usize, crest: bool) -> TacanFeatureParams {
        TacanFeatureParams { window, crest }
    }

    #[test]
    fn defaults_are_a_window_of_ten_without_the_crest_factor() {
        let p: TacanFeatureParams = serde_json::from_str("{}").unwrap();
        assert_eq!(p, params(10, false));
        assert_eq!((p.dim(), params(10, true).dim()), (3, 4));
        assert!(serde_json::from_str::<TacanFeatureParams>(r#"{"windw": 3}"#).is_err());
    }

    #[test]
    fn features_match_hand_computed_values() {
        // ins = [0, 0, 0, 4]: mean 1, c = [−1, −1, −1, 3], Σc² = 12, var 3, rms √3,
        // mean|c| = 6/4 = 1.5, shape √3/1.5, crest 3/√3 = √3.
        // tacan = [1, 3, 1, 3]: mean 2, c = ±1, var 1, rms 1, mean|c| 1, shape 1, crest 1.
        let x = window_features(
            &[0.0, 0.0, 0.0, 4.0],
            &[1.0, 3.0, 1.0, 3.0],
            &params(4, true),
        )
        .unwrap();
        assert_relative_eq!(x[0], 1.0);
        assert_relative_eq!(x[1], 2.0);
        assert_relative_eq!(x[2], 3f64.sqrt() / 1.5 - 1.0, epsilon = 1e-15);
        assert_relative_eq!(x[3], 3f64.sqrt() - 1.0, epsilon = 1e-15);
        let y = window_features(
            &[0.0, 0.0, 0.0, 4.0],
            &[1.0, 3.0, 1.0, 3.0],
            &params(4, false),
        )
        .unwrap();
        assert_eq!(y, x[..3].to_vec());
    }

    #[test]
    fn a_shared_trend_cancels_and_a_spike_shows_in_variance_and_shape() {
        // A linear ramp (the aircraft closing on the station) is common to both series.
        let ins: Vec<f64> = (0..10).map(|i| 1000.0 + 8.0 * i as f64).collect();
        let mut tacan = ins.clone();
        let x = window_features(&ins, &tacan, &params(10, false)).unwrap();
        assert_eq!(x, vec![0.0, 0.0, 0.0]);
        // A 150 m jump on one sample: the mean moves by 15 m; the variance of the
        // centred spike alone is 150² · (1/10)(9/10) = 2025 m², plus the ramp's cross term.
        tacan[4] += 150.0;
        let x = window_features(&ins, &tacan, &params(10, false)).unwrap();
        assert_relative_eq!(x[0], 15.0, epsilon = 1e-12);
        // Cross term: 2 · (1/10) Σ r_i s_i with r the centred ramp and s the centred
        // spike: s = 150·(e₅ − 1/10) and Σ r_i = 0, so (2/10) · 150 · r₅ = 30 · (−4) = −120.
        assert_relative_eq!(x[1], 2025.0 - 120.0, epsilon = 1e-9);
        assert!(x[2] > 0.1);
    }

    #[test]
    fn a_constant_window_has_unit_shape_and_crest_factors() {
        let x = window_features(&[5.0; 3], &[7.0, 9.0, 8.0], &params(3, true)).unwrap();
        // tacan: mean 8, c = [−1, 1, 0], var 2/3, rms √(2/3), mean|c| 2/3.
        assert_relative_eq!(x[0], 3.0);
        assert_relative_eq!(x[1], 2.0 / 3.0, epsilon = 1e-15);
        assert_relative_eq!(
            x[2],
            (2f64 / 3.0).sqrt() / (2.0 / 3.0) - 1.0,
            epsilon = 1e-15
        );
        assert_relative_eq!(x[3], 1.0 / (2f64 / 3.0).sqrt() - 1.0, epsilon = 1e-15);
        assert!(x.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn series_gives_one_vector_per_sliding_window() {
        let ins = [0.0, 1.0, 2.0, 3.0, 4.0];
        let tacan = [0.0, 1.0, 2.0, 3.0, 14.0];
        let all = series_features(&ins, &tacan, &params(3, false)).unwrap();
        assert_eq!(all.len(), 3);
        assert_eq!(all[0], vec![0.0, 0.0, 0.0]);
        for (i, v) in all.iter().enumerate() {
            let w = window_features(&ins[i..i + 3], &tacan[i..i + 3], &params(3, false)).unwrap();
            assert_eq!(v, &w);
        }
        // Last window: tacan [2, 3, 14], mean 19/3 vs 3.
        assert_relative_eq!(all[2][0], 10.0 / 3.0, epsilon = 1e-12);
    }

    #[test]
    fn bad_inputs_are_refused_naming_the_field() {
        let p = params(3, false);
        fn field<T: std::fmt::Debug>(r: Result<T, FeatureError>) -> String {
            r.unwrap_err().field
        }
        assert_eq!(
            field(series_features(&[1.0; 4], &[1.0; 5], &p)),
            "tacan_range_m"
        );
        assert_eq!(
            field(series_features(&[1.0; 2], &[1.0; 2], &p)),
            "ins_range_m"
        );
        assert_eq!(
            field(series_features(&[1.0; 4], &[1.0; 4], &params(1, false))),
            "window"
        );
        assert_eq!(
            field(series_features(&[1.0, 2.0, f64::NAN, 3.0], &[1.0; 4], &p)),
            "ins_range_m[2]"
        );
        assert_eq!(
            field(window_features(&[1.0; 3], &[1.0, f64::INFINITY, 1.0], &p)),
            "tacan_range_m[1]"
        );
        assert_eq!(
            field(window_features(&[1.0; 4], &[1.0; 4], &p)),
            "ins_range_m"
        );
    }
}
