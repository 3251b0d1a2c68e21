"""AWV vs AGMWM in the near-stationary setting (004 §III Theorems 1-2, §IV Simulations I-II):
what each estimator targets, shown numerically with standard errors.

Targets (004 eq. 4; calibration.multisignal.near_stationary_target): the AWV targets
θ₀ = argmin_θ E‖ν(ϑ) − ν(θ)‖²_Ω, the AGMWM E[ϑ]. Because the Haar WV of a sum of
independent processes is the sum of their WVs (002 eq. 28), the mean WV over G is

    E[ν(ϑ)] = E[σ²]/τ + E[γ²](τ² + 2)/(12τ) + E[ν_AR1(φ, ξ²; τ)].

WN, QN, RW and DR enter linearly, so their part is the WV of the averaged parameter. The
AR1 part is a mixture of AR1 WVs: with φ fixed (a point mass) it is ν_AR1(φ, E[ξ²]) and
θ₀ = E[ϑ] exactly (004 Proposition 3); with φ random it is in general no AR1 WV at all,
so θ₀ — the best fit of the whole model to E[ν(ϑ)] — moves φ and ξ² AND the linear
parameters that absorb the mismatch (in Simulation II the RW: the mixture decays more
slowly than one AR1 at the large scales, and γ²₀ is 16 % above E[γ²]).

Design per run (K replicates of N = 1e6, J = 13 scales, Ω the replicates' average):
* near-stationary arm: ϑ_i drawn from 004's rescaled Betas (bench_calibration.draw_theta_004);
* control arm: every replicate at E[ϑ] (G a point mass, so θ₀ = E[ϑ]) with the same
  innovations (common random numbers).
Per parameter the runs give the AWV and AGMWM means (± SE = sd/√runs), and the paired
differences d = AWV − AGMWM in both arms; the split predicted by the theorems is
θ₀ − E[ϑ]; d_control measures the finite-T difference of the two estimators that is not
due to G (both are biased a little at T = 1e6), and d − d_control is the estimate of the
split freed from it.

    PYTHONPATH=$PWD python3 benchmarks/awv_theorems.py [--sim 1 2] [--runs 40] [--K 6]
        [--json OUT.json]

CPU time (time.process_time), fixed seeds.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_calibration import draw_theta_004

from calibration import processes as P
from calibration.multisignal import multi_signal, near_stationary_omega, near_stationary_target
from calibration.wavelet_variance import wavelet_variance

N = 10 ** 6
LEVELS = 13
MODELS = {1: ("WN", "AR1"), 2: ("WN", "AR1", "RW")}
# 004 §IV Beta(a, b) rescaled to [lo, hi], per parameter (the draws of draw_theta_004)
BETAS = {1: [(4e-5, 7e-5, 8, 5), (0.999, 0.9999, 7, 2), (6e-10, 8e-10, 3, 5)],
         2: [(2e-6, 4e-6, 8, 5), (0.998, 0.999, 7, 4), (1e-10, 1.5e-10, 3, 5),
             (0.5e-12, 1e-12, 4, 8)]}


def expected_theta(sim: int) -> np.ndarray:
    """E[ϑ] = lo + (hi − lo)·a/(a + b) per parameter (exact)."""
    return np.array([lo + (hi - lo) * a / (a + b) for lo, hi, a, b in BETAS[sim]])


def mean_wv_exact(sim: int, tau: np.ndarray, nodes: int = 400) -> np.ndarray:
    """E[ν(ϑ)] under G: the linear processes at their exact means; the AR1 as
    E[ξ²]·E_φ[ν_AR1(φ, 1)] (φ and ξ² independent), the φ expectation by Gauss-Legendre
    quadrature against the Beta density (no Monte-Carlo error in θ₀ − E[ϑ])."""
    from scipy.stats import beta

    model = P.canonical(MODELS[sim])
    mean = expected_theta(sim)
    y, wq = np.polynomial.legendre.leggauss(nodes)
    y, wq = 0.5 * (y + 1.0), 0.5 * wq
    total, i = np.zeros_like(tau), 0
    for p in model:
        if p == "AR1":
            lo, hi, a, b = BETAS[sim][i]
            pdf = beta.pdf(y, a, b) * wq
            ar = sum(c * P.ar1_wv(lo + (hi - lo) * yy, 1.0, tau) for c, yy in zip(pdf, y))
            total += mean[i + 1] * ar / pdf.sum()
            i += 2
        else:
            total += P.process_wv(p, [mean[i]], tau)
            i += 1
    return total


def finite_k_target(sim: int, K: int, sets: int, tau: np.ndarray, seed: int):
    """The split of the AWV from the AGMWM with K replicates and T → ∞: per set of K draws
    θ₀ of the set (the fit to their mean WV with their average Ω; the noise-free AWV)
    minus the mean of the set (the noise-free AGMWM); mean and SE over ``sets`` sets."""
    model = P.canonical(MODELS[sim])
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(sets):
        d = np.array([draw_theta_004(rng, sim) for _ in range(K)])
        nu_bar = np.mean([P.model_wv(model, t, tau) for t in d], axis=0)
        out.append(near_stationary_target(model, tau, nu_bar,
                                          near_stationary_omega(model, d, tau, N),
                                          d.mean(axis=0)) - d.mean(axis=0))
    out = np.array(out)
    return out.mean(axis=0), out.std(axis=0, ddof=1) / np.sqrt(sets)


def run_arms(sim: int, runs: int, K: int, seed: int) -> dict:
    model = P.canonical(MODELS[sim])
    mean = expected_theta(sim)
    rng_theta = np.random.default_rng(seed)
    out = {arm: {"awv": [], "agmwm": []} for arm in ("near_stationary", "control")}
    for r in range(runs):
        thetas = [draw_theta_004(rng_theta, sim) for _ in range(K)]
        seeds = [seed * 100_000 + r * 100 + i for i in range(K)]
        for arm, params in (("near_stationary", thetas), ("control", [mean] * K)):
            wvs = [wavelet_variance(P.simulate(model, th, N, np.random.default_rng(s)),
                                    levels=LEVELS) for th, s in zip(params, seeds)]
            ms = multi_signal(wvs, model)
            out[arm]["awv"].append(ms.awv.theta)
            out[arm]["agmwm"].append(ms.agmwm_theta)
    return {arm: {k: np.array(v) for k, v in d.items()} for arm, d in out.items()}


def _ms(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return x.mean(axis=0), x.std(axis=0, ddof=1) / np.sqrt(x.shape[0])


def study(sim: int, runs: int, K: int, sets: int = 400, draws: int = 4000) -> dict:
    model = P.canonical(MODELS[sim])
    tau = 2.0 ** np.arange(1, LEVELS + 1)
    mean = expected_theta(sim)
    rng = np.random.default_rng(200 + sim)
    omega = near_stationary_omega(model, [draw_theta_004(rng, sim) for _ in range(draws)],
                                  tau, N)
    theta0 = near_stationary_target(model, tau, mean_wv_exact(sim, tau), omega, mean)
    split_ks, split_ks_se = finite_k_target(sim, K, sets, tau, seed=250 + sim)
    cpu = time.process_time()
    arms = run_arms(sim, runs, K, seed=300 + sim) if runs > 1 else None
    cpu = time.process_time() - cpu
    rows = []
    print(f"== 004 Simulation {'I' * sim} ({P.model_name(model)}), K = {K}, {runs} runs, "
          f"N = {N}, J = {LEVELS}; CPU {cpu:.0f} s. θ₀: K → ∞ (exact mean WV, Ω from {draws} "
          f"draws); split_K: noise-free AWV − AGMWM with K replicates ({sets} sets, ± SE); "
          "% of E[ϑ] (of 1 − E[φ] for φ)")
    for k, lab in enumerate(P.parameter_labels(model)):
        split, split_k = theta0[k] - mean[k], split_ks[k]
        ref = 1.0 - mean[k] if lab.endswith(".phi") else mean[k]
        row = {"parameter": lab, "theta0": theta0[k], "E_theta": mean[k], "split": split,
               "split_K": [split_k, split_ks_se[k]]}
        print(f"  {lab:13s} E[ϑ] {mean[k]:.7g}  θ₀ {theta0[k]:.7g}  θ₀−E {split:+.4g} "
              f"({split / ref:+.2%})  split_K {split_k:+.4g} ± {split_ks_se[k]:.2g} "
              f"({split_k / ref:+.2%})")
        if arms is not None:
            ns, ct = arms["near_stationary"], arms["control"]
            d_ns = ns["awv"][:, k] - ns["agmwm"][:, k]
            d_ct = ct["awv"][:, k] - ct["agmwm"][:, k]
            a, sa = _ms(ns["awv"][:, k])
            g, sg = _ms(ns["agmwm"][:, k])
            d, sd = _ms(d_ns)
            c, sc = _ms(d_ct)
            dd, sdd = _ms(d_ns - d_ct)
            row.update({"awv": [a, sa], "agmwm": [g, sg], "d": [d, sd], "d_control": [c, sc],
                        "d_minus_control": [dd, sdd]})
            print(f"  {'':13s} AWV {a:.7g} ± {sa:.2g}   AGMWM {g:.7g} ± {sg:.2g}")
            print(f"  {'':13s} AWV−AGMWM {d:+.4g} ± {sd:.2g}; control arm {c:+.4g} ± {sc:.2g}; "
                  f"difference {dd:+.4g} ± {sdd:.2g} = {dd / split_k:.2f} × split_K "
                  f"(z vs split_K {(dd - split_k) / sdd:+.1f}, z vs 0 {dd / sdd:+.1f})")
        rows.append(row)
    return {"sim": sim, "model": list(model), "K": K, "runs": runs, "cpu_s": cpu,
            "rows": rows, "estimates": None if arms is None else
            {a: {k: v.tolist() for k, v in d.items()} for a, d in arms.items()}}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sim", type=int, nargs="+", choices=[1, 2], default=[1, 2])
    ap.add_argument("--runs", type=int, default=40, help="Monte-Carlo runs (0: targets only)")
    ap.add_argument("--K", type=int, default=6)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    report = [study(s, args.runs, args.K) for s in args.sim]
    if args.json:
        args.json.write_text(json.dumps(report, indent=1, default=float))


if __name__ == "__main__":
    main()
