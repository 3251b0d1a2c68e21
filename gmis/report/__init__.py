"""`gmis report`: figures, tables and one HTML page from `gmis run` / `gmis vce` results.

Python API::

    summary = make_report("results/")                       # run or vce folder
    summary = make_report("run/", vce_dir="vce/", formats=("png", "pdf"))
    summary = make_report("parent/")                        # parent of run/ and vce/

Which folders are read (gmis.report.inputs.locate_results): the folder itself when it
holds `gmis run` files (solution.npz, records.npz) and/or `gmis vce` files
(vce_history.csv); otherwise its immediate sub-folders (at most one of each kind);
``vce_dir`` adds or replaces the VCE part.

Report folder (default ``<results_dir>/report``, written all-or-nothing):
  report.html               self-contained page; links only to files below, relatively
  figures/<stem>.png        150 dpi (and .pdf/.svg on request)
  tables/<stem>.csv         the tables shown on the page

Figures (001 §5.3.5, §6.2.3.5, §6.2.4.2; Figs 5-2..5-12, 6-11..6-42):
  run:  trajectory, speed, solution_sigma, imu_biases, imu_scale_factors (27 states),
        errors_vs_reference (with errors.csv), forward_vs_smoothed (smoothed runs),
        innovation_histograms,
        innovations_{gyro,accel,gnss_position,gnss_velocity,heading}
  tight: tc_fix_status, dd_residual_histograms (+ table dd_residuals_per_satellite)
  vce:  residual_histograms_{measurement,process}, vce_sigma, vce_sigma0, vce_redundancy,
        vce_windows
Tables: run: blunders, innovation_statistics, error_statistics (with a reference);
        vce: vce_table, vce_blunders, residual_statistics.
Statistics (histograms, KS tests) use every sample; only drawn lines are decimated.
"""

from __future__ import annotations

import time
from pathlib import Path

import matplotlib as mpl

from gmis.errors import GmisInputError
from gmis.report import (
    figures_residuals,
    figures_smoother,
    figures_solution,
    figures_tc,
    figures_vce,
    tables,
)
from gmis.report.html import render_page
from gmis.report.inputs import RunData, VceData, load_run, load_vce, locate_results
from gmis.report.plotting import STYLE
from gmis.results import results_directory

FORMATS = ("png", "pdf", "svg")


def _overview(run: RunData | None, vce: VceData | None) -> list:
    items = []
    if run is not None:
        s = run.summary
        items += [("run folder", run.folder.name), ("dataset", s.get("dataset", "?")),
                  ("states", s.get("states", run.solution["x"].shape[1])),
                  ("duration (s)", tables.fmt(s.get("duration_s", float(
                      run.solution["t"][-1] - run.solution["t"][0])))),
                  ("epochs", s.get("epochs", run.solution["t"].shape[0])),
                  ("reference", "yes" if run.errors is not None else "no")]
    if vce is not None:
        s = vce.summary
        items += [("VCE folder", vce.folder.name),
                  ("VCE iterations", int(max(r["iteration"] for r in vce.history))),
                  ("converged", s.get("converged", "?")),
                  ("tolerance |σ̂²₀ − 1|", s.get("tol", "?")),
                  ("blunders (final iteration)", s.get("blunders_total", "?")),
                  ("low-redundancy components",
                   ", ".join(s.get("low_redundancy_components") or []) or "none")]
    return items


def make_report(results_dir, formats=("png",), out_dir=None, progress=None,
                vce_dir=None) -> dict:
    """Write the report of a results folder; returns a summary dict (report folder, page,
    figure and table names, KS statistics first/final, timing). formats: any of png, pdf,
    svg (png is always written: the page shows it). progress: callback(fraction)."""
    t_start = time.perf_counter()
    bad = [f for f in formats if f not in FORMATS]
    if bad:
        raise GmisInputError(f"unknown figure format(s) {', '.join(map(str, bad))}; "
                             f"choose from {', '.join(FORMATS)}")
    formats = ("png",) + tuple(dict.fromkeys(f for f in formats if f != "png"))
    run_path, vce_path = locate_results(results_dir, vce_dir)
    run = load_run(run_path) if run_path is not None else None
    vce = load_vce(vce_path) if vce_path is not None else None
    out = Path(out_dir) if out_dir is not None else Path(results_dir).expanduser() / "report"

    steps = []
    if run is not None:
        steps += [(f, run) for f in (
            figures_solution.trajectory_figure, figures_solution.speed_figure,
            figures_solution.sigma_figure, figures_solution.sensor_error_figure,
            figures_solution.error_figure, figures_smoother.forward_vs_smoothed_figure,
            figures_residuals.innovation_histograms,
            figures_residuals.innovation_series)]
        if run.tc is not None:
            steps += [(f, run) for f in (figures_tc.tc_status_figure,
                                         figures_tc.dd_residual_histograms)]
    if vce is not None:
        steps += [(f, vce) for f in (
            figures_residuals.residual_histograms, figures_vce.sigma_figure,
            figures_vce.sigma0_redundancy_figure, figures_vce.windows_figure)]
    figures, section_tables = [], {"solution": [], "innovations": [], "vce": []}
    with results_directory(out) as folder, mpl.rc_context(STYLE):
        (folder / "figures").mkdir()
        (folder / "tables").mkdir()
        for k, (step, data) in enumerate(steps):
            made = step(data, folder, formats)
            if made is not None:
                figures += made if isinstance(made, list) else [made]
            if progress is not None:
                progress((k + 1) / (len(steps) + 1))
        stats = {f.stem: f.stats for f in figures if f.stats}
        if run is not None:
            err = tables.error_statistics_table(run.summary)
            if err is not None:
                section_tables["solution"].append(err)
            section_tables["innovations"] += [
                tables.innovation_statistics_table(stats["innovation_histograms"]),
                tables.blunder_table(run)]
            if "dd_residual_histograms" in stats:
                section_tables["innovations"].append(
                    figures_tc.dd_satellite_table(stats["dd_residual_histograms"]))
        residual_ks = {}
        if vce is not None:
            for stem in ("residual_histograms_measurement", "residual_histograms_process"):
                residual_ks.update(stats.get(stem, {}))
            section_tables["vce"] += [tables.vce_table(vce), tables.vce_blunders_table(vce),
                                      tables.residual_statistics_table(residual_ks)]
        all_tables = [t for ts in section_tables.values() for t in ts]
        for t in all_tables:
            tables.write_table(t, folder)
        title = "gmis report — " + " + ".join(
            p.name for p in (run_path, vce_path) if p is not None)
        page = render_page(title, _overview(run, vce), figures, section_tables)
        (folder / "report.html").write_text(page, encoding="utf-8")
    if progress is not None:
        progress(1.0)
    out = out.resolve()
    summary = {
        "report_dir": str(out), "html": str(out / "report.html"),
        "run_dir": str(run_path.resolve()) if run_path else None,
        "vce_dir": str(vce_path.resolve()) if vce_path else None,
        "figures": [f for fig in figures for f in fig.files],
        "tables": [t.file for t in all_tables],
        "residual_ks": {name: {label: s["ks"] for label, s in by.items()}
                        for name, by in residual_ks.items()},
        "innovation_ks": {name: s["ks"] for name, s in
                          stats.get("innovation_histograms", {}).items()},
        "dd_residual_ks": {g: by["all"]["ks"] for g, by in
                           stats.get("dd_residual_histograms", {}).items()},
        "timing_s": time.perf_counter() - t_start,
    }
    return summary


__all__ = ["FORMATS", "load_run", "load_vce", "locate_results", "make_report"]
