"""Benchmark the GMIKF loop on a simulated IMU + 5 Hz GNSS + heading drive (default 10 min
at 100 Hz), A/B against a reference kernel in the same process.

    python benchmarks/bench_gmikf.py [--minutes 10] [--states 27] [--keep DIR]
                                     [--reference COMMIT] [--rounds 5] [--filter-only]

The reference is the kernel of git COMMIT (default b36893a, the staged kernel before the
sparse propagation/update), re-created by benchmarks/reference_kernel.py. For the plain
filter and for a VCE iteration (residuals and redundancy indices on) it prints, per kernel,
the CPU time (time.process_time, the figure to compare on a shared machine) and the wall
time side by side: the filter loop alone (records preallocated and warm) and the whole
``run_prepared`` (records allocated per run), each over --rounds rounds run A, B, A, B, …
(median and best), IMU epochs per CPU second, µs per epoch, and the reference/new CPU ratio.
It also prints the largest state difference between the two kernels' records.
"""

import argparse
import contextlib
import copy
import dataclasses
import statistics
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.reference_kernel import load_reference_kernel
from gmis import run_filter
from gmis.pipeline import prepare_run, run_prepared
from gmis.recipe import load_recipe
from gmis.simulate import default_scenario_path, simulate_scenario

KERNEL_NAMES = ("EpochInputs", "EpochRecords", "KernelSettings", "gmikf_chunk")
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


@contextlib.contextmanager
def kernel(module):
    """gmis.run_filter runs the kernel of ``module`` (None: the live gmis.gmikf)."""
    saved = {k: getattr(run_filter, k) for k in KERNEL_NAMES}
    if module is not None:
        for k in KERNEL_NAMES:
            setattr(run_filter, k, getattr(module, k))
    try:
        yield
    finally:
        for k, v in saved.items():
            setattr(run_filter, k, v)


def loop_only(prep, cfg, runner):
    """The filter loop over all epochs into the runner's (warm) records."""
    runner.x[:] = prep.x0
    runner.p[:] = run_filter.initial_covariance(cfg.p0_sd)
    runner.e_next, runner.t_prev = 0, np.nan
    for e0 in range(0, runner.e_total, cfg.chunk):
        runner.advance(e0 + cfg.chunk)


def timed(fn):
    c0, t0 = time.process_time(), time.perf_counter()
    fn()
    return time.process_time() - c0, time.perf_counter() - t0


def ab_rounds(prep, cfg, variants, rounds):
    """{label: {"loop": [(cpu, wall)], "run": [(cpu, wall)], "x": final records x}}."""
    out = {}
    runners = {}
    for label, module in variants:
        with kernel(module):
            rec = run_prepared(prep, cfg)                 # JIT warm-up / cache load
            runners[label] = run_filter.GmikfRunner(prep.epochs, prep.meas, prep.x0, cfg,
                                                    prep.frame, prep.stationary)
            loop_only(prep, cfg, runners[label])
        out[label] = {"loop": [], "run": [], "x": rec.x}
    for _ in range(rounds):
        for label, module in variants:
            with kernel(module):
                runner = runners[label]
                out[label]["loop"].append(timed(lambda r=runner: loop_only(prep, cfg, r)))
                out[label]["run"].append(timed(lambda: run_prepared(prep, cfg)))
    return out


def report(mode_label, out, n_imu, duration, states):
    labels = list(out)
    for what, title in (("loop", "filter loop"), ("run", "run_prepared")):
        for label in labels:
            cpu = [c for c, _ in out[label][what]]
            wall = [w for _, w in out[label][what]]
            med = statistics.median(cpu)
            print(f"{mode_label:5s} {states}-state {title:12s} {label:9s}: CPU median "
                  f"{med:.3f} s best {min(cpu):.3f} s | wall median "
                  f"{statistics.median(wall):.3f} s best {min(wall):.3f} s | "
                  f"{n_imu / med:,.0f} IMU epochs/CPU s = {med / n_imu * 1e6:.2f} µs/epoch, "
                  f"{duration / med:.0f}x real time")
        if len(labels) == 2:
            a, b = ([statistics.median([c for c, _ in out[k][what]]) for k in labels])
            pairs = [ra[0] / rb[0] for ra, rb in zip(out[labels[1]][what],
                                                      out[labels[0]][what], strict=True)]
            print(f"{mode_label:5s} {title:12s} CPU ratio {labels[1]}/{labels[0]}: median of "
                  f"medians {b / a:.2f}, per round {min(pairs):.2f}-{max(pairs):.2f}")
    if len(labels) == 2:
        dx = np.nanmax(np.abs(out[labels[0]]["x"] - out[labels[1]]["x"]))
        print(f"{mode_label:5s} max |x_new − x_ref| over all epochs: {dx:.3e}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--states", type=int, default=27, choices=(21, 27))
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=3, help="VCE-iteration repeats")
    ap.add_argument("--reference", default="b36893a",
                    help="git commit of the reference kernel ('none': new kernel only)")
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
    c0, t0 = time.process_time(), time.perf_counter()
    prep = prepare_run(recipe)
    print(f"read + prepare: CPU {time.process_time() - c0:.2f} s "
          f"(wall {time.perf_counter() - t0:.2f} s)")
    n_imu = int((prep.epochs.imu >= 0).sum())
    duration = float(prep.dataset.imu.t[-1] - prep.dataset.imu.t[0])
    variants = [("new", None)]
    if args.reference != "none":
        c0 = time.process_time()
        variants.insert(0, (f"ref@{args.reference}", load_reference_kernel(args.reference)))
        print(f"reference kernel {args.reference} loaded (CPU {time.process_time() - c0:.2f} s)")
    results = {}
    for label, mode in (("plain", 0), ("vce", 1)):
        cfg = dataclasses.replace(prep.config, vce_mode=mode)
        out = ab_rounds(prep, cfg, variants, args.rounds)
        report(label, out, n_imu, duration, args.states)
        results[label] = statistics.median(c for c, _ in out["new"]["run"])
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
