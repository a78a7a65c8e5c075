//! Federated fusion (docs/methods.md §M3, §M6, seed 004 §1): one local 15-state filter per aid over
//! the common INS error state of [`crate::filter::ins`], measurements from
//! [`crate::filter::aiding`], the Kalman filter of [`crate::filter::kalman`], and between
//! them the per-aid decisions of the detector layer's policies. The federated monitor
//! drives it once per INS epoch.
//!
//! # The filter (Carlson's federated filter, fusion-reset mode)
//! Local filter `i` holds `(x_i, P_i)` and an information-sharing factor `β_i` (`Σβ = 1`).
//! It predicts with `Φ` and `Q/β_i`, so after a reset `P_i = P_g/β_i` gives
//! `P_i⁻ = Φ (P_g/β_i) Φᵀ + Q/β_i = P_g⁻/β_i`: the process-noise information is split like
//! the state information, and `Σ_i P_i⁻¹ = P_g⁻¹` before the updates. Each epoch:
//! 1. predict; 2. for each aid with data, the local innovation and `λ_i = rᵀ S⁻¹ r`;
//! 3. the aid's decision (docs/methods.md §M3): *healthy* → update and fuse; *suspect* → predict only,
//!    still fused; *isolated* → left out of fusion; returning from isolated (`reset`) → the
//!    local prior is replaced by the master's `(x_g⁻, P_g⁻/β_i)` before the update;
//! 4. fusion over the filters that take part: `P_g = (Σ P_i⁻¹)⁻¹`, `x_g = P_g Σ P_i⁻¹ x_i`;
//! 5. reset of the fused filters: `x_i = x_g`, `P_i = P_g/β_i`. Filters left out keep their
//!    own estimate. With no filter fused, the master keeps its own prediction `(x_g⁻, P_g⁻)`.
//!
//! **Renormalisation.** The fused filters' shares are renormalised to `β_i / B`,
//! `B = Σ_fused β`, before their updates (each fused local prior covariance is multiplied
//! by `B`). Every local prior is a copy of the same common information; without this, each
//! epoch an aid is left out would discard `1 − B` of it and `P_g` would grow by `1/B` per
//! epoch — `1.5¹²⁰⁰` over seed 004's two-minute GNSS fault at 10 Hz. With all aids fused
//! `B = 1` and nothing changes. A *suspect* filter brings exactly its share of the prior, so
//! for the master, suspect and isolated differ only in what happens to the local filter.
//!
//! # How it is computed (equivalences, tested against the straightforward form)
//! After a reset every fused local filter *is* `(x_g, P_g/β_i)`, so only the master is
//! stored for them ("shared" locals) and it is predicted once. In information form a KF
//! update gives `P⁺⁻¹ = P⁻⁻¹ + Hᵀ R⁻¹ H` and `P⁺⁻¹ x⁺ = P⁻⁻¹ x⁻ + Hᵀ R⁻¹ z`, so fusing the shared
//! filters gives `P_g⁻¹ = (B_s/B) P_g⁻⁻¹ + Σ_updated H_iᵀ R_i⁻¹ H_i`, `B_s = Σ_shared,fused β`:
//! the same as **one** Kalman filter from the prior `(x_g⁻, P_g⁻ B/B_s)` updated sequentially
//! with the updated aids' measurements. No 15 × 15 inverse is formed. With every aid fused
//! this *is* the centralised Kalman filter over all measurements (the known optimality of the
//! reset form). The local tests still use each local prior `(x_g⁻, P_g⁻/β_i)`.
//!
//! A filter that takes part in fusion with an estimate of its own (the classic policy lets a
//! filter that was rejected last epoch back without a reset) is fused as an independent
//! estimate: information fusion of `(x_a, P_a)` and `(x_b, P_b)` is the Kalman update of `a`
//! by the "measurement" `z = x_b`, `H = I`, `R = P_b` — one Cholesky factorisation of
//! `P_a + P_b` in diagonally scaled coordinates, which unlike `P⁻¹` keeps its accuracy at the
//! INS state's scales (variances from 1e-17 to 1e2).
//!
//! # Speed (docs/performance.md: ≥ 200,000 epochs/s with three aids)
//! The hot path uses the same algebra as [`kalman::predict`], [`kalman::innovation`] and
//! [`kalman::update`] in kernels that exploit the INS structure (tested equal to them to
//! rounding): the prediction uses `Φ`'s constant bias rows, every aid's `H` has zero bias
//! columns, the Joseph form is written out as a rank-`M` correction (one rank-1
//! correction per component for the aids, whose `R` is diagonal), and the two state
//! buffers are flipped on commit rather than copied. Nothing is allocated per epoch. The
//! kernels run a second, AVX2 build of themselves when the CPU has it (a runtime check;
//! the same IEEE operations in the same order, so the same results to the bit, tested).
//! `NAVGUARD_NO_AVX2` set in the environment keeps them on the baseline build.

use nalgebra::{SVector, U15};
use serde::{Deserialize, Serialize};

use super::aiding::AidMeasurement;
use super::ins::{self, ErrorMatrix, ErrorVector, ImuErrors, NavSolution};
use super::kalman::{FilterError, LinearTransition, StateEstimate};
use crate::detect::Decision;

mod solver;

use solver::{fuse_estimates, fused_slope, joseph_update, predict_into, scaled, share_test};

/// Most aids a federated filter runs (GNSS, DVL, CNS).
pub const MAX_AIDS: usize = 3;

/// The longest single prediction step, s; longer intervals are split into equal sub-steps
/// (`Φ = I + FΔt + (FΔt)²/2` is a truncated series).
pub const MAX_SUBSTEP_S: f64 = 1.0;

/// A 15-state estimate: `x` and `P` of the INS error.
pub type ErrorEstimate = StateEstimate<U15>;

/// One aid's measurement this epoch, of whichever dimension the aid yields.
// The variants differ in size (D6 holds a 6 × 15 H); boxing them would allocate on every
// epoch, which the federated step avoids.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Observation {
    /// Two components (CNS east, north).
    D2(AidMeasurement<2>),
    /// Three components (GNSS position or velocity, DVL).
    D3(AidMeasurement<3>),
    /// Six components (GNSS velocity and position).
    D6(AidMeasurement<6>),
}

impl Observation {
    /// The measurement dimension: the dof of its χ² statistic.
    pub fn dof(&self) -> u32 {
        match self {
            Observation::D2(_) => 2,
            Observation::D3(_) => 3,
            Observation::D6(_) => 6,
        }
    }
}

impl From<AidMeasurement<2>> for Observation {
    fn from(m: AidMeasurement<2>) -> Self {
        Observation::D2(m)
    }
}

impl From<AidMeasurement<3>> for Observation {
    fn from(m: AidMeasurement<3>) -> Self {
        Observation::D3(m)
    }
}

impl From<AidMeasurement<6>> for Observation {
    fn from(m: AidMeasurement<6>) -> Self {
        Observation::D6(m)
    }
}

/// Runs `$body` with `$m` bound to the fixed-size measurement inside an [`Observation`].
macro_rules! with_measurement {
    ($obs:expr, $m:ident => $body:expr) => {
        match $obs {
            Observation::D2($m) => $body,
            Observation::D3($m) => $body,
            Observation::D6($m) => $body,
        }
    };
}

/// Why a federated filter cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FederatedError {
    /// No aid, or more than [`MAX_AIDS`].
    #[error("a federated filter needs 1 to {MAX_AIDS} aids, got {0}")]
    AidCount(usize),
    /// A sharing factor is not in (0, 1].
    #[error("beta[{index}] must be in (0, 1], got {value}")]
    Beta {
        /// Which aid.
        index: usize,
        /// The value given.
        value: f64,
    },
    /// The sharing factors do not sum to 1.
    #[error("the information-sharing factors must sum to 1, got {0}")]
    BetaSum(f64),
    /// The interval is negative or not finite.
    #[error("prediction interval must be finite and >= 0, got {0} s")]
    Interval(f64),
}

/// Equal sharing factors `β_i = 1/n` (the default).
pub fn equal_betas(n: usize) -> Vec<f64> {
    vec![1.0 / n as f64; n]
}

/// The INS transition over `dt` seconds about `nav`: `Φ` and `Q_d` of [`ins::discretize`],
/// composed from `⌈dt / MAX_SUBSTEP_S⌉` equal sub-steps when `dt` is longer
/// (`Φ = Φ_hⁿ`, `Q = Σ_k Φ_hᵏ Q_h Φ_hᵏᵀ`: exactly n successive predictions). `dt = 0` gives
/// `Φ = I`, `Q = 0`.
#[inline]
pub fn ins_transition(
    nav: &NavSolution,
    imu: &ImuErrors,
    dt: f64,
) -> Result<LinearTransition<U15>, FederatedError> {
    let mut out = LinearTransition {
        f: ErrorMatrix::zeros(),
        q: ErrorMatrix::zeros(),
    };
    ins_transition_into(nav, imu, dt, &mut out)?;
    Ok(out)
}

/// [`ins_transition`] written into `out` (whatever it held; unchanged on an error), so the
/// monitor's step keeps one transition buffer instead of moving 3.6 kB per epoch.
pub fn ins_transition_into(
    nav: &NavSolution,
    imu: &ImuErrors,
    dt: f64,
    out: &mut LinearTransition<U15>,
) -> Result<(), FederatedError> {
    if !(dt.is_finite() && dt >= 0.0) {
        return Err(FederatedError::Interval(dt));
    }
    let steps = (dt / MAX_SUBSTEP_S).ceil().max(1.0);
    ins::transition_into(nav, imu, dt / steps, &mut out.f, &mut out.q);
    if steps == 1.0 {
        return Ok(());
    }
    let (phi, q) = (out.f, out.q);
    for _ in 1..steps as usize {
        out.f = phi * out.f;
        out.q = phi * out.q * phi.transpose() + q;
    }
    out.q = (out.q + out.q.transpose()) * 0.5;
    Ok(())
}

/// A local filter's χ² test for one epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalTest {
    /// `λ = rᵀ S⁻¹ r` against the local prior.
    pub statistic: f64,
    /// Its dof (the measurement dimension).
    pub dof: u32,
    /// The normalised innovation `ν = L⁻¹ r` (`S = L Lᵀ`, `‖ν‖² = λ`) in its first `dof`
    /// entries, the rest zero: the input of the consistency diagnostics and of the drift
    /// and stuck tests (docs/methods.md §M22, §M23). Fixed-size, so nothing is allocated.
    pub nu: SVector<f64, 6>,
}

impl LocalTest {
    /// `ν` as a slice of `dof` entries.
    pub fn nu(&self) -> &[f64] {
        &self.nu.as_slice()[..self.dof as usize]
    }
}

/// What happened to one aid's local filter in one epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AidStep {
    /// The test, when the aid had data.
    pub test: Option<LocalTest>,
    /// The policy's decision (the idle decision without data).
    pub decision: Decision,
    /// The local filter updated with the aid's measurement.
    pub updated: bool,
    /// The filter took part in fusion.
    pub fused: bool,
    /// For an aid that updated and was fused: `max_j ‖K_h e_j‖ / sqrt((S⁻¹)_jj)` (metres per
    /// unit of `sqrt(λ)`, docs/methods.md §M7), with `K_h` the horizontal rows of the aid's gain onto
    /// the *fused* solution, `P_g H_iᵀ R_i⁻¹` (the local gain `P_i⁺ H_iᵀ R_i⁻¹` carried through
    /// the fusion weight `P_g P_i⁺⁻¹`), and `S` the local innovation covariance the test used.
    pub slope: Option<f64>,
}

/// The filter's state: the master (fused) estimate and each local filter's own estimate,
/// `None` for a local filter that shares the master's (`x_g`, `P_g/β_i`). It is what a
/// monitor checkpoint saves of the filter ([`FederatedFilter::with_state`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FederatedState {
    /// `(x_g, P_g)` after the last fusion.
    pub master: ErrorEstimate,
    /// Local estimates of the filters left out of the last fusion.
    pub own: [Option<ErrorEstimate>; MAX_AIDS],
}

/// The per-aid report of [`FederatedFilter::step`]; the next state waits in
/// [`FederatedFilter::pending`] until [`FederatedFilter::commit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FederatedStep {
    /// One entry per configured aid (the first `n` of [`MAX_AIDS`]).
    pub aids: [AidStep; MAX_AIDS],
}

/// The federated filter: sharing factors and two state buffers, the current one and the
/// one a step writes (committing flips them, so no 15 × 15 state is ever copied).
#[derive(Debug, Clone, PartialEq)]
pub struct FederatedFilter {
    betas: [f64; MAX_AIDS],
    n: usize,
    states: [FederatedState; 2],
    current: usize,
    pending_ready: bool,
}

impl FederatedFilter {
    /// A filter for `betas.len()` aids starting from `initial` (every local filter at
    /// `(x₀, P₀/β_i)`). Each `β_i` must lie in (0, 1] and they must sum to 1 (within 1e-9).
    pub fn new(betas: &[f64], initial: ErrorEstimate) -> Result<Self, FederatedError> {
        let n = betas.len();
        if n == 0 || n > MAX_AIDS {
            return Err(FederatedError::AidCount(n));
        }
        for (index, &value) in betas.iter().enumerate() {
            if !(value > 0.0 && value <= 1.0) {
                return Err(FederatedError::Beta { index, value });
            }
        }
        let sum: f64 = betas.iter().sum();
        if (sum - 1.0).abs() > 1e-9 {
            return Err(FederatedError::BetaSum(sum));
        }
        let mut b = [0.0; MAX_AIDS];
        b[..n].copy_from_slice(betas);
        let state = FederatedState {
            master: initial,
            own: [None, None, None],
        };
        Ok(FederatedFilter {
            betas: b,
            n,
            states: [state.clone(), state],
            current: 0,
            pending_ready: false,
        })
    }

    /// Number of aids.
    pub fn aids(&self) -> usize {
        self.n
    }

    /// The sharing factors.
    pub fn betas(&self) -> &[f64] {
        &self.betas[..self.n]
    }

    /// The current state.
    pub fn state(&self) -> &FederatedState {
        &self.states[self.current]
    }

    /// The state the last successful [`FederatedFilter::step`] computed, not yet committed.
    pub fn pending(&self) -> Option<&FederatedState> {
        self.pending_ready.then(|| &self.states[1 - self.current])
    }

    /// The fused estimate `(x_g, P_g)`.
    pub fn master(&self) -> &ErrorEstimate {
        &self.state().master
    }

    /// Local filter `i`'s estimate (`(x_g, P_g/β_i)` when it shares the master's).
    pub fn local(&self, i: usize) -> ErrorEstimate {
        match &self.state().own[i] {
            Some(e) => e.clone(),
            None => scaled(self.master(), self.betas[i]),
        }
    }

    /// A filter with this one's aids and sharing factors whose current state is `state`,
    /// nothing pending: the restore of a checkpoint, which saves only [`FederatedFilter::state`]
    /// (the other buffer is scratch, fully rewritten by every step). The reason when `state`
    /// does not fit (an estimate of its own for an aid the filter does not have).
    pub fn with_state(&self, state: FederatedState) -> Result<Self, String> {
        if let Some(i) = (self.n..MAX_AIDS).find(|&i| state.own[i].is_some()) {
            return Err(format!(
                "local filter {i} has an estimate of its own, the filter has {} aids",
                self.n
            ));
        }
        Ok(FederatedFilter {
            betas: self.betas,
            n: self.n,
            states: [state.clone(), state],
            current: 0,
            pending_ready: false,
        })
    }

    /// Restarts from `initial`, every local filter sharing it.
    pub fn restart(&mut self, initial: ErrorEstimate) {
        self.states[self.current] = FederatedState {
            master: initial,
            own: [None, None, None],
        };
        self.pending_ready = false;
    }

    /// Closed-loop feedback of the pending state (docs/methods.md §M31): returns the fused
    /// error estimate `x_g` the caller removes from its navigation solution and IMU bias
    /// estimates, and subtracts it from the master and from every local filter's own
    /// estimate, so each stays the error of the corrected solution. Covariances are
    /// unchanged (the correction is a known shift of the linearisation point). `None`
    /// without a pending state.
    pub fn feed_back_pending(&mut self) -> Option<ErrorVector> {
        if !self.pending_ready {
            return None;
        }
        let next = &mut self.states[1 - self.current];
        let dx = next.master.x;
        next.master.x = ErrorVector::zeros();
        for own in next.own.iter_mut().flatten() {
            own.x -= dx;
        }
        Some(dx)
    }

    /// Makes the pending state of the last successful step current; without one it does
    /// nothing.
    pub fn commit(&mut self) {
        if self.pending_ready {
            self.current = 1 - self.current;
            self.pending_ready = false;
        }
    }

    /// One epoch: predict with `trans`, test each aid with data (`obs[i]`, one entry per aid),
    /// ask `decide(i, test)` for each aid in order (`None` for an aid without data), update,
    /// fuse and reset. The next state goes to [`FederatedFilter::pending`]; the current one
    /// is not touched, so a caller that fails later (or gets `Err`) simply does not commit.
    pub fn step(
        &mut self,
        trans: &LinearTransition<U15>,
        obs: &[Option<Observation>],
        decide: impl FnMut(usize, Option<LocalTest>) -> Decision,
    ) -> Result<FederatedStep, FilterError> {
        self.step_from(None, trans, obs, decide)
    }

    /// As [`FederatedFilter::step`], but from `initial` (every local filter sharing it)
    /// instead of the current state: a restart that only takes effect on commit.
    pub fn restart_step(
        &mut self,
        initial: &ErrorEstimate,
        trans: &LinearTransition<U15>,
        obs: &[Option<Observation>],
        decide: impl FnMut(usize, Option<LocalTest>) -> Decision,
    ) -> Result<FederatedStep, FilterError> {
        let base = FederatedState {
            master: initial.clone(),
            own: [None, None, None],
        };
        self.step_from(Some(&base), trans, obs, decide)
    }

    /// The epoch of [`FederatedFilter::step`] from `base` (or the current state), in the
    /// module doc's five stages, each a method of [`EpochWork`]. Every working array lives
    /// on the stack; the next state is written in place into the other buffer.
    fn step_from(
        &mut self,
        base: Option<&FederatedState>,
        trans: &LinearTransition<U15>,
        obs: &[Option<Observation>],
        mut decide: impl FnMut(usize, Option<LocalTest>) -> Decision,
    ) -> Result<FederatedStep, FilterError> {
        self.pending_ready = false;
        let [first, second] = &mut self.states;
        let (current, next) = if self.current == 0 {
            (&*first, second)
        } else {
            (&*second, first)
        };
        let current = base.unwrap_or(current);
        let mut work = EpochWork::new(&self.betas[..self.n], obs);

        // 1. Prediction (into the master buffer, which then holds the prior x_g⁻, P_g⁻).
        work.predict(current, trans, &mut next.master)?;
        // 2. Tests and decisions, in aid order.
        work.test_and_decide(&next.master, &mut decide)?;
        // 3. Local updates of the filters that do not share the master's estimate.
        let (total, shared_total) = work.fused_shares();
        let mut own_fused: [Option<ErrorEstimate>; MAX_AIDS] = [None, None, None];
        work.update_locals(&next.master, total, &mut next.own, &mut own_fused)?;
        // 4. Fusion, in place in the master.
        work.fuse(&mut next.master, total, shared_total, &mut own_fused)?;
        // 5. HPL slopes onto the fused solution.
        work.slopes(&next.master);

        self.pending_ready = true;
        Ok(FederatedStep { aids: work.aids })
    }
}

/// The working set of one [`FederatedFilter::step`]: the stage methods below read and fill
/// it in order. Fixed-size arrays only, so an epoch allocates nothing.
struct EpochWork<'a> {
    /// `β_i` of the configured aids (`n` entries).
    betas: &'a [f64],
    /// The epoch's measurements, one entry per aid (missing entries: no data).
    obs: &'a [Option<Observation>],
    /// Stage 1: the predicted local estimate of each filter that has its own.
    own_prior: [Option<ErrorEstimate>; MAX_AIDS],
    /// Stage 2 on: the per-aid report.
    aids: [AidStep; MAX_AIDS],
    /// Diagonal of each local test's S⁻¹ (first M entries), for the slopes.
    s_local: [SVector<f64, 6>; MAX_AIDS],
    /// The filter shares the master's estimate this epoch (it had no own one, or is reset).
    shared: [bool; MAX_AIDS],
}

impl<'a> EpochWork<'a> {
    fn new(betas: &'a [f64], obs: &'a [Option<Observation>]) -> Self {
        let idle = Decision {
            health: crate::detect::Health::Healthy,
            update: false,
            fuse: false,
            reset: false,
        };
        EpochWork {
            betas,
            obs,
            own_prior: [None, None, None],
            aids: [AidStep {
                test: None,
                decision: idle,
                updated: false,
                fused: false,
                slope: None,
            }; MAX_AIDS],
            s_local: [SVector::<f64, 6>::zeros(); MAX_AIDS],
            shared: [false; MAX_AIDS],
        }
    }

    /// Number of aids.
    fn n(&self) -> usize {
        self.betas.len()
    }

    /// Aid `i`'s measurement this epoch.
    fn observation(&self, i: usize) -> Option<&'a Observation> {
        self.obs.get(i).and_then(Option::as_ref)
    }

    /// Stage 1: the master predicted once into `master` (the shared local filters are its
    /// β-shares, `P_i⁻ = P_g⁻/β_i`), and every filter with its own estimate with `Q/β_i`.
    fn predict(
        &mut self,
        current: &FederatedState,
        trans: &LinearTransition<U15>,
        master: &mut ErrorEstimate,
    ) -> Result<(), FilterError> {
        predict_into(&current.master, trans, master)?;
        for (i, own) in current.own.iter().enumerate().take(self.n()) {
            if let Some(e) = own {
                let local = LinearTransition {
                    f: trans.f,
                    q: trans.q / self.betas[i],
                };
                let mut prior = e.clone();
                predict_into(e, &local, &mut prior)?;
                self.own_prior[i] = Some(prior);
            }
        }
        Ok(())
    }

    /// Stage 2: each aid's local test `λ_i = rᵀ S⁻¹ r` against its prior (a shared filter's
    /// is `(x_g⁻, P_g⁻/β_i)`) and the policy's decision, in aid order.
    fn test_and_decide(
        &mut self,
        master_prior: &ErrorEstimate,
        decide: &mut impl FnMut(usize, Option<LocalTest>) -> Decision,
    ) -> Result<(), FilterError> {
        for i in 0..self.n() {
            let o = self.observation(i);
            let test = match o {
                Some(o) => {
                    let (prior, beta) = match &self.own_prior[i] {
                        Some(e) => (e, 1.0),
                        None => (master_prior, self.betas[i]),
                    };
                    let t = with_measurement!(o, m => share_test(prior, beta, m)?);
                    self.s_local[i] = t.s_inv;
                    Some(LocalTest {
                        statistic: t.statistic,
                        dof: o.dof(),
                        nu: t.nu,
                    })
                }
                None => None,
            };
            let decision = decide(i, test);
            let has_own = self.own_prior[i].is_some();
            self.shared[i] = !has_own || decision.reset;
            self.aids[i] = AidStep {
                test,
                decision,
                updated: decision.update && o.is_some(),
                fused: decision.fuse,
                slope: None,
            };
            if let (true, true, Some(o)) = (decision.reset, has_own, o) {
                // The test ran on the stale own prior; the update and the slope use the
                // master's share the filter was just reset to.
                self.s_local[i] =
                    with_measurement!(o, m => share_test(master_prior, self.betas[i], m)?.s_inv);
            }
        }
        Ok(())
    }

    /// `(B, B_shared)`: the sharing factors of the fused filters, and of those among them
    /// that share the master's estimate (renormalisation, module doc).
    fn fused_shares(&self) -> (f64, f64) {
        let (n, aids, betas) = (self.n(), &self.aids, self.betas);
        let total: f64 = (0..n).filter(|&i| aids[i].fused).map(|i| betas[i]).sum();
        let shared_total: f64 = (0..n)
            .filter(|&i| aids[i].fused && self.shared[i])
            .map(|i| betas[i])
            .sum();
        (total, shared_total)
    }

    /// Stage 3: local updates of the filters that do not share the master's estimate. The
    /// fused filters share the whole prior information: each one's share becomes `β_i / B`
    /// with `B = Σ_fused β` (renormalisation; without it every epoch of isolation would
    /// throw away `1 − B` of the common information). Filters left out of fusion go to
    /// `own_next`, fused ones with an estimate of their own to `own_fused`.
    fn update_locals(
        &mut self,
        master_prior: &ErrorEstimate,
        total: f64,
        own_next: &mut [Option<ErrorEstimate>; MAX_AIDS],
        own_fused: &mut [Option<ErrorEstimate>; MAX_AIDS],
    ) -> Result<(), FilterError> {
        for i in 0..self.n() {
            own_next[i] = None;
            let (shared, aid) = (self.shared[i], self.aids[i]);
            if shared && aid.fused {
                continue; // the master's filter, stage 4
            }
            let mut local = match (self.own_prior[i].take(), shared) {
                (Some(e), false) => e,
                _ => scaled(master_prior, self.betas[i]),
            };
            if aid.fused {
                local.p *= total;
            }
            if let (true, Some(o)) = (aid.updated, self.observation(i)) {
                with_measurement!(o, m => joseph_update(&mut local, m)?);
            }
            if aid.fused {
                own_fused[i] = Some(local);
            } else {
                own_next[i] = Some(local);
            }
        }
        Ok(())
    }

    /// Stage 4: fusion into `master`, which holds the prior `(x_g⁻, P_g⁻)`. The shared fused
    /// filters are one Kalman filter from `(x_g⁻, P_g⁻ B / B_shared)` through the updated
    /// aids' measurements (module doc); the filters fused with their own estimate join by
    /// independent-estimate fusion. With nothing fused the master keeps its prediction.
    fn fuse(
        &self,
        master: &mut ErrorEstimate,
        total: f64,
        shared_total: f64,
        own_fused: &mut [Option<ErrorEstimate>; MAX_AIDS],
    ) -> Result<(), FilterError> {
        let n = self.n();
        let mut any_fused = false;
        if shared_total > 0.0 {
            any_fused = true;
            let ratio = total / shared_total;
            if ratio != 1.0 {
                master.p *= ratio;
            }
            for i in 0..n {
                let aid = &self.aids[i];
                if let (true, true, Some(o)) = (
                    self.shared[i] && aid.fused,
                    aid.updated,
                    self.observation(i),
                ) {
                    with_measurement!(o, m => joseph_update(master, m)?);
                }
            }
        }
        for own in own_fused.iter_mut().take(n) {
            if let Some(own) = own.take() {
                *master = if any_fused {
                    fuse_estimates(master, &own)?
                } else {
                    own
                };
                any_fused = true;
            }
        }
        Ok(())
    }

    /// Stage 5: each updated, fused aid's HPL slope from its gain onto the fused solution,
    /// `P_g H_iᵀ R_i⁻¹`, and its local `S_i` ([`AidStep::slope`]).
    fn slopes(&mut self, master: &ErrorEstimate) {
        for i in 0..self.n() {
            let aid = &self.aids[i];
            if let (true, true, Some(o)) = (aid.updated, aid.fused, self.observation(i)) {
                let slope = with_measurement!(o, m => fused_slope(&master.p, m, &self.s_local[i]));
                self.aids[i].slope = slope.ok();
            }
        }
    }
}

#[cfg(test)]
mod tests;
