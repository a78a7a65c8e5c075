//! RAIM on a [`super::wls`] fix, the last step of the `gnss` layer before the monitors:
//! the residual χ² test (WSSR against `detect::chi2`), fault detection and exclusion
//! ([`FdeMethod`]: RTKLIB's leave-one-out, greedy w-test, and the hook for ARAIM's
//! solution separation), and slope-based protection levels for weighted RAIM.

use std::cell::RefCell;

use nalgebra::DMatrix;

use super::araim::{self, AraimModel, AraimParams, AraimSat};
use super::wls::{MIN_REDUNDANCY, WlsError, WlsParams, WlsSolution, solve, solve_excluding};
use crate::detect::chi2::{self, Chi2Error};
use crate::epoch::{SatId, SatObs};

/// RTKLIB's GDOP limit in `valsol` (`maxgdop` default 30), applied by [`FdeMethod::Rtklib`].
pub const RTKLIB_MAX_GDOP: f64 = 30.0;

/// RTKLIB's starting residual RMS (m) in `raim_fde`: a leave-one-out subset must do better.
const RTKLIB_MAX_RMS_M: f64 = 100.0;

/// Why a RAIM step failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RaimError {
    /// The WLS fix failed.
    #[error(transparent)]
    Wls(#[from] WlsError),
    /// The χ² machinery refused its inputs (e.g. P_FA outside (0, 1)).
    #[error(transparent)]
    Chi2(#[from] Chi2Error),
    /// No redundancy (dof = 0): nothing to test.
    #[error("no redundancy: the residual test needs dof >= 1")]
    NoRedundancy,
    /// ARAIM could not run on the fix (too many satellites, a singular subset).
    #[error("araim: {0}")]
    Araim(String),
}

/// The residual χ² test of one fix: `WSSR ~ χ²(dof)` when fault-free.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Chi2Test {
    /// Weighted sum of squared residuals.
    pub wssr: f64,
    /// Degrees of freedom.
    pub dof: u32,
    /// Threshold `F⁻¹_{χ²(dof)}(1 − P_FA)`.
    pub threshold: f64,
    /// `wssr <= threshold`.
    pub passed: bool,
}

thread_local! {
    /// χ² quantiles and detection non-centralities already computed on this thread, keyed
    /// by their arguments' bits: an epoch's fault exclusion tests several subsets at the
    /// same few dofs, and each quantile costs an incomplete-gamma inversion.
    static MEMO: RefCell<Vec<([u64; 3], f64)>> = const { RefCell::new(Vec::new()) };
}

/// Most memoised values kept (a monitor uses a few dofs at one or two p_fa).
const MEMO_CAP: usize = 256;

/// `f(args)`, memoised per thread by the bits of `args`.
fn memo<E>(args: [f64; 3], f: impl FnOnce() -> Result<f64, E>) -> Result<f64, E> {
    let key = args.map(f64::to_bits);
    if let Some(v) = MEMO.with(|m| m.borrow().iter().find(|(k, _)| *k == key).map(|e| e.1)) {
        return Ok(v);
    }
    let v = f()?;
    MEMO.with(|m| {
        let mut m = m.borrow_mut();
        if m.len() >= MEMO_CAP {
            m.clear();
        }
        m.push((key, v));
    });
    Ok(v)
}

/// `chi2::threshold(dof, p_fa)`, memoised per thread.
pub fn threshold(dof: u32, p_fa: f64) -> Result<f64, Chi2Error> {
    memo([f64::from(dof), p_fa, -1.0], || chi2::threshold(dof, p_fa))
}

/// The χ² test of `sol` at false-alarm probability `p_fa`.
pub fn chi2_test(sol: &WlsSolution, p_fa: f64) -> Result<Chi2Test, RaimError> {
    if sol.dof == 0 {
        return Err(RaimError::NoRedundancy);
    }
    let threshold = threshold(sol.dof, p_fa)?;
    Ok(Chi2Test {
        wssr: sol.wssr,
        dof: sol.dof,
        threshold,
        passed: sol.wssr <= threshold,
    })
}

/// How faulty satellites are found and excluded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FdeMethod {
    /// RTKLIB's `raim_fde` (pntpos.c): when the χ² test fails and there are at least 6
    /// observations, solve once without each satellite; among the subsets that pass χ²
    /// (and GDOP ≤ 30) with at least 5 satellites, keep the one with the smallest
    /// (unweighted) residual RMS, if below 100 m. At most one exclusion.
    Rtklib,
    /// Exclude the largest |w-test|, re-solve, re-test, up to `max_exclusions`, while
    /// the test fails and `dof ≥ 2` (with dof = 1 every w-test has the same size).
    Greedy,
    /// ARAIM solution separation: see [`solution_separation_fde`].
    SolutionSeparation,
}

/// What ARAIM's solution separation needs beyond the WLS settings: the allocations and
/// priors ([`AraimParams`], the ADD's defaults) and the nominal error model of the
/// integrity support message. Each satellite's integrity σ is
/// `sqrt(σ_URA² + σ_i²)` and its accuracy σ `sqrt(σ_URE² + σ_i²)`, with `σ_i` the WLS σ
/// model's (which stands for the ADD's σ_tropo and σ_user, and for whatever else the
/// receiver's pseudoranges carry).
#[derive(Debug, Clone, PartialEq)]
pub struct SolutionSeparationParams {
    /// Allocations, priors and tolerances.
    pub araim: AraimParams,
    /// σ_URA, m (integrity).
    pub sigma_ura_m: f64,
    /// σ_URE, m (accuracy and continuity).
    pub sigma_ure_m: f64,
    /// b_nom, m (integrity).
    pub b_nom_m: f64,
}

impl Default for SolutionSeparationParams {
    /// The ADD's allocations; σ_URA = 1 m, σ_URE = 0.5 m, b_nom = 0.5 m (this crate's
    /// defaults, of the order ARAIM studies assume for GPS and Galileo; set them from
    /// the ISM in use).
    fn default() -> Self {
        SolutionSeparationParams {
            araim: AraimParams::default(),
            sigma_ura_m: 1.0,
            sigma_ure_m: 0.5,
            b_nom_m: 0.5,
        }
    }
}

/// The ARAIM view of a WLS fix: per used satellite its line of sight, clock column,
/// error model and elevation, and the residual vector `y` at the fix (the linearisation
/// point, so every subset solution is a correction `S_k y` about it).
pub fn araim_inputs(sol: &WlsSolution, ss: &SolutionSeparationParams) -> (Vec<AraimSat>, Vec<f64>) {
    let g = &sol.geometry_enu;
    let sats = sol
        .sats
        .iter()
        .enumerate()
        .map(|(j, s)| {
            let clock = (3..g.ncols()).position(|c| g[(j, c)] != 0.0).unwrap_or(0);
            let u = [-g[(j, 0)], -g[(j, 1)], -g[(j, 2)]];
            let norm = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
            AraimSat {
                id: s.id,
                los_enu: u.map(|x| x / norm),
                clock,
                sigma_ura: ss.sigma_ura_m,
                sigma_ure: ss.sigma_ure_m,
                b_nom: ss.b_nom_m,
                el: s.az_el.el,
                sigma_local: Some(s.sigma_m),
            }
        })
        .collect();
    let y = sol.sats.iter().map(|s| s.residual_m).collect();
    (sats, y)
}

/// Settings of fault detection and exclusion.
#[derive(Debug, Clone, PartialEq)]
pub struct FdeParams {
    /// The method.
    pub method: FdeMethod,
    /// False-alarm probability of each χ² test.
    pub p_fa: f64,
    /// Most exclusions ([`FdeMethod::Greedy`]; Rtklib makes at most one).
    pub max_exclusions: usize,
    /// For [`FdeMethod::SolutionSeparation`].
    pub solution_separation: SolutionSeparationParams,
}

impl Default for FdeParams {
    /// RTKLIB's method at RTKLIB's α = 0.001, one exclusion.
    fn default() -> Self {
        FdeParams {
            method: FdeMethod::Rtklib,
            p_fa: 1e-3,
            max_exclusions: 1,
            solution_separation: SolutionSeparationParams::default(),
        }
    }
}

/// What became of one input satellite.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SatStatus {
    /// In the final fix.
    Used,
    /// Excluded by FDE.
    Excluded,
    /// Below the elevation mask.
    Masked,
}

/// The result of FDE.
#[derive(Debug, Clone, PartialEq)]
pub struct FdeOutcome {
    /// The final fix (the all-in-view one when nothing was excluded).
    pub solution: WlsSolution,
    /// Excluded satellites, in the order they were excluded.
    pub excluded: Vec<SatId>,
    /// Per input satellite, in input order.
    pub status: Vec<(SatId, SatStatus)>,
    /// The all-in-view test failed (`None` when it could not be run, dof = 0).
    pub detected: Option<bool>,
    /// The all-in-view test itself (`None` when it could not be run).
    pub all_in_view: Option<Chi2Test>,
    /// The final fix's test (`None` when dof = 0).
    pub test: Option<Chi2Test>,
    /// Solution separation only: the ARAIM model of the satellites kept (its protection
    /// levels are the final fix's, so a caller need not fit it again).
    pub araim: Option<AraimModel>,
}

/// Fault detection and exclusion on one epoch by `params.method`.
pub fn fde(obs: &[SatObs], wls: &WlsParams, params: &FdeParams) -> Result<FdeOutcome, RaimError> {
    match params.method {
        FdeMethod::Rtklib => rtklib_fde(obs, wls, params.p_fa),
        FdeMethod::Greedy => greedy_fde(obs, wls, params.p_fa, params.max_exclusions),
        FdeMethod::SolutionSeparation => {
            solution_separation_fde(obs, wls, params.p_fa, &params.solution_separation)
        }
    }
}

/// Solution-separation FDE (ARAIM, [`araim::solution_separation_fde`]) on the all-in-view
/// WLS fix: when a separation exceeds its threshold, the fault mode whose subset passes
/// is excluded (a constellation mode excludes every satellite of it) and the fix is
/// solved again without it. `p_fa` is for the χ² tests the outcome also reports; the
/// separation tests use the ADD's P_FA allocations.
pub fn solution_separation_fde(
    obs: &[SatObs],
    wls: &WlsParams,
    p_fa: f64,
    params: &SolutionSeparationParams,
) -> Result<FdeOutcome, RaimError> {
    let full = solve(obs, wls)?;
    let all_in_view = maybe_test(&full, p_fa)?;
    let (sats, y) = araim_inputs(&full, params);
    let decided = araim::solution_separation_fde(&sats, &y, &params.araim)
        .map_err(|e| RaimError::Araim(e.to_string()))?;
    let (sol, excluded) = if decided.excluded.is_empty() {
        (full, Vec::new())
    } else {
        (
            solve_excluding(obs, wls, &decided.excluded)?,
            decided.excluded,
        )
    };
    let mut out = outcome(obs, sol, excluded, all_in_view, p_fa)?;
    out.araim = Some(decided.model);
    Ok(out)
}

/// The χ² test, `None` when dof = 0.
fn maybe_test(sol: &WlsSolution, p_fa: f64) -> Result<Option<Chi2Test>, RaimError> {
    match chi2_test(sol, p_fa) {
        Ok(t) => Ok(Some(t)),
        Err(RaimError::NoRedundancy) => Ok(None),
        Err(e) => Err(e),
    }
}

/// Per-satellite status of `obs` in `sol` after excluding `excluded`.
fn statuses(obs: &[SatObs], sol: &WlsSolution, excluded: &[SatId]) -> Vec<(SatId, SatStatus)> {
    obs.iter()
        .map(|o| {
            let s = if excluded.contains(&o.id) {
                SatStatus::Excluded
            } else if sol.masked.contains(&o.id) {
                SatStatus::Masked
            } else {
                SatStatus::Used
            };
            (o.id, s)
        })
        .collect()
}

fn outcome(
    obs: &[SatObs],
    solution: WlsSolution,
    excluded: Vec<SatId>,
    all_in_view: Option<Chi2Test>,
    p_fa: f64,
) -> Result<FdeOutcome, RaimError> {
    let test = maybe_test(&solution, p_fa)?;
    let status = statuses(obs, &solution, &excluded);
    Ok(FdeOutcome {
        solution,
        detected: all_in_view.map(|t| !t.passed),
        all_in_view,
        excluded,
        status,
        test,
        araim: None,
    })
}

/// [`FdeMethod::Rtklib`].
fn rtklib_fde(obs: &[SatObs], wls: &WlsParams, p_fa: f64) -> Result<FdeOutcome, RaimError> {
    let full = solve(obs, wls);
    let full_test = match &full {
        Ok(sol) => maybe_test(sol, p_fa)?,
        Err(_) => None,
    };
    let gdop_ok = |s: &WlsSolution| s.dops.gdop > 0.0 && s.dops.gdop <= RTKLIB_MAX_GDOP;
    let full_ok = matches!((&full, full_test), (Ok(s), Some(t)) if t.passed && gdop_ok(s));
    // pntpos: raim_fde only after a failed estpos, with n >= 6 observations.
    if full_ok || obs.len() < 6 || matches!(&full, Ok(s) if s.dof == 0) {
        return outcome(obs, full?, Vec::new(), full_test, p_fa);
    }
    let mut best: Option<(f64, SatId, WlsSolution)> = None;
    for o in obs {
        let Ok(sol) = solve_excluding(obs, wls, &[o.id]) else {
            continue;
        };
        let passed = maybe_test(&sol, p_fa)?.is_some_and(|t| t.passed);
        if !passed || !gdop_ok(&sol) || sol.sats.len() < 5 {
            continue;
        }
        let rms = (sol.sats.iter().map(|s| s.residual_m.powi(2)).sum::<f64>()
            / sol.sats.len() as f64)
            .sqrt();
        let limit = best.as_ref().map_or(RTKLIB_MAX_RMS_M, |b| b.0);
        if rms <= limit {
            best = Some((rms, o.id, sol));
        }
    }
    match best {
        Some((_, id, sol)) => outcome(obs, sol, vec![id], full_test, p_fa),
        None => outcome(obs, full?, Vec::new(), full_test, p_fa),
    }
}

/// [`FdeMethod::Greedy`].
fn greedy_fde(
    obs: &[SatObs],
    wls: &WlsParams,
    p_fa: f64,
    max_exclusions: usize,
) -> Result<FdeOutcome, RaimError> {
    let mut sol = solve(obs, wls)?;
    let all_in_view = maybe_test(&sol, p_fa)?;
    let mut excluded = Vec::new();
    while let Some(test) = maybe_test(&sol, p_fa)? {
        if test.passed || excluded.len() >= max_exclusions || sol.dof < 2 {
            break;
        }
        let worst = sol
            .sats
            .iter()
            .filter(|s| s.redundancy > MIN_REDUNDANCY)
            .max_by(|a, b| a.normalised.abs().total_cmp(&b.normalised.abs()));
        let Some(worst) = worst else { break };
        excluded.push(worst.id);
        match solve_excluding(obs, wls, &excluded) {
            Ok(next) => sol = next,
            Err(_) => {
                excluded.pop();
                break;
            }
        }
    }
    outcome(obs, sol, excluded, all_in_view, p_fa)
}

/// One satellite's slopes: the position error per unit of `sqrt(λ)` that a bias on it
/// causes (m), `∞` when its redundancy is zero (the bias is unobservable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SatSlope {
    /// The satellite.
    pub id: SatId,
    /// Horizontal slope, m.
    pub horizontal: f64,
    /// Vertical slope, m.
    pub vertical: f64,
}

/// Slope-based protection levels of a weighted-RAIM fix.
#[derive(Debug, Clone, PartialEq)]
pub struct SlopeProtection {
    /// `max_i slope_H,i · sqrt(λ_det)`, m.
    pub hpl_m: f64,
    /// `max_i slope_V,i · sqrt(λ_det)`, m.
    pub vpl_m: f64,
    /// The non-centrality at which the test misses with probability P_MD.
    pub lambda_det: f64,
    /// The detection threshold.
    pub threshold: f64,
    /// Per used satellite, in the fix's order.
    pub slopes: Vec<SatSlope>,
}

/// Slope protection levels (Walter & Enge 1995, "Weighted RAIM for precision approach",
/// ION GPS-95; the unweighted form is Brown & Chin 1997): with `S = (GᵀWG)⁻¹GᵀW` and
/// `P = I − GS`, a bias `b` on satellite `i` moves east/north/up by `S_{·i} b` and makes
/// the statistic `WSSR = yᵀPᵀWPy` non-central with `λ = b²(WP)_ii = b² r_i/σ_i²`
/// (r_i the redundancy number). So `slope_H,i = ‖S_{EN,i}‖ σ_i / sqrt(r_i)`, and the
/// largest horizontal error missed with probability P_MD is `slope_H,i · sqrt(λ_det)`,
/// `λ_det` from `chi2::noncentrality_for_missed_detection(dof, T_D, P_MD)`.
///
/// The fault-free noise term (`k(P_FF)·σ_H`, as Brown & Chin add) is not included:
/// these are the bias-only bounds of Walter & Enge; a caller wanting it adds it with
/// `detect::hpl::combine`.
pub fn slope_protection_levels(
    sol: &WlsSolution,
    p_fa: f64,
    p_md: f64,
) -> Result<SlopeProtection, RaimError> {
    let test = chi2_test(sol, p_fa)?;
    let lambda_det = memo([f64::from(sol.dof), test.threshold, p_md], || {
        chi2::noncentrality_for_missed_detection(sol.dof, test.threshold, p_md)
    })?;
    let g = &sol.geometry_enu;
    let mut gw: DMatrix<f64> = g.clone();
    for (j, s) in sol.sats.iter().enumerate() {
        gw.row_mut(j).scale_mut(1.0 / s.sigma_m);
    }
    let q = gw
        .tr_mul(&gw)
        .try_inverse()
        .ok_or(WlsError::SingularGeometry)?;
    let mut slopes = Vec::with_capacity(sol.sats.len());
    for (j, s) in sol.sats.iter().enumerate() {
        // Column i of S = Q g_iᵀ / σ_i².
        let col = &q * g.row(j).transpose() / (s.sigma_m * s.sigma_m);
        // A satellite without redundancy (alone in its constellation) cannot be tested;
        // its bias moves the position by its gain, which is zero when its own clock
        // absorbs it (slope 0), and is unbounded otherwise (slope ∞).
        let slope = |gain: f64| {
            if s.redundancy > MIN_REDUNDANCY {
                gain * s.sigma_m / s.redundancy.sqrt()
            } else if gain < 1e-9 {
                0.0
            } else {
                f64::INFINITY
            }
        };
        slopes.push(SatSlope {
            id: s.id,
            horizontal: slope(col[0].hypot(col[1])),
            vertical: slope(col[2].abs()),
        });
    }
    let worst = |f: fn(&SatSlope) -> f64| slopes.iter().map(f).fold(0.0, f64::max);
    Ok(SlopeProtection {
        hpl_m: worst(|s| s.horizontal) * lambda_det.sqrt(),
        vpl_m: worst(|s| s.vertical) * lambda_det.sqrt(),
        lambda_det,
        threshold: test.threshold,
        slopes,
    })
}
