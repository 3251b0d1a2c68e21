"""Tightly coupled figures: standardized DD residual histograms per observable group and
per satellite (001 §6.2.4.2), and the ambiguity-fixing status along the run."""

from __future__ import annotations

import numpy as np

from gmis.report.figures_residuals import (
    finish_histogram_axes,
    histogram_grid,
    normal_density,
    standardized_histogram,
)
from gmis.report.plotting import ks_normal, new_figure, saved_figure, subplot_grid
from gmis.report.tables import Table

GROUPS = ("code", "phase_l1", "phase_l2", "doppler")   # files written before group_names
HIST_RANGE = 5.0


def dd_residual_histograms(run, out_dir, formats):
    """One panel per DD group: standardized residuals (all epochs and satellites) against
    N(0,1) with the KS statistic; stats carry per-group and per-satellite KS values."""
    tc = run.tc
    groups = tuple(str(n) for n in tc["group_names"]) if "group_names" in tc else GROUPS
    w, grp, prn = tc["dd_residual_std"], tc["dd_residual_group"], tc["dd_residual_prn"]
    present = [g for g in range(4) if np.any(grp == g)]
    if not present:
        return None
    fig, axes = histogram_grid(len(present), 2 if len(present) > 1 else 1)
    x = np.linspace(-HIST_RANGE, HIST_RANGE, 400)
    stats = {}
    for ax, g in zip(axes, present):
        sel = grp == g
        s = ks_normal(w[sel])
        stats[groups[g]] = {"all": s}
        frac = standardized_histogram(ax, w[sel], f"n={s['n']}, s={s['std']:.3f}", True, "tab:blue")
        ax.plot(x, normal_density(x), "k--", linewidth=0.9, label="N(0,1)")
        ax.set_title(f"DD {groups[g]}\nKS D = {s['ks']:.4f}")
        finish_histogram_axes(ax, f"outside ±{HIST_RANGE:g}: {100 * frac:.2f} %")
        for p in np.unique(prn[sel]):
            stats[groups[g]][f"G{int(p):02d}"] = ks_normal(w[sel & (prn == p)])
    fig.suptitle("Standardized DD residuals (tightly coupled) against N(0,1)")
    return saved_figure(
        fig, out_dir, formats, "dd_residual_histograms",
        "Standardized DD residuals per observable group",
        "Density of v/σ_v (dimensionless; Q_v = R D⁻¹ R with the correlated DD covariance) "
        "of every used DD observation against N(0,1) (dashed); KS statistic on the full set. "
        "Per-satellite statistics are in the table below.", "innovations", stats)


def dd_satellite_table(stats) -> Table:
    rows = []
    for group, by in stats.items():
        for key, s in by.items():
            if key != "all":
                rows.append([group, key, s["n"], s["mean"], s["std"], s["ks"]])
    return Table("dd_residuals_per_satellite", "Standardized DD residuals per satellite",
                 "v/σ_v statistics per DD group and satellite (the satellite k of the DD "
                 "k − reference); KS statistic D against N(0,1).",
                 ["group", "satellite", "n", "mean", "std", "KS D"], rows, group_by=0)


def tc_status_figure(run, out_dir, formats):
    """Satellites, fixed epochs and LAMBDA ratio along the run."""
    tc = run.tc
    t = tc["t"] - tc["t"][0]
    fig = new_figure(7.5, 4.2)
    ax = subplot_grid(fig, 2, 1, top=0.45, hgap=0.45, bottom=0.5).ravel()
    ax[0].step(t, tc["n_sat"], where="post", color="tab:blue", label="satellites")
    fixed = tc["fixed"].astype(bool)
    ax[0].plot(t[fixed], np.full(fixed.sum(), -0.3), "|", color="tab:green", ms=4,
               label="fixed epoch")
    ax[0].set_ylabel("satellites (-)")
    ax[0].legend(loc="lower right", fontsize=6, frameon=False)
    ratio = np.where(tc["ratio"] > 0, tc["ratio"], np.nan)
    ax[1].semilogy(t, ratio, ".", ms=2, color="tab:purple", label="ratio (second/best)")
    ax[1].axhline(3.0, color="k", linestyle="--", linewidth=0.8, label="threshold 3")
    ax[1].set_ylabel("ratio (-)")
    ax[1].set_xlabel("time since first GNSS epoch (s)")
    ax[1].legend(loc="lower right", fontsize=6, frameon=False)
    fig.suptitle(f"Ambiguity resolution: fix rate {fixed.mean():.3f}")
    return saved_figure(fig, out_dir, formats, "tc_fix_status", "Satellites and ambiguity fixing",
                        "Satellites used per GNSS epoch (DD reference included), epochs with a "
                        "validated fix, and the LAMBDA ratio test value (log scale; epochs "
                        "whose ambiguities are all held are not searched again and show no "
                        "ratio).", "solution")
