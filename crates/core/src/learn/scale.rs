//! Standardisation (docs/methods.md §M8): every model kind standardises its inputs (and
//! regression targets) with the training set's mean and standard deviation unless
//! `"standardize": false`; the statistics are stored with the model so predictions
//! come back in the original units.

use serde::{Deserialize, Serialize};

/// Per-column mean and standard deviation of a training set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Standardizer {
    /// Column means.
    pub mean: Vec<f64>,
    /// Column standard deviations (sample, n − 1); a constant column gets 1 so it
    /// maps to 0 rather than dividing by zero.
    pub std: Vec<f64>,
}

impl Standardizer {
    /// Fits the statistics of the columns of `rows` (each row one sample).
    pub fn fit<'a>(rows: impl IntoIterator<Item = &'a [f64]>) -> Self {
        let mut n = 0usize;
        let mut mean: Vec<f64> = Vec::new();
        let mut m2: Vec<f64> = Vec::new();
        for row in rows {
            if n == 0 {
                mean = vec![0.0; row.len()];
                m2 = vec![0.0; row.len()];
            }
            n += 1;
            // Welford: stable in one pass.
            for (j, &v) in row.iter().enumerate() {
                let delta = v - mean[j];
                mean[j] += delta / n as f64;
                m2[j] += delta * (v - mean[j]);
            }
        }
        let std = m2
            .iter()
            .map(|&s| {
                let sd = if n > 1 {
                    (s / (n - 1) as f64).sqrt()
                } else {
                    0.0
                };
                if sd > 0.0 && sd.is_finite() { sd } else { 1.0 }
            })
            .collect();
        Standardizer { mean, std }
    }

    /// The identity transform of dimension `d` (for `"standardize": false`).
    pub fn identity(d: usize) -> Self {
        Standardizer {
            mean: vec![0.0; d],
            std: vec![1.0; d],
        }
    }

    /// Dimension.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Standardises `x` in place.
    pub fn apply(&self, x: &mut [f64]) {
        for ((v, m), s) in x.iter_mut().zip(&self.mean).zip(&self.std) {
            *v = (*v - m) / s;
        }
    }

    /// Standardised copy of `x`.
    pub fn applied(&self, x: &[f64]) -> Vec<f64> {
        let mut out = x.to_vec();
        self.apply(&mut out);
        out
    }

    /// Maps a standardised scalar of column `j` back to original units.
    pub fn invert(&self, j: usize, v: f64) -> f64 {
        v * self.std[j] + self.mean[j]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn standardised_columns_have_zero_mean_and_unit_sample_std() {
        let rows = [vec![1.0, 10.0], vec![2.0, 10.0], vec![3.0, 10.0]];
        let s = Standardizer::fit(rows.iter().map(|r| r.as_slice()));
        assert_relative_eq!(s.mean[0], 2.0);
        assert_relative_eq!(s.std[0], 1.0);
        // A constant column maps to 0, not NaN.
        assert_eq!(s.std[1], 1.0);
        assert_eq!(s.applied(&[3.0, 10.0]), vec![1.0, 0.0]);
        assert_relative_eq!(s.invert(0, 1.0), 3.0);
    }
}
