//! Outlier pre-filter (seed 001 §2.2.1, made precise in docs/methods.md §M12), in front of the
//! online LS-SVM window: a new value whose third difference is too large for the
//! recent scatter is replaced by the cubic Newton extrapolation of the last four
//! accepted values before it enters the window.
//!
//! With `s` the sample standard deviation (n − 1) of the last 4 accepted values and
//! `Δ³ = x − 3x₋₁ + 3x₋₂ − x₋₃` the third difference ending at the new value `x`, the
//! value is an outlier when `|Δ³| > c·√20·s` (√20 is the standard-deviation factor of
//! a third difference of white noise: 1 + 9 + 9 + 1 = 20); it is then replaced by
//! `4x₋₁ − 6x₋₂ + 4x₋₃ − x₋₄` and counted. The first 4 values pass unchecked.
//!
//! As docs/methods.md §M12 specifies it, a genuine step much larger than the scatter is replaced
//! for as long as it lasts (the replacements become the history). Callers that must
//! follow real steps can bound that with [`OutlierFilter::with_max_run`].

use serde::{Deserialize, Serialize};

/// The filter's state: the last accepted values.
///
/// Serde: a monitor checkpoint saves it whole and [`OutlierFilter::restored`] checks it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct OutlierFilter {
    c: f64,
    /// Last 4 accepted values, oldest first (fewer at start-up).
    last: [f64; 4],
    seen: usize,
    replaced: u64,
    /// Consecutive replacements so far.
    run: usize,
    /// After this many consecutive replacements the next value is accepted as is
    /// (`None`: never, the rule of docs/methods.md §M12).
    max_run: Option<usize>,
}

impl OutlierFilter {
    /// A filter with threshold factor `c` (default 3). A non-finite or negative `c`
    /// is taken as 3.
    pub fn new(c: f64) -> Self {
        let c = if c.is_finite() && c >= 0.0 { c } else { 3.0 };
        OutlierFilter {
            c,
            last: [0.0; 4],
            seen: 0,
            replaced: 0,
            run: 0,
            max_run: None,
        }
    }

    /// Accept a value after `max_run` consecutive replacements, so a real step is
    /// followed after that many samples (an extension; the default never gives up).
    pub fn with_max_run(mut self, max_run: usize) -> Self {
        self.max_run = Some(max_run);
        self
    }

    /// The threshold factor.
    pub fn c(&self) -> f64 {
        self.c
    }

    /// Filters one value: returns the value to use and whether it was replaced.
    /// A non-finite value is always replaced once 4 values have been accepted.
    pub fn filter(&mut self, value: f64) -> (f64, bool) {
        if self.seen < 4 {
            self.accept(value);
            return (value, false);
        }
        let [x4, x3, x2, x1] = self.last;
        let d3 = value - 3.0 * x1 + 3.0 * x2 - x3;
        let mean = (x1 + x2 + x3 + x4) / 4.0;
        let var = [x1, x2, x3, x4]
            .iter()
            .map(|v| (v - mean).powi(2))
            .sum::<f64>()
            / 3.0;
        let limit = self.c * 20f64.sqrt() * var.sqrt();
        // A NaN Δ³ (non-finite input) counts as beyond the limit.
        let within = d3.abs() <= limit;
        let outlier = !within
            && !self
                .max_run
                .is_some_and(|m| self.run >= m && value.is_finite());
        if outlier {
            // seed 001 §2.2.1: cubic Newton extrapolation through the last four.
            let guess = 4.0 * x1 - 6.0 * x2 + 4.0 * x3 - x4;
            self.replaced += 1;
            self.run += 1;
            self.accept(guess);
            (guess, true)
        } else {
            self.run = 0;
            self.accept(value);
            (value, false)
        }
    }

    fn accept(&mut self, v: f64) {
        self.last.rotate_left(1);
        self.last[3] = v;
        self.seen += 1;
    }

    /// Values replaced so far.
    pub fn replaced(&self) -> u64 {
        self.replaced
    }

    /// `saved` (read from a checkpoint) as the running state of this filter: the same
    /// factor `c` and run limit; the reason otherwise.
    pub fn restored(&self, saved: OutlierFilter) -> Result<OutlierFilter, String> {
        if saved.c.to_bits() != self.c.to_bits() || saved.max_run != self.max_run {
            return Err(format!(
                "outlier filter with c = {}, the channel's has c = {}",
                saved.c, self.c
            ));
        }
        Ok(saved)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{SeedableRng, rngs::StdRng};
    use rand_distr::{Distribution, Normal};

    fn noisy_sine(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        let noise = Normal::new(0.0, 0.05).unwrap();
        (0..n)
            .map(|k| (k as f64 * 0.1).sin() + noise.sample(&mut rng))
            .collect()
    }

    #[test]
    fn clean_sinusoid_passes_untouched() {
        let mut f = OutlierFilter::new(3.0);
        for k in 0..2000 {
            let v = (k as f64 * 0.1).sin();
            assert_eq!(f.filter(v), (v, false), "k {k}");
        }
        assert_eq!(f.replaced(), 0);
    }

    #[test]
    fn injected_spikes_are_replaced_by_the_newton_extrapolation() {
        let clean = noisy_sine(600, 1);
        let spikes = [100, 250, 251, 400, 555];
        let mut f = OutlierFilter::new(3.0);
        let mut accepted: Vec<f64> = Vec::new();
        for (k, &v) in clean.iter().enumerate() {
            let input = if spikes.contains(&k) { v + 5.0 } else { v };
            let (out, replaced) = f.filter(input);
            if spikes.contains(&k) {
                assert!(replaced, "spike at {k} missed");
                let n = accepted.len();
                let (x1, x2, x3, x4) = (
                    accepted[n - 1],
                    accepted[n - 2],
                    accepted[n - 3],
                    accepted[n - 4],
                );
                assert_eq!(out, 4.0 * x1 - 6.0 * x2 + 4.0 * x3 - x4);
                assert!((out - v).abs() < 1.0, "replacement {out} far from {v}");
            }
            accepted.push(out);
        }
        // Gaussian noise at c = 3 also trips a few false replacements (|Δ³| beyond
        // 3σ-ish of a 4-sample scatter); the spikes must dominate.
        assert!(f.replaced() >= spikes.len() as u64);
        assert!(f.replaced() < 60, "{}", f.replaced());
    }

    #[test]
    fn max_run_lets_a_real_step_through() {
        let mut f = OutlierFilter::new(3.0).with_max_run(3);
        for k in 0..10 {
            f.filter(k as f64 * 0.01);
        }
        let outs: Vec<bool> = (0..5).map(|_| f.filter(50.0).1).collect();
        assert_eq!(outs, vec![true, true, true, false, false]);
        let mut strict = OutlierFilter::new(3.0);
        for k in 0..10 {
            strict.filter(k as f64 * 0.01);
        }
        assert!((0..5).all(|_| strict.filter(50.0).1));
    }
}
