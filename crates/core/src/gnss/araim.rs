//! ARAIM by multiple-hypothesis solution separation (Blanch et al., "Baseline advanced
//! RAIM user algorithm and possible improvements", IEEE TAES 51(1), 2015, called [B15]
//! below; EU–US WG-C "ARAIM Airborne Algorithm Description Document", the ADD): the
//! integrity layer of `gnss`, after the position is solved. It takes the geometry of one
//! epoch (line-of-sight unit vectors in ENU, a clock column per constellation), the
//! ISM's error model and fault priors, and the pre-fit residuals `y`, and yields the
//! fault modes, subset solutions, solution-separation tests, VPL / HPL, σ_acc and EMT,
//! and a fault detection and exclusion ([`solution_separation_fde`]).
//!
//! Independent of how the position was solved: `y` only needs to be the linearised
//! pseudorange residuals at the all-in-view linearisation point, and every subset
//! solution is a correction `x̂_k = S_k y` about that point.
//!
//! Sign conventions: row i of the geometry matrix is `g_i = [−u_i, 1 at clock column]`
//! with `u_i` the receiver→satellite unit vector in ENU, so a positive range residual
//! moves the solution away from the satellite.
//!
//! Not implemented (see the module tests for what is checked): the ADD's exposure-time
//! scaling of priors (v4), the χ² test on the all-in-view residuals, the
//! post-exclusion protection levels that budget for a wrong exclusion, and the nominal
//! bias for continuity (`b_nom,acc`, taken as 0 in the thresholds as in ADD v2/v3).

mod modes;
mod pl;
#[cfg(test)]
mod pl_tests;
mod subsets;
#[cfg(test)]
mod tests;

use nalgebra::{DMatrix, DVector, SMatrix};
use serde::{Deserialize, Serialize};

use crate::epoch::{Constellation, SatId};

pub use modes::FaultMode;
pub use pl::{PlTerm, lhs as pl_lhs, q, q_inv, solve as solve_pl};
use subsets::Nominal;

/// Most satellites one epoch may hold (fault modes are 64-bit masks).
pub const MAX_SATS: usize = 64;

/// Most clock columns (one per constellation of [`Constellation::ALL`]).
pub const MAX_CLOCKS: usize = 7;

/// The normal matrices are fixed 10 × 10 (3 position + [`MAX_CLOCKS`]) so a subset costs
/// no allocation; unused clock columns carry the identity, which leaves the position
/// block of the inverse that of the reduced geometry.
const M: usize = 3 + MAX_CLOCKS;
type Normal = SMatrix<f64, M, M>;

/// The ARAIM integrity and continuity allocations and ISM fault priors. Defaults are
/// the LPV-200 allocations of ADD v2.0/v3.0 (Table "parameters", also [B15] Table 1)
/// and the ISM priors used in WG-C availability studies; each field says which.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AraimParams {
    /// Total integrity budget P_HMI, per approach: 1e-7 (ADD, LPV-200). Must equal
    /// `p_hmi_vert + p_hmi_hor`, up to rounding.
    pub p_hmi: f64,
    /// Vertical share P_HMI,VERT: 9.8e-8 (ADD).
    pub p_hmi_vert: f64,
    /// Horizontal share P_HMI,HOR: 2e-9 (ADD), split equally between east and north.
    pub p_hmi_hor: f64,
    /// Vertical false-alert budget P_FA,VERT of the solution-separation test: 3.9e-6 (ADD).
    pub p_fa_vert: f64,
    /// Horizontal false-alert budget P_FA,HOR: 9e-8 (ADD).
    pub p_fa_hor: f64,
    /// P_THRES, the most the unmonitored fault modes may hold: 8e-8 (ADD).
    pub p_thres: f64,
    /// Prior probability of a satellite fault, P_sat: 1e-5 (ISM value of the ADD and
    /// [B15] simulations, GPS and Galileo).
    pub p_sat: f64,
    /// Prior probability of a constellation-wide fault, per constellation in
    /// [`Constellation::ALL`] order (GPS, Galileo, GLONASS, BeiDou, QZSS, NavIC, SBAS):
    /// 1e-8 for GPS (the ADD's GPS ISM value), 1e-4 for the others ([B15] simulations).
    pub p_const: [f64; 7],
    /// TOL_PL, the width at which the PL bisection stops: 5e-2 m (ADD).
    pub tol_pl: f64,
    /// K_acc, the 95 % quantile for the accuracy requirement: 1.96 (ADD).
    pub k_acc: f64,
    /// K_ffd, the fault-free quantile at 1e-7 (two-sided): 5.33 (ADD).
    pub k_ffd: f64,
    /// P_EMT: fault modes at least this probable set the EMT: 1e-5 (ADD).
    pub p_emt: f64,
    /// Largest number of simultaneous fault events enumerated: 3 (a cap of this crate;
    /// the ADD enumerates until P_not_monitored ≤ P_THRES, which for realistic ISM
    /// values needs at most 2, and what the cap leaves is kept in P_not_monitored).
    pub max_fault_order: usize,
}

impl Default for AraimParams {
    fn default() -> Self {
        Self {
            p_hmi: 1e-7,
            p_hmi_vert: 9.8e-8,
            p_hmi_hor: 2e-9,
            p_fa_vert: 3.9e-6,
            p_fa_hor: 9e-8,
            p_thres: 8e-8,
            p_sat: 1e-5,
            p_const: [1e-8, 1e-4, 1e-4, 1e-4, 1e-4, 1e-4, 1e-4],
            tol_pl: 5e-2,
            k_acc: 1.96,
            k_ffd: 5.33,
            p_emt: 1e-5,
            max_fault_order: 3,
        }
    }
}

impl AraimParams {
    /// The prior of a constellation-wide fault of `c`.
    pub fn p_const_of(&self, c: Constellation) -> f64 {
        let i = Constellation::ALL.iter().position(|&k| k == c).unwrap_or(0);
        self.p_const[i]
    }

    /// Checks every probability is in its range and the budgets add up.
    pub fn check(&self) -> Result<(), AraimError> {
        let open = [
            ("p_hmi", self.p_hmi),
            ("p_hmi_vert", self.p_hmi_vert),
            ("p_hmi_hor", self.p_hmi_hor),
            ("p_fa_vert", self.p_fa_vert),
            ("p_fa_hor", self.p_fa_hor),
            ("p_thres", self.p_thres),
            ("p_emt", self.p_emt),
        ];
        for (name, value) in open {
            if !(value > 0.0 && value < 1.0) {
                return Err(AraimError::Param { name, value });
            }
        }
        if !(self.p_sat >= 0.0 && self.p_sat < 1.0) {
            return Err(AraimError::Param {
                name: "p_sat",
                value: self.p_sat,
            });
        }
        if let Some(&value) = self.p_const.iter().find(|p| !(**p >= 0.0 && **p < 1.0)) {
            return Err(AraimError::Param {
                name: "p_const",
                value,
            });
        }
        if ((self.p_hmi_vert + self.p_hmi_hor) / self.p_hmi - 1.0).abs() > 1e-9 {
            return Err(AraimError::Param {
                name: "p_hmi",
                value: self.p_hmi,
            });
        }
        for (name, value) in [
            ("tol_pl", self.tol_pl),
            ("k_acc", self.k_acc),
            ("k_ffd", self.k_ffd),
        ] {
            if !(value > 0.0 && value.is_finite()) {
                return Err(AraimError::Param { name, value });
            }
        }
        Ok(())
    }
}

/// LPV-200 availability limits ([B15] §II, ADD): VPL ≤ VAL, HPL ≤ HAL, EMT ≤ 15 m,
/// K_acc σ_acc ≤ 4 m (95 % vertical accuracy) and K_ffd σ_acc ≤ 10 m (fault-free).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AvailabilityLimits {
    /// Vertical alert limit, m: 35.
    pub val_m: f64,
    /// Horizontal alert limit, m: 40.
    pub hal_m: f64,
    /// EMT limit, m: 15.
    pub emt_m: f64,
    /// 95 % vertical accuracy, m: 4.
    pub acc95_m: f64,
    /// Fault-free vertical error bound at 1e-7, m: 10.
    pub ffd_m: f64,
}

impl Default for AvailabilityLimits {
    fn default() -> Self {
        Self {
            val_m: 35.0,
            hal_m: 40.0,
            emt_m: 15.0,
            acc95_m: 4.0,
            ffd_m: 10.0,
        }
    }
}

/// One satellite as ARAIM sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AraimSat {
    /// The satellite (its constellation decides the constellation-fault events).
    pub id: SatId,
    /// Receiver→satellite unit vector in local ENU.
    pub los_enu: [f64; 3],
    /// Index of the receiver-clock column this satellite's pseudorange carries
    /// (0-based; one per constellation usually). A subset that loses every satellite of a
    /// column drops the column.
    pub clock: usize,
    /// σ_URA, m: the ISM's clock and ephemeris σ for integrity.
    pub sigma_ura: f64,
    /// σ_URE, m: the ISM's clock and ephemeris σ for accuracy and continuity.
    pub sigma_ure: f64,
    /// b_nom, m: the ISM's nominal bias bound for integrity.
    pub b_nom: f64,
    /// Elevation, rad (for the ADD σ models when `sigma_local` is absent).
    pub el: f64,
    /// `sqrt(σ_tropo² + σ_user²)`, m; absent means [`sigma_tropo`] and
    /// [`sigma_user_airborne`] (dual frequency) at `el`.
    pub sigma_local: Option<f64>,
}

impl AraimSat {
    /// `σ_tropo² + σ_user²`, m².
    fn var_local(&self) -> f64 {
        match self.sigma_local {
            Some(s) => s * s,
            None => sigma_tropo(self.el).powi(2) + sigma_user_airborne(self.el, true).powi(2),
        }
    }
}

/// Tropospheric residual σ of the MOPS (DO-229, used by the ADD):
/// `0.12 · 1.001 / sqrt(0.002001 + sin² el)`, m.
pub fn sigma_tropo(el: f64) -> f64 {
    0.12 * 1.001 / (0.002_001 + el.sin().powi(2)).sqrt()
}

/// Airborne multipath and noise σ (ADD, from the MOPS airborne accuracy designator A):
/// `σ_MP = 0.13 + 0.53 e^(−θ/10°)`, `σ_noise = 0.15 + 0.43 e^(−θ/6.9°)`, θ the
/// elevation in degrees; for the L1/L5 iono-free combination (`dual_frequency`) scaled by
/// `sqrt((f1⁴ + f5⁴)/(f1² − f5²)²) ≈ 2.59`. This is the ADD's GPS model; it is used
/// for every constellation here (the ADD tabulates Galileo's separately).
pub fn sigma_user_airborne(el: f64, dual_frequency: bool) -> f64 {
    let deg = el.to_degrees();
    let mp = 0.13 + 0.53 * (-deg / 10.0).exp();
    let noise = 0.15 + 0.43 * (-deg / 6.9).exp();
    let single = (mp * mp + noise * noise).sqrt();
    if dual_frequency {
        let (f1, f5) = (1575.42e6_f64, 1176.45e6_f64);
        single * ((f1.powi(4) + f5.powi(4)) / (f1 * f1 - f5 * f5).powi(2)).sqrt()
    } else {
        single
    }
}

/// Why ARAIM could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AraimError {
    /// A parameter out of range.
    #[error("ARAIM parameter {name} out of range: {value}")]
    Param {
        /// The parameter.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// Fewer satellites than unknowns (3 + one clock per constellation), or more than
    /// [`MAX_SATS`].
    #[error("ARAIM needs between 3 + one per constellation and 64 satellites, got {0}")]
    SatelliteCount(usize),
    /// A satellite's σ, bias or line of sight is not finite or not valid.
    #[error("satellite {0}: σ must be > 0, b_nom ≥ 0, the line of sight a unit vector")]
    Satellite(SatId),
    /// `y` does not have one entry per satellite.
    #[error("expected {expected} residuals, got {got}")]
    Residuals {
        /// Satellites.
        expected: usize,
        /// Residuals given.
        got: usize,
    },
    /// The all-in-view geometry cannot be solved.
    #[error("the all-in-view geometry is singular")]
    Singular,
}

/// A fitted epoch: fault modes, subset gains, σ's, biases, thresholds and PLs. Built once
/// per geometry by [`AraimModel::fit`]; [`AraimModel::test`] then runs the solution
/// separation test on any residual vector of that geometry.
#[derive(Debug, Clone, PartialEq)]
pub struct AraimModel {
    /// The satellites, in input order.
    ids: Vec<SatId>,
    /// Monitored fault modes (subset k + 1 in the arrays below is mode k).
    modes: Vec<FaultMode>,
    /// ENU rows of the WLS gain S_k, row-major `[subset][q][i]`: subset 0 all-in-view.
    gains: Vec<f64>,
    /// `σ_q⁽ᵏ⁾` (integrity, with C_int), per subset.
    sigma: Vec<[f64; 3]>,
    /// `σ_ss,q⁽ᵏ⁾` (solution separation, with C_acc), per subset (0 for subset 0).
    sigma_ss: Vec<[f64; 3]>,
    /// `b_q⁽ᵏ⁾ = Σ_i |S_k(q, i)| b_nom,i`, per subset.
    bias: Vec<[f64; 3]>,
    /// `T_k,q = K_fa,q σ_ss,q⁽ᵏ⁾`, per subset (0 for subset 0).
    thresholds: Vec<[f64; 3]>,
    /// `K_fa,q`.
    k_fa: [f64; 3],
    /// P_not_monitored.
    p_not_monitored: f64,
    /// The largest number of simultaneous events enumerated.
    max_order: usize,
    /// East and north PLs, m.
    hpl_en: [f64; 2],
    /// VPL, m.
    vpl: f64,
    /// σ_acc (vertical, with C_acc), m.
    sigma_acc: f64,
    /// EMT, m.
    emt: f64,
    /// K_acc and K_ffd, kept for [`AraimModel::available`].
    k_acc_ffd: [f64; 2],
}

/// The solution separation test on one residual vector.
#[derive(Debug, Clone, PartialEq)]
pub struct SsTest {
    /// `|x̂_k,q − x̂_0,q|` per fault mode (index k in [`AraimModel::modes`]), m.
    pub separations: Vec<[f64; 3]>,
    /// The all-in-view ENU position correction `x̂_0 = S_0 y`, m.
    pub x0_enu: [f64; 3],
    /// Largest `|x̂_k,q − x̂_0,q| / T_k,q` over modes and axes (0 when no modes).
    pub max_ratio: f64,
    /// The mode and axis of `max_ratio`.
    pub worst: Option<(usize, usize)>,
}

impl SsTest {
    /// Whether every separation is within its threshold.
    pub fn passed(&self) -> bool {
        self.max_ratio <= 1.0
    }
}

impl AraimModel {
    /// Determines the fault modes, solves every subset and the protection levels
    /// ([B15] §III; ADD steps "determine subsets" to "protection levels").
    pub fn fit(sats: &[AraimSat], params: &AraimParams) -> Result<Self, AraimError> {
        params.check()?;
        let nominal = Nominal::new(sats)?;
        let n = sats.len();
        let all: u64 = if n == 64 { u64::MAX } else { (1u64 << n) - 1 };

        // Fault modes: events, then enumerate until P_not_monitored ≤ P_THRES.
        let constellations: Vec<Constellation> = sats.iter().map(|s| s.id.constellation).collect();
        let p_sat = vec![params.p_sat; n];
        let (events, p_unmon) = modes::events(&constellations, &p_sat, |c| params.p_const_of(c));
        // A subset is a candidate when it keeps at least as many satellites as unknowns:
        // solution separation needs the subset's solution, not its redundancy (a subset
        // whose geometry is still singular is caught by its Cholesky and counted as
        // unmonitored).
        let solvable = |mask: u64| {
            let kept = (all & !mask).count_ones() as usize;
            kept >= 3 + nominal.clocks_of(mask).count_ones() as usize
        };
        let set = modes::determine(
            &events,
            p_unmon,
            params.p_thres,
            params.max_fault_order,
            solvable,
        );
        let subsets = nominal.solve_subsets(&set.modes, set.p_not_monitored)?;

        // K_fa: the false-alert budget split over the N_ss modes, two-sided; east and
        // north share P_FA,HOR ([B15] and ADD "solution separation threshold tests").
        let n_ss = subsets.modes.len().max(1) as f64;
        let k_fa = [
            q_inv(params.p_fa_hor / (4.0 * n_ss)),
            q_inv(params.p_fa_hor / (4.0 * n_ss)),
            q_inv(params.p_fa_vert / (2.0 * n_ss)),
        ];
        let thresholds: Vec<[f64; 3]> = subsets
            .sigma_ss
            .iter()
            .map(|s| [k_fa[0] * s[0], k_fa[1] * s[1], k_fa[2] * s[2]])
            .collect();
        let mut model = Self {
            ids: sats.iter().map(|s| s.id).collect(),
            modes: subsets.modes,
            gains: subsets.gains,
            sigma: subsets.sigma,
            sigma_ss: subsets.sigma_ss,
            bias: subsets.bias,
            thresholds,
            k_fa,
            p_not_monitored: subsets.p_not_monitored,
            max_order: set.max_order,
            hpl_en: [0.0; 2],
            vpl: 0.0,
            sigma_acc: 0.0,
            emt: 0.0,
            k_acc_ffd: [params.k_acc, params.k_ffd],
        };
        model.solve_levels(params, &nominal.var_acc);
        Ok(model)
    }

    /// The protection levels, σ_acc and EMT of a fitted model.
    fn solve_levels(&mut self, params: &AraimParams, var_acc: &[f64]) {
        // The budget left once the unmonitored modes are paid for.
        let scale = 1.0 - self.p_not_monitored / (params.p_hmi_vert + params.p_hmi_hor);
        let terms = |q: usize| -> Vec<PlTerm> {
            let mut t = Vec::with_capacity(self.sigma.len());
            t.push(PlTerm {
                coef: 2.0,
                offset: self.bias[0][q],
                sigma: self.sigma[0][q],
            });
            for (k, md) in self.modes.iter().enumerate() {
                t.push(PlTerm {
                    coef: md.p_fault,
                    offset: self.thresholds[k + 1][q] + self.bias[k + 1][q],
                    sigma: self.sigma[k + 1][q],
                });
            }
            t
        };
        self.vpl = solve_pl(&terms(2), params.p_hmi_vert * scale, params.tol_pl);
        self.hpl_en = [
            solve_pl(&terms(0), 0.5 * params.p_hmi_hor * scale, params.tol_pl),
            solve_pl(&terms(1), 0.5 * params.p_hmi_hor * scale, params.tol_pl),
        ];
        // σ_acc (vertical, C_acc) and EMT = max T_k,3 over modes with p_fault ≥ P_EMT.
        self.sigma_acc = self
            .gain_row(0, 2)
            .iter()
            .zip(var_acc)
            .map(|(s, v)| s * s * v)
            .sum::<f64>()
            .sqrt();
        self.emt = self
            .modes
            .iter()
            .enumerate()
            .filter(|(_, md)| md.p_fault >= params.p_emt)
            .map(|(k, _)| self.thresholds[k + 1][2])
            .fold(0.0, f64::max);
    }

    /// The solution separation test: `|x̂_k,q − x̂_0,q| ≤ T_k,q` for every mode and axis,
    /// with `x̂_k = S_k y`.
    pub fn test(&self, y: &[f64]) -> Result<SsTest, AraimError> {
        let n = self.ids.len();
        if y.len() != n {
            return Err(AraimError::Residuals {
                expected: n,
                got: y.len(),
            });
        }
        let dot = |k: usize, q: usize| -> f64 {
            self.gains[(k * 3 + q) * n..(k * 3 + q + 1) * n]
                .iter()
                .zip(y)
                .map(|(s, v)| s * v)
                .sum()
        };
        let x0 = [dot(0, 0), dot(0, 1), dot(0, 2)];
        let mut separations = Vec::with_capacity(self.modes.len());
        let mut max_ratio = 0.0;
        let mut worst = None;
        for k in 1..self.sigma.len() {
            let mut d = [0.0; 3];
            for q in 0..3 {
                d[q] = (dot(k, q) - x0[q]).abs();
                let r = d[q] / self.thresholds[k][q];
                if r > max_ratio {
                    max_ratio = r;
                    worst = Some((k - 1, q));
                }
            }
            separations.push(d);
        }
        Ok(SsTest {
            separations,
            x0_enu: x0,
            max_ratio,
            worst,
        })
    }

    /// The satellites, in input order.
    pub fn ids(&self) -> &[SatId] {
        &self.ids
    }
    /// The monitored fault modes, most probable first.
    pub fn modes(&self) -> &[FaultMode] {
        &self.modes
    }
    /// The satellites fault mode `k` excludes.
    pub fn excluded(&self, k: usize) -> Vec<SatId> {
        let mask = self.modes[k].excluded_mask;
        self.ids
            .iter()
            .enumerate()
            .filter(|(i, _)| mask & (1 << i) != 0)
            .map(|(_, id)| *id)
            .collect()
    }
    /// ENU row q of the WLS gain `S_k` (k = 0 all-in-view, k = j + 1 fault mode j).
    pub fn gain_row(&self, k: usize, q: usize) -> &[f64] {
        let n = self.ids.len();
        &self.gains[(k * 3 + q) * n..(k * 3 + q + 1) * n]
    }
    /// `σ_q⁽ᵏ⁾` (east, north, up), m, k as in [`AraimModel::gain_row`].
    pub fn sigma(&self, k: usize) -> [f64; 3] {
        self.sigma[k]
    }
    /// `σ_ss,q⁽ᵏ⁾`, m.
    pub fn sigma_ss(&self, k: usize) -> [f64; 3] {
        self.sigma_ss[k]
    }
    /// `b_q⁽ᵏ⁾`, m.
    pub fn bias(&self, k: usize) -> [f64; 3] {
        self.bias[k]
    }
    /// `T_k,q`, m.
    pub fn threshold(&self, k: usize) -> [f64; 3] {
        self.thresholds[k]
    }
    /// `K_fa,q` (east, north, up).
    pub fn k_fa(&self) -> [f64; 3] {
        self.k_fa
    }
    /// P_not_monitored: priors of the fault combinations no subset covers.
    pub fn p_not_monitored(&self) -> f64 {
        self.p_not_monitored
    }
    /// Largest number of simultaneous fault events enumerated.
    pub fn max_fault_order(&self) -> usize {
        self.max_order
    }
    /// VPL, m (infinite when the budget is used up by unmonitored modes).
    pub fn vpl(&self) -> f64 {
        self.vpl
    }
    /// HPL = sqrt(HPL_east² + HPL_north²), m.
    pub fn hpl(&self) -> f64 {
        self.hpl_en[0].hypot(self.hpl_en[1])
    }
    /// The east and north PLs, m.
    pub fn hpl_en(&self) -> [f64; 2] {
        self.hpl_en
    }
    /// σ_acc: the vertical all-in-view σ with C_acc, m.
    pub fn sigma_acc(&self) -> f64 {
        self.sigma_acc
    }
    /// EMT: the largest vertical threshold of the modes with `p_fault ≥ P_EMT`, m.
    pub fn emt(&self) -> f64 {
        self.emt
    }
    /// Whether the epoch meets `limits` (VPL, HPL, EMT, K_acc σ_acc, K_ffd σ_acc).
    pub fn available(&self, limits: &AvailabilityLimits) -> bool {
        self.vpl <= limits.val_m
            && self.hpl() <= limits.hal_m
            && self.emt <= limits.emt_m
            && self.k_acc_ffd[0] * self.sigma_acc <= limits.acc95_m
            && self.k_acc_ffd[1] * self.sigma_acc <= limits.ffd_m
    }
}

/// What [`solution_separation_fde`] decided.
#[derive(Debug, Clone)]
pub struct FdeOutcome {
    /// The all-in-view test.
    pub detection: SsTest,
    /// Satellites excluded (empty when the test passed or no exclusion worked).
    pub excluded: Vec<SatId>,
    /// Whether a fault was detected and no single-level exclusion cleared it (alert).
    pub unresolved: bool,
    /// The model in use after the decision: all-in-view, or that of the kept subset.
    pub model: AraimModel,
}

/// Fault detection and exclusion by solution separation ([B15] §III.E; ADD "fault
/// detection and exclusion"). Detection: the all-in-view test of [`AraimModel::test`].
/// Exclusion, one level: the fault modes are tried fewest excluded satellites first and,
/// among equals, in increasing order of the weighted residual sum of squares of their
/// subset (the most consistent subset first; a raw sum of squares alone would favour
/// the subsets that drop a whole constellation, having fewer residuals); for each the
/// whole ARAIM is re-run on the kept satellites (its own fault modes and thresholds), and
/// the first subset whose test passes is kept. A second level (exclusion within the
/// subset) and the ADD's post-exclusion PLs are not done.
pub fn solution_separation_fde(
    sats: &[AraimSat],
    y: &[f64],
    params: &AraimParams,
) -> Result<FdeOutcome, AraimError> {
    let model = AraimModel::fit(sats, params)?;
    let detection = model.test(y)?;
    if detection.passed() {
        return Ok(FdeOutcome {
            detection,
            excluded: Vec::new(),
            unresolved: false,
            model,
        });
    }
    let mut candidates: Vec<(u32, f64, u64)> = model
        .modes()
        .iter()
        .filter_map(|md| {
            let mask = md.excluded_mask;
            subset_wssr(sats, y, mask).map(|r| (mask.count_ones(), r, mask))
        })
        .collect();
    candidates.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    for (_, _, mask) in candidates {
        let keep: Vec<usize> = (0..sats.len()).filter(|i| mask & (1 << i) == 0).collect();
        let sub = renumber_clocks(keep.iter().map(|&i| sats[i]).collect());
        let y_sub: Vec<f64> = keep.iter().map(|&i| y[i]).collect();
        let Ok(sub_model) = AraimModel::fit(&sub, params) else {
            continue;
        };
        if sub_model.test(&y_sub)?.passed() {
            let excluded = (0..sats.len())
                .filter(|i| mask & (1 << i) != 0)
                .map(|i| sats[i].id)
                .collect();
            return Ok(FdeOutcome {
                detection,
                excluded,
                unresolved: false,
                model: sub_model,
            });
        }
    }
    Ok(FdeOutcome {
        detection,
        excluded: Vec::new(),
        unresolved: true,
        model,
    })
}

/// Renumbers the clock columns of `sats` densely (a subset may have lost one).
fn renumber_clocks(mut sats: Vec<AraimSat>) -> Vec<AraimSat> {
    let mut used: Vec<usize> = sats.iter().map(|s| s.clock).collect();
    used.sort_unstable();
    used.dedup();
    for s in &mut sats {
        s.clock = used.iter().position(|&c| c == s.clock).unwrap_or(0);
    }
    sats
}

/// Weighted residual sum of squares `Σ w_i (y_i − g_i x̂)²` of the WLS on the satellites
/// not in `mask` (W = C_int⁻¹), or `None` when that subset is singular.
fn subset_wssr(sats: &[AraimSat], y: &[f64], mask: u64) -> Option<f64> {
    let keep: Vec<usize> = (0..sats.len()).filter(|i| mask & (1 << i) == 0).collect();
    let sub = renumber_clocks(keep.iter().map(|&i| sats[i]).collect());
    let m = 3 + sub.iter().map(|s| s.clock + 1).max()?;
    let gm = DMatrix::from_fn(sub.len(), m, |r, c| match c {
        0..=2 => -sub[r].los_enu[c],
        _ => f64::from(u8::from(c - 3 == sub[r].clock)),
    });
    let w = DVector::from_iterator(
        sub.len(),
        sub.iter()
            .map(|s| 1.0 / (s.sigma_ura.powi(2) + s.var_local())),
    );
    let yv = DVector::from_iterator(keep.len(), keep.iter().map(|&i| y[i]));
    let gtw = gm.transpose() * DMatrix::from_diagonal(&w);
    let x = (&gtw * &gm).cholesky()?.solve(&(&gtw * &yv));
    let r = &yv - &gm * x;
    Some(r.iter().zip(w.iter()).map(|(r, w)| w * r * r).sum())
}
