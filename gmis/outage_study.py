"""`gmis outages RECIPE --window START:DURATION ...`: GNSS outages at given times on any
dataset, scored against the GNSS solution that was withheld (gmis.outage_windows).

Both the GMIKF and the conventional error-state EKF (gmis.errins) run on the same prepared
data with GNSS position/velocity (and heading, unless kept) removed inside the windows
(with ``smooth``, the GMIKF's two-filter smoother too, gmis.smoothed_run: the post-processed
solution, scored at its output epochs [filter].smoother_rate_hz interpolated linearly);
their primary-antenna positions (IMU centre + C_b^n l) are compared with the withheld GNSS
positions epoch by epoch. Per window and over all withheld epochs: horizontal max and RMS,
vertical RMS and max (m).

Outputs (gmis.results.results_directory, all-or-nothing): outage_windows.csv (one row per
window, GMIKF and error-state columns side by side; window 0 = all withheld epochs), summary.json, outage_errors.png (horizontal error
vs time since the window start, one line per window and filter).
"""

from __future__ import annotations

import time
from itertools import pairwise
from pathlib import Path

import numpy as np

from gmis.errors import GmisInputError
from gmis.outage_windows import score_windows

FILTERS = ("gmikf", "errins")
FILTER_LABELS = {"gmikf": "GMIKF", "errins": "error-state EKF",
                 "gmikf_smoothed": "GMIKF smoothed"}
STAT_KEYS = ("n", "horizontal_max_m", "horizontal_rms_m", "vertical_rms_m", "vertical_max_m")


def _figure(path, tracks, gnss_t, gnss_enu, windows, title):
    """tracks: {filter name: (t (K,) s, antenna ENU (K, 3) m)}."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))
    styles = {"gmikf": "-", "errins": "--", "gmikf_smoothed": ":"}
    for name, (t_sol, enu) in tracks.items():
        for i, (a, b) in enumerate(windows):
            sel = (gnss_t >= a) & (gnss_t <= b)
            if not sel.any():
                continue
            sol = np.column_stack([np.interp(gnss_t[sel], t_sol, enu[:, k]) for k in range(3)])
            e = sol - gnss_enu[sel]
            ax.plot(gnss_t[sel] - a, np.maximum(np.hypot(e[:, 0], e[:, 1]), 1e-3),
                    styles[name],
                    color=f"C{i % 10}", lw=1.0,
                    label=FILTER_LABELS[name] if i == 0 else None)
    ax.set_xlabel("time since outage start (s)")
    ax.set_yscale("log")     # errors span cm (start) to tens of m (a bad window)
    ax.set_ylabel("horizontal error vs withheld GNSS (m, log)")
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="minor", alpha=0.1)
    ax.grid(True, alpha=0.3)
    from matplotlib.lines import Line2D
    filters = ax.legend([Line2D([0], [0], color="k", ls=styles[name]) for name in tracks],
                        [FILTER_LABELS[name] for name in tracks], loc="upper left",
                        fontsize=8)
    ax.add_artist(filters)
    colours = min(len(windows), 10)          # colours repeat every 10 windows
    ax.legend([Line2D([0], [0], color=f"C{i}") for i in range(colours)],
              [", ".join(str(k + 1) for k in range(i, len(windows), 10))
               for i in range(colours)],
              title="window", loc="lower right", fontsize=7, title_fontsize=7,
              ncol=2 if colours > 5 else 1)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def gmikf_antenna_track(prep, rec, imu_epochs_only: bool = True):
    """(t (K,) s, primary-antenna ENU (K, 3) m) of a GMIKF run at its IMU epochs (all of
    its epochs when imu_epochs_only is False: smoothed records, at the output epochs):
    the solution IMU centre + C_b^n l (gmis.solution_antenna), the track scored against
    the withheld GNSS."""
    from gmis.navigation_solution import navigation_solution
    from gmis.solution_antenna import antenna_enu

    nav = navigation_solution(prep, rec)
    rows = rec.imu_row >= 0 if imu_epochs_only else np.ones(rec.t.size, bool)
    lever = np.asarray(prep.recipe.antennas.primary_lever_arm_m, float)
    return rec.t[rows], antenna_enu(nav["enu"][rows], nav["euler"][rows], lever)


def run_window_study(recipe_path, windows, results_dir=None, progress=None,
                     keep_heading: bool = False, smooth: bool = False) -> dict:
    """Outages at the given (start, end) windows (GPS s); see the module docstring.
    recipe_path: a recipe file or a loaded gmis.recipe.Recipe; smooth: score the GMIKF's
    two-filter smoother as well ("gmikf_smoothed").
    Returns the summary dict; writes the results folder when results_dir is given."""
    from gmis.enu_rows import geodetic_to_enu_rows
    from gmis.errins import REC_ATT, REC_R, run_errins_prepared
    from gmis.recipe import Recipe, load_recipe
    from gmis.results import results_directory, write_csv, write_json
    from gmis.run_preparation import prepare_run, run_prepared
    from gmis.run_summary import estimated_settings
    from gmis.solution_antenna import antenna_enu

    t_start = time.perf_counter()
    report = progress or (lambda fraction: None)
    recipe = recipe_path if isinstance(recipe_path, Recipe) else load_recipe(recipe_path)
    if recipe.filter.mode != "loose":
        raise GmisInputError(f"filter.mode = {recipe.filter.mode!r}: outage windows compare "
                             "loosely coupled filters; use \"loose\"", source=str(recipe.path))
    windows = sorted([*map(tuple, windows), *recipe.outages.spans()])
    if not windows:
        raise GmisInputError("no outage window: give --window START:DURATION or "
                             "[outages].windows", source=str(recipe.path))
    for (a0, b0), (a1, b1) in pairwise(windows):
        if a1 <= b0:      # a withheld epoch would be scored twice, as two outages
            raise GmisInputError(f"outage windows overlap: {a0:g}..{b0:g} and {a1:g}..{b1:g} "
                                 "(GPS s); give one window for the whole outage",
                                 source=str(recipe.path))
    prep = prepare_run(recipe, gnss_outages=windows,
                       remove_heading=False if keep_heading else None)
    gnss = prep.dataset.gnss
    if gnss is None or gnss.t.size == 0:
        raise GmisInputError("outage windows need a GNSS solution to withhold "
                             "([paths].gnss_solution or gnss_pos)", source=str(recipe.path))
    gnss_enu = geodetic_to_enu_rows(prep.frame, np.ascontiguousarray(gnss.llh))
    lever = np.asarray(recipe.antennas.primary_lever_arm_m, float)
    report(0.05)
    names = (*FILTERS, "gmikf_smoothed") if smooth else FILTERS
    if smooth:    # its forward pass is the plain forward run (tests/test_smoothed_run.py)
        from gmis.smoothed_run import run_smoothed
        from gmis.smoother import refuse_unsmoothable
        refuse_unsmoothable(prep.config)
        smoothed = run_smoothed(prep, progress=lambda f: report(0.05 + 0.45 * f))
        rec_g = smoothed.forward
    else:
        rec_g = run_prepared(prep, progress=lambda f: report(0.05 + 0.45 * f))
    t_sol, gmikf_antenna = gmikf_antenna_track(prep, rec_g)
    imu = rec_g.imu_row >= 0
    antenna = {"gmikf": gmikf_antenna}
    rec_e = run_errins_prepared(prep, progress=lambda f: report(0.5 + 0.45 * f))
    antenna["errins"] = antenna_enu(rec_e.nav[imu, REC_R:REC_R + 3],
                                    rec_e.nav[imu, REC_ATT:REC_ATT + 3], lever)
    tracks = {name: (t_sol, antenna[name]) for name in FILTERS}
    if smooth:
        tracks["gmikf_smoothed"] = gmikf_antenna_track(prep, smoothed.records,
                                                       imu_epochs_only=False)
    scores = {name: score_windows(*tracks[name], gnss.t, gnss_enu, windows)
              for name in names}
    summary = {
        "recipe": str(recipe.path),
        "dataset": recipe.dataset.name,
        "scored_against": "withheld GNSS solution at the primary antenna",
        "heading_in_outages": "kept" if keep_heading or not recipe.outages.remove_heading
        else "removed",
        "states": recipe.filter.states,
        "nonholonomic": recipe.nonholonomic is not None,
        "gnss_samples_removed": prep.gnss_removed,
        "windows": [{"index": i + 1, "start_gps_s": a, "end_gps_s": b,
                     **{name: scores[name][0][i] for name in names}}
                    for i, (a, b) in enumerate(windows)],
        "all_withheld_epochs": {name: scores[name][1] for name in names},
        "gmikf_covariance_reopened_epochs": int((rec_g.reopened != 0).sum()),
        **estimated_settings(prep),
    }
    summary["timing_s"] = {"total": time.perf_counter() - t_start}
    if results_dir is not None:
        with results_directory(results_dir) as folder:
            stats = [k for k in STAT_KEYS if k != "n"]
            header = ["window", "start_gps_s", "end_gps_s", "n_gnss_withheld"]
            cols = [np.r_[np.arange(1, len(windows) + 1), 0],
                    np.r_[[a for a, _ in windows], np.nan],
                    np.r_[[b for _, b in windows], np.nan],
                    np.r_[[r["n"] for r in scores["gmikf"][0]], scores["gmikf"][1]["n"]]]
            for name in names:
                for k in stats:
                    header.append(f"{name}_{k}")
                    cols.append(np.r_[[r[k] for r in scores[name][0]], scores[name][1][k]])
            write_csv(folder / "outage_windows.csv", header, *cols,
                      allow_nonfinite=("start_gps_s", "end_gps_s"))
            with open(folder / "outage_windows.csv", "a") as fh:
                fh.write("# window 0 = all withheld epochs together; errors of the antenna "
                         "solution against the withheld GNSS solution (m)\n")
            figures = ", ".join(
                f"{FILTER_LABELS[name]} {scores[name][1]['horizontal_rms_m']:.2f} m (max "
                f"{scores[name][1]['horizontal_max_m']:.2f})" for name in names)
            _figure(folder / "outage_errors.png", tracks, gnss.t, gnss_enu, windows,
                    f"{recipe.dataset.name}: {len(windows)} GNSS outages (colour = window)\n"
                    f"horizontal RMS {figures}")
            write_json(folder / "summary.json", summary)
        summary["results_dir"] = str(Path(results_dir).resolve())
    report(1.0)
    return summary


__all__ = ["gmikf_antenna_track", "run_window_study"]
