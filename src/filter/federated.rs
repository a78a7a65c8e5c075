//! Federated fusion (DESIGN §3.3–3.4, seed 004 §1): one local 15-state filter per aid over
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
//! 3. the aid's decision (DESIGN §3.3): *healthy* → update and fuse; *suspect* → predict only,
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
//! # Speed (DESIGN §5: ≥ 200,000 epochs/s with three aids)
//! The hot path uses the same algebra as [`kalman::predict`], [`kalman::innovation`] and
//! [`kalman::update`] in kernels that exploit the INS structure (tested equal to them to
//! rounding): the prediction uses `Φ`'s constant bias rows, every aid's `H` has zero bias
//! columns, the Joseph form is written out as a rank-`M` correction, and the two state
//! buffers are flipped on commit rather than copied. Nothing is allocated per epoch.

use nalgebra::{SMatrix, SVector, U15};

use super::aiding::AidMeasurement;
use super::ins::{self, ErrorMatrix, ErrorVector, ImuErrors, N, NavSolution, POS};
use super::kalman::{self, FilterError, LinearObservation, LinearTransition, StateEstimate};
use crate::detect::Decision;
use crate::detect::hpl;

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
pub fn ins_transition(
    nav: &NavSolution,
    imu: &ImuErrors,
    dt: f64,
) -> Result<LinearTransition<U15>, FederatedError> {
    if !(dt.is_finite() && dt >= 0.0) {
        return Err(FederatedError::Interval(dt));
    }
    let steps = (dt / MAX_SUBSTEP_S).ceil().max(1.0);
    let (phi, q) = ins::transition(nav, imu, dt / steps);
    if steps == 1.0 {
        return Ok(LinearTransition { f: phi, q });
    }
    let (mut phi_n, mut q_n) = (phi, q);
    for _ in 1..steps as usize {
        phi_n = phi * phi_n;
        q_n = phi * q_n * phi.transpose() + q;
    }
    Ok(LinearTransition {
        f: phi_n,
        q: (q_n + q_n.transpose()) * 0.5,
    })
}

/// A local filter's χ² test for one epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalTest {
    /// `λ = rᵀ S⁻¹ r` against the local prior.
    pub statistic: f64,
    /// Its dof (the measurement dimension).
    pub dof: u32,
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
    /// unit of `sqrt(λ)`, DESIGN §3.6), with `K_h` the horizontal rows of the aid's gain onto
    /// the *fused* solution, `P_g H_iᵀ R_i⁻¹` (the local gain `P_i⁺ H_iᵀ R_i⁻¹` carried through
    /// the fusion weight `P_g P_i⁺⁻¹`), and `S` the local innovation covariance the test used.
    pub slope: Option<f64>,
}

/// The filter's state: the master (fused) estimate and each local filter's own estimate,
/// `None` for a local filter that shares the master's (`x_g`, `P_g/β_i`).
#[derive(Debug, Clone, PartialEq)]
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

    /// Restarts from `initial`, every local filter sharing it.
    pub fn restart(&mut self, initial: ErrorEstimate) {
        self.states[self.current] = FederatedState {
            master: initial,
            own: [None, None, None],
        };
        self.pending_ready = false;
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

    fn step_from(
        &mut self,
        base: Option<&FederatedState>,
        trans: &LinearTransition<U15>,
        obs: &[Option<Observation>],
        mut decide: impl FnMut(usize, Option<LocalTest>) -> Decision,
    ) -> Result<FederatedStep, FilterError> {
        self.pending_ready = false;
        let (n, betas) = (self.n, self.betas);
        let [first, second] = &mut self.states;
        let (current, next) = if self.current == 0 {
            (&*first, second)
        } else {
            (&*second, first)
        };
        let current = base.unwrap_or(current);

        // 1. Prediction: the master once (the shared local filters are its β-shares), and
        //    every filter with its own estimate with Q/β_i.
        predict_into(&current.master, trans, &mut next.master)?;
        let mut own_prior: [Option<ErrorEstimate>; MAX_AIDS] = [None, None, None];
        for (i, own) in current.own.iter().enumerate().take(n) {
            if let Some(e) = own {
                let local = LinearTransition {
                    f: trans.f,
                    q: trans.q / betas[i],
                };
                let mut prior = e.clone();
                predict_into(e, &local, &mut prior)?;
                own_prior[i] = Some(prior);
            }
        }
        let master_prior = &next.master;
        let observation = |i: usize| obs.get(i).and_then(Option::as_ref);

        // 2. Tests and decisions, in aid order. A shared filter's prior is (x_g⁻, P_g⁻/β_i).
        let idle = Decision {
            health: crate::detect::Health::Healthy,
            update: false,
            fuse: false,
            reset: false,
        };
        let mut aids = [AidStep {
            test: None,
            decision: idle,
            updated: false,
            fused: false,
            slope: None,
        }; MAX_AIDS];
        // Diagonal of each local test's S⁻¹ (first M entries), for the slopes.
        let mut s_local = [SVector::<f64, 6>::zeros(); MAX_AIDS];
        let mut shared = [false; MAX_AIDS];
        for i in 0..n {
            let o = observation(i);
            let test = match o {
                Some(o) => {
                    let (prior, beta) = match &own_prior[i] {
                        Some(e) => (e, 1.0),
                        None => (master_prior, betas[i]),
                    };
                    let (statistic, s) = with_measurement!(o, m => share_test(prior, beta, m)?);
                    s_local[i] = s;
                    Some(LocalTest {
                        statistic,
                        dof: o.dof(),
                    })
                }
                None => None,
            };
            let decision = decide(i, test);
            shared[i] = own_prior[i].is_none() || decision.reset;
            aids[i] = AidStep {
                test,
                decision,
                updated: decision.update && o.is_some(),
                fused: decision.fuse,
                slope: None,
            };
            if let (true, true, Some(o)) = (decision.reset, own_prior[i].is_some(), o) {
                // The test ran on the stale own prior; the update and the slope use the
                // master's share the filter was just reset to.
                s_local[i] = with_measurement!(o, m => share_test(master_prior, betas[i], m)?.1);
            }
        }

        // 3. Local updates of the filters that do not share the master's estimate. The
        //    fused filters share the whole prior information: each one's share becomes
        //    β_i / B with B = Σ_fused β (renormalisation; without it every epoch of
        //    isolation would throw away 1 − B of the common information).
        let total: f64 = (0..n).filter(|&i| aids[i].fused).map(|i| betas[i]).sum();
        let shared_total: f64 = (0..n)
            .filter(|&i| aids[i].fused && shared[i])
            .map(|i| betas[i])
            .sum();
        let mut own_fused: [Option<ErrorEstimate>; MAX_AIDS] = [None, None, None];
        for i in 0..n {
            next.own[i] = None;
            if shared[i] && aids[i].fused {
                continue; // the master's filter below
            }
            let mut local = match (own_prior[i].take(), shared[i]) {
                (Some(e), false) => e,
                _ => scaled(master_prior, betas[i]),
            };
            if aids[i].fused {
                local.p *= total;
            }
            if let (true, Some(o)) = (aids[i].updated, observation(i)) {
                with_measurement!(o, m => joseph_update(&mut local, m)?);
            }
            if aids[i].fused {
                own_fused[i] = Some(local);
            } else {
                next.own[i] = Some(local);
            }
        }

        // 4. Fusion. Shared fused filters: one Kalman filter from (x_g⁻, P_g⁻ B / B_shared)
        //    through the updated aids' measurements (module doc), in place in the master.
        //    With nothing fused the master keeps its prediction (x_g⁻, P_g⁻).
        let master = &mut next.master;
        let mut any_fused = false;
        if shared_total > 0.0 {
            any_fused = true;
            let ratio = total / shared_total;
            if ratio != 1.0 {
                master.p *= ratio;
            }
            for i in 0..n {
                if let (true, true, Some(o)) =
                    (shared[i] && aids[i].fused, aids[i].updated, observation(i))
                {
                    with_measurement!(o, m => joseph_update(master, m)?);
                }
            }
        }
        // Filters fused with their own estimate: independent-estimate fusion.
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

        // 5. HPL slopes: gain onto the fused solution P_g H_iᵀ R_i⁻¹, local S_i.
        for i in 0..n {
            if let (true, true, Some(o)) = (aids[i].updated, aids[i].fused, observation(i)) {
                let slope = with_measurement!(o, m => fused_slope(&master.p, m, &s_local[i]));
                aids[i].slope = slope.ok();
            }
        }
        self.pending_ready = true;
        Ok(FederatedStep { aids })
    }
}

/// `(x, P/β)`.
fn scaled(est: &ErrorEstimate, beta: f64) -> ErrorEstimate {
    StateEstimate {
        x: est.x,
        p: est.p / beta,
    }
}

/// `(P + Pᵀ)/2`, exactly symmetric.
fn symmetrise<const R: usize>(p: &SMatrix<f64, R, R>) -> SMatrix<f64, R, R> {
    (p + p.transpose()) * 0.5
}

/// `Err(NonFinite(what))` unless every entry is finite.
fn finite<const R: usize, const C: usize>(
    what: &'static str,
    m: &SMatrix<f64, R, C>,
) -> Result<(), FilterError> {
    if m.as_slice().iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(FilterError::NonFinite(what))
    }
}

/// [`kalman::predict`] into `out`, with the INS transition's structure used when `Φ` has
/// it: the bias rows of an INS `Φ` are `[0 I]` (biases are random constants), so with
/// `Φ = [[A, B], [0, I]]` (A 9 × 9, B 9 × 6) `Φ P Φᵀ` needs only
/// `M₁ = A P₁₁ + B P₂₁`, `M₂ = A P₁₂ + B P₂₂`, top-left `M₁ Aᵀ + M₂ Bᵀ`, top-right `M₂`,
/// bottom-right `P₂₂` — half the multiplications. Any other `Φ` takes the generic path.
/// On `Err`, `out` may hold a partial result.
fn predict_into(
    est: &ErrorEstimate,
    trans: &LinearTransition<U15>,
    out: &mut ErrorEstimate,
) -> Result<(), FilterError> {
    let phi = &trans.f;
    // Column-major: rows 9..15 of column c are as_slice()[15c + 9 .. 15c + 15].
    let structured = phi.as_slice().chunks_exact(N).enumerate().all(|(c, col)| {
        col[9..]
            .iter()
            .enumerate()
            .all(|(k, &v)| v == if c == 9 + k { 1.0 } else { 0.0 })
    });
    if !structured {
        *out = kalman::predict(est, trans)?;
        return Ok(());
    }
    let a = phi.fixed_view::<9, 9>(0, 0);
    let b = phi.fixed_view::<9, 6>(0, 9);
    let p = &est.p;
    let m1 = a * p.fixed_view::<9, 9>(0, 0) + b * p.fixed_view::<6, 9>(9, 0);
    let m2 = a * p.fixed_view::<9, 6>(0, 9) + b * p.fixed_view::<6, 6>(9, 9);
    let top_left = m1 * a.transpose() + m2 * b.transpose();
    let p22 = p.fixed_view::<6, 6>(9, 9);
    out.x = phi * est.x;
    // Each block symmetrised so that Φ P Φᵀ + Q is exactly symmetric.
    out.p
        .fixed_view_mut::<9, 9>(0, 0)
        .copy_from(&((top_left + top_left.transpose()) * 0.5));
    out.p.fixed_view_mut::<9, 6>(0, 9).copy_from(&m2);
    out.p
        .fixed_view_mut::<6, 9>(9, 0)
        .copy_from(&m2.transpose());
    out.p
        .fixed_view_mut::<6, 6>(9, 9)
        .copy_from(&((p22 + p22.transpose()) * 0.5));
    out.p += (trans.q + trans.q.transpose()) * 0.5;
    finite("predicted state", &out.x)?;
    finite("predicted covariance", &out.p)?;
    Ok(())
}

/// True when `H`'s bias columns 9..15 are zero (every aid's H): column-major, they are the
/// last `6·M` entries.
fn bias_columns_zero<const M: usize>(h: &SMatrix<f64, M, N>) -> bool {
    h.as_slice()[9 * M..].iter().all(|&v| v == 0.0)
}

/// The local test of `m` against the prior `(x, P/β)` without forming `P/β`:
/// `r = z − H x`, `S = H P Hᵀ / β + R`, `λ = |L⁻¹ r|²` with `S = L Lᵀ` — what
/// [`kalman::innovation`] computes for that prior. Returns `λ` and the diagonal of `S⁻¹`
/// (first M entries), which the HPL slope needs.
fn share_test<const M: usize>(
    prior: &ErrorEstimate,
    beta: f64,
    m: &AidMeasurement<M>,
) -> Result<(f64, SVector<f64, 6>), FilterError> {
    let h = &m.obs.h;
    let r = m.z - h * prior.x;
    let hph = if bias_columns_zero(h) {
        let h9 = h.fixed_columns::<9>(0);
        (h9 * prior.p.fixed_view::<9, 9>(0, 0)) * h9.transpose()
    } else {
        (h * prior.p) * h.transpose()
    };
    let s = symmetrise(&(hph / beta + m.obs.r));
    finite("innovation", &r)?;
    finite("innovation covariance", &s)?;
    let l_inv = inverse_cholesky_factor(&s).ok_or(FilterError::NotPositiveDefinite)?;
    // λ = rᵀ (L Lᵀ)⁻¹ r = |L⁻¹ r|², and (S⁻¹)_ii = Σ_k (L⁻¹)_ki² (column norms of L⁻¹).
    let statistic = (l_inv * r).norm_squared();
    if !statistic.is_finite() {
        return Err(FilterError::NonFinite("chi-square statistic"));
    }
    let mut s_inv = SVector::<f64, 6>::zeros();
    for i in 0..M {
        s_inv[i] = l_inv.column(i).norm_squared();
    }
    Ok((statistic, s_inv))
}

/// `L⁻¹` for the Cholesky factor `S = L Lᵀ` of a small SPD matrix, by plain loops (for
/// `M ≤ 6` these beat the general factor-and-solve routines several times over); `None`
/// unless `S` is positive definite.
fn inverse_cholesky_factor<const M: usize>(s: &SMatrix<f64, M, M>) -> Option<SMatrix<f64, M, M>> {
    let mut l = SMatrix::<f64, M, M>::zeros();
    for j in 0..M {
        let mut d = s[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        let ljj = d.sqrt();
        l[(j, j)] = ljj;
        for i in j + 1..M {
            let mut v = s[(i, j)];
            for k in 0..j {
                v -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = v / ljj;
        }
    }
    // Forward substitution, one column of L⁻¹ at a time.
    let mut inv = SMatrix::<f64, M, M>::zeros();
    for j in 0..M {
        inv[(j, j)] = 1.0 / l[(j, j)];
        for i in j + 1..M {
            let mut v = 0.0;
            for k in j..i {
                v -= l[(i, k)] * inv[(k, j)];
            }
            inv[(i, j)] = v / l[(i, i)];
        }
    }
    Some(inv)
}

/// The Kalman update of `est` by `m`, in place, with the Joseph form written out. With
/// `S = HPHᵀ + R`, `Kᵀ = S⁻¹ H P` and `U = HP − ½ S Kᵀ`:
/// `(I − KH) P (I − KH)ᵀ + K R Kᵀ = P − KHP − (KHP)ᵀ + K S Kᵀ = P − (K U + Uᵀ Kᵀ)` — the
/// same expression as [`kalman::update`]'s (first-order insensitive to errors in K, exactly
/// symmetric) for about `15²·M` multiplications instead of `2·15³`. On `Err`, `est` may be
/// partly updated (the caller discards it).
fn joseph_update<const M: usize>(
    est: &mut ErrorEstimate,
    m: &AidMeasurement<M>,
) -> Result<(), FilterError> {
    let h = &m.obs.h;
    let (hp, hph) = if bias_columns_zero(h) {
        let h9 = h.fixed_columns::<9>(0);
        let hp = h9 * est.p.fixed_rows::<9>(0);
        let hph = hp.fixed_columns::<9>(0) * h9.transpose();
        (hp, hph)
    } else {
        let hp = h * est.p;
        (hp, hp * h.transpose())
    };
    let s = symmetrise(&(hph + m.obs.r));
    let r = m.z - h * est.x;
    finite("innovation", &r)?;
    finite("innovation covariance", &s)?;
    // Kᵀ = S⁻¹ (H P): S is M × M and well conditioned (R bounds it below), so its inverse
    // S⁻¹ = L⁻ᵀ L⁻¹ costs less than 15 triangular solves and loses nothing.
    let l_inv = inverse_cholesky_factor(&s).ok_or(FilterError::NotPositiveDefinite)?;
    let kt = l_inv.transpose() * (l_inv * hp);
    finite("gain", &kt)?;
    let u = hp - (s * kt) * 0.5;
    let ktu = kt.transpose() * u;
    est.x += kt.transpose() * r;
    est.p -= ktu + ktu.transpose();
    finite("updated state", &est.x)?;
    finite("updated covariance", &est.p)
}

/// A Kalman update of `prior` by one aid measurement with the generic filter (the
/// reference the fast kernels are tested against).
#[cfg(test)]
fn kalman_update<const M: usize>(
    prior: &ErrorEstimate,
    m: &AidMeasurement<M>,
) -> Result<ErrorEstimate, FilterError> {
    let innov = kalman::innovation(prior, &m.obs, &m.z)?;
    Ok(kalman::update(prior, &m.obs, &innov)?.0)
}

/// Information fusion of two independent estimates, `P = (P_a⁻¹ + P_b⁻¹)⁻¹`,
/// `x = P (P_a⁻¹ x_a + P_b⁻¹ x_b)`, as the Kalman update of `a` by `z = x_b`, `H = I`,
/// `R = P_b` (Joseph form, no explicit inverse). It runs in the coordinates `D⁻¹ x` with
/// `D = diag(sqrt(diag(P_a + P_b)))`: the INS states' variances span 1e-17 to 1e2, and
/// unscaled products would bury the bias block in the position block's rounding.
fn fuse_estimates(a: &ErrorEstimate, b: &ErrorEstimate) -> Result<ErrorEstimate, FilterError> {
    let d = ErrorVector::from_fn(|i, _| (a.p[(i, i)] + b.p[(i, i)]).sqrt());
    if d.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        return Err(FilterError::NotPositiveDefinite);
    }
    let down = |e: &ErrorEstimate| StateEstimate {
        x: e.x.component_div(&d),
        p: ErrorMatrix::from_fn(|i, j| e.p[(i, j)] / (d[i] * d[j])),
    };
    let (sa, sb) = (down(a), down(b));
    let obs = LinearObservation::<U15, U15> {
        h: ErrorMatrix::identity(),
        r: sb.p,
    };
    let innov = kalman::innovation(&sa, &obs, &sb.x)?;
    let fused = kalman::update(&sa, &obs, &innov)?.0;
    Ok(StateEstimate {
        x: fused.x.component_mul(&d),
        p: ErrorMatrix::from_fn(|i, j| fused.p[(i, j)] * (d[i] * d[j])),
    })
}

/// HPL slope of one aid: `K_h = (P_g H_iᵀ R_i⁻¹)` rows east and north, and the diagonal of the
/// local test's `S⁻¹`. `R` is diagonal for every aid model (then `R⁻¹` is a division).
fn fused_slope<const M: usize>(
    p_g: &ErrorMatrix,
    m: &AidMeasurement<M>,
    s_inv: &SVector<f64, 6>,
) -> Result<f64, hpl::HplError> {
    let ph: SMatrix<f64, N, 2> = p_g.fixed_columns::<2>(POS).into_owned();
    let hph = m.obs.h * ph; // M × 2 = (P_g[h, :] Hᵀ)ᵀ
    let r = &m.obs.r;
    let diagonal = (0..M).all(|i| (0..M).all(|j| i == j || r[(i, j)] == 0.0));
    // K_h = P_g[h, :] Hᵀ R⁻¹  ⇔  R K_hᵀ = H P_g[:, h]  (R symmetric).
    let k_h_t = if diagonal {
        SMatrix::<f64, M, 2>::from_fn(|i, j| hph[(i, j)] / r[(i, i)])
    } else {
        let chol = r.cholesky().ok_or(hpl::HplError::NotPositiveDefinite)?;
        chol.solve(&hph)
    };
    let d: SVector<f64, M> = s_inv.fixed_rows::<M>(0).into_owned();
    hpl::slope_max_with::<M>(&k_h_t.transpose(), &d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::{Health, PolicyConfig, PolicyState};
    use crate::filter::aiding;
    use crate::filter::ins::{ACC, ATT, GYRO, VEL};
    use crate::geo::Lla;
    use crate::monitor::epoch::InsBlock;
    use nalgebra::{DMatrix, DVector, Dyn};
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;

    const HEALTHY: Decision = Decision {
        health: Health::Healthy,
        update: true,
        fuse: true,
        reset: false,
    };
    const SUSPECT: Decision = Decision {
        health: Health::Suspect,
        update: false,
        fuse: true,
        reset: false,
    };
    const ISOLATED: Decision = Decision {
        health: Health::Isolated,
        update: false,
        fuse: false,
        reset: false,
    };
    const RECOVERED: Decision = Decision {
        health: Health::Healthy,
        update: true,
        fuse: true,
        reset: true,
    };

    fn gauss(rng: &mut StdRng) -> f64 {
        rng.sample(StandardNormal)
    }

    /// A ship at 30° N heading 045° at 5 m/s, level, gravity only.
    fn ship() -> NavSolution {
        NavSolution::from_ins(&InsBlock {
            lat: 30f64.to_radians(),
            lon: 120f64.to_radians(),
            h: 0.0,
            vel: [5.0 * 0.5f64.sqrt(), 5.0 * 0.5f64.sqrt(), 0.0],
            att: [0.0, 0.0, 45f64.to_radians()],
            f_b: None,
        })
    }

    /// Seed 004's initial uncertainty: attitude 5″, 5″, 30″, velocity 0.1 m/s, position 10 m,
    /// gyro bias 0.002 °/h, accelerometer bias 10 µg.
    fn seed004_p0() -> ErrorMatrix {
        let imu = ImuErrors::default();
        let arcsec = (1.0f64 / 3600.0).to_radians();
        let mut d = ErrorVector::zeros();
        for i in 0..3 {
            d[ATT + i] = ([5.0, 5.0, 30.0][i] * arcsec).powi(2);
            d[VEL + i] = 0.01;
            d[POS + i] = 100.0;
            d[GYRO + i] = imu.gyro_bias_rps().powi(2);
            d[ACC + i] = imu.accel_bias_mps2().powi(2);
        }
        ErrorMatrix::from_diagonal(&d)
    }

    /// GNSS position, DVL and CNS measurements of the error `x` (noise-free unless `noise`).
    fn aid_observations(
        nav: &NavSolution,
        x: &ErrorVector,
        rng: Option<&mut StdRng>,
    ) -> [Option<Observation>; 3] {
        let fix = Lla { ..nav.lla };
        let mut g = aiding::gnss_velocity_position(nav, &fix, &nav.vel, 10.0, 0.1);
        let mut d = aiding::dvl_velocity(nav, &(nav.c_bn.transpose() * nav.vel), 0.1);
        let mut c = aiding::cns_position(nav, nav.lla.lat, nav.lla.lon, 450.0);
        g.z = g.predicted(x);
        d.z = d.predicted(x);
        c.z = c.predicted(x);
        if let Some(rng) = rng {
            for i in 0..6 {
                g.z[i] += g.obs.r[(i, i)].sqrt() * gauss(rng);
            }
            for i in 0..3 {
                d.z[i] += 0.1 * gauss(rng);
            }
            for i in 0..2 {
                c.z[i] += 450.0 * gauss(rng);
            }
        }
        [Some(g.into()), Some(d.into()), Some(c.into())]
    }

    fn initial(p0: ErrorMatrix) -> ErrorEstimate {
        StateEstimate {
            x: ErrorVector::zeros(),
            p: p0,
        }
    }

    #[test]
    fn sharing_factors_are_validated() {
        let init = initial(seed004_p0());
        assert_eq!(
            FederatedFilter::new(&[], init.clone()),
            Err(FederatedError::AidCount(0))
        );
        assert_eq!(
            FederatedFilter::new(&[0.5, 0.0, 0.5], init.clone()),
            Err(FederatedError::Beta {
                index: 1,
                value: 0.0
            })
        );
        assert!(matches!(
            FederatedFilter::new(&[0.5, 0.6], init.clone()),
            Err(FederatedError::BetaSum(_))
        ));
        let f = FederatedFilter::new(&equal_betas(3), init).unwrap();
        assert_eq!(f.betas().len(), 3);
        assert_cov_close(&f.local(1).p, &(f.master().p * 3.0), 1e-15);
    }

    #[test]
    fn long_intervals_compose_sub_steps_into_successive_predictions() {
        let nav = ship();
        let imu = ImuErrors::default();
        let long = ins_transition(&nav, &imu, 2.5).unwrap();
        let short = ins_transition(&nav, &imu, 2.5 / 3.0).unwrap();
        let mut a = initial(seed004_p0());
        for _ in 0..3 {
            a = kalman::predict(&a, &short).unwrap();
        }
        let b = kalman::predict(&initial(seed004_p0()), &long).unwrap();
        for i in 0..N {
            for j in 0..N {
                let scale = (a.p[(i, i)] * a.p[(j, j)]).sqrt();
                assert!((a.p[(i, j)] - b.p[(i, j)]).abs() <= 1e-12 * scale);
            }
        }
        let zero = ins_transition(&nav, &imu, 0.0).unwrap();
        assert_eq!(zero.f, ErrorMatrix::identity());
        assert_eq!(zero.q, ErrorMatrix::zeros());
        assert_eq!(
            ins_transition(&nav, &imu, -1.0),
            Err(FederatedError::Interval(-1.0))
        );
    }

    #[test]
    fn single_aid_with_beta_one_is_the_plain_kalman_filter() {
        // The same algebra as kalman::{predict, innovation, update}; the fast kernels
        // (block prediction, Joseph form written out) differ from them only in rounding.
        let nav = ship();
        let trans = ins_transition(&nav, &ImuErrors::default(), 0.1).unwrap();
        let mut rng = StdRng::seed_from_u64(1);
        let mut fed = FederatedFilter::new(&[1.0], initial(seed004_p0())).unwrap();
        let mut plain = initial(seed004_p0());
        let truth = ErrorVector::zeros();
        for _ in 0..300 {
            let [g, ..] = aid_observations(&nav, &truth, Some(&mut rng));
            let Some(Observation::D6(m)) = &g else {
                unreachable!()
            };
            let prior = kalman::predict(&plain, &trans).unwrap();
            let innov = kalman::innovation(&prior, &m.obs, &m.z).unwrap();
            plain = kalman::update(&prior, &m.obs, &innov).unwrap().0;
            let step = fed
                .step(&trans, std::slice::from_ref(&g), |_, _| HEALTHY)
                .unwrap();
            let lambda = step.aids[0].test.unwrap().statistic;
            assert!((lambda - innov.statistic).abs() <= 1e-10 * innov.statistic.max(1.0));
            fed.commit();
            assert_cov_close(&fed.master().p, &plain.p, 1e-10);
            assert_state_close(&fed.master().x, &plain.x, &plain.p, 1e-10);
        }
    }

    #[test]
    fn inverse_cholesky_factor_inverts_the_factor_and_refuses_indefinite_matrices() {
        // S = [[4, 2], [2, 5]] = L Lᵀ with L = [[2, 0], [1, 2]], L⁻¹ = [[1/2, 0], [−1/4, 1/2]].
        let s = SMatrix::<f64, 2, 2>::new(4.0, 2.0, 2.0, 5.0);
        let l_inv = inverse_cholesky_factor(&s).unwrap();
        assert_eq!(l_inv, SMatrix::<f64, 2, 2>::new(0.5, 0.0, -0.25, 0.5));
        let mut rng = StdRng::seed_from_u64(12);
        let a = SMatrix::<f64, 6, 6>::from_fn(|_, _| rng.random::<f64>() - 0.5);
        let s = a * a.transpose() + SMatrix::<f64, 6, 6>::identity() * 0.1;
        let l_inv = inverse_cholesky_factor(&s).unwrap();
        let s_inv = l_inv.transpose() * l_inv;
        assert!((s_inv * s - SMatrix::<f64, 6, 6>::identity()).amax() < 1e-12);
        assert!(inverse_cholesky_factor(&SMatrix::<f64, 2, 2>::new(1.0, 2.0, 2.0, 1.0)).is_none());
        assert!(inverse_cholesky_factor(&SMatrix::<f64, 1, 1>::new(f64::NAN)).is_none());
    }

    #[test]
    fn fast_kernels_equal_the_generic_kalman_filter() {
        let mut rng = StdRng::seed_from_u64(11);
        for _ in 0..20 {
            // Dense (non-INS) Φ and H take the generic paths, INS ones the structured ones.
            let (dense, obs) = synthetic(&mut rng);
            let ins = ins_transition(&ship(), &ImuErrors::default(), 1.0).unwrap();
            for trans in [dense, ins] {
                let a = ErrorMatrix::from_fn(|_, _| rng.random::<f64>() - 0.5);
                let est = StateEstimate {
                    x: ErrorVector::from_fn(|_, _| rng.random::<f64>()),
                    p: a * a.transpose() + ErrorMatrix::identity(),
                };
                let mut fast = est.clone();
                predict_into(&est, &trans, &mut fast).unwrap();
                let slow = kalman::predict(&est, &trans).unwrap();
                assert_cov_close(&fast.p, &slow.p, 1e-13);
                assert_eq!(fast.p, fast.p.transpose());
                for o in obs.iter().flatten() {
                    with_measurement!(o, m => {
                        let (lambda, _) = share_test(&slow, 0.25, m).unwrap();
                        let innov =
                            kalman::innovation(&scaled(&slow, 0.25), &m.obs, &m.z).unwrap();
                        assert!((lambda - innov.statistic).abs() <= 1e-12 * innov.statistic);
                        let mut fast = slow.clone();
                        joseph_update(&mut fast, m).unwrap();
                        let reference = kalman_update(&slow, m).unwrap();
                        assert_cov_close(&fast.p, &reference.p, 1e-12);
                        assert_state_close(&fast.x, &reference.x, &reference.p, 1e-12);
                        assert_eq!(fast.p, fast.p.transpose());
                    });
                }
            }
        }
        // Aid H have zero bias columns (the sparse path) at the INS state's scales.
        let nav = ship();
        let mut est = initial(seed004_p0());
        let trans = ins_transition(&nav, &ImuErrors::default(), 1.0).unwrap();
        for o in aid_observations(&nav, &ErrorVector::zeros(), Some(&mut rng))
            .iter()
            .flatten()
        {
            with_measurement!(o, m => {
                assert!(bias_columns_zero(&m.obs.h));
                let prior = kalman::predict(&est, &trans).unwrap();
                let mut fast = prior.clone();
                joseph_update(&mut fast, m).unwrap();
                let reference = kalman_update(&prior, m).unwrap();
                assert_cov_close(&fast.p, &reference.p, 1e-10);
                assert_state_close(&fast.x, &reference.x, &reference.p, 1e-10);
                est = reference;
            });
        }
    }

    /// Per-element comparison of covariances scaled by their standard deviations.
    fn assert_cov_close(a: &ErrorMatrix, b: &ErrorMatrix, tol: f64) {
        for i in 0..N {
            for j in 0..N {
                let scale = (b[(i, i)] * b[(j, j)]).sqrt();
                assert!(
                    (a[(i, j)] - b[(i, j)]).abs() <= tol * scale,
                    "P[({i}, {j})]: {} vs {}",
                    a[(i, j)],
                    b[(i, j)]
                );
            }
        }
    }

    fn assert_state_close(a: &ErrorVector, b: &ErrorVector, p: &ErrorMatrix, tol: f64) {
        for i in 0..N {
            assert!(
                (a[i] - b[i]).abs() <= tol * p[(i, i)].sqrt(),
                "x[{i}]: {} vs {}",
                a[i],
                b[i]
            );
        }
    }

    #[test]
    fn all_healthy_with_reset_every_epoch_equals_the_centralised_filter() {
        let nav = ship();
        let trans = ins_transition(&nav, &ImuErrors::default(), 1.0).unwrap();
        let trans_dyn = LinearTransition::<Dyn> {
            f: DMatrix::from_column_slice(N, N, trans.f.as_slice()),
            q: DMatrix::from_column_slice(N, N, trans.q.as_slice()),
        };
        let mut rng = StdRng::seed_from_u64(2);
        let mut fed = FederatedFilter::new(&[0.5, 0.3, 0.2], initial(seed004_p0())).unwrap();
        let mut central = StateEstimate::<Dyn> {
            x: DVector::zeros(N),
            p: DMatrix::from_column_slice(N, N, seed004_p0().as_slice()),
        };
        let truth = ErrorVector::zeros();
        for _ in 0..200 {
            let obs = aid_observations(&nav, &truth, Some(&mut rng));
            // Stack the 6 + 3 + 2 measurements into one 11-row batch update.
            let (mut h, mut r, mut z) = (
                DMatrix::zeros(11, N),
                DMatrix::zeros(11, 11),
                DVector::zeros(11),
            );
            let mut row = 0;
            for o in obs.iter().flatten() {
                with_measurement!(o, m => {
                    let k = m.z.len();
                    h.view_mut((row, 0), (k, N)).copy_from(&m.obs.h);
                    r.view_mut((row, row), (k, k)).copy_from(&m.obs.r);
                    z.rows_mut(row, k).copy_from(&m.z);
                    row += k;
                });
            }
            let batch = LinearObservation::<Dyn, Dyn> { h, r };
            let prior = kalman::predict(&central, &trans_dyn).unwrap();
            let innov = kalman::innovation(&prior, &batch, &z).unwrap();
            central = kalman::update(&prior, &batch, &innov).unwrap().0;

            fed.step(&trans, &obs, |_, _| HEALTHY).unwrap();
            fed.commit();
            let p = ErrorMatrix::from_column_slice(central.p.as_slice());
            let x = ErrorVector::from_column_slice(central.x.as_slice());
            assert_cov_close(&fed.master().p, &p, 1e-8);
            assert_state_close(&fed.master().x, &x, &p, 1e-8);
        }
    }

    /// The federated filter written out: every local filter stored and predicted with
    /// `Q/β_i`, the fused ones' shares renormalised (prior covariance × Σ_fused β), fused
    /// with explicit inverses `P_g = (Σ P_i⁻¹)⁻¹`, and reset.
    struct Reference {
        betas: Vec<f64>,
        master: ErrorEstimate,
        locals: Vec<ErrorEstimate>,
    }

    impl Reference {
        fn new(betas: &[f64], init: &ErrorEstimate) -> Self {
            Reference {
                betas: betas.to_vec(),
                master: init.clone(),
                locals: betas.iter().map(|&b| scaled(init, b)).collect(),
            }
        }

        fn step(
            &mut self,
            trans: &LinearTransition<U15>,
            obs: &[Option<Observation>],
            decisions: &[Decision],
        ) -> Vec<Option<f64>> {
            let master_prior = kalman::predict(&self.master, trans).unwrap();
            let total: f64 = (0..self.betas.len())
                .filter(|&i| decisions[i].fuse)
                .map(|i| self.betas[i])
                .sum();
            let mut posts = Vec::new();
            let mut lambdas = Vec::new();
            for (i, beta) in self.betas.iter().enumerate() {
                let local = LinearTransition {
                    f: trans.f,
                    q: trans.q / *beta,
                };
                let mut prior = kalman::predict(&self.locals[i], &local).unwrap();
                let d = decisions[i];
                lambdas.push(obs[i].as_ref().map(|o| {
                    with_measurement!(o, m => kalman::innovation(&prior, &m.obs, &m.z).unwrap().statistic)
                }));
                if d.reset {
                    prior = scaled(&master_prior, *beta);
                }
                if d.fuse {
                    prior.p *= total; // shares renormalised over the fused filters
                }
                let post = match &obs[i] {
                    Some(o) if d.update => {
                        with_measurement!(o, m => kalman_update(&prior, m).unwrap())
                    }
                    _ => prior,
                };
                posts.push(post);
            }
            let fused: Vec<usize> = (0..self.betas.len())
                .filter(|&i| decisions[i].fuse)
                .collect();
            self.master = if fused.is_empty() {
                master_prior
            } else {
                let mut y = ErrorMatrix::zeros();
                let mut v = ErrorVector::zeros();
                for &i in &fused {
                    let inv = posts[i].p.try_inverse().unwrap();
                    y += inv;
                    v += inv * posts[i].x;
                }
                let p = y.try_inverse().unwrap();
                StateEstimate {
                    x: p * v,
                    p: (p + p.transpose()) * 0.5,
                }
            };
            for (i, post) in posts.into_iter().enumerate() {
                self.locals[i] = if decisions[i].fuse {
                    scaled(&self.master, self.betas[i])
                } else {
                    post
                };
            }
            lambdas
        }
    }

    /// A random well-conditioned 15-state model: Φ near I, Q, and aids of 6, 3 and 2 rows.
    fn synthetic(rng: &mut StdRng) -> (LinearTransition<U15>, [Option<Observation>; 3]) {
        let mut u = |scale: f64| scale * (rng.random::<f64>() - 0.5);
        let f = ErrorMatrix::identity() + ErrorMatrix::from_fn(|_, _| u(0.1));
        let a = ErrorMatrix::from_fn(|_, _| u(0.2));
        let q = a * a.transpose() + ErrorMatrix::identity() * 0.01;
        fn aid<const M: usize>(u: &mut impl FnMut(f64) -> f64) -> AidMeasurement<M> {
            let b = SMatrix::<f64, M, M>::from_fn(|_, _| u(1.0));
            AidMeasurement {
                z: SVector::<f64, M>::from_fn(|_, _| u(4.0)),
                obs: LinearObservation {
                    h: SMatrix::<f64, M, N>::from_fn(|_, _| u(2.0)),
                    r: b * b.transpose() + SMatrix::<f64, M, M>::identity() * 0.5,
                },
            }
        }
        let obs = [
            Some(Observation::D6(aid::<6>(&mut u))),
            Some(Observation::D3(aid::<3>(&mut u))),
            Some(Observation::D2(aid::<2>(&mut u))),
        ];
        (LinearTransition { f, q }, obs)
    }

    #[test]
    fn shared_prediction_and_sequential_fusion_match_the_straightforward_form() {
        let mut rng = StdRng::seed_from_u64(3);
        let betas = [0.5, 0.25, 0.25];
        let init = initial(ErrorMatrix::identity() * 2.0);
        let mut fed = FederatedFilter::new(&betas, init.clone()).unwrap();
        let mut reference = Reference::new(&betas, &init);
        let choices = [HEALTHY, SUSPECT, ISOLATED, RECOVERED];
        let mut seen = [false; 4];
        for epoch in 0..300 {
            let (trans, mut obs) = synthetic(&mut rng);
            for o in obs.iter_mut() {
                if rng.random::<f64>() < 0.2 {
                    *o = None;
                }
            }
            // Mostly healthy; every kind of decision, including the classic policy's return
            // without reset (a filter with its own estimate fused again).
            let decisions: Vec<Decision> = (0..3)
                .map(|_| {
                    let pick = if rng.random::<f64>() < 0.5 {
                        0
                    } else {
                        rng.random_range(0..4)
                    };
                    seen[pick] = true;
                    choices[pick]
                })
                .collect();
            let lambdas = reference.step(&trans, &obs, &decisions);
            let step = fed.step(&trans, &obs, |i, _| decisions[i]).unwrap();
            for (i, lambda) in lambdas.iter().enumerate() {
                match (step.aids[i].test, *lambda) {
                    (Some(t), Some(l)) => {
                        assert!(
                            (t.statistic - l).abs() <= 1e-9 * l.max(1.0),
                            "epoch {epoch}"
                        )
                    }
                    (None, None) => {}
                    other => panic!("epoch {epoch}: tests differ {other:?}"),
                }
            }
            fed.commit();
            assert_cov_close(&fed.master().p, &reference.master.p, 1e-9);
            assert_state_close(
                &fed.master().x,
                &reference.master.x,
                &reference.master.p,
                1e-9,
            );
            for i in 0..3 {
                let local = fed.local(i);
                assert_cov_close(&local.p, &reference.locals[i].p, 1e-9);
                assert_state_close(&local.x, &reference.locals[i].x, &local.p, 1e-9);
            }
        }
        assert_eq!(seen, [true; 4]);
    }

    #[test]
    fn suspect_filters_are_fused_without_their_update() {
        let nav = ship();
        let trans = ins_transition(&nav, &ImuErrors::default(), 1.0).unwrap();
        let mut rng = StdRng::seed_from_u64(4);
        let mut fed = FederatedFilter::new(&equal_betas(3), initial(seed004_p0())).unwrap();
        // A GNSS fault of 300 m east: suspect, so the master never sees it.
        let mut obs = aid_observations(&nav, &ErrorVector::zeros(), Some(&mut rng));
        if let Some(Observation::D6(g)) = &mut obs[0] {
            g.z[3] += 300.0;
        }
        let step = fed
            .step(&trans, &obs, |i, _| if i == 0 { SUSPECT } else { HEALTHY })
            .unwrap();
        assert!(!step.aids[0].updated && step.aids[0].fused);
        assert!(step.aids[0].test.unwrap().statistic > 100.0);
        // The same as a plain KF from the master prior with only DVL and CNS (B = 1: the
        // suspect filter still brings its share of the prior information).
        let mut expect = kalman::predict(&initial(seed004_p0()), &trans).unwrap();
        for o in obs[1..].iter().flatten() {
            expect = with_measurement!(o, m => kalman_update(&expect, m).unwrap());
        }
        assert_cov_close(&fed.pending().unwrap().master.p, &expect.p, 1e-9);
        assert_state_close(&fed.pending().unwrap().master.x, &expect.x, &expect.p, 1e-9);
        assert!(
            fed.pending().unwrap().own[0].is_none(),
            "a fused filter is reset to the master"
        );
        assert!(step.aids[0].slope.is_none() && step.aids[1].slope.is_some());
    }

    #[test]
    fn isolated_filters_are_left_out_and_reset_from_the_master_on_recovery() {
        let nav = ship();
        let trans = ins_transition(&nav, &ImuErrors::default(), 1.0).unwrap();
        let mut rng = StdRng::seed_from_u64(5);
        let betas = equal_betas(3);
        let mut fed = FederatedFilter::new(&betas, initial(seed004_p0())).unwrap();
        let mut policy = PolicyState::new(PolicyConfig::counters_default());
        let truth = ErrorVector::zeros();
        let mut states = Vec::new();
        for epoch in 0..40 {
            let mut obs = aid_observations(&nav, &truth, Some(&mut rng));
            let faulty = (5..15).contains(&epoch);
            if faulty && let Some(Observation::D6(g)) = &mut obs[0] {
                g.z[4] += 200.0;
            }
            let master_prior = kalman::predict(fed.master(), &trans).unwrap();
            let before = fed.state().own[0].clone();
            let step = fed
                .step(&trans, &obs, |i, test| match (i, test) {
                    (0, Some(t)) => policy.step(t.statistic > 20.0),
                    _ => HEALTHY,
                })
                .unwrap();
            let a = step.aids[0];
            states.push(a.decision.health);
            if a.decision.health == Health::Isolated {
                assert!(!a.fused && !a.updated);
                // Left out: the fused solution is the DVL + CNS filters' alone, from the
                // whole master prior (their shares renormalised to 1/2 each).
                let mut expect = master_prior.clone();
                for o in obs[1..].iter().flatten() {
                    expect = with_measurement!(o, m => kalman_update(&expect, m).unwrap());
                }
                assert_cov_close(&fed.pending().unwrap().master.p, &expect.p, 1e-9);
                assert_state_close(&fed.pending().unwrap().master.x, &expect.x, &expect.p, 1e-9);
                assert!(
                    fed.pending().unwrap().own[0].is_some(),
                    "an isolated filter keeps its own state"
                );
            }
            if a.decision.reset {
                assert!(
                    before.is_some(),
                    "only a filter with its own state is reset"
                );
                assert!(a.updated && a.fused);
                assert!(fed.pending().unwrap().own[0].is_none());
            }
            fed.commit();
        }
        // Counters: suspect from the first exceedance, isolated after N2 = 5 more, healthy
        // (and reset) once N1 = 10 quiet epochs have passed.
        assert_eq!(states[4], Health::Healthy);
        assert_eq!(states[5], Health::Suspect);
        assert_eq!(states[11], Health::Isolated);
        let back = states.iter().rposition(|&h| h != Health::Healthy).unwrap() + 1;
        assert_eq!(
            back, 24,
            "N1 = 10 quiet epochs after the last exceedance at epoch 14"
        );
        assert!(states[back..].iter().all(|&h| h == Health::Healthy));
    }

    #[test]
    fn fused_covariance_stays_symmetric_positive_definite_under_random_decisions() {
        let nav = ship();
        let trans = ins_transition(&nav, &ImuErrors::default(), 0.1).unwrap();
        let mut rng = StdRng::seed_from_u64(6);
        let mut fed = FederatedFilter::new(&[0.4, 0.4, 0.2], initial(seed004_p0())).unwrap();
        let truth = ErrorVector::zeros();
        let choices = [HEALTHY, SUSPECT, ISOLATED, RECOVERED];
        for epoch in 0..1500 {
            let mut obs = aid_observations(&nav, &truth, Some(&mut rng));
            for o in obs.iter_mut() {
                if rng.random::<f64>() < 0.5 {
                    *o = None;
                }
            }
            let d: Vec<Decision> = (0..3).map(|_| choices[rng.random_range(0..4)]).collect();
            fed.step(&trans, &obs, |i, _| d[i]).unwrap();
            fed.commit();
            let p = fed.master().p;
            assert_eq!(p, p.transpose());
            assert!(
                p.cholesky().is_some(),
                "epoch {epoch}: {d:?} {:?}",
                obs.iter().map(|o| o.is_some()).collect::<Vec<_>>()
            );
            for i in 0..3 {
                assert!(fed.local(i).p.cholesky().is_some());
            }
        }
    }

    /// Innovation covariance of `m` against `prior`.
    fn innovation_cov<const M: usize>(
        prior: &ErrorEstimate,
        m: &AidMeasurement<M>,
    ) -> DMatrix<f64> {
        let s = m.obs.h * prior.p * m.obs.h.transpose() + m.obs.r;
        DMatrix::from_column_slice(M, M, s.as_slice())
    }

    #[test]
    fn innovations_are_chi_square_consistent_on_a_simulated_ship() {
        // Truth: the INS error propagated with the same Φ and sampled white noise G w, seed
        // 004's initial errors and biases; aids with their white noise. 3,000 s at 1 Hz.
        let nav = ship();
        let imu = ImuErrors::default();
        let dt = 1.0;
        let trans = ins_transition(&nav, &imu, dt).unwrap();
        let g = ins::noise_input(&nav);
        let p0 = seed004_p0();
        let mut rng = StdRng::seed_from_u64(7);
        let mut truth = ErrorVector::from_fn(|i, _| p0[(i, i)].sqrt() * gauss(&mut rng));
        let mut fed = FederatedFilter::new(&equal_betas(3), initial(p0)).unwrap();
        let epochs = 3000;
        // Per aid: Σ centralised NIS, Σ local NIS, Σ its expectation and variance.
        let mut central = [0.0; 3];
        let mut local = [0.0; 3];
        let mut local_mean = [0.0; 3];
        let mut local_var = [0.0; 3];
        let mut dofs = [0u32; 3];
        for _ in 0..epochs {
            let w = SVector::<f64, 6>::from_fn(|i, _| {
                let psd = if i < 3 {
                    imu.gyro_noise_psd()
                } else {
                    imu.accel_noise_psd()
                };
                (psd * dt).sqrt() * gauss(&mut rng)
            });
            truth = trans.f * truth + g * w;
            let obs = aid_observations(&nav, &truth, Some(&mut rng));
            let prior = kalman::predict(fed.master(), &trans).unwrap();
            for (i, o) in obs.iter().enumerate() {
                let o = o.as_ref().unwrap();
                dofs[i] = o.dof();
                central[i] += with_measurement!(o, m => kalman::innovation(&prior, &m.obs, &m.z).unwrap().statistic);
                // E[λ_i] = tr(S_i⁻¹ S) and Var = 2 tr((S_i⁻¹ S)²), S_i = local (P/β_i).
                let (s_i, s) = with_measurement!(o, m => (
                    innovation_cov(&scaled(&prior, 1.0 / 3.0), m),
                    innovation_cov(&prior, m),
                ));
                let a = s_i.cholesky().unwrap().solve(&s);
                local_mean[i] += a.trace();
                local_var[i] += 2.0 * (&a * &a).trace();
            }
            let step = fed.step(&trans, &obs, |_, _| HEALTHY).unwrap();
            for (sum, aid) in local.iter_mut().zip(&step.aids) {
                *sum += aid.test.unwrap().statistic;
            }
            fed.commit();
        }
        let k = f64::from(epochs);
        for i in 0..3 {
            // Centralised NIS ~ χ²(m): mean m, standard error sqrt(2m/K); 4σ bound.
            let m = f64::from(dofs[i]);
            let mean = central[i] / k;
            assert!(
                (mean - m).abs() < 4.0 * (2.0 * m / k).sqrt(),
                "aid {i}: centralised NIS mean {mean} for dof {m}"
            );
            // Local NIS: its own (smaller) expectation, as the local P_i = P_g/β_i is inflated.
            assert!(
                (local[i] - local_mean[i]).abs() < 4.0 * local_var[i].sqrt(),
                "aid {i}: local NIS sum {} vs expected {}",
                local[i],
                local_mean[i]
            );
            assert!(local_mean[i] / k <= m);
        }
        // The final fused error is inside its covariance: NEES of position and velocity.
        let e = fed.master().x - truth;
        let nav_block = |v: &ErrorVector| SVector::<f64, 6>::from_fn(|i, _| v[VEL + i]);
        let p6 = fed.master().p.fixed_view::<6, 6>(VEL, VEL).into_owned();
        let nees = nav_block(&e).dot(&p6.cholesky().unwrap().solve(&nav_block(&e)));
        // χ²(6) at p = 1e-4: 27.86.
        assert!(nees < 27.86, "NEES {nees}");
    }
}
