//! Criterion bench of the LS-SVM family (docs/performance.md): batch training (kernel matrix,
//! blocked Cholesky, two-solve trick) at n = 250, 500, 1000, 2000 and the Cholesky
//! alone; one sliding-window update of the online LS-SVM at N = 50, 100, 200 against a
//! batch re-solve of the same window (target ≥ 20× at N = 200).
//!
//! Data: 5-D inputs `x[i][j] = 2·sin(0.7·i + 1.3·j)`, targets
//! `y[i] = sin(x[i][0]) + 0.1·cos(3.1·i)`, RBF σ² = 5, γ = 10: no RNG, so
//! `benches/numpy_lssvm.py` builds exactly the same system.
//!
//! Run: `cargo bench --bench lssvm` (add `-- --quick` for a short run).

// criterion_group! defines a public function it cannot document.
#![allow(missing_docs)]

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use navguard_core::learn::Kernel;
use navguard_core::learn::lssvm_solve as solve;
use navguard_core::learn::online::{OnlineLsSvm, OnlineParams};

const DIM: usize = 5;
const GAMMA: f64 = 10.0;
const SIGMA2: f64 = 5.0;

fn sample(i: usize) -> ([f64; DIM], f64) {
    let x: [f64; DIM] = std::array::from_fn(|j| 2.0 * (0.7 * i as f64 + 1.3 * j as f64).sin());
    (x, x[0].sin() + 0.1 * (3.1 * i as f64).cos())
}

fn data(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut rows = Vec::with_capacity(n * DIM);
    let mut y = Vec::with_capacity(n);
    for i in 0..n {
        let (x, t) = sample(i);
        rows.extend_from_slice(&x);
        y.push(t);
    }
    (rows, y)
}

fn batch(c: &mut Criterion) {
    let kernel = Kernel::Rbf { sigma2: SIGMA2 };
    let mut group = c.benchmark_group("lssvm_batch");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(3));
    for n in [250, 500, 1000, 2000] {
        let (rows, y) = data(n);
        group.bench_with_input(BenchmarkId::new("train", n), &n, |b, _| {
            b.iter(|| black_box(solve::fit(&rows, DIM, &y, &kernel, GAMMA).expect("fit")))
        });
        let h = solve::regularised_kernel(&rows, DIM, &kernel, GAMMA);
        group.bench_with_input(BenchmarkId::new("cholesky", n), &n, |b, _| {
            b.iter(|| {
                let mut a = h.clone();
                solve::cholesky(&mut a).expect("spd");
                black_box(a)
            })
        });
    }
    group.finish();
}

fn online(c: &mut Criterion) {
    let kernel = Kernel::Rbf { sigma2: SIGMA2 };
    let mut group = c.benchmark_group("lssvm_online");
    group
        .sample_size(20)
        .measurement_time(Duration::from_secs(2));
    for n in [50, 100, 200] {
        let params = OnlineParams {
            window: n,
            gamma: GAMMA,
            sigma2: SIGMA2,
            refresh: 1000,
        };
        let mut w = OnlineLsSvm::new(params).expect("params");
        let mut k = 0;
        while k < n {
            let (x, y) = sample(k);
            w.push(&x, y).expect("push");
            k += 1;
        }
        // One slide: the oldest leaves, a new sample enters (refresh amortised in).
        group.bench_with_input(BenchmarkId::new("update", n), &n, |b, _| {
            b.iter(|| {
                let (x, y) = sample(k);
                k += 1;
                w.push(black_box(&x), black_box(y)).expect("push");
            })
        });
        let (rows, y) = data(n);
        group.bench_with_input(BenchmarkId::new("batch_resolve", n), &n, |b, _| {
            b.iter(|| black_box(solve::fit(&rows, DIM, &y, &kernel, GAMMA).expect("fit")))
        });
    }
    group.finish();
}

criterion_group!(benches, batch, online);
criterion_main!(benches);
