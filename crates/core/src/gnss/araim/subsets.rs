//! The subsets of one ARAIM fit: the nominal model of the epoch's satellites, each fault
//! mode's subset solved from the all-in-view normal matrix, and the separation σ and
//! biases ([B15] §III; ADD "determine subsets" to "solution separation").

use nalgebra::SMatrix;

use super::{AraimError, AraimSat, FaultMode, M, MAX_CLOCKS, MAX_SATS, Normal};

/// The nominal error model and geometry of one epoch's satellites: what every subset
/// solve needs.
pub(super) struct Nominal {
    /// Rows `[−u_E, −u_N, −u_U, 1]` (the 1 in the satellite's clock column).
    g: Vec<[f64; 4]>,
    /// Clock column of each satellite.
    clock: Vec<usize>,
    /// `W = C_int⁻¹` (diagonal).
    w: Vec<f64>,
    /// `C_acc` (diagonal).
    pub(super) var_acc: Vec<f64>,
    /// Clock columns in use.
    n_clk: usize,
}

/// Every solvable subset's gains and σ, and the modes they monitor.
pub(super) struct Subsets {
    /// ENU rows of `S_k`, row-major `[subset][q][i]`, subset 0 the all-in-view.
    pub(super) gains: Vec<f64>,
    /// `σ_q⁽ᵏ⁾` (integrity) per subset.
    pub(super) sigma: Vec<[f64; 3]>,
    /// The modes kept (subset k + 1 is mode k).
    pub(super) modes: Vec<FaultMode>,
    /// P_not_monitored, with the modes whose subset turned out singular.
    pub(super) p_not_monitored: f64,
}

impl Nominal {
    /// Checks the satellites and builds the model ([B15]'s nominal model: `C_int`,
    /// `C_acc` diagonal, `W = C_int⁻¹`).
    pub(super) fn new(sats: &[AraimSat]) -> Result<Self, AraimError> {
        let n = sats.len();
        let n_clk = sats.iter().map(|s| s.clock + 1).max().unwrap_or(0);
        if n > MAX_SATS || n < 4 + n_clk.saturating_sub(1) || n_clk > MAX_CLOCKS {
            return Err(AraimError::SatelliteCount(n));
        }
        for s in sats {
            let norm = s.los_enu.iter().map(|v| v * v).sum::<f64>().sqrt();
            let ok = s.sigma_ura > 0.0
                && s.sigma_ure > 0.0
                && s.b_nom >= 0.0
                && s.b_nom.is_finite()
                && s.el.is_finite()
                && s.sigma_local.is_none_or(|v| v >= 0.0 && v.is_finite())
                && (norm - 1.0).abs() < 1e-6;
            if !ok {
                return Err(AraimError::Satellite(s.id));
            }
        }
        Ok(Nominal {
            g: sats
                .iter()
                .map(|s| [-s.los_enu[0], -s.los_enu[1], -s.los_enu[2], 1.0])
                .collect(),
            clock: sats.iter().map(|s| s.clock).collect(),
            w: sats
                .iter()
                .map(|s| 1.0 / (s.sigma_ura.powi(2) + s.var_local()))
                .collect(),
            var_acc: sats
                .iter()
                .map(|s| s.sigma_ure.powi(2) + s.var_local())
                .collect(),
            n_clk,
        })
    }

    /// The clock columns the satellites outside `mask` use, as bits.
    pub(super) fn clocks_of(&self, mask: u64) -> u32 {
        self.clock
            .iter()
            .enumerate()
            .filter(|(i, _)| mask & (1 << i) == 0)
            .fold(0u32, |c, (_, &k)| c | (1 << k))
    }

    /// The all-in-view normal matrix `N_0 = Gᵀ W G`, unused clock columns the identity.
    pub(super) fn normal(&self) -> Normal {
        let mut n0 = Normal::zeros();
        for (i, g) in self.g.iter().enumerate() {
            accumulate(&mut n0, g, self.clock[i], self.w[i]);
        }
        for c in self.n_clk..MAX_CLOCKS {
            n0[(3 + c, 3 + c)] = 1.0;
        }
        n0
    }

    /// Solves the all-in-view and every mode's subset; a singular subset's mode is
    /// dropped into P_not_monitored (`p_nm` on entry).
    pub(super) fn solve_subsets(
        &self,
        modes: &[FaultMode],
        mut p_nm: f64,
    ) -> Result<Subsets, AraimError> {
        let n = self.g.len();
        let n0 = self.normal();
        let mut out = Subsets {
            gains: Vec::with_capacity((modes.len() + 1) * 3 * n),
            sigma: Vec::with_capacity(modes.len() + 1),
            modes: Vec::with_capacity(modes.len()),
            p_not_monitored: 0.0,
        };
        let inverse = n0.cholesky().map(|c| c.inverse());
        let all_clocks = self.clocks_of(0);
        let masks = std::iter::once(0u64).chain(modes.iter().map(|md| md.excluded_mask));
        for (k, mask) in masks.enumerate() {
            // One satellite out and no clock lost: a rank-one downdate of N_0⁻¹.
            let one = mask.count_ones() == 1 && self.clocks_of(mask) == all_clocks;
            let solved = match (&inverse, one) {
                (Some(inv), true) => self.downdate(inv, mask.trailing_zeros() as usize),
                _ => None,
            };
            match solved.or_else(|| self.subset(&n0, mask)) {
                Some((x, sig)) => {
                    self.push_gains(&mut out.gains, &x, mask);
                    out.sigma.push(sig);
                    if k > 0 {
                        out.modes.push(modes[k - 1].clone());
                    }
                }
                None if k == 0 => return Err(AraimError::Singular),
                None => p_nm += modes[k - 1].p_fault,
            }
        }
        out.p_not_monitored = p_nm;
        Ok(out)
    }

    /// The first three columns of `N_k⁻¹` for the subset without satellite `i`, by
    /// Sherman–Morrison from `N_0⁻¹`: with `u = N_0⁻¹ g_i`,
    /// `N_k⁻¹ = N_0⁻¹ + w_i u uᵀ / (1 − w_i g_iᵀ u)`. `None` when the denominator is
    /// not safely positive (the satellite carries the geometry): the caller then
    /// factorises `N_k` itself.
    pub(super) fn downdate(
        &self,
        inv: &Normal,
        i: usize,
    ) -> Option<(SMatrix<f64, M, 3>, [f64; 3])> {
        let (g, c) = (&self.g[i], 3 + self.clock[i]);
        let u: nalgebra::SVector<f64, M> =
            inv.column(0) * g[0] + inv.column(1) * g[1] + inv.column(2) * g[2] + inv.column(c);
        let denom = 1.0 - self.w[i] * (g[0] * u[0] + g[1] * u[1] + g[2] * u[2] + u[c]);
        if denom.is_nan() || denom <= 1e-9 {
            return None;
        }
        let scale = self.w[i] / denom;
        let mut x: SMatrix<f64, M, 3> = inv.fixed_columns::<3>(0).into_owned();
        for q in 0..3 {
            let f = scale * u[q];
            for r in 0..M {
                x[(r, q)] += f * u[r];
            }
        }
        let sig = [x[(0, 0)].sqrt(), x[(1, 1)].sqrt(), x[(2, 2)].sqrt()];
        sig.iter().all(|s| s.is_finite()).then_some((x, sig))
    }

    /// The first three columns of `N_k⁻¹` and the subset's σ, `None` when singular.
    /// `N_k = N_0 − Σ_excluded w_i g_i g_iᵀ` (the ADD's `W_k` with zero weights), a lost
    /// clock column replaced by the identity so the position block of `N_k⁻¹` is that of
    /// the reduced geometry.
    pub(super) fn subset(&self, n0: &Normal, mask: u64) -> Option<(SMatrix<f64, M, 3>, [f64; 3])> {
        let mut nk = *n0;
        for i in (0..self.g.len()).filter(|i| mask & (1 << i) != 0) {
            accumulate(&mut nk, &self.g[i], self.clock[i], -self.w[i]);
        }
        let clk = self.clocks_of(mask);
        for c in (0..self.n_clk).filter(|c| clk & (1 << c) == 0) {
            for j in 0..M {
                nk[(3 + c, j)] = 0.0;
                nk[(j, 3 + c)] = 0.0;
            }
            nk[(3 + c, 3 + c)] = 1.0;
        }
        let x = nk.cholesky()?.solve(&SMatrix::<f64, M, 3>::identity());
        let sig = [x[(0, 0)].sqrt(), x[(1, 1)].sqrt(), x[(2, 2)].sqrt()];
        sig.iter().all(|s| s.is_finite()).then_some((x, sig))
    }

    /// Appends `S_k(q, i) = w_i (N_k⁻¹ g_i)_q` for q = E, N, U (0 for excluded satellites).
    fn push_gains(&self, gains: &mut Vec<f64>, x: &SMatrix<f64, M, 3>, mask: u64) {
        for q in 0..3 {
            for (i, gi) in self.g.iter().enumerate() {
                let s = if mask & (1 << i) != 0 {
                    0.0
                } else {
                    self.w[i]
                        * (x[(0, q)] * gi[0]
                            + x[(1, q)] * gi[1]
                            + x[(2, q)] * gi[2]
                            + x[(3 + self.clock[i], q)])
                };
                gains.push(s);
            }
        }
    }
}

impl Subsets {
    /// Per subset `σ_ss² = e_qᵀ (S_k − S_0) C_acc (S_k − S_0)ᵀ e_q` and the bias
    /// `b = Σ_i |S_k(q, i)| b_nom,i`.
    pub(super) fn separations(
        &self,
        nominal: &Nominal,
        sats: &[AraimSat],
    ) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
        let n = sats.len();
        let row = |k: usize, q: usize| &self.gains[(k * 3 + q) * n..(k * 3 + q + 1) * n];
        let mut sigma_ss = vec![[0.0; 3]; self.sigma.len()];
        let mut bias = vec![[0.0; 3]; self.sigma.len()];
        for k in 0..self.sigma.len() {
            for q in 0..3 {
                let (sk, s0) = (row(k, q), row(0, q));
                let mut v = 0.0;
                let mut b = 0.0;
                for i in 0..n {
                    let d = sk[i] - s0[i];
                    v += d * d * nominal.var_acc[i];
                    b += sk[i].abs() * sats[i].b_nom;
                }
                sigma_ss[k][q] = v.sqrt();
                bias[k][q] = b;
            }
        }
        (sigma_ss, bias)
    }
}

/// `N += w g gᵀ` for a row `g = [g_e, g_n, g_u, 1 at clock]`.
fn accumulate(n: &mut Normal, g: &[f64; 4], clock: usize, w: f64) {
    let idx = [0, 1, 2, 3 + clock];
    for a in 0..4 {
        for b in 0..4 {
            n[(idx[a], idx[b])] += w * g[a] * g[b];
        }
    }
}
