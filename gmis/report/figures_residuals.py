"""Residual and innovation figures (001 §5.3.5, Figs 5-2..5-12, 6-11..6-42 style).

* standardized VCE residual histograms per component, first vs final iteration, against
  the N(0,1) density, with the Kolmogorov-Smirnov statistic D = sup|F_n − Φ| of the full
  residual set in each title;
* normalized innovation histograms d/√D per measurement slot of a plain run (accepted
  epochs), same test;
* innovation time series per sensor and axis: normalized d/√D and raw d in the sensor's
  unit, outlier-rejected epochs marked.
"""

from __future__ import annotations

import math

import numpy as np

from gmis.report.plotting import (
    AXIS_COLORS,
    ks_normal,
    new_figure,
    plot_decimated,
    saved_figure,
    subplot_grid,
    time_axis,
    time_label,
)

HIST_RANGE = 5.0
HIST_BINS = 80
DEG = 180.0 / math.pi

# sensor groups of the measurement slots (gmis.gmikf.SLOT_NAMES): report unit, SI → unit
SENSOR_GROUPS = (
    ("gyro", "gyroscope", ("gyro_x", "gyro_y", "gyro_z"), "deg/s", DEG),
    ("accel", "accelerometer", ("accel_x", "accel_y", "accel_z"), "m/s²", 1.0),
    ("gnss_position", "GNSS position", ("pos_e", "pos_n", "pos_u"), "m", 1.0),
    ("gnss_velocity", "GNSS velocity", ("vel_e", "vel_n", "vel_u"), "m/s", 1.0),
    ("heading", "dual-antenna heading", ("heading",), "deg", DEG),
    ("zupt", "zero-velocity update", ("zupt_x", "zupt_y", "zupt_z"), "m/s", 1.0),
    ("zaru", "zero-angular-rate update", ("zaru_x", "zaru_y", "zaru_z"), "deg/s", DEG),
    ("gnss_speed", "GNSS speed over ground", ("speed",), "m/s", 1.0),
    ("gnss_course", "GNSS course", ("course",), "deg", DEG),
    ("nonholonomic", "non-holonomic constraint", ("nhc_lateral", "nhc_vertical"), "m/s", 1.0),
)


def is_process_component(name: str) -> bool:
    """Process-noise components: jerk, angular acceleration, bias/scale-factor drifts."""
    return name.startswith(("jerk", "angacc")) or "_drift" in name


def normal_density(x: np.ndarray) -> np.ndarray:
    return np.exp(-0.5 * x * x) / math.sqrt(2.0 * math.pi)


def standardized_histogram(ax, w: np.ndarray, label: str, filled: bool, color: str) -> float:
    """Density histogram of all finite w on ±HIST_RANGE normalized by the full count (mass
    outside the range is not re-spread); returns the fraction outside the range."""
    w = w[np.isfinite(w)]
    if w.size == 0:
        return math.nan
    edges = np.linspace(-HIST_RANGE, HIST_RANGE, HIST_BINS + 1)
    counts, _ = np.histogram(w, bins=edges)
    density = counts / (w.size * np.diff(edges))
    if filled:
        ax.stairs(density, edges, fill=True, alpha=0.45, color=color, label=label)
    else:
        ax.stairs(density, edges, color=color, linewidth=1.0, label=label)
    return 1.0 - counts.sum() / w.size


def finish_histogram_axes(ax, note: str, xlabel: str = "standardized residual (-)"):
    ax.set_xlim(-HIST_RANGE, HIST_RANGE)
    ax.set_ylim(0, 1.55 * max(ax.get_ylim()[1], 0.42))
    ax.set_xlabel(xlabel)
    ax.set_ylabel("density (-)")
    ax.legend(loc="upper left", title=note, title_fontsize=5.5, fontsize=5.5, frameon=False,
              alignment="left")


def histogram_grid(n: int, ncols: int):
    rows = max(1, math.ceil(n / ncols))
    fig = new_figure(7.5 if ncols <= 3 else 9.0, 2.35 * rows + 0.5)
    axes = subplot_grid(fig, rows, ncols, left=0.55, wgap=0.55, hgap=0.8, top=0.7,
                        bottom=0.45).ravel()
    for ax in axes[n:]:
        ax.set_visible(False)
    return fig, axes


def residual_histograms(vce, out_dir, formats) -> list:
    """Histograms of the standardized residuals of the first and final VCE iterations per
    component against N(0,1); one figure for measurement, one for process components.
    Returns FigureFile list; each carries stats {component: {first: ks..., final: ks...}}."""
    figures = []
    names = list(dict.fromkeys(list(vce.residuals_first) + list(vce.residuals_final)))
    x = np.linspace(-HIST_RANGE, HIST_RANGE, 400)
    for kind, title in (("measurement", "Standardized measurement residuals"),
                        ("process", "Standardized process-noise residuals")):
        group = [n for n in names if is_process_component(n) == (kind == "process")]
        if not group:
            continue
        fig, axes = histogram_grid(len(group), 3)
        stats = {}
        for ax, name in zip(axes, group):
            stats[name] = {}
            outside = []
            for label, res, filled, color in (("first", vce.residuals_first, False, "tab:red"),
                                              ("final", vce.residuals_final, True, "tab:blue")):
                if name not in res:
                    continue
                w = res[name][1]
                s = ks_normal(w)
                stats[name][label] = s
                frac = standardized_histogram(ax, w, f"{label}: n={s['n']}, s={s['std']:.3f}", filled,
                                  color)
                outside.append(f"{label} {100 * frac:.2f} %")
            ax.plot(x, normal_density(x), "k--", linewidth=0.9, label="N(0,1)")
            ks = " → ".join(f"{lab} {v['ks']:.4f}" for lab, v in stats[name].items())
            ax.set_title(f"{name}\nKS D: {ks}")
            finish_histogram_axes(ax, f"outside ±{HIST_RANGE:g}: " + "; ".join(outside))
        fig.suptitle(f"{title}: first vs final VCE iteration against N(0,1)")
        figures.append(saved_figure(
            fig, out_dir, formats, f"residual_histograms_{kind}",
            f"{title}, first vs final iteration",
            f"Density of the standardized {kind} residuals v/σ_v of the first (red outline) "
            "and final (blue, filled) VCE iteration, every epoch of the run (no decimation), "
            f"drawn on ±{HIST_RANGE:g} (dimensionless) with the N(0,1) density (dashed). "
            "Titles: Kolmogorov-Smirnov statistic D against N(0,1) on the full residual set.",
            "vce", stats))
    return figures


def _slot_index(records) -> dict:
    return {str(s): i for i, s in enumerate(records["slot_names"])}


def normalized_innovations(records, slot: int) -> tuple:
    """(t, d/√D, d, rejected) of the epochs where the slot has a measurement."""
    d = records["innov"][:, slot]
    var = records["innov_var"][:, slot]
    ok = np.isfinite(d) & np.isfinite(var) & (var > 0)
    t = records["t"][ok]
    return t, d[ok] / np.sqrt(var[ok]), d[ok], records["rejected"][ok, slot] != 0


def innovation_histograms(run, out_dir, formats) -> list:
    """Histograms of d/√D per measurement slot (accepted epochs) against N(0,1)."""
    rec = run.records
    present = [(i, str(s)) for i, s in enumerate(rec["slot_names"])
               if np.isfinite(rec["innov"][:, i]).any()]     # sensors this run had
    fig, axes = histogram_grid(max(len(present), 1), 4)
    x = np.linspace(-HIST_RANGE, HIST_RANGE, 400)
    stats = {}
    for ax, (i, name) in zip(axes, present):
        _, z, _, rej = normalized_innovations(rec, i)
        s = ks_normal(z[~rej])
        s["rejected"] = int(rej.sum())
        stats[name] = s
        frac = standardized_histogram(ax, z[~rej], f"n={s['n']}, s={s['std']:.3f}", True, "tab:blue")
        ax.plot(x, normal_density(x), "k--", linewidth=0.9, label="N(0,1)")
        ax.set_title(f"{name}\nKS D: {s['ks']:.4f}")
        finish_histogram_axes(ax, f"outside ±{HIST_RANGE:g}: {100 * frac:.2f} %; "
                               f"rejected {s['rejected']}", "d/√D (-)")
    fig.suptitle("Normalized innovations d/√D per measurement against N(0,1)")
    return [saved_figure(fig, out_dir, formats, "innovation_histograms",
                         "Normalized innovation histograms",
                         "Density of the normalized innovations d/√D (d = z − h(x̂⁻), "
                         "D = R + HP⁻Hᵀ, dimensionless) of every accepted epoch, against N(0,1) "
                         "(dashed); outlier-rejected epochs are excluded and counted. Titles: "
                         "Kolmogorov-Smirnov statistic D on the full set.",
                         "innovations", stats)]


def innovation_series(run, out_dir, formats) -> list:
    """Per sensor: normalized and raw innovation vs time for each axis, rejected marked."""
    rec = run.records
    index = _slot_index(rec)
    t0 = float(rec["t"][0])
    figures = []
    for key, label, slots, unit, scale in SENSOR_GROUPS:
        present = [s for s in slots if s in index]
        if not present:
            continue
        series = [normalized_innovations(rec, index[s]) for s in present]
        if all(s[0].size == 0 for s in series):
            continue
        fig = new_figure(7.5, 1.4 * len(present) + 1.0)
        axes = subplot_grid(fig, len(present), 2, left=0.75, wgap=0.8, hgap=0.15, top=0.6,
                            bottom=0.45, sharex=True)
        for row, (slot, (t, z, d, rej)) in enumerate(zip(present, series)):
            ts = time_axis(t, t0)
            color = AXIS_COLORS[row % 3]
            plot_decimated(axes[row, 0], ts, z, color=color, linewidth=0.5)
            plot_decimated(axes[row, 1], ts, d * scale, color=color, linewidth=0.5)
            for ax, y in ((axes[row, 0], z), (axes[row, 1], d * scale)):
                if rej.any():
                    ax.plot(ts[rej], y[rej], "x", color="tab:red", markersize=3.5,
                            label=f"rejected ({int(rej.sum())})")
                    ax.legend(loc="upper right")
            for c in (-3.0, 3.0):
                axes[row, 0].axhline(c, color="0.3", linestyle="--", linewidth=0.6)
            axes[row, 0].set_ylabel(f"{slot} d/√D (-)")
            axes[row, 1].set_ylabel(f"{slot} d ({unit})")
        axes[0, 0].set_title("normalized innovation (dashed: ±3)")
        axes[0, 1].set_title(f"innovation ({unit})")
        for ax in axes[-1]:
            ax.set_xlabel(time_label(t0))
        fig.suptitle(f"{label} innovations d = z − h(x̂⁻)")
        figures.append(saved_figure(
            fig, out_dir, formats, f"innovations_{key}", f"{label} innovations",
            f"{label} innovations per axis: normalized d/√D (left, dimensionless, ±3 dashed) "
            f"and raw d (right, {unit}); red crosses: epochs rejected by the outlier tests. "
            "Lines are min/max-decimated for drawing only.", "innovations"))
    return figures
