"""gmis RTK (gnss.rtk) versus RTKLIB rnx2rtkp on the 0759 (base) / 3040 (rover) session.

Settings on both sides: kinematic, GPS L1+L2, elevation mask 15°, continuous AR (RTKLIB's
default AR mode in rnx2rtkp; gmis: float ambiguity filter + held integers), ratio 3.0,
base position = 0759 header APPROX POSITION (ECEF).
RTKLIB: rnx2rtkp -p 2 -f 2 -m 15 -v 3.0 -sys G -r X Y Z (this Debian build rejected
pos1-frequency=l1+l2 in a config file; -f 2 on the command line works).

Prints the fix rate of each, the horizontal/vertical differences between epochs fixed by
both (median, 95th percentile of |Δ|, mean Δ ENU), and wall times (RTKLIB process; gmis
in-process run_rtk_recipe incl. RINEX reading, and a fresh Python process calling
run_rtk_recipe, i.e. what `gmis rtk` costs incl. interpreter start and imports) and ratios.

Single frequency (--frequencies L1): gmis with [rtk] frequencies = ["L1"] (C2/L2 dropped as
an L1-only receiver records them) against rnx2rtkp -f 1 (L1 only), same other settings;
also prints the share of commonly fixed epochs within 1 cm (3-D) of RTKLIB.

Run:  python benchmarks/rtk_vs_rtklib.py  [--repeat 3] [--frequencies L1|L1L2]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gmis.rtk_job import read_rtk_recipe, run_rtk_recipe
from gnss.geodesy import ecef_to_enu_matrix, ecef_to_geodetic, geodetic_to_ecef
from gnss.pos_file import read_pos
from gnss.rtk import Q_FIXED
from tests.rtklib_reference import run_rnx2rtkp

DATASET_RECIPE = REPO / "datasets" / "rtklib-0759-3040" / "recipe.toml"


def run_rtklib(inp: dict, out: Path, n_frequencies: int) -> float:
    return run_rnx2rtkp(inp["rover_obs"], inp["base_obs"], inp["nav"], inp["base_ecef"], out,
                        n_frequencies=n_frequencies)


def single_frequency_recipe(inp: dict, folder: Path) -> Path:
    """The dataset recipe with its data paths made absolute and [rtk] frequencies = ["L1"]."""
    text = DATASET_RECIPE.read_text()
    for key in ("rover_obs", "base_obs", "nav"):
        rel = next(line.split("=", 1)[1].strip() for line in text.splitlines()
                   if line.startswith(key))
        text = text.replace(rel, f'"{Path(inp[key]).as_posix()}"')
    path = folder / "recipe_l1.toml"
    path.write_text(text + '\n[rtk]\nfrequencies = ["L1"]\n')
    return path


def enu(llh: np.ndarray, origin: np.ndarray) -> np.ndarray:
    x = np.array([geodetic_to_ecef(*p) for p in llh])
    lat, lon, _ = ecef_to_geodetic(*origin)
    return (x - origin) @ ecef_to_enu_matrix(lat, lon).T


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="timing repetitions (best kept)")
    ap.add_argument("--frequencies", choices=("L1L2", "L1"), default="L1L2")
    args = ap.parse_args()
    if shutil.which("rnx2rtkp") is None:
        sys.exit("rnx2rtkp (Debian package rtklib) not found")
    inp = read_rtk_recipe(DATASET_RECIPE)
    tmp = Path(tempfile.mkdtemp(prefix="rtk_bench_"))
    n_freq = 1 if args.frequencies == "L1" else 2
    recipe = single_frequency_recipe(inp, tmp) if n_freq == 1 else DATASET_RECIPE
    inp = read_rtk_recipe(recipe)
    print(f"frequencies: gmis {list(inp['config'].frequencies)}, RTKLIB -f {n_freq}")
    t_rtklib = min(run_rtklib(inp, tmp / "rtklib.pos", n_freq) for _ in range(args.repeat))
    t_gmis = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        summary = run_rtk_recipe(recipe, tmp / "gmis")
        t_gmis.append(time.perf_counter() - t0)
    t_proc = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        code = ("import sys; from gmis.rtk_job import run_rtk_recipe; "
                "run_rtk_recipe(sys.argv[1], sys.argv[2])")
        subprocess.run([sys.executable, "-c", code, str(recipe), str(tmp / "gmis_proc")],
                       check=True, cwd=REPO)
        t_proc.append(time.perf_counter() - t0)
    g = read_pos(tmp / "gmis" / "rtk.pos")
    r = read_pos(tmp / "rtklib.pos")
    n_ep = summary["epochs"]
    print(f"epochs in session: {n_ep}; gmis troposphere model: {inp['config'].troposphere} "
          f"(RTKLIB: Saastamoinen, its default)")
    for name, p in (("gmis", g), ("RTKLIB", r)):
        nfix = int((p["q"] == Q_FIXED).sum())
        print(f"{name:7s}: {p['q'].size:4d} epochs output, {nfix:4d} fixed -> fix rate "
              f"{nfix / n_ep:.3f} of all epochs, {nfix / max(p['q'].size, 1):.3f} of output")
    j = np.clip(np.searchsorted(r["t_gps"], g["t_gps"]), 0, r["t_gps"].size - 1)
    jm = np.clip(j - 1, 0, r["t_gps"].size - 1)
    j = np.where(np.abs(r["t_gps"][jm] - g["t_gps"]) < np.abs(r["t_gps"][j] - g["t_gps"]), jm, j)
    both = (np.abs(r["t_gps"][j] - g["t_gps"]) < 0.5) & (g["q"] == Q_FIXED) & \
           (r["q"][j] == Q_FIXED)
    base = np.asarray(inp["base_ecef"])
    d = enu(g["llh"][both], base) - enu(r["llh"][j[both]], base)
    dh = np.hypot(d[:, 0], d[:, 1])
    dv = np.abs(d[:, 2])
    print(f"epochs fixed by both: {both.sum()}")
    print(f"horizontal |Δ| gmis−RTKLIB: median {1e3 * np.median(dh):.1f} mm, "
          f"95% {1e3 * np.percentile(dh, 95):.1f} mm")
    print(f"vertical   |Δ| gmis−RTKLIB: median {1e3 * np.median(dv):.1f} mm, "
          f"95% {1e3 * np.percentile(dv, 95):.1f} mm")
    print(f"mean Δ ENU (mm): {np.round(1e3 * d.mean(axis=0), 1).tolist()}")
    d3 = np.linalg.norm(d, axis=1)
    print(f"3-D |Δ|: 95% {1e3 * np.percentile(d3, 95):.1f} mm, max {1e3 * d3.max():.1f} mm, "
          f"share within 1 cm {np.mean(d3 < 0.01):.3f}")
    for name, p, sel in (("gmis", g, both), ("RTKLIB", r, j[both])):
        fx = p["q"] == Q_FIXED
        e = enu(p["llh"][fx], base)
        ec = enu(p["llh"][sel], base)
        print(f"{name:7s} fixed ENU baseline: all fixed ({fx.sum()}) mean (m) "
              f"{np.round(e.mean(axis=0), 4).tolist()} std (mm) "
              f"{np.round(1e3 * e.std(axis=0), 1).tolist()}; common epochs std (mm) "
              f"{np.round(1e3 * ec.std(axis=0), 1).tolist()}")
    print(f"wall time (best of {args.repeat}): RTKLIB {t_rtklib:.3f} s, gmis in-process "
          f"{min(t_gmis):.3f} s (ratio {min(t_gmis) / t_rtklib:.1f}x), gmis fresh "
          f"interpreter {min(t_proc):.3f} s (ratio {min(t_proc) / t_rtklib:.1f}x)")
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
