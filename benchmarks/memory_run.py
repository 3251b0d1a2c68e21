"""Peak memory of `gmis run` against drive duration (issue 18: flat is the goal).

    python benchmarks/memory_run.py [--minutes 10 60 180] [--work DIR] [--command run]

For each duration the default drive's moving part is repeated to that length (100 Hz IMU,
benchmarks/bench_gmikf.long_scenario), simulated once into WORK/<minutes>min, and
``python3 -m gmis <command> RECIPE -o OUT --quiet`` runs in a child process. Printed per
duration: epochs, the child's peak RSS (os.wait4 → ru_maxrss), its CPU (user + sys) and
wall time, bytes written to the results folder and per hour of data, and the RSS growth per
epoch between consecutive durations.
"""

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.bench_gmikf import long_scenario
from gmis.simulate import simulate_scenario


def folder_bytes(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def measure(cmd, env):
    """(peak RSS bytes, CPU s, wall s) of one child."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
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
    args = ap.parse_args()
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    prev = None
    for minutes in args.minutes:
        folder = args.work / f"{minutes:g}min"
        recipe = folder / "recipe.toml"
        if not recipe.exists():
            c0 = time.process_time()
            simulate_scenario(long_scenario(minutes), folder, overwrite=True)
            print(f"simulated {minutes:g} min in CPU {time.process_time() - c0:.1f} s")
        out = args.work / f"out-{args.command}-{minutes:g}min"
        shutil.rmtree(out, ignore_errors=True)
        rss, cpu, wall = measure([sys.executable, "-m", "gmis", args.command, str(recipe),
                                  "-o", str(out), "--quiet"], env)
        n_epochs = int(minutes * 60 * 100)
        written = folder_bytes(out)
        line = (f"gmis {args.command} {minutes:6g} min ({n_epochs} IMU epochs): peak RSS "
                f"{rss / 2**20:7.0f} MiB, CPU {cpu:6.1f} s, wall {wall:6.1f} s, written "
                f"{written / 2**20:6.0f} MiB ({written / 2**20 * 60 / minutes:.0f} MiB per h)")
        if prev is not None:
            line += f", +{(rss - prev[0]) / (n_epochs - prev[1]):.0f} B RSS per epoch"
        print(line, flush=True)
        prev = (rss, n_epochs)


if __name__ == "__main__":
    main()
