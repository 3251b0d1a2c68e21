"""VCE convergence figures (001 §6.2.3.5, §6.2.4.2): σ per component vs iteration,
the variance factor σ̂²₀ vs iteration with the convergence band |σ̂²₀ − 1| ≤ tol, the
mean redundancy per component with the hold threshold (0.1 by default), and σ̂²₀ over the
sliding windows of the final iteration."""

from __future__ import annotations

import math

import numpy as np
from matplotlib.ticker import FuncFormatter

from gmis.report.figures_residuals import is_process_component
from gmis.report.plotting import FigureFile, new_figure, pretty_unit, saved_figure, subplot_grid

PLAIN = FuncFormatter(lambda v, _: f"{v:g}")
PLAIN_MINOR = FuncFormatter(lambda v, _: f"{v:g}" if f"{v:.1e}"[0] in "25" else "")
DEFAULT_TOL = 0.02
DEFAULT_MIN_REDUNDANCY = 0.1


def history_series(vce, column: str) -> dict:
    """{component: (iterations, values)} of one vce_history.csv column."""
    out = {}
    for name in vce.components:
        rows = [r for r in vce.history if r["component"] == name]
        out[name] = (np.array([r["iteration"] for r in rows]),
                     np.array([r[column] for r in rows]))
    return out


def _units(vce) -> dict:
    return {r["component"]: pretty_unit(r["unit"]) for r in vce.history}


def sigma_figure(vce, out_dir, formats) -> FigureFile:
    """σ used in each iteration and the final proposal (next σ) per component."""
    sig = history_series(vce, "sigma")
    nxt = history_series(vce, "next_sigma")
    units = _units(vce)
    n = len(vce.components)
    rows = max(1, math.ceil(n / 4))
    fig = new_figure(7.5, 2.0 * rows + 0.6)
    axes = subplot_grid(fig, rows, 4, left=0.6, wgap=0.7, hgap=0.65, top=0.5,
                        bottom=0.45).ravel()
    for ax in axes[n:]:
        ax.set_visible(False)
    for ax, name in zip(axes, vce.components):
        it, s = sig[name]
        it2, s2 = nxt[name]
        color = "tab:red" if is_process_component(name) else "tab:blue"
        ax.plot(it, s, "o-", markersize=2.5, color=color)
        ax.plot([it[-1], it2[-1] + 1], [s[-1], s2[-1]], "o--", markersize=3.5,
                color=color, markerfacecolor="white", markevery=[1])
        ax.set_title(name)
        ax.set_ylabel(f"σ ({units[name]})")
        ax.set_xlabel("iteration")
        ax.xaxis.get_major_locator().set_params(integer=True)
    fig.suptitle("VCE: σ per component vs iteration (hollow, dashed: σ proposed by the final "
                 "iteration)")
    return saved_figure(fig, out_dir, formats, "vce_sigma",
                        "σ per variance component vs iteration",
                        "Standard deviation σ of each variance component used in each VCE "
                        "iteration (units per panel: deg/s, m/s², m/s³, deg/s², or a "
                        "dimensionless scale on the per-epoch file sigmas); the last point is "
                        "the σ proposed by the final iteration (hollow marker). Blue: "
                        "measurement, red: process noise.", "vce")


def sigma0_redundancy_figure(vce, out_dir, formats) -> list:
    """σ̂²₀ vs iteration (band 1 ± tol, log axis) and mean redundancy (line at threshold)."""
    tol = float(vce.summary.get("tol") or DEFAULT_TOL)
    rmin = float(vce.summary.get("min_redundancy") or DEFAULT_MIN_REDUNDANCY)
    s0 = history_series(vce, "sigma0_sq")
    red = history_series(vce, "mean_redundancy")
    figures = []
    for stem, series, title, ylabel, caption in (
            ("vce_sigma0", s0, "Variance factor σ̂²₀ vs iteration", "σ̂²₀ (-)",
             (f"Helmert variance factor σ̂²₀ of each component per iteration "
              f"(dimensionless; log scale when it spans more than a factor 4); grey band: "
              f"convergence tolerance |σ̂²₀ − 1| ≤ {tol:g}; a missing point: not computed "
              f"(component held for low redundancy).")),
            ("vce_redundancy", red, "Mean redundancy per component vs iteration",
             "mean redundancy r̄ (-)",
             (f"Mean redundancy index r̄ of each component per iteration (dimensionless); "
              f"dashed: hold threshold {rmin:g} (components below keep their σ)."))):
        fig = new_figure(7.5, 3.4)
        axes = subplot_grid(fig, 1, 2, left=0.65, top=0.5, bottom=0.5).ravel()
        for ax, kind in zip(axes, ("measurement", "process")):
            names = [c for c in vce.components if is_process_component(c) == (kind == "process")]
            for name in names:
                it, y = series[name]
                ax.plot(it, y, "o-", markersize=2.5, label=name)
            if stem == "vce_sigma0":
                ax.axhspan(1 - tol, 1 + tol, color="0.6", alpha=0.35, label=f"1 ± {tol:g}")
                ax.axhline(1.0, color="k", linewidth=0.6)
                values = np.concatenate([series[n][1] for n in names] + [[1.0]])
                values = values[np.isfinite(values) & (values > 0)]
                if values.max() / values.min() > 4.0:
                    ax.set_yscale("log")
                    ax.yaxis.set_major_formatter(PLAIN)
                    ax.yaxis.set_minor_formatter(PLAIN_MINOR)
            else:
                ax.axhline(rmin, color="k", linestyle="--", linewidth=0.8,
                           label=f"threshold {rmin:g}")
                ax.set_ylim(bottom=0)
            ax.set_title(f"{kind} components")
            ax.set_xlabel("iteration")
            ax.set_ylabel(ylabel)
            ax.xaxis.get_major_locator().set_params(integer=True)
            if names:
                ax.legend(ncol=2, loc="best")
        fig.suptitle(title)
        figures.append(saved_figure(fig, out_dir, formats, stem, title, caption, "vce"))
    return figures


def windows_figure(vce, out_dir, formats) -> FigureFile | None:
    """σ̂²₀ over the sliding windows of the final iteration, per component."""
    if not vce.windows_final:
        return None
    t0 = min((float(t[0]) for t, _, _ in vce.windows_final.values() if t.size), default=0.0)
    fig = new_figure(7.5, 3.4)
    axes = subplot_grid(fig, 1, 2, left=0.65, top=0.5, bottom=0.5).ravel()
    for ax, kind in zip(axes, ("measurement", "process")):
        drawn = False
        for name, (t, s, _r) in vce.windows_final.items():
            if is_process_component(name) != (kind == "process"):
                continue
            ax.plot(t - t0, s, ".-", markersize=3, label=name)
            drawn = True
        ax.axhline(1.0, color="k", linewidth=0.6)
        ax.set_title(f"{kind} components")
        ax.set_xlabel("window centre − t₀ (s)")
        ax.set_ylabel("σ̂²₀ in window (-)")
        if drawn:
            ax.legend(ncol=2)
    fig.suptitle("Final iteration: variance factor over sliding windows "
                 f"(t₀ = {t0:.2f} s GPS, the first window's centre)")
    return saved_figure(fig, out_dir, formats, "vce_windows", "σ̂²₀ over sliding windows (final iteration)",
                        "Variance factor σ̂²₀ per component computed over sliding windows of the "
                        "final VCE iteration (dimensionless) vs window centre time (s); values "
                        "near 1 throughout mean the tuned noise fits the whole run.",
                        "vce")
