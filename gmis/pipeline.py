"""`gmis run`: recipe → dataset → GMIKF → results folder (solution, records, summary).

Python API::

    prep = prepare_run(load_recipe("recipe.toml"))
    records = run_prepared(prep)
    summary = run_recipe("recipe.toml", "results/")

The steps live in one module each: gmis.run_preparation (dataset, alignment, x0, engine
configs), gmis.navigation_solution (solution numerics and errors against the reference),
gmis.run_statistics (summary figures), gmis.run_writers (files); this module orchestrates
them and is the public face of `gmis run`.

Results folder (written all-or-nothing, see gmis.results):
  solution.csv   time, lat/lon/h, ENU, ENU and body velocity, attitude, biases, scale
                 factors and their 1σ, decimated to at most ``csv_rate_hz`` (default 10 Hz)
  solution.npz   the same quantities at every epoch plus the full state and 1σ
  records.npz    per-epoch innovations, innovation variances, outlier flags (and VCE
                 residuals/redundancies when computed)
  tc_records.npz tightly coupled runs: per-GNSS-epoch fix, satellites, DD residuals
  errors.csv     errors against the reference trajectory (when the recipe has one) at
                 the solution.csv epochs; summary.json's error statistics use every epoch
  summary.json   configuration, counts, timings and error statistics
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from gmis.lazy_exports import lazy_getattr

if TYPE_CHECKING:
    from gmis.run_preparation import PreparedRun

# The numerical modules (numba kernels, scipy) are imported on first use, so that
# ``import gmis.pipeline`` stays light (docs/DESIGN.md "Start-up time"); the names this
# module re-exports resolve through __getattr__.
_REEXPORTS = {
    "PreparedRun": "gmis.run_preparation",
    "prepare_run": "gmis.run_preparation",
    "run_prepared": "gmis.run_preparation",
    "enu_to_geodetic_rows": "gmis.enu_rows",
    "geodetic_to_enu_rows": "gmis.enu_rows",
    "navigation_solution": "gmis.navigation_solution",
    "reference_errors": "gmis.navigation_solution",
    "summarize_errors": "gmis.run_statistics",
}


def _this():
    """This module: its re-exported names are looked up on it (resolved lazily, and a test's
    monkeypatch of gmis.pipeline.run_prepared still takes effect)."""
    return sys.modules[__name__]


__getattr__ = lazy_getattr(__name__, _REEXPORTS)


def _run_filter(prep: PreparedRun, progress):
    """(FilterRecords, TcRecords | None, tc info | None, per-epoch 'GNSS fix' flags)."""
    import numpy as np

    run_prepared = _this().run_prepared
    if prep.recipe.filter.mode == "tight":
        from gmis.tc import run_tight
        rec, tc_rec, tc_info = run_tight(prep, progress=progress)
        gnss_fix = np.zeros(rec.t.size, bool)
        gnss_fix[tc_rec.epoch_index[tc_rec.n_sat >= 5]] = True
        return rec, tc_rec, tc_info, gnss_fix
    rec = run_prepared(prep, progress=progress)
    return rec, None, None, prep.epochs.pos >= 0


def run_recipe(recipe_path, results_dir, progress=None, gnss_outages=(),
               csv_rate_hz: float = 10.0, smooth: bool | None = None,
               bounded_memory: bool = True) -> dict:
    """Run the GMIKF on a recipe and write the results folder; returns the summary.
    smooth: True = two-filter smoother (gmis.smoothed_run), None = [filter].smoother.
    bounded_memory: a loosely coupled run (forward or smoothed) streams its records to
    the results folder (docs/DESIGN.md "Bounded memory"); False holds them whole in
    memory — the same files, the reference path the streamed ones are tested against.
    Tightly coupled runs hold them whole."""
    from gmis.smoother_choice import smoother_choice

    t_start = time.perf_counter()
    from gmis.recipe import load_recipe
    from gmis.results import results_directory, write_json
    from gmis.run_statistics import tc_summary
    from gmis.run_summary import error_summaries, run_summary
    from gmis.run_writers import write_errors_csv, write_solution, write_tc_records

    recipe = load_recipe(recipe_path)
    smoothing = smoother_choice(recipe, smooth) != "none"
    this = _this()
    streamed = bounded_memory and recipe.filter.mode != "tight"
    if streamed:
        # the streamed run reads the reference block by block into its spool
        # (StreamedOutputs, ReferenceTrack.from_file): not whole, beside the prepared run
        # and, in the plain loosely coupled case, keeps the IMU samples on disk
        # (gmis.imu_spool: the filter reads each chunk's rows)
        from gmis.readers import load_dataset
        from gmis.run_preparation import streams_imu
        prep = this.prepare_run(recipe, load_dataset(recipe, with_reference=False,
                                                     imu_on_disk=streams_imu(recipe)),
                                gnss_outages=gnss_outages)
        t_read = time.perf_counter()
        if smoothing:
            from gmis.smoothed_stream import run_smoothed_streamed
            return run_smoothed_streamed(prep, results_dir, progress, csv_rate_hz,
                                         (t_start, t_read))
        return _run_streamed(prep, results_dir, progress, csv_rate_hz, (t_start, t_read))
    prep = this.prepare_run(recipe, gnss_outages=gnss_outages)
    t_read = time.perf_counter()
    if smoothing:
        from gmis.smoothed_run import run_smoothed, write_smoothed
    smoothed = run_smoothed(prep, progress) if smoothing else None
    rec, tc_rec, tc_info, gnss_fix = (smoothed.forward, None, None, prep.epochs.pos >= 0) \
        if smoothing else _run_filter(prep, progress)
    t_filter = time.perf_counter()
    nav = this.navigation_solution(prep, rec)
    errs = this.reference_errors(prep, rec, nav)
    has_errors = errs is not None and errs["t"].size
    from gmis.run_statistics import RecordTotals
    summary = run_summary(prep, RecordTotals.of(rec), (t_start, t_read, t_filter))
    if has_errors:
        error_summaries(summary, errs, rec.t, gnss_fix, recipe.filter.static_alignment_s,
                         tc_rec is not None)
    if tc_rec is not None:
        summary["tightly_coupled"] = tc_summary(tc_rec, tc_info)
    with results_directory(results_dir) as folder:
        csv_epochs = write_solution(folder, prep, rec, nav, csv_rate_hz)
        if tc_rec is not None:
            write_tc_records(folder, tc_rec, tc_info)
        if has_errors:
            write_errors_csv(folder, errs, csv_epochs)
        if smoothed is not None:
            write_smoothed(folder, prep, smoothed, summary, gnss_fix, csv_rate_hz)
        summary["timing_s"]["total"] = time.perf_counter() - t_start
        write_json(folder / "summary.json", summary)
    summary["results_dir"] = str(Path(results_dir).resolve())
    return summary


def _run_streamed(prep: PreparedRun, results_dir, progress, csv_rate_hz, timing) -> dict:
    """The forward loosely coupled run with bounded memory: the filter hands its records
    chunk by chunk to gmis.run_writers.StreamedOutputs, which writes the results folder as
    they come (docs/DESIGN.md "Bounded memory"); the files equal those of the in-memory
    path."""
    from dataclasses import replace

    import numpy as np

    from gmis.results import results_directory, write_json
    from gmis.run_summary import error_summaries, run_summary
    from gmis.run_writers import StreamedOutputs

    t_start, t_read = timing
    with results_directory(results_dir) as folder:
        out = StreamedOutputs(folder, prep, csv_rate_hz, spool_reference=True,
                              reference_from_file=prep.dataset.reference is None)
        # the reference now lives in the spool: this run's PreparedRun (run_recipe's own)
        # lets go of it (run_recipe never read it whole) and of the aiding streams' copies
        from gmis.run_preparation import release_prepared_inputs
        release_prepared_inputs(prep)
        _this().run_prepared(prep, progress=progress, sink=out.add)
        # the filter is done: the IMU samples (48 bytes per epoch) go before the summary
        # (which needs the IMU times only)
        empty = np.empty((0, 3))
        prep.dataset = replace(prep.dataset, imu=replace(prep.dataset.imu, gyro=empty,
                                                         accel=empty))
        prep.meas = replace(prep.meas, imu_z=np.empty((0, 6)))
        errs = out.close()
        t_filter = time.perf_counter()
        summary = run_summary(prep, out.totals, (t_start, t_read, t_filter))
        summary["timing_s"]["outputs_cpu_s"] = out.sink_cpu_s
        if errs is not None:
            error_summaries(summary, errs, prep.epochs.t, prep.epochs.pos,
                             prep.recipe.filter.static_alignment_s, False)
        out.remove_spools()
        summary["timing_s"]["total"] = time.perf_counter() - t_start
        write_json(folder / "summary.json", summary)
    summary["results_dir"] = str(Path(results_dir).resolve())
    return summary


def __dir__():
    return sorted(set(globals()) | set(_REEXPORTS))


__all__ = ["run_recipe", *sorted(_REEXPORTS)]  # noqa: PLE0604 - names resolved lazily
