"""VCE started at the true noise (issue 13 item 3): one iteration of `vce.tune` on the
random-dynamics drive (every component's truth known) per seed; prints per component the
mean of the Helmert factor used and of the simplified ratio with their Monte-Carlo standard
errors, the estimator used, and the IMU factor averaged over the 6 axes (mean ± s.e. over
seeds). A factor consistent with the truth is 1 within its standard error.

Usage: PYTHONPATH=$PWD python3 benchmarks/monte_carlo_vce_truth.py --seeds 8
"""

from __future__ import annotations

import argparse
import collections
import tempfile

import numpy as np

from gmis.pipeline import prepare_run
from gmis.recipe import load_recipe
from gmis.simulate import scenario_path, simulate_scenario
from vce import tune


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--first-seed", type=int, default=1)
    args = ap.parse_args(argv)
    helmert, simplified, how = (collections.defaultdict(list) for _ in range(3))
    names = []
    with tempfile.TemporaryDirectory() as work:
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            sim = simulate_scenario(scenario_path("random_dynamics"), f"{work}/s{seed}",
                                    seed=seed)
            res = tune(prepare_run(load_recipe(sim.recipe_path)), max_iterations=1,
                       min_redundancy=0.001)
            it = res.history[0]
            names = [c.name for c in res.components]
            for c, h0, e, est in zip(res.components, it.sigma0_sq, it.estimates,
                                     it.estimator):
                helmert[c.name].append(h0)
                simplified[c.name].append(e.sigma0_sq)
                how[c.name].append(est)
            print(f"seed {seed}: " + ", ".join(f"{n} {h:.4f}" for n, h in
                                               zip(names[:6], it.sigma0_sq[:6])), flush=True)
    se = lambda a: np.std(a, ddof=1) / np.sqrt(len(a)) if len(a) > 1 else np.nan
    print(f"\n{args.seeds} seeds, factors at the true noise (1 = unbiased)")
    for n in names:
        h, s = np.array(helmert[n]), np.array(simplified[n])
        print(f"{n:14s} used {h.mean():.4f} ± {se(h):.4f}  simplified {s.mean():.4f} ± "
              f"{se(s):.4f}  estimator {collections.Counter(how[n]).most_common(1)[0][0]}")
    imu = np.array([helmert[n] for n in names[:6]]).mean(axis=0)
    print(f"IMU factor (mean of 6 axes): {imu.mean():.4f} ± {se(imu):.4f} over seeds")


if __name__ == "__main__":
    main()
