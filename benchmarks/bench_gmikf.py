"""Benchmark the GMIKF loop on a simulated IMU + 5 Hz GNSS + heading drive (default 10 min
at 100 Hz), A/B against a reference commit, one worker process per tree.

    python benchmarks/bench_gmikf.py [--minutes 10] [--states 27] [--keep DIR]
                                     [--reference COMMIT] [--rounds 5] [--filter-only]

The drive is simulated once by this tree; two worker processes, one with PYTHONPATH at
the reference tree (``git archive COMMIT``, default 9f59828, the code when issue 12 was
filed; benchmarks/reference_kernel.reference_tree) and one at this tree, each read and
prepare it and warm up (numba compile / cache load). Then, for the plain filter and for a
VCE iteration's filter (vce_mode 1: residuals, redundancy indices, Helmert sums), the
workers time alternately reference, this, reference, this, … (A/B interleaved on the same
machine load): the filter loop alone (a fresh GmikfRunner built untimed, then its advance
over all chunks; "loop, streamed": the same with the records in one chunk buffer handed to
a sink, as ``gmis run`` streams them — timed when both trees have it) and the whole
``run_prepared`` (records allocated per run). Printed per
tree: CPU time (time.process_time in the worker: median and best) with wall time beside
it, IMU epochs per CPU second and µs per epoch; the CPU ratio this/reference (median of
medians and the per-round range); and the largest difference between the two trees'
state records (heading wrapped). ``--reference none``: this tree only. Without
--filter-only, this tree's VCE iteration (filter + estimates + Helmert solve) and a
single-iteration job are timed in-process afterwards.

The workers import only names both trees have (gmis.pipeline.prepare_run/run_prepared,
gmis.recipe.load_recipe, gmis.run_filter.GmikfRunner/initial_covariance).
"""

import argparse
import copy
import dataclasses
import inspect
import statistics
import sys
import time
import tomllib
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parents[1]))   # a worker's gmis: PYTHONPATH
from benchmarks import reference_kernel as ab

MODES = (("plain", 0), ("vce", 1))


def long_scenario(minutes: float) -> dict:
    """The default drive's moving part repeated until the drive lasts `minutes`."""
    from gmis.simulate import default_scenario_path
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


def timed(fn):
    c0, t0 = time.process_time(), time.perf_counter()
    out = fn()
    return time.process_time() - c0, time.perf_counter() - t0, out


def worker(folder: Path) -> None:
    """Prepare ``folder``'s bench recipe, warm up both modes, then answer 'run MODE' (loop
    and run_prepared timings), 'save PATH' (the last run_prepared x of each mode) and
    'quit'."""
    import numpy as np

    from gmis import run_filter
    from gmis.pipeline import prepare_run, run_prepared
    from gmis.recipe import load_recipe

    c0 = time.process_time()
    prep = prepare_run(load_recipe(folder / "bench.toml"))
    t_prep = time.process_time() - c0
    configs = {label: dataclasses.replace(prep.config, vce_mode=mode) for label, mode in MODES}
    last = {label: run_prepared(prep, cfg) for label, cfg in configs.items()}   # warm-up

    streams = "sink" in inspect.signature(run_filter.GmikfRunner).parameters

    def loop_only(cfg, sink=None):
        """The filter loop over all epochs into a fresh runner's records (built untimed):
        whole-run records (sink None), or one chunk buffer handed to ``sink`` (the bounded-
        memory path of ``gmis run``; trees without it answer None)."""
        extra = {} if sink is None else {"sink": sink}
        runner = run_filter.GmikfRunner(prep.epochs, prep.meas, prep.x0, cfg, prep.frame,
                                        prep.stationary, **extra)

        def loop():
            for e0 in range(0, runner.e_total, cfg.chunk):
                runner.advance(e0 + cfg.chunk)
        return timed(loop)[:2]

    ab.say(prep_cpu=t_prep, n_imu=int((prep.epochs.imu >= 0).sum()),
        n_states=int(prep.x0.shape[0]),
        duration=float(prep.dataset.imu.t[-1] - prep.dataset.imu.t[0]))
    for line in sys.stdin:
        cmd = line.split()
        if cmd[0] == "run":
            cfg = configs[cmd[1]]
            loop = loop_only(cfg)
            streamed = loop_only(cfg, sink=lambda e0, chunk: None) if streams else None
            cpu, wall, last[cmd[1]] = timed(lambda c=cfg: run_prepared(prep, c))
            ab.say(loop=loop, streamed=streamed, run=(cpu, wall))
        elif cmd[0] == "save":
            np.savez(cmd[1], **{label: rec.x for label, rec in last.items()})
            ab.say(saved=cmd[1])
        else:
            return


def summary(label, title, mode, times, n_imu, duration, states):
    cpu = [c for c, _ in times]
    wall = [w for _, w in times]
    med = statistics.median(cpu)
    print(f"{mode:5s} {states}-state {title:12s} {label:14s}: CPU median {med:.3f} s best "
          f"{min(cpu):.3f} s | wall median {statistics.median(wall):.3f} s best "
          f"{min(wall):.3f} s | {n_imu / med:,.0f} IMU epochs/CPU s = "
          f"{med / n_imu * 1e6:.2f} µs/epoch, {duration / med:.0f}x real time")
    return med


def vce_iteration_timings(folder: Path, states: int, repeat: int):
    """This tree's VCE iteration and single-iteration job, in-process (not A/B)."""
    from gmis.pipeline import prepare_run, run_prepared
    from gmis.recipe import load_recipe
    from vce.components import gmikf_components
    from vce.estimate import estimate_component
    from vce.tune import _initial_sigma, apply_sigma, helmert_sigma0, tune
    prep = prepare_run(load_recipe(folder / "bench.toml"))
    c0 = time.process_time()
    run_prepared(prep)
    plain = time.process_time() - c0
    comps = gmikf_components(prep.config.n_imu)
    cfg, meas = apply_sigma(prep, comps, _initial_sigma(prep, comps))
    best = float("inf")
    for _ in range(repeat):
        c0 = time.process_time()
        rec = run_prepared(prep, cfg, meas=meas)
        ests = [estimate_component(rec, c, cfg.q_sd ** 2, rec.still) for c in comps]
        helmert_sigma0(rec.helmert_s, rec.helmert_totals, comps, ests,
                       ["estimated"] * len(comps))
        best = min(best, time.process_time() - c0)
    print(f"one VCE iteration (filter + estimates + Helmert solve): CPU {best:.2f} s = "
          f"{best / plain:.2f}x the plain filter run ({plain:.2f} s)")
    c0, t0 = time.process_time(), time.perf_counter()
    tune(prep, max_iterations=1)
    print(f"single-iteration job incl. first/final residual sets and windows: "
          f"CPU {time.process_time() - c0:.2f} s (wall {time.perf_counter() - t0:.2f} s)")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--states", type=int, default=27, choices=(21, 27))
    ap.add_argument("--repeat", type=int, default=3, help="VCE-iteration repeats")
    ap.add_argument("--filter-only", action="store_true",
                    help="time the filter loops only (skip the VCE iteration and job)")
    ab.ab_arguments(ap)
    args = ab.parse_ab(ap, worker)
    if args is None:
        return
    import numpy as np

    from gmis.simulate import simulate_scenario
    folder = ab.bench_folder(args.keep, "gmis-bench-")
    if not (folder / "recipe.toml").exists():
        t0 = time.perf_counter()
        simulate_scenario(long_scenario(args.minutes), folder, overwrite=True)
        print(f"simulated {args.minutes:g} min in {time.perf_counter() - t0:.1f} s -> {folder}")
    text = (folder / "recipe.toml").read_text()
    if "states = 27" not in text:
        raise SystemExit("recipe.toml: no 'states = 27' line to set --states in")
    (folder / "bench.toml").write_text(text.replace("states = 27", f"states = {args.states}"))
    workers = ab.start_workers(Path(__file__).resolve(), args.reference, folder, "gmikf-worker")
    for label, w in workers.items():
        w.info = w.reply()
        print(f"{label:14s} read + prepare: CPU {w.info['prep_cpu']:.2f} s")
    info = workers["this"].info
    n_imu, duration, states = info["n_imu"], info["duration"], info["n_states"]
    results = {}
    for mode, _ in MODES:
        times = {label: {"loop": [], "streamed": [], "run": []} for label in workers}
        for _ in range(args.rounds):
            for label, w in workers.items():
                r = w.ask(f"run {mode}")
                for what in times[label]:
                    if r.get(what) is not None:
                        times[label][what].append(tuple(r[what]))
        for what, title in (("loop", "filter loop"), ("streamed", "loop, streamed"),
                            ("run", "run_prepared")):
            if not all(times[label][what] for label in workers):
                continue
            med = {label: summary(label, title, mode, times[label][what], n_imu, duration,
                                  states) for label in workers}
            results[(mode, what)] = med["this"]
            if len(workers) == 2:
                ref, this = list(workers)
                per_round = [b[0] / a[0] for a, b in zip(times[ref][what], times[this][what],
                                                         strict=True)]
                print(f"{mode:5s} {title:12s} CPU ratio {this}/{ref}: median of medians "
                      f"{med[this] / med[ref]:.3f}, per round {min(per_round):.3f}-"
                      f"{max(per_round):.3f} ({args.rounds} rounds, A/B interleaved)")
    print(f"VCE filter loop / plain loop CPU cost ratio: "
          f"{results[('vce', 'loop')] / results[('plain', 'loop')]:.2f}")
    if len(workers) == 2:
        saved = {label: folder / f"gmikf-records-{i}.npz" for i, label in enumerate(workers)}
        for label, w in workers.items():
            w.ask(f"save {saved[label]}")
        ref, this = list(workers)
        a, b = np.load(saved[ref]), np.load(saved[this])
        for mode, _ in MODES:
            print(f"{mode:5s} records {this} vs {ref}: max |x_this - x_ref| "
                  f"{ab.max_state_difference(b[mode], a[mode]):.3e} over all epochs (heading "
                  f"wrapped; nan: shapes differ), bit-identical "
                  f"{np.array_equal(a[mode], b[mode], equal_nan=True)}")
    for w in workers.values():
        w.close()
    if not args.filter_only:
        vce_iteration_timings(folder, args.states, args.repeat)


if __name__ == "__main__":
    main()
