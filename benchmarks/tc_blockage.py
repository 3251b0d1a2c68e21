"""Sky blockage study of the tightly coupled GMIKF: the embedded tightly_coupled drive
(IMU440-class IMU, sideslip truth) with its 20 s blockage (500-520 s) keeping the N
highest satellites, run with and without the non-holonomic constraint (2 Hz, σ 0.1 m/s).

    python benchmarks/tc_blockage.py [--highest 3 2] [--grade IMU440] [--keep DIR]

Prints, per case, the maximum |error| E/N/U and 3D inside the blockage, the fixed-epoch
rate and the mean NEES over the drive (sampled every 10 s from 305 s).
"""

import argparse
import shutil
import tempfile
import tomllib
from pathlib import Path

import numpy as np

from gmis.pipeline import run_recipe
from gmis.simulate import scenario_path, simulate_scenario

NHC = "\n[nonholonomic]\nsigma_lateral_m_s = 0.1\nsigma_vertical_m_s = 0.1\nrate_hz = 2.0\n"
TACTICAL = {"grade": "HG1700", "gyro_bias_deg_h": [2.0, -1.5, 1.0],
            "accel_bias_mg": [1.0, -0.8, 1.5], "gyro_scale_ppm": [150.0, -100.0, 120.0],
            "accel_scale_ppm": [300.0, -200.0, 150.0], "bias_correlation_time_s": 100.0}


def blockage_case(folder: Path, highest: int, grade: str, nhc: bool) -> dict:
    dataset = folder / f"{grade}-{highest}"
    if not (dataset / "recipe.toml").exists():
        doc = tomllib.loads(Path(scenario_path("tightly_coupled")).read_text())
        doc["raw_gnss"]["blockage"][0]["highest_n"] = highest
        if grade != "IMU440":
            doc["imu"] = dict(TACTICAL, grade=grade)
        simulate_scenario(doc, dataset, overwrite=True)
    text = (dataset / "recipe.toml").read_text().replace('mode = "loose"', 'mode = "tight"')
    recipe = dataset / ("tight_nhc.toml" if nhc else "tight.toml")
    recipe.write_text(text + (NHC if nhc else ""))
    results = folder / f"res-{grade}-{highest}-{'nhc' if nhc else 'free'}"
    shutil.rmtree(results, ignore_errors=True)
    summary = run_recipe(recipe, results)
    err = np.genfromtxt(results / "errors.csv", delimiter=",", names=True)
    t = err["time_gps_s"] - err["time_gps_s"][0]
    inside = (t >= 500.0) & (t <= 521.0)
    enu = np.column_stack([err["de_m"], err["dn_m"], err["du_m"]])[inside]
    rows = [int(np.argmin(np.abs(t - s))) for s in np.arange(305.0, 600.0, 10.0)]
    return {"max_enu": np.abs(enu).max(axis=0), "max_3d": np.linalg.norm(enu, axis=1).max(),
            "fix_rate": summary["tightly_coupled"]["fix_rate"],
            "nees": [float(err[c][rows].mean()) for c in
                     ("nees_position", "nees_velocity_body", "nees_attitude")]}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--highest", type=int, nargs="+", default=[3, 2],
                    help="satellites left by the blockage (the N highest)")
    ap.add_argument("--grade", default="IMU440", choices=["IMU440", "HG1700"])
    ap.add_argument("--keep", type=Path, help="simulate into / reuse this folder")
    args = ap.parse_args()
    folder = args.keep or Path(tempfile.mkdtemp(prefix="gmis-blockage-"))
    print(f"20 s blockage, {args.grade}; max |error| inside the blockage (m)")
    for highest in args.highest:
        for nhc in (False, True):
            r = blockage_case(folder, highest, args.grade, nhc)
            e, n, u = r["max_enu"]
            print(f"  {highest} satellites, {'NHC 2 Hz σ 0.1 m/s' if nhc else 'no constraint':19s}"
                  f": E {e:.3f}  N {n:.3f}  U {u:.3f}  3D {r['max_3d']:.3f}; fixed "
                  f"{r['fix_rate']:.3f}; NEES p/v/θ "
                  + "/".join(f"{x:.2f}" for x in r["nees"]))


if __name__ == "__main__":
    main()
