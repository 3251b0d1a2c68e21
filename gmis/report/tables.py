"""Report tables, written as CSV and rendered into the HTML page.

* ``vce_table``: iteration × component (σ, mean r, σ̂²₀, blunders, next σ, status, F-test),
  the layout of 001 Tables 6-4..6-7;
* ``vce_blunders``: blunders (observations excluded by the outlier tests) per component
  and iteration;
* ``residual_statistics``: n, mean, std, KS statistic and p-value of the standardized
  residuals, first and final iteration (full residual sets);
* ``innovation_statistics``: the same for the normalized innovations of a run;
* ``error_statistics``: RMS / 95 % / max errors against the reference (summary.json);
* ``blunders``: rejected observations per measurement slot of a run.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gmis.report.plotting import pretty_unit


@dataclass
class Table:
    stem: str
    title: str
    caption: str
    header: list
    rows: list
    file: str = ""              # CSV path relative to the report folder
    group_by: int | None = None  # column whose value starts a new HTML block


def fmt(v, digits: int = 4) -> str:
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        if not math.isfinite(v):
            return "—" if math.isnan(v) else str(v)
        if v == int(v) and abs(v) < 1e9:
            return str(int(v))
        return f"{v:.{digits}g}"
    return "" if v is None else str(v)


def write_table(table: Table, out_dir: Path) -> Table:
    rel = f"tables/{table.stem}.csv"
    with open(out_dir / rel, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(table.header)
        for row in table.rows:
            w.writerow([fmt(v, 10) for v in row])
    table.file = rel
    return table


def vce_table(vce) -> Table:
    header = ["iteration", "component", "unit", "σ", "mean r", "σ̂²₀", "observations",
              "blunders", "next σ", "status", "F", "F crit", "F-test", "estimator",
              "σ̂²₀ 1σ", "σ̂²₀ 1σ joint"]
    rows = [[int(r["iteration"]), r["component"], pretty_unit(r["unit"]), r["sigma"], r["mean_redundancy"],
             r["sigma0_sq"], int(r["observations"]), int(r["blunders"]), r["next_sigma"],
             r["status"], r["f_statistic"], r["f_critical"], r["f_test"],
             r.get("estimator") or "", r.get("sigma0_sq_sd") or "",
             r.get("sigma0_sq_sd_joint") or ""]
            for r in vce.history]
    return Table("vce_table", "VCE iterations (001 Tables 6-4..6-7 layout)",
                 "Per iteration and variance component: σ used (unit column; 'x file σ' is a "
                 "dimensionless scale on the per-epoch file sigmas), mean redundancy r̄, "
                 "Helmert variance factor σ̂²₀, observations, blunders, σ proposed for the "
                 "next iteration, status, regional F-test (F vs its critical value), the "
                 "estimator used (helmert = joint solve, simplified = Σ vᵀPv/Σr, held = not "
                 "estimated) and the 1σ precision of σ̂²₀ (001 §5.2.1, 2σ⁴S⁻¹; 'joint': with "
                 "every candidate solved together, the component's identifiability).",
                 header, rows, group_by=0)


def vce_blunders_table(vce) -> Table:
    iterations = sorted({int(r["iteration"]) for r in vce.history})
    lookup = {(r["component"], int(r["iteration"])): int(r["blunders"]) for r in vce.history}
    rows = [[c] + [lookup.get((c, i), "") for i in iterations] for c in vce.components]
    return Table("vce_blunders", "Blunders per component and VCE iteration",
                 "Observations excluded by the outlier tests (local χ² and per-observation z "
                 "tests on the innovations) per component and iteration (count).",
                 ["component"] + [f"iter {i}" for i in iterations], rows)


def residual_statistics_table(stats: dict) -> Table:
    rows = []
    for name, by_label in stats.items():
        for label, s in by_label.items():
            rows.append([name, label, s["n"], s["mean"], s["std"], s["ks"], s["p"]])
    return Table("residual_statistics", "Standardized residuals against N(0,1)",
                 "Standardized VCE residuals per component, first and final iteration, all "
                 "epochs: count, mean and standard deviation (dimensionless, ideal 0 and 1), "
                 "Kolmogorov-Smirnov statistic D against N(0,1) and its p-value.",
                 ["component", "iteration", "n", "mean", "std", "KS D", "KS p"], rows)


def innovation_statistics_table(stats: dict) -> Table:
    rows = [[name, s["n"], s["rejected"], s["mean"], s["std"], s["ks"], s["p"]]
            for name, s in stats.items()]
    return Table("innovation_statistics", "Normalized innovations against N(0,1)",
                 "Normalized innovations d/√D per measurement slot over all accepted epochs: "
                 "count, rejected count, mean, standard deviation (dimensionless), "
                 "Kolmogorov-Smirnov statistic D against N(0,1) and its p-value.",
                 ["slot", "n", "rejected", "mean", "std", "KS D", "KS p"], rows)


def error_statistics_table(summary: dict) -> Table | None:
    rows = []
    for key, label in (("errors_vs_reference", "all epochs"),
                       ("errors_vs_reference_gnss_aided", "GNSS-aided epochs")):
        block = summary.get(key)
        if not isinstance(block, dict):
            continue
        for quantity in ("position", "velocity", "attitude"):
            for axis, s in (block.get(quantity) or {}).items():
                if isinstance(s, dict):
                    rows.append([label, quantity, axis, s.get("unit", ""), s.get("rms"),
                                 s.get("p95"), s.get("max"), block.get("epochs_compared")])
        for name, v in (block.get("nees_mean") or {}).items():
            rows.append([label, "mean NEES", name, "-", v, None, None,
                         block.get("epochs_compared")])
    if not rows:
        return None
    return Table("error_statistics", "Errors against the reference",
                 "RMS, 95th percentile and maximum of |error| per axis (m, m/s, deg as in the "
                 "unit column) after the static alignment, over all compared epochs and over "
                 "epochs at most 1 s after a GNSS position update; mean NEES of the 3-D "
                 "position, body velocity and attitude blocks (ideal 3).",
                 ["epochs", "quantity", "axis", "unit", "RMS", "95 %", "max", "compared"], rows)


def blunder_table(run) -> Table:
    rec = run.records
    rows = []
    for i, name in enumerate(rec["slot_names"]):
        present = int(np.isfinite(rec["innov"][:, i]).sum())
        rejected = int((rec["rejected"][:, i] != 0).sum())
        rows.append([str(name), present, rejected,
                     100.0 * rejected / present if present else math.nan])
    return Table("blunders", "Rejected observations per measurement slot",
                 "Measurements available per slot, rejected by the outlier tests (count) and "
                 "the rejected share (%).", ["slot", "measurements", "rejected", "rejected %"],
                 rows)
