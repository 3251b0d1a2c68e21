"""Per-epoch cost of `gmis rtk` (gnss.rtk.process_rtk) on the shared 0759 (base) / 3040
(rover) session, start-up and RINEX reading removed, beside RTKLIB's rnx2rtkp.

    python benchmarks/bench_rtk.py [--rounds 5] [--frequencies L1L2|L1]

gmis: the observation and navigation files are read once (timed once), then process_rtk
(SPP of the rover, double differences, slip flags, float filter, LAMBDA, hold) runs
--rounds times in this process after one warm-up; printed: CPU time (time.process_time,
median and best) with wall time beside it, and ms per epoch. RTKLIB: rnx2rtkp with the
settings of tests/rtklib_reference.run_rnx2rtkp, --rounds times, CPU time of the child
process (getrusage; it includes the process start and its RINEX reading, so RTKLIB's
per-epoch figure is an upper bound). The CPU ratio gmis/RTKLIB uses the medians. On a
loaded machine run both in the same invocation (they alternate).
"""

import argparse
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

DATASET_RECIPE = REPO / "datasets" / "rtklib-0759-3040" / "recipe.toml"


def child_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def main() -> None:
    import shutil

    from benchmarks.rtk_vs_rtklib import single_frequency_recipe
    from gmis.rtk_job import read_rtk_recipe
    from gnss.rinex import read_nav, read_obs
    from gnss.rtk import process_rtk
    from tests.rtklib_reference import run_rnx2rtkp
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--frequencies", choices=("L1L2", "L1"), default="L1L2")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_rtk_"))
    inp = read_rtk_recipe(DATASET_RECIPE)
    n_freq = 2 if args.frequencies == "L1L2" else 1
    if n_freq == 1:
        inp = read_rtk_recipe(single_frequency_recipe(inp, tmp))
    c0 = time.process_time()
    base, rover, nav = read_obs(inp["base_obs"]), read_obs(inp["rover_obs"]), \
        read_nav(inp["nav"])
    t_read = time.process_time() - c0
    sol = process_rtk(base, rover, nav, inp["base_ecef"], inp["config"])   # warm-up
    n_ep = int(sol.t_gps.size)
    have_rtklib = shutil.which("rnx2rtkp") is not None
    gm, rl = [], []
    for _ in range(args.rounds):
        c0, t0 = time.process_time(), time.perf_counter()
        process_rtk(base, rover, nav, inp["base_ecef"], inp["config"])
        gm.append((time.process_time() - c0, time.perf_counter() - t0))
        if have_rtklib:
            c0 = child_cpu()
            wall = run_rnx2rtkp(inp["rover_obs"], inp["base_obs"], inp["nav"],
                                inp["base_ecef"], tmp / "rtklib.pos", n_frequencies=n_freq)
            rl.append((child_cpu() - c0, wall))
    print(f"session {DATASET_RECIPE.parent.name}, {args.frequencies}: {n_ep} epochs; gmis "
          f"RINEX reading {t_read:.2f} s CPU (once, not counted)")
    med = {}
    for name, times in (("gmis process_rtk", gm), ("RTKLIB rnx2rtkp", rl)):
        if not times:
            print(f"{name}: not available")
            continue
        cpu = [c for c, _ in times]
        med[name] = statistics.median(cpu)
        print(f"{name:17s}: CPU median {med[name]:.3f} s best {min(cpu):.3f} s | wall median "
              f"{statistics.median(w for _, w in times):.3f} s | {1e3 * med[name] / n_ep:.2f} "
              f"ms/epoch CPU (best {1e3 * min(cpu) / n_ep:.2f})")
    if len(med) == 2:
        print(f"CPU ratio gmis/RTKLIB (medians, {args.rounds} rounds alternated): "
              f"{med['gmis process_rtk'] / med['RTKLIB rnx2rtkp']:.2f}")
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
