"""`gmis batch` on a dask LocalCluster against the same jobs one after another (issue 18).

    python benchmarks/bench_batch.py [--seeds 8] [--workers 2] [--scenario default]
                                     [--work DIR]

The jobs: Monte Carlo seeds 1..N of the scenario (simulate, then `gmis run`), plus one job
made to fail (a recipe that does not exist). Runs them serially in this process and on
LocalCluster(workers), prints per mode the wall time, the CPU time (this process + its
children: the cluster's worker processes) and the sum of the jobs' own CPU, the wall ratio,
whether every job's folder is identical between the two modes
(benchmarks/compare_outputs.py, summary timings ignored) and the failing job's line.
"""

import argparse
import contextlib
import io
import resource
import shutil
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.compare_outputs import compare
from gmis.batch import Job, run_batch


def _cpu():
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scenario", default="default")
    ap.add_argument("--work", type=Path, default=Path("/tmp/gmis-bench-batch"))
    args = ap.parse_args()
    shutil.rmtree(args.work, ignore_errors=True)
    jobs = [Job(f"mc-seed{s}", "simulate", scenario=args.scenario, seed=s, then="run")
            for s in range(1, args.seeds + 1)]
    jobs.append(Job("made-to-fail", "run", recipe=str(args.work / "missing" / "recipe.toml")))
    out = {}
    for mode in ("serial", "dask"):
        c0, w0 = _cpu(), time.perf_counter()
        rows = run_batch(jobs=jobs, output=args.work / mode, serial=mode == "serial",
                         workers=args.workers)
        wall, cpu = time.perf_counter() - w0, _cpu() - c0
        job_cpu = sum(r["cpu_s"] for r in rows if r["status"] == "ok")
        ok = sum(r["status"] == "ok" for r in rows)
        print(f"{mode:6s}: {ok} of {len(rows)} jobs ok, wall {wall:7.1f} s, CPU (process + "
              f"children) {cpu:7.1f} s, jobs' own CPU {job_cpu:7.1f} s", flush=True)
        out[mode] = (rows, wall)
    (rs, ws), (rd, wd) = out["serial"], out["dask"]
    same = []
    for a, b in zip(rs, rd):
        if a["status"] == "ok" and b["status"] == "ok":
            with contextlib.redirect_stdout(io.StringIO()):
                same.append(compare(Path(a["folder"]), Path(b["folder"]), tol=0.0))
    print(f"wall ratio dask / serial: {wd / ws:.3f} ({args.workers} workers)")
    print(f"job folders identical: {sum(same)} of {len(same)}; h RMS per seed (m): "
          + ", ".join(f"{r.get('h_rms_m', float('nan')):.4f}" for r in rd if r["status"] == "ok"))
    for r in rd:
        if r["status"] != "ok":
            print(f"failed job reported: {r['name']}: {r['error']}")
    return 0 if all(same) and len(same) == args.seeds else 1


if __name__ == "__main__":
    sys.exit(main())
