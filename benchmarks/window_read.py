"""A short [time] window of a long drive (issue 18: "reading restricted to the requested
time window"): `gmis run` of W seconds out of a long simulated drive, this tree against a
reference checkout that parses the whole files, in the same invocation.

    python benchmarks/window_read.py [--minutes 180] [--work DIR] [--window-s 10]
                                     [--ref CHECKOUT] [--rounds 3]

The drive is benchmarks/memory_run.py's (WORK/<minutes>min, simulated once and kept). The
window starts in the middle of the drive; its recipe (the drive's, [time] changed, paths
absolute) is written to a temporary folder. After one warm-up round per tree (numba cache), printed per round and tree: the child's CPU
(user + sys), wall time and peak RSS; at the end the medians, their ratio, and whether
the two trees' solution.csv are byte-identical.
"""

import argparse
import re
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.memory_run import measure, simulate_drive


def window_recipe(drive: Path, start: float, end: float, out: Path) -> Path:
    text = (drive / "recipe.toml").read_text()
    text = re.sub(r"(?m)^start_gps_s = .*$", f"start_gps_s = {start!r}", text)
    text = re.sub(r"(?m)^end_gps_s = .*$", f"end_gps_s = {end!r}", text)
    for key in ("imu", "gnss_solution", "heading", "reference"):
        text = re.sub(rf'(?m)^{key} = "(.*)"$',
                      lambda m, k=key: f'{k} = "{(drive / m.group(1)).as_posix()}"', text)
    out.write_text(text)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=180.0)
    ap.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "gmis-memory")
    ap.add_argument("--window-s", type=float, default=10.0)
    ap.add_argument("--ref", type=Path, default=None,
                    help="a checkout of the reference commit (git worktree add)")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()

    drive = args.work / f"{args.minutes:g}min"
    if not (drive / "recipe.toml").exists():
        print(f"simulating {drive} ...", flush=True)
        simulate_drive(args.minutes, 100.0, drive)
    text = (drive / "recipe.toml").read_text()
    t0 = float(re.search(r"(?m)^start_gps_s = (.*)$", text).group(1))
    t1 = float(re.search(r"(?m)^end_gps_s = (.*)$", text).group(1))
    mid = round(0.5 * (t0 + t1), 2)
    size = sum((drive / f).stat().st_size for f in ("imu.csv", "reference.csv"))
    print(f"drive {drive} ({(t1 - t0) / 60:.0f} min, IMU + reference text "
          f"{size / 2**20:.0f} MiB); window {mid}..{mid + args.window_s} s")
    trees = {"this": Path(__file__).resolve().parents[1]}
    if args.ref is not None:
        trees["ref"] = args.ref.resolve()
    results = {name: [] for name in trees}
    with tempfile.TemporaryDirectory(prefix="gmis-window-") as tmp:
        tmp = Path(tmp)
        recipe = window_recipe(drive, mid, mid + args.window_s, tmp / "recipe.toml")
        for r in range(-1, args.rounds):          # round 0: warm-up (numba cache), not kept
            for name, tree in trees.items():
                out = tmp / f"out-{name}-{r + 1}"
                cmd = [sys.executable, "-m", "gmis", "run", str(recipe), "-o", str(out),
                       "--quiet"]
                env = {"PYTHONPATH": str(tree), "PATH": "/usr/bin:/bin",
                       "HOME": str(Path.home())}
                rss, cpu, wall = measure(cmd, env, tree)
                if r < 0:
                    continue
                results[name].append((cpu, wall, rss))
                print(f"round {r + 1} {name:4s}: CPU {cpu:6.2f} s  wall {wall:6.2f} s  "
                      f"peak RSS {rss / 2**20:6.0f} MiB", flush=True)
        same = None
        if "ref" in trees:
            a = (tmp / "out-this-0" / "solution.csv").read_bytes()
            b = (tmp / "out-ref-0" / "solution.csv").read_bytes()
            same = a == b
    print()
    for name, rows in results.items():
        cpu = statistics.median(r[0] for r in rows)
        wall = statistics.median(r[1] for r in rows)
        rss = max(r[2] for r in rows)
        print(f"{name:4s} median CPU {cpu:6.2f} s  wall {wall:6.2f} s  peak RSS "
              f"{rss / 2**20:.0f} MiB")
    if "ref" in results:
        ratio = statistics.median(r[0] for r in results["this"]) / \
            statistics.median(r[0] for r in results["ref"])
        print(f"CPU ratio this / ref {ratio:.3f}; solution.csv byte-identical: {same}")


if __name__ == "__main__":
    main()
