"""`gmis vce <recipe>`: the iterative VCE tuning job and its output folder.

Writes (all-or-nothing, gmis.results.results_directory):
  vce_history.csv          one row per (iteration, component): σ, mean and summed
                           redundancy, Helmert σ̂²_0 (and the simplified ratio), observations,
                           blunders, next σ, status, regional F-test (001 Tables 6-4..6-7)
  vce_table.md             the same as per-iteration tables for reports
  tuned_noise.toml         the final [noise] as a recipe fragment; use it from a recipe
                           with [paths].noise_override = "tuned_noise.toml"
  residuals_first.npz      standardized residuals per component, first iteration
  residuals_final.npz      the same, final iteration (for the histograms of gmis report)
  windows_final.npz        σ̂²_0 per component over sliding windows (final iteration)
  summary.json             convergence, final sigmas, blunders, timing
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from gmis.errors import GmisInputError
from gmis.noise_registry import apply_aiding_scales
from gmis.recipe import NoiseSection, format_noise_fragment, load_recipe
from gmis.results import results_directory, write_json, write_npz
from vce.tune import TuningResult, tune, tuned_noise_overrides

HISTORY_COLUMNS = ["iteration", "component", "unit", "sigma", "mean_redundancy",
                   "sum_redundancy", "sigma0_sq", "sigma0_sq_simplified", "observations",
                   "blunders", "next_sigma", "status", "f_statistic", "f_critical", "f_test"]


def _fmt(v):
    if isinstance(v, float):
        return "nan" if not math.isfinite(v) else f"{v:.6g}"
    return str(v)


def history_markdown(result: TuningResult) -> str:
    lines = ["# VCE iterations (layout of 001 Tables 6-4..6-7)", ""]
    rows = result.table_rows()
    for it in result.history:
        lines += [(f"## Iteration {it.iteration} (stationary epochs skipped by dynamics "
                   f"components: {it.stationary_epochs})"), "",
                  "| component | unit | σ | mean r | σ̂²₀ | blunders | next σ | status | F-test |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            if r["iteration"] != it.iteration:
                continue
            lines.append(f"| {r['component']} | {r['unit']} | {_fmt(r['sigma'])} | "
                         f"{r['mean_redundancy']:.3f} | {_fmt(r['sigma0_sq'])} | "
                         f"{r['blunders']} | {_fmt(r['next_sigma'])} | {r['status']} | "
                         f"{r['f_test']} |")
        lines.append("")
    return "\n".join(lines)


def write_history_csv(path: Path, result: TuningResult):
    rows = result.table_rows()
    with open(path, "w") as fh:
        fh.write(",".join(HISTORY_COLUMNS) + "\n")
        fh.writelines(",".join(_fmt(r[c]) for c in HISTORY_COLUMNS) + "\n" for r in rows)


def tune_recipe(recipe_path, results_dir, progress=None, max_iterations: int = 10,
                tol: float = 0.02, min_redundancy: float = 0.1,
                estimate_drifts: bool = False) -> dict:
    """Run the VCE job on a recipe and write the results folder; returns the summary."""
    if max_iterations < 1:
        raise GmisInputError(f"max_iterations must be ≥ 1, got {max_iterations}")
    t0 = time.perf_counter()
    recipe = load_recipe(recipe_path)
    result = tune(recipe, max_iterations=max_iterations, tol=tol,
                  min_redundancy=min_redundancy, estimate_drifts=estimate_drifts,
                  progress=progress)
    fields, scales = tuned_noise_overrides(result, recipe)
    tuned = recipe.with_noise(**fields)
    noise = tuned.noise
    # aiding scales → the [noise] sigmas used when files carry none; when they do, the
    # scale is reported in the fragment's comment and in the summary
    scale_note = ", ".join(f"{k} ×{v:.4g}" for k, v in scales.items())
    noise = apply_aiding_scales(noise, scales)
    last = result.history[-1]
    final = {c.name: {"sigma": float(s / c.to_si), "unit": c.unit,
                      "mean_redundancy": float(e.mean_redundancy), "status": st,
                      "sigma0_sq": float(h0), "blunders": int(e.n_blunders)}
             for c, s, e, st, h0 in zip(result.components, result.final_sigma,
                                         last.estimates, last.status, last.sigma0_sq)}
    summary = {"recipe": str(recipe.path), "iterations": len(result.history),
               "converged": result.converged, "tol": tol, "min_redundancy": min_redundancy,
               "final": final, "aiding_sigma_scales": scales,
               "blunders_total": int(sum(e.n_blunders for e in last.estimates)),
               "low_redundancy_components": [c.name for c, st in
                                             zip(result.components, last.status)
                                             if st == "low redundancy"]}
    with results_directory(results_dir) as folder:
        write_history_csv(folder / "vce_history.csv", result)
        (folder / "vce_table.md").write_text(history_markdown(result))
        comment = (f"VCE-tuned noise from {recipe.path.name} after {len(result.history)} "
                   f"iterations (converged: {result.converged}); aiding scales: "
                   f"{scale_note or 'none'}. Per-epoch file sigmas are multiplied by "
                   "those scales only if you apply them yourself.")
        (folder / "tuned_noise.toml").write_text(format_noise_fragment(noise, comment))
        for label, res in (("first", result.residuals_first),
                           ("final", result.residuals_final)):
            arrays = {}
            for name, (t, w) in res.items():
                arrays[f"{name}__t"] = t
                arrays[f"{name}__w"] = w
            write_npz(folder / f"residuals_{label}.npz", **arrays)
        arrays = {}
        for name, (tc, sig, sr) in result.windows_final.items():
            arrays[f"{name}__t"], arrays[f"{name}__sigma0_sq"], arrays[f"{name}__r"] = \
                tc, sig, sr
        write_npz(folder / "windows_final.npz", **arrays)
        summary["timing_s"] = time.perf_counter() - t0
        write_json(folder / "summary.json", summary)
    summary["results_dir"] = str(Path(results_dir).resolve())
    return summary


__all__ = ["NoiseSection", "history_markdown", "np", "tune_recipe"]
