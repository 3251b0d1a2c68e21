"""The non-holonomic constraint point of the real drive estimated from parts of it
(gmis.nhc_offset_estimation): ŷ from the whole outage run (the GNSS the outage schedule
leaves), and from the likelihood of its first and second halves only — if ŷ is a property
of the car and not of one stretch of road the halves agree, and each half's ŷ can be
evaluated on the other half's outage windows (benchmarks/smoother_real_drive.py
--nhc-forward).

    PYTHONPATH=. python3 benchmarks/nhc_point_real_drive.py datasets/drive-boulder-0708/recipe.toml \
        [--first-start 243298.499 --every 45 --count 11 --duration 15] [--estimate-latency]
"""

import argparse
import dataclasses
import time

import numpy as np

from gmis.nhc_offset_estimation import estimate_nhc_offset, nhc_innovation_cost
from gmis.recipe import load_recipe
from gmis.run_preparation import prepare_run


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("recipe")
    ap.add_argument("--first-start", type=float, default=243298.499, metavar="GPS_S")
    ap.add_argument("--every", type=float, default=45.0)
    ap.add_argument("--count", type=int, default=11)
    ap.add_argument("--duration", type=float, default=15.0)
    ap.add_argument("--estimate-latency", action="store_true",
                    help="[gnss].estimate_time_offset = true first (gmis.latency_estimation)")
    args = ap.parse_args()
    windows = [(args.first_start + k * args.every,
                args.first_start + k * args.every + args.duration) for k in range(args.count)]
    recipe = load_recipe(args.recipe)
    if args.estimate_latency:
        recipe = dataclasses.replace(recipe, gnss=dataclasses.replace(
            recipe.gnss, estimate_time_offset=True))
    prep = prepare_run(recipe, gnss_outages=windows)
    t = prep.epochs.t
    mid = 0.5 * (t[0] + t[-1])
    for name, window in (("whole drive", None), ("first half", (t[0], mid)),
                         ("second half", (mid, t[-1] + 1.0))):
        c0 = time.process_time()
        est = estimate_nhc_offset(
            prep, cost=lambda p, y, w=window: nhc_innovation_cost(p, y, window_s=w))
        span = "" if window is None else f" (t - t0 in [{window[0] - t[0]:.0f}, " \
                                         f"{min(window[1], t[-1]) - t[0]:.0f}] s)"
        print(f"{name}{span}: y = {est.forward_m:+.3f} m, 1 sigma {est.sigma_m:.3f} m, "
              f"{est.runs} runs, {time.process_time() - c0:.1f} s CPU; coarse profile "
              f"c - min: {np.round(est.cost - est.cost.min(), 1).tolist()}", flush=True)


if __name__ == "__main__":
    main()
