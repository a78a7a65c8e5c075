//! Iterated weighted least squares on one epoch's pseudoranges, after [`super::correct`]
//! and before [`super::raim`]: ECEF position plus one receiver clock (m) per
//! constellation present, Gauss–Newton from a given point or the Earth's centre, with
//! the elevation mask applied once a position is known (as RTKLIB's `pntpos`).
//!
//! Model: `y_i = ‖R_z(ω_E τ_i) s_i − x‖ + c_k(i) + ε_i`, `ε_i ~ N(0, σ_i²)`, where `y_i` is
//! the corrected pseudorange and `k(i)` the satellite's constellation. A constellation
//! with a single satellite still gets its own clock column: that satellite then only
//! fixes its clock, adds nothing to the redundancy (`dof` is unchanged by it), has a
//! zero residual and a zero redundancy number, and a fault on it is undetectable (its
//! slope, in [`super::raim`], is infinite).

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

use super::correct::saastamoinen;
use super::correct::{AzEl, RTKLIB_REL_HUMIDITY, az_el, corrected_pseudorange, sagnac_rotate};
use crate::epoch::{Constellation, SatId, SatObs};
use crate::geo::{Lla, ecef_to_enu_rotation, ecef_to_lla};

/// Elevation below which the elevation σ model is evaluated at this floor instead
/// (RTKLIB 2.4.3's `MIN_EL`, 5°): keeps σ finite for the iterates started at the
/// Earth's centre, where elevations mean nothing.
const SIGMA_MIN_EL_RAD: f64 = 5.0 * std::f64::consts::PI / 180.0;

/// A redundancy number below this is treated as zero (no w-test, infinite slope).
pub const MIN_REDUNDANCY: f64 = 1e-9;

/// How the pseudorange standard deviation σ_i (before [`WlsParams::sigma_scale`]) is
/// formed; weights are `1/σ_i²`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SigmaModel {
    /// The satellite's own `SatObs::sigma` (e.g. a phone's reported uncertainty),
    /// `fallback_m` where absent.
    Given {
        /// σ (m) of a satellite without one.
        fallback_m: f64,
    },
    /// `σ² = a² + b²/sin²(el)`, el floored at 5°. RTKLIB's code error model (rtkpos.c
    /// `varerr`; pntpos.c 2.4.2 divides by sin(el), not sin²): its defaults
    /// `err = [100, 0.003, 0.003]` (code/phase ratio × phase terms) give a = b = 0.3 m,
    /// [`SigmaModel::RTKLIB_ELEVATION`]. RTKLIB's per-constellation factors (GLONASS 1.5,
    /// SBAS 3) are not applied.
    Elevation {
        /// Elevation-independent term a, m.
        a_m: f64,
        /// Elevation-dependent term b, m.
        b_m: f64,
    },
    /// `σ² = a² + b²·10^(−C/N0/10)` with C/N0 in dB-Hz: the SIGMA-ε form (Hartinger &
    /// Brunner 1999, GPS Solutions 2(4); Wieser & Brunner 2000) plus a floor a. The
    /// defaults of [`SigmaModel::PHONE_CN0`] are ours (σ ≈ 0.9 m at 45 dB-Hz, 4.7 m at
    /// 30 dB-Hz), not the papers'. `fallback_m` where C/N0 is absent.
    Cn0 {
        /// Floor a, m.
        a_m: f64,
        /// b, m (b² in m²·Hz).
        b_m: f64,
        /// σ (m) of a satellite without a C/N0.
        fallback_m: f64,
    },
}

impl SigmaModel {
    /// RTKLIB's default elevation model, a = b = 0.3 m.
    pub const RTKLIB_ELEVATION: SigmaModel = SigmaModel::Elevation { a_m: 0.3, b_m: 0.3 };
    /// A C/N0 model for phones: a = 0.3 m, b = 150 m, 10 m without C/N0.
    pub const PHONE_CN0: SigmaModel = SigmaModel::Cn0 {
        a_m: 0.3,
        b_m: 150.0,
        fallback_m: 10.0,
    };

    /// σ (m) of `obs` at elevation `el` (rad).
    pub fn sigma(&self, obs: &SatObs, el: f64) -> f64 {
        match *self {
            SigmaModel::Given { fallback_m } => obs.sigma.unwrap_or(fallback_m),
            SigmaModel::Elevation { a_m, b_m } => {
                let s = el.max(SIGMA_MIN_EL_RAD).sin();
                (a_m * a_m + b_m * b_m / (s * s)).sqrt()
            }
            SigmaModel::Cn0 {
                a_m,
                b_m,
                fallback_m,
            } => match obs.cn0 {
                Some(cn0) => (a_m * a_m + b_m * b_m * 10f64.powf(-cn0 / 10.0)).sqrt(),
                None => fallback_m,
            },
        }
    }
}

/// Settings of one WLS fix.
#[derive(Debug, Clone, PartialEq)]
pub struct WlsParams {
    /// The σ model.
    pub sigma_model: SigmaModel,
    /// Factor on every σ (phones' reported σ are usually optimistic).
    pub sigma_scale: f64,
    /// Satellites below this elevation (rad) are dropped once a position is known.
    pub elevation_mask_rad: f64,
    /// Relative humidity of the model troposphere, in [0, 1].
    pub rel_humidity: f64,
    /// Most Gauss–Newton iterations per solve (RTKLIB: 10).
    pub max_iterations: usize,
    /// Convergence when `‖dx‖` (position and clocks, m) falls below this (RTKLIB: 1e-4).
    pub tolerance_m: f64,
    /// Starting point (ECEF, m); `None` starts at the Earth's centre.
    pub initial_ecef: Option<Vector3<f64>>,
}

impl Default for WlsParams {
    /// RTKLIB's single-point defaults: elevation σ model a = b = 0.3 m, 15° mask,
    /// 70 % humidity, 10 iterations, 1e-4 m.
    fn default() -> Self {
        WlsParams {
            sigma_model: SigmaModel::RTKLIB_ELEVATION,
            sigma_scale: 1.0,
            elevation_mask_rad: 15f64.to_radians(),
            rel_humidity: RTKLIB_REL_HUMIDITY,
            max_iterations: 10,
            tolerance_m: 1e-4,
            initial_ecef: None,
        }
    }
}

/// Why a WLS fix failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WlsError {
    /// Fewer satellites than unknowns (3 + one clock per constellation).
    #[error("too few satellites: {have} for {need} unknowns")]
    TooFewSatellites {
        /// Satellites used.
        have: usize,
        /// Unknowns.
        need: usize,
    },
    /// The normal matrix has no (well-conditioned) Cholesky factor.
    #[error("singular geometry")]
    SingularGeometry,
    /// `‖dx‖` never fell below the tolerance.
    #[error("no convergence in {iterations} iterations")]
    NoConvergence {
        /// Iterations done.
        iterations: usize,
    },
    /// A NaN or infinity in the data or the iterate.
    #[error("non-finite value in the measurements or the solution")]
    NonFinite,
    /// A parameter out of range.
    #[error("invalid WLS parameter: {0}")]
    InvalidParams(&'static str),
}

impl WlsParams {
    /// Checks ranges: positive finite scale and tolerance, humidity in [0, 1], at least
    /// one iteration, finite mask and start, positive σ model terms.
    pub fn check(&self) -> Result<(), WlsError> {
        let positive = |x: f64| x.is_finite() && x > 0.0;
        let (a, b) = match self.sigma_model {
            SigmaModel::Given { fallback_m } => (fallback_m, 1.0),
            SigmaModel::Elevation { a_m, b_m } => (a_m.max(b_m), 1.0),
            SigmaModel::Cn0 {
                a_m, fallback_m, ..
            } => (a_m, fallback_m),
        };
        if !(positive(a) && positive(b) && positive(self.sigma_scale)) {
            return Err(WlsError::InvalidParams(
                "sigma model terms and scale must be > 0",
            ));
        }
        if !positive(self.tolerance_m) || self.max_iterations == 0 {
            return Err(WlsError::InvalidParams(
                "tolerance > 0 and max_iterations >= 1",
            ));
        }
        if !(0.0..=1.0).contains(&self.rel_humidity) || !self.elevation_mask_rad.is_finite() {
            return Err(WlsError::InvalidParams("humidity in [0, 1], finite mask"));
        }
        if self
            .initial_ecef
            .is_some_and(|x| !x.iter().all(|v| v.is_finite()))
        {
            return Err(WlsError::InvalidParams("initial position must be finite"));
        }
        Ok(())
    }
}

/// Dilutions of precision from the unweighted geometry in ENU (`Q = (GᵀG)⁻¹`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dops {
    /// `sqrt(trace Q)`, position and every clock.
    pub gdop: f64,
    /// `sqrt(Q_ee + Q_nn + Q_uu)`.
    pub pdop: f64,
    /// `sqrt(Q_ee + Q_nn)`.
    pub hdop: f64,
    /// `sqrt(Q_uu)`.
    pub vdop: f64,
}

/// One used satellite's part of a fix.
#[derive(Debug, Clone, PartialEq)]
pub struct SatResidual {
    /// The satellite.
    pub id: SatId,
    /// Its index in the observation slice given to the solver.
    pub index: usize,
    /// Post-fit residual `y − ŷ`, m.
    pub residual_m: f64,
    /// w-test `residual / sqrt(C_v,ii)` with `C_v = W⁻¹ − G (GᵀWG)⁻¹ Gᵀ`; 0 where the
    /// redundancy number is below [`MIN_REDUNDANCY`].
    pub normalised: f64,
    /// Redundancy number `C_v,ii / σ_i²` in [0, 1].
    pub redundancy: f64,
    /// σ used (scale included), m.
    pub sigma_m: f64,
    /// Azimuth and elevation at the fix.
    pub az_el: AzEl,
    /// Tropospheric delay applied, m (given or modelled).
    pub tropo_m: f64,
}

/// A WLS fix and what integrity monitoring needs of it.
#[derive(Debug, Clone, PartialEq)]
pub struct WlsSolution {
    /// Position, ECEF, m.
    pub ecef: Vector3<f64>,
    /// Position, geodetic.
    pub lla: Lla,
    /// Receiver clock (m) per constellation used, in [`Constellation::ALL`] order.
    pub clocks: Vec<(Constellation, f64)>,
    /// Position covariance in ENU at the fix, m² (`(GᵀWG)⁻¹`, not rescaled by WSSR).
    pub cov_enu: Matrix3<f64>,
    /// DOPs.
    pub dops: Dops,
    /// The used satellites, in input order.
    pub sats: Vec<SatResidual>,
    /// Satellites dropped by the elevation mask.
    pub masked: Vec<SatId>,
    /// Weighted sum of squared residuals `Σ v_i²/σ_i²`.
    pub wssr: f64,
    /// Degrees of freedom `n − 3 − n_clk`.
    pub dof: u32,
    /// Gauss–Newton iterations of the last solve.
    pub iterations: usize,
    /// Design matrix in ENU, one row per used satellite: `[−e_enu | clock indicator]`
    /// (the slope computations of [`super::raim`] need it).
    pub geometry_enu: DMatrix<f64>,
}

impl WlsSolution {
    /// The receiver clock of constellation `c`, m, if it was estimated.
    pub fn clock(&self, c: Constellation) -> Option<f64> {
        self.clocks.iter().find(|(k, _)| *k == c).map(|&(_, v)| v)
    }
}

/// Solves with every satellite (see [`solve_excluding`]).
pub fn solve(obs: &[SatObs], params: &WlsParams) -> Result<WlsSolution, WlsError> {
    solve_excluding(obs, params, &[])
}

/// Solves without the satellites in `excluded`: Gauss–Newton from `initial_ecef` or the
/// Earth's centre with every satellite; then, if any lies below the elevation mask at
/// that fix, again from that fix without them.
pub fn solve_excluding(
    obs: &[SatObs],
    params: &WlsParams,
    excluded: &[SatId],
) -> Result<WlsSolution, WlsError> {
    params.check()?;
    let candidates: Vec<usize> = (0..obs.len())
        .filter(|&i| !excluded.contains(&obs[i].id))
        .collect();
    let start = params.initial_ecef.unwrap_or_else(Vector3::zeros);
    let mut fit = gauss_newton(obs, &candidates, params, start)?;
    let above = |j: usize| fit.lin.az_el[j].el >= params.elevation_mask_rad;
    if (0..candidates.len()).all(above) {
        return Ok(fit.into_solution(obs, Vec::new()));
    }
    let (kept, masked): (Vec<usize>, Vec<usize>) =
        (0..candidates.len()).partition(|&j| fit.lin.az_el[j].el >= params.elevation_mask_rad);
    let kept: Vec<usize> = kept.into_iter().map(|j| candidates[j]).collect();
    let masked: Vec<SatId> = masked.into_iter().map(|j| obs[candidates[j]].id).collect();
    let from = fit.pos();
    fit = gauss_newton(obs, &kept, params, from)?;
    Ok(fit.into_solution(obs, masked))
}

/// One linearisation: design matrix (ECEF), residuals, σ, geometry per used row.
struct Linearisation {
    /// Rows `[−e_ecef | clock indicator]`.
    h: DMatrix<f64>,
    /// `y − ŷ`, m.
    v: DVector<f64>,
    sigma: Vec<f64>,
    az_el: Vec<AzEl>,
    tropo: Vec<f64>,
}

/// A converged fit: state `[x, y, z, clocks…]` and its last linearisation (at the state).
struct Fit {
    rows: Vec<usize>,
    clocks: Vec<Constellation>,
    state: DVector<f64>,
    lin: Linearisation,
    iterations: usize,
}

/// The constellations present among `rows`, in [`Constellation::ALL`] order.
fn constellations(obs: &[SatObs], rows: &[usize]) -> Vec<Constellation> {
    Constellation::ALL
        .into_iter()
        .filter(|c| rows.iter().any(|&i| obs[i].id.constellation == *c))
        .collect()
}

/// Fills `lin` at `state`.
fn linearise(
    obs: &[SatObs],
    fit_rows: &[usize],
    clocks: &[Constellation],
    state: &DVector<f64>,
    params: &WlsParams,
    lin: &mut Linearisation,
) {
    let rx = Vector3::new(state[0], state[1], state[2]);
    let rx_lla = ecef_to_lla(&rx);
    lin.h.fill(0.0);
    for (j, &i) in fit_rows.iter().enumerate() {
        let o = &obs[i];
        let sat = sagnac_rotate(&Vector3::from(o.pos), &rx);
        let los = sat - rx;
        let range = los.norm();
        let e = los / range;
        let mut ae = az_el(&rx, &rx_lla, &sat);
        if let (Some(el), Some(az)) = (o.el, o.az) {
            ae = AzEl { az, el };
        }
        let tropo = saastamoinen(rx_lla.lat, rx_lla.h, ae.el, params.rel_humidity);
        let k = clocks
            .iter()
            .position(|c| *c == o.id.constellation)
            .unwrap_or(0);
        lin.v[j] = corrected_pseudorange(o, tropo) - (range + state[3 + k]);
        for a in 0..3 {
            lin.h[(j, a)] = -e[a];
        }
        lin.h[(j, 3 + k)] = 1.0;
        lin.sigma[j] = params.sigma_model.sigma(o, ae.el) * params.sigma_scale;
        lin.az_el[j] = ae;
        lin.tropo[j] = o.tropo.unwrap_or(tropo);
    }
}

/// `(HᵀWH)`'s Cholesky factor and `HᵀWv`, or `SingularGeometry`.
fn normal_equations(
    lin: &Linearisation,
) -> Result<(nalgebra::Cholesky<f64, nalgebra::Dyn>, DVector<f64>), WlsError> {
    let mut hw = lin.h.clone();
    let mut vw = lin.v.clone();
    for (j, s) in lin.sigma.iter().enumerate() {
        hw.row_mut(j).scale_mut(1.0 / s);
        vw[j] /= s;
    }
    let n = hw.tr_mul(&hw);
    let b = hw.tr_mul(&vw);
    if !n.iter().chain(b.iter()).all(|x| x.is_finite()) {
        return Err(WlsError::NonFinite);
    }
    let chol = n.cholesky().ok_or(WlsError::SingularGeometry)?;
    // A tiny pivot against the largest means a condition number beyond ~1e14.
    let d = chol.l_dirty().diagonal();
    if d.min() <= d.max() * 1e-7 {
        return Err(WlsError::SingularGeometry);
    }
    Ok((chol, b))
}

/// Gauss–Newton on the satellites `rows` from `start` (clocks start at 0).
fn gauss_newton(
    obs: &[SatObs],
    rows: &[usize],
    params: &WlsParams,
    start: Vector3<f64>,
) -> Result<Fit, WlsError> {
    let clocks = constellations(obs, rows);
    let m = 3 + clocks.len();
    if rows.len() < m {
        return Err(WlsError::TooFewSatellites {
            have: rows.len(),
            need: m,
        });
    }
    let n = rows.len();
    let mut lin = Linearisation {
        h: DMatrix::zeros(n, m),
        v: DVector::zeros(n),
        sigma: vec![0.0; n],
        az_el: vec![AzEl { az: 0.0, el: 0.0 }; n],
        tropo: vec![0.0; n],
    };
    let mut state = DVector::zeros(m);
    state.fixed_rows_mut::<3>(0).copy_from(&start);
    for it in 1..=params.max_iterations {
        linearise(obs, rows, &clocks, &state, params, &mut lin);
        let (chol, b) = normal_equations(&lin)?;
        let dx = chol.solve(&b);
        state += &dx;
        if !state.iter().all(|x| x.is_finite()) {
            return Err(WlsError::NonFinite);
        }
        if dx.norm() < params.tolerance_m {
            linearise(obs, rows, &clocks, &state, params, &mut lin);
            return Ok(Fit {
                rows: rows.to_vec(),
                clocks,
                state,
                lin,
                iterations: it,
            });
        }
    }
    Err(WlsError::NoConvergence {
        iterations: params.max_iterations,
    })
}

impl Fit {
    fn pos(&self) -> Vector3<f64> {
        Vector3::new(self.state[0], self.state[1], self.state[2])
    }

    /// Covariances, DOPs, residuals and w-tests at the converged state.
    fn into_solution(self, obs: &[SatObs], masked: Vec<SatId>) -> WlsSolution {
        let ecef = self.pos();
        let lla = ecef_to_lla(&ecef);
        let r = ecef_to_enu_rotation(lla.lat, lla.lon);
        let n = self.rows.len();
        let m = 3 + self.clocks.len();
        // The factor exists: the same matrix was factored at the last iteration, a
        // tolerance step away.
        let q = normal_equations(&self.lin)
            .map(|(c, _)| c.inverse())
            .unwrap_or_else(|_| DMatrix::from_element(m, m, f64::NAN));
        let q_pos: Matrix3<f64> = q.fixed_view::<3, 3>(0, 0).into_owned();
        let cov_enu = r * q_pos * r.transpose();
        let mut g = DMatrix::zeros(n, m);
        for j in 0..n {
            let e_ecef = Vector3::new(self.lin.h[(j, 0)], self.lin.h[(j, 1)], self.lin.h[(j, 2)]);
            let e_enu = r * e_ecef;
            for a in 0..3 {
                g[(j, a)] = e_enu[a];
            }
            for k in 3..m {
                g[(j, k)] = self.lin.h[(j, k)];
            }
        }
        let mut wssr = 0.0;
        let mut sats = Vec::with_capacity(n);
        for (j, &i) in self.rows.iter().enumerate() {
            let s = self.lin.sigma[j];
            let hj = self.lin.h.row(j);
            let c_vv = s * s - (hj * &q * hj.transpose())[(0, 0)];
            let redundancy = (c_vv / (s * s)).clamp(0.0, 1.0);
            let v = self.lin.v[j];
            wssr += (v / s).powi(2);
            sats.push(SatResidual {
                id: obs[i].id,
                index: i,
                residual_m: v,
                normalised: if redundancy > MIN_REDUNDANCY {
                    v / c_vv.sqrt()
                } else {
                    0.0
                },
                redundancy,
                sigma_m: s,
                az_el: self.lin.az_el[j],
                tropo_m: self.lin.tropo[j],
            });
        }
        WlsSolution {
            ecef,
            lla,
            clocks: self
                .clocks
                .iter()
                .enumerate()
                .map(|(k, &c)| (c, self.state[3 + k]))
                .collect(),
            cov_enu,
            dops: dops(&g),
            sats,
            masked,
            wssr,
            dof: (n - m) as u32,
            iterations: self.iterations,
            geometry_enu: g,
        }
    }
}

/// DOPs of the ENU design matrix `g` (NaN if `GᵀG` is singular).
pub fn dops(g: &DMatrix<f64>) -> Dops {
    let Some(q) = g.tr_mul(g).try_inverse() else {
        return Dops {
            gdop: f64::NAN,
            pdop: f64::NAN,
            hdop: f64::NAN,
            vdop: f64::NAN,
        };
    };
    let (e, n, u) = (q[(0, 0)], q[(1, 1)], q[(2, 2)]);
    Dops {
        gdop: q.trace().sqrt(),
        pdop: (e + n + u).sqrt(),
        hdop: (e + n).sqrt(),
        vdop: u.sqrt(),
    }
}
