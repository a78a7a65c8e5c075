//! Consistency diagnostics of one test (docs/methods.md §M22): is the model behind the
//! test tuned as it claims? Fed the *normalised* innovation `ν` of each healthy epoch
//! (for a Kalman test `ν = L⁻¹ r` with `S = L Lᵀ`, so `‖ν‖² = λ`, the NIS; for a
//! predictor's residual, `r` scaled by its healthy variance), over the last `window`
//! epochs it reports:
//!
//! - the **NIS mean** `mean ‖ν‖²` against its dof d. With N epochs `Σ‖ν‖² ~ χ²(N d)`
//!   under a consistent model; above the upper bound the innovations are larger than the
//!   model believes (**overconfident**: Q or R too small), below the lower bound smaller
//!   (**underconfident**);
//! - the **lag-1 autocorrelation** `ρ₁ = Σ ν_kᵀ ν_{k−1} / Σ ‖ν_k‖²` over consecutive
//!   healthy epochs. Under a consistent model the innovations are white and
//!   `ρ₁ ≈ N(0, 1/(N_lag d))`; beyond the bound they are **correlated** (unmodelled
//!   dynamics, a scale-factor error, a mis-set correlation time).
//!
//! Bounds are two-sided at [`CONFIDENCE`] (99.9 %): a sliding window re-evaluated every
//! epoch is flagged about 0.1 % of the time on a consistent model. The flag reads
//! `overconfident`, `underconfident`, `correlated` or `ok`, in that order of precedence,
//! and is absent until [`MIN_SAMPLES`] epochs have been seen. Epochs that are not
//! healthy are left out (a fault is not mis-tuning) and break the lag chain.

use std::collections::VecDeque;
use std::sync::OnceLock;

use serde::{Deserialize, Serialize};

use super::chi2;

/// Epochs in the sliding window.
pub const DEFAULT_WINDOW: usize = 100;
/// Epochs before a flag is given.
pub const MIN_SAMPLES: usize = 30;
/// Two-sided confidence of the bounds.
pub const CONFIDENCE: f64 = 0.999;
/// Each tail's share of `1 −` [`CONFIDENCE`].
const HALF_ALPHA: f64 = 0.0005;
/// The normal quantile of the two-sided bound, Φ⁻¹(1 − 0.0005).
const Z_BOUND: f64 = 3.290_526_731_491_926;

/// The verdict on a model's tuning.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConsistencyFlag {
    /// Within every bound.
    Ok,
    /// NIS mean above its bound: innovations larger than the model's covariance.
    Overconfident,
    /// NIS mean below its bound: innovations smaller than the model's covariance.
    Underconfident,
    /// Lag-1 autocorrelation beyond its bound.
    Correlated,
}

/// What the diagnostics show now.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ConsistencySummary {
    /// Epochs in the window.
    pub samples: usize,
    /// Degrees of freedom of one epoch's `‖ν‖²`.
    pub dof: u32,
    /// `mean ‖ν‖²` (dof under a consistent model).
    pub nis_mean: f64,
    /// The bounds of `nis_mean` at [`CONFIDENCE`].
    pub nis_bounds: [f64; 2],
    /// Lag-1 autocorrelation of ν (`None` with fewer than two consecutive epochs).
    pub autocorr: Option<f64>,
    /// `|autocorr|` above this is `correlated`.
    pub autocorr_bound: f64,
    /// The verdict (`None` until [`MIN_SAMPLES`] epochs).
    pub flag: Option<ConsistencyFlag>,
}

/// The running diagnostics of one test (serde: a monitor checkpoint saves them, the
/// cached bounds included).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Consistency {
    window: usize,
    /// Per epoch in the window: `‖ν‖²` and, when the previous epoch was in it too,
    /// `ν_kᵀ ν_{k−1}`.
    entries: VecDeque<(f64, Option<f64>)>,
    nis_sum: f64,
    lag_sum: f64,
    lag_count: usize,
    /// ν of the previous epoch, if it was healthy.
    previous: Option<Vec<f64>>,
    dof: u32,
    /// NIS bounds cached for `(samples, dof)`.
    bounds: Option<(usize, u32, [f64; 2])>,
    /// Epochs observed since the sums were last recomputed.
    since_resum: usize,
}

impl Default for Consistency {
    fn default() -> Self {
        Consistency::new(DEFAULT_WINDOW)
    }
}

impl Consistency {
    /// Diagnostics over the last `window` healthy epochs (≥ [`MIN_SAMPLES`]).
    pub fn new(window: usize) -> Self {
        let window = window.max(MIN_SAMPLES);
        Consistency {
            window,
            // Grown as epochs come: an idle session holds no window.
            entries: VecDeque::new(),
            nis_sum: 0.0,
            lag_sum: 0.0,
            lag_count: 0,
            previous: None,
            dof: 0,
            bounds: None,
            since_resum: 0,
        }
    }

    /// Forgets everything (a new stream).
    pub fn reset(&mut self) {
        *self = Consistency::new(self.window);
    }

    /// `saved` (read from a checkpoint) as diagnostics of this one's window, with the
    /// capacity [`Consistency::new`] reserves (so observing allocates nothing); the
    /// reason when it does not fit: another window, more entries than it, running
    /// counts that disagree with the entries, a previous ν not of the dof.
    pub fn restored(&self, mut saved: Consistency) -> Result<Consistency, String> {
        if saved.window != self.window {
            return Err(format!(
                "consistency window {}, the test's is {}",
                saved.window, self.window
            ));
        }
        let lags = saved.entries.iter().filter(|e| e.1.is_some()).count();
        let previous_fits = saved
            .previous
            .as_ref()
            .is_none_or(|p| p.len() == saved.dof as usize && !p.is_empty());
        if saved.entries.len() > saved.window
            || saved.lag_count != lags
            || saved.since_resum >= saved.window
            || !previous_fits
        {
            return Err("consistency diagnostics are inconsistent".into());
        }
        saved
            .entries
            .reserve((saved.window + 1).saturating_sub(saved.entries.len()));
        Ok(saved)
    }

    /// Takes one healthy epoch's normalised innovation. A change of dimension (GNSS with
    /// and without velocity) restarts the window, as the two are not comparable.
    pub fn observe(&mut self, nu: &[f64]) {
        if nu.is_empty() || nu.iter().any(|v| !v.is_finite()) {
            self.interrupt();
            return;
        }
        let dof = nu.len() as u32;
        if dof != self.dof {
            let window = self.window;
            *self = Consistency::new(window);
            self.dof = dof;
        }
        let nis: f64 = nu.iter().map(|v| v * v).sum();
        let lag = self
            .previous
            .as_ref()
            .map(|p| p.iter().zip(nu).map(|(a, b)| a * b).sum::<f64>());
        if self.entries.len() >= self.window
            && let Some((old_nis, old_lag)) = self.entries.pop_front()
        {
            self.nis_sum -= old_nis;
            if let Some(l) = old_lag {
                self.lag_sum -= l;
                self.lag_count -= 1;
            }
        }
        self.entries.push_back((nis, lag));
        self.nis_sum += nis;
        if let Some(l) = lag {
            self.lag_sum += l;
            self.lag_count += 1;
        }
        match &mut self.previous {
            Some(p) => p.copy_from_slice(nu),
            None => self.previous = Some(nu.to_vec()),
        }
        // Recompute the sums once per window so removals carry no round-off.
        self.since_resum += 1;
        if self.since_resum >= self.window {
            self.resum();
        }
    }

    /// An epoch that is not used (the test did not run healthy): the lag chain breaks.
    pub fn interrupt(&mut self) {
        self.previous = None;
    }

    fn resum(&mut self) {
        self.since_resum = 0;
        self.nis_sum = self.entries.iter().map(|e| e.0).sum();
        self.lag_sum = self.entries.iter().filter_map(|e| e.1).sum();
        self.lag_count = self.entries.iter().filter(|e| e.1.is_some()).count();
    }

    /// The diagnostics now; `None` before the first epoch. Updates the bound cache.
    pub fn summary(&mut self) -> Option<ConsistencySummary> {
        let n = self.entries.len();
        if n == 0 {
            return None;
        }
        let d = self.dof;
        let bounds = match self.bounds {
            Some((bn, bd, b)) if bn == n && bd == d => b,
            _ => {
                let b = nis_bounds(n, d);
                self.bounds = Some((n, d, b));
                b
            }
        };
        let nis_mean = self.nis_sum / n as f64;
        let autocorr = (self.lag_count > 1 && self.nis_sum > 0.0)
            .then(|| self.lag_sum / (self.nis_sum * self.lag_count as f64 / n as f64));
        let autocorr_bound = Z_BOUND / ((self.lag_count.max(1) as f64) * f64::from(d)).sqrt();
        let flag = (n >= MIN_SAMPLES).then(|| {
            if nis_mean > bounds[1] {
                ConsistencyFlag::Overconfident
            } else if nis_mean < bounds[0] {
                ConsistencyFlag::Underconfident
            } else if autocorr.is_some_and(|r| r.abs() > autocorr_bound) {
                ConsistencyFlag::Correlated
            } else {
                ConsistencyFlag::Ok
            }
        });
        Some(ConsistencySummary {
            samples: n,
            dof: d,
            nis_mean,
            nis_bounds: bounds,
            autocorr,
            autocorr_bound,
            flag,
        })
    }
}

/// `[χ²_{α/2}(N d), χ²_{1−α/2}(N d)] / N` with `α = 1 −` [`CONFIDENCE`].
fn nis_bounds(n: usize, d: u32) -> [f64; 2] {
    let dof = (n as u32).saturating_mul(d.max(1));
    let [lo, hi] = nis_quantiles(dof);
    [lo / n as f64, hi / n as f64]
}

/// Total degrees of freedom whose quantiles [`nis_quantiles`] keeps, shared by every
/// session (a window of 100 epochs of a 3-component test is 300).
const SHARED_DOF: usize = 2048;

/// The χ²(`dof`) quantiles at `1 − HALF_ALPHA` and `HALF_ALPHA`. While a window fills,
/// each publication of a session's statistics asks for a new `dof` per test; a stream's
/// first seconds asked for the same few hundred inversions in every session, so they are
/// computed once per process (the same numbers: a table of what `chi2::threshold` says).
fn nis_quantiles(dof: u32) -> [f64; 2] {
    static SHARED: [OnceLock<[f64; 2]>; SHARED_DOF] = [const { OnceLock::new() }; SHARED_DOF];
    let compute = || {
        [
            chi2::threshold(dof, 1.0 - HALF_ALPHA).unwrap_or(0.0),
            chi2::threshold(dof, HALF_ALPHA).unwrap_or(f64::INFINITY),
        ]
    };
    match SHARED.get(dof as usize) {
        Some(cell) => *cell.get_or_init(compute),
        None => compute(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, StandardNormal};

    /// Feeds `epochs` of `dim`-component AR(1) innovations `ν = φ ν₋₁ + g e` scaled by
    /// `scale` and returns the share of epochs (after the first window) with each flag.
    fn flag_shares(scale: f64, phi: f64, dim: usize, epochs: usize, seed: u64) -> [f64; 4] {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut c = Consistency::default();
        let mut nu = vec![0.0; dim];
        let g = (1.0 - phi * phi).sqrt();
        let mut counts = [0usize; 4];
        let mut seen = 0;
        for k in 0..epochs {
            for v in nu.iter_mut() {
                let e: f64 = StandardNormal.sample(&mut rng);
                *v = phi * *v + g * e;
            }
            let scaled: Vec<f64> = nu.iter().map(|v| v * scale).collect();
            c.observe(&scaled);
            if k >= DEFAULT_WINDOW {
                seen += 1;
                let i = match c.summary().unwrap().flag.unwrap() {
                    ConsistencyFlag::Ok => 0,
                    ConsistencyFlag::Overconfident => 1,
                    ConsistencyFlag::Underconfident => 2,
                    ConsistencyFlag::Correlated => 3,
                };
                counts[i] += 1;
            }
        }
        counts.map(|n| n as f64 / seen as f64)
    }

    #[test]
    fn a_consistent_model_is_ok_almost_always() {
        for (dim, seed) in [(1, 1), (3, 2)] {
            let s = flag_shares(1.0, 0.0, dim, 20_000, seed);
            // Three bounds at 99.9 % each; sliding windows cluster the excursions.
            assert!(s[0] > 0.98, "dim {dim}: {s:?}");
        }
    }

    #[test]
    fn mis_tuned_models_are_named() {
        // Innovations 1.5× larger than S says (R too small by 2.25).
        assert!(flag_shares(1.5, 0.0, 2, 5_000, 3)[1] > 0.99);
        // Innovations half what S says.
        assert!(flag_shares(0.5, 0.0, 2, 5_000, 4)[2] > 0.99);
        // Right size but correlated (φ = 0.6): ρ₁ ≈ 0.6 against a bound of ≈ 0.23.
        assert!(flag_shares(1.0, 0.6, 2, 5_000, 5)[3] > 0.95);
    }

    #[test]
    fn bounds_and_autocorrelation_by_hand() {
        let mut c = Consistency::new(30);
        // ν alternating +1, −1: NIS 1 each, ρ₁ = −1.
        for k in 0..40 {
            c.observe(&[if k % 2 == 0 { 1.0 } else { -1.0 }]);
        }
        let s = c.summary().unwrap();
        assert_eq!(s.samples, 30);
        assert_eq!(s.dof, 1);
        assert!((s.nis_mean - 1.0).abs() < 1e-15);
        assert!((s.autocorr.unwrap() + 1.0).abs() < 1e-12);
        // χ²(30) at 0.0005 and 0.9995, over 30.
        let lo = chi2::threshold(30, 0.9995).unwrap() / 30.0;
        let hi = chi2::threshold(30, 0.0005).unwrap() / 30.0;
        assert_eq!(s.nis_bounds, [lo, hi]);
        assert_eq!(s.flag, Some(ConsistencyFlag::Correlated));
    }

    #[test]
    fn shared_quantiles_are_the_inversions_themselves() {
        // In the table, at its edge, past it, and asked twice (the second from the table).
        for dof in [
            1,
            2,
            3,
            29,
            300,
            SHARED_DOF as u32 - 1,
            SHARED_DOF as u32,
            5_000,
        ] {
            let direct = [
                chi2::threshold(dof, 1.0 - HALF_ALPHA).unwrap(),
                chi2::threshold(dof, HALF_ALPHA).unwrap(),
            ];
            assert_eq!(nis_quantiles(dof), direct, "dof {dof}");
            assert_eq!(nis_quantiles(dof), direct, "dof {dof}, again");
        }
        assert!(nis_quantiles(300)[0] < 300.0 && nis_quantiles(300)[1] > 300.0);
    }

    #[test]
    fn interruptions_break_the_lag_chain_and_a_new_dimension_restarts() {
        let mut c = Consistency::new(30);
        c.observe(&[1.0]);
        c.interrupt();
        c.observe(&[1.0]);
        assert_eq!(c.lag_count, 0);
        c.observe(&[1.0]);
        assert_eq!(c.lag_count, 1);
        c.observe(&[1.0, 2.0]);
        let s = c.summary().unwrap();
        assert_eq!((s.samples, s.dof, s.flag), (1, 2, None));
        assert!((s.nis_mean - 5.0).abs() < 1e-15);
        c.observe(&[f64::NAN, 0.0]);
        assert_eq!(c.summary().unwrap().samples, 1);
    }
}
