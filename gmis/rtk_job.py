"""`gmis rtk <recipe>`: the GNSS-only RTK job (gnss.rtk) on a recipe and its results folder.

The recipe is read by the one recipe loader (gmis.recipe.load_recipe with
``gnss_only=True``: [paths] rover_obs/base_obs/nav and [base] required, no IMU needed);
its [rtk] table becomes the RtkConfig in gmis.engine_configs.

Results folder (written all-or-nothing, gmis.results.results_directory):
  rtk.pos        RTKLIB-like text (gnss.pos_file.write_pos)
  rtk.csv        t, ECEF, lat/lon/h, Q, ratio, satellites, 1σ ENU per epoch
  summary.json   fix rate, frequencies, partial-AR fixes, median ratio, mean fixed
                 position, baseline length, time
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from gmis.engine_configs import rtk_config
from gmis.errors import GmisInputError
from gmis.plausibility import check_rtk_inputs, check_rtk_options, solved_epochs
from gmis.recipe import load_recipe
from gmis.results import results_directory, write_csv, write_json
from gnss.pos_file import write_pos
from gnss.rinex import read_nav, read_obs
from gnss.rtk import Q_FIXED, process_rtk


def read_rtk_recipe(recipe_path) -> dict:
    """Validated GNSS-only inputs of a recipe: rover_obs, base_obs, nav (absolute paths),
    base_ecef ((3,) m), config (gnss.rtk.RtkConfig from [rtk]), name ([dataset].name)."""
    recipe = load_recipe(recipe_path, gnss_only=True)
    check_rtk_options(recipe.rtk.given(), str(recipe.path))
    return {"rover_obs": recipe.paths.rover_obs, "base_obs": recipe.paths.base_obs,
            "nav": recipe.paths.nav, "base_ecef": np.array(recipe.base.ecef_m, float),
            "config": rtk_config(recipe), "name": recipe.dataset.name,
            "time": recipe.time}


def rover_in_time_window(rover, window, source: str):
    """The rover epochs inside the recipe's [time] window (start_gps_s / end_gps_s in GPS
    seconds of week; of [time].gps_week, else of the rover's first epoch's week): the
    GNSS-only jobs process only those, as the IMU jobs do. GmisInputError naming the
    window and the file's span when none is inside."""
    from gnss.rinex import _slice_epochs

    if window is None or (window.start_gps_s is None and window.end_gps_s is None):
        return rover
    week = window.gps_week if window.gps_week is not None else int(rover.week[0])
    lo = -np.inf if window.start_gps_s is None else week * 604800.0 + window.start_gps_s
    hi = np.inf if window.end_gps_s is None else week * 604800.0 + window.end_gps_s
    keep = (rover.t_gps >= lo - 1e-6) & (rover.t_gps <= hi + 1e-6)
    if not keep.any():
        span = f"{rover.sow[0]:.1f}..{rover.sow[-1]:.1f}"
        raise GmisInputError(f"time: no rover epoch inside the [time] window "
                             f"{window.start_gps_s}..{window.end_gps_s} s of GPS week {week} "
                             f"(the rover file holds {span} s of week {int(rover.week[0])})",
                             source=source)
    return rover if keep.all() else _slice_epochs(rover, keep)


def run_rtk_recipe(recipe_path, results_dir, progress=None) -> dict:
    """Run RTK for a recipe and write rtk.pos, rtk.csv and summary.json into results_dir.
    Returns the summary dict."""
    recipe_path = Path(recipe_path).expanduser().resolve()
    inp = read_rtk_recipe(recipe_path)
    t0 = time.perf_counter()
    base = read_obs(inp["base_obs"])
    rover = rover_in_time_window(read_obs(inp["rover_obs"]), inp["time"], str(recipe_path))
    nav = read_nav(inp["nav"])
    check_rtk_inputs(base, rover, nav, inp["base_ecef"], str(recipe_path))
    sol = process_rtk(base, rover, nav, inp["base_ecef"], inp["config"], progress=progress)
    wall = time.perf_counter() - t0
    fixed = sol.q == Q_FIXED
    summary = {
        "dataset": inp["name"],
        "epochs": int(sol.t_gps.size),
        "epochs_solved": int((sol.q > 0).sum()),
        "epochs_fixed": int(fixed.sum()),
        "fix_rate": sol.fix_rate,
        "frequencies": list(inp["config"].frequencies),
        "epochs_partial_fixed": int((fixed & sol.partial).sum()),
        "median_ratio": float(np.median(sol.ratio[sol.q > 0])) if (sol.q > 0).any() else 0.0,
        "mean_fixed_ecef_m": sol.ecef[fixed].mean(axis=0).tolist() if fixed.any() else None,
        "baseline_length_m": float(np.linalg.norm(sol.ecef[fixed].mean(axis=0)
                                                  - inp["base_ecef"])) if fixed.any() else None,
        "wall_time_s": wall,
    }
    sol = solved_epochs(sol, sol.q > 0, "gmis rtk", inp["rover_obs"])
    with results_directory(results_dir) as out:
        write_pos(out / "rtk.pos", sol, [f"gmis rtk {recipe_path}",
                                         f"base ECEF {np.round(inp['base_ecef'], 4).tolist()}"])
        write_csv(out / "rtk.csv", ["t_gps_s", "x_m", "y_m", "z_m", "lat_deg", "lon_deg",
                                    "h_m", "q", "ratio", "n_sat", "sigma_e_m", "sigma_n_m",
                                    "sigma_u_m"],
                  sol.t_gps, sol.ecef, np.degrees(sol.llh[:, :2]), sol.llh[:, 2], sol.q,
                  sol.ratio, sol.n_sat, sol.sigma_enu, fmt="%.12g")
        write_json(out / "summary.json", summary)
    return summary


__all__ = ["read_rtk_recipe", "rover_in_time_window", "run_rtk_recipe"]
