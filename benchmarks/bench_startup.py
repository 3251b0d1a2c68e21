"""Start-up and whole-run cost of `gmis`, this tree against a reference commit, A/B
interleaved, CPU time (user + sys of the child process) and wall time side by side.

    python benchmarks/bench_startup.py [--reference b36893a] [--rounds 5] [--no-cold]
                                       [--bytecode]

Each figure is one fresh ``python3`` process per round, run alternately with PYTHONPATH
at the reference tree (``git archive COMMIT gmis gnss vce`` unpacked under
~/.cache/gmis-bench, numba cache beside it) and at this tree:

- ``import gmis.pipeline``;
- the run stack: everything ``gmis run`` imports before it computes (prepare_run,
  run_prepared, navigation_solution, the writers and statistics);
- ``gmis --help``;
- ``gmis run default`` on the embedded default drive (simulated once into a work folder
  both trees share), numba cache warm;
- unless --no-cold: ``gmis run default`` once per tree with an empty NUMBA_CACHE_DIR, the
  cost of a cold numba cache (all kernels compiled).
Medians and best over the rounds, and the CPU ratio this/reference. --bytecode lets the
children write and use .pyc files even when PYTHONDONTWRITEBYTECODE is set (an installed
package has them; without, every gmis module is compiled from source in every process).
"""

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from benchmarks.reference_kernel import reference_tree

RUN_STACK = ("from gmis.pipeline import prepare_run, run_prepared, navigation_solution; "
             "import gmis.run_writers, gmis.run_statistics, gmis.results")


BYTECODE = {"allowed": False}   # --bytecode


def child(tree: Path, args, cwd: Path, env_extra=None):
    """(CPU s, wall s) of one python3 child with PYTHONPATH=tree."""
    env = dict(os.environ, PYTHONPATH=str(tree), **(env_extra or {}))
    if BYTECODE["allowed"]:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, *args], cwd=cwd, env=env, capture_output=True,
                         text=True, check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if out.returncode != 0:
        raise SystemExit(f"{args} failed in {tree}:\n{out.stderr[-2000:]}")
    return (after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime), wall


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", default="b36893a")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--no-cold", action="store_true")
    ap.add_argument("--bytecode", action="store_true",
                    help="children write/use .pyc despite PYTHONDONTWRITEBYTECODE")
    args = ap.parse_args()
    BYTECODE["allowed"] = args.bytecode
    trees = {f"ref@{args.reference}": reference_tree(args.reference), "this": REPO}
    work = Path(tempfile.mkdtemp(prefix="gmis-startup-"))
    counter = iter(range(10 ** 6))

    def run_default(tree, env_extra=None):
        return child(tree, ["-m", "gmis", "run", "default", "-o",
                            str(work / f"out-{next(counter)}"), "--quiet"], work, env_extra)

    cases = {
        "import gmis.pipeline": lambda tree: child(tree, ["-c", "import gmis.pipeline"], work),
        "import run stack": lambda tree: child(tree, ["-c", RUN_STACK], work),
        "gmis --help": lambda tree: child(tree, ["-m", "gmis", "--help"], work),
        "gmis run default (warm)": run_default,
    }
    for tree in trees.values():                      # dataset + numba caches
        run_default(tree)
    results = {(c, t): [] for c in cases for t in trees}
    for _ in range(args.rounds):
        for case, fn in cases.items():
            for label, tree in trees.items():
                results[case, label].append(fn(tree))
    ref_label = next(iter(trees))
    for case in cases:
        med = {}
        for label in trees:
            cpu = [c for c, _ in results[case, label]]
            wall = [w for _, w in results[case, label]]
            med[label] = statistics.median(cpu)
            print(f"{case:26s} {label:14s} CPU median {med[label]:.3f} s best {min(cpu):.3f} s"
                  f" | wall median {statistics.median(wall):.3f} s best {min(wall):.3f} s")
        print(f"{case:26s} CPU ratio this/{ref_label}: {med['this'] / med[ref_label]:.2f}")
    if not args.no_cold:
        for label, tree in trees.items():
            cold = Path(tempfile.mkdtemp(prefix="numba-cold-"))
            cpu, wall = run_default(tree, {"NUMBA_CACHE_DIR": str(cold)})
            cpu2, wall2 = run_default(tree, {"NUMBA_CACHE_DIR": str(cold)})
            print(f"gmis run default, cold numba cache {label:14s}: CPU {cpu:.2f} s (wall "
                  f"{wall:.2f} s); same cache warm next run: CPU {cpu2:.2f} s (wall "
                  f"{wall2:.2f} s)")
            shutil.rmtree(cold, ignore_errors=True)
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
