//! The variance-collapse ("stuck sensor") test (docs/methods.md §M21): too little change
//! in a signal. A stuck or frozen sensor repeats its last value (seed 001's stuck fault,
//! a frozen GNSS fix), which no test on the signal's *level* can see once a predictor or
//! filter has followed it; its successive differences collapse to zero.
//!
//! - **Window**: `w = Σ ‖d_j‖² / (k·dim)` over the last `k` successive differences
//!   `d_j = x_j − x_{j−1}` of the input (whatever the health of their epochs, so a
//!   freeze is still seen while another test holds the signal suspect).
//! - **Reference**: the same mean square `ρ` over the last `max_reference` differences
//!   between two healthy epochs (frozen while not healthy), once there are
//!   `min_reference` of them.
//! - **Law**: for white inputs the squared differences of a window are correlated
//!   (adjacent differences have correlation −1/2), so `w/ρ` is referred to
//!   `F(ν(k)·dim, ν(R)·dim)` with the moment-matched (Satterthwaite) dof
//!   `ν(k) = k² / (k + (k − 1)/2)` (≈ 2k/3). The test's tail is the *lower* tail
//!   `F_F(w/ρ)`, reported as the χ²(1) value with that tail probability
//!   ([`super::window::chi2_equivalent`]), so it is compared with a χ²(1) threshold like
//!   any other test. Exact repeats give `w = 0`, the smallest tail, and a value of
//!   ≈ 1366 (the χ²(1) value of a 1e-300 tail).

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use super::f_law::FLaw;
use super::window::chi2_equivalent;

/// Default differences in the window (a freeze is flagged after about this many
/// repeated samples).
pub const DEFAULT_K: usize = 8;
/// Default healthy differences kept for the reference.
pub const DEFAULT_MAX_REFERENCE: usize = 500;
/// Default healthy differences needed before the test reports.
pub const DEFAULT_MIN_REFERENCE: usize = 50;
/// Default false-alarm probability of the test: a freeze is an exact condition that any
/// threshold catches, so the test can afford to be nearly silent on healthy data.
pub const DEFAULT_P_FA: f64 = 1e-6;

/// Why an input could not be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StuckError {
    /// The input does not have the test's dimension.
    #[error("input has {got} components, the test expects {want}")]
    Dimension {
        /// Components received.
        got: usize,
        /// Components expected.
        want: usize,
    },
    /// A component is NaN or infinite.
    #[error("input has a non-finite component")]
    NonFinite,
}

/// Parameters of a [`StuckTest`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct StuckParams {
    /// Input dimension (≥ 1).
    pub dim: usize,
    /// Differences in the window (≥ 2).
    pub k: usize,
    /// Healthy differences kept for the reference (≥ `min_reference`).
    pub max_reference: usize,
    /// Healthy differences before the test reports (≥ 2).
    pub min_reference: usize,
}

impl StuckParams {
    /// The defaults for inputs of dimension `dim`.
    pub fn new(dim: usize) -> Self {
        StuckParams {
            dim,
            k: DEFAULT_K,
            max_reference: DEFAULT_MAX_REFERENCE,
            min_reference: DEFAULT_MIN_REFERENCE,
        }
        .normalised()
    }

    fn normalised(self) -> Self {
        let min_reference = self.min_reference.max(2);
        StuckParams {
            dim: self.dim.max(1),
            k: self.k.max(2),
            max_reference: self.max_reference.max(min_reference),
            min_reference,
        }
    }
}

/// One evaluation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StuckValue {
    /// The χ²(1) value of the lower-tail probability: compared with the threshold.
    pub value: f64,
    /// `w / ρ`: the window's mean square difference relative to the healthy one.
    pub ratio: f64,
    /// The lower-tail probability of `ratio` under no fault.
    pub tail: f64,
}

/// The moment-matched dof of a sum of `k` squared successive differences of white noise.
fn effective_dof(k: usize) -> f64 {
    let k = k as f64;
    k * k / (k + (k - 1.0) / 2.0)
}

/// The running variance-collapse test of one signal (serde: a monitor checkpoint saves it
/// whole, parameters included, and [`StuckTest::restored`] checks it).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StuckTest {
    params: StuckParams,
    /// The previous input and whether its epoch was healthy.
    last: Option<(Vec<f64>, bool)>,
    /// `‖d‖²` of the last `k` differences.
    window: VecDeque<f64>,
    /// `‖d‖²` of the last healthy differences, and their sum.
    reference: VecDeque<f64>,
    reference_sum: f64,
    /// The F law of the window against the reference, renewed on commit (not saved: a
    /// restored test forms it again).
    #[serde(skip)]
    law: Option<FLaw>,
}

impl StuckTest {
    /// A fresh test.
    pub fn new(params: StuckParams) -> Self {
        let params = params.normalised();
        StuckTest {
            last: None,
            window: VecDeque::new(),
            reference: VecDeque::new(),
            reference_sum: 0.0,
            law: None,
            params,
        }
    }

    /// The parameters in force.
    pub fn params(&self) -> StuckParams {
        self.params
    }

    /// Back to the state of [`StuckTest::new`].
    pub fn reset(&mut self) {
        *self = StuckTest::new(self.params);
    }

    /// `saved` (read from a checkpoint) as the running state of this test: the same
    /// parameters, a previous input of the test's dimension, windows no longer than
    /// kept; with the capacities [`StuckTest::new`] reserves. The reason otherwise.
    pub fn restored(&self, mut saved: StuckTest) -> Result<StuckTest, String> {
        let p = self.params;
        if saved.params != p {
            return Err(format!(
                "stuck test of {} differences in {} dimensions, the test's has {} in {}",
                saved.params.k, saved.params.dim, p.k, p.dim
            ));
        }
        let fits = saved.last.as_ref().is_none_or(|(x, _)| x.len() == p.dim)
            && saved.window.len() <= p.k
            && saved.reference.len() <= p.max_reference;
        if !fits {
            return Err("stuck test state does not fit its parameters".into());
        }
        saved
            .window
            .reserve((p.k + 1).saturating_sub(saved.window.len()));
        saved
            .reference
            .reserve((p.max_reference + 1).saturating_sub(saved.reference.len()));
        Ok(saved)
    }

    fn check(&self, x: &[f64]) -> Result<(), StuckError> {
        if x.len() != self.params.dim {
            return Err(StuckError::Dimension {
                got: x.len(),
                want: self.params.dim,
            });
        }
        if x.iter().any(|v| !v.is_finite()) {
            return Err(StuckError::NonFinite);
        }
        Ok(())
    }

    fn squared_difference(&self, x: &[f64]) -> Option<f64> {
        self.last
            .as_ref()
            .map(|(prev, _)| x.iter().zip(prev).map(|(a, b)| (a - b) * (a - b)).sum())
    }

    /// The test with `x` as the newest input, changing nothing; `Ok(None)` until the
    /// window holds `k` differences and the reference `min_reference` (or when the
    /// reference is zero: a signal that never moves cannot collapse further).
    pub fn evaluate(&self, x: &[f64]) -> Result<Option<StuckValue>, StuckError> {
        self.check(x)?;
        let Some(newest) = self.squared_difference(x) else {
            return Ok(None);
        };
        let p = self.params;
        let skip = usize::from(self.window.len() >= p.k);
        if self.window.len() + 1 - skip < p.k || self.reference.len() < p.min_reference {
            return Ok(None);
        }
        let window: f64 = self.window.iter().skip(skip).sum::<f64>() + newest;
        let dim = p.dim as f64;
        let rho = self.reference_sum / (self.reference.len() as f64 * dim);
        if rho <= 0.0 {
            return Ok(None);
        }
        let ratio = (window / (p.k as f64 * dim)) / rho;
        let (d1, d2) = self.dofs();
        let tail = FLaw::reuse(self.law, d1, d2).lower_tail(ratio);
        Ok(Some(StuckValue {
            value: chi2_equivalent(1, tail),
            ratio,
            tail,
        }))
    }

    /// Takes `x` as the newest input. Its difference to the previous input enters the
    /// window always, and the reference only when both epochs were healthy.
    pub fn commit(&mut self, x: &[f64], healthy: bool) -> Result<(), StuckError> {
        self.check(x)?;
        if let Some(d2) = self.squared_difference(x) {
            if self.window.len() >= self.params.k {
                self.window.pop_front();
            }
            self.window.push_back(d2);
            let both_healthy = healthy && self.last.as_ref().is_some_and(|(_, h)| *h);
            if both_healthy {
                self.reference.push_back(d2);
                self.reference_sum += d2;
                if self.reference.len() > self.params.max_reference {
                    if let Some(old) = self.reference.pop_front() {
                        self.reference_sum -= old;
                    }
                    // Recompute now and then so the running sum carries no round-off.
                    if self.reference.len() % 64 == 0 {
                        self.reference_sum = self.reference.iter().sum();
                    }
                }
            }
        }
        match &mut self.last {
            Some((last, h)) => {
                last.copy_from_slice(x);
                *h = healthy;
            }
            None => self.last = Some((x.to_vec(), healthy)),
        }
        if self.reference.len() >= self.params.min_reference {
            let (d1, d2) = self.dofs();
            self.law = Some(FLaw::reuse(self.law, d1, d2));
        }
        Ok(())
    }

    /// The dofs of the window's law against the reference's.
    fn dofs(&self) -> (f64, f64) {
        let dim = self.params.dim as f64;
        (
            effective_dof(self.params.k) * dim,
            effective_dof(self.reference.len()) * dim,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::chi2;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, StandardNormal};

    #[test]
    fn effective_dof_matches_the_moments_of_squared_differences() {
        // k = 1: one squared difference of white noise is σ²·2·χ²(1): dof 1.
        assert_eq!(effective_dof(1), 1.0);
        // k = 8: 64 / (8 + 3.5).
        assert!((effective_dof(8) - 64.0 / 11.5).abs() < 1e-15);
        // Monte Carlo: Var(Σ d²)/E(Σ d²)² = 2/ν for white inputs, k = 8.
        let mut rng = StdRng::seed_from_u64(1);
        let (mut s1, mut s2, runs) = (0.0, 0.0, 200_000);
        for _ in 0..runs {
            let x: Vec<f64> = (0..9).map(|_| StandardNormal.sample(&mut rng)).collect();
            let w: f64 = x.windows(2).map(|p| (p[1] - p[0]) * (p[1] - p[0])).sum();
            s1 += w;
            s2 += w * w;
        }
        let mean = s1 / runs as f64;
        let var = s2 / runs as f64 - mean * mean;
        let nu = 2.0 * mean * mean / var;
        assert!((nu / effective_dof(8) - 1.0).abs() < 0.03, "{nu}");
    }

    #[test]
    fn a_stuck_signal_is_flagged_after_k_repeats_and_white_noise_is_quiet() {
        let mut rng = StdRng::seed_from_u64(2);
        let mut test = StuckTest::new(StuckParams::new(1));
        let t = chi2::threshold(1, DEFAULT_P_FA).unwrap();
        let mut false_alarms = 0;
        let mut x = 0.0;
        for _ in 0..100_000 {
            x = StandardNormal.sample(&mut rng);
            if let Some(v) = test.evaluate(&[x]).unwrap() {
                false_alarms += usize::from(v.value > t);
            }
            test.commit(&[x], true).unwrap();
        }
        assert!(
            false_alarms <= 2,
            "{false_alarms} of 100,000 above the 1e-6 threshold"
        );
        // Freeze: the k-th repeated difference is flagged, not earlier.
        let mut flagged = None;
        for j in 1..=12 {
            let v = test.evaluate(&[x]).unwrap().unwrap();
            if v.value > t && flagged.is_none() {
                flagged = Some(j);
                assert_eq!(v.ratio, 0.0);
                assert!(v.value > 1300.0);
            }
            test.commit(&[x], v.value <= t).unwrap();
        }
        assert_eq!(flagged, Some(DEFAULT_K));
    }

    #[test]
    fn the_lower_tail_matches_the_f_law_by_hand() {
        let mut test = StuckTest::new(StuckParams {
            dim: 1,
            k: 2,
            max_reference: 4,
            min_reference: 4,
        });
        // Differences 1, −1, 2, −2 (squares 1, 1, 4, 4): ρ = 2.5. Then 0 and 0.5.
        for x in [0.0, 1.0, 0.0, 2.0, 0.0, 0.0] {
            test.commit(&[x], true).unwrap();
        }
        // Reference keeps the last 4 healthy: 1, 4, 4, 0 → ρ = 9/4. Window [0, 0.25].
        let v = test.evaluate(&[0.5]).unwrap().unwrap();
        let ratio = (0.25 / 2.0) / (9.0 / 4.0);
        assert!((v.ratio - ratio).abs() < 1e-15);
        let tail = crate::detect::window::f_lower_tail(ratio, effective_dof(2), effective_dof(4));
        assert!((v.tail - tail).abs() < 1e-15);
        assert!((v.value - chi2::threshold(1, tail).unwrap()).abs() < 1e-12);
    }

    #[test]
    fn unhealthy_epochs_feed_the_window_but_not_the_reference() {
        let mut test = StuckTest::new(StuckParams {
            dim: 2,
            k: 2,
            max_reference: 10,
            min_reference: 2,
        });
        test.commit(&[0.0, 0.0], true).unwrap();
        test.commit(&[1.0, 0.0], true).unwrap();
        test.commit(&[5.0, 0.0], false).unwrap();
        test.commit(&[6.0, 0.0], true).unwrap();
        assert_eq!(
            test.reference.len(),
            1,
            "only the first pair was healthy on both ends"
        );
        assert_eq!(test.window.len(), 2);
        assert_eq!(
            test.evaluate(&[6.0, 0.0]).unwrap(),
            None,
            "reference too short"
        );
        assert!(matches!(
            test.evaluate(&[1.0]),
            Err(StuckError::Dimension { got: 1, want: 2 })
        ));
        assert_eq!(
            test.commit(&[f64::INFINITY, 0.0], true),
            Err(StuckError::NonFinite)
        );
    }
}
