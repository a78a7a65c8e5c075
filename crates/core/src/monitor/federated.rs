//! The `federated` monitor (docs/methods.md §M6, §M7, §M23, §M24; docs/architecture.md §A6;
//! seed 004): an INS aided by GNSS, DVL and CNS through the federated filter of
//! [`crate::filter::federated`], one χ² test per configured aid (`gnss`, `dvl`, `cns`) under
//! the session's policy, beside it the aid's drift and stuck tests (`gnss.drift`,
//! `gnss.stuck`, …), and the integrity availability of the solution from the horizontal
//! protection level against the alert limit. The session actor steps it once per epoch.
//!
//! # Epochs
//! - It runs on epochs that carry `ins` (1–100 Hz) and ignores the others (no tests, the last
//!   outputs repeated). The first INS epoch initialises the filter from the `init` config
//!   (zero error, no prediction) and already uses any aid that comes with it.
//! - `gnss`, `dvl`, `cns` are used when present, as of the INS epoch they arrive with; any may
//!   be absent for any stretch (the local filter then predicts only, its policies idle).
//!   A `gnss` block with `vel` gives the 6-dim measurement `[δV; δP]` of seed 004 eq. 3 (the
//!   `gnss` test then has dof 6), without `vel` the 3-dim position one (dof 3); both
//!   thresholds are resolved when the spec is set, never per epoch.
//! - The interval since the previous INS epoch drives the prediction: `dt = 0` (a second
//!   frame of the same instant) predicts nothing; up to [`MAX_GAP_S`] it is predicted in
//!   sub-steps of at most 1 s; a longer gap (or time going back) restarts the filter from
//!   the `init` uncertainty, as the INS may have drifted beyond the linearised model.
//!   Policies (and the drift and stuck tests' histories) keep their state across a restart.
//!
//! # Tests
//! Per aid, `λ_i = rᵀ S⁻¹ r` of its local filter (dof 6 or 3 for `gnss`, 3 for `dvl`, 2 for
//! `cns`), thresholds and policy from the monitor's spec; its normalised innovation
//! `ν = L⁻¹ r` feeds the test's consistency diagnostics (docs/methods.md §M22). Beside it,
//! as the config enables them (docs/methods.md §M23, [`super::guards`]): `<aid>.drift`, a
//! windowed-mean test on `ν` (GNSS: its horizontal position components, dof 2; DVL 3; CNS 2) under
//! the monitor's threshold and policy, and `<aid>.stuck`, the variance collapse of the same
//! `ν` (dof 1, its own threshold, default p_fa 1e-6). The aid's local filter follows the
//! *combined* decision of its tests: the worst health, an update only when every test
//! allows it, fusion only when every test allows it; under counters, a filter whose combined
//! health leaves `isolated` is reset from the master.
//!
//! # Integrity (docs/methods.md §M7, §M24, see [`crate::detect::hpl`])
//! `HPL₁ = k_md σ_h` from the fused `P_g`; `HPL₂ = max_i slope_i sqrt(λ_det,i)` over the aids
//! that take part in fusion, `λ_det,i` for the aid's dof and threshold at `p_md`. An aid's slope
//! is computed when it updates (gain onto the fused solution, its local `S`) and kept until its
//! next update, so the HPL does not jump between aid epochs at a 10 Hz INS rate; an aid left
//! out of fusion drops out of `HPL₂`. HPL against `hal_m` is not a test: it makes
//! [`MonitorReport::integrity`] `converging`, `available` or `unavailable` every INS epoch
//! ([`integrity`] defines them), a state of the solution rather than a fault of a sensor.
//!
//! # Outputs
//! `solution {lat, lon (degrees), h (m), vel (m/s ENU)}`: the INS solution minus the fused
//! error estimate (open loop); `hpl` (m); `isolated`: the aids left out of fusion (combined
//! health `isolated`).

mod config;
mod imu;
mod integrity;
mod saved;

pub use config::{
    BetaSection, CNS_DRIFT_DEFAULT_ON, CnsNoise, DEFAULT_CONVERGE_MAX_S, DEFAULT_HAL_M,
    DVL_DRIFT_DEFAULT_ON, DvlNoise, FederatedConfig, FederatedConfigWire, GNSS_DRIFT_DEFAULT_ON,
    GnssNoise, ImuSection, InitSigma, MAX_GAP_S, STUCK_DEFAULT_ON,
};
pub use imu::{
    AlignSection, Alignment, DEFAULT_REINIT_AFTER_S, FrontState, InputKind, StrapdownConfig,
    StrapdownSection,
};

use nalgebra::{Matrix2, Vector3};
use serde::{Deserialize, Serialize};

use super::guards::{GuardPreview, InnovationGuards, worse};
use super::{
    BuildError, CheckpointError, ConfigError, EpochError, Integrity, Monitor, MonitorKind,
    MonitorReport, Outputs, StepError, TestBank, TestOutcome,
};
use crate::detect::hpl::{self, DetectionNoncentrality, HplError};
use crate::detect::{Decision, Health, PolicyConfig, PolicyState, ThresholdError, ThresholdSpec};
use crate::epoch::{Aid, Epoch, GnssBlock};
use crate::filter::aiding;
use crate::filter::federated::{
    self, ErrorEstimate, FederatedFilter, LocalTest, MAX_AIDS, Observation,
};
use crate::filter::ins::{ErrorMatrix, NavSolution, POS, VEL};
use crate::filter::kalman::{FilterError, LinearTransition};
use crate::geo::{self, Lla};
use crate::monitor::{Availability, Integrity as IntegrityReport};
use integrity::Convergence;

/// The part of an aid's normalised innovation its drift and stuck tests watch: GNSS its
/// horizontal position components (east and north, the 4th and 5th of `[δV; δP]` or the
/// first two of `δP`: whitening by the Cholesky factor makes a prefix of `ν` the whitened
/// prefix, so these are the horizontal position innovations given the velocity ones,
/// covariance `I` either way; the horizontal solution is what the protection level
/// guards, docs/methods.md §M23), the others all of it.
fn guard_input(aid: Aid, test: &LocalTest) -> &[f64] {
    let nu = test.nu();
    match aid {
        Aid::Gnss => {
            let east = nu.len().saturating_sub(3);
            &nu[east..east + 2]
        }
        Aid::Dvl | Aid::Cns => nu,
    }
}

/// The dimension of [`guard_input`] for `aid`.
fn guard_dim(aid: Aid) -> usize {
    match aid {
        Aid::Dvl => 3,
        Aid::Gnss | Aid::Cns => 2,
    }
}

/// The corrected navigation solution on the wire: degrees, metres, m/s ENU.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FederatedSolution {
    /// Latitude, degrees.
    pub lat: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Ellipsoidal height, m.
    pub h: f64,
    /// Velocity east, north, up, m/s.
    pub vel: [f64; 3],
    /// Roll, pitch, yaw of the mechanized solution, degrees (`input: imu` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub att: Option<[f64; 3]>,
}

/// The `federated` monitor.
#[derive(Debug, Clone)]
pub struct FederatedMonitor {
    config: FederatedConfig,
    filter: FederatedFilter,
    bank: TestBank,
    /// Per aid (in `aids` order), its drift and stuck tests.
    guards: Vec<InnovationGuards>,
    /// Converging, then available or unavailable (docs/methods.md §M24).
    convergence: Convergence,
    k_md: f64,
    lambda_det: DetectionNoncentrality,
    /// Per aid, `slope · sqrt(λ_det)` from its last update while fused.
    hpl2: [Option<f64>; MAX_AIDS],
    /// Time of the last INS epoch.
    last_t: Option<f64>,
    outputs: Outputs,
    /// The step's transition, written in place each epoch (not state: a checkpoint does not
    /// save it). A field rather than a local because a local would be zero-filled every
    /// epoch (3.6 kB) before being overwritten, and a returned one copied.
    trans: LinearTransition<nalgebra::U15>,
    /// With `input: imu`, the strapdown front end's state (module [`imu`]).
    front: Option<FrontState>,
}

impl FederatedMonitor {
    /// Builds the monitor: one test per aid (gnss: dof 6, also 3), then each aid's drift and
    /// stuck tests as its config enables them.
    pub fn new(
        config: FederatedConfig,
        policy: PolicyConfig,
        spec: ThresholdSpec,
    ) -> Result<Self, BuildError> {
        let tests: Vec<(&str, u32)> = config
            .aids
            .iter()
            .map(|a| {
                let dof = match a {
                    Aid::Gnss => 6,
                    Aid::Dvl => 3,
                    Aid::Cns => 2,
                };
                (a.as_str(), dof)
            })
            .collect();
        let mut bank = TestBank::new(&tests, spec, policy)?;
        if let Some(i) = config.aids.iter().position(|&a| a == Aid::Gnss) {
            bank.add_dofs(i, &[3])?;
        }
        let guards = config
            .aids
            .iter()
            .zip(&config.guards)
            .map(|(&aid, g)| InnovationGuards::new(&mut bank, aid.as_str(), guard_dim(aid), g))
            .collect::<Result<Vec<_>, ThresholdError>>()?;
        let filter = FederatedFilter::new(&config.beta, config.initial_estimate())
            .map_err(|e| ConfigError::new("beta", e.to_string()))?;
        let k_md = hpl::k_md(config.p_md).map_err(|e| ConfigError::new("p_md", e.to_string()))?;
        let lambda_det = DetectionNoncentrality::new(config.p_md)
            .map_err(|e| ConfigError::new("p_md", e.to_string()))?;
        let convergence = Convergence::new(config.converge_max_s);
        Ok(FederatedMonitor {
            filter,
            bank,
            guards,
            convergence,
            k_md,
            lambda_det,
            hpl2: [None; MAX_AIDS],
            last_t: None,
            outputs: Outputs::Federated {
                solution: None,
                hpl: None,
                isolated: Vec::new(),
                alignment: config.strapdown.as_ref().map(|_| Alignment::Levelling),
            },
            trans: LinearTransition {
                f: ErrorMatrix::identity(),
                q: ErrorMatrix::zeros(),
            },
            front: config.strapdown.as_ref().map(FrontState::new),
            config,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &FederatedConfig {
        &self.config
    }

    /// The federated filter (fused and local estimates).
    pub fn filter(&self) -> &FederatedFilter {
        &self.filter
    }

    /// The epoch's GNSS fix where the INS is: with `input: imu` moved from the antenna by
    /// the lever arm, else as given.
    fn gnss_fix(&self, nav: &NavSolution, epoch: &Epoch) -> Option<GnssBlock> {
        let g = epoch.gnss.as_ref()?;
        Some(match (&self.config.strapdown, &self.front) {
            (Some(cfg), Some(front)) => imu::fix_at_imu(g, nav, &front.last_rate(), &cfg.lever_b),
            _ => g.clone(),
        })
    }

    /// This epoch's measurement for `aid`, when the epoch carries it. A GNSS fix's own σ
    /// (`pos_sigma`, `vel_sigma`) replaces the configured one.
    fn observation(&self, aid: Aid, nav: &NavSolution, epoch: &Epoch) -> Option<Observation> {
        let c = &self.config;
        match aid {
            Aid::Gnss => self.gnss_fix(nav, epoch).map(|g| {
                let fix = Lla {
                    lat: g.lat,
                    lon: g.lon,
                    h: g.h,
                };
                match g.vel {
                    Some(v) => {
                        let mut m = aiding::gnss_velocity_position(
                            nav,
                            &fix,
                            &Vector3::from(v),
                            c.gnss_pos_sigma_m,
                            c.gnss_vel_sigma_mps,
                        );
                        if let Some(s) = &g.vel_sigma {
                            m.set_sigmas(0, s);
                        }
                        if let Some(s) = &g.pos_sigma {
                            m.set_sigmas(3, s);
                        }
                        m.into()
                    }
                    None => {
                        let mut m = aiding::gnss_position(nav, &fix, c.gnss_pos_sigma_m);
                        if let Some(s) = &g.pos_sigma {
                            m.set_sigmas(0, s);
                        }
                        m.into()
                    }
                }
            }),
            Aid::Dvl => epoch
                .dvl_vel_b
                .map(|v| aiding::dvl_velocity(nav, &Vector3::from(v), c.dvl_vel_sigma_mps).into()),
            Aid::Cns => epoch
                .cns
                .as_ref()
                .map(|f| aiding::cns_position(nav, f.lat, f.lon, c.cns_pos_sigma_m).into()),
        }
    }

    /// Aid `i`'s combined health now: the worst of its χ² test's and its guards'.
    fn aid_health(&self, i: usize) -> Health {
        worse(
            self.bank.slots()[i].policy.health(),
            self.guards[i].worst_health(&self.bank),
        )
    }

    fn isolated(&self) -> Vec<&'static str> {
        self.config
            .aids
            .iter()
            .enumerate()
            .filter(|&(i, _)| self.aid_health(i) == Health::Isolated)
            .map(|(_, a)| a.as_str())
            .collect()
    }

    /// The transition since the last INS epoch, into `self.trans`, and whether the filter
    /// restarts (module doc, Epochs): a first epoch, a gap over [`MAX_GAP_S`] or time going
    /// back restarts with `Φ = I`, `Q = 0`; otherwise [`federated::ins_transition`] over `dt`.
    fn transition(&mut self, nav: &NavSolution, t: f64) -> Result<bool, StepError> {
        let dt = self.last_t.map(|last| t - last);
        let dt = dt.filter(|d| (0.0..=MAX_GAP_S).contains(d));
        self.transition_over(nav, dt)?;
        Ok(dt.is_none())
    }

    /// The transition over `dt` seconds into `self.trans`; `None`: a restart (`Φ = I`, `Q = 0`).
    fn transition_over(&mut self, nav: &NavSolution, dt: Option<f64>) -> Result<(), StepError> {
        let trans = &mut self.trans;
        match dt {
            None => {
                trans.f = ErrorMatrix::identity();
                trans.q = ErrorMatrix::zeros();
            }
            Some(dt) => federated::ins_transition_into(nav, &self.config.imu, dt, trans)
                .map_err(|_| FilterError::NonFinite("prediction interval"))?,
        }
        Ok(())
    }

    /// The federated filter's epoch over `self.trans`, its state left pending. Each aid's tests
    /// go through their policies with [`TestBank::preview`] (module doc, Tests: the filter
    /// follows their combined decision); the previews are written into `pending` (all
    /// `None` on entry) for the commit, so nothing in the bank or the guards changes until
    /// the whole step has succeeded.
    fn filter_step(
        &mut self,
        obs: &[Option<Observation>],
        restart: bool,
        pending: &mut Previews,
    ) -> Result<federated::FederatedStep, StepError> {
        let mut error: Option<StepError> = None;
        let (bank, guards, aids) = (&self.bank, &self.guards, &self.config.aids);
        let decide = |i: usize, test: Option<LocalTest>| {
            let Some(t) = test else {
                return guards[i].idle(bank, bank.idle(i));
            };
            // Written into the aid's slot as it is formed, not moved there.
            let previewed = bank.preview(i, t.statistic, t.dof).map_err(StepError::from);
            let decided = previewed.and_then(|(outcome, state)| {
                let p = pending[i].insert(AidPreview {
                    outcome,
                    state,
                    guard: GuardPreview::default(),
                    test: t,
                    health: Health::Healthy,
                });
                guards[i].preview_into(bank, guard_input(aids[i], &p.test), &mut p.guard)?;
                let d = aid_decision(bank, &guards[i], i, &p.outcome, &p.guard);
                p.health = d.health;
                Ok(d)
            });
            decided.unwrap_or_else(|e| {
                pending[i] = None;
                error = Some(e);
                guards[i].idle(bank, bank.idle(i))
            })
        };
        let trans = &self.trans;
        let step = if restart {
            let initial = self.config.initial_estimate();
            self.filter.restart_step(&initial, trans, obs, decide)?
        } else {
            self.filter.step(trans, obs, decide)?
        };
        if let Some(e) = error {
            return Err(e);
        }
        Ok(step)
    }

    /// The protection level (module doc, Integrity): `HPL₁ = k_md σ_h` from the fused `P_g`,
    /// `HPL₂ = max_i` of the aids' `terms` ([`FederatedMonitor::hpl2_terms`]), combined by
    /// [`hpl::combine`], and the integrity it gives at `t`.
    fn protection_level(
        &self,
        master: &ErrorEstimate,
        terms: [Option<f64>; MAX_AIDS],
        t: f64,
        restart: bool,
    ) -> HplStep {
        let p_h = Matrix2::new(
            master.p[(POS, POS)],
            master.p[(POS, POS + 1)],
            master.p[(POS + 1, POS)],
            master.p[(POS + 1, POS + 1)],
        );
        let hpl1 = self.k_md * hpl::sigma_h(&p_h);
        let n = self.config.aids.len();
        let hpl2_max = terms[..n].iter().flatten().fold(0.0_f64, |m, &v| m.max(v));
        let value = hpl::combine(hpl1, hpl2_max);
        let (integrity, convergence) = self.convergence.judge(t, restart, value, self.config.hal_m);
        HplStep {
            value,
            terms,
            integrity,
            convergence,
        }
    }

    /// Per aid (`aids`, one step per configured aid), `slope_i sqrt(λ_det,i)` with
    /// `λ_det,i` for the dof and threshold its χ² test used: renewed when the aid updates
    /// while fused, kept from `previous` while it is fused without an update, dropped when
    /// it is left out of fusion. A restart forgets the slopes of the old solution.
    fn hpl2_terms(
        lambda_det: &mut DetectionNoncentrality,
        previous: [Option<f64>; MAX_AIDS],
        aids: &[federated::AidStep],
        pending: &Previews,
        restart: bool,
    ) -> Result<[Option<f64>; MAX_AIDS], StepError> {
        let mut hpl2 = if restart { [None; MAX_AIDS] } else { previous };
        for (i, a) in aids.iter().enumerate() {
            if !a.fused {
                hpl2[i] = None;
            } else if let (Some(slope), Some(p)) = (a.slope, &pending[i]) {
                let s = p.outcome.statistic;
                let l = lambda_det.get(s.dof, s.threshold).map_err(|e| match e {
                    HplError::Chi2(c) => StepError::Threshold(c.into()),
                    _ => StepError::Filter(FilterError::NotPositiveDefinite),
                })?;
                hpl2[i] = Some(slope * l.sqrt());
            }
        }
        Ok(hpl2)
    }

    /// Makes the step current: each aid's policy states (`pending`, committed by
    /// reference: a preview is not moved again), guard inputs and consistency diagnostics,
    /// the filter's pending state (a restart included), the HPL terms and the convergence,
    /// the time and the outputs. Returns the epoch's test outcomes, per aid its χ² test then
    /// its guards.
    fn commit(
        &mut self,
        t: f64,
        pending: &mut Previews,
        hpl: HplStep,
        solution: FederatedSolution,
        front: Option<FrontState>,
    ) -> Vec<TestOutcome> {
        let n = self.config.aids.len();
        let mut tests = Vec::with_capacity(3 * n);
        for (i, slot) in pending.iter_mut().enumerate().take(n) {
            if let Some(p) = slot {
                let aid = self.config.aids[i];
                self.bank.commit(i, p.state.clone());
                self.bank.observe(i, p.test.nu(), p.health);
                tests.push(p.outcome.clone());
                let healthy = p.health == Health::Healthy;
                let input = guard_input(aid, &p.test);
                self.guards[i].commit(&mut self.bank, &mut p.guard, input, healthy, &mut tests);
            }
        }
        self.filter.commit();
        self.hpl2 = hpl.terms;
        self.convergence = hpl.convergence;
        self.last_t = Some(t);
        if front.is_some() {
            self.front = front;
        }
        self.outputs = Outputs::Federated {
            solution: Some(solution),
            hpl: Some(hpl.value),
            isolated: self.isolated(),
            alignment: self.front.as_ref().map(FrontState::alignment),
        };
        tests
    }

    /// The last outputs again, no tests: an epoch without the monitor's input.
    fn repeat(&self) -> MonitorReport {
        MonitorReport {
            tests: Vec::new(),
            outputs: self.outputs.clone(),
            integrity: None,
        }
    }

    /// One epoch of the filter about `nav` over `self.trans` (the transition is set):
    /// the aids' measurements, the filter with the policies, the protection level and
    /// integrity, the solution, then the commit (module doc). With `front` (`input: imu`)
    /// the fused error is fed back into the mechanization before the commit and the
    /// solution is the corrected mechanization. Any failure leaves the monitor as it was.
    fn filter_epoch(
        &mut self,
        epoch: &Epoch,
        nav: &NavSolution,
        restart: bool,
        mut front: Option<FrontState>,
    ) -> Result<MonitorReport, StepError> {
        // The aids' previews are written in place and passed by reference: three ~340-byte
        // previews would otherwise be copied through the step.
        let mut pending: Previews = [None, None, None];
        let n = self.config.aids.len();
        let mut obs: [Option<Observation>; MAX_AIDS] = [None, None, None];
        for (i, &aid) in self.config.aids.iter().enumerate() {
            obs[i] = self.observation(aid, nav, epoch);
        }
        let step = self.filter_step(&obs[..n], restart, &mut pending)?;
        let Some(next) = self.filter.pending() else {
            return Err(FilterError::NonFinite("federated step").into());
        };
        let terms = Self::hpl2_terms(
            &mut self.lambda_det,
            self.hpl2,
            &step.aids[..n],
            &pending,
            restart,
        )?;
        let hpl = self.protection_level(&next.master, terms, epoch.t, restart);
        let solution = match &mut front {
            None => corrected_solution(nav, &next.master)?,
            Some(f) => {
                let dx = self
                    .filter
                    .feed_back_pending()
                    .ok_or(FilterError::NonFinite("federated step"))?;
                f.feed_back(&dx);
                mechanized_solution(f)?
            }
        };
        let integrity = hpl.integrity;
        let tests = self.commit(epoch.t, &mut pending, hpl, solution, front);
        let all_isolated = (0..n).all(|i| self.aid_health(i) == Health::Isolated);
        if let Some(f) = &mut self.front {
            f.note_isolation(epoch.t, all_isolated);
        }
        Ok(MonitorReport {
            tests,
            outputs: self.outputs.clone(),
            integrity: Some(integrity),
        })
    }

    /// One epoch with `input: imu` (module [`imu`]): the front end advances; while it
    /// aligns, no test runs and integrity is `converging`; once aligned, the filter runs
    /// on the mechanized solution and feeds its estimate back.
    fn step_imu(&mut self, epoch: &Epoch) -> Result<MonitorReport, StepError> {
        let (Some(imu), Some(cfg)) = (&epoch.imu, &self.config.strapdown) else {
            return Ok(self.repeat());
        };
        let mut front = match &self.front {
            Some(f) => f.clone(),
            None => FrontState::new(cfg),
        };
        match front.advance(cfg, epoch, imu) {
            imu::Advance::Aligning => {
                let alignment = front.alignment();
                self.front = Some(front);
                self.last_t = None;
                self.outputs = Outputs::Federated {
                    solution: None,
                    hpl: None,
                    isolated: self.isolated(),
                    alignment: Some(alignment),
                };
                Ok(MonitorReport {
                    tests: Vec::new(),
                    outputs: self.outputs.clone(),
                    integrity: Some(IntegrityReport {
                        state: Availability::Converging,
                        protection_level: f64::NAN,
                        alert_limit: self.config.hal_m,
                    }),
                })
            }
            imu::Advance::Nav { nav, restart, dt } => {
                self.transition_over(&nav, (!restart).then_some(dt))?;
                if !restart {
                    return self.filter_epoch(epoch, &nav, false, Some(front));
                }
                // A (re)start of the mechanization is a new stream for the tests too: a
                // re-placed INS is tested afresh, not under the policies of the one that
                // drifted (restored if the step fails).
                let saved = (self.bank.clone(), self.guards.clone());
                self.bank.reset();
                self.guards.iter_mut().for_each(InnovationGuards::reset);
                let stepped = self.filter_epoch(epoch, &nav, true, Some(front));
                if stepped.is_err() {
                    (self.bank, self.guards) = saved;
                }
                stepped
            }
        }
    }
}

/// Aid `i`'s decision this epoch: its χ² test's `outcome` combined with its guards'
/// (module doc, Tests). Under counters a filter whose combined health leaves `isolated`
/// (it rejoins the fusion) is reset from the master, as seed 004 §2 resets a filter that
/// returns from isolation; classic and traditional readmit without a reset.
fn aid_decision(
    bank: &TestBank,
    guards: &InnovationGuards,
    i: usize,
    outcome: &TestOutcome,
    guard: &GuardPreview,
) -> Decision {
    let mut d = guards.combined(bank, guard, outcome.decision);
    let was = worse(outcome.previous, guards.worst_health(bank));
    let counters = matches!(
        bank.slots()[i].policy.config(),
        PolicyConfig::Counters { .. }
    );
    d.reset = counters && was == Health::Isolated && d.fuse;
    d
}

/// One aid's previewed tests, committed with the step.
struct AidPreview {
    /// The χ² test's outcome and policy state.
    outcome: TestOutcome,
    state: PolicyState,
    /// The guards' outcomes and policy states.
    guard: GuardPreview,
    /// The local test (its ν feeds the guards and the diagnostics).
    test: LocalTest,
    /// The aid's combined health this epoch.
    health: Health,
}

/// Each aid's previewed tests, committed with the step.
type Previews = [Option<AidPreview>; MAX_AIDS];

/// One epoch's protection level and integrity, committed with the step.
struct HplStep {
    /// The HPL, m.
    value: f64,
    /// Per aid, its `HPL₂` term.
    terms: [Option<f64>; MAX_AIDS],
    /// Available, unavailable or converging.
    integrity: Integrity,
    /// The convergence tracker after this epoch.
    convergence: Convergence,
}

/// The corrected solution: the INS minus the fused error estimate (open loop), on the
/// wire in degrees; a non-finite one fails the step.
fn corrected_solution(
    nav: &NavSolution,
    master: &ErrorEstimate,
) -> Result<FederatedSolution, StepError> {
    let x = &master.x;
    let dp = Vector3::new(x[POS], x[POS + 1], x[POS + 2]);
    let fixed = geo::apply_offset(&nav.lla, &-dp);
    let vel = nav.vel - Vector3::new(x[VEL], x[VEL + 1], x[VEL + 2]);
    if !(fixed.lat.is_finite() && fixed.lon.is_finite() && vel.iter().all(|v| v.is_finite())) {
        return Err(FilterError::NonFinite("corrected solution").into());
    }
    Ok(FederatedSolution {
        lat: fixed.lat.to_degrees(),
        lon: fixed.lon.to_degrees(),
        h: fixed.h,
        vel: [vel.x, vel.y, vel.z],
        att: None,
    })
}

/// The corrected mechanization (`input: imu`, after the feedback) on the wire; a
/// non-finite one fails the step.
fn mechanized_solution(front: &FrontState) -> Result<FederatedSolution, StepError> {
    let Some(mech) = front.mech() else {
        return Err(FilterError::NonFinite("mechanization").into());
    };
    let (p, v, att) = (mech.lla(), mech.vel(), mech.att());
    let all = [p.lat, p.lon, p.h, v.x, v.y, v.z, att[0], att[1], att[2]];
    if !all.iter().all(|x| x.is_finite()) {
        return Err(FilterError::NonFinite("mechanized solution").into());
    }
    Ok(FederatedSolution {
        lat: p.lat.to_degrees(),
        lon: p.lon.to_degrees(),
        h: p.h,
        vel: [v.x, v.y, v.z],
        att: Some(att.map(f64::to_degrees)),
    })
}

impl Monitor for FederatedMonitor {
    fn kind(&self) -> MonitorKind {
        MonitorKind::Federated
    }

    fn tests(&self) -> &TestBank {
        &self.bank
    }

    fn tests_mut(&mut self) -> &mut TestBank {
        &mut self.bank
    }

    /// Every block is optional and already validated (finite, in range) at the edge: an aid
    /// block without `ins` is ignored, not refused, and so are blocks of unconfigured aids.
    /// Nothing here can make an epoch unusable before the step; a polar INS latitude
    /// (|L| = 90°, where east is undefined) fails the step numerically and changes nothing.
    fn check_epoch(&self, _name: &str, _epoch: &Epoch) -> Result<(), EpochError> {
        Ok(())
    }

    /// One INS epoch: transition, the aids' measurements, the filter with the policies,
    /// the protection level and integrity, the corrected solution, then the commit (module
    /// doc). Any failure leaves the monitor as it was.
    fn step(&mut self, epoch: &Epoch) -> Result<MonitorReport, StepError> {
        if self.config.strapdown.is_some() {
            return self.step_imu(epoch);
        }
        let Some(ins) = &epoch.ins else {
            return Ok(self.repeat());
        };
        let nav = NavSolution::from_ins(ins);
        let restart = self.transition(&nav, epoch.t)?;
        self.filter_epoch(epoch, &nav, restart, None)
    }

    fn checkpoint(&self) -> Result<Vec<u8>, CheckpointError> {
        self.save()
    }

    /// Checks the saved filter state, the tests, each aid's guards, the convergence cap,
    /// the HPL terms and the isolated aids against this monitor's before anything is
    /// replaced.
    fn restore(&mut self, bytes: &[u8]) -> Result<(), CheckpointError> {
        self.load(bytes)
    }

    fn reset(&mut self) {
        self.filter.restart(self.config.initial_estimate());
        self.bank.reset();
        for g in &mut self.guards {
            g.reset();
        }
        self.convergence.reset();
        self.hpl2 = [None; MAX_AIDS];
        self.last_t = None;
        self.outputs = Outputs::Federated {
            solution: None,
            hpl: None,
            isolated: Vec::new(),
            alignment: self.config.strapdown.as_ref().map(|_| Alignment::Levelling),
        };
        self.front = self.config.strapdown.as_ref().map(FrontState::new);
    }
}

#[cfg(test)]
mod imu_tests;
#[cfg(test)]
mod tests;
