"""Calibration benchmarks: Monte-Carlo accuracy and CI coverage of the GMWM, RGMWM under
outliers, and CPU time of the issue-17 budgets (AWV vs AGMWM, 004 Theorems 1-2:
benchmarks/awv_theorems.py, which uses this module's draw_theta_004).

    PYTHONPATH=$PWD python3 benchmarks/bench_calibration.py [--runs R] [--part NAME]

CPU time (time.process_time) throughout; fixed seeds.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from calibration import processes as P
from calibration.despike import despike, despiked_wavelet_variance
from calibration.gmwm import fit_gmwm
from calibration.model_selection import select_model
from calibration.multisignal import average_wv, multi_signal
from calibration.robust import robust_wavelet_variance
from calibration.wavelet_variance import wavelet_variance

N = 10 ** 6
CASES = {  # 004 §IV Simulation I/II central values; a 5-process case
    "WN+RW": (("WN", "RW"), [1e-4, 1e-10]),
    "WN+AR1": (("WN", "AR1"), [5.5e-5, 0.9995, 7e-10]),
    "WN+AR1+RW": (("WN", "AR1", "RW"), [3e-6, 0.9985, 1.2e-10, 7e-13]),
    "WN+QN+2*AR1+RW": (("WN", "QN", "AR1", "AR1", "RW"),
                       [1e-4, 1e-5, 0.99, 1e-7, 0.9999, 1e-9, 1e-11]),
}


def _inside(fit, theta, cov_z) -> np.ndarray:
    """True θ inside the 95 % CI built on the optimiser's scale z with covariance cov_z."""
    from calibration import gmwm as G

    z = G._to_z(fit.model, fit.theta)
    se = np.sqrt(np.maximum(np.diag(cov_z), 0.0))
    lo, hi = G._from_z(fit.model, z - G.Z95 * se), G._from_z(fit.model, z + G.Z95 * se)
    return (lo <= theta) & (theta <= hi)


def monte_carlo(runs: int, cases=None, seed: int = 100) -> dict:
    """Per case and parameter: relative bias and spread of θ̂, and the share of runs whose
    95 % CI holds the truth — the fit's reported CI (sandwich SEs with the model-implied WV
    covariance; boundary-aware [0, â + 1.96 se] where 0 is not excluded) and the old
    log-scale interval with the χ²(η₃)-diagonal V = Ω⁻¹; the number of boundary-aware CIs
    (and how many of them hold the truth) and the mean CI width relative to θ."""
    print(f"== GMWM Monte Carlo, N = {N}, {runs} runs per case: relative bias, relative sd, "
          "CI95 coverage sandwich | diagonal (binomial sd of a 95 % coverage "
          f"{np.sqrt(0.95 * 0.05 / runs):.3f})")
    out = {}
    for name in cases or CASES:
        model, theta = CASES[name]
        model = P.canonical(model)
        theta = np.asarray(theta)
        rng = np.random.default_rng(seed)
        est, cover, cover_diag, at_bound, ci_width = [], [], [], [], []
        for _ in range(runs):
            f = fit_gmwm(wavelet_variance(P.simulate(model, theta, N, rng)), model)
            est.append(f.theta)
            ci_width.append(f.ci_high - f.ci_low)
            cover.append((f.ci_low <= theta) & (theta <= f.ci_high))
            at_bound.append([lab in f.extra["ci_at_bound"] for lab in f.labels])
            cover_diag.append(_inside(f, theta, f.extra["cov_z_diagonal"]))
        est, cover, cover_diag = np.array(est), np.array(cover), np.array(cover_diag)
        at_bound, ci_width = np.array(at_bound), np.array(ci_width)
        out[name] = {"theta": theta.tolist(), "estimates": est.tolist(),
                     "coverage": cover.mean(axis=0).tolist(),
                     "coverage_diagonal": cover_diag.mean(axis=0).tolist()}
        for k, lab in enumerate(P.parameter_labels(model)):
            t = theta[k]
            print(f"  {name:16s} {lab:14s} true {t:.4g}  rel.bias {np.mean(est[:, k]) / t - 1:+.4f}"
                  f"  rel.sd {np.std(est[:, k], ddof=1) / t:.4f}  CI95 coverage "
                  f"{np.mean(cover[:, k]):.2f} | {np.mean(cover_diag[:, k]):.2f}"
                  f"  boundary CIs {int(at_bound[:, k].sum())} (cover "
                  f"{int(cover[at_bound[:, k], k].sum())})  mean CI width/true "
                  f"{np.mean(ci_width[:, k]) / t:.3f}", flush=True)
    return out


def bootstrap_coverage(runs: int, B: int = 20) -> None:
    model, theta = CASES["WN+AR1+RW"]
    print(f"== parametric-bootstrap CIs (B = {B}), WN+AR1+RW, {runs} runs")
    rng = np.random.default_rng(500)
    cover = []
    for _ in range(runs):
        f = fit_gmwm(wavelet_variance(P.simulate(model, theta, N, rng)), model, bootstrap=B,
                     rng=rng)
        cover.append((f.ci_low <= theta) & (np.asarray(theta) <= f.ci_high))
    for lab, c in zip(P.parameter_labels(model), np.mean(cover, axis=0)):
        print(f"  {lab:14s} CI95 coverage {c:.2f}")


def draw_theta_004(rng, sim: int):
    """ϑ_i of 004 §IV Simulation I (WN+AR1) or II (WN+AR1+RW): rescaled Betas."""
    b = rng.beta
    if sim == 1:
        return [4e-5 + b(8, 5) * 3e-5, 0.999 + b(7, 2) * 0.0009, 6e-10 + b(3, 5) * 2e-10]
    return [2e-6 + b(8, 5) * 2e-6, 0.998 + b(7, 4) * 0.001, 1e-10 + b(3, 5) * 0.5e-10,
            0.5e-12 + b(4, 8) * 0.5e-12]


def outliers(runs: int, fractions=(0.01, 0.03, 0.05)) -> dict:
    """Paired design: per run one clean series x and, for each fraction, x with ±10 sd
    additive spikes at random samples (own generator). Per method the median over runs of
    θ̂(contaminated)/θ̂(clean) — the effect of the contamination, free of the estimator's own
    sampling spread — and of θ̂(clean)/θ; and per scale the median WV ratio
    ν̂(contaminated)/ν̂(clean despiked) of the despiked robust WV without and with the
    replacement-bias correction ("corrected": calibration.despike.despiked_wavelet_variance),
    which shows where a leak enters."""
    model, theta = ("WN", "AR1", "RW"), np.array([3e-6, 0.9985, 1.2e-10, 7e-13])
    labels = P.parameter_labels(model)
    methods = {
        "GMWM": lambda y: wavelet_variance(y),
        "RGMWM": lambda y: robust_wavelet_variance(y),
        "despiked GMWM": lambda y: wavelet_variance(despike(y)[0]),
        "despiked RGMWM": lambda y: robust_wavelet_variance(despike(y)[0]),
        "corrected GMWM": lambda y: despiked_wavelet_variance(y, 1.0, wavelet_variance)[0],
        "corrected RGMWM": lambda y: despiked_wavelet_variance(y, 1.0,
                                                               robust_wavelet_variance)[0],
    }
    print(f"== outliers (±10 sd spikes), {P.model_name(model)}, {runs} paired runs; median "
          "θ̂(contaminated)/θ̂(clean) per method (θ̂(clean)/θ in brackets at 0 %)")
    ratios = {m: {f: [] for f in fractions} for m in methods}
    clean = {m: [] for m in methods}
    wv_ratio = {m: {f: [] for f in fractions} for m in ("despiked RGMWM", "corrected RGMWM")}
    rng = np.random.default_rng(300)
    for r in range(runs):
        x = P.simulate(model, theta, N, rng)
        base = {m: fit_gmwm(est(x), model).theta for m, est in methods.items()}
        base_wv = robust_wavelet_variance(despike(x)[0])
        for m in methods:
            clean[m].append(base[m] / theta)
        for f in fractions:
            y = P.add_outliers(x, P.Outliers(f, 10.0), np.random.default_rng(1000 + r))
            for m, est in methods.items():
                wv = est(y)
                ratios[m][f].append(fit_gmwm(wv, model).theta / base[m])
                if m in wv_ratio:
                    wv_ratio[m][f].append(wv.nu2 / base_wv.nu2)
        print(f"  run {r + 1} done", flush=True)
    out = {"labels": labels, "clean": {}, "ratios": {}, "wv_ratio": {}}
    for m in methods:
        c = np.median(clean[m], axis=0)
        out["clean"][m] = c.tolist()
        print(f"  {m:15s}  0%: [" + " ".join(f"{lab}={v:.3g}" for lab, v in zip(labels, c))
              + "]")
        for f in fractions:
            q = np.percentile(ratios[m][f], [25, 50, 75], axis=0)
            out["ratios"].setdefault(m, {})[f] = q.tolist()
            print(f"  {m:15s} {f:3.0%}: " + " ".join(
                f"{lab}={q[1, k]:.3g} ({q[0, k]:.3g}-{q[2, k]:.3g})"
                for k, lab in enumerate(labels)))
    tau = base_wv.tau
    for m in wv_ratio:
        for f in fractions:
            med = np.median(wv_ratio[m][f], axis=0)
            out["wv_ratio"].setdefault(m, {})[f] = med.tolist()
            print(f"  {m} WV / clean despiked robust WV at {f:.0%}, tau = 2..2^"
                  f"{int(np.log2(tau[-1]))}: " + " ".join(f"{v:.3f}" for v in med))
    return out


def speed() -> None:
    print("== CPU time (time.process_time)")
    rng = np.random.default_rng(400)
    model, theta = ("WN", "AR1", "AR1", "RW"), [1e-4, 0.99, 1e-7, 0.9999, 1e-9, 1e-11]
    x = P.simulate(model, theta, N, rng)
    wavelet_variance(x[:1000])
    fit_gmwm(wavelet_variance(x[:4096]), model)  # warm caches
    t = time.process_time()
    fit_gmwm(wavelet_variance(x), model)
    print(f"  one axis 1e6: WV + GMWM WN+2*AR1+RW: {time.process_time() - t:.2f} s (budget 2)")
    signals = [[P.simulate(model, theta, N, rng) for _ in range(6)] for _ in range(4)]
    t = time.process_time()
    for axis in range(6):
        wvs = [wavelet_variance(signals[r][axis]) for r in range(4)]
        G_fit = multi_signal(wvs, model, fit_replicates=False).awv
    print(f"  AWV 4 replicates x 6 axes (WV + AWV fit): {time.process_time() - t:.2f} s "
          f"(budget 30); last fit {G_fit.name}")
    t = time.process_time()
    rows = select_model(average_wv([wavelet_variance(signals[r][0]) for r in range(4)]),
                        P.parse_model("WN+QN+2*AR1+RW+DR"))
    print(f"  model selection over {len(rows)} nested models of WN+QN+2*AR1+RW+DR: "
          f"{time.process_time() - t:.2f} s (budget 60); best {rows[0].model}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--case", action="append", choices=list(CASES),
                    help="Monte-Carlo case(s) (default: all)")
    ap.add_argument("--json", help="write the Monte-Carlo estimates and coverages here")
    ap.add_argument("--part", choices=["all", "mc", "outliers", "speed",
                                       "bootstrap"],
                    default="all")
    args = ap.parse_args()
    if args.part in ("all", "speed"):
        speed()
    if args.part in ("all", "mc"):
        mc = monte_carlo(args.runs, args.case)
        if args.json:
            import json

            with open(args.json, "w") as fh:
                json.dump(mc, fh)
    if args.part in ("all", "outliers"):
        outliers(max(args.runs // 4, 3))
    if args.part in ("all", "bootstrap"):
        bootstrap_coverage(max(args.runs // 2, 3))


if __name__ == "__main__":
    main()
