"""Model selection among the nested models of a user's largest model (000 §3.3.5, eq. 3.22).

WVIC = (ν̂ − ν(θ̂))ᵀ Ω (ν̂ − ν(θ̂)) + 2 tr(cov[ν̂, ν(θ̂)] Ωᵀ). The optimism term is taken
from the delta method instead of a parametric bootstrap: ν(θ̂) ≈ ν + D (DᵀΩD)⁻¹ DᵀΩ (ν̂ − ν)
gives cov[ν̂, ν(θ̂)] = V Ω D (DᵀΩD)⁻¹ Dᵀ, so the penalty is 2 tr(Ω D (DᵀΩD)⁻¹ DᵀΩ V),
which is 2p when Ω = V⁻¹ (as here) — an AIC-like criterion on the GMWM objective.
The table lists every nested model, its objective, penalty, WVIC and rank.

:func:`choose` then applies 000 §4.2's simplification: an AR1 of the best model with
φ ≤ 0.2 is over-bounded by white noise (000 eq. 4.5), so the model with that AR1 replaced
by WN is taken instead (it is in the table, being nested).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from calibration import processes as P
from calibration.gmwm import GmwmFit, fit_gmwm
from calibration.wavelet_variance import WaveletVariance


@dataclass
class SelectionRow:
    model: str
    n_params: int
    objective: float
    penalty: float
    wvic: float
    fit: GmwmFit


def nested_models(largest) -> list[tuple[str, ...]]:
    """Every non-empty sub-model: each single process in or out, 0..k of the k AR1s."""
    largest = P.canonical(largest)
    singles = [p for p in ("WN", "QN", "RW", "DR") if p in largest]
    k = largest.count("AR1")
    out = []
    for r in range(len(singles) + 1):
        for chosen in itertools.combinations(singles, r):
            for n_ar in range(k + 1):
                model = tuple(chosen) + ("AR1",) * n_ar
                if model:
                    out.append(P.canonical(model))
    return sorted(out, key=lambda m: (P.n_params(m), P.model_name(m)))


def wvic_penalty(fit: GmwmFit) -> float:
    """2 tr(Ω D (DᵀΩD)⁻¹ DᵀΩ V) with V = Ω⁻¹: 2p. A parameter driven to its bound (a
    process fitted as ≈ 0) still counts, so a model never ties with its sub-model."""
    return 2.0 * float(P.n_params(fit.model))


def select_model(wv: WaveletVariance, largest, scales=None, progress=None) -> list[SelectionRow]:
    """Fit all nested models; rows sorted by WVIC (best first)."""
    rows = []
    models = nested_models(largest)
    for i, model in enumerate(models):
        if P.n_params(model) > (wv.tau.size if scales is None else len(wv.tau[scales])):
            continue
        fit = fit_gmwm(wv, model, scales=scales, se="none")  # WVIC needs θ̂ and Q only
        pen = wvic_penalty(fit)
        rows.append(SelectionRow(P.model_name(model), P.n_params(model), fit.objective, pen,
                                 fit.objective + pen, fit))
        if progress is not None:
            progress((i + 1) / len(models))
    rows.sort(key=lambda r: r.wvic)
    return rows


WHITE_AR1_PHI = 0.2


def choose(rows: list[SelectionRow], wv: WaveletVariance) -> tuple[SelectionRow, str]:
    """The best row after 000 §4.2's simplification: every AR1 of the best model with
    φ ≤ 0.2 is replaced by WN of variance ξ²/(1−φ)² (its over-bound, eq. 4.5) and the
    simpler model is refitted from the best model's values; it is taken only if its WVIC
    is not larger (on real MEMS data the fast AR1 often describes the sensor's own
    low-pass filter, and dropping it costs far more than its penalty); the note says
    what was done."""
    best = rows[0]
    blocks = P.split_theta(best.fit.model, best.fit.theta)
    fast = [b for p, b in zip(best.fit.model, blocks) if p == "AR1" and b[0] <= WHITE_AR1_PHI]
    if not fast:
        return best, ""
    white = sum(b[1] / (1.0 - b[0]) ** 2 for b in fast)
    model, start = [], []
    for p, b in zip(best.fit.model, blocks):
        if p == "AR1" and b[0] <= WHITE_AR1_PHI:
            continue
        if p == "WN":
            b = b + white
        model.append(p)
        start.append(b)
    if "WN" not in model:
        model.insert(0, "WN")
        start.insert(0, np.array([white]))
    fit = fit_gmwm(wv, model, start=np.concatenate(start), se="none")
    row = SelectionRow(P.model_name(model), P.n_params(fit.model), fit.objective,
                       wvic_penalty(fit), fit.objective + wvic_penalty(fit), fit)
    what = (f"{best.model} has {len(fast)} AR1 with phi <= {WHITE_AR1_PHI}; {row.model} "
            f"(AR1 -> WN, 000 eq. 4.5) refitted: WVIC {row.wvic:.6g} vs {best.wvic:.6g}")
    if row.wvic <= best.wvic:
        return row, what + f" -> {row.model}"
    return best, what + f" -> kept {best.model}"
