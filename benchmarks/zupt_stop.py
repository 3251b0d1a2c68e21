"""ZUPT/ZARU acceptance (issue 15): a simulated 60 s stop with GNSS position, velocity and
heading withheld, with and without [zupt]; position and heading drift over the stop.

    PYTHONPATH=. python3 benchmarks/zupt_stop.py [--seed N]

The scenario is the default IMU440-class unit on a short drive: 120 s static alignment,
accelerate, cruise, right turn, cruise, stop for 70 s, drive off. GNSS and heading are
withheld from 5 s after the vehicle stands still until 65 s later (60 s). Drift = the
largest change of the solution's error (against the truth) inside the window relative to
its value at the window's start (horizontal+vertical 3D norm for position)."""

import argparse
import copy
import tempfile
from pathlib import Path

import numpy as np

from gmis.pipeline import run_recipe
from gmis.simulate import default_scenario_path, load_scenario, simulate_scenario

STOP_WITHHELD_S = 60.0


def stop_scenario(seed=None):
    scn = copy.deepcopy(load_scenario(default_scenario_path()))
    scn["segment"] = [
        {"type": "static", "label": "alignment", "duration_s": 120.0},
        {"type": "accelerate", "speed_m_s": 10.0, "accel_m_s2": 1.5},
        {"type": "cruise", "duration_s": 15.0},
        {"type": "turn", "angle_deg": 90.0, "rate_deg_s": 15.0},
        {"type": "cruise", "duration_s": 10.0},
        {"type": "accelerate", "label": "stop", "speed_m_s": 0.0, "accel_m_s2": 2.0},
        {"type": "static", "label": "stop", "duration_s": 70.0},
        {"type": "accelerate", "speed_m_s": 10.0, "accel_m_s2": 1.5},
        {"type": "cruise", "duration_s": 20.0},
    ]
    scn["gnss"]["outage"] = []
    if seed is not None:
        scn["scenario"]["seed"] = seed
    return scn


def stop_window(truth):
    """(start, end) GPS s of the withheld window: 5 s after the stop begins, 60 s long."""
    t = truth.time_gps_s
    speed = np.linalg.norm(truth.v_b, axis=1)
    moved = np.flatnonzero(speed > 1.0)
    still = np.flatnonzero((speed < 1e-9) & (t > t[moved[0]]))
    return t[still[0]] + 5.0, t[still[0]] + 5.0 + STOP_WITHHELD_S


def drifts(results: Path, window):
    err = np.genfromtxt(results / "errors.csv", delimiter=",", names=True)
    t = err["time_gps_s"]
    inside = np.flatnonzero((t >= window[0]) & (t <= window[1]))
    pos = np.column_stack([err["de_m"], err["dn_m"], err["du_m"]])[inside]
    hdg = err["dheading_deg"][inside]
    return (float(np.linalg.norm(pos - pos[0], axis=1).max()),
            float(np.abs(hdg - hdg[0]).max()))


def run_stop_case(root: Path, seed=None, zupt_toml="[zupt]\n"):
    """Simulate the stop drive into root; run without and with ZUPT/ZARU; return
    {"without": (pos m, heading deg), "with": (...), "window": (a, b), "summary": ...}."""
    sim = simulate_scenario(stop_scenario(seed), root / "dataset")
    window = stop_window(sim.truth)
    out = {"window": window}
    recipe = Path(sim.recipe_path)
    zupt_recipe = recipe.with_name("recipe_zupt.toml")
    zupt_recipe.write_text(recipe.read_text() + "\n" + zupt_toml)
    for label, path in (("without", recipe), ("with", zupt_recipe)):
        summary = run_recipe(path, root / f"results_{label}", gnss_outages=[window])
        out[label] = drifts(root / f"results_{label}", window)
        out[f"summary_{label}"] = summary
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=None)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = run_stop_case(Path(tmp), args.seed)
    a, b = out["window"]
    print(f"GNSS + heading withheld {a:.1f}-{b:.1f} s (60 s, vehicle stopped)")
    for label in ("without", "with"):
        pos, hdg = out[label]
        print(f"{label:7s} ZUPT/ZARU: position drift {pos:.4f} m, heading drift {hdg:.4f} deg")


if __name__ == "__main__":
    main()
