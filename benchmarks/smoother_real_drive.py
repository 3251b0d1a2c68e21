"""Two-filter smoother on a real drive with a GNSS outage schedule (issue 15 acceptance):
per-window and overall horizontal max / RMS and vertical RMS of the antenna position
against the WITHHELD GNSS fixes, forward filter vs smoothed, and the CPU of both.

    PYTHONPATH=. python3 benchmarks/smoother_real_drive.py datasets/drive-boulder-0708/recipe.toml \
        [--count 11 --duration 15] [--outlier-alpha 0.0] [--zupt] [--first-start GPS_S]
        [--estimate-nhc-point] [--nhc-forward M] [--nhc-up M] [--estimate-latency]
        [--repeats N]

Windows: gmis.outages.choose_outage_windows (the schedule of `gmis outages`); GNSS position,
velocity and heading are removed inside them (prepare_run gnss_outages). The smoothed
solution (10 Hz) and the forward solution (every epoch) are interpolated linearly to the
withheld GNSS epochs."""

import argparse
import dataclasses
import time

import numpy as np

from gmis.enu_rows import geodetic_to_enu_rows
from gmis.navigation_solution import navigation_solution
from gmis.outages import choose_outage_windows
from gmis.recipe import NonholonomicSection, ZuptSection, load_recipe
from gmis.run_preparation import prepare_run, run_prepared
from gmis.smoother import run_two_filter, smoothed_records
from gmis.solution_antenna import antenna_solution


def _antenna_at(prep, rec, t_query):
    nav = navigation_solution(prep, rec)
    enu_ant, _ = antenna_solution(prep, rec.t, nav["enu"], nav["euler"])
    return np.column_stack([np.interp(t_query, rec.t, enu_ant[:, i]) for i in range(3)])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("recipe")
    ap.add_argument("--count", type=int, default=11)
    ap.add_argument("--duration", type=float, default=15.0)
    ap.add_argument("--outlier-alpha", type=float, default=None)
    ap.add_argument("--zupt", action="store_true", help="add a default [zupt] table")
    ap.add_argument("--first-start", type=float, default=None, metavar="GPS_S",
                    help="windows at FIRST + k·EVERY (k < count) instead of the evenly spaced "
                         "ones, e.g. 243298.499 with --every 45 (the drive author's schedule)")
    ap.add_argument("--every", type=float, default=45.0, metavar="S")
    ap.add_argument("--states", type=int, choices=(21, 27), default=None)
    ap.add_argument("--nhc", action="store_true", help="add a default [nonholonomic] table")
    ap.add_argument("--estimate-nhc-point", action="store_true",
                    help="[nonholonomic].estimate_lever_arm = true (gmis.nhc_offset_estimation, "
                         "from the GNSS the outage run is given)")
    ap.add_argument("--nhc-forward", type=float, default=None, metavar="M",
                    help="[nonholonomic].lever_arm_m[1] (body forward, m)")
    ap.add_argument("--nhc-up", type=float, default=None, metavar="M",
                    help="[nonholonomic].lever_arm_m[2] (body up, m)")
    ap.add_argument("--estimate-latency", action="store_true",
                    help="[gnss].estimate_time_offset = true (gmis.latency_estimation)")
    ap.add_argument("--repeats", type=int, default=1,
                    help="time forward and smoother interleaved this many times (min CPU)")
    args = ap.parse_args()
    recipe = load_recipe(args.recipe)
    if args.outlier_alpha is not None:
        recipe = dataclasses.replace(recipe, filter=dataclasses.replace(
            recipe.filter, outlier_alpha=args.outlier_alpha))
    if args.zupt:
        recipe = dataclasses.replace(recipe, zupt=ZuptSection())
    if args.states is not None:
        recipe = dataclasses.replace(recipe, filter=dataclasses.replace(
            recipe.filter, states=args.states))
    if args.nhc:
        recipe = dataclasses.replace(recipe, nonholonomic=NonholonomicSection())
    for axis, value in ((1, args.nhc_forward), (2, args.nhc_up)):
        if value is not None:
            lever = list(recipe.nonholonomic.lever_arm_m)
            lever[axis] = value
            recipe = dataclasses.replace(recipe, nonholonomic=dataclasses.replace(
                recipe.nonholonomic, lever_arm_m=tuple(lever)))
    if args.estimate_latency:
        recipe = dataclasses.replace(recipe, gnss=dataclasses.replace(
            recipe.gnss, estimate_time_offset=True))
    if args.estimate_nhc_point:
        recipe = dataclasses.replace(recipe, nonholonomic=dataclasses.replace(
            recipe.nonholonomic, estimate_lever_arm=True))
    full = prepare_run(dataclasses.replace(            # GNSS truth, windows
        recipe, nonholonomic=None, gnss=dataclasses.replace(recipe.gnss,
                                                            estimate_time_offset=False)))
    if args.first_start is None:
        windows = choose_outage_windows(full, args.duration, args.count)
    else:
        windows = [(args.first_start + k * args.every,
                    args.first_start + k * args.every + args.duration)
                   for k in range(args.count)]
    c0 = time.process_time()
    prep = prepare_run(recipe, dataset=full.dataset, gnss_outages=windows)
    c_est = time.process_time() - c0
    if prep.nhc_offset is not None:
        print(f"NHC point estimated: {prep.nhc_offset.summary()} ({c_est:.1f} s CPU)")
    if prep.gnss_time_offset is not None:
        print(f"GNSS time offset estimated: {prep.gnss_time_offset.summary()}")
    c0 = time.process_time()
    rec_plain = run_prepared(prep)
    c1 = time.process_time()
    fwd, sm = run_two_filter(prep.epochs, prep.meas, prep.x0, prep.config, prep.frame,
                             stationary=prep.stationary,
                             rate_hz=recipe.filter.smoother_rate_hz)
    c2 = time.process_time()
    assert np.array_equal(rec_plain.x, fwd.x)
    g = full.dataset.gnss
    withheld = np.zeros(g.t.size, bool)
    for a, b in windows:
        withheld |= (g.t >= a) & (g.t <= b)
    truth = geodetic_to_enu_rows(prep.frame, np.ascontiguousarray(g.llh[withheld]))
    tw = g.t[withheld]
    if prep.gnss_time_offset is not None:     # the fixes' times as the run uses them
        tw = tw + prep.gnss_time_offset.offset_s
    err = {"forward": _antenna_at(prep, fwd, tw) - truth,
           "smoothed": _antenna_at(prep, smoothed_records(fwd, sm), tw) - truth}
    t0 = prep.dataset.imu.t[0]
    print(f"{args.recipe}: states {recipe.filter.states}, NHC "
          f"{'on' if recipe.nonholonomic else 'off'}, outlier_alpha "
          f"{recipe.filter.outlier_alpha:g}, NHC point {prep.config.nhc_lever_arm.tolist()} m, zupt {'on' if args.zupt else 'off'}; {len(windows)} windows x {args.duration:g} s, "
          f"{tw.size} withheld GNSS epochs")
    print("window  start(s)  forward: hmax  hrms  vrms | smoothed: hmax  hrms  vrms  (m)")
    for i, (a, b) in enumerate(windows):
        k = (tw >= a) & (tw <= b)
        cells = []
        for name in ("forward", "smoothed"):
            e = err[name][k]
            h = np.hypot(e[:, 0], e[:, 1])
            cells.append(f"{h.max():6.3f} {np.sqrt((h ** 2).mean()):6.3f} "
                         f"{np.sqrt((e[:, 2] ** 2).mean()):6.3f}")
        print(f"{i + 1:4d}   {a - t0:8.1f}   {cells[0]}  |  {cells[1]}")
    for name in ("forward", "smoothed"):
        e = err[name]
        h = np.hypot(e[:, 0], e[:, 1])
        print(f"all withheld epochs, {name:8s}: horizontal max {h.max():.3f} m, RMS "
              f"{np.sqrt((h ** 2).mean()):.3f} m; vertical RMS "
              f"{np.sqrt((e[:, 2] ** 2).mean()):.3f} m")
    print(f"CPU: forward filter {c1 - c0:.2f} s, forward + backward + combination "
          f"{c2 - c1:.2f} s (ratio {(c2 - c1) / (c1 - c0):.2f})")
    if args.repeats > 1:
        fw, sm = [c1 - c0], [c2 - c1]
        for _ in range(args.repeats - 1):
            c0 = time.process_time()
            run_prepared(prep)
            c1 = time.process_time()
            run_two_filter(prep.epochs, prep.meas, prep.x0, prep.config, prep.frame,
                           stationary=prep.stationary, rate_hz=recipe.filter.smoother_rate_hz)
            c2 = time.process_time()
            fw.append(c1 - c0)
            sm.append(c2 - c1)
        print(f"CPU over {args.repeats} interleaved repeats: forward min {min(fw):.3f} s "
              f"(median {np.median(fw):.3f}), smoother min {min(sm):.3f} s (median "
              f"{np.median(sm):.3f}); ratio of the minima {min(sm) / min(fw):.2f}, of the "
              f"medians {np.median(sm) / np.median(fw):.2f}")


if __name__ == "__main__":
    main()
