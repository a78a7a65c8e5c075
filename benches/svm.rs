//! SVM training benches (docs/performance.md): one-class SVM on 30,000 × 3 features against
//! scikit-learn's `OneClassSVM` (reference script `benches/sklearn_ocsvm.py`, same
//! data from the same SplitMix64 generator, same parameters), and C-SVC on 688 × 8
//! (the size of seed 002's training set).
//!
//! `python3 benches/sklearn_ocsvm.py && cargo bench --bench svm`: the script writes
//! scikit-learn's decisions to `target/svm-bench/`; this bench prints the share of
//! points where the signs agree before timing.

// criterion_group! defines a public function it cannot document.
#![allow(missing_docs)]

use std::hint::black_box;
use std::time::Instant;

use criterion::{Criterion, criterion_group, criterion_main};
use navguard_core::learn::Dataset;
use navguard_core::learn::svm::{OcSvmParams, SvcParams};

/// SplitMix64 (Steele, Lea & Flood 2014), identical to the Python script's.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Box–Muller, one normal per pair of uniforms (as the script).
    fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * (1.0 - u1).ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// Three features with scales (1, 2, 0.5); every 20th row is 3× wider.
fn ocsvm_data() -> Dataset {
    let mut rng = SplitMix64(2024);
    let rows: Vec<Vec<f64>> = (0..30_000)
        .map(|i| {
            let wide = if i % 20 == 0 { 3.0 } else { 1.0 };
            [1.0, 2.0, 0.5]
                .iter()
                .map(|s| rng.normal() * s * wide)
                .collect()
        })
        .collect();
    Dataset::new(&rows, None).expect("finite data")
}

/// 400 normal (−1) and 288 fault (+1) windows of 8 features; faults shifted by 0.8.
fn svc_data() -> Dataset {
    let mut rng = SplitMix64(688);
    let mut x = Vec::new();
    let mut y = Vec::new();
    for i in 0..688 {
        let fault = i >= 400;
        let shift = if fault { 0.8 } else { 0.0 };
        x.push((0..8).map(|_| rng.normal() + shift).collect::<Vec<f64>>());
        y.push(if fault { 1.0 } else { -1.0 });
    }
    Dataset::new(&x, Some(&y)).expect("finite data")
}

/// scikit-learn's `OneClassSVM(gamma=1/3, nu=0.1, tol=1e-3, cache_size=200)`.
fn ocsvm_params() -> OcSvmParams {
    OcSvmParams {
        nu: Some(0.1),
        gamma: Some(1.0 / 3.0),
        standardize: false,
        ..OcSvmParams::default()
    }
}

/// scikit-learn's `SVC(C=1, gamma=1/8, tol=1e-3, cache_size=200)`.
fn svc_params() -> SvcParams {
    SvcParams {
        c: 1.0,
        gamma: Some(1.0 / 8.0),
        standardize: false,
        ..SvcParams::default()
    }
}

/// Share of equal signs between our decisions and scikit-learn's, if its file exists.
fn agreement(file: &str, ours: &[f64]) {
    let path = std::path::Path::new("target/svm-bench").join(file);
    let Ok(text) = std::fs::read_to_string(&path) else {
        println!(
            "{}: not found (run benches/sklearn_ocsvm.py first)",
            path.display()
        );
        return;
    };
    let theirs: Vec<f64> = text.lines().filter_map(|l| l.trim().parse().ok()).collect();
    if theirs.len() != ours.len() {
        println!(
            "{}: {} values, expected {}",
            path.display(),
            theirs.len(),
            ours.len()
        );
        return;
    }
    let same = ours
        .iter()
        .zip(&theirs)
        .filter(|(a, b)| (**a >= 0.0) == (**b >= 0.0))
        .count();
    let max_diff = ours
        .iter()
        .zip(&theirs)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    println!(
        "agreement with scikit-learn ({file}): {:.3} % of {} points, max |Δdecision| {max_diff:.2e}",
        100.0 * same as f64 / ours.len() as f64,
        ours.len()
    );
}

fn bench(c: &mut Criterion) {
    let oc_data = ocsvm_data();
    let started = Instant::now();
    let fitted = ocsvm_params()
        .check()
        .expect("valid params")
        .fit_with(&oc_data, &navguard_core::learn::NoProgress)
        .expect("ocsvm trains");
    let (model, metrics) = (fitted.model, fitted.metrics);
    println!(
        "navguard ocsvm 30000x3: {:.3} s, {} SVs, rho {:.6}, {} iterations, outliers {:.4}",
        started.elapsed().as_secs_f64(),
        model.n_support(),
        model.rho(),
        metrics.iterations.unwrap_or(0),
        metrics.outlier_fraction.unwrap_or(f64::NAN)
    );
    let decisions: Vec<f64> = (0..oc_data.n())
        .map(|i| model.decision_one(&oc_data.row(i)))
        .collect();
    agreement("sklearn_ocsvm_decisions.csv", &decisions);

    let svc = svc_data();
    let model = svc_params().fit(&svc).expect("svc trains");
    let decisions: Vec<f64> = (0..svc.n())
        .map(|i| model.decision_one(&svc.row(i)))
        .collect();
    println!(
        "navguard svc 688x8: {} SVs, intercept {:.6}",
        model.n_support(),
        model.intercept()
    );
    agreement("sklearn_svc_decisions.csv", &decisions);

    let mut group = c.benchmark_group("svm");
    group.sample_size(10);
    group.bench_function("ocsvm_train_30000x3", |b| {
        b.iter(|| ocsvm_params().fit(black_box(&oc_data)).expect("trains"))
    });
    group.bench_function("svc_train_688x8", |b| {
        b.iter(|| svc_params().fit(black_box(&svc)).expect("trains"))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
