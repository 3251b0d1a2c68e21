"""Peak memory of `gmis run` against drive duration (issue 18: flat is the goal).

    python benchmarks/memory_run.py [--minutes 10 60 180] [--work DIR] [--command run]
                                    [--rate-hz 100] [--ref CHECKOUT] [--smooth]

For each duration the default drive's moving part is repeated to that length
(benchmarks/bench_gmikf.long_scenario, IMU at --rate-hz), simulated once into
WORK/<minutes>min[-<rate>hz], and ``python3 -m gmis <command> RECIPE -o OUT --quiet`` runs
in a child process. Printed per duration: epochs, the child's peak RSS (os.wait4 →
ru_maxrss), its CPU (user + sys) and wall time, bytes written to the results folder and per
hour of data, and the RSS growth per epoch between consecutive durations. With --ref, the
same command of another checkout (e.g. ``git worktree add /tmp/ref <commit>``) runs
right before each measurement of this tree, on the same data, and is printed beside it.
"""

import argparse
import multiprocessing
import os
import shutil
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.bench_gmikf import long_scenario
from gmis.simulate import simulate_scenario


def simulate_drive(minutes: float, rate_hz: float, folder: Path) -> float:
    """Simulate the long drive into folder; returns the CPU seconds it took."""
    c0 = time.process_time()
    doc = long_scenario(minutes)
    doc["scenario"]["imu_rate_hz"] = rate_hz
    simulate_scenario(doc, folder, overwrite=True)
    return time.process_time() - c0


def folder_bytes(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def measure(cmd, env, cwd):
    """(peak RSS bytes, CPU s, wall s) of one child, run in the folder cwd: ``python -m``
    puts the working folder first on sys.path, before PYTHONPATH, so a child started from
    another checkout would import that checkout's gmis."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, cwd=cwd, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode() if proc.stderr else ""
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{cmd} failed:\n{err[-2000:]}")
    return usage.ru_maxrss * 1024, usage.ru_utime + usage.ru_stime, wall


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, nargs="+", default=[10.0, 60.0])
    ap.add_argument("--work", type=Path, default=Path.home() / ".cache" / "gmis-bench" / "memory")
    ap.add_argument("--command", default="run", choices=("run", "vce"))
    ap.add_argument("--rate-hz", type=float, default=100.0, help="IMU rate (default 100)")
    ap.add_argument("--ref", type=Path, default=None,
                    help="another checkout measured beside this one")
    ap.add_argument("--keep", action="store_true", help="keep the results folders")
    ap.add_argument("--smooth", action="store_true",
                    help="`gmis run --smooth` (the two-filter smoother; --command run)")
    args = ap.parse_args()
    trees = [("this", Path(__file__).resolve().parents[1])]
    if args.ref is not None:
        trees.insert(0, ("ref", args.ref.resolve()))
    prev = {}
    for minutes in args.minutes:
        tag = f"{minutes:g}min" + ("" if args.rate_hz == 100.0 else f"-{args.rate_hz:g}hz")
        folder = args.work / tag
        recipe = folder / "recipe.toml"
        if not recipe.exists():
            # in a spawned process: a child forked from this one starts with this
            # process's RSS as its ru_maxrss (not reset by exec), so simulating here would
            # put the simulation's memory into every measurement (3.6 GB for 10 h at 200 Hz)
            with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
                cpu = pool.submit(simulate_drive, minutes, args.rate_hz, folder).result()
            print(f"simulated {tag} in CPU {cpu:.1f} s")
        n_epochs = int(minutes * 60 * args.rate_hz)
        for label, tree in trees:
            env = dict(os.environ, PYTHONPATH=str(tree))
            out = args.work / f"out-{args.command}-{tag}-{label}"
            shutil.rmtree(out, ignore_errors=True)
            smooth = ["--smooth"] if args.smooth else []
            rss, cpu, wall = measure([sys.executable, "-m", "gmis", args.command,
                                      str(recipe), "-o", str(out), "--quiet", *smooth],
                                     env, tree)
            written = folder_bytes(out)
            line = (f"{label:4s} gmis {args.command}{' --smooth' if smooth else ''} {tag:>12s} ({n_epochs} IMU epochs): "
                    f"peak RSS {rss / 2**20:7.0f} MiB, CPU {cpu:6.1f} s, wall {wall:6.1f} s, "
                    f"written {written / 2**20:6.0f} MiB "
                    f"({written / 2**20 * 60 / minutes:.0f} MiB per h)")
            if label in prev and n_epochs != prev[label][1]:
                line += (f", {(rss - prev[label][0]) / (n_epochs - prev[label][1]):+.0f} B "
                         "RSS per epoch")
            print(line, flush=True)
            prev[label] = (rss, n_epochs)
            if not args.keep:
                shutil.rmtree(out, ignore_errors=True)


if __name__ == "__main__":
    main()
