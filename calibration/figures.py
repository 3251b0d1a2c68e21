"""Calibration plots: empirical WV with CIs, the model-implied WV and each process'
contribution (000 Fig. 4.1 style); ADEV with CIs and the line fits; replicate overlay."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from calibration.allan import LINES


def _finish(fig, ax, path: Path, xlabel: str, ylabel: str, title: str) -> Path:
    """Labels, log grid, legend; save as PNG (110 dpi) and close."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def wv_figure(path: Path, axis: str, unit: str, fit, title: str, excluded=None) -> Path:
    """Empirical WV with CI, the fit's implied WV and each process' contribution;
    ``excluded``: the leading scales the smallest-scale choice left out (open markers)."""
    wv = fit.wv
    fig, ax = plt.subplots(figsize=(7, 5))
    ax.fill_between(wv.tau_s, wv.ci_low, wv.ci_high, color="0.85", label="95 % CI")
    ax.loglog(wv.tau_s, wv.nu2, "k.-", label="empirical WV")
    if excluded is not None and excluded.tau.size:
        ax.loglog(excluded.tau_s, excluded.nu2, "o", mfc="none", color="0.4",
                  label="not fitted (smallest-scale test)")
    ax.loglog(wv.tau_s, fit.implied_wv(), "r-", lw=2, label=f"implied: {fit.name}")
    k = 0
    for p, c in zip(fit.model, fit.contributions()):
        k += p == "AR1"
        ax.loglog(wv.tau_s, c, "--", lw=1, label=f"AR1[{k}]" if p == "AR1" else p)
    top = np.max(wv.ci_high) if excluded is None or not excluded.tau.size else \
        max(np.max(wv.ci_high), np.max(excluded.nu2))
    ax.set_ylim(np.min(wv.ci_low) / 10, top * 3)
    return _finish(fig, ax, path, "scale τ (s)", f"wavelet variance ({unit})²",
                   f"{axis}: {title}")


def adev_figure(path: Path, axis: str, unit: str, avs, fits) -> Path:
    fig, ax = plt.subplots(figsize=(7, 5))
    for i, av in enumerate(avs):
        ax.loglog(av.tau_s, av.adev, ".-", lw=1, label=f"replicate {i + 1}")
        ax.fill_between(av.tau_s, np.sqrt(av.ci_low), np.sqrt(av.ci_high), alpha=0.15)
    tau = avs[0].tau_s
    for name, (_, factor) in LINES.items():
        f = fits.get(name)
        if f is not None:
            ax.loglog(tau, f.coefficient * factor(tau), ":", label=f"{name} (rep. 1)")
    return _finish(fig, ax, path, "cluster time τ (s)", f"Allan deviation ({unit})",
                   f"{axis}: overlapping Allan deviation")


def overlay_figure(path: Path, axis: str, unit: str, wvs, bar, fit) -> Path:
    fig, ax = plt.subplots(figsize=(7, 5))
    for i, wv in enumerate(wvs):
        ax.loglog(wv.tau_s, wv.nu2, ".-", lw=1, label=f"replicate {i + 1}")
    ax.loglog(bar.tau_s, bar.nu2, "k-", lw=2, label="AWV ν̄")
    ax.loglog(bar.tau_s, fit.implied_wv(), "r--", lw=2, label=f"AWV fit {fit.name}")
    return _finish(fig, ax, path, "scale τ (s)", f"wavelet variance ({unit})²",
                   f"{axis}: replicates")
