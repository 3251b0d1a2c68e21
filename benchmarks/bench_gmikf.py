"""Benchmark the GMIKF loop on a simulated 1-hour, 100 Hz IMU + 5 Hz GNSS + heading drive.

    python benchmarks/bench_gmikf.py [--minutes 60] [--states 27] [--keep DIR] [--filter-only]

Prints, for the plain filter and for a VCE iteration (residuals and redundancy indices on),
the CPU time (time.process_time, the figure to compare on a shared machine) and the wall
time of the filter loop (after JIT warm-up, best of --repeat runs), IMU epochs per CPU
second and the ratio to real time, and their cost ratio. A/B comparisons: run this script
alternately with PYTHONPATH pointing at the two trees (it uses only public entry points).
"""

import argparse
import copy
import dataclasses
import tempfile
import time
import tomllib
from pathlib import Path

from gmis.pipeline import prepare_run, run_prepared
from gmis.recipe import load_recipe
from gmis.simulate import default_scenario_path, simulate_scenario


def long_scenario(minutes: float) -> dict:
    """The default drive's moving part repeated until the drive lasts `minutes`."""
    doc = tomllib.loads(Path(default_scenario_path()).read_text())
    segments = doc["segment"]
    static, moving = segments[0], segments[1:]
    static = dict(static, duration_s=60.0)
    out = [static]
    # durations of segments that have one; others (accelerate/turn) ~10 s each
    total = 60.0
    while total < minutes * 60.0:
        for seg in moving:
            out.append(copy.deepcopy(seg))
            total += float(seg.get("duration_s", 10.0))
    doc["segment"] = out
    doc["scenario"]["name"] = f"bench-{minutes:g}min"
    for key in ("gnss", "heading"):
        if key in doc:
            doc[key].pop("outage", None)
    return doc


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--states", type=int, default=27, choices=(21, 27))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--keep", type=Path, help="simulate into / reuse this folder")
    ap.add_argument("--filter-only", action="store_true",
                    help="time the filter loops only (skip the VCE iteration and job)")
    args = ap.parse_args()
    folder = args.keep or Path(tempfile.mkdtemp(prefix="gmis-bench-"))
    recipe_path = folder / "recipe.toml"
    if not recipe_path.exists():
        t0 = time.perf_counter()
        simulate_scenario(long_scenario(args.minutes), folder, overwrite=True)
        print(f"simulated {args.minutes:g} min in {time.perf_counter() - t0:.1f} s -> {folder}")
    recipe = load_recipe(recipe_path)
    recipe = dataclasses.replace(recipe, filter=dataclasses.replace(recipe.filter,
                                                                    states=args.states))
    t0 = time.perf_counter()
    prep = prepare_run(recipe)
    print(f"read + prepare: {time.perf_counter() - t0:.1f} s")
    n_imu = int((prep.epochs.imu >= 0).sum())
    duration = float(prep.dataset.imu.t[-1] - prep.dataset.imu.t[0])
    results = {}
    for label, mode in (("plain", 0), ("vce", 1)):
        cfg = dataclasses.replace(prep.config, vce_mode=mode)
        run_prepared(prep, cfg)               # JIT warm-up / cache load
        best_cpu = best_wall = float("inf")
        for _ in range(args.repeat):
            c0, t0 = time.process_time(), time.perf_counter()
            run_prepared(prep, cfg)
            best_cpu = min(best_cpu, time.process_time() - c0)
            best_wall = min(best_wall, time.perf_counter() - t0)
        results[label] = best_cpu
        print(f"{label:5s} {args.states}-state LC GMIKF: {n_imu} IMU epochs in "
              f"CPU {best_cpu:.3f} s (wall {best_wall:.3f} s) = {n_imu / best_cpu:,.0f} IMU "
              f"epochs per CPU s, {duration / best_cpu:.0f}x real time")
    print(f"VCE filter loop / plain loop CPU cost ratio: {results['vce'] / results['plain']:.2f}")
    if args.filter_only:
        return
    # a VCE iteration = filter with residuals/redundancy + per-component estimates
    # + the Helmert solve; the first and last iterations also extract standardized
    # residual sets and sliding windows (once per job, reported separately)
    from vce.components import gmikf_components
    from vce.estimate import estimate_component
    from vce.tune import _initial_sigma, apply_sigma, helmert_sigma0, tune
    comps = gmikf_components(prep.config.n_imu)
    cfg, meas = apply_sigma(prep, comps, _initial_sigma(prep, comps))
    best = float("inf")
    for _ in range(args.repeat):
        c0 = time.process_time()
        rec = run_prepared(prep, cfg, meas=meas)
        ests = [estimate_component(rec, c, cfg.q_sd ** 2, rec.still) for c in comps]
        helmert_sigma0(rec.helmert_s, rec.helmert_totals, comps, ests,
                       ["estimated"] * len(comps))
        best = min(best, time.process_time() - c0)
    print(f"one VCE iteration (filter + estimates + Helmert solve): CPU {best:.2f} s = "
          f"{best / results['plain']:.2f}x the plain filter run")
    c0, t0 = time.process_time(), time.perf_counter()
    tune(prep, max_iterations=1)
    print(f"single-iteration job incl. first/final residual sets and windows: "
          f"CPU {time.process_time() - c0:.2f} s (wall {time.perf_counter() - t0:.2f} s)")

if __name__ == "__main__":
    main()
