"""ErrINSEKF throughput on a 1-hour, 100-Hz simulated road test (IMU epochs per second).

The dataset is the embedded default scenario (IMU440-class, 5 Hz GNSS position/velocity,
5 Hz heading) with its moving part repeated until the run lasts ``--hours`` hours, simulated
by gmis.simulate into a temporary folder and read back through gmis.pipeline.prepare_run
(the same path `gmis run` takes). Timed: the ErrINSEKF epoch loop (run_errins_prepared),
best of ``--repeats`` runs after one warm-up run (numba compilation/cache load); the GMIKF
on the same PreparedRun once for comparison (``--no-gmikf`` to skip).

Run:  python benchmarks/bench_errins.py [--hours 1.0] [--repeats 2] [--no-gmikf]
"""

from __future__ import annotations

import argparse
import copy
import tempfile
import time

import numpy as np

from gmis.errins import run_errins_prepared
from gmis.pipeline import prepare_run, run_prepared
from gmis.recipe import load_recipe
from gmis.simulate import load_scenario, scenario_path, simulate_scenario


def long_scenario(hours: float):
    sc = copy.deepcopy(load_scenario(scenario_path("default")))
    first, moving = sc["segment"][0], sc["segment"][1:]
    one = sum(s.get("duration_s", 0.0) for s in moving) + 60.0   # rough length of a lap
    laps = max(1, int(np.ceil((hours * 3600.0 - first["duration_s"]) / one)))
    sc["segment"] = [first] + moving * laps
    sc["gnss"]["outage"] = []
    sc["heading"]["outage"] = []
    return sc


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--no-gmikf", action="store_true")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        res = simulate_scenario(long_scenario(args.hours), f"{tmp}/ds")
        t1 = time.perf_counter()
        prep = prepare_run(load_recipe(res.recipe_path))
        t2 = time.perf_counter()
        n_imu = int((prep.epochs.imu >= 0).sum())
        span = float(prep.dataset.imu.t[-1] - prep.dataset.imu.t[0])
        print(f"dataset: {span / 3600:.2f} h, {n_imu} IMU epochs, {len(prep.epochs)} epochs "
              f"(simulate {t1 - t0:.1f} s, read+prepare {t2 - t1:.1f} s)")
        tw = time.perf_counter()
        run_errins_prepared(prep)
        print(f"ErrINSEKF warm-up (incl. numba compile/cache load): {time.perf_counter() - tw:.2f} s")
        best = np.inf
        for _ in range(max(1, args.repeats)):
            ts = time.perf_counter()
            rec = run_errins_prepared(prep)
            best = min(best, time.perf_counter() - ts)
        print(f"ErrINSEKF: {best:.2f} s  ->  {n_imu / best:,.0f} IMU epochs/s, "
              f"{span / best:,.0f}x real time")
        ref = prep.dataset.reference
        if ref is not None:
            from gmis.pipeline import geodetic_to_enu_rows
            enu = geodetic_to_enu_rows(prep.frame, np.ascontiguousarray(ref.llh))
            m = rec.imu_row >= 0
            err = rec.nav[m, 0:3] - np.column_stack(
                [np.interp(rec.t[m], ref.t, enu[:, i]) for i in range(3)])
            print("ErrINSEKF position RMS vs reference (E, N, U m): "
                  + ", ".join(f"{v:.3f}" for v in np.sqrt((err ** 2).mean(axis=0))))
        if not args.no_gmikf:
            ts = time.perf_counter()
            run_prepared(prep)
            tg = time.perf_counter() - ts
            print(f"GMIKF (same data, incl. any compile): {tg:.2f} s  ->  {n_imu / tg:,.0f} "
                  f"IMU epochs/s")


if __name__ == "__main__":
    main()
