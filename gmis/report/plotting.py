"""Shared plotting helpers: headless figures, decimation for drawing, saving, statistics.

Decimation is for drawing only: :func:`minmax_indices` keeps, per bucket, the samples with
the smallest and largest value, so spikes survive while a 1-hour 100-Hz series is drawn
with at most ``MAX_POINTS`` points per line. Statistics (histograms, KS tests, RMS) are
always computed on the full arrays.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from scipy import stats

DPI = 150
MAX_POINTS = 6000
STYLE = {"font.size": 8, "axes.titlesize": 8.5, "axes.labelsize": 8, "legend.fontsize": 7,
         "xtick.labelsize": 7, "ytick.labelsize": 7, "axes.grid": True, "grid.alpha": 0.3,
         "lines.linewidth": 0.8, "savefig.dpi": DPI}
AXIS_COLORS = ("tab:blue", "tab:orange", "tab:green")


@dataclass
class FigureFile:
    """One saved figure: file stem, title, caption (with units), saved file names
    (relative to the report folder), report section."""
    stem: str
    title: str
    caption: str
    files: list
    section: str
    stats: dict = field(default_factory=dict)


def new_figure(width_in: float, height_in: float) -> Figure:
    """A pyplot-free figure (no GUI backend, no global state). Layout is fixed by
    :func:`subplot_grid` margins in inches: constrained layout costs ~0.5 s per figure."""
    return Figure(figsize=(width_in, height_in))


def subplot_grid(fig: Figure, rows: int, cols: int, left=0.7, right=0.15, bottom=0.5,
                 top=0.5, hgap=0.55, wgap=0.7, **kw):
    """fig.subplots(rows, cols) (always a 2-D array) with margins and gaps in inches:
    ``top`` leaves room for a suptitle, ``hgap`` for a panel title plus x labels."""
    w, h = fig.get_size_inches()
    ax_w = (w - left - right - (cols - 1) * wgap) / cols
    ax_h = (h - top - bottom - (rows - 1) * hgap) / rows
    if ax_w <= 0 or ax_h <= 0:
        raise ValueError(f"figure {w}x{h} in too small for a {rows}x{cols} grid")
    fig.subplots_adjust(left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h,
                        wspace=wgap / ax_w, hspace=hgap / ax_h)
    return fig.subplots(rows, cols, squeeze=False, **kw)


def save_figure(fig: Figure, out_dir: Path, stem: str, formats) -> list:
    """Save ``fig`` as figures/<stem>.<fmt> for each format; returns relative paths."""
    files = []
    for fmt in formats:
        rel = f"figures/{stem}.{fmt}"
        fig.savefig(out_dir / rel, dpi=DPI, format=fmt)
        files.append(rel)
    fig.clear()
    return files


def saved_figure(fig: Figure, out_dir: Path, formats, stem: str, title: str, caption: str,
                 section: str, stats: dict | None = None) -> FigureFile:
    """Save ``fig`` (:func:`save_figure`) and return its FigureFile for the report."""
    files = save_figure(fig, out_dir, stem, formats)
    return FigureFile(stem, title, caption, files, section, {} if stats is None else stats)


def minmax_indices(y: np.ndarray, max_points: int = MAX_POINTS) -> np.ndarray:
    """Sorted indices of at most ~max_points samples of y for drawing: per bucket the
    arg-min and arg-max (NaN ignored). All indices when y is short enough."""
    n = y.shape[0]
    if n <= max_points:
        return np.arange(n)
    buckets = max(1, max_points // 2)
    size = math.ceil(n / buckets)
    pad = buckets * size - n
    yy = np.concatenate([y, np.full(pad, np.nan)]).reshape(buckets, size)
    nan = np.isnan(yy)
    lo = np.argmin(np.where(nan, np.inf, yy), axis=1)
    hi = np.argmax(np.where(nan, -np.inf, yy), axis=1)
    base = np.arange(buckets) * size
    idx = np.unique(np.concatenate([base + lo, base + hi]))
    return idx[idx < n]


def gap_breaks(t: np.ndarray, factor: float = 5.0) -> np.ndarray:
    """Indices i where t[i+1] − t[i] exceeds ``factor`` × the median step (data gaps,
    e.g. GNSS outages), so lines are not drawn across them."""
    if t.size < 3:
        return np.zeros(0, dtype=int)
    dt = np.diff(t)
    return np.nonzero(dt > factor * np.median(dt))[0]


def decimate_for_drawing(t, y, max_points: int = MAX_POINTS):
    """(t, y) of the finite samples, min/max-decimated per gap-free segment, with a NaN
    between segments to break the line at data gaps. For drawing only."""
    ok = np.isfinite(y)
    t, y = np.asarray(t)[ok], np.asarray(y)[ok]
    if t.size == 0:
        return t, y
    bounds = np.concatenate([[0], gap_breaks(t) + 1, [t.size]])
    ts, ys = [], []
    for a, b in itertools.pairwise(bounds):
        share = max(4, int(max_points * (b - a) / t.size))
        idx = a + minmax_indices(y[a:b], share)
        ts += [t[idx], [np.nan]]
        ys += [y[idx], [np.nan]]
    return np.concatenate(ts[:-1]), np.concatenate(ys[:-1])


def plot_decimated(ax, t, y, max_points: int = MAX_POINTS, **kw):
    """ax.plot of the finite samples of y(t), min/max-decimated for drawing, broken at
    data gaps."""
    td, yd = decimate_for_drawing(t, y, max_points)
    return ax.plot(td, yd, **kw)


def fill_decimated(ax, t, lo, hi, max_points: int = MAX_POINTS, **kw):
    """ax.fill_between of an envelope, decimated on the upper curve (envelopes are smooth)."""
    ok = np.isfinite(lo) & np.isfinite(hi)
    t, lo, hi = t[ok], lo[ok], hi[ok]
    idx = minmax_indices(hi, max_points)
    return ax.fill_between(t[idx], lo[idx], hi[idx], **kw)


def ks_normal(w: np.ndarray) -> dict:
    """Kolmogorov-Smirnov test of the finite samples of w against N(0,1) (all samples,
    never decimated): n, mean, std, KS statistic D, p-value."""
    w = np.asarray(w, dtype=float)
    w = w[np.isfinite(w)]
    if w.size == 0:
        return {"n": 0, "mean": math.nan, "std": math.nan, "ks": math.nan, "p": math.nan}
    res = stats.kstest(w, "norm")
    return {"n": int(w.size), "mean": float(w.mean()), "std": float(w.std()),
            "ks": float(res.statistic), "p": float(res.pvalue)}


def pretty_unit(unit: str) -> str:
    """'m/s^2' → 'm/s²' for labels."""
    return unit.replace("^2", "²").replace("^3", "³")


def time_axis(t: np.ndarray, t0: float) -> np.ndarray:
    return np.asarray(t, dtype=float) - t0


def time_label(t0: float) -> str:
    return f"time since start (s); start = {t0:.2f} s GPS"
