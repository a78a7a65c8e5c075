#!/usr/bin/env python3
"""scikit-learn reference for benches/svm.rs (docs/performance.md: one-class SVM training on
30,000 x 3 features must take no longer than scikit-learn's OneClassSVM, with the
same decisions on >= 99.5 % of points).

Run from the repository root:

    pip install scikit-learn numpy
    python3 benches/sklearn_ocsvm.py          # writes target/svm-bench/*.csv
    cargo bench --bench svm                   # times navguard, prints agreement

The data come from the same tiny generator as benches/svm.rs (SplitMix64 ->
uniform -> Box-Muller), so both sides train on identical inputs without a data
file. Parameters: OneClassSVM(kernel="rbf", gamma=1/3, nu=0.1, tol=1e-3,
cache_size=200, shrinking=True) == navguard ocsvm {"gamma": 1/3, "nu": 0.1,
"standardize": false, "tol": 1e-3, "cache_mb": 200, "shrinking": true}; and
SVC(C=1, gamma=1/8, tol=1e-3, cache_size=200) on 688 x 8 for the C-SVC figure.
scikit-learn is a reference here, never a dependency of navguard.
"""
import math
import os
import time

import numpy as np
from sklearn.svm import SVC, OneClassSVM

MASK = (1 << 64) - 1


class SplitMix64:
    """Steele, Lea & Flood (2014); identical to `SplitMix64` in benches/svm.rs."""

    def __init__(self, seed):
        self.state = seed & MASK

    def next_u64(self):
        self.state = (self.state + 0x9E3779B97F4A7C15) & MASK
        z = self.state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
        return z ^ (z >> 31)

    def uniform(self):
        return (self.next_u64() >> 11) * (1.0 / (1 << 53))

    def normal(self):
        u1, u2 = self.uniform(), self.uniform()
        return math.sqrt(-2.0 * math.log(1.0 - u1)) * math.cos(2.0 * math.pi * u2)


def ocsvm_data(n=30000):
    """Three features with scales (1, 2, 0.5); every 20th row is 3x wider."""
    rng = SplitMix64(2024)
    scales = (1.0, 2.0, 0.5)
    rows = []
    for i in range(n):
        wide = 3.0 if i % 20 == 0 else 1.0
        rows.append([rng.normal() * s * wide for s in scales])
    return np.array(rows)


def svc_data():
    """400 normal (-1) and 288 fault (+1) windows of 8 features; faults shifted by 0.8."""
    rng = SplitMix64(688)
    x, y = [], []
    for i in range(688):
        fault = i >= 400
        shift = 0.8 if fault else 0.0
        x.append([rng.normal() + shift for _ in range(8)])
        y.append(1.0 if fault else -1.0)
    return np.array(x), np.array(y)


def best_of(k, fit):
    times, model = [], None
    for _ in range(k):
        t0 = time.perf_counter()
        model = fit()
        times.append(time.perf_counter() - t0)
    return min(times), model


def main():
    out = os.path.join("target", "svm-bench")
    os.makedirs(out, exist_ok=True)

    x = ocsvm_data()
    t, oc = best_of(3, lambda: OneClassSVM(
        kernel="rbf", gamma=1.0 / 3.0, nu=0.1, tol=1e-3, cache_size=200, shrinking=True
    ).fit(x))
    dec = oc.decision_function(x)
    np.savetxt(os.path.join(out, "sklearn_ocsvm_decisions.csv"), dec, fmt="%.17g")
    print(f"sklearn OneClassSVM 30000x3: best of 3 {t:.3f} s, {len(oc.support_)} SVs, "
          f"rho {oc.offset_[0]:.6f}, outliers {np.mean(dec < 0):.4f}")

    xs, ys = svc_data()
    t, svc = best_of(5, lambda: SVC(C=1.0, kernel="rbf", gamma=1.0 / 8.0, tol=1e-3,
                                    cache_size=200, shrinking=True).fit(xs, ys))
    np.savetxt(os.path.join(out, "sklearn_svc_decisions.csv"), svc.decision_function(xs),
               fmt="%.17g")
    print(f"sklearn SVC 688x8: best of 5 {t * 1e3:.2f} ms, {len(svc.support_)} SVs, "
          f"intercept {svc.intercept_[0]:.6f}")


if __name__ == "__main__":
    main()
