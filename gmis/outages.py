"""GNSS-outage experiment: GMIKF vs the conventional error-state EKF ("ErrINSEKF") vs pure
dead reckoning (001 §4.3.5, Table 4-7, Fig. 4-26).

Window rule (``choose_outage_windows``): the moving part of the run is
[t_a, t_b] with t_a = max(end of the static alignment, first GNSS epoch with horizontal
speed > 0.5 m/s) and t_b = min(last such GNSS epoch, last GNSS epoch, last IMU sample).
The data's own GNSS gaps (no fix for > 3 nominal intervals, ±2 s margin) are taken out of
[t_a, t_b]; the remaining GNSS-covered time is cut into ``count`` equal slots, and window i
(length ``duration_s``) is centred in slot i, or, where it would touch a gap, moved the
least distance to just before or just after that gap; a window that then overlaps its
predecessor (2 s margin) or leaves [t_a, t_b] is an error. Windows therefore never overlap,
never touch a native gap, lie wholly inside the IMU and GNSS data, and sample the drive
evenly (stops inside the moving part can fall into a window, as in 001's Table 4-7). A
slot shorter than duration_s + 2 s is an input error.

Inside each window GNSS position and velocity are removed, and by default the heading too
(``keep_heading=False``: 001's outages leave "only the IMU raw outputs"; with
``keep_heading=True`` the dual-antenna heading stays). Both filters run on the same
PreparedRun from the same initial state (the static alignment x0). The third column is
pure dead reckoning, 001's "conventional DR" baseline: at the last epoch before each window
the strapdown mechanization (gmis.errins) restarts from the error-state EKF's state and
integrates the IMU alone, with the raw outputs (``dr_biases="raw"``, default) or with the
biases that EKF had estimated removed (``"filter"``; without heading in the window that
equals the EKF's own free-inertial solution). Drift of a solution in a
window is its position error (against the reference trajectory, or without one against the
same filter's full-GNSS solution) minus the error at the last epoch before the window:
d(t) = e(t) − e(t_start). Per window the maximum |d| per ENU axis and the maximum horizontal
|d| are reported; the last row is the RMS across windows (layout of 001 Table 4-7).

Outputs (gmis.results.results_directory, all-or-nothing): outages.csv, summary.json,
outage_drift.png (drift vs time since outage start, 150 dpi).
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np
from numba import njit

from gmis.errins import mechanize_into, nav_state, run_errins_prepared
from gmis.errors import GmisInputError
from gmis.pipeline import geodetic_to_enu_rows, navigation_solution, prepare_run, run_prepared
from gmis.recipe import load_recipe
from gmis.results import results_directory, write_csv, write_json
from gmis.state import NAV_R

NATIVE_GAP_MARGIN_S = 2.0  # keep windows this far from the data's own GNSS gaps
MOVING_SPEED_M_S = 0.5
SLOT_MARGIN_S = 2.0
FILTERS = ("errins", "gmikf", "dr")
FILTER_LABELS = {"errins": "ErrINSEKF (conventional)", "gmikf": "GMIKF",
                 "dr": "dead reckoning (raw IMU)"}


def choose_outage_windows(prep, duration_s: float, count: int):
    """[(start, end), ...] GPS s by the rule in the module docstring."""
    if not (duration_s > 0 and math.isfinite(duration_s)):
        raise GmisInputError(f"outage duration must be > 0 s, got {duration_s}", "--duration")
    if int(count) != count or count < 1:
        raise GmisInputError(f"outage count must be a positive integer, got {count}", "--count")
    ds = prep.dataset
    t_imu = ds.imu.t
    g = ds.gnss
    if g is None or g.t.size == 0:
        raise GmisInputError("the dataset has no GNSS solution to remove",
                             str(prep.recipe.path))
    if g.vel_enu is not None:
        speed = np.hypot(g.vel_enu[:, 0], g.vel_enu[:, 1])
    else:
        enu = geodetic_to_enu_rows(prep.frame, np.ascontiguousarray(g.llh))
        step = np.diff(enu[:, :2], axis=0)
        speed = np.r_[0.0, np.hypot(step[:, 0], step[:, 1]) / np.maximum(np.diff(g.t), 1e-9)]
    moving = g.t[speed > MOVING_SPEED_M_S]
    if moving.size == 0:
        raise GmisInputError("the vehicle never moves faster than 0.5 m/s: no moving part to "
                             "place outages in", str(prep.recipe.path))
    t_align_end = t_imu[0] + prep.recipe.filter.static_alignment_s
    t_a = max(t_align_end, moving[0])
    t_b = min(moving[-1], g.t[-1], t_imu[-1])
    # native GNSS gaps (no fix for more than 3 nominal intervals): windows must not touch
    # them, or the experiment would measure a longer, different outage. The slots cut the
    # GNSS-covered time of [t_a, t_b] (the gaps with their margins taken out) into equal
    # parts, so a native gap costs its slot no length.
    dt = np.diff(g.t)
    nominal = float(np.median(dt)) if dt.size else 0.0
    gap_idx = np.flatnonzero(dt > 3.0 * nominal)
    gaps = [(g.t[k] - NATIVE_GAP_MARGIN_S, g.t[k + 1] + NATIVE_GAP_MARGIN_S) for k in gap_idx]
    free = _free_intervals(t_a, t_b, gaps)
    free_len = np.array([b - a for a, b in free])
    free_total = float(free_len.sum())
    slot = free_total / count
    if slot < duration_s + SLOT_MARGIN_S:
        raise GmisInputError(f"{count} outages of {duration_s:g} s do not fit in the moving part "
                             f"of the run ({max(free_total, 0.0):.1f} s with GNSS after the "
                             f"static alignment): need slots of at least "
                             f"{duration_s + SLOT_MARGIN_S:g} s", "--count/--duration")
    cum = np.r_[0.0, np.cumsum(free_len)]

    def real_time(u):
        """GNSS-covered time u (s from t_a, gaps skipped) → GPS time."""
        k = min(int(np.searchsorted(cum, u, side="right")) - 1, len(free) - 1)
        return free[k][0] + (u - cum[k])

    windows = []
    for i in range(count):
        s0, s1 = real_time(i * slot), real_time((i + 1) * slot)
        a = real_time((i + 0.5) * slot) - 0.5 * duration_s
        a = _clear_of_gaps(a, duration_s, gaps)
        lo = windows[-1][1] + SLOT_MARGIN_S if windows else t_a
        if a is None or a < lo or a + duration_s > t_b:
            raise GmisInputError(f"outage slot {i + 1} ({s0:.1f}..{s1:.1f} s) has no "
                                 f"{duration_s:g} s stretch clear of the data's own GNSS gaps; "
                                 "use fewer or shorter outages", "--count/--duration")
        windows.append((float(a), float(a + duration_s)))
    return windows


def _clear_of_gaps(a, duration_s, gaps):
    """Start of a window [a, a + duration_s] moved the least distance (before or after a
    gap it touches) so that it touches no gap; None if none found."""
    for _ in range(2 * len(gaps) + 1):
        hit = [(ga, gb) for ga, gb in gaps if not (a + duration_s < ga or a > gb)]
        if not hit:
            return a
        ga, gb = hit[0]
        before, after = ga - duration_s - 1e-6, gb + 1e-6
        a = before if a - before <= after - a else after
    return None


def _free_intervals(t_a, t_b, gaps):
    """[t_a, t_b] without the (merged) gap intervals: [(a, b), ...] in time order."""
    out, start = [], t_a
    for ga, gb in sorted(gaps):
        if gb <= start or ga >= t_b:
            continue
        if ga > start:
            out.append((start, ga))
        start = max(start, gb)
    if start < t_b:
        out.append((start, t_b))
    return out or [(t_a, t_a)]


def _interp_rows(t, tp, fp):
    return np.column_stack([np.interp(t, tp, fp[:, i]) for i in range(fp.shape[1])])


def _reference_positions(prep, t):
    ref = prep.dataset.reference
    if ref is None:
        return None
    enu = geodetic_to_enu_rows(prep.frame, np.ascontiguousarray(ref.llh))
    return _interp_rows(t, ref.t, enu)


def _motion_label(t, speed, yaw_rate, a, b):
    sel = (t >= a) & (t <= b)
    if not sel.any():
        return "unknown"
    if np.mean(speed[sel]) < MOVING_SPEED_M_S:
        return "static"
    if np.max(np.abs(yaw_rate[sel])) > math.radians(3.0):
        return "turning"
    return "straight line"


def _motion_profile(prep):
    """(t, horizontal speed m/s, heading rate rad/s) from the reference, else from GNSS."""
    ref = prep.dataset.reference
    if ref is not None:
        t = ref.t
        speed = np.hypot(ref.vel_enu[:, 0], ref.vel_enu[:, 1])
        hdg = np.unwrap(ref.euler[:, 2])
    else:
        g = prep.dataset.gnss
        t = g.t
        v = g.vel_enu if g.vel_enu is not None else np.zeros((t.size, 3))
        speed = np.hypot(v[:, 0], v[:, 1])
        hdg = np.unwrap(np.arctan2(v[:, 0], v[:, 1]))
        hdg[speed < MOVING_SPEED_M_S] = np.nan
        hdg = np.where(np.isnan(hdg), 0.0, hdg)
    rate = np.gradient(hdg, t) if t.size > 1 else np.zeros_like(t)
    return t, speed, rate


def window_drifts(t, pos, ref_pos, windows):
    """Per window: (times since start, drift (K,3)) and max |drift| E, N, U, horizontal."""
    out = []
    err = pos - ref_pos
    for a, b in windows:
        before = np.nonzero(t < a)[0]
        if before.size == 0:
            raise GmisInputError(f"outage window starting at {a:.3f} s has no epoch before it",
                                 "outages")
        k0 = before[-1]
        sel = np.nonzero((t >= a) & (t <= b))[0]
        d = err[sel] - err[k0]
        horiz = np.hypot(d[:, 0], d[:, 1])
        out.append({"t": t[sel] - a, "drift": d,
                    "max_abs": np.r_[np.abs(d).max(axis=0), horiz.max()]})
    return out


@njit(cache=True)
def _dead_reckon_into(nav, t_imu, gyro, accel, i0, i1, frame, out_pos):
    """Strapdown mechanization (gmis.errins.mechanize_into, trapezoid rates) of IMU samples
    i0…i1 from nav (21,), with the biases held in nav[15:21] (zero = raw IMU);
    out_pos[k] = r^n at sample i0 + k."""
    work3 = np.zeros((4, 3, 3))
    g = np.zeros(3)
    dg = np.zeros((3, 3))
    for i in range(3):
        out_pos[0, i] = nav[i]
    for i in range(i0, i1):
        dt = t_imu[i + 1] - t_imu[i]
        w = np.empty(6)
        for j in range(3):
            w[j] = 0.5 * (gyro[i, j] + gyro[i + 1, j]) - nav[15 + j]
            w[3 + j] = 0.5 * (accel[i, j] + accel[i + 1, j]) - nav[18 + j]
        mechanize_into(nav, w[0], w[1], w[2], w[3], w[4], w[5], dt, frame, work3, g, dg)
        for j in range(3):
            out_pos[i + 1 - i0, j] = nav[j]


def dead_reckoning_positions(prep, rec_e, t, keep, windows, base_pos, biases: str):
    """Positions (E, 3) equal to base_pos except inside the windows, where they come from
    pure dead reckoning (001 §4.3.5 'conventional DR'): the strapdown mechanization of the
    IMU alone, started from the error-state EKF's navigation state at the last epoch before
    the window. biases = "raw" mechanizes the raw IMU outputs (001's baseline); "filter"
    removes the biases the error-state EKF had estimated at the window start (then the DR
    equals the error-state EKF's free inertial solution unless heading is kept)."""
    imu = prep.dataset.imu
    rows = rec_e.imu_row
    out = np.array(base_pos, float)
    idx = np.flatnonzero(keep)
    frame = np.ascontiguousarray(prep.frame, dtype=float)
    gyro = np.ascontiguousarray(imu.gyro, dtype=float)
    accel = np.ascontiguousarray(imu.accel, dtype=float)
    for a, b in windows:
        before = idx[t[idx] < a]
        if before.size == 0:
            continue
        k0 = before[-1]
        inside = idx[(t[idx] >= a) & (t[idx] <= b)]
        if inside.size == 0:
            continue
        i0, i1 = int(rows[k0]), int(rows[inside[-1]])
        n = rec_e.nav[k0]
        nav = nav_state(n[0:3], n[3:6], n[6:9], n[9:12], n[12:15])
        if biases == "raw":
            nav[15:21] = 0.0
        pos = np.empty((i1 - i0 + 1, 3))
        _dead_reckon_into(nav, np.ascontiguousarray(imu.t, dtype=float), gyro, accel, i0, i1,
                          frame, pos)
        out[inside] = pos[rows[inside] - i0]
    return out


def _figure(path, drifts, windows, title):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), sharex=True)
    colors = {"errins": "tab:red", "gmikf": "tab:blue", "dr": "tab:gray"}
    names = ["East", "North", "Up", "Horizontal"]
    for name in FILTERS:
        for i, w in enumerate(drifts[name]):
            d = w["drift"]
            series = [d[:, 0], d[:, 1], d[:, 2], np.hypot(d[:, 0], d[:, 1])]
            for ax, s in zip(axes.ravel(), series):
                ax.plot(w["t"], s, color=colors[name], lw=0.9, alpha=0.8,
                        label=FILTER_LABELS[name] if i == 0 else None)
    for ax, n in zip(axes.ravel(), names):
        ax.set_title(f"{n} drift")
        ax.set_ylabel("m")
        ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("time since outage start (s)")
    axes[0, 0].legend(loc="best", fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def _without_gnss(prep, windows):
    """The dataset with the GNSS solution (position and velocity) removed inside the
    windows, heading untouched; and the number of GNSS samples removed."""
    g = prep.dataset.gnss
    keep = np.ones(g.t.size, bool)
    for a, b in windows:
        keep &= ~((g.t >= a) & (g.t <= b))
    gnss = dataclasses.replace(
        g, t=g.t[keep], llh=g.llh[keep], pos_sigma=g.pos_sigma[keep],
        vel_enu=None if g.vel_enu is None else g.vel_enu[keep],
        vel_sigma=None if g.vel_sigma is None else g.vel_sigma[keep])
    return dataclasses.replace(prep.dataset, gnss=gnss), int((~keep).sum())


def _rows_by_imu_sample(imu_row_full, imu_rows_wanted) -> np.ndarray:
    """The epochs of a run (its (E,) IMU row per epoch, −1 for aiding-only epochs) that
    hold the IMU samples imu_rows_wanted."""
    imu_row_full = np.asarray(imu_row_full)
    epochs = np.flatnonzero(imu_row_full >= 0)
    by_sample = np.full(int(imu_row_full.max()) + 1, -1, dtype=np.int64)
    by_sample[imu_row_full[epochs]] = epochs
    return by_sample[np.asarray(imu_rows_wanted)]


def run_outage_experiment(recipe_path, duration_s: float = 20.0, count: int = 8,
                          results_dir=None, progress=None, keep_heading: bool = False,
                          dr_biases: str = "raw") -> dict:
    """Run the experiment; write the results folder when results_dir is given. Returns the
    summary dict (windows, per-window drifts of the GMIKF, the error-state EKF and pure dead
    reckoning, RMS rows). keep_heading: the dual-antenna heading stays in the outages (only
    GNSS position/velocity are removed; default: removed too, as in the GNSS-only outages
    of 001 §4.3.5). dr_biases: "raw" (dead reckoning of the raw IMU, 001's baseline) or
    "filter" (IMU biases the error-state EKF estimated before the window removed)."""
    if dr_biases not in ("raw", "filter"):
        raise GmisInputError(f"must be 'raw' or 'filter', got {dr_biases!r}", "--dr-biases")
    t_start = time.perf_counter()
    report = progress or (lambda fraction: None)
    recipe = load_recipe(recipe_path)
    if recipe.filter.mode != "loose":
        raise GmisInputError(f"filter.mode = {recipe.filter.mode!r}: the outage experiment "
                             "compares loosely coupled filters; use \"loose\"",
                             source=str(recipe.path))
    full = prepare_run(recipe)
    windows = choose_outage_windows(full, float(duration_s), count)
    if keep_heading:
        ds_out, removed = _without_gnss(full, windows)
        prep = prepare_run(recipe, dataset=ds_out)
        prep.gnss_removed = removed
    else:
        prep = prepare_run(recipe, dataset=full.dataset, gnss_outages=windows)
    report(0.05)
    has_ref = prep.dataset.reference is not None
    n_runs = 2 if has_ref else 4
    done = [0]

    def sub(fraction):
        report(0.05 + 0.9 * (done[0] + fraction) / n_runs)

    positions = {}
    rec_g = run_prepared(prep, progress=sub)
    done[0] += 1
    t = rec_g.t
    imu_rows = rec_g.imu_row >= 0
    positions["gmikf"] = navigation_solution(prep, rec_g)["enu"]
    rec_e = run_errins_prepared(prep, progress=sub)
    done[0] += 1
    positions["errins"] = rec_e.nav[:, NAV_R]
    if has_ref:
        inside = (t >= prep.dataset.reference.t[0]) & (t <= prep.dataset.reference.t[-1])
        keep = imu_rows & inside
        ref_pos = {name: _reference_positions(prep, t[keep]) for name in FILTERS}
        basis = "reference trajectory"
    else:
        keep = imu_rows
        rec_full = run_prepared(full, progress=sub)
        g_full = navigation_solution(full, rec_full)["enu"]
        done[0] += 1
        e_full = run_errins_prepared(full, progress=sub).nav[:, NAV_R]
        done[0] += 1
        # the two runs share the IMU epochs, not the aiding-only ones (withheld GNSS
        # leaves some out): compare them IMU sample by IMU sample
        at = _rows_by_imu_sample(rec_full.imu_row, rec_g.imu_row[keep])
        ref_pos = {"gmikf": g_full[at], "errins": e_full[at], "dr": e_full[at]}
        basis = "same filter with full GNSS (no reference trajectory in the dataset)"
    positions["dr"] = dead_reckoning_positions(prep, rec_e, t, keep, windows,
                                               positions["errins"], dr_biases)
    drifts = {name: window_drifts(t[keep], positions[name][keep], ref_pos[name], windows)
              for name in FILTERS}
    mt, speed, yaw_rate = _motion_profile(prep)
    motion = [_motion_label(mt, speed, yaw_rate, a, b) for a, b in windows]
    table = np.array([[*drifts["errins"][i]["max_abs"], *drifts["gmikf"][i]["max_abs"],
                       *drifts["dr"][i]["max_abs"]] for i in range(len(windows))])
    rms = np.sqrt((table ** 2).mean(axis=0))
    in_windows = np.zeros(t.size, bool)
    for a, b in windows:
        in_windows |= (t >= a) & (t <= b)
    t0 = prep.dataset.imu.t[0]
    axes = ("east", "north", "up", "horizontal")
    summary = {
        "recipe": str(recipe.path),
        "dataset": recipe.dataset.name,
        "duration_s": float(duration_s),
        "count": int(count),
        "drift_basis": basis,
        "window_rule": "moving part after static alignment (GNSS horizontal speed > 0.5 m/s) "
                       "cut into equal slots, one window centred per slot",
        "gnss_samples_removed": prep.gnss_removed,
        "heading_in_outages": "kept" if keep_heading else "removed",
        "dead_reckoning_biases": dr_biases,
        "windows": [{"index": i + 1, "start_gps_s": a, "end_gps_s": b,
                     "start_since_begin_s": a - t0, "motion": motion[i],
                     "errins_max_drift_m": dict(zip(axes, table[i, :4].tolist())),
                     "gmikf_max_drift_m": dict(zip(axes, table[i, 4:8].tolist())),
                     "dr_max_drift_m": dict(zip(axes, table[i, 8:].tolist()))}
                    for i, (a, b) in enumerate(windows)],
        "rms_max_drift_m": {"errins": dict(zip(axes, rms[:4].tolist())),
                            "gmikf": dict(zip(axes, rms[4:8].tolist())),
                            "dr": dict(zip(axes, rms[8:].tolist()))},
        "ratio_errins_over_gmikf": dict(zip(axes, (rms[:4] / np.maximum(rms[4:8], 1e-12))
                                            .tolist())),
        "ratio_dr_over_gmikf": dict(zip(axes, (rms[8:] / np.maximum(rms[4:8], 1e-12))
                                        .tolist())),
        "errins_rejected_observations": int(rec_e.rejected.sum()),
        "gmikf_rejected_observations": int(rec_g.rejected.sum()),
        "gmikf_rejected_outside_windows": int(rec_g.rejected[~in_windows].sum()),
        "gmikf_rejected_imu_in_windows": int(rec_g.rejected[in_windows, :6].sum()),
    }
    summary["less_drift"] = ("gmikf" if rms[7] < rms[3] else "errins")
    summary["timing_s"] = {"total": time.perf_counter() - t_start}
    if results_dir is not None:
        with results_directory(results_dir) as folder:
            idx = np.arange(1, len(windows) + 1)
            starts = np.array([a for a, _ in windows])
            write_csv(folder / "outages.csv",
                      ["window", "start_gps_s", "end_gps_s", "errins_east_m", "errins_north_m",
                       "errins_up_m", "errins_horizontal_m", "gmikf_east_m", "gmikf_north_m",
                       "gmikf_up_m", "gmikf_horizontal_m", "dr_east_m", "dr_north_m",
                       "dr_up_m", "dr_horizontal_m"],
                      np.r_[idx, 0], np.r_[starts, np.nan], np.r_[starts + duration_s, np.nan],
                      np.vstack([table, rms]), allow_nonfinite=("start_gps_s", "end_gps_s"))
            with open(folder / "outages.csv", "a") as fh:
                fh.write("# last row (window 0) = RMS across windows; motion per window: "
                         + ", ".join(f"{i + 1}: {m}" for i, m in enumerate(motion)) + "\n")
            _figure(folder / "outage_drift.png", drifts, windows,
                    f"{recipe.dataset.name}: {count} GNSS outages of {duration_s:g} s — drift vs "
                    f"{'reference' if has_ref else 'full-GNSS solution'}; RMS horizontal: "
                    f"ErrINSEKF {rms[3]:.2f} m, GMIKF {rms[7]:.2f} m, DR {rms[11]:.2f} m")
            write_json(folder / "summary.json", summary)
        summary["results_dir"] = str(Path(results_dir).resolve())
    report(1.0)
    return summary


__all__ = ["choose_outage_windows", "run_outage_experiment", "window_drifts"]
