#!/usr/bin/env python3
"""NumPy reference for `benches/lssvm.rs` (docs/performance.md: batch LS-SVM training at n = 1000
must take no longer than NumPy/LAPACK solving the same system).

Builds exactly the bench's system -- 5-D inputs x[i][j] = 2 sin(0.7 i + 1.3 j), targets
y[i] = sin(x[i][0]) + 0.1 cos(3.1 i), RBF kernel exp(-|x - z|^2 / sigma2) with sigma2 = 5,
gamma = 10 -- as the bordered (n+1) x (n+1) system of seed 000 eq. 6,
[[0, 1^T], [1, Omega + I/gamma]] [b; alpha] = [0; y], and times
  * `numpy.linalg.solve` of it (LU with partial pivoting, LAPACK dgesv): what a NumPy
    user would write; the kernel matrix is built outside the timed region;
  * `numpy.linalg.cholesky` of Omega + I/gamma alone (LAPACK dpotrf), for a like-for-like
    comparison with the Rust `cholesky` bench.
Each figure is the median of `--repeat` runs. NumPy is a reference, not a dependency.

Run (single-threaded BLAS, then the default thread count):
    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 python3 benches/numpy_lssvm.py
    python3 benches/numpy_lssvm.py

`--golden 250` prints, at full precision (repr), the solution entries
`crates/core/src/learn/lssvm_tests.rs` (`bench_system_matches_numpy_golden_numbers`) pins:
b, alpha_0, alpha_124 and alpha_249 (alpha_k is entry k + 1 of the bordered solution).
"""
import argparse
import time

import numpy as np

DIM, GAMMA, SIGMA2 = 5, 10.0, 5.0


def system(n):
    i = np.arange(n, dtype=float)[:, None]
    j = np.arange(DIM, dtype=float)[None, :]
    x = 2.0 * np.sin(0.7 * i + 1.3 * j)
    y = np.sin(x[:, 0]) + 0.1 * np.cos(3.1 * np.arange(n))
    d2 = ((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=2)
    h = np.exp(-d2 / SIGMA2) + np.eye(n) / GAMMA
    a = np.zeros((n + 1, n + 1))
    a[0, 1:] = 1.0
    a[1:, 0] = 1.0
    a[1:, 1:] = h
    rhs = np.concatenate([[0.0], y])
    return a, rhs, h


def median_time(f, repeat):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return float(np.median(times))


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="*", default=[250, 500, 1000, 2000])
    p.add_argument("--repeat", type=int, default=10)
    p.add_argument("--golden", type=int, metavar="N",
                   help="print b and alpha_0, alpha_(N/2-1), alpha_(N-1) at n = N, then exit")
    args = p.parse_args()
    print(f"numpy {np.__version__}")
    if args.golden:
        n = args.golden
        a, rhs, _ = system(n)
        sol = np.linalg.solve(a, rhs)
        b, alpha = sol[0], sol[1:]
        print(f"n={n}  b={float(b)!r}")
        for k in (0, n // 2 - 1, n - 1):
            print(f"alpha[{k}]={float(alpha[k])!r}")
        print(f"max |residual| = {np.abs(a @ sol - rhs).max():.3e}")
        return
    for n in args.sizes:
        a, rhs, h = system(n)
        sol = np.linalg.solve(a, rhs)
        t_solve = median_time(lambda: np.linalg.solve(a, rhs), args.repeat)
        t_chol = median_time(lambda: np.linalg.cholesky(h), args.repeat)
        print(f"n={n:5d}  solve {t_solve * 1e3:9.3f} ms  cholesky {t_chol * 1e3:9.3f} ms  b={sol[0]:.12f}")


if __name__ == "__main__":
    main()
