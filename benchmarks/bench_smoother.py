"""Cost of the two-filter smoother (issue 15): CPU time of `gmis run` with and without
--smooth, interleaved A/B in fresh processes (process time of run_recipe, peak RSS), on a
simulated drive of --minutes (default 60) at 100 Hz: the default scenario's motion
repeated after its 300 s static alignment.

    PYTHONPATH=. python3 benchmarks/bench_smoother.py [--minutes 60] [--repeats 2]
"""

import argparse
import copy
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from gmis.simulate import default_scenario_path, load_scenario, simulate_scenario

CHILD = """
import json, resource, sys, time
from gmis.pipeline import run_recipe
c0 = time.process_time()
s = run_recipe(sys.argv[1], sys.argv[2], smooth=sys.argv[3] == "1")
cpu = time.process_time() - c0
print(json.dumps({"cpu_s": cpu, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "epochs": s["epochs"], "smoother": s.get("smoother")}))
"""


def long_scenario(minutes: float):
    scn = copy.deepcopy(load_scenario(default_scenario_path()))
    align, motion = scn["segment"][0], scn["segment"][1:]
    segments, total = [align], align["duration_s"]
    while total < minutes * 60.0 - 300.0:
        segments += copy.deepcopy(motion)
        total += 300.0
    scn["segment"] = segments
    scn["gnss"]["outage"] = []
    return scn


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        sim = simulate_scenario(long_scenario(args.minutes), root / "dataset")
        rows = []
        for rep in range(args.repeats):
            for smooth in (0, 1):
                out = subprocess.run([sys.executable, "-c", CHILD, str(sim.recipe_path),
                                      str(root / f"res{rep}{smooth}"), str(smooth)],
                                     capture_output=True, text=True, check=True)
                row = json.loads(out.stdout.strip().splitlines()[-1])
                row["smooth"] = bool(smooth)
                rows.append(row)
                print(f"repeat {rep} {'smoothed' if smooth else 'forward '}: CPU "
                      f"{row['cpu_s']:.1f} s, peak RSS {row['peak_rss_mb']:.0f} MB, "
                      f"{row['epochs']} epochs", flush=True)
    fwd = min(r["cpu_s"] for r in rows if not r["smooth"])
    smo = min(r["cpu_s"] for r in rows if r["smooth"])
    sm = next(r for r in rows if r["smooth"])["smoother"]
    print(f"best CPU: forward {fwd:.1f} s, smoothed {smo:.1f} s, ratio {smo / fwd:.2f}; "
          f"smoother forward+backward+combination {sm['cpu_s_forward_backward']:.1f} s; "
          f"spool {sm['spool_bytes_per_output_epoch']} B per output epoch "
          f"({sm['output_epochs']} output epochs at {sm['output_rate_hz']} Hz)")


if __name__ == "__main__":
    main()
