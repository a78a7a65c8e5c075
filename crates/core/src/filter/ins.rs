//! The 15-state INS error model (docs/methods.md §M4, seed 004 §1.1): sits between
//! `geo` (radii, Earth and transport rates) and the federated filter, which
//! predicts every local filter with the Φ and Q_d built here; the simulator
//! propagates its true INS errors with the same model.
//!
//! Error state, ENU navigation frame (docs/methods.md §M4):
//! `φ` (0..3, rad; `C̃_bⁿ = (I − [φ×]) C_bⁿ`), `δv` (3..6, m/s, INS − true),
//! `δp` (6..9, m, local level ENU, INS − true), `ε` gyro bias (9..12, rad/s, body),
//! `∇` accelerometer bias (12..15, m/s², body). Continuous model:
//!
//! - `φ̇ = −ω_in × φ − C_bⁿ ε − C_bⁿ w_g`, with `ω_in = ω_ie + ω_en`;
//! - `δv̇ = fⁿ × φ − (2ω_ie + ω_en) × δv + C_bⁿ ∇ + C_bⁿ w_a`;
//! - `δṗ = δv`; `ε̇ = −ε/τ + w_ε`, `∇̇ = −∇/τ + w_∇`: first-order Gauss–Markov with the
//!   correlation time τ of [`ImuErrors::bias_tau_s`] and steady-state σ the bias figures,
//!   plus an optional bias random walk; with neither (the default) random constants.
//!
//! `fⁿ × φ` follows from `f̃ⁿ = C̃_bⁿ f_b = fⁿ − φ × fⁿ`. The terms of `δω_in` and of
//! gravity in `δp` are left out, as docs/methods.md §M4 states the model (over the
//! seed's 3,000 s they are below the aid noise).

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use serde::{Deserialize, Serialize};

use crate::epoch::InsBlock;
use crate::geo::{self, Lla};

/// Number of error states.
pub const N: usize = 15;
/// Offset of the misalignment angles φ (rad).
pub const ATT: usize = 0;
/// Offset of the velocity errors δv (m/s, ENU).
pub const VEL: usize = 3;
/// Offset of the position errors δp (m, ENU local level).
pub const POS: usize = 6;
/// Offset of the gyro biases ε (rad/s, body).
pub const GYRO: usize = 9;
/// Offset of the accelerometer biases ∇ (m/s², body).
pub const ACC: usize = 12;

/// A 15-element error vector.
pub type ErrorVector = SVector<f64, N>;
/// A 15 × 15 matrix over the error state (F, Φ, P, Q).
pub type ErrorMatrix = SMatrix<f64, N, N>;
/// The noise input matrix G: 15 states × (3 gyro + 3 accelerometer) white noises.
pub type NoiseInput = SMatrix<f64, N, 6>;

/// Degrees per hour → rad/s.
const DPH_TO_RPS: f64 = std::f64::consts::PI / 180.0 / 3600.0;
/// One micro-g, m/s² (standard gravity 9.80665 m/s²).
const MICRO_G: f64 = 9.806_65e-6;

/// The INS solution an error model is linearised about.
#[derive(Debug, Clone, PartialEq)]
pub struct NavSolution {
    /// Position (rad, rad, m).
    pub lla: Lla,
    /// Velocity ENU, m/s.
    pub vel: Vector3<f64>,
    /// Body (RFU) to navigation (ENU) direction cosine matrix `C_bⁿ`.
    pub c_bn: Matrix3<f64>,
    /// Specific force in the navigation frame, m/s².
    pub f_n: Vector3<f64>,
}

impl NavSolution {
    /// Builds the solution from an epoch's INS block. `fⁿ = C_bⁿ f_b`, or `[0, 0, g]`
    /// (normal gravity, the specific force of unaccelerated motion) when `f_b` is absent.
    pub fn from_ins(ins: &InsBlock) -> Self {
        let lla = Lla {
            lat: ins.lat,
            lon: ins.lon,
            h: ins.h,
        };
        let c_bn = geo::dcm_body_to_nav(ins.att[0], ins.att[1], ins.att[2]);
        let f_n = match ins.f_b {
            Some(f_b) => c_bn * Vector3::from(f_b),
            None => Vector3::new(0.0, 0.0, geo::normal_gravity(ins.lat, ins.h)),
        };
        NavSolution {
            lla,
            vel: Vector3::from(ins.vel),
            c_bn,
            f_n,
        }
    }
}

/// IMU error parameters (docs/methods.md §M4, §M19 and §M31, seed 004 §3).
///
/// Defaults: gyro bias 0.002 °/h and accelerometer bias 10 µg (seed 004), and — the seed gives
/// no white-noise figures — angle random walk 0.001 °/√h and velocity random walk
/// 0.001 m/s/√h, typical of the navigation-grade marine INS the seed's biases describe;
/// biases are random constants (no correlation time, no bias random walk). A MEMS IMU
/// needs its own figures (docs/methods.md §M31 gives the shared car drive's).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImuErrors {
    /// Gyro bias (1σ: of the random constant, or the Gauss–Markov steady state), °/h.
    pub gyro_bias_dph: f64,
    /// Accelerometer bias (1σ, as the gyro's), µg.
    pub accel_bias_ug: f64,
    /// Gyro angle random walk, °/√h.
    pub arw_deg_rthr: f64,
    /// Accelerometer velocity random walk, m/s/√h.
    pub vrw_mps_rthr: f64,
    /// Bias correlation time τ, s: the biases are first-order Gauss–Markov processes with
    /// steady-state σ the bias figures above; absent: no decay.
    #[serde(default)]
    pub bias_tau_s: Option<f64>,
    /// Gyro bias random walk, °/h/√h (0: none).
    #[serde(default)]
    pub gyro_bias_walk_dph_rthr: f64,
    /// Accelerometer bias random walk, µg/√h (0: none).
    #[serde(default)]
    pub accel_bias_walk_ug_rthr: f64,
}

impl Default for ImuErrors {
    fn default() -> Self {
        ImuErrors {
            gyro_bias_dph: 0.002,
            accel_bias_ug: 10.0,
            arw_deg_rthr: 0.001,
            vrw_mps_rthr: 0.001,
            bias_tau_s: None,
            gyro_bias_walk_dph_rthr: 0.0,
            accel_bias_walk_ug_rthr: 0.0,
        }
    }
}

impl ImuErrors {
    /// Gyro bias in rad/s.
    pub fn gyro_bias_rps(&self) -> f64 {
        self.gyro_bias_dph * DPH_TO_RPS
    }

    /// Accelerometer bias in m/s².
    pub fn accel_bias_mps2(&self) -> f64 {
        self.accel_bias_ug * MICRO_G
    }

    /// Gyro white-noise power spectral density, (rad/s)²/Hz = rad²/s:
    /// ARW °/√h → rad/√s is `× π/180 / 60`, squared.
    pub fn gyro_noise_psd(&self) -> f64 {
        let arw = self.arw_deg_rthr.to_radians() / 60.0;
        arw * arw
    }

    /// Accelerometer white-noise power spectral density, (m/s²)²/Hz = m²/s³:
    /// VRW m/s/√h → m/s/√s is `/ 60`, squared.
    pub fn accel_noise_psd(&self) -> f64 {
        let vrw = self.vrw_mps_rthr / 60.0;
        vrw * vrw
    }

    /// `1/τ` of the bias Gauss–Markov processes, 1/s (0 without a correlation time).
    pub fn bias_decay(&self) -> f64 {
        self.bias_tau_s.map_or(0.0, |tau| 1.0 / tau)
    }

    /// The bias blocks of `Q_d` over `dt` (gyro, accelerometer; per axis): the bias random
    /// walk's `q dt` plus, with a correlation time, the Gauss–Markov driving noise
    /// `2σ²/τ · dt` that keeps the steady-state σ.
    pub fn bias_noise(&self, dt: f64) -> (f64, f64) {
        let walk_g = self.gyro_bias_walk_dph_rthr * DPH_TO_RPS / 60.0;
        let walk_a = self.accel_bias_walk_ug_rthr * MICRO_G / 60.0;
        let decay = self.bias_decay();
        let gm = |sigma: f64| 2.0 * sigma * sigma * decay;
        (
            (walk_g * walk_g + gm(self.gyro_bias_rps())) * dt,
            (walk_a * walk_a + gm(self.accel_bias_mps2())) * dt,
        )
    }
}

/// The continuous error dynamics F of docs/methods.md §M4 (see the module doc), linearised about `nav`.
pub fn error_dynamics(nav: &NavSolution) -> ErrorMatrix {
    let w_ie = geo::earth_rate_enu(nav.lla.lat);
    let w_en = geo::transport_rate_enu(nav.lla.lat, nav.lla.h, &nav.vel);
    let mut f = ErrorMatrix::zeros();
    // φ̇ = −ω_in × φ − C_bⁿ ε
    f.fixed_view_mut::<3, 3>(ATT, ATT)
        .copy_from(&-geo::skew(&(w_ie + w_en)));
    f.fixed_view_mut::<3, 3>(ATT, GYRO).copy_from(&-nav.c_bn);
    // δv̇ = fⁿ × φ − (2ω_ie + ω_en) × δv + C_bⁿ ∇
    f.fixed_view_mut::<3, 3>(VEL, ATT)
        .copy_from(&geo::skew(&nav.f_n));
    f.fixed_view_mut::<3, 3>(VEL, VEL)
        .copy_from(&-geo::skew(&(2.0 * w_ie + w_en)));
    f.fixed_view_mut::<3, 3>(VEL, ACC).copy_from(&nav.c_bn);
    // δṗ = δv
    f.fixed_view_mut::<3, 3>(POS, VEL)
        .copy_from(&Matrix3::identity());
    f
}

/// [`error_dynamics`] with the biases' Gauss–Markov decay of `imu`: `ε̇ = −ε/τ`, `∇̇ = −∇/τ`
/// (the same F when `imu` has no correlation time).
pub fn error_dynamics_imu(nav: &NavSolution, imu: &ImuErrors) -> ErrorMatrix {
    let mut f = error_dynamics(nav);
    let decay = imu.bias_decay();
    for i in GYRO..N {
        f[(i, i)] = -decay;
    }
    f
}

/// The noise input G: gyro white noise drives φ through `−C_bⁿ`, accelerometer white noise
/// drives δv through `C_bⁿ` (columns 0..3 gyro, 3..6 accelerometer).
pub fn noise_input(nav: &NavSolution) -> NoiseInput {
    let mut g = NoiseInput::zeros();
    g.fixed_view_mut::<3, 3>(ATT, 0).copy_from(&-nav.c_bn);
    g.fixed_view_mut::<3, 3>(VEL, 3).copy_from(&nav.c_bn);
    g
}

/// Discretises over `dt` seconds: `Φ = I + FΔt + (FΔt)²/2` and `Q_d = G Q Gᵀ Δt` with
/// `Q = diag(gyro PSD ×3, accelerometer PSD ×3)` (docs/methods.md §M4), plus the bias noise
/// of [`ImuErrors::bias_noise`] on the bias diagonal. `Q_d` is exactly symmetric.
pub fn discretize(
    f: &ErrorMatrix,
    g: &NoiseInput,
    imu: &ImuErrors,
    dt: f64,
) -> (ErrorMatrix, ErrorMatrix) {
    let fdt = f * dt;
    let phi = ErrorMatrix::identity() + fdt + fdt * fdt * 0.5;
    let q = SVector::<f64, 6>::from_fn(|i, _| {
        if i < 3 {
            imu.gyro_noise_psd()
        } else {
            imu.accel_noise_psd()
        }
    });
    // G Q Gᵀ with diagonal Q: scale G's columns by Q, then multiply by Gᵀ.
    let gq = SMatrix::<f64, N, 6>::from_fn(|r, c| g[(r, c)] * q[c] * dt);
    let qd = gq * g.transpose();
    let mut qd = (qd + qd.transpose()) * 0.5;
    let (qg, qa) = imu.bias_noise(dt);
    for i in 0..3 {
        qd[(GYRO + i, GYRO + i)] += qg;
        qd[(ACC + i, ACC + i)] += qa;
    }
    (phi, qd)
}

/// `Φ` and `Q_d` of [`discretize`] for `F = error_dynamics(nav)` and `G = noise_input(nav)`,
/// computed from F's 3 × 3 blocks instead of 15 × 15 products (the federated filter's hot
/// path). With `A = −[ω_in×]`, `V = −[(2ω_ie + ω_en)×]`, `B = [fⁿ×]`, `C = C_bⁿ`, the nonzero
/// blocks of F² are: `(φ,φ) A²`, `(φ,ε) −AC`, `(δv,φ) BA + VB`, `(δv,δv) V²`, `(δv,ε) −BC`,
/// `(δv,∇) VC`, `(δp,φ) B`, `(δp,δv) V`, `(δp,∇) C`; and `Q_d` has the blocks
/// `C diag(q_g) Cᵀ Δt` on φ and `C diag(q_a) Cᵀ Δt` on δv. Written into `phi` and `q`
/// (whatever they held): a 15 × 15 pair returned by value is copied on its way out, which
/// the federated step's 10 Hz path avoids.
#[inline]
pub fn transition_into(
    nav: &NavSolution,
    imu: &ImuErrors,
    dt: f64,
    phi: &mut ErrorMatrix,
    q: &mut ErrorMatrix,
) {
    let w_ie = geo::earth_rate_enu(nav.lla.lat);
    let w_en = geo::transport_rate_enu(nav.lla.lat, nav.lla.h, &nav.vel);
    let a = -geo::skew(&(w_ie + w_en));
    let v = -geo::skew(&(2.0 * w_ie + w_en));
    let b = geo::skew(&nav.f_n);
    let c = nav.c_bn;
    let decay = imu.bias_decay();
    let (h1, h2) = (dt, 0.5 * dt * dt);
    // Through the slice: nalgebra's `fill` walks its strided iterator, ~10 instructions
    // an entry.
    phi.as_mut_slice().fill(0.0);
    for i in 0..N {
        phi[(i, i)] = 1.0;
    }
    let mut put = |row: usize, col: usize, m: Matrix3<f64>| {
        let mut blk = phi.fixed_view_mut::<3, 3>(row, col);
        blk += m;
    };
    put(ATT, ATT, a * h1 + a * a * h2);
    put(VEL, ATT, b * h1 + (b * a + v * b) * h2);
    put(VEL, VEL, v * h1 + v * v * h2);
    put(VEL, GYRO, -(b * c) * h2);
    if decay == 0.0 {
        put(ATT, GYRO, -c * h1 - a * c * h2);
        put(VEL, ACC, c * h1 + v * c * h2);
    } else {
        // F's bias blocks −I/τ add `C/τ` terms to F²'s (φ,ε) and (δv,∇) blocks.
        put(ATT, GYRO, -c * h1 + (c * decay - a * c) * h2);
        put(VEL, ACC, c * h1 + (v * c - c * decay) * h2);
        let d = Matrix3::identity() * (-decay * h1 + decay * decay * h2);
        put(GYRO, GYRO, d);
        put(ACC, ACC, d);
    }
    put(POS, ATT, b * h2);
    put(POS, VEL, Matrix3::identity() * h1 + v * h2);
    put(POS, ACC, c * h2);
    q.as_mut_slice().fill(0.0);
    let block = |psd: f64| {
        let m = c * Matrix3::from_diagonal_element(psd * dt) * c.transpose();
        (m + m.transpose()) * 0.5
    };
    q.fixed_view_mut::<3, 3>(ATT, ATT)
        .copy_from(&block(imu.gyro_noise_psd()));
    q.fixed_view_mut::<3, 3>(VEL, VEL)
        .copy_from(&block(imu.accel_noise_psd()));
    let (qg, qa) = imu.bias_noise(dt);
    for i in 0..3 {
        q[(GYRO + i, GYRO + i)] = qg;
        q[(ACC + i, ACC + i)] = qa;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn ship_at_30n() -> NavSolution {
        NavSolution::from_ins(&InsBlock {
            lat: 30f64.to_radians(),
            lon: 120f64.to_radians(),
            h: 0.0,
            vel: [5.0, 8.0, 0.0],
            att: [0.01, -0.02, 0.5],
            f_b: None,
        })
    }

    #[test]
    fn default_imu_errors_convert_to_si_units() {
        let imu = ImuErrors::default();
        assert_relative_eq!(
            imu.gyro_bias_rps(),
            0.002 * std::f64::consts::PI / 180.0 / 3600.0,
            max_relative = 1e-15
        );
        assert_relative_eq!(imu.accel_bias_mps2(), 9.806_65e-5, max_relative = 1e-15);
        // 0.001 °/√h = 1.745e-5 rad / 60 √s = 2.909e-7 rad/√s.
        assert_relative_eq!(
            imu.gyro_noise_psd().sqrt(),
            2.908_882_086_657_216e-7,
            max_relative = 1e-12
        );
        assert_relative_eq!(imu.accel_noise_psd().sqrt(), 0.001 / 60.0);
    }

    #[test]
    fn missing_specific_force_means_gravity_straight_up() {
        let nav = ship_at_30n();
        assert_eq!(nav.f_n.x, 0.0);
        assert_eq!(nav.f_n.y, 0.0);
        assert_relative_eq!(nav.f_n.z, geo::normal_gravity(nav.lla.lat, 0.0));
    }

    #[test]
    fn specific_force_error_from_misalignment_matches_the_perturbed_dcm() {
        // δf = C̃ f_b − C f_b with C̃ = (I − [φ×]) C must equal F's block fⁿ × φ.
        let ins = InsBlock {
            lat: 0.5,
            lon: 2.0,
            h: 10.0,
            vel: [1.0, 2.0, 0.1],
            att: [0.1, 0.2, 1.0],
            f_b: Some([0.3, -0.4, 9.8]),
        };
        let nav = NavSolution::from_ins(&ins);
        let phi = Vector3::new(1e-6, -2e-6, 3e-6);
        let c_tilde = (Matrix3::identity() - geo::skew(&phi)) * nav.c_bn;
        let f_b = Vector3::from(ins.f_b.unwrap_or_default());
        let df = c_tilde * f_b - nav.c_bn * f_b;
        let f = error_dynamics(&nav);
        let mut x = ErrorVector::zeros();
        x.fixed_rows_mut::<3>(ATT).copy_from(&phi);
        let dv_dot = (f * x).fixed_rows::<3>(VEL).into_owned();
        // Exact in φ (C̃ is linear in φ); the tolerance covers the cancellation in C̃ f − C f.
        assert_relative_eq!(dv_dot, df, max_relative = 1e-9);
    }

    #[test]
    fn dynamics_blocks_are_the_design_model() {
        let nav = ship_at_30n();
        let f = error_dynamics(&nav);
        let w_ie = geo::earth_rate_enu(nav.lla.lat);
        let w_en = geo::transport_rate_enu(nav.lla.lat, nav.lla.h, &nav.vel);
        let w_in = w_ie + w_en;
        // −ω_in × φ: the (0, 1) entry of −[ω×] is +ω_z.
        assert_relative_eq!(f[(ATT, ATT + 1)], w_in.z, max_relative = 1e-15);
        assert_relative_eq!(f[(ATT + 1, ATT)], -w_in.z, max_relative = 1e-15);
        for i in 0..3 {
            for j in 0..3 {
                assert_eq!(f[(ATT + i, GYRO + j)], -nav.c_bn[(i, j)]);
                assert_eq!(f[(VEL + i, ACC + j)], nav.c_bn[(i, j)]);
                assert_eq!(f[(POS + i, VEL + j)], if i == j { 1.0 } else { 0.0 });
            }
        }
        // Biases are random constants: their rows are zero.
        assert!(f.rows(GYRO, 6).iter().all(|&v| v == 0.0));
    }

    #[test]
    fn block_transition_equals_the_full_discretisation() {
        let ins = InsBlock {
            lat: -0.7,
            lon: 2.0,
            h: 150.0,
            vel: [12.0, -7.0, 0.5],
            att: [0.05, -0.1, 4.0],
            f_b: Some([0.4, 1.5, 9.7]),
        };
        let nav = NavSolution::from_ins(&ins);
        let imu = ImuErrors::default();
        for dt in [0.0, 0.01, 0.1, 1.0] {
            let (phi, q) = discretize(&error_dynamics(&nav), &noise_input(&nav), &imu, dt);
            // Whatever the buffers held is overwritten.
            let (mut phi_b, mut q_b) = (ErrorMatrix::repeat(7.0), ErrorMatrix::repeat(7.0));
            transition_into(&nav, &imu, dt, &mut phi_b, &mut q_b);
            assert_relative_eq!(phi_b, phi, epsilon = 1e-15, max_relative = 1e-13);
            // Off-diagonal entries are rounding-level (C Cᵀ = I): compare on Q's scale.
            assert_relative_eq!(q_b, q, epsilon = 1e-13 * q.amax(), max_relative = 1e-13);
            assert_eq!(q_b, q_b.transpose());
        }
    }

    #[test]
    fn gauss_markov_biases_decay_and_keep_their_steady_state() {
        let ins = InsBlock {
            lat: 0.7,
            lon: -1.8,
            h: 1600.0,
            vel: [3.0, 4.0, 0.0],
            att: [0.02, -0.01, 1.0],
            f_b: Some([0.5, 1.0, 9.8]),
        };
        let nav = NavSolution::from_ins(&ins);
        let imu = ImuErrors {
            gyro_bias_dph: 10.0,
            accel_bias_ug: 500.0,
            bias_tau_s: Some(300.0),
            gyro_bias_walk_dph_rthr: 0.5,
            accel_bias_walk_ug_rthr: 60.0,
            ..ImuErrors::default()
        };
        for dt in [0.01, 0.1, 1.0] {
            let f = error_dynamics_imu(&nav, &imu);
            let (phi, q) = discretize(&f, &noise_input(&nav), &imu, dt);
            let (mut phi_b, mut q_b) = (ErrorMatrix::repeat(7.0), ErrorMatrix::repeat(7.0));
            transition_into(&nav, &imu, dt, &mut phi_b, &mut q_b);
            assert_relative_eq!(phi_b, phi, epsilon = 1e-15, max_relative = 1e-13);
            assert_relative_eq!(q_b, q, epsilon = 1e-13 * q.amax(), max_relative = 1e-13);
            // The bias diagonal is the series of exp(−dt/τ).
            let x = dt / 300.0;
            assert_relative_eq!(
                phi[(GYRO, GYRO)],
                1.0 - x + x * x / 2.0,
                max_relative = 1e-15
            );
        }
        // Without the walk, the Gauss–Markov noise holds the steady state:
        // σ² = Φ² σ² + q  ⇔  q = σ² (1 − Φ²) ≈ 2σ² dt/τ to first order.
        let gm = ImuErrors {
            gyro_bias_walk_dph_rthr: 0.0,
            accel_bias_walk_ug_rthr: 0.0,
            ..imu
        };
        let (qg, qa) = gm.bias_noise(0.01);
        let s2 = gm.gyro_bias_rps().powi(2);
        assert_relative_eq!(
            qg,
            s2 * (1.0 - (-0.02f64 / 300.0).exp()),
            max_relative = 1e-4
        );
        let s2 = gm.accel_bias_mps2().powi(2);
        assert_relative_eq!(
            qa,
            s2 * (1.0 - (-0.02f64 / 300.0).exp()),
            max_relative = 1e-4
        );
        // A walk alone: 60 µg/√h → (60e-6 g / 60)² per second.
        let walk = ImuErrors {
            bias_tau_s: None,
            ..imu
        };
        let (_, qa) = walk.bias_noise(1.0);
        assert_relative_eq!(qa, (60.0 * MICRO_G / 60.0).powi(2), max_relative = 1e-12);
    }

    #[test]
    fn discretisation_is_the_second_order_series_and_integrates_noise() {
        let nav = ship_at_30n();
        let f = error_dynamics(&nav);
        let g = noise_input(&nav);
        let imu = ImuErrors::default();
        let dt = 0.1;
        let (phi, qd) = discretize(&f, &g, &imu, dt);
        assert_relative_eq!(
            phi,
            ErrorMatrix::identity() + f * dt + f * f * (dt * dt / 2.0)
        );
        // An accelerometer bias of 1 m/s² along body x shows in position after dt as ≈ dt²/2.
        let mut x = ErrorVector::zeros();
        x[ACC] = 1.0;
        let dp = (phi * x).fixed_rows::<3>(POS).into_owned();
        assert_relative_eq!(dp, nav.c_bn.column(0) * dt * dt / 2.0, epsilon = 1e-12);
        // C_bⁿ is orthogonal, so the velocity block of Q_d is PSD·dt·I and likewise φ.
        assert_relative_eq!(
            qd.fixed_view::<3, 3>(VEL, VEL).into_owned(),
            Matrix3::identity() * imu.accel_noise_psd() * dt,
            max_relative = 1e-12
        );
        assert_relative_eq!(
            qd.fixed_view::<3, 3>(ATT, ATT).into_owned(),
            Matrix3::identity() * imu.gyro_noise_psd() * dt,
            max_relative = 1e-12
        );
        assert_eq!(qd, qd.transpose());
        assert!(qd.fixed_view::<3, 3>(ATT, VEL).iter().all(|&v| v == 0.0));
    }
}
