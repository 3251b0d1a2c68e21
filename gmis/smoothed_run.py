"""`gmis run` with the two-filter smoother (gmis.smoother): the run, its outputs and its
summary entries.

Results folder of a smoothed run (docs/formats.md):
  solution.csv/.npz/.pos   the SMOOTHED solution at the smoother's output epochs
                           ([filter].smoother_rate_hz, default 10 Hz)
  solution_forward.*       the forward filter's solution (every epoch, as without --smooth)
  errors.csv               errors of the smoothed solution; errors_forward.csv: forward
  records.npz              the forward filter's per-epoch innovations and VCE terms
  summary.json             "smoother": method and figures; "errors_vs_reference*": the
                           smoothed solution, "errors_vs_reference*_forward": the forward
"""

from __future__ import annotations

import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gmis.navigation_solution import navigation_solution, reference_errors
from gmis.run_filter import FilterRecords
from gmis.run_statistics import seconds_since_last_fix, summarize_errors
from gmis.smoother import (
    DIFFUSE_FACTOR,
    SmoothedStates,
    run_two_filter,
    smoothed_records,
    smoother_output_rate_hz,
)
from gmis.smoother_choice import smoother_choice
from gmis.state import POS

SOLUTION_FILES = ("solution.csv", "solution.npz", "solution.pos")


@dataclass
class SmoothedRun:
    forward: FilterRecords
    states: SmoothedStates
    records: FilterRecords      # the output epochs, smoothed x / 1σ / covariance blocks
    cpu_s: float                # process time of forward + backward + combination


def run_smoothed(prep, progress=None) -> SmoothedRun:
    """Forward filter and two-filter smoother over a prepared run."""
    c0 = time.process_time()
    fwd, states = run_two_filter(prep.epochs, prep.meas, prep.x0, prep.config, prep.frame,
                                 stationary=prep.stationary,
                                 rate_hz=prep.recipe.filter.smoother_rate_hz,
                                 progress=progress)
    return SmoothedRun(fwd, states, smoothed_records(fwd, states), time.process_time() - c0)


def _rename(folder: Path, names, suffix: str):
    for name in names:
        src = folder / name
        if src.exists():
            src.rename(folder / f"{Path(name).stem}{suffix}{Path(name).suffix}")


def write_smoothed(folder: Path, prep, run: SmoothedRun, summary: dict, gnss_fix,
                   csv_rate_hz: float):
    """After the forward outputs are in ``folder``: rename them to *_forward, write the
    smoothed solution, errors and summary entries in their place."""
    from gmis.run_writers import write_errors_csv, write_solution

    _rename(folder, (*SOLUTION_FILES, "errors.csv"), "_forward")
    nav = navigation_solution(prep, run.records)
    rate = smoother_output_rate_hz(prep.recipe)
    staging = folder / ".smoothed"
    staging.mkdir()
    # write_solution decimates the IMU epochs by imu_rate / csv_rate: the output epochs are
    # already at the smoother's rate
    write_solution(staging, prep, run.records, nav,
                   csv_rate_hz * prep.recipe.imu.rate_hz / rate if csv_rate_hz else 0.0)
    for name in SOLUTION_FILES:
        if (staging / name).exists():
            (staging / name).rename(folder / name)
    shutil.rmtree(staging)
    errs = reference_errors(prep, run.records, nav)
    forward_errors_aside(summary)
    if errs is not None and errs["t"].size:
        write_errors_csv(folder, errs)
        skip = prep.recipe.filter.static_alignment_s
        summary["errors_vs_reference"] = summarize_errors(errs, skip_s=skip)
        since = seconds_since_last_fix(run.forward.t, gnss_fix)[run.states.idx]
        aided = summarize_errors(errs, skip, since[errs["idx"]] <= 1.0)
        aided["definition"] = "epochs at most 1 s after a GNSS position update"
        summary["errors_vs_reference_gnss_aided"] = aided
    summary["smoother"] = smoother_summary(run, prep)
    warn_on_disagreement(summary)


AGREEMENT_WARN_RMS_Z = 3.0   # forward vs backward position disagreement reported above
ERROR_KEYS = ("errors_vs_reference", "errors_vs_reference_gnss_aided")


def forward_errors_aside(summary: dict):
    """The forward filter's error figures of a smoothed run under *_forward; the plain
    keys are left for the smoothed ones (removed: a smoothed run whose output epochs
    miss the reference has none)."""
    for key in ERROR_KEYS:
        if key in summary:
            summary[f"{key}_forward"] = summary.pop(key)


def warn_on_disagreement(summary: dict):
    """A printed and recorded warning when the forward and backward filters disagree
    (summary["smoother"]["forward_backward_position_rms_z"] above AGREEMENT_WARN_RMS_Z)."""
    agreement = summary["smoother"]["forward_backward_position_rms_z"]
    if not agreement <= AGREEMENT_WARN_RMS_Z:
        from gmis.plausibility import announce
        line = (f"smoother: forward and backward filters disagree (position RMS z = "
                f"{agreement:.3g}, ≈ 1 when both are consistent): the smoothed solution is "
                "not to be trusted; the forward one is in solution_forward.*")
        summary.setdefault("warnings", []).append(line)
        announce([line])


def forward_backward_agreement(run: SmoothedRun) -> float:
    """RMS over the output epochs and the 3 position axes of z = (x_b − x_f) / √(σ_f² + σ_b²):
    the forward (updated) and backward (predicted) estimates have independent errors, so
    z ~ N(0, 1) and the RMS ≈ 1 when both filters are consistent; a diverged backward filter
    (or a forward one) shows as RMS ≫ 1 — the smoothed solution is then not to be trusted."""
    sm = run.states
    d = sm.x_backward[:, POS] - run.forward.x[sm.idx][:, POS]
    var = run.forward.sd[sm.idx][:, POS] ** 2 + sm.sd_backward[:, POS] ** 2
    ok = np.isfinite(d) & (var > 0)
    return float(np.sqrt(np.mean(d[ok] ** 2 / var[ok]))) if ok.any() else float("nan")


def smoother_summary(run: SmoothedRun, prep) -> dict:
    sm = run.states
    fwd_sd = run.forward.sd[sm.idx]
    return smoother_entry(
        forward_backward_agreement(run), smoother_output_rate_hz(prep.recipe), sm.idx.size,
        sm.spool_bytes_per_epoch, run.cpu_s, float(np.nanmax(
            np.where(fwd_sd > 0, sm.sd / np.where(fwd_sd > 0, fwd_sd, 1.0), np.nan))))


def smoother_entry(agreement_rms_z: float, rate_hz: float, output_epochs: int,
                   spool_bytes_per_epoch: int, cpu_s: float, max_sigma_ratio: float) -> dict:
    """summary.json's "smoother" entry (docs/formats.md)."""
    return {
        "forward_backward_position_rms_z": agreement_rms_z,
        "method": "two_filter",
        "solution": "solution.* and errors.csv: smoothed; solution_forward.*, "
                    "errors_forward.csv: forward filter",
        "output_rate_hz": rate_hz,
        "output_epochs": int(output_epochs),
        "backward_prior_sigma_factor": DIFFUSE_FACTOR,
        "spool_bytes_per_output_epoch": int(spool_bytes_per_epoch),
        "cpu_s_forward_backward": cpu_s,
        "max_sigma_ratio_smoothed_over_forward": max_sigma_ratio,
    }


__all__ = ["SmoothedRun", "run_smoothed", "smoother_choice", "write_smoothed"]
