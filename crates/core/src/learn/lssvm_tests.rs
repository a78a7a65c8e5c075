//! Unit tests of the batch LS-SVM (`lssvm.rs`), kept beside it to keep that file short.

use super::*;
use crate::learn::cv::make_folds;
use crate::learn::{AnyModel, ModelKind, ModelParams};
use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng, rngs::StdRng};

/// `n` samples of `y = sin(2x₀) + 0.5x₁ + noise`, `x` uniform in `[−2, 2]²`.
fn sample(n: usize, noise: f64, seed: u64) -> (Vec<Vec<f64>>, Vec<f64>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let x: Vec<Vec<f64>> = (0..n)
        .map(|_| vec![rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0)])
        .collect();
    let y = x
        .iter()
        .map(|r| (2.0 * r[0]).sin() + 0.5 * r[1] + noise * (rng.random::<f64>() - 0.5))
        .collect();
    (x, y)
}

/// Solves seed 000 eq. 6 `[[0, 1ᵀ], [1, Ω + I/γ]] [b; α] = [0; y]` as one dense
/// (n+1)×(n+1) system by LU: an independent path to the same solution.
fn dense_lu(x: &[Vec<f64>], y: &[f64], kernel: Kernel, gamma: f64) -> (Vec<f64>, f64) {
    let n = x.len();
    let a = DMatrix::from_fn(n + 1, n + 1, |i, j| match (i, j) {
        (0, 0) => 0.0,
        (0, _) | (_, 0) => 1.0,
        _ => kernel.eval(&x[i - 1], &x[j - 1]) + if i == j { 1.0 / gamma } else { 0.0 },
    });
    let rhs = DVector::from_iterator(n + 1, std::iter::once(0.0).chain(y.iter().copied()));
    let s = a.lu().solve(&rhs).unwrap();
    (s.iter().skip(1).copied().collect(), s[0])
}

fn raw(gamma: f64, sigma2: f64) -> LsSvmParams {
    LsSvmParams {
        standardize: false,
        ..LsSvmParams::new(gamma, sigma2)
    }
}

#[test]
fn batch_solution_equals_a_dense_lu_solve_of_the_bordered_system() {
    // 150 samples: the blocked Cholesky crosses two block boundaries.
    let (x, y) = sample(150, 0.1, 1);
    let data = Dataset::new(&x, Some(&y)).unwrap();
    for (gamma, sigma2) in [(10.0, 0.5), (1000.0, 2.0)] {
        let m = raw(gamma, sigma2).fit(&data).unwrap();
        let (alpha, b) = dense_lu(&x, &y, Kernel::Rbf { sigma2 }, gamma);
        assert!((m.bias() - b).abs() < 1e-10, "b {} vs {b}", m.bias());
        for (u, v) in m.alpha().iter().zip(&alpha) {
            assert!((u - v).abs() < 1e-10 * (1.0 + v.abs()), "α {u} vs {v}");
        }
    }
}

#[test]
fn linear_kernel_recovers_a_plane_in_original_units() {
    // y = 3x₀ − 2x₁ + 7: with a large γ the linear LS-SVM is nearly least squares.
    let x: Vec<Vec<f64>> = (0..40)
        .map(|i| vec![i as f64 * 0.3, (i as f64 * 0.7).cos() * 5.0])
        .collect();
    let y: Vec<f64> = x.iter().map(|r| 3.0 * r[0] - 2.0 * r[1] + 7.0).collect();
    let params = LsSvmParams {
        kernel: KernelKind::Linear,
        gamma: Hyper::Value(1e8),
        ..LsSvmParams::default()
    };
    let m = params.fit(&Dataset::new(&x, Some(&y)).unwrap()).unwrap();
    assert!((m.predict_one(&[10.0, 1.0]) - 35.0).abs() < 1e-4);
}

#[test]
fn standardisation_round_trips_to_original_units() {
    // A model on standardised data equals a raw model on the standardised set, mapped
    // back with the training mean and std.
    let (x, mut y) = sample(60, 0.1, 2);
    let x: Vec<Vec<f64>> = x
        .iter()
        .map(|r| vec![100.0 + 30.0 * r[0], -5.0 + 0.01 * r[1]])
        .collect();
    y.iter_mut().for_each(|v| *v = 1000.0 + 50.0 * *v);
    let m = LsSvmParams::new(20.0, 1.5)
        .fit(&Dataset::new(&x, Some(&y)).unwrap())
        .unwrap();
    let xs = Standardizer::fit(x.iter().map(|r| r.as_slice()));
    let ys = Standardizer::fit(y.chunks_exact(1));
    let zx: Vec<Vec<f64>> = x.iter().map(|r| xs.applied(r)).collect();
    let zy: Vec<f64> = y.iter().map(|v| (v - ys.mean[0]) / ys.std[0]).collect();
    let r = raw(20.0, 1.5)
        .fit(&Dataset::new(&zx, Some(&zy)).unwrap())
        .unwrap();
    for q in [[110.0, -5.0], [70.0, -4.99], [150.0, -5.02]] {
        let expected = ys.invert(0, r.predict_one(&xs.applied(&q)));
        assert!((m.predict_one(&q) - expected).abs() < 1e-9);
    }
    // And the fit is good in original units.
    let t = train(
        &LsSvmParams::new(20.0, 1.5),
        None,
        &Dataset::new(&x, Some(&y)).unwrap(),
        &NoProgress,
    )
    .unwrap();
    assert!(
        t.metrics.train_rmse.unwrap() < 5.0,
        "{:?}",
        t.metrics.train_rmse
    );
}

#[test]
fn bad_params_are_refused_naming_the_field() {
    let field = |v: serde_json::Value| match ModelParams::from_json(ModelKind::LsSvm, &v) {
        Err(LearnError::InvalidParams { field, .. }) => field,
        other => panic!("{other:?}"),
    };
    // An error names the spelling the body used.
    assert_eq!(field(serde_json::json!({"gamma": -1.0})), "gamma");
    assert_eq!(field(serde_json::json!({"reg": -1.0})), "reg");
    assert_eq!(field(serde_json::json!({"gamma": "big"})), "gamma");
    assert_eq!(field(serde_json::json!({"reg": "big"})), "reg");
    assert_eq!(field(serde_json::json!({"sigma2": 0.0})), "sigma2");
    assert_eq!(field(serde_json::json!({"sigma2": true})), "sigma2");
    assert_eq!(field(serde_json::json!({"kernel": "poly"})), "kernel");
    assert_eq!(field(serde_json::json!({"sigmа2": 1.0})), "sigmа2");
    // The linear kernel does not need sigma2; the defaults are "auto".
    let ok = ModelParams::from_json(
        ModelKind::LsSvm,
        &serde_json::json!({"kernel": "linear", "gamma": 5}),
    )
    .unwrap();
    assert_eq!(ok.to_json()["sigma2"], "auto");
    // `reg` is the wire name; `gamma` its accepted old spelling, never both.
    assert_eq!(ok.to_json()["reg"], 5.0);
    assert!(ok.to_json().get("gamma").is_none());
    let new = ModelParams::from_json(
        ModelKind::LsSvm,
        &serde_json::json!({"reg": 5, "kernel": "linear"}),
    );
    assert_eq!(new.unwrap(), ok);
    assert!(
        ModelParams::from_json(ModelKind::LsSvm, &serde_json::json!({"reg": 5, "gamma": 5}))
            .is_err()
    );
    let d = ModelParams::from_json(ModelKind::LsSvm, &serde_json::Value::Null).unwrap();
    assert_eq!(d, ModelParams::LsSvm(LsSvmParams::default()));
}

#[test]
fn stored_model_round_trip_predicts_identically() {
    let (x, y) = sample(40, 0.1, 3);
    let m = LsSvmParams::new(10.0, 1.0)
        .fit(&Dataset::new(&x, Some(&y)).unwrap())
        .unwrap();
    let any = AnyModel::LsSvm(m.clone());
    let back = AnyModel::from_stored_json(&any.to_stored_json()).unwrap();
    assert_eq!(back, any);
    for q in &x[..5] {
        assert_eq!(back.predict_one(q).to_bits(), m.predict_one(q).to_bits());
    }
}

/// CV error of one (γ, σ²) computed independently: the folds from `make_folds`, each
/// fold solved as a dense bordered system by LU, squared errors summed over folds / n.
fn independent_cv_error(x: &[Vec<f64>], y: &[f64], gamma: f64, sigma2: f64) -> f64 {
    let mut sse = 0.0;
    for fold in make_folds(x.len(), 5, 0).unwrap() {
        let tx: Vec<Vec<f64>> = fold.train.iter().map(|&i| x[i].clone()).collect();
        let ty: Vec<f64> = fold.train.iter().map(|&i| y[i]).collect();
        let k = Kernel::Rbf { sigma2 };
        let (alpha, b) = dense_lu(&tx, &ty, k, gamma);
        for &i in &fold.val {
            let f: f64 = b + tx
                .iter()
                .zip(&alpha)
                .map(|(t, a)| a * k.eval(t, &x[i]))
                .sum::<f64>();
            sse += (f - y[i]).powi(2);
        }
    }
    sse / x.len() as f64
}

#[test]
fn cross_validation_picks_the_best_pair_of_its_grid() {
    let (x, y) = sample(60, 0.2, 4);
    let data = Dataset::new(&x, Some(&y)).unwrap();
    let params = LsSvmParams {
        standardize: false,
        ..LsSvmParams::default()
    };
    let cv = CvParams::default();
    let t = train(&params, Some(&cv), &data, &NoProgress).unwrap();
    let report = t.metrics.cv.clone().unwrap();
    assert_eq!(report.evaluated, 49 * 2);
    // The coarse grid, evaluated independently: the chosen pair must be at least as
    // good as its best point (refinement can only improve on it) and its reported
    // error must match the independent computation.
    let grid = |lo: f64, hi: f64| -> Vec<f64> {
        (0..7)
            .map(|i| (lo.ln() + (hi / lo).ln() * i as f64 / 6.0).exp())
            .collect()
    };
    let mut best = f64::INFINITY;
    for g in grid(1e-2, 1e4) {
        for s in grid(1e-2, 1e3) {
            best = best.min(independent_cv_error(&x, &y, g, s));
        }
    }
    let chosen = independent_cv_error(&x, &y, report.gamma, report.sigma2.unwrap());
    assert!(
        (chosen - report.error).abs() < 1e-8 * chosen,
        "{chosen} vs {}",
        report.error
    );
    assert!(
        chosen <= best * (1.0 + 1e-12),
        "chosen {chosen}, grid best {best}"
    );
    // A known-good region for this function: σ² of order 1 (the sine's scale).
    let s = report.sigma2.unwrap();
    assert!((0.1..=10.0).contains(&s), "σ² {s}");
    assert_eq!(t.params.gamma, Hyper::Value(report.gamma));
}

#[test]
fn training_reports_cv_progress_and_honours_cancellation() {
    use std::sync::Mutex;
    struct Log(Mutex<Vec<String>>, bool);
    impl Progress for Log {
        fn report(&self, _f: f64, stage: &str) {
            self.0.lock().unwrap().push(stage.to_owned());
        }
        fn cancelled(&self) -> bool {
            self.1
        }
    }
    let (x, y) = sample(30, 0.1, 5);
    let data = Dataset::new(&x, Some(&y)).unwrap();
    let log = Log(Mutex::new(Vec::new()), false);
    train(&LsSvmParams::default(), None, &data, &log).unwrap();
    let stages = log.0.lock().unwrap().clone();
    assert!(stages.contains(&"cv fold 3/5".to_owned()));
    assert!(stages.contains(&"cv refine fold 5/5".to_owned()));
    let cancelled = Log(Mutex::new(Vec::new()), true);
    assert_eq!(
        train(&LsSvmParams::default(), None, &data, &cancelled),
        Err(LearnError::Cancelled)
    );
}

#[test]
fn bench_system_matches_numpy_golden_numbers() {
    // The system of benches/lssvm.rs at n = 250 (x[i][j] = 2 sin(0.7i + 1.3j),
    // y[i] = sin(x[i][0]) + 0.1 cos(3.1i), σ² = 5, γ = 10). Golden values from
    // `numpy.linalg.solve` of the bordered system built by benches/numpy_lssvm.py
    // (numpy 2.4.6, OpenBLAS): b, α₀, α₁₂₄, α₂₄₉.
    let mut rows = Vec::new();
    let mut y = Vec::new();
    for i in 0..250 {
        let x: Vec<f64> = (0..5)
            .map(|j| 2.0 * (0.7 * i as f64 + 1.3 * j as f64).sin())
            .collect();
        y.push(x[0].sin() + 0.1 * (3.1 * i as f64).cos());
        rows.extend(x);
    }
    let sol =
        crate::learn::lssvm_solve::fit(&rows, 5, &y, &Kernel::Rbf { sigma2: 5.0 }, 10.0).unwrap();
    assert!((sol.b - 0.00035891082519630315).abs() < 1e-12, "{}", sol.b);
    for (i, golden) in [
        (0, 0.979960954088946),
        (124, 0.41694118959163046),
        (249, 0.608735069316306),
    ] {
        assert!(
            (sol.alpha[i] - golden).abs() < 1e-10,
            "α{i} {}",
            sol.alpha[i]
        );
    }
}

#[test]
fn the_variance_term_equals_the_gp_posterior_in_training_units() {
    use crate::learn::variance::bordered_reference;
    let (x, y) = sample(80, 0.2, 37);
    let data = Dataset::new(&x, Some(&y)).unwrap();
    for params in [raw(20.0, 0.7), LsSvmParams::new(200.0, 1.3)] {
        let model = params.fit(&data).unwrap();
        let term = model.model_term().unwrap();
        for q in [
            x[0].clone(),
            x[41].clone(),
            vec![0.3, -0.2],
            vec![6.0, -5.0],
        ] {
            let z: Vec<f64> = q
                .iter()
                .enumerate()
                .map(|(j, v)| model.x_scale.apply_one(j, *v))
                .collect();
            let reference =
                bordered_reference(&model.support, 2, model.kernel(), model.gamma(), &z);
            let got = model.variance_term(&term, &q);
            assert!(
                (got - reference).abs() <= 1e-9 * reference,
                "{q:?}: {got:e} vs {reference:e}"
            );
        }
    }
}
