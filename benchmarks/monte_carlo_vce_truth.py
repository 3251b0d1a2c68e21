"""VCE started at the true noise (issue 13 item 3): one iteration of `vce.tune` on the
random-dynamics drive (every component's truth known) per seed; prints per component the
mean of the Helmert factor used and of the simplified ratio with their Monte-Carlo standard
errors, the estimator used, and the IMU factor averaged over the 6 axes (mean ± s.e. over
seeds). A factor consistent with the truth is 1 within its standard error.

Variants (each written into the scenario/recipe by code, same seeds): --tests-off also
runs every seed with the outlier tests off (α = 0: no truncation) on the same simulated
data and prints the paired difference (tests on − off) per component; --reversion-s sets
the random segment's reversion time (0 = none: the filter's process model exactly, see
gmis/simulate/trajectory.py); --states 21 runs the 21-state filter (no scale factors).

Usage: PYTHONPATH=$PWD python3 benchmarks/monte_carlo_vce_truth.py --seeds 8
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import tempfile
import time
import tomllib

import numpy as np

from gmis.pipeline import prepare_run
from gmis.recipe import load_recipe
from gmis.simulate import scenario_path, simulate_scenario
from gmis.simulate.imu_grades import IMU_GRADES
from vce import tune


def _scenario(reversion_s, drop=(), noise_scale=None, dynamics_scale=None, random_s=None,
              imu_rate_hz=None):
    with open(scenario_path("random_dynamics"), "rb") as fh:
        raw = tomllib.load(fh)
    if imu_rate_hz is not None:
        raw["scenario"]["imu_rate_hz"] = float(imu_rate_hz)
    for seg in raw["segment"]:
        if seg["type"] == "random" and dynamics_scale is not None:
            for key in ("sigma_jerk_m_s3", "sigma_angacc_deg_s2"):
                seg[key] = [dynamics_scale * v for v in seg[key]]
        if seg["type"] == "random" and random_s is not None:
            seg["duration_s"] = float(random_s)
    if noise_scale is not None:      # every sensor's white noise × noise_scale
        raw["imu"]["gyro_arw_deg_sqrt_h"] = IMU_GRADES[raw["imu"]["grade"]][
            "gyro_arw_deg_sqrt_h"] * noise_scale
        raw["imu"]["accel_vrw_m_s_sqrt_h"] = IMU_GRADES[raw["imu"]["grade"]][
            "accel_vrw_m_s_sqrt_h"] * noise_scale
        for key in ("position_sigma_m", "velocity_sigma_m_s"):
            raw["gnss"][key] = [noise_scale * v for v in raw["gnss"][key]]
        raw["heading"]["sigma_deg"] *= noise_scale
    raw["segment"] = [seg for seg in raw["segment"] if seg["type"] not in drop]
    if reversion_s is not None:
        for seg in raw["segment"]:
            if seg["type"] == "random":
                seg["reversion_time_s"] = float(reversion_s)
    return raw


def _recipe(path, states, alpha):
    recipe = load_recipe(path)
    changes = {}
    if states is not None:
        changes["states"] = states
    if alpha is not None:
        changes["outlier_alpha"] = alpha
    if changes:
        recipe = dataclasses.replace(recipe, filter=dataclasses.replace(recipe.filter,
                                                                        **changes))
    return recipe


def nees_rates(sim, prep, skip_s=80.0):
    """Mean (x̂ − x)²/σ̂² of the filter's a^b and ω states (6) over the moving epochs
    after skip_s s (the posterior covariance's consistency with the truth)."""
    from gmis.run_preparation import run_prepared
    rec = run_prepared(prep)
    tr = sim.truth
    k = np.searchsorted(tr.t_s, rec.t - rec.t[0] + tr.t_s[0] - 1e-9)
    err = np.c_[rec.x[:, 6:9] - tr.a_b[k], rec.x[:, 12:15] - tr.omega_b[k]]
    sd = np.c_[rec.sd[:, 6:9], rec.sd[:, 12:15]]
    sel = ~rec.still & (rec.t - rec.t[0] > skip_s)
    return ((err / sd) ** 2)[sel].mean(axis=0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--nees", action="store_true",
                    help="also print the normalized squared errors of a^b and ω")
    ap.add_argument("--tests-off", action="store_true",
                    help="also run each seed with the outlier tests off (paired)")
    ap.add_argument("--reversion-s", type=float, default=None,
                    help="random segment reversion time (s); 0 = none")
    ap.add_argument("--states", type=int, choices=(21, 27), default=None)
    ap.add_argument("--dynamics-scale", type=float, default=None,
                    help="the random segment's jerk and angular-acceleration σ × this")
    ap.add_argument("--random-s", type=float, default=None,
                    help="duration of the random segment (s)")
    ap.add_argument("--imu-rate", type=float, default=None,
                    help="IMU rate (Hz; the per-step jerk/angular-acceleration σ is kept)")
    ap.add_argument("--noise-scale", type=float, default=None,
                    help="every sensor's white noise (IMU, GNSS, heading) × this")
    ap.add_argument("--drop-segments", default="",
                    help="comma-separated segment types left out, e.g. accelerate,cruise")
    args = ap.parse_args(argv)
    drop = tuple(x for x in args.drop_segments.split(",") if x)
    modes = ["on", "off"] if args.tests_off else ["on"]
    helmert, simplified, how = ({m: collections.defaultdict(list) for m in modes}
                                for _ in range(3))
    names = []
    nees = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as work:
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            sim = simulate_scenario(_scenario(args.reversion_s, drop,
                                              args.noise_scale, args.dynamics_scale,
                                              args.random_s, args.imu_rate), f"{work}/s{seed}",
                                    seed=seed)
            if args.nees:
                nees.append(nees_rates(sim, prepare_run(_recipe(sim.recipe_path,
                                                                args.states, None))))
            for mode in modes:
                recipe = _recipe(sim.recipe_path, args.states,
                                 0.0 if mode == "off" else None)
                res = tune(prepare_run(recipe), max_iterations=1, min_redundancy=0.001)
                it = res.history[0]
                names = [c.name for c in res.components]
                for c, h0, e, est in zip(res.components, it.sigma0_sq, it.estimates,
                                         it.estimator):
                    helmert[mode][c.name].append(h0)
                    simplified[mode][c.name].append(e.sigma0_sq)
                    how[mode][c.name].append(est)
                print(f"seed {seed} tests {mode}: " + ", ".join(
                    f"{n} {h:.4f}" for n, h in zip(names[:6], it.sigma0_sq[:6]))
                    + f"  ({time.perf_counter() - t0:.0f} s)", flush=True)
    se = lambda a: np.std(a, ddof=1) / np.sqrt(len(a)) if len(a) > 1 else np.nan
    variant = ", ".join(f"{k} {v}" for k, v in (("reversion_s", args.reversion_s),
                                                ("states", args.states),
                                                ("noise_scale", args.noise_scale),
                                                ("dynamics_scale", args.dynamics_scale),
                                                ("random_s", args.random_s),
                                                ("imu_rate_hz", args.imu_rate),
                                                ("dropped", ",".join(drop) or None))
                       if v is not None)
    for mode in modes:
        print(f"\n{args.seeds} seeds, outlier tests {mode}"
              + (f" ({variant})" if variant else "")
              + ", factors at the true noise (1 = unbiased)")
        for n in names:
            h, s = np.array(helmert[mode][n]), np.array(simplified[mode][n])
            print(f"{n:14s} used {h.mean():.4f} ± {se(h):.4f}  simplified {s.mean():.4f} "
                  f"± {se(s):.4f}  estimator "
                  f"{collections.Counter(how[mode][n]).most_common(1)[0][0]}")
        imu = np.array([helmert[mode][n] for n in names[:6]]).mean(axis=0)
        print(f"IMU factor (mean of 6 axes): {imu.mean():.4f} ± {se(imu):.4f} over seeds")
    if nees:
        a = np.array(nees)
        print("\nNEES (x̂ − x)²/σ̂², moving epochs after 80 s, a^b x y z, ω x y z:\n  "
              + "  ".join(f"{m:.4f} ± {e:.4f}" for m, e in
                          zip(a.mean(axis=0), a.std(axis=0, ddof=1) / np.sqrt(len(a)))))
    if args.tests_off:
        print("\npaired difference, tests on − off (same data): used / simplified")
        for n in names:
            dh = np.array(helmert["on"][n]) - np.array(helmert["off"][n])
            ds = np.array(simplified["on"][n]) - np.array(simplified["off"][n])
            print(f"{n:14s} {dh.mean():+.4f} ± {se(dh):.4f}   {ds.mean():+.4f} ± "
                  f"{se(ds):.4f}")
        d = (np.array([helmert["on"][n] for n in names[:6]])
             - np.array([helmert["off"][n] for n in names[:6]])).mean(axis=0)
        print(f"IMU factor on − off: {d.mean():+.4f} ± {se(d):.4f}")


if __name__ == "__main__":
    main()
