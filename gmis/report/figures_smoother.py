"""Figures of a smoothed `gmis run` folder (gmis.smoothed_run): forward vs smoothed
horizontal/vertical position error and 1σ against time, GNSS gaps shaded (from the
forward records), and without a reference the ratio σ_smoothed / σ_forward. Units: m, s."""

from __future__ import annotations

import numpy as np

from gmis.report.plotting import (
    FigureFile,
    new_figure,
    plot_decimated,
    saved_figure,
    subplot_grid,
    time_axis,
)


def gnss_gaps(records, min_gap_s: float = 1.0):
    """[(start, end)] GPS s of the gaps longer than min_gap_s between GNSS position
    updates in records.npz (outages in the data and withheld windows alike)."""
    names = [str(n) for n in records["slot_names"]]
    if "pos_e" not in names:
        return []
    t = records["t"][np.isfinite(records["innov"][:, names.index("pos_e")])]
    if t.size < 2:
        return []
    k = np.flatnonzero(np.diff(t) > min_gap_s)
    return [(float(t[i]), float(t[i + 1])) for i in k]


def _shade_outages(ax, gaps, t0):
    for k, (a, b) in enumerate(gaps):
        ax.axvspan(a - t0, b - t0, color="tab:red", alpha=0.12, linewidth=0,
                   label="no GNSS" if k == 0 else None)


def forward_vs_smoothed_figure(run, out_dir, formats) -> FigureFile | None:
    """Horizontal and vertical position error (with a reference) and 1σ, forward vs
    smoothed; None for a run without the smoother."""
    if run.forward is None:
        return None
    fwd, smo = run.forward, run.solution
    t0 = float(fwd["t"][0])
    have_err = run.errors is not None and run.errors_forward is not None
    fig = new_figure(7.5, 7.4 if have_err else 5.0)
    rows = 3 if have_err else 2
    axes = subplot_grid(fig, rows, 1, left=0.8, top=0.45, bottom=0.5, hgap=0.4, sharex=True)
    r = 0
    if have_err:
        for name, err, color in (("forward", run.errors_forward, "tab:orange"),
                                 ("smoothed", run.errors, "tab:blue")):
            ts = time_axis(err["time_gps_s"], t0)
            plot_decimated(axes[0, 0], ts, np.hypot(err["de_m"], err["dn_m"]), color=color,
                           label=f"{name} horizontal")
            plot_decimated(axes[1, 0], ts, np.abs(err["du_m"]), color=color,
                           label=f"{name} |vertical|")
        axes[0, 0].set_ylabel("horizontal error (m)")
        axes[1, 0].set_ylabel("|vertical error| (m)")
        axes[0, 0].set_yscale("log")
        axes[1, 0].set_yscale("log")
        r = 2
    sd_ax = axes[r, 0] if have_err else axes[0, 0]
    for name, sol, color in (("forward", fwd, "tab:orange"), ("smoothed", smo, "tab:blue")):
        ts = time_axis(sol["t"], t0)
        plot_decimated(sd_ax, ts, np.hypot(sol["enu_sd"][:, 0], sol["enu_sd"][:, 1]),
                       color=color, label=f"{name} horizontal 1σ")
    sd_ax.set_yscale("log")
    sd_ax.set_ylabel("horizontal 1σ (m)")
    if not have_err:
        rows_f = np.searchsorted(fwd["t"], smo["t"])
        ratio = smo["enu_sd"][:, 0] / fwd["enu_sd"][rows_f, 0]
        plot_decimated(axes[1, 0], time_axis(smo["t"], t0), ratio, color="tab:blue",
                       label="σ_E smoothed / forward")
        axes[1, 0].set_ylabel("σ ratio (-)")
    gaps = gnss_gaps(run.records)
    for ax in axes[:, 0]:
        _shade_outages(ax, gaps, t0)
        ax.legend(loc="upper right", fontsize=7)
    axes[-1, 0].set_xlabel("time since start (s)")
    fig.suptitle(f"Forward filter vs two-filter smoother (start = {t0:.2f} s GPS)")
    return saved_figure(fig, out_dir, formats, "forward_vs_smoothed", "Forward vs smoothed",
                        "Horizontal and |vertical| position error against the reference (m, "
                        "log scale; when the dataset has one) and horizontal 1σ (m) of the "
                        "forward filter and of the two-filter smoother vs time (s); shaded: "
                        "gaps of more than 1 s between GNSS position updates.",
                        "solution")


__all__ = ["forward_vs_smoothed_figure"]
