"""`gmis vce <recipe>`: the iterative VCE tuning job and its output folder.

Writes (all-or-nothing, gmis.results.results_directory):
  vce_history.csv          one row per (iteration, component): σ, mean and summed
                           redundancy, Helmert σ̂²_0 (and the simplified ratio), observations,
                           blunders, next σ, status, regional F-test (001 Tables 6-4..6-7),
                           the estimator used (helmert | simplified | held) and the 1σ
                           precision of σ̂²_0 (used estimator; joint with all candidates)

A run whose last iteration is inconsistent (> 5 % of a component's observations rejected,
or normalised innovation χ² per observation outside [1/3, 3]) is refused: no
tuned_noise.toml, summary["refused"] holds the one-line reason (the other files stay as
diagnostics) and `gmis vce` prints it as ``gmis: error: …`` and exits with status 2.
  vce_table.md             the same as per-iteration tables for reports
  tuned_noise.toml         the final [noise] as a recipe fragment; use it from a recipe
                           with [paths].noise_override = "tuned_noise.toml"
  residuals_first.npz      standardized residuals per component, first iteration
  residuals_final.npz      the same, final iteration (for the histograms of gmis report)
  windows_final.npz        σ̂²_0 per component over sliding windows (final iteration)
  summary.json             convergence, final sigmas, blunders, timing
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

from gmis.errors import GmisInputError
from gmis.noise_registry import apply_aiding_scales
from gmis.recipe import format_noise_fragment, load_recipe
from gmis.record_spool import write_npz_members
from gmis.results import results_directory, write_json, write_npz
from vce.components import GNSS_ERROR_COMPONENTS
from vce.spooled_records import SpooledPair
from vce.tune import TuningResult, tune, tuned_noise_overrides

HISTORY_COLUMNS = ["iteration", "component", "unit", "sigma", "mean_redundancy",
                   "sum_redundancy", "sigma0_sq", "sigma0_sq_simplified", "observations",
                   "blunders", "next_sigma", "status", "f_statistic", "f_critical", "f_test",
                   "estimator", "sigma0_sq_sd", "sigma0_sq_sd_joint"]


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
                  ("| component | unit | σ | mean r | σ̂²₀ | ± (1σ) | ± joint | blunders | "
                   "next σ | status | F-test |"),
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            if r["iteration"] != it.iteration:
                continue
            label = not_estimated_label(r["status"], r["estimator"], r["mean_redundancy"])
            lines.append(f"| {r['component']} | {r['unit']} | {_fmt(r['sigma'])} | "
                         f"{r['mean_redundancy']:.3f} | {_fmt(r['sigma0_sq'])} | "
                         f"{_fmt(r['sigma0_sq_sd'])} | {_fmt(r['sigma0_sq_sd_joint'])} | "
                         f"{r['blunders']} | {_fmt(r['next_sigma'])} | {label} | "
                         f"{r['f_test']} |")
        if it.dropped:
            lines.append("")
            lines.append("Left the joint Helmert solve (simplified ratio used): "
                         + "; ".join(f"{n} ({why})" for n, why in it.dropped))
        lines.append("")
    lines += [("σ̂²₀ ± is the 1σ precision of the estimate used (001 §5.2.1: 2σ⁴S⁻¹ for the "
               "joint solve, 2σ⁴/Σr for the simplified ratio); '± joint' is sqrt(2 (S⁻¹)_jj) "
               "with every candidate solved together — how well the data separate that "
               "component from the others (identifiability)."), ""]
    return "\n".join(lines)


def write_history_csv(path: Path, result: TuningResult):
    rows = result.table_rows()
    with open(path, "w") as fh:
        fh.write(",".join(HISTORY_COLUMNS) + "\n")
        fh.writelines(",".join(_fmt(r[c]) for c in HISTORY_COLUMNS) + "\n" for r in rows)


MAX_BLUNDER_FRACTION = 0.05   # of a component's observations in the last iteration
WARN_BLUNDER_FRACTION = 0.01  # above: reported (real data hold real outliers), not refused
NIS_BAND = (1.0 / 3.0, 3.0)   # Σ dᵀD⁻¹d / Σ m of the last iteration's filter run


def heavy_tail_notes(result: TuningResult) -> list[str]:
    """Components of the last iteration with more than WARN_BLUNDER_FRACTION (but not more
    than MAX_BLUNDER_FRACTION) of their observations rejected: heavy-tailed data (the
    real drive's RTK track holds 20 cm steps: 1.8 % of its positions), tuned from the
    accepted ones and reported."""
    last = result.history[-1]
    out = []
    for c, e in zip(result.components, last.estimates):
        total = e.n_obs + e.n_blunders
        if total and WARN_BLUNDER_FRACTION * total < e.n_blunders <= \
                MAX_BLUNDER_FRACTION * total:
            out.append(f"{c.name}: {e.n_blunders} of {total} observations "
                       f"({100.0 * e.n_blunders / total:.1f} %) rejected as outliers; "
                       "tuned from the accepted ones")
    return out


def consistency_problems(result: TuningResult) -> list[str]:
    """Why the last iteration's filter run is not one to tune from (empty = fine): a
    component with more than 5 % of its observations rejected by the outlier tests (a
    consistent filter rejects ≈ α = 0.1 % of good data; a diverged one most of them; real
    data with real outliers sit in between, see heavy_tail_notes), or a normalised
    innovation χ² per observation outside [1/3, 3] (a consistent filter gives ≈ 1)."""
    last = result.history[-1]
    out = []
    for c, e in zip(result.components, last.estimates):
        total = e.n_obs + e.n_blunders
        if total and e.n_blunders > MAX_BLUNDER_FRACTION * total:
            out.append(f"{c.name}: {e.n_blunders} of {total} observations rejected")
    rec = result.records_final
    if rec is not None and rec.helmert_totals is not None and rec.helmert_totals[1] > 0:
        nis = rec.helmert_totals[0] / rec.helmert_totals[1]
        if not NIS_BAND[0] <= nis <= NIS_BAND[1]:
            out.append(f"normalised innovation χ² per observation {nis:.3g}")
    return out


def not_estimated_label(status: str, estimator: str, mean_redundancy: float) -> str:
    """The table's status text: held components say so with their mean redundancy."""
    if estimator == "held" or status != "estimated":
        return f"not estimated (r̄ = {mean_redundancy:.3g}; {status})"
    return f"estimated ({estimator})"


def residual_members(residuals: dict) -> dict:
    """residuals_*.npz members {<component>__t, <component>__w}: the .npy files of spooled
    residuals (vce.spooled_records.SpooledPair, copied without loading) or arrays."""
    out = {}
    for name, pair in residuals.items():
        t, w = pair.paths if isinstance(pair, SpooledPair) else pair
        out[f"{name}__t"], out[f"{name}__w"] = t, w
    return out


def tune_recipe(recipe_path, results_dir, progress=None, max_iterations: int = 30,
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
    problems = consistency_problems(result)
    refused = None
    if problems:
        refused = (f"{recipe.path}: refusing to tune: the filter run of iteration "
                   f"{len(result.history)} is inconsistent or diverged ("
                   + "; ".join(problems[:4])
                   + (f"; {len(problems) - 4} more" if len(problems) > 4 else "")
                   + "); no tuned_noise.toml written (diagnostics in the results folder); "
                   "fix the recipe's noise/initial sigmas first")
    fields, scales = tuned_noise_overrides(result, recipe)
    tuned = recipe.with_noise(**fields)
    noise = tuned.noise
    # aiding scales → [noise].gnss_position_scale / gnss_velocity_scale / heading_scale
    # (times the recipe's): they multiply the per-epoch σ the stream has, file or [noise]
    scale_note = ", ".join(f"{k} ×{v:.4g}" for k, v in scales.items())
    # the fix-error σ_b (gmis.gnss_error_states) is a [gnss] value, not a [noise] one:
    # summary.json "gnss_error_sigma_m" and the fragment's comment carry it
    names = [c.name for c in result.components]
    gnss_error_sigma = [float(result.final_sigma[names.index(n)])
                        for n in GNSS_ERROR_COMPONENTS if n in names]
    noise = apply_aiding_scales(noise, scales)
    # the fragment's gyro/accel σ are those of the final VCE run (estimated, or held at the
    # value that run used — after the at-rest floor): a run with it must not floor again
    noise = dataclasses.replace(noise, imu_sigma_source="vce")
    last = result.history[-1]
    final = {c.name: {"sigma": float(s / c.to_si), "unit": c.unit,
                      "mean_redundancy": float(e.mean_redundancy), "status": st,
                      "estimator": how, "sigma0_sq": float(h0),
                      "sigma0_sq_sd": float(sd), "sigma0_sq_sd_joint": float(sdj),
                      "label": not_estimated_label(st, how, e.mean_redundancy),
                      "blunders": int(e.n_blunders)}
             for c, s, e, st, h0, how, sd, sdj in zip(
                 result.components, result.final_sigma, last.estimates, last.status,
                 last.sigma0_sq, last.estimator, last.sigma0_sd, last.sigma0_sd_joint)}
    summary = {"recipe": str(recipe.path), "iterations": len(result.history),
               "converged": result.converged, "tol": tol, "min_redundancy": min_redundancy,
               "final": final, "aiding_sigma_scales": scales,
               "gnss_error_sigma_m": gnss_error_sigma or None,
               "blunders_total": int(sum(e.n_blunders for e in last.estimates)),
               "low_redundancy_components": [c.name for c, st in
                                             zip(result.components, last.status)
                                             if st == "low redundancy"],
               "not_estimated_components": [c.name for c, how in
                                            zip(result.components, last.estimator)
                                            if how == "held"],
               "simplified_components": [c.name for c, how in
                                         zip(result.components, last.estimator)
                                         if how == "simplified"],
               "refused": refused, "consistency_problems": problems,
               "heavy_tail_notes": heavy_tail_notes(result)}
    if summary["heavy_tail_notes"] and refused is None:   # a refusal is one error line
        from gmis.plausibility import announce
        announce(summary["heavy_tail_notes"])
    with results_directory(results_dir) as folder:
        write_history_csv(folder / "vce_history.csv", result)
        (folder / "vce_table.md").write_text(history_markdown(result))
        comment = (f"VCE-tuned noise from {recipe.path.name} after {len(result.history)} "
                   f"iterations (converged: {result.converged}); aiding scales: "
                   f"{scale_note or 'none'} (in gnss_position_scale, gnss_velocity_scale "
                   "and heading_scale: they multiply the streams' per-epoch sigmas).")
        if gnss_error_sigma:
            comment += ("\nFix-error Gauss-Markov sigma (E N U, m; for [gnss].error_sigma_m "
                        "with the recipe's error_correlation_time_s): "
                        + ", ".join(f"{v:.4g}" for v in gnss_error_sigma))
        if refused is None:
            (folder / "tuned_noise.toml").write_text(format_noise_fragment(noise, comment))
        for label, res in (("first", result.residuals_first),
                           ("final", result.residuals_final)):
            write_npz_members(folder / f"residuals_{label}.npz", residual_members(res))
        arrays = {}
        for name, (tc, sig, sr) in result.windows_final.items():
            arrays[f"{name}__t"], arrays[f"{name}__sigma0_sq"], arrays[f"{name}__r"] = \
                tc, sig, sr
        write_npz(folder / "windows_final.npz", **arrays)
        summary["timing_s"] = time.perf_counter() - t0
        write_json(folder / "summary.json", summary)
    summary["results_dir"] = str(Path(results_dir).resolve())
    return summary


__all__ = ["history_markdown", "tune_recipe"]
