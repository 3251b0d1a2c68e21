"""In-filter cycle slips (detection, reset, repair) and partial / WL → L1 ambiguity
resolution of the tightly coupled filter, GNSS-only (`gmis rtk --tight` path) on the
simulated sessions of tests/tc_gnss_scene (7 satellites above 15°, 1 Hz, rover 7.2 m/s):

A. undetected (1, 1) slips (no LLI, RINEX-level flags cleared as if the detectors had missed
   them) on a held non-reference satellite at t0 + 40 s and on the reference at t0 + 80 s,
   120 epochs: TcConfig(phase_slip_reset) off / on with reset only / on with repair;
B. the same session without slips, 120 epochs: false slip events; L1 only with and
   with the success-rate gate (0.999);
C. a 5-satellite blockage (t0 + 60 … 120 s) and a half-cycle L1 bias on the lowest
   satellite, 180 epochs: partial_ar × wide_lane_cascade, with and without the
   leave-one-out stage + per-satellite test (TcConfig.leave_one_out / satellite_test);
E. the same blockage with the half-cycle L1 bias on the 5th-highest satellite instead, so
   the biased satellite is one of the 5 in view during the stretch
   (tests.tc_gnss_scene.five_satellite_stretch), L1+L2 and L1 only: partial_ar off,
   variance ordering only (the code before the leave-one-out stage), leave-one-out
   without / with the satellite test; fixed epochs and fixed 3-D error inside the stretch,
   fixes holding the biased L1, 3-D error over all stretch epochs (fixed or float), fixes
   refused because the per-satellite test could not name a culprit (TcRecords.
   unidentifiable); L1 only also with the defaults at 001's VCE-final code / phase σ
   (0.15 m / 3 mm, Table 6-3), with and without the bootstrapping success-rate gate
   (TcConfig.min_success_rate = 0.999; default off); and the same geometry without the bias, L1 only;
F. the same 5-satellite stretch without bias but a flagged slip (loss of lock, L1 and L2)
   on the 3rd-highest satellite at t0 + 80 s, inside the stretch: its ambiguities restart
   from code, the others stay held; the E configurations, fixed epochs in the stretch;
D. the real 0759/3040 session (../shared/data, 120 epochs at 30 s), L1+L2 and L1 only,
   all options off, the defaults, the defaults without leave-one-out / satellite
   test, and each option alone (slip_repair with the slip test):
   fixed epochs, in-filter slip events, and the
   median / 95 % 3-D difference to RTKLIB's fixed solution (rnx2rtkp, same frequencies)
   over the epochs both fixed.

Per run: fixed epochs, resets / repairs / reference changes, wrong DD integers of the fixed
epochs against the simulated truth (C: the biased satellite's L1 not checked, its L2 is),
time from each slip to the slipped satellite's L1 being part of a fix again, max fixed
3-D error in the 10 s after each slip, max / 95 % fixed 3-D error overall, fixes
rejected (χ² or per-satellite test), CPU time (time.process_time).

Run:  python benchmarks/tc_slips_partial_ar.py [--parts A B C D E F]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gmis import tc_gnss_only
from gmis.simulate.raw_gnss import CycleSlip, RawGnssConfig, SkyBlockage
from gmis.tc_filter import TcConfig
from tests import tc_gnss_scene
from tests.tc_gnss_scene import (
    BASE,
    T0,
    five_satellite_stretch,
    satellites_by_elevation,
    simulate_session,
    wrong_integers,
)

_prepare = tc_gnss_only.prepare_tc_epochs
_without_flags = tc_gnss_scene.without_slip_flags(_prepare)


def run(obs, nav, cfg):
    t0 = time.process_time()
    sol = tc_gnss_only.run_tight_without_imu(obs["rover"], obs["base"], nav, BASE, cfg,
                                             hydrostatic_troposphere=False)
    return sol, time.process_time() - t0


def fixed_in(sol, start_s, end_s=np.inf) -> str:
    """'fixed/epochs' of the solution epochs in T0 + [start_s, end_s)."""
    inside = (sol.t_gps >= T0 + start_s) & (sol.t_gps < T0 + end_s)
    return f"{int(sol.fixed[inside].sum())}/{int(inside.sum())}"


def refix_delay(sol, t_slip, prn):
    rec = sol.tc_records
    times = [sol.t_gps[g] for g, ints in zip(np.flatnonzero(sol.fixed), rec.integers)
             if sol.t_gps[g] >= t_slip and (prn, 1) in ints]
    return times[0] - t_slip if times else np.inf


def report(name, sim, sol, cpu, events=(), skip=()):
    rec = sol.tc_records
    wrong, checked = wrong_integers(sim, sol, skip)
    err = np.linalg.norm(sol.ecef - sim.receivers["rover"].antenna_ecef, axis=1)
    line = (f"{name}: fixed {int(sol.fixed.sum())}/{sol.fixed.size}, partial "
            f"{int((rec.partial & sol.fixed).sum())}, cascade {int(rec.cascade.sum())}, "
            f"resets {int(rec.slip_resets.sum())}, repairs {int(rec.slip_repairs.sum())}, "
            f"reference changes {int(rec.reference_slips.sum())}, fixes rejected "
            f"{int(rec.fix_rejected.sum())}, refused as P_s too low "
            f"{int(rec.low_success_rate.sum())}, wrong integers "
            f"{wrong}/{checked}, fixed 3-D error max / 95 % "
            f"{err[sol.fixed].max() * 100 if sol.fixed.any() else np.nan:.1f} / "
            f"{np.percentile(err[sol.fixed], 95) * 100 if sol.fixed.any() else np.nan:.1f} "
            f"cm")
    for t_slip, prn in events:
        ev = (sol.t_gps >= t_slip) & (sol.t_gps < t_slip + 10.0)
        line += (f"; slip G{prn:02d} at +{t_slip - T0:.0f} s: L1 re-fixed after "
                 f"{refix_delay(sol, t_slip, prn):.0f} s, max error 10 s "
                 f"{err[ev].max() * 100:.1f} cm")
    print(line + f", CPU {cpu:.1f} s", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--parts", nargs="+", default=["A", "B", "C", "D", "E", "F"])
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="tc_slips_"))
    if "A" in args.parts or "B" in args.parts:
        tc_gnss_only.prepare_tc_epochs = _without_flags
    if "A" in args.parts:
        order = satellites_by_elevation(120)
        ref, other = int(order[0]), int(order[2])
        events = ((T0 + 40.0, other), (T0 + 80.0, ref))
        slips = [CycleSlip(t, prn, f, 1, loss_of_lock=False) for t, prn in events
                 for f in (1, 2)]
        (tmp / "a").mkdir()
        sim, obs, nav = simulate_session(tmp / "a", 120, RawGnssConfig(slips=slips))
        for name, cfg in (("A slip test off", TcConfig(phase_slip_reset=False)),
                          ("A slip test on, reset", TcConfig(phase_slip_reset=True,
                                                             slip_repair=False)),
                          ("A slip test on, repair", TcConfig(phase_slip_reset=True,
                                                              slip_repair=True)),
                          ("A defaults without leave-one-out / satellite test",
                           TcConfig(leave_one_out=False, satellite_test=False))):
            report(name, sim, *run(obs, nav, cfg), events=events)
    if "B" in args.parts:
        (tmp / "b").mkdir()
        sim, obs, nav = simulate_session(tmp / "b", 120)
        for name, cfg in (("B clean, slip test off", TcConfig(phase_slip_reset=False)),
                          ("B clean, slip test on + repair", TcConfig(phase_slip_reset=True,
                                                                      slip_repair=True)),
                          ("B clean, defaults", TcConfig()),
                          ("B clean, L1 only, defaults", TcConfig(use=(True, True, False, True))),
                          (f"B clean, L1 only, success-rate gate P_s ≥ {GATE}",
                           TcConfig(use=(True, True, False, True), min_success_rate=GATE)),
                          ("B clean, defaults without leave-one-out / satellite test",
                           TcConfig(leave_one_out=False, satellite_test=False))):
            report(name, sim, *run(obs, nav, cfg))
    tc_gnss_only.prepare_tc_epochs = _prepare
    if "C" in args.parts:
        (tmp / "c").mkdir()
        cfg = RawGnssConfig(blockages=[SkyBlockage(T0 + 60, T0 + 120, highest_n=5)])
        sim, obs, nav = simulate_session(tmp / "c", 180, cfg, lowest_l1_bias_cycles=0.5)
        biased = int(satellites_by_elevation(180)[-1])
        for pa, cas, loo in ((False, False, False), (False, True, False),
                             (True, False, False), (True, True, False),
                             (True, False, True), (True, True, True)):
            sol, cpu = run(obs, nav, TcConfig(partial_ar=pa, wide_lane_cascade=cas,
                                              leave_one_out=loo, satellite_test=loo))
            print(f"C partial_ar={pa} cascade={cas} leave-one-out + satellite test={loo}: "
                  f"blockage (5 sat) fixed "
                  f"{fixed_in(sol, 60, 120)}, after {fixed_in(sol, 120)}", end="; ")
            report("", sim, sol, cpu, skip={(biased, 1)})

    if "E" in args.parts:
        (tmp / "e").mkdir()
        sim, obs, nav, biased = five_satellite_stretch(tmp / "e")
        block = (sim.t_gps >= T0 + 60) & (sim.t_gps < T0 + 120)
        vce_sigma = {"sigma_code_m": 0.15, "sigma_phase_l1_m": 0.003}   # 001 Table 6-3 final
        for freq, use, configs in (
                ("L1+L2", (True,) * 4, E_CONFIGS),
                ("L1 only", (True, True, False, True),
                 (*E_CONFIGS, ("defaults, σ 0.15 m / 3 mm (001 Table 6-3 final)", vce_sigma),
                  (f"defaults + success-rate gate P_s ≥ {GATE}, σ 0.15 m / 3 mm",
                   {**vce_sigma, "min_success_rate": GATE})))):
            for name, kw in configs:
                sol, cpu = run(obs, nav, TcConfig(use=use, **kw))
                err = np.linalg.norm(sol.ecef - sim.receivers["rover"].antenna_ecef, axis=1)
                inside = sol.fixed & (sol.t_gps >= T0 + 60) & (sol.t_gps < T0 + 120)
                stretch = (f"{err[inside].max() * 100:.1f} / "
                           f"{np.percentile(err[inside], 95) * 100:.1f} cm"
                           if inside.any() else "-")
                in_fix = sum((biased, 1) in ints for ints in sol.tc_records.integers)
                every = (sol.t_gps >= T0 + 60) & (sol.t_gps < T0 + 120)
                print(f"E {freq} {name}: 5-satellite stretch fixed {fixed_in(sol, 60, 120)} "
                      f"({int(block.sum())} simulated), its fixed 3-D error max / 95 % "
                      f"{stretch}, all its epochs {err[every].max() * 100:.1f} / "
                      f"{np.percentile(err[every], 95) * 100:.1f} cm, biased L1 in {in_fix} "
                      f"fixes, fixes refused as unidentifiable "
                      f"{int(sol.tc_records.unidentifiable.sum())}, as P_s too low "
                      f"{int(sol.tc_records.low_success_rate.sum())}", end="; ")
                report("", sim, sol, cpu, skip={(biased, 1)})
        # the same geometry without the bias, L1 only: fixes of the stretch that the
        # identifiability requirement must not cost (held integers are trusted)
        (tmp / "e0").mkdir()
        sim, obs, nav = simulate_session(tmp / "e0", 180, RawGnssConfig(
            blockages=[SkyBlockage(T0 + 60, T0 + 120, highest_n=5)]))
        for name, kw in E_CONFIGS:
            sol, cpu = run(obs, nav, TcConfig(use=(True, True, False, True), **kw))
            err = np.linalg.norm(sol.ecef - sim.receivers["rover"].antenna_ecef, axis=1)
            every = (sol.t_gps >= T0 + 60) & (sol.t_gps < T0 + 120)
            print(f"E without bias, L1 only, {name}: 5-satellite stretch fixed "
                  f"{fixed_in(sol, 60, 120)}, all its epochs 3-D error max / 95 % "
                  f"{err[every].max() * 100:.1f} / {np.percentile(err[every], 95) * 100:.1f} "
                  f"cm, fixes refused as unidentifiable "
                  f"{int(sol.tc_records.unidentifiable.sum())}", end="; ")
            report("", sim, sol, cpu)
    if "F" in args.parts:
        (tmp / "f").mkdir()
        third = int(satellites_by_elevation(180)[2])
        cfg = RawGnssConfig(blockages=[SkyBlockage(T0 + 60, T0 + 120, highest_n=5)],
                            slips=[CycleSlip(T0 + 80.0, third, f, 3, loss_of_lock=True)
                                   for f in (1, 2)])
        sim, obs, nav = simulate_session(tmp / "f", 180, cfg)
        for name, kw in E_CONFIGS:
            sol, cpu = run(obs, nav, TcConfig(**kw))
            print(f"F {name}: 5-satellite stretch fixed {fixed_in(sol, 60, 120)}, "
                  f"after the slip {fixed_in(sol, 80, 120)}", end="; ")
            report("", sim, sol, cpu, events=((T0 + 80.0, third),))
    if "D" in args.parts:
        real_session(tmp)


GATE = 0.999     # TcConfig.min_success_rate of the gated runs (default 0: off)
E_CONFIGS = (("partial_ar off", {"partial_ar": False}),
             ("partial_ar, variance ordering only", {"leave_one_out": False,
                                                     "satellite_test": False}),
             ("partial_ar + leave-one-out, no satellite test", {"satellite_test": False}),
             ("defaults (partial_ar + leave-one-out + satellite test)", {}))


def real_session(tmp):
    from gmis.earth import ecef_to_enu, geodetic_to_ecef
    from gmis.tc_gnss_only import compare_fixed_epochs
    from gnss.pos_file import read_pos
    from gnss.rinex import read_nav, read_obs
    from gnss.rtk import Q_FIXED
    from tests.rtklib_reference import (
        BASE_0759,
        BASE_ECEF_0759,
        NAV_0759,
        ROVER_3040,
        run_rnx2rtkp,
    )
    rover, base, nav = read_obs(ROVER_3040), read_obs(BASE_0759), read_nav(NAV_0759)
    for n_f in (2, 1):
        out = tmp / f"rtklib_{n_f}.pos"
        run_rnx2rtkp(ROVER_3040, BASE_0759, NAV_0759, BASE_ECEF_0759, out, n_frequencies=n_f)
        ref = read_pos(out)
        use = (True, True, n_f == 2, True)
        off = {"phase_slip_reset": False, "partial_ar": False, "slip_repair": False,
               "wide_lane_cascade": False, "leave_one_out": False, "satellite_test": False}
        options = {"all off": off, "defaults": {},
                   "defaults without leave-one-out / satellite test":
                       {"leave_one_out": False, "satellite_test": False}}
        for name in off:
            if n_f == 2 or name != "wide_lane_cascade":
                options[f"only {name}"] = {**off, name: True}
        options["only partial_ar + leave_one_out"] = {**off, "partial_ar": True,
                                                      "leave_one_out": True}
        del options["only leave_one_out"]           # it needs partial_ar
        for name, kw in options.items():
            t0 = time.process_time()
            cfg = TcConfig(use=use, **kw)
            if cfg.slip_repair:
                cfg = TcConfig(use=use, **{**kw, "phase_slip_reset": True})
            sol = tc_gnss_only.run_tight_without_imu(rover, base, nav, BASE_ECEF_0759, cfg)
            cpu = time.process_time() - t0
            enu_ref = np.array([ecef_to_enu(sol.frame, geodetic_to_ecef(*p))
                                for p in ref["llh"]])
            c = compare_fixed_epochs(sol.t_gps, sol.enu, sol.fixed, ref["t_gps"], enu_ref,
                                     ref["q"] == Q_FIXED)
            rec = sol.tc_records
            print(f"D {'L1+L2' if n_f == 2 else 'L1   '} {name}: fixed "
                  f"{int(sol.fixed.sum())}/{sol.fixed.size} (RTKLIB "
                  f"{int((ref['q'] == Q_FIXED).sum())}), partial {int(rec.partial.sum())}, "
                  f"cascade {int(rec.cascade.sum())}, resets {int(rec.slip_resets.sum())}, "
                  f"repairs {int(rec.slip_repairs.sum())}; vs RTKLIB over {c['n_common']} "
                  f"common fixed: 3-D median {c['median_3d'] * 1e3:.1f} mm, 95 % "
                  f"{c['p95_3d'] * 1e3:.1f} mm, CPU {cpu:.1f} s", flush=True)


if __name__ == "__main__":
    main()
