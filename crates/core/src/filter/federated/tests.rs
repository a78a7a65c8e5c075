//! Tests of the federated filter: the fast kernels against the generic Kalman filter,
//! fusion against the information form, and the filter's behaviour under faults.

use super::solver::{
    bias_columns_zero, diagonal, fused_slope_body, inverse_cholesky_factor, joseph_update_body,
    kalman_update, predict_into_body, product, share_test_body,
};
use super::*;
use crate::detect::{Health, PolicyConfig, PolicyState};
use crate::epoch::InsBlock;
use crate::filter::aiding;
use crate::filter::ins::{ACC, ATT, GYRO, VEL};
use crate::filter::ins::{ErrorMatrix, ErrorVector, N, POS};
use crate::filter::kalman::{self, LinearObservation};
use crate::geo::Lla;
use nalgebra::SMatrix;
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
                    let test = share_test(&slow, 0.25, m).unwrap();
                    let lambda = test.statistic;
                    let innov =
                        kalman::innovation(&scaled(&slow, 0.25), &m.obs, &m.z).unwrap();
                    assert!((lambda - innov.statistic).abs() <= 1e-12 * innov.statistic);
                    // ν = L⁻¹ r with the generic filter's Cholesky factor of S.
                    let nu = innov.s_chol.l().solve_lower_triangular(&innov.r).unwrap();
                    for (i, v) in nu.iter().enumerate() {
                        assert!((test.nu[i] - v).abs() <= 1e-10 * (1.0 + v.abs()), "ν[{i}]");
                    }
                    assert!(test.nu.iter().skip(nu.len()).all(|&v| v == 0.0));
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

#[test]
fn aid_updates_one_component_at_a_time_equal_the_block_update_and_stay_symmetric() {
    // Every aid's R is diagonal and its H has zero bias columns, so `joseph_update` takes
    // the sequential path; the generic filter's update takes all M components at once.
    // Both must agree to rounding, at the INS state's scales, over many epochs, and
    // the sequential P must be exactly symmetric.
    let mut rng = StdRng::seed_from_u64(31);
    let nav = ship();
    let trans = ins_transition(&nav, &ImuErrors::default(), 0.1).unwrap();
    let mut est = initial(seed004_p0());
    for epoch in 0..200 {
        let mut prior = est.clone();
        predict_into(&est, &trans, &mut prior).unwrap();
        let truth =
            ErrorVector::from_fn(|i, _| 1e-3 * (rng.random::<f64>() - 0.5) * (i + 1) as f64);
        for o in aid_observations(&nav, &truth, Some(&mut rng))
            .iter()
            .flatten()
        {
            with_measurement!(o, m => {
                assert!(bias_columns_zero(&m.obs.h));
                assert!(diagonal(&m.obs.r));
                let mut sequential = prior.clone();
                joseph_update(&mut sequential, m).unwrap();
                let block = kalman_update(&prior, m).unwrap();
                assert_cov_close(&sequential.p, &block.p, 1e-10);
                assert_state_close(&sequential.x, &block.x, &block.p, 1e-10);
                assert_eq!(sequential.p, sequential.p.transpose(), "epoch {epoch}");
                prior = sequential;
            });
        }
        est = prior;
    }
}

#[test]
fn the_inlined_products_equal_nalgebras_to_the_bit() {
    // Same operations in the same order as nalgebra's `*` (also inside `a1 * b1 + a2 * b2`), so
    // every bit agrees, signed zeros included.
    fn same<const R: usize, const C: usize>(a: &SMatrix<f64, R, C>, b: &SMatrix<f64, R, C>) {
        let bits = |m: &SMatrix<f64, R, C>| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(a), bits(b));
    }
    let mut rng = StdRng::seed_from_u64(22);
    let mut u = || {
        let v: f64 = rng.sample(StandardNormal);
        // Some exact zeros and negative zeros, as Φ and H have.
        match (v.abs() * 10.0) as u32 % 7 {
            0 => 0.0,
            1 => -0.0,
            _ => v * 10f64.powi((v * 3.0) as i32),
        }
    };
    for _ in 0..50 {
        let p = ErrorMatrix::from_fn(|_, _| u());
        let phi = ErrorMatrix::from_fn(|_, _| u());
        let (a, b) = (phi.fixed_view::<9, 9>(0, 0), phi.fixed_view::<9, 6>(0, 9));
        let m1 =
            product(&a, &p.fixed_view::<9, 9>(0, 0)) + product(&b, &p.fixed_view::<6, 9>(9, 0));
        same(
            &m1,
            &(a * p.fixed_view::<9, 9>(0, 0) + b * p.fixed_view::<6, 9>(9, 0)),
        );
        let m2 = SMatrix::<f64, 9, 6>::from_fn(|_, _| u());
        same(
            &(product(&m1, &a.transpose()) + product(&m2, &b.transpose())),
            &(m1 * a.transpose() + m2 * b.transpose()),
        );
        let x = ErrorVector::from_fn(|_, _| u());
        same(&product(&phi, &x), &(phi * x));
        let kt = SMatrix::<f64, 6, 15>::from_fn(|_, _| u());
        let s = SMatrix::<f64, 6, 6>::from_fn(|_, _| u());
        same(&product(&s, &kt), &(s * kt));
        same(&product(&kt.transpose(), &kt), &(kt.transpose() * kt));
    }
}

#[test]
fn the_dispatched_kernels_equal_the_baseline_build_to_the_bit() {
    // `predict_into`, `share_test`, `joseph_update` and `fused_slope` run their AVX2 builds
    // on a CPU with AVX2; the `_body` functions called from here are the baseline build
    // (this test function has no target features). Same operations in the same order, so
    // the results must be identical, not merely close. On a CPU without AVX2 both sides
    // are the baseline and the test holds trivially.
    let mut rng = StdRng::seed_from_u64(21);
    let nav = ship();
    for k in 0..30 {
        // Dense Φ and H take the generic paths; the INS Φ and the aids' H the structured ones.
        let (dense, dense_obs) = synthetic(&mut rng);
        let dt = [0.1, 1.0, 2.5][k % 3];
        let ins = ins_transition(&nav, &ImuErrors::default(), dt).unwrap();
        let a = ErrorMatrix::from_fn(|_, _| rng.random::<f64>() - 0.5);
        let scales = ErrorVector::from_fn(|i, _| [30.0, 0.3, 1e-3, 1e-4, 1e-6][i / 3]);
        let est = StateEstimate {
            x: ErrorVector::from_fn(|i, _| scales[i] * (rng.random::<f64>() - 0.5)),
            p: ErrorMatrix::from_fn(|i, j| scales[i] * scales[j])
                .component_mul(&(a * a.transpose() + ErrorMatrix::identity())),
        };
        for trans in [&dense, &ins] {
            let (mut fast, mut base) = (est.clone(), est.clone());
            predict_into(&est, trans, &mut fast).unwrap();
            predict_into_body(&est, trans, &mut base).unwrap();
            assert_eq!(fast, base, "prediction, step {k}");
        }
        let mut prior = est.clone();
        predict_into_body(&est, &ins, &mut prior).unwrap();
        let truth = ErrorVector::from_fn(|i, _| scales[i] * (rng.random::<f64>() - 0.5));
        let aids = aid_observations(&nav, &truth, Some(&mut rng));
        for o in aids.iter().chain(dense_obs.iter()).flatten() {
            with_measurement!(o, m => {
                let fast = share_test(&prior, 0.3, m).unwrap();
                let base = share_test_body(&prior, 0.3, m).unwrap();
                assert_eq!(fast.statistic.to_bits(), base.statistic.to_bits());
                assert_eq!((fast.s_inv, fast.nu), (base.s_inv, base.nu));
                let s_inv = SVector::<f64, 6>::from_fn(|i, _| 1.0 + i as f64);
                let fast = fused_slope(&prior.p, m, &s_inv).unwrap();
                let base = fused_slope_body(&prior.p, m, &s_inv).unwrap();
                assert_eq!(fast.to_bits(), base.to_bits());
                let (mut fast, mut base) = (prior.clone(), prior.clone());
                joseph_update(&mut fast, m).unwrap();
                joseph_update_body(&mut base, m).unwrap();
                assert_eq!(fast, base, "Joseph update, step {k}");
                prior = base;
            });
        }
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
fn innovation_cov<const M: usize>(prior: &ErrorEstimate, m: &AidMeasurement<M>) -> DMatrix<f64> {
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

#[test]
fn the_structured_prediction_takes_any_navigation_rows_and_skips_only_zeros() {
    // Φ with the INS bias rows [0 I] but navigation rows of random values, a random third of
    // them zero (not the INS zero blocks): the structured path must equal the generic
    // prediction, skip nothing that is non-zero and keep P exactly symmetric.
    let mut rng = StdRng::seed_from_u64(41);
    for _ in 0..50 {
        let mut f = ErrorMatrix::identity();
        for i in 0..9 {
            for j in 0..N {
                f[(i, j)] = if rng.random::<f64>() < 1.0 / 3.0 {
                    0.0
                } else {
                    rng.random::<f64>() - 0.5
                };
            }
        }
        let g = ErrorMatrix::from_fn(|_, _| rng.random::<f64>() - 0.5);
        let trans = LinearTransition {
            f,
            q: g * g.transpose(),
        };
        let a = ErrorMatrix::from_fn(|_, _| rng.random::<f64>() - 0.5);
        let est = StateEstimate {
            x: ErrorVector::from_fn(|_, _| rng.random::<f64>() - 0.5),
            p: a * a.transpose() + ErrorMatrix::identity(),
        };
        let mut fast = est.clone();
        predict_into_body(&est, &trans, &mut fast).unwrap();
        let slow = kalman::predict(&est, &trans).unwrap();
        assert_cov_close(&fast.p, &slow.p, 1e-13);
        assert_eq!(fast.p, fast.p.transpose());
        for i in 0..N {
            assert!((fast.x[i] - slow.x[i]).abs() <= 1e-14 * (1.0 + slow.x[i].abs()));
        }
    }
}
