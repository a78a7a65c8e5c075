//! Aiding measurement models (docs/methods.md §M5, seed 004 §1.2): each turns one aid's fix and
//! the INS solution of the same epoch into a fixed-size INS-minus-aid measurement
//! `(z, H, R)` over the 15 error states of [`crate::filter::ins`], which the federated
//! filter hands to the generic Kalman filter.
//!
//! - GNSS position (3, seed 004 eq. 3): `z = [Δλ (R_N+h) cos L, ΔL (R_M+h), Δh]` metres ENU
//!   (`geo::local_offset(ins, gnss)`), `H = [0 0 I 0 0]`;
//! - GNSS velocity (3): `z = v_ins − v_gnss`, `H = [0 I 0 0 0]`;
//! - GNSS velocity and position (6, seed 004 eq. 3's order `[δV; δP]`);
//! - DVL (3, seed 004 eq. 4): `z = v_ins − C̃_bⁿ v_dvl_b`, `H = [−[vⁿ×] I 0 0 0]`, because
//!   `C̃_bⁿ v_b = (I − [φ×]) vⁿ = vⁿ + [vⁿ×] φ` and `v_ins = vⁿ + δv`;
//! - CNS (2, seed 004 eq. 5): `z = [Δλ (R_N+h) cos L, ΔL (R_M+h)]` east and north metres,
//!   `H` picks `δp_e, δp_n`.
//!
//! `R` is diagonal, `σ²` per component (white noise, as the seed models every aid).

use nalgebra::{Const, SMatrix, SVector, Vector3};

use super::ins::{ATT, N, NavSolution, POS, VEL};
use super::kalman::LinearObservation;
use crate::geo::{self, Lla};

/// One aid measurement of dimension `M`: `z` (INS minus aid) and its observation model.
#[derive(Debug, Clone, PartialEq)]
pub struct AidMeasurement<const M: usize> {
    /// INS minus aid, SI units (metres ENU for positions, m/s for velocities).
    pub z: SVector<f64, M>,
    /// `H` (M × 15) and `R` (M × M).
    pub obs: LinearObservation<Const<N>, Const<M>>,
}

impl<const M: usize> AidMeasurement<M> {
    /// `z = H x` for an error state `x`: the measurement a noise-free aid would give.
    pub fn predicted(&self, x: &SVector<f64, N>) -> SVector<f64, M> {
        self.obs.h * x
    }

    /// Replaces the 1-σ of components `from..from + sigmas.len()` (R stays diagonal): the
    /// σ an aid reports with its fix instead of the configured one.
    pub fn set_sigmas(&mut self, from: usize, sigmas: &[f64]) {
        for (k, s) in sigmas.iter().enumerate() {
            self.obs.r[(from + k, from + k)] = s * s;
        }
    }
}

/// `R = σ² I` of dimension `M`.
fn diagonal_r<const M: usize>(sigma: f64) -> SMatrix<f64, M, M> {
    SMatrix::<f64, M, M>::from_diagonal_element(sigma * sigma)
}

/// An `M × 15` matrix with identity blocks `I₃` placed at `(row, col)` pairs.
fn selector<const M: usize>(blocks: &[(usize, usize, usize)]) -> SMatrix<f64, M, N> {
    let mut h = SMatrix::<f64, M, N>::zeros();
    for &(row, col, len) in blocks {
        for i in 0..len {
            h[(row + i, col + i)] = 1.0;
        }
    }
    h
}

/// GNSS position: `z = local_offset(ins, gnss)` (metres ENU at the fix), `H = [0 0 I 0 0]`,
/// `R = σ² I₃`.
pub fn gnss_position(nav: &NavSolution, fix: &Lla, pos_sigma_m: f64) -> AidMeasurement<3> {
    AidMeasurement {
        z: geo::local_offset(&nav.lla, fix),
        obs: LinearObservation {
            h: selector::<3>(&[(0, POS, 3)]),
            r: diagonal_r::<3>(pos_sigma_m),
        },
    }
}

/// GNSS velocity: `z = v_ins − v_gnss`, `H = [0 I 0 0 0]`, `R = σ² I₃`.
pub fn gnss_velocity(
    nav: &NavSolution,
    vel: &Vector3<f64>,
    vel_sigma_mps: f64,
) -> AidMeasurement<3> {
    AidMeasurement {
        z: nav.vel - vel,
        obs: LinearObservation {
            h: selector::<3>(&[(0, VEL, 3)]),
            r: diagonal_r::<3>(vel_sigma_mps),
        },
    }
}

/// GNSS velocity and position stacked as seed 004 eq. 3: `z = [v_ins − v_gnss; δP]`,
/// `H = [[0 I 0 0 0]; [0 0 I 0 0]]`, `R = diag(σ_v² I₃, σ_p² I₃)`.
pub fn gnss_velocity_position(
    nav: &NavSolution,
    fix: &Lla,
    vel: &Vector3<f64>,
    pos_sigma_m: f64,
    vel_sigma_mps: f64,
) -> AidMeasurement<6> {
    let mut z = SVector::<f64, 6>::zeros();
    z.fixed_rows_mut::<3>(0).copy_from(&(nav.vel - vel));
    z.fixed_rows_mut::<3>(3)
        .copy_from(&geo::local_offset(&nav.lla, fix));
    let (sv, sp) = (vel_sigma_mps * vel_sigma_mps, pos_sigma_m * pos_sigma_m);
    AidMeasurement {
        z,
        obs: LinearObservation {
            h: selector::<6>(&[(0, VEL, 3), (3, POS, 3)]),
            r: SMatrix::<f64, 6, 6>::from_diagonal(&SVector::from([sv, sv, sv, sp, sp, sp])),
        },
    }
}

/// DVL: `z = v_ins − C̃_bⁿ v_dvl_b` with the INS attitude, `H = [−[vⁿ×] I 0 0 0]` with the INS
/// velocity, `R = σ² I₃`.
pub fn dvl_velocity(
    nav: &NavSolution,
    vel_b: &Vector3<f64>,
    vel_sigma_mps: f64,
) -> AidMeasurement<3> {
    let mut h = selector::<3>(&[(0, VEL, 3)]);
    h.fixed_view_mut::<3, 3>(0, ATT)
        .copy_from(&-geo::skew(&nav.vel));
    AidMeasurement {
        z: nav.vel - nav.c_bn * vel_b,
        obs: LinearObservation {
            h,
            r: diagonal_r::<3>(vel_sigma_mps),
        },
    }
}

/// CNS: `z` = east and north of `local_offset(ins, cns)` (the fix has no height; the INS
/// height is used so Δh plays no part), `H` picks `δp_e, δp_n`, `R = σ² I₂`.
pub fn cns_position(nav: &NavSolution, lat: f64, lon: f64, pos_sigma_m: f64) -> AidMeasurement<2> {
    let fix = Lla {
        lat,
        lon,
        h: nav.lla.h,
    };
    let d = geo::local_offset(&nav.lla, &fix);
    AidMeasurement {
        z: SVector::<f64, 2>::new(d.x, d.y),
        obs: LinearObservation {
            h: selector::<2>(&[(0, POS, 2)]),
            r: diagonal_r::<2>(pos_sigma_m),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::ins::ErrorVector;
    use approx::assert_relative_eq;
    use nalgebra::{Matrix3, Rotation3};

    /// The true state the INS errors are applied to.
    struct Truth {
        lla: Lla,
        vel: Vector3<f64>,
        c_bn: Matrix3<f64>,
    }

    fn truth() -> Truth {
        Truth {
            lla: Lla {
                lat: 30f64.to_radians(),
                lon: 122f64.to_radians(),
                h: 12.0,
            },
            vel: Vector3::new(6.0, -9.0, 0.3),
            c_bn: geo::dcm_body_to_nav(0.02, -0.03, 2.4),
        }
    }

    /// The INS solution that is `x` away from the truth: `δp` in local metres, `δv` added, and
    /// `C̃ = exp(−[φ×]) C` (orthogonal; equal to `(I − [φ×]) C` to first order).
    fn ins_with_error(t: &Truth, x: &ErrorVector) -> NavSolution {
        let dp = x.fixed_rows::<3>(POS).into_owned();
        let dv = x.fixed_rows::<3>(VEL).into_owned();
        let phi = x.fixed_rows::<3>(ATT).into_owned();
        let rot = Rotation3::new(-phi).into_inner();
        NavSolution {
            lla: geo::apply_offset(&t.lla, &dp),
            vel: t.vel + dv,
            c_bn: rot * t.c_bn,
            f_n: Vector3::new(0.0, 0.0, 9.79),
        }
    }

    /// Central differences of `z(x)` about the nominal solution, column by column, against `H`.
    fn check_jacobian<const M: usize>(z_of: impl Fn(&NavSolution) -> AidMeasurement<M>) {
        let t = truth();
        let nominal = z_of(&ins_with_error(&t, &ErrorVector::zeros()));
        let h = nominal.obs.h;
        // Step per state: 10 m (z is exactly linear in δp, and a smaller step would lose digits
        // to the rounding of longitude ≈ 2 rad), 1e-4 m/s, 1e-6 rad; biases do not enter z.
        let step = |j: usize| match j {
            POS..=8 => 10.0,
            VEL..=5 => 1e-4,
            _ => 1e-6,
        };
        let scale = h.abs().max().max(1.0);
        for j in 0..N {
            let mut x = ErrorVector::zeros();
            x[j] = step(j);
            let zp = z_of(&ins_with_error(&t, &x)).z;
            let zm = z_of(&ins_with_error(&t, &(-x))).z;
            let numeric = (zp - zm) / (2.0 * step(j));
            for i in 0..M {
                assert!(
                    (numeric[i] - h[(i, j)]).abs() <= 1e-6 * scale,
                    "H[({i}, {j})] = {} but the finite difference gives {}",
                    h[(i, j)],
                    numeric[i]
                );
            }
        }
        // The nominal measurement is zero: a noise-free aid agrees with an error-free INS.
        assert!(nominal.z.norm() < 1e-9, "z = {}", nominal.z);
    }

    #[test]
    fn gnss_position_jacobian_matches_finite_differences() {
        let t = truth();
        check_jacobian(|nav| gnss_position(nav, &t.lla, 10.0));
    }

    #[test]
    fn gnss_velocity_jacobian_matches_finite_differences() {
        let t = truth();
        check_jacobian(|nav| gnss_velocity(nav, &t.vel, 0.1));
    }

    #[test]
    fn stacked_gnss_jacobian_matches_finite_differences() {
        let t = truth();
        check_jacobian(|nav| gnss_velocity_position(nav, &t.lla, &t.vel, 10.0, 0.1));
    }

    #[test]
    fn dvl_jacobian_matches_finite_differences() {
        let t = truth();
        let vel_b = t.c_bn.transpose() * t.vel;
        check_jacobian(|nav| dvl_velocity(nav, &vel_b, 0.1));
    }

    #[test]
    fn cns_jacobian_matches_finite_differences() {
        let t = truth();
        check_jacobian(|nav| cns_position(nav, t.lla.lat, t.lla.lon, 450.0));
    }

    #[test]
    fn gnss_position_is_metres_east_north_up_and_noise_is_sigma_squared() {
        // 1e-5 rad of latitude is ≈ 63.5 m of northing at 30° N (R_M ≈ 6.351e6 m).
        let t = truth();
        let nav = ins_with_error(&t, &ErrorVector::zeros());
        let mut fix = t.lla;
        fix.lat -= 1e-5;
        fix.h -= 2.0;
        let m = gnss_position(&nav, &fix, 10.0);
        let rm = geo::radii(fix.lat).meridian;
        // ΔL = 1e-5 is rounded to ~1e-16/1e-5 relative.
        assert_relative_eq!(m.z[1], 1e-5 * (rm + fix.h), max_relative = 1e-10);
        assert_relative_eq!(m.z[2], 2.0, max_relative = 1e-12);
        assert_eq!(m.z[0], 0.0);
        assert_eq!(m.obs.r, Matrix3::identity() * 100.0);
        let stacked = gnss_velocity_position(&nav, &fix, &t.vel, 10.0, 0.1);
        assert_relative_eq!(stacked.obs.r[(0, 0)], 0.01, max_relative = 1e-15);
        assert_eq!(stacked.obs.r[(5, 5)], 100.0);
        assert_eq!(stacked.z.fixed_rows::<3>(3).into_owned(), m.z);
    }
}
