"""Benchmark the tightly coupled GMIKF (IMU 100 Hz + DD code/L1/L2/Doppler at 2 Hz + dual-
antenna heading) on the simulated tightly_coupled scenario, A/B against a reference commit.

    python benchmarks/bench_tc.py [--nav PATH] [--start-gps-s S] [--keep DIR]
                                  [--reference COMMIT] [--rounds 5]

--nav uses a real broadcast file (e.g. ../shared/data/rtklib-test/brdc1820.10n, GPS week
1590) instead of the synthetic 24-satellite constellation, for a real satellite count;
--start-gps-s moves the drive in the week (with brdc1820.10n, 421200 s is a window with 9
GPS satellites above 15° at the scenario origin for the whole drive: the 8-10 satellite
case of the issue).

The dataset is simulated once by this tree; two worker processes, one with PYTHONPATH at
this tree and one at the reference tree (``git archive COMMIT``, default 9f59828, the code
when issue 12 was filed; benchmarks/reference_kernel.reference_tree), each read and
prepare it (RINEX reading, DD preparation and the dual-antenna heading solution, timed
once) and warm up (numba compile / cache load). Then ``run_tight`` runs --rounds times in
each, alternately reference, this, reference, this, … (A/B interleaved on the same machine
load). Printed per tree: satellites per epoch, CPU time of the filter run (time.process_time
in the worker: median and best) with wall time beside it, IMU epochs per CPU second, the
CPU ratio this/reference (median of medians and the per-round range), and the largest
difference between the two trees' state records and fix flags. ``--reference none``: this
tree only.
"""

import argparse
import statistics
import sys
import time
import tomllib
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parents[1]))   # a worker's gmis: PYTHONPATH
from benchmarks import reference_kernel as ab


def worker(folder: Path) -> None:
    """Prepare the tight run of ``folder``, warm up, then run on each 'run' line of stdin
    (answers one TAG JSON line each); 'save PATH' writes the last records, 'quit' ends.
    Imports only names the reference commits have too (gmis.pipeline, gmis.recipe, gmis.tc)."""
    import numpy as np

    from gmis.pipeline import prepare_run
    from gmis.recipe import load_recipe
    from gmis.tc import prepare_tight, run_tight

    prep = prepare_run(load_recipe(folder / "tight.toml"))
    c0 = time.process_time()
    inputs = prepare_tight(prep)
    t_prep = time.process_time() - c0
    n_sat = np.array([ep.prn.size for ep in inputs.epochs])     # base and rover, any elevation
    rec, tc, _ = run_tight(prep, inputs=inputs)                   # warm-up
    used = tc.n_sat[tc.n_sat > 0]
    ab.say(prep_cpu=t_prep, n_gnss=int(n_sat.size), sat=[float(np.median(n_sat)),
        int(n_sat.min()), int(n_sat.max())], used=[float(np.median(used)), int(used.min()),
        int(used.max())], mask=float(inputs.config.elevation_mask_deg),
        n_imu=int((rec.imu_row >= 0).sum()), n_states=[int(prep.config.n_imu),
        int(rec.x.shape[1])], duration=float(prep.dataset.imu.t[-1] - prep.dataset.imu.t[0]),
        fix_rate=float(tc.fixed.mean()))
    for line in sys.stdin:
        cmd = line.split()
        if cmd[0] == "run":
            c0, t0 = time.process_time(), time.perf_counter()
            rec, tc, _ = run_tight(prep, inputs=inputs)
            ab.say(cpu=time.process_time() - c0, wall=time.perf_counter() - t0)
        elif cmd[0] == "save":
            np.savez(cmd[1], x=rec.x, t=rec.t, fixed=tc.fixed)
            ab.say(saved=cmd[1])
        else:
            return


def simulate(folder: Path, nav: Path | None, start_gps_s: float | None) -> None:
    from gmis.simulate import scenario_path, simulate_scenario
    if not (folder / "recipe.toml").exists():
        doc = tomllib.loads(Path(scenario_path("tightly_coupled")).read_text())
        if nav:
            doc["raw_gnss"]["nav"] = str(nav.resolve())
            doc["scenario"]["gps_week"] = 1590
        if start_gps_s is not None:
            doc["scenario"]["start_gps_s"] = start_gps_s
        simulate_scenario(doc, folder, overwrite=True)
    text = (folder / "recipe.toml").read_text().replace('mode = "loose"', 'mode = "tight"')
    (folder / "tight.toml").write_text(text)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nav", type=Path, help="real broadcast nav file (GPS week 1590)")
    ap.add_argument("--start-gps-s", type=float, help="drive start, GPS seconds of week")
    ab.ab_arguments(ap)
    args = ab.parse_ab(ap, worker)
    if args is None:
        return
    import numpy as np

    folder = ab.bench_folder(args.keep, "gmis-bench-tc-")
    simulate(folder, args.nav, args.start_gps_s)
    workers = ab.start_workers(Path(__file__).resolve(), args.reference, folder, "worker")
    for label, w in workers.items():
        i = w.info = w.reply()
        print(f"{label:14s} GNSS epochs {i['n_gnss']}, satellites per epoch: median "
              f"{i['sat'][0]:.0f}, min {i['sat'][1]}, max {i['sat'][2]}; used above the "
              f"{i['mask']:g}° mask: median {i['used'][0]:.0f}, min {i['used'][1]}, max "
              f"{i['used'][2]}; RINEX + DD inputs + dual-antenna heading: "
              f"{i['prep_cpu']:.1f} s CPU; fix rate {i['fix_rate']:.3f}")
    times = {label: [] for label in workers}
    for _ in range(args.rounds):
        for label, w in workers.items():
            r = w.ask("run")
            times[label].append((r["cpu"], r["wall"]))
    info = workers["this"].info
    n_imu, duration = info["n_imu"], info["duration"]
    med = {}
    for label in workers:
        cpu = [c for c, _ in times[label]]
        wall = [w for _, w in times[label]]
        med[label] = statistics.median(cpu)
        print(f"TC GMIKF ({info['n_states'][0]} + {info['n_states'][1] - info['n_states'][0]} "
              f"states) {label:14s}: CPU median {med[label]:.2f} s best {min(cpu):.2f} s | "
              f"wall median {statistics.median(wall):.2f} s best {min(wall):.2f} s | "
              f"{n_imu / med[label]:,.0f} IMU epochs/CPU s, {duration / med[label]:.0f}x real "
              f"time")
    if len(workers) == 2:
        ref, this = list(workers)
        per_round = [b[0] / a[0] for a, b in zip(times[ref], times[this], strict=True)]
        print(f"CPU ratio {this}/{ref}: median of medians {med[this] / med[ref]:.3f}, per "
              f"round {min(per_round):.3f}-{max(per_round):.3f} ({args.rounds} rounds, A/B "
              "interleaved)")
        saved = {label: folder / f"records-{i}.npz" for i, label in enumerate(workers)}
        for label, w in workers.items():
            w.ask(f"save {saved[label]}")
        a, b = (np.load(saved[label]) for label in (ref, this))
        same_t = a["t"].shape == b["t"].shape and np.array_equal(a["t"], b["t"])
        dx = ab.max_state_difference(b["x"], a["x"])
        print(f"records {this} vs {ref}: same epochs {same_t}, max |x_this - x_ref| {dx:.3e} "
              f"(heading wrapped), fix flags equal {np.array_equal(a['fixed'], b['fixed'])}")
    for w in workers.values():
        w.close()


if __name__ == "__main__":
    main()
