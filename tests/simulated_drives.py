"""Simulated drives and checks shared by several test modules (one definition each).

- ``default_scenario_cut(seconds)``: the embedded default scenario cut to its first
  segments lasting at least ``seconds`` s.
- ``square_drive_segments()``: a ~2 min drive (20 s static, 10 m/s, two 90° turns, stop).
- ``simulate_random_dynamics(folder)``: the random-dynamics scenario simulated, read and
  prepared; ``true_sigmas(recipe)``: its true noise σ per VCE component.
- ``assert_nees_time_average_in_chi2_band(errors_csv)``: sampled NEES of the default
  drive's aided motion against the χ²(3K)/K band.
"""

import copy

import numpy as np
from scipy import stats

from gmis.pipeline import prepare_run
from gmis.recipe import load_recipe
from gmis.simulate import load_scenario, scenario_path, simulate_scenario


def default_scenario_cut(seconds: float) -> dict:
    """The default scenario's segments up to the first that brings the drive to
    ``seconds`` s (segments without a duration_s count 10 s)."""
    sc = copy.deepcopy(load_scenario(scenario_path("default")))
    kept, total = [], 0.0
    for seg in sc["segment"]:
        kept.append(seg)
        total += float(seg.get("duration_s", 10.0))
        if total >= seconds:
            break
    sc["segment"] = kept
    return sc


def square_drive_segments() -> list[dict]:
    """Static 20 s, accelerate to 10 m/s, cruise, ±90° turns, stop, static 10 s."""
    return [
        {"type": "static", "duration_s": 20.0},
        {"type": "accelerate", "speed_m_s": 10.0, "accel_m_s2": 2.0},
        {"type": "cruise", "duration_s": 15.0},
        {"type": "turn", "angle_deg": 90.0, "rate_deg_s": 15.0},
        {"type": "cruise", "duration_s": 20.0},
        {"type": "turn", "angle_deg": -90.0, "rate_deg_s": 15.0},
        {"type": "cruise", "duration_s": 15.0},
        {"type": "accelerate", "speed_m_s": 0.0, "accel_m_s2": 2.0},
        {"type": "static", "duration_s": 10.0},
    ]


def simulate_random_dynamics(folder):
    """(SimulationResult, Recipe, PreparedRun) of the random-dynamics drive: jerk/angular
    acceleration are white per-step noises with known σ (the simulator's recipe [noise]
    holds the true values of every component)."""
    sim = simulate_scenario(scenario_path("random_dynamics"), folder)
    recipe = load_recipe(sim.recipe_path)
    return sim, recipe, prepare_run(recipe)


def true_sigmas(recipe) -> dict:
    """True σ per VCE component of a simulated recipe (aiding scales 1)."""
    nz = recipe.noise
    out = {"gnss_position": 1.0, "gnss_velocity": 1.0, "heading": 1.0}
    for i, a in enumerate("xyz"):
        out[f"gyro_{a}"] = nz.gyro_sigma_rad_s[i]
        out[f"accel_{a}"] = nz.accel_sigma_m_s2[i]
        out[f"jerk_{a}"] = nz.jerk_sigma_m_s3[i]
        out[f"angacc_{a}"] = nz.angular_acceleration_sigma_rad_s2[i]
    return out


def assert_nees_time_average_in_chi2_band(errors_csv):
    """NEES of r^n, v^b, θ sampled every 10 s of the default drive's aided motion (errors
    decorrelate within seconds), the 430-445 s outage and its recovery left out, averaged
    over the K samples: inside the two-sided 95 % χ²(3K)/K band."""
    err = np.genfromtxt(errors_csv, delimiter=",", names=True)
    t = err["time_gps_s"] - err["time_gps_s"][0]
    outage = (t >= 425) & (t <= 450)   # the scenario's 430-445 s outage and recovery
    rows = [np.argmin(np.abs(t - s)) for s in np.arange(305.0, 600.0, 10.0)]
    rows = [r for r in rows if not outage[r]]
    k = len(rows)
    lo, hi = stats.chi2.ppf([0.025, 0.975], 3 * k) / k
    for name in ("nees_position", "nees_velocity_body", "nees_attitude"):
        mean = err[name][rows].mean()
        assert lo <= mean <= hi, (name, mean, lo, hi)
