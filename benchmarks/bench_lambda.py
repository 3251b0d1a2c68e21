"""LAMBDA timing on GNSS-like float ambiguity covariances, n = 10, 20, 30.

Covariance model (cycles^2), from a short-baseline DD geometry:

    Q_a = G P_b G^T + sigma_phi^2 C_DD

G: rows (u_s - u_ref)/lambda_f, DD line-of-sight differences (reference = highest satellite)
scaled to cycles of the frequency of that ambiguity; P_b = sigma_b^2 I_3 the float baseline
covariance; C_DD = I + 1 1^T per frequency (DD correlation), sigma_phi = 0.01 cycles.
sigma_b is chosen per trial so that the median float ambiguity sigma is 0.3 cycles (brief:
0.1-0.5 cycles).  n = 10: GPS L1, 11 satellites; n = 20: L1+L2, 11 satellites;
n = 30: L1+L2, 16 satellites.  Float a = integer truth + N(0, Q_a) noise.

Run:  python benchmarks/bench_lambda.py  [--trials 200] [--median-sigma 0.3] [--sigma-phi 0.01]
Prints per n: mean/median time of the search alone and of the whole resolve_integers
(decomposition + reduction + search + back-transformation), ms; the condition numbers of Q_a
and Z^T Q_a Z; the fraction of trials whose best candidate equals the truth and that pass
the ratio test (threshold 3).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from gnss.lambda_ils import decorrelate, ldl_decompose, ratio_test, resolve_integers, search

C_LIGHT = 299792458.0
WAVELENGTHS = (C_LIGHT / 1575.42e6, C_LIGHT / 1227.60e6)


def dd_ambiguity_covariance(rng, n_sats, n_freq, median_sigma=0.3, sigma_phi=0.01):
    az = rng.uniform(0.0, 2 * np.pi, size=n_sats)
    el = np.deg2rad(rng.uniform(10.0, 85.0, size=n_sats))
    u = np.column_stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])
    ref = int(np.argmax(el))
    dd = np.delete(u, ref, axis=0) - u[ref]
    G = np.vstack([dd / lam for lam in WAVELENGTHS[:n_freq]])
    C = np.kron(np.eye(n_freq), np.eye(n_sats - 1) + np.ones((n_sats - 1, n_sats - 1)))
    geometric = G @ G.T
    sigma_b = median_sigma / np.sqrt(np.median(np.diag(geometric)))
    Q = sigma_b**2 * geometric + sigma_phi**2 * C
    return 0.5 * (Q + Q.T)


def run(n_amb, n_sats, n_freq, trials, rng, median_sigma, sigma_phi):
    t_search, t_total, cond_q, cond_z, correct, passed = [], [], [], [], 0, 0
    for _ in range(trials):
        Q = dd_ambiguity_covariance(rng, n_sats, n_freq, median_sigma, sigma_phi)
        assert Q.shape[0] == n_amb
        truth = rng.integers(-1000, 1000, size=n_amb)
        a = truth + np.linalg.cholesky(Q) @ rng.normal(size=n_amb)
        t0 = time.perf_counter()
        res = resolve_integers(a, Q)
        t_total.append(time.perf_counter() - t0)
        L, D = ldl_decompose(Q)
        Z, Lz, Dz = decorrelate(L, D)
        z_hat = Z.T.astype(float) @ a
        t0 = time.perf_counter()
        search(z_hat, Lz, Dz, 2)
        t_search.append(time.perf_counter() - t0)
        cond_q.append(np.linalg.cond(Q))
        cond_z.append(np.linalg.cond(Z.T.astype(float) @ Q @ Z.astype(float)))
        correct += bool(np.array_equal(res.fixed, truth))
        passed += ratio_test(res, 3.0)
    ms = 1e3
    print(f"n={n_amb:2d} ({n_sats} sats, {n_freq} freq): search mean {np.mean(t_search)*ms:7.3f} ms"
          f" median {np.median(t_search)*ms:7.3f} ms | resolve_integers mean "
          f"{np.mean(t_total)*ms:7.3f} ms median {np.median(t_total)*ms:7.3f} ms | "
          f"median cond(Q) {np.median(cond_q):.2e} -> cond(Z'QZ) {np.median(cond_z):.2e} | "
          f"best==truth {correct/trials:.1%} ratio>=3 {passed/trials:.1%}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=200)
    parser.add_argument("--seed", type=int, default=20240601)
    parser.add_argument("--median-sigma", type=float, default=0.3,
                        help="median float ambiguity sigma [cycles]")
    parser.add_argument("--sigma-phi", type=float, default=0.01,
                        help="non-geometric (phase/residual) DD sigma [cycles]")
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    # warm-up: numba compilation / cache load is not part of the timing
    resolve_integers(np.array([0.1, 0.2, 0.3]), np.eye(3))
    for n_amb, n_sats, n_freq in ((10, 11, 1), (20, 11, 2), (30, 16, 2)):
        run(n_amb, n_sats, n_freq, args.trials, rng, args.median_sigma, args.sigma_phi)


if __name__ == "__main__":
    main()
