"""The estimated non-holonomic constraint point on simulated drives with truth (issue 15):
per seed of the default scenario (the vehicle moves along its body forward axis at the IMU,
so the true point is the IMU, forward offset 0), the estimate ŷ of
gmis.nhc_offset_estimation and the outage drift (max horizontal error in the scenario's
GNSS outages, forward and smoothed) with [nonholonomic] at the truth and with the point
estimated ([nonholonomic].estimate_lever_arm = true, search 0 ± 2 m).

    PYTHONPATH=. python3 benchmarks/nhc_point_simulated.py [--seeds 3] [--scenario default]
"""

import argparse
import tempfile
from pathlib import Path

import numpy as np

from gmis.pipeline import run_recipe
from gmis.simulate import load_scenario, scenario_path, simulate_scenario

VARIANTS = {"truth point": "[nonholonomic]\n",
            "estimated": "[nonholonomic]\nestimate_lever_arm = true\n"}


def outage_max(res: Path, name: str, outages):
    err = np.genfromtxt(res / name, delimiter=",", names=True)
    t = err["time_gps_s"] - np.load(res / "solution_forward.npz")["t"][0]
    h = np.hypot(err["de_m"], err["dn_m"])
    return [float(h[(t >= a) & (t <= b)].max()) for a, b in outages]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--scenario", default="default")
    args = ap.parse_args()
    outages = [(o["start_s"], o["end_s"]) for o in
               load_scenario(scenario_path(args.scenario))["gnss"].get("outage", [])]
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        for seed in range(args.seeds):
            sim = simulate_scenario(scenario_path(args.scenario), root / f"ds{seed}",
                                    seed=seed)
            base = Path(sim.recipe_path).read_text()
            for name, table in VARIANTS.items():
                recipe = Path(sim.recipe_path).with_name(f"recipe_{name.split()[0]}.toml")
                recipe.write_text(base + "\n" + table)
                res = root / f"res{seed}{name.split()[0]}"
                summary = run_recipe(recipe, res, smooth=True)
                est = summary.get("nonholonomic_lever_arm")
                fw = outage_max(res, "errors_forward.csv", outages)
                sm = outage_max(res, "errors.csv", outages)
                y = "" if est is None else (f", y = {est['forward_offset_m']:+.3f} m "
                                            f"(1 sigma {est['sigma_m']:.3f})")
                print(f"seed {seed} {name:11s}{y}: outage max forward "
                      f"{' '.join(f'{v:.3f}' for v in fw)} m, smoothed "
                      f"{' '.join(f'{v:.3f}' for v in sm)} m", flush=True)


if __name__ == "__main__":
    main()
