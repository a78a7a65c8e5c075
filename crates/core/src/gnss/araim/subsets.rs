//! The subsets of one ARAIM fit: the nominal model of the epoch's satellites, each fault
//! mode's subset solved from the all-in-view normal matrix, and the separation σ and
//! biases ([B15] §III; ADD "determine subsets" to "solution separation").

use nalgebra::{SMatrix, SVector};

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
    /// `b_nom` of each satellite.
    b_nom: Vec<f64>,
    /// The satellites of each clock column, as bits.
    clock_sats: [u64; MAX_CLOCKS],
    /// Clock columns in use.
    n_clk: usize,
}

/// Every solvable subset's gains, σ, separation σ and bias, and the modes they monitor.
pub(super) struct Subsets {
    /// ENU rows of `S_k`, row-major `[subset][q][i]`, subset 0 the all-in-view.
    pub(super) gains: Vec<f64>,
    /// `σ_q⁽ᵏ⁾` (integrity) per subset.
    pub(super) sigma: Vec<[f64; 3]>,
    /// `σ_ss,q⁽ᵏ⁾ = sqrt(e_qᵀ (S_k − S_0) C_acc (S_k − S_0)ᵀ e_q)` per subset (0 for
    /// subset 0).
    pub(super) sigma_ss: Vec<[f64; 3]>,
    /// `b_q⁽ᵏ⁾ = Σ_i |S_k(q, i)| b_nom,i` per subset.
    pub(super) bias: Vec<[f64; 3]>,
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
            b_nom: sats.iter().map(|s| s.b_nom).collect(),
            clock_sats: sats
                .iter()
                .enumerate()
                .fold([0; MAX_CLOCKS], |mut bits, (i, s)| {
                    bits[s.clock] |= 1 << i;
                    bits
                }),
            n_clk,
        })
    }

    /// The clock columns the satellites outside `mask` use, as bits.
    pub(super) fn clocks_of(&self, mask: u64) -> u32 {
        (0..self.n_clk)
            .filter(|&c| self.clock_sats[c] & !mask != 0)
            .fold(0u32, |bits, c| bits | (1 << c))
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
        let per = 3 * self.g.len();
        let n0 = self.normal();
        let mut out = Subsets {
            gains: Vec::with_capacity((modes.len() + 1) * per),
            sigma: Vec::with_capacity(modes.len() + 1),
            sigma_ss: Vec::with_capacity(modes.len() + 1),
            bias: Vec::with_capacity(modes.len() + 1),
            modes: Vec::with_capacity(modes.len()),
            p_not_monitored: 0.0,
        };
        let inverse = n0.cholesky().map(|c| c.inverse());
        let all_clocks = self.clocks_of(0);
        // Scratch for each downdate's `v_l = w_l g_lᵀ u`.
        let mut v = vec![0.0; self.g.len()];
        // The rows of S_0, once solved (the downdates start from them).
        let mut all_in_view: Vec<f64> = Vec::new();
        let masks = std::iter::once(0u64).chain(modes.iter().map(|md| md.excluded_mask));
        for (k, mask) in masks.enumerate() {
            // One satellite out and no clock lost: a rank-one downdate of N_0⁻¹.
            let one = mask.count_ones() == 1 && self.clocks_of(mask) == all_clocks;
            let j = mask.trailing_zeros() as usize;
            let downdate = match (&inverse, one) {
                (Some(inv), true) => self.rank_one(inv, j),
                _ => None,
            };
            let start = out.gains.len();
            let solved = match downdate {
                Some(r) if k > 0 => Some((
                    r.sigma,
                    r.push_gains(self, &mut out.gains, &all_in_view, j, &mut v),
                )),
                _ => self.subset(&n0, mask).map(|(x, sig)| {
                    self.push_gains(&mut out.gains, &x, mask);
                    let rows = &out.gains[start..];
                    let s0 = if k == 0 { rows } else { &all_in_view[..] };
                    (sig, self.separation(rows, s0))
                }),
            };
            match solved {
                Some((sig, (sigma_ss, bias))) => {
                    if k == 0 {
                        all_in_view.extend_from_slice(&out.gains[..per]);
                    }
                    out.sigma.push(sig);
                    out.sigma_ss.push(sigma_ss);
                    out.bias.push(bias);
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

    /// The subset without satellite `i` as a rank-one downdate of `N_0⁻¹`
    /// (Sherman–Morrison): with `u = N_0⁻¹ g_i`,
    /// `N_k⁻¹ = N_0⁻¹ + w_i u uᵀ / (1 − w_i g_iᵀ u)`. `None` when the denominator is not
    /// safely positive (the satellite carries the geometry) or a σ is not finite: the
    /// caller then factorises `N_k` itself.
    fn rank_one(&self, inv: &Normal, i: usize) -> Option<RankOne> {
        let (g, c) = (&self.g[i], 3 + self.clock[i]);
        let u: SVector<f64, M> =
            inv.column(0) * g[0] + inv.column(1) * g[1] + inv.column(2) * g[2] + inv.column(c);
        let denom = 1.0 - self.w[i] * (g[0] * u[0] + g[1] * u[1] + g[2] * u[2] + u[c]);
        if denom.is_nan() || denom <= 1e-9 {
            return None;
        }
        let scale = self.w[i] / denom;
        let sigma = [0, 1, 2].map(|q| (inv[(q, q)] + scale * u[q] * u[q]).sqrt());
        sigma
            .iter()
            .all(|s| s.is_finite())
            .then_some(RankOne { u, scale, sigma })
    }

    /// The first three columns of `N_k⁻¹` for the subset without satellite `i`, by the
    /// downdate of [`Nominal::rank_one`], and the subset's σ (the tests compare it with
    /// [`Nominal::subset`]).
    #[cfg(test)]
    pub(super) fn downdate(
        &self,
        inv: &Normal,
        i: usize,
    ) -> Option<(SMatrix<f64, M, 3>, [f64; 3])> {
        let r = self.rank_one(inv, i)?;
        let mut x: SMatrix<f64, M, 3> = inv.fixed_columns::<3>(0).into_owned();
        for q in 0..3 {
            let f = r.scale * r.u[q];
            for row in 0..M {
                x[(row, q)] += f * r.u[row];
            }
        }
        Some((x, r.sigma))
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

    /// Appends the ENU rows of `S_k`, `S_k(q, i) = w_i (N_k⁻¹ g_i)_q` (0 for excluded
    /// satellites), to `gains`.
    fn push_gains(&self, gains: &mut Vec<f64>, x: &SMatrix<f64, M, 3>, mask: u64) {
        for q in 0..3 {
            let (xe, xn, xu) = (x[(0, q)], x[(1, q)], x[(2, q)]);
            let mut xc = [0.0; MAX_CLOCKS];
            for (c, v) in xc.iter_mut().enumerate() {
                *v = x[(3 + c, q)];
            }
            let start = gains.len();
            let sats = self.g.iter().zip(&self.w).zip(&self.clock);
            gains.extend(
                sats.map(|((gi, w), &c)| w * (xe * gi[0] + xn * gi[1] + xu * gi[2] + xc[c])),
            );
            let mut excluded = mask;
            while excluded != 0 {
                gains[start + excluded.trailing_zeros() as usize] = 0.0;
                excluded &= excluded - 1;
            }
        }
    }

    /// Per axis `σ_ss² = e_qᵀ (S_k − S_0) C_acc (S_k − S_0)ᵀ e_q` and the bias
    /// `b = Σ_i |S_k(q, i)| b_nom,i`, from the rows of `S_k` and `S_0`.
    fn separation(&self, rows: &[f64], all_in_view: &[f64]) -> ([f64; 3], [f64; 3]) {
        let n = self.g.len();
        let mut sigma_ss = [0.0; 3];
        let mut bias = [0.0; 3];
        let axes = rows.chunks_exact(n).zip(all_in_view.chunks_exact(n));
        for (q, (sk, s0)) in axes.enumerate() {
            let mut v = 0.0;
            let mut b = 0.0;
            let sats = s0.iter().zip(&self.var_acc).zip(&self.b_nom);
            for (s, ((s0, var), b_nom)) in sk.iter().zip(sats) {
                let d = s - s0;
                v += d * d * var;
                b += s.abs() * b_nom;
            }
            sigma_ss[q] = v.sqrt();
            bias[q] = b;
        }
        (sigma_ss, bias)
    }
}

/// A single-satellite subset as a downdate of the all-in-view inverse,
/// `N_k⁻¹ = N_0⁻¹ + scale · u uᵀ`.
struct RankOne {
    /// `u = N_0⁻¹ g_i`.
    u: SVector<f64, M>,
    /// `w_i / (1 − w_i g_iᵀ u)`.
    scale: f64,
    /// `σ_q⁽ᵏ⁾ = sqrt((N_k⁻¹)_qq)`.
    sigma: [f64; 3],
}

impl RankOne {
    /// Appends the rows of `S_k` (satellite `i` left out) to `gains` from those of
    /// `S_0`, and returns the subset's separation σ and bias. With `v_l = w_l g_lᵀ u`,
    /// `S_k(q, l) = S_0(q, l) + scale u_q v_l` for `l ≠ i` (and 0 at `i`), so
    /// `σ_ss,q² = (scale u_q)² Σ_{l≠i} v_l² σ²_acc,l + S_0(q, i)² σ²_acc,i`: one sum
    /// for the three axes. `v` is scratch, one entry per satellite.
    fn push_gains(
        &self,
        nominal: &Nominal,
        gains: &mut Vec<f64>,
        all_in_view: &[f64],
        i: usize,
        v: &mut [f64],
    ) -> ([f64; 3], [f64; 3]) {
        let n = nominal.g.len();
        let u = &self.u;
        let mut uc = [0.0; MAX_CLOCKS];
        for (c, x) in uc.iter_mut().enumerate() {
            *x = u[3 + c];
        }
        let sats = nominal.g.iter().zip(&nominal.w).zip(&nominal.clock);
        for (vl, ((g, w), &c)) in v.iter_mut().zip(sats) {
            *vl = w * (u[0] * g[0] + u[1] * g[1] + u[2] * g[2] + uc[c]);
        }
        v[i] = 0.0;
        let spread: f64 = v
            .iter()
            .zip(&nominal.var_acc)
            .map(|(vl, var)| vl * vl * var)
            .sum();
        let mut sigma_ss = [0.0; 3];
        let mut bias = [0.0; 3];
        for (q, s0) in all_in_view.chunks_exact(n).enumerate() {
            let f = self.scale * u[q];
            let start = gains.len();
            gains.extend(s0.iter().zip(&*v).map(|(a, vl)| a + f * vl));
            let row = &mut gains[start..];
            row[i] = 0.0;
            sigma_ss[q] = (f * f * spread + s0[i] * s0[i] * nominal.var_acc[i]).sqrt();
            bias[q] = row
                .iter()
                .zip(&nominal.b_nom)
                .map(|(s, b)| s.abs() * b)
                .sum();
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
