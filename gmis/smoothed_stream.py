"""`gmis run --smooth` in bounded memory (issue 15, item 2; docs/DESIGN.md "Two-filter
smoother" and "Bounded memory").

The in-memory smoothed run (gmis.smoothed_run.run_smoothed) holds the forward filter's
records of every epoch (~2.4 KB per epoch with 27 states) and the smoothed arrays of every
output epoch. This one holds neither:

forward   GmikfRunner in sink mode. Every buffer of records goes to StreamedOutputs (the
          forward files, renamed *_forward at the end) and the rows of its output epochs
          to a column spool (their measurement records, x and 1σ); x and the upper
          triangle of P after each output epoch go to the StateSpool of gmis.smoother,
          packed by the same compiled forward_block, run on the buffer's own epochs.
backward  gmis.smoother.backward_block over blocks of BLOCK_OUTPUT_EPOCHS output epochs,
          newest first, on the kernel inputs of the block's epochs only (the IMU rows
          read from gmis.imu_spool when on disk); each block's smoothed x, 1σ, backward x,
          1σ and covariance blocks are written to a row file at their output rows.
outputs   the smoothed rows read back in order, OUTPUT_CHUNK at a time, into a second
          StreamedOutputs (solution.*, errors.csv) that shares the forward one's
          reference track; the summary figures accumulated on the way.

What stays in memory per epoch is the forward streamed run's (epoch times and indices,
stillness flags: docs/DESIGN.md "Bounded memory"), plus, per output epoch, its epoch row,
time and IMU row (24 bytes). The results folder is the in-memory smoothed run's, file for
file (tests/test_smoothed_stream.py).
"""

from __future__ import annotations

import shutil
import time
from pathlib import Path

import numpy as np

from gmis.gmikf import GROUP_NAMES, N_SLOTS
from gmis.run_filter import FilterDivergedError, GmikfRunner, check_finite
from gmis.smoother import (
    BLOCK_OUTPUT_EPOCHS,
    DIFFUSE_FACTOR,
    StateSpool,
    _backward_inputs,
    _record_buffers,
    backward_block,
    backward_prior,
    forward_block,
    output_epochs,
    refuse_unsmoothable,
    smoother_output_rate_hz,
)
from gmis.state import POS, n_noise_for

MAX_BLOCK_EPOCHS = 8192      # epochs per backward block at most (beside BLOCK_OUTPUT_EPOCHS)
OUTPUT_CHUNK = 4096          # output epochs per chunk of the smoothed outputs (~5 KB each)
FORWARD_AT_OUTPUT = ("x", "sd", "innov", "innov_var", "rejected", "vz", "rz", "vw", "rw",
                     "rx", "nobs", "rvar", "still")


class RowFile:
    """(rows, width) float64 in a temporary file, written and read by row range."""

    def __init__(self, folder: Path, rows: int, width: int):
        self.path = Path(folder) / "smoothed.bin"
        self.rows, self.width = int(rows), int(width)
        self._fh = open(self.path, "w+b")  # noqa: SIM115 - closed in close()
        self._fh.truncate(self.rows * self.width * 8)

    def write(self, j0: int, block: np.ndarray):
        self._fh.seek(j0 * self.width * 8)
        self._fh.write(np.ascontiguousarray(block, dtype=np.float64).data)

    def read(self, j0: int, j1: int) -> np.ndarray:
        self._fh.seek(j0 * self.width * 8)
        return np.fromfile(self._fh, dtype=np.float64,
                           count=(j1 - j0) * self.width).reshape(j1 - j0, self.width)

    def close(self):
        self._fh.close()


def _forward_columns(runner: GmikfRunner) -> dict:
    n, nw = runner.n, runner.nw_vce
    return {"x": ((n,), np.float64), "sd": ((n,), np.float64),
            "innov": ((N_SLOTS,), np.float64), "innov_var": ((N_SLOTS,), np.float64),
            "rejected": ((N_SLOTS,), np.int8), "vz": ((N_SLOTS,), np.float64),
            "rz": ((N_SLOTS,), np.float64), "vw": ((nw,), np.float64),
            "rw": ((nw,), np.float64), "rx": ((), np.float64), "nobs": ((), np.int64),
            "rvar": ((N_SLOTS,), np.float64), "still": ((), np.bool_)}


def forward_pass(runner: GmikfRunner, out, states: StateSpool, progress=None):
    """The forward filter in sink mode with x, P after every output epoch out[j] packed
    into ``states`` (gmis.smoother.forward_block on each record buffer's own epochs; the
    buffer is handed to the runner's sink as in GmikfRunner.advance)."""
    settings = runner.kernel_settings()
    buf = np.empty((BLOCK_OUTPUT_EPOCHS, states.width))
    j = 0
    while runner.e_next < runner.e_total:
        b0 = runner.buffer_start
        stop = min(runner.e_total, b0 + runner.rows)
        j_stop = int(np.searchsorted(out, stop))
        while j < j_stop:
            j1 = min(j + BLOCK_OUTPUT_EPOCHS, j_stop)
            e_start = runner.e_next
            e_rel, runner.t_prev = forward_block(
                out[j:j1] - b0, 0, j1 - j, runner.e_next - b0, runner.t_prev,
                runner.buffer_inputs, settings, runner.x, runner.p, runner.records, buf)
            runner.e_next = b0 + int(e_rel)
            check_finite(runner.x, runner.p, runner.chunk_records(b0, runner.e_next - b0),
                         e_start - b0, runner.e_next - b0, offset=b0)
            states.file.write(buf[:j1 - j].tobytes())
            states.count += j1 - j
            j = j1
        runner.finish_buffer()
        if progress is not None:
            progress(0.5 * runner.e_next / runner.e_total)


def backward_pass(runner: GmikfRunner, out, states: StateSpool, smoothed: RowFile,
                  diffuse_factor: float = DIFFUSE_FACTOR, progress=None):
    """The backward filter and the combination (gmis.smoother._backward_pass) block by
    block on the inputs of each block's epochs; the rows [x_s, 1σ_s, x_b, 1σ_b, the
    r^n / v^b / θ covariance blocks] of the output epochs go to ``smoothed``."""
    n, k_out = runner.n, out.size
    settings = runner.kernel_settings()._replace(compute_vce=0)
    x_b = runner.x.copy()
    p_b = backward_prior(runner, diffuse_factor)
    nw = n_noise_for(runner.n_imu)
    e_hi, t_prev = runner.e_total - 1, np.nan
    streak = np.zeros(len(GROUP_NAMES), dtype=np.int64)
    still = runner.rec.still
    j_hi = k_out - 1
    while j_hi >= 0:
        j_lo = max(0, j_hi - BLOCK_OUTPUT_EPOCHS + 1)
        # at most MAX_BLOCK_EPOCHS epochs per block too (low output rates), but always
        # one output epoch: the block's scratch records are ~1.9 KB per epoch
        j_lo = max(j_lo, min(j_hi, int(np.searchsorted(out, e_hi - MAX_BLOCK_EPOCHS))))
        m = j_hi - j_lo + 1
        states.file.seek(j_lo * states.bytes_per_epoch)
        fwd_buf = np.frombuffer(states.file.read(m * states.bytes_per_epoch),
                                dtype=np.float64).reshape(-1, states.width)
        e_lo = int(out[j_lo])
        local = runner.inputs_from(e_lo, e_hi + 1)
        inp_b, phantoms = _backward_inputs(local, still[e_lo:e_hi + 2], out, j_lo, j_hi,
                                           e_hi, e0=e_lo, e_total=runner.e_total)
        rec_b = _record_buffers(inp_b.t.size, n, nw, streak)
        xs, sds, xbs, sdbs = (np.empty((m, n)) for _ in range(4))
        cov = np.empty((m, 3, 3, 3))
        t_prev, failed = backward_block(inp_b, phantoms, m - 1, fwd_buf, 0, settings, x_b,
                                        p_b, rec_b, t_prev, xs, sds, xbs, sdbs, cov)
        if failed >= 0 or not (np.isfinite(x_b).all() and np.isfinite(p_b).all()):
            e = int(out[j_lo + max(failed, 0)])
            raise FilterDivergedError(
                f"backward filter of the smoother diverged near epoch {e} (t = "
                f"{runner.rec.t[e]:.3f} s): non-finite or non-positive-definite covariance; "
                "no solution written")
        smoothed.write(j_lo, np.hstack([xs, sds, xbs, sdbs, cov.reshape(m, 27)]))
        e_hi = e_lo
        j_hi = j_lo - 1
        if progress is not None:
            progress(0.5 + 0.5 * (k_out - j_lo) / k_out)


def _rows_at(index, epochs, block: int = 1 << 16) -> np.ndarray:
    """index[epochs] of an (E,) index array or gmis.epochs.RowIndex, for increasing
    epochs, read in blocks of epochs (no (E,) array)."""
    if isinstance(index, np.ndarray):
        return index[epochs]
    out = np.empty(epochs.size, dtype=np.int64)
    j0 = 0
    while j0 < epochs.size:             # runs of epochs spanning at most `block` epochs
        j1 = max(j0 + 1, int(np.searchsorted(epochs, epochs[j0] + block)))
        e = epochs[j0:j1]
        out[j0:j1] = index.dense(int(e[0]), int(e[-1]) + 1)[e - e[0]]
        j0 = j1
    return out


class SmootherFigures:
    """The summary's "smoother" figures accumulated over chunks of output epochs
    (gmis.smoothed_run.smoother_summary of the whole arrays)."""

    def __init__(self):
        self.z2, self.count, self.ratio = 0.0, 0, -np.inf

    def add(self, x_f, sd_f, x_s, sd_s, x_b, sd_b):
        d = x_b[:, POS] - x_f[:, POS]
        var = sd_f[:, POS] ** 2 + sd_b[:, POS] ** 2
        ok = np.isfinite(d) & (var > 0)
        self.z2 += float(np.sum(d[ok] ** 2 / var[ok]))
        self.count += int(ok.sum())
        r = np.where(sd_f > 0, sd_s / np.where(sd_f > 0, sd_f, 1.0), np.nan)
        if np.isfinite(r).any():
            self.ratio = max(self.ratio, float(np.nanmax(r)))

    def agreement(self) -> float:
        return float(np.sqrt(self.z2 / self.count)) if self.count else float("nan")


def run_smoothed_streamed(prep, results_dir, progress=None, csv_rate_hz: float = 10.0,
                          timing=None) -> dict:
    """The smoothed `gmis run` of a prepared loosely coupled run, writing the results
    folder of gmis.smoothed_run (solution.* smoothed, solution_forward.*, errors*.csv,
    records.npz of the forward filter, summary.json) in bounded memory; returns the
    summary."""
    from dataclasses import replace

    from gmis.results import results_directory, write_json
    from gmis.run_statistics import fix_epochs_of, summarize_errors
    from gmis.run_summary import error_summaries, run_summary
    from gmis.run_writers import StreamedOutputs
    from gmis.smoothed_run import (
        SOLUTION_FILES,
        _rename,
        forward_errors_aside,
        smoother_entry,
        warn_on_disagreement,
    )

    t_start, t_read = timing if timing is not None else (time.perf_counter(),) * 2
    config, meas = prep.config, prep.meas
    refuse_unsmoothable(config)
    rate = prep.recipe.filter.smoother_rate_hz
    skip = prep.recipe.filter.static_alignment_s
    with results_directory(results_dir) as folder:
        fwd_out = StreamedOutputs(folder, prep, csv_rate_hz, spool_reference=True,
                                  reference_from_file=prep.dataset.reference is None)
        from gmis.run_preparation import release_prepared_inputs
        release_prepared_inputs(prep)
        epochs = prep.epochs
        out = np.ascontiguousarray(output_epochs(epochs.t, epochs.imu, rate), dtype=np.int64)
        work = folder / ".smoother"
        work.mkdir()
        from gmis.record_spool import GrowingColumns

        captured = None

        def sink(e0, chunk):
            fwd_out.add(e0, chunk)
            lo, hi = np.searchsorted(out, [e0, e0 + chunk.t.size])
            rows = out[lo:hi] - e0
            captured.append(**{k: getattr(chunk, k)[rows] for k in FORWARD_AT_OUTPUT})

        c0 = time.process_time()
        runner = GmikfRunner(epochs, meas, prep.x0, config, prep.frame, prep.stationary,
                             sink=sink)
        captured = GrowingColumns(work / "forward", _forward_columns(runner))
        states = StateSpool(runner.n)
        smoothed = RowFile(work, out.size, 4 * runner.n + 27)
        try:
            forward_pass(runner, out, states, progress)
            captured.close()
            backward_pass(runner, out, states, smoothed, DIFFUSE_FACTOR, progress)
        except BaseException:
            captured.close()
            smoothed.close()
            raise
        finally:
            states.close()
        cpu_s = time.process_time() - c0
        totals = fwd_out.totals
        # the filter is done: the IMU samples go before the outputs (as in _run_streamed)
        empty = np.empty((0, 3))
        prep.dataset = replace(prep.dataset, imu=replace(prep.dataset.imu, gyro=empty,
                                                         accel=empty))
        prep.meas = replace(prep.meas, imu_z=np.empty((0, 6)))
        track = fwd_out.track
        errs = fwd_out.close()
        t_filter = time.perf_counter()
        summary = run_summary(prep, totals, (t_start, t_read, t_filter))
        summary["timing_s"]["outputs_cpu_s"] = fwd_out.sink_cpu_s
        if errs is not None:
            error_summaries(summary, errs, epochs.t, epochs.pos, skip, False)
        forward_errors_aside(summary)
        if fwd_out.errors is not None:
            shutil.rmtree(fwd_out.errors.folder, ignore_errors=True)
        _rename(folder, (*SOLUTION_FILES, "errors.csv"), "_forward")

        # the smoothed outputs, in order, into a staging folder (its records.npz unused)
        staging = folder / ".smoothed"
        staging.mkdir()
        t_out = epochs.t[out]
        imu_out = _rows_at(epochs.imu, out)
        if track is not None:
            track.rewind()
        sm_out = StreamedOutputs(staging, prep, csv_rate_hz * prep.recipe.imu.rate_hz
                                 / smoother_output_rate_hz(prep.recipe)
                                 if csv_rate_hz else 0.0, t=t_out, imu_row=imu_out,
                                 track=track, errors_at_csv_epochs=False)
        figures = SmootherFigures()
        n = runner.n
        template = runner.rec
        try:
            for j0 in range(0, out.size, OUTPUT_CHUNK):
                j1 = min(j0 + OUTPUT_CHUNK, out.size)
                rows = smoothed.read(j0, j1)
                fwd = {k: captured.read(k, j0, j1) for k in FORWARD_AT_OUTPUT}
                x_s, sd_s = rows[:, :n], rows[:, n:2 * n]
                figures.add(fwd["x"], fwd["sd"], x_s, sd_s, rows[:, 2 * n:3 * n],
                            rows[:, 3 * n:4 * n])
                still = fwd.pop("still")
                fwd.pop("x")
                fwd.pop("sd")
                rec = replace(template, t=t_out[j0:j1], x=np.ascontiguousarray(x_s),
                              sd=np.ascontiguousarray(sd_s),
                              cov_blocks=np.ascontiguousarray(rows[:, 4 * n:]).reshape(-1, 3, 3, 3),
                              imu_row=imu_out[j0:j1], still=still, reopened=None, nll=None,
                              **fwd)
                sm_out.add(j0, rec)
        finally:
            smoothed.close()
        errs_s = sm_out.close()
        for name in (*SOLUTION_FILES, "errors.csv"):
            if (staging / name).exists():
                (staging / name).rename(folder / name)
        if errs_s is not None:
            summary["errors_vs_reference"] = summarize_errors(errs_s, skip_s=skip)
            fixes = fix_epochs_of(epochs.pos)
            j = np.searchsorted(fixes, out, side="right") - 1
            last = epochs.t[fixes[np.maximum(j, 0)]] if fixes.size else np.zeros(out.size)
            since = epochs.t[out] - np.where(j >= 0, last, -np.inf)
            aided = summarize_errors(errs_s, skip, since[errs_s["idx"]] <= 1.0)
            aided["definition"] = "epochs at most 1 s after a GNSS position update"
            summary["errors_vs_reference_gnss_aided"] = aided
        summary["smoother"] = smoother_entry(figures.agreement(),
                                             smoother_output_rate_hz(prep.recipe), out.size,
                                             states.bytes_per_epoch, cpu_s, figures.ratio)
        warn_on_disagreement(summary)
        sm_out.remove_spools()
        fwd_out.remove_spools()
        shutil.rmtree(staging, ignore_errors=True)
        shutil.rmtree(work, ignore_errors=True)
        summary["timing_s"]["total"] = time.perf_counter() - t_start
        write_json(folder / "summary.json", summary)
    summary["results_dir"] = str(Path(results_dir).resolve())
    return summary


__all__ = ["RowFile", "SmootherFigures", "backward_pass", "forward_pass",
           "run_smoothed_streamed"]
