"""Tightly coupled GMIKF WITHOUT IMU (gmis.tc_gnss_only) versus RTKLIB rnx2rtkp on the
0759 (base) / 3040 (rover) session — the real-data check of the TC DD models, SD
ambiguity states, LAMBDA + ratio + χ² protection and fix-and-hold. The files have no IMU
(and no Doppler): the GMIKF's kinematic model is propagated between the 30 s epochs and
updated by DD code/L1/L2 rows only.

Settings: kinematic, GPS L1+L2, elevation mask 15°, ratio 3.0, base = 0759 header APPROX
POSITION. RTKLIB: rnx2rtkp -p 2 -f 2 -m 15 -v 3.0 -sys G -t -r X Y Z (as
benchmarks/rtk_vs_rtklib.py).

Prints fix rates (TC, RTKLIB, gnss.rtk), over the epochs fixed by TC and RTKLIB the median
and 95th percentile of the 3D / horizontal / vertical difference and the mean Δ ENU —
for the TC run with the differential hydrostatic troposphere correction (the default;
RTKLIB's relative mode applies it) and without it — the scatter (std) of each solution's
fixed positions about their mean (the rover is static), their offset from the rover's
RINEX header position (an approximate coordinate, not a surveyed reference), and wall
times (warm, RINEX reading excluded for the filters).

Run:  python benchmarks/tc_vs_rtklib.py
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gmis.earth import ecef_to_enu, geodetic_to_ecef
from gmis.rtk_job import read_rtk_recipe
from gmis.tc_gnss_only import compare_fixed_epochs, run_tight_without_imu
from gnss.pos_file import read_pos
from gnss.rinex import read_nav, read_obs
from gnss.rtk import Q_FIXED, process_rtk
from tests.rtklib_reference import run_rnx2rtkp

RECIPE = REPO / "datasets" / "rtklib-0759-3040" / "recipe.toml"


def run_rtklib(inp: dict, out: Path) -> float:
    return run_rnx2rtkp(inp["rover_obs"], inp["base_obs"], inp["nav"], inp["base_ecef"], out)


def mm(v) -> str:
    return str(np.round(1e3 * np.asarray(v, float), 1).tolist())


def print_comparison(label: str, c: dict) -> None:
    print(f"{label}: epochs fixed by both {c['n_common']}")
    print(f"   3D  |Δ| median {1e3 * c['median_3d']:.1f} mm, 95% {1e3 * c['p95_3d']:.1f} mm")
    print(f"   hor |Δ| median {1e3 * c['median_h']:.1f} mm, 95% {1e3 * c['p95_h']:.1f} mm")
    print(f"   ver |Δ| median {1e3 * c['median_v']:.1f} mm, 95% {1e3 * c['p95_v']:.1f} mm")
    print(f"   mean Δ ENU (mm) {mm(c['mean_enu'])}")


def main() -> None:
    if shutil.which("rnx2rtkp") is None:
        sys.exit("rnx2rtkp (Debian package rtklib) not found")
    inp = read_rtk_recipe(RECIPE)
    tmp = Path(tempfile.mkdtemp(prefix="tc_bench_"))
    t_rtklib = run_rtklib(inp, tmp / "rtklib.pos")
    rover, base = read_obs(inp["rover_obs"]), read_obs(inp["base_obs"])
    nav = read_nav(inp["nav"])
    run_tight_without_imu(rover, base, nav, inp["base_ecef"])       # warm-up (numba cache)
    t0 = time.perf_counter()
    tc = run_tight_without_imu(rover, base, nav, inp["base_ecef"])
    t_tc = time.perf_counter() - t0
    tc_notrop = run_tight_without_imu(rover, base, nav, inp["base_ecef"],
                                      hydrostatic_troposphere=False)
    t0 = time.perf_counter()
    rtk = process_rtk(base, rover, nav, inp["base_ecef"], inp["config"])
    t_rtk = time.perf_counter() - t0
    frame = tc.frame
    r = read_pos(tmp / "rtklib.pos")
    r_enu = np.array([ecef_to_enu(frame, geodetic_to_ecef(*p)) for p in r["llh"]])
    r_fix = r["q"] == Q_FIXED
    rtk_enu = np.array([ecef_to_enu(frame, x) if np.all(np.isfinite(x)) else np.full(3, np.nan)
                        for x in rtk.ecef])
    rtk_fix = rtk.q == Q_FIXED
    n_ep = tc.t_gps.size
    print("IMU ABSENT: tightly coupled GMIKF = kinematic model + DD code/L1/L2 updates "
          f"(Doppler: {'present' if np.isfinite(rover.D1).any() else 'absent in the files'})")
    print(f"GNSS epochs: {n_ep}")
    for name, fx, n_out in (("TC (no IMU)", tc.fixed, n_ep), ("RTKLIB", r_fix, r["q"].size),
                            ("gnss.rtk", rtk_fix, int((rtk.q > 0).sum()))):
        print(f"{name:12s}: {n_out:4d} epochs output, {int(fx.sum()):4d} fixed -> fix rate "
              f"{fx.sum() / n_ep:.3f} of all epochs")
    print(f"TC fixes rejected by the χ² wrong-fix test: {int(tc.fix_rejected.sum())}")
    print_comparison("TC − RTKLIB (hydrostatic troposphere corrected, default)",
                     compare_fixed_epochs(tc.t_gps, tc.enu, tc.fixed, r["t_gps"], r_enu, r_fix))
    print_comparison("TC − RTKLIB (troposphere assumed to cancel)",
                     compare_fixed_epochs(tc_notrop.t_gps, tc_notrop.enu, tc_notrop.fixed,
                                          r["t_gps"], r_enu, r_fix))
    print_comparison("gnss.rtk − RTKLIB (troposphere assumed to cancel)",
                     compare_fixed_epochs(rtk.t_gps, rtk_enu, rtk_fix, r["t_gps"], r_enu,
                                          r_fix))
    print_comparison("TC (troposphere assumed to cancel) − gnss.rtk",
                     compare_fixed_epochs(tc_notrop.t_gps, tc_notrop.enu, tc_notrop.fixed,
                                          rtk.t_gps, rtk_enu, rtk_fix))
    header = ecef_to_enu(frame, rover.approx_position_ecef) \
        if rover.approx_position_ecef is not None else None
    print("static-point constancy of the fixed positions (std about their mean, mm) and "
          "mean − rover header APPROX POSITION (mm):")
    for name, e, fx in (("TC (no IMU)", tc.enu, tc.fixed), ("TC no trop", tc_notrop.enu,
                                                             tc_notrop.fixed),
                        ("RTKLIB", r_enu, r_fix), ("gnss.rtk", rtk_enu, rtk_fix)):
        m = e[fx].mean(axis=0)
        extra = f", mean − header {mm(m - header)}" if header is not None else ""
        t_sol = r["t_gps"] if name == "RTKLIB" else (rtk.t_gps if name == "gnss.rtk"
                                                      else tc.t_gps)
        common = fx & np.isin(np.round(t_sol), np.round(r["t_gps"][r_fix]))
        print(f"   {name:12s} n={int(fx.sum()):3d} std ENU {mm(e[fx].std(axis=0))}; on the "
              f"{int(common.sum())} RTKLIB-fixed epochs {mm(e[common].std(axis=0))}{extra}")
    print(f"wall time (warm, RINEX reading excluded): TC (no IMU) {t_tc:.3f} s, gnss.rtk "
          f"{t_rtk:.3f} s; RTKLIB process incl. reading {t_rtklib:.3f} s")
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
