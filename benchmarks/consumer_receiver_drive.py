"""Issue 20 acceptance: a simulated drive that starts at 15 m/s, logged by a consumer
receiver — 10 Hz fixes with 1.5 m σ correlated over 5 s (Gauss-Markov), 0.1 s latency,
speed/course instead of an ENU velocity, no heading stream (gmis.simulate.consumer_receiver).

Per seed: simulate (gmis.simulate from SCENARIO, seed), write the receiver's file, then
  1. estimate the GNSS time offset from the data (gmis.latency_estimation) with the
     Gauss-Markov fix-error states on ([gnss].error_correlation_time_s = 5,
     error_sigma_m = 1.5), and run the GMIKF with the estimate
     ([gnss].estimate_time_offset = true, as `gmis run` does);
  2. report, after the first 10 s: mean NEES of r^n, v^b, θ (3 dof each), the heading
     error (max and RMS), the horizontal position RMS of the filter and of the fixes alone
     (fix_rms: fix − true antenna at the fix's stamp, i.e. with its latency, as a user
     would take them; fix_err_rms: the fix errors themselves, latency removed), the
     latency error ô + 0.1 s and its σ.
  Reference runs per seed: (a) white fixes (no error states), latency known; (b) error
  states, latency ignored (offset 0).

    PYTHONPATH=. python3 benchmarks/consumer_receiver_drive.py [n_seeds] [first_seed] [nhc]

nhc: every run also carries the car's non-holonomic constraint ([nonholonomic] at its
defaults, as the real drive's recipe; the simulated car has no sideslip), which ties the
heading to the course.
"""

from __future__ import annotations

import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from gmis.simulate.consumer_receiver import ConsumerReceiver, write_consumer_receiver

SCENARIO = """
[scenario]
name = "consumer-receiver-moving-start"
seed = 1
start_gps_s = 345600.0
imu_rate_hz = 100.0

[origin]
lat_deg = 40.0
lon_deg = -105.2
h_m = 1600.0

[initial]
heading_deg = 30.0
speed_m_s = 15.0
pitch_deg = -2.0

[[segment]]
type = "accelerate"
speed_m_s = 25.0
accel_m_s2 = 2.0
ramp_s = 0.5

[[segment]]
type = "turn"
angle_deg = 90.0
rate_deg_s = 10.0

[[segment]]
type = "cruise"
duration_s = 8.0

[[segment]]
type = "accelerate"
speed_m_s = 12.0
accel_m_s2 = 2.0
ramp_s = 0.5

[[segment]]
type = "turn"
angle_deg = -90.0
rate_deg_s = 12.0

[[segment]]
type = "accelerate"
speed_m_s = 20.0
accel_m_s2 = 1.5
ramp_s = 0.5

[[segment]]
type = "turn"
angle_deg = 60.0
rate_deg_s = 8.0

[[segment]]
type = "cruise"
duration_s = 10.0

[imu]
grade = "IMU440"

[gnss]
rate_hz = 10.0
position_sigma_m = [0.0, 0.0, 0.0]
velocity_sigma_m_s = [0.0, 0.0, 0.0]
lever_arm_m = [0.3, 1.0, 1.5]

[heading]
rate_hz = 1.0
sigma_deg = 0.5
lever_arm_m = [0.3, -1.0, 1.5]
"""

MODEL = ConsumerReceiver()
GM_KEYS = {"error_correlation_time_s": MODEL.error_tau_s,
           "error_sigma_m": list(MODEL.error_sigma_m)}
SETTLE_S = 10.0


def simulate(seed: int, folder: Path):
    """The dataset of one seed; returns (recipe path, receiver truth)."""
    from gmis.simulate import simulate_scenario

    scenario = folder / "scenario.toml"
    scenario.write_text(SCENARIO)
    sim = simulate_scenario(scenario, folder / "dataset", seed=seed, overwrite=True)
    truth = write_consumer_receiver(sim, MODEL, seed + 10_000, {**GM_KEYS})
    return Path(sim.recipe_path), sim, truth


def run_case(recipe_path, gnss_keys: dict, nhc: bool = False):
    """prepare + run with [gnss] replaced by gnss_keys (and [nonholonomic] when nhc);
    returns (prep, rec, errs, seconds)."""
    from gmis.navigation_solution import navigation_solution, reference_errors
    from gmis.recipe import GnssSection, NonholonomicSection, load_recipe
    from gmis.run_preparation import prepare_run, run_prepared

    recipe = load_recipe(recipe_path)
    if nhc:
        recipe = replace(recipe, nonholonomic=NonholonomicSection())
    gnss = replace(GnssSection(), **{k: (tuple(v) if isinstance(v, list) else v)
                                     for k, v in gnss_keys.items()})
    recipe = replace(recipe, gnss=gnss)
    c0 = time.process_time()
    prep = prepare_run(recipe)
    rec = run_prepared(prep)
    cpu = time.process_time() - c0
    return prep, rec, reference_errors(prep, rec, navigation_solution(prep, rec)), cpu


def figures(prep, errs, sim, truth):
    """The acceptance figures of one run after SETTLE_S."""
    late = errs["t"] >= errs["t"][0] + SETTLE_S
    out = {f"nees_{k}": float(np.mean(errs["nees"][k][late]))
           for k in ("position", "velocity_body", "attitude")}
    out["heading_err_deg_max"] = float(np.degrees(np.abs(errs["att"][late, 2])).max())
    out["heading_err_deg_rms"] = float(np.degrees(np.sqrt(np.mean(errs["att"][late, 2] ** 2))))
    out["pos_rms_h_m"] = float(np.sqrt(np.mean(np.sum(errs["pos"][late, :2] ** 2, axis=1))))
    out["pos_rms_3d_m"] = float(np.sqrt(np.mean(np.sum(errs["pos"][late] ** 2, axis=1))))
    # the fixes alone: the file's position at its stamp against the true antenna there
    tr = sim.truth
    t_stamp = truth["t_true"] + MODEL.latency_s
    true_at_stamp = np.column_stack([np.interp(t_stamp, tr.gnss_time_gps_s,
                                               tr.gnss_true_r_enu[:, i]) for i in range(3)])
    fix = tr.gnss_true_r_enu + truth["error_enu"]
    keep = t_stamp >= t_stamp[0] + SETTLE_S
    d = fix[keep] - true_at_stamp[keep]
    out["fix_rms_h_m"] = float(np.sqrt(np.mean(np.sum(d[:, :2] ** 2, axis=1))))
    # ... and with the latency removed: the fix errors themselves (GM + white)
    e = truth["error_enu"][truth["t_true"] >= truth["t_true"][0] + SETTLE_S]
    out["fix_err_rms_h_m"] = float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1))))
    out["fix_rms_3d_m"] = float(np.sqrt(np.mean(np.sum(d ** 2, axis=1))))
    return out


def one_seed(seed: int, nhc: bool = False):
    with tempfile.TemporaryDirectory() as tmp:
        recipe_path, sim, truth = simulate(seed, Path(tmp))
        prep, _rec, errs, cpu = run_case(recipe_path, {**GM_KEYS, "estimate_time_offset": True},
                                         nhc)
        est = prep.gnss_time_offset
        row = {"seed": seed, **figures(prep, errs, sim, truth),
               "offset_s": est.offset_s, "offset_sigma_s": est.sigma_s,
               "latency_err_ms": (est.offset_s + MODEL.latency_s) * 1e3,
               "runs": est.runs, "cpu_s": cpu}
        _, _, errs_w, _ = run_case(recipe_path, {"time_offset_s": -MODEL.latency_s}, nhc)
        white = figures(prep, errs_w, sim, truth)
        row["white_nees_position"] = white["nees_position"]
        row["white_pos_rms_h_m"] = white["pos_rms_h_m"]
        _, _, errs_0, _ = run_case(recipe_path, {**GM_KEYS}, nhc)
        row["nolat_pos_rms_h_m"] = figures(prep, errs_0, sim, truth)["pos_rms_h_m"]
        row["nolat_nees_position"] = figures(prep, errs_0, sim, truth)["nees_position"]
        return row


def main(n_seeds=10, first=1, nhc=False):
    rows = []
    keys = ("nees_position", "nees_velocity_body", "nees_attitude", "heading_err_deg_max",
            "heading_err_deg_rms", "pos_rms_h_m", "fix_rms_h_m", "fix_err_rms_h_m",
            "latency_err_ms", "offset_sigma_s",
            "white_nees_position", "white_pos_rms_h_m", "nolat_nees_position",
            "nolat_pos_rms_h_m")
    print("seed " + " ".join(f"{k[:14]:>14}" for k in keys), flush=True)
    for seed in range(first, first + n_seeds):
        row = one_seed(seed, nhc)
        rows.append(row)
        print(f"{seed:4d} " + " ".join(f"{row[k]:14.4g}" for k in keys), flush=True)
    arr = {k: np.array([r[k] for r in rows]) for k in keys}
    print("mean " + " ".join(f"{arr[k].mean():14.4g}" for k in keys))
    print("max  " + " ".join(f"{np.abs(arr[k]).max():14.4g}" for k in keys))
    lat = arr["latency_err_ms"]
    print(f"latency error: RMS {np.sqrt(np.mean(lat ** 2)):.2f} ms, max |.| "
          f"{np.abs(lat).max():.2f} ms, mean σ {1e3 * arr['offset_sigma_s'].mean():.2f} ms, "
          f"RMS(err/σ) {np.sqrt(np.mean((lat / 1e3 / arr['offset_sigma_s']) ** 2)):.2f}, "
          f"|error| > 10 ms in {int(np.sum(np.abs(lat) > 10.0))} of {lat.size} seeds, "
          f"> 2σ in {int(np.sum(np.abs(lat / 1e3 / arr['offset_sigma_s']) > 2.0))}")
    hdg = arr["heading_err_deg_max"]
    print(f"heading error after {SETTLE_S:.0f} s: max > 1° in {int(np.sum(hdg > 1.0))} of "
          f"{hdg.size} seeds; RMS over the seeds {np.sqrt(np.mean(arr['heading_err_deg_rms'] ** 2)):.3f}°")
    # χ²(3n) band of the Monte Carlo mean NEES (3 dof, n seeds, epochs correlated in time:
    # the band is that of one epoch per seed, 95 %)
    from scipy.stats import chi2
    n = len(rows)
    lo, hi = chi2.ppf([0.025, 0.975], 3 * n) / n
    print(f"95 % band of a {n}-seed mean NEES (3 dof): [{lo:.2f}, {hi:.2f}]")
    return rows


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]), nhc="nhc" in sys.argv[3:])
