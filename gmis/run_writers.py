"""Writers of a `gmis run` results folder (docs/formats.md): solution.npz/.csv,
records.npz, tc_records.npz (tightly coupled) and errors.csv (with a reference)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from gmis.gmikf import N_SLOTS, SLOT_NAMES
from gmis.results import CsvStream, write_npz
from gmis.run_filter import FilterRecords
from gmis.solution_antenna import antenna_solution, write_solution_pos_blocks
from gmis.state import BA, BG, NOISE_NAMES_27, SA, SG, STATE_NAMES_27
from gmis.tc_models import group_names

RAD_TO_DEG = 180 / math.pi        # rad → deg
SCALE_FACTORS = slice(SG.start, SA.stop)


SOLUTION_HEADER = ["time_gps_s", "lat_deg", "lon_deg", "h_m", "e_m", "n_m", "u_m",
                   "ve_m_s", "vn_m_s", "vu_m_s", "vx_m_s", "vy_m_s", "vz_m_s",
                   "pitch_deg", "roll_deg", "heading_deg",
                   "bgx_deg_s", "bgy_deg_s", "bgz_deg_s", "bax_m_s2", "bay_m_s2", "baz_m_s2"]
SOLUTION_SD_HEADER = ["sd_e_m", "sd_n_m", "sd_u_m", "sd_ve_m_s", "sd_vn_m_s", "sd_vu_m_s",
                      "sd_pitch_deg", "sd_roll_deg", "sd_heading_deg", "sd_bgx_deg_s",
                      "sd_bgy_deg_s", "sd_bgz_deg_s", "sd_bax_m_s2", "sd_bay_m_s2",
                      "sd_baz_m_s2"]
SCALE_HEADER = ["sgx", "sgy", "sgz", "sax", "say", "saz"]
# solution.npz / records.npz columns indexed by epoch (besides t, imu_row): per-epoch shape
SOLUTION_COLUMNS = {"llh": (3,), "enu": (3,), "llh_antenna": (3,), "enu_antenna": (3,),
                    "enu_sd": (3,), "vel_enu": (3,), "vel_enu_sd": (3,), "vel_body": (3,),
                    "vel_body_sd": (3,), "euler": (3,), "euler_sd": (3,)}
RECORD_COLUMNS = ("innov", "innov_var", "rejected", "nobs", "vz", "rz", "vw", "rw")
SPOOL_FOLDER = ".columns"
POS_SPOOL_FOLDER = ".pos-columns"
POS_BLOCK = 20_000   # solution.pos rows read back and written at a time
REFERENCE_SPOOL_FOLDER = ".reference-columns"


class SolutionWriter:
    """solution.npz (every epoch, full state and 1σ), records.npz (innovations, outlier
    flags, VCE terms), solution.csv (at most csv_rate_hz) and solution.pos, fed chunk by
    chunk (:meth:`add`, epochs in order) and finished by :meth:`close`. The npz columns
    are spooled as .npy files in ``<folder>/.columns`` (gmis.record_spool) and zipped at
    the end; the CSV rows are written as they come; memory holds one chunk."""

    def __init__(self, folder: Path, prep, t, imu_row, n: int, nw: int,
                 csv_rate_hz: float = 10.0):
        from gmis.record_spool import ColumnSpool, GrowingColumns

        self.folder, self.prep, self.n = Path(folder), prep, n
        self.t, self.imu_row = t, imu_row
        e = t.size
        self.spool = ColumnSpool(self.folder / SPOOL_FOLDER, e, {
            **{k: (tail, np.float64) for k, tail in SOLUTION_COLUMNS.items()},
            "x": ((n,), np.float64), "sd": ((n,), np.float64),
            "innov": ((N_SLOTS,), np.float64), "innov_var": ((N_SLOTS,), np.float64),
            "rejected": ((N_SLOTS,), np.int8), "nobs": ((), np.int64),
            "vz": ((N_SLOTS,), np.float64), "rz": ((N_SLOTS,), np.float64),
            "vw": ((nw,), np.float64), "rw": ((nw,), np.float64)})
        # every step-th IMU epoch: the rate at most csv_rate_hz (40 Hz of 100 Hz: 33.3)
        step = max(1, math.ceil(prep.recipe.imu.rate_hz / csv_rate_hz - 1e-9)) \
            if csv_rate_hz else 1
        # a copy of the every-step-th rows: the slice alone would keep the whole list of
        # IMU epochs (8 bytes per epoch) alive for the run
        self.csv_rows = every_step_imu_epoch(imu_row, step)
        header = SOLUTION_HEADER + (SCALE_HEADER if n == 27 else [])
        sd_header = SOLUTION_SD_HEADER + ([f"sd_{h}" for h in SCALE_HEADER] if n == 27
                                          else [])
        # %.10g everywhere but latitude / longitude: 10 digits of -105.1234567 deg are
        # 8 mm of longitude; %.12g keeps 0.1 mm
        fmt = ",".join("%.12g" if h in ("lat_deg", "lon_deg") else "%.10g"
                       for h in header + sd_header)
        self.csv = CsvStream(self.folder / "solution.csv", header + sd_header, fmt=fmt)
        # the solution.pos rows (CSV rate) on disk until close (7 numbers per row)
        self.pos_rows = GrowingColumns(self.folder / POS_SPOOL_FOLDER, {
            "t": ((), np.float64), "llh": ((3,), np.float64), "sd": ((3,), np.float64)})

    def csv_epochs(self, e0: int, count: int) -> np.ndarray:
        """The CSV epochs (solution.csv, solution.pos, errors.csv) among [e0, e0 + count)."""
        lo, hi = np.searchsorted(self.csv_rows, [e0, e0 + count])
        return self.csv_rows[lo:hi]

    def add(self, e0: int, rec: FilterRecords, nav):
        """Epochs [e0, e0 + len(rec.t)): their records and navigation_solution."""
        n = self.n
        enu_ant, llh_ant = antenna_solution(self.prep, rec.t, nav["enu"], nav["euler"])
        self.spool.append(
            llh=nav["llh"], enu=nav["enu"], llh_antenna=llh_ant, enu_antenna=enu_ant,
            enu_sd=nav["enu_sd"], vel_enu=nav["vel_enu"], vel_enu_sd=nav["vel_enu_sd"],
            vel_body=nav["vel_body"], vel_body_sd=nav["vel_body_sd"], euler=nav["euler"],
            euler_sd=nav["euler_sd"], x=rec.x[:, :n], sd=rec.sd[:, :n],
            **{k: getattr(rec, k) for k in RECORD_COLUMNS})
        rows = self.csv_epochs(e0, rec.t.size) - e0
        cols = [rec.t[rows], nav["llh"][rows, :2] * RAD_TO_DEG, nav["llh"][rows, 2],
                nav["enu"][rows], nav["vel_enu"][rows], nav["vel_body"][rows],
                nav["euler"][rows] * RAD_TO_DEG, rec.x[rows, BG] * RAD_TO_DEG, rec.x[rows, BA]]
        sd_cols = [nav["enu_sd"][rows], nav["vel_enu_sd"][rows],
                   nav["euler_sd"][rows] * RAD_TO_DEG, rec.sd[rows, BG] * RAD_TO_DEG,
                   rec.sd[rows, BA]]
        if n == 27:
            cols.append(rec.x[rows, SCALE_FACTORS])
            sd_cols.append(rec.sd[rows, SCALE_FACTORS])
        self.csv.write(*cols, *sd_cols)
        self.pos_rows.append(t=rec.t[rows], llh=llh_ant[rows], sd=nav["enu_sd"][rows])

    def close(self):
        """Finish the CSV, zip the npz files, write solution.pos, remove the spool."""
        import shutil

        from gmis.record_spool import write_npz_members

        self.csv.close()
        self.spool.close()
        col = self.spool.path
        n = self.n
        write_npz_members(self.folder / "solution.npz", {
            "t": self.t, **{k: col(k) for k in ("llh", "enu", "llh_antenna", "enu_antenna",
                                                 "enu_sd", "vel_enu", "vel_enu_sd",
                                                 "vel_body", "vel_body_sd", "euler",
                                                 "euler_sd", "x", "sd")},
            "state_names": np.array(STATE_NAMES_27[:n]), "frame": self.prep.frame})
        imu_row = self.imu_row
        if not isinstance(imu_row, np.ndarray):   # gmis.epochs.RowIndex: a column file
            imu_row = _column_file(self.folder / SPOOL_FOLDER / "imu_row.npy", imu_row)
        write_npz_members(self.folder / "records.npz", {
            "t": self.t, "imu_row": imu_row, **{k: col(k) for k in RECORD_COLUMNS},
            "slot_names": np.array(SLOT_NAMES), "noise_names": np.array(NOISE_NAMES_27[:n - 9])})
        shutil.rmtree(self.spool.folder)
        prep = self.prep
        gnss = prep.dataset.gnss
        week = prep.recipe.time.gps_week if prep.recipe.time.gps_week is not None \
            else getattr(gnss, "gps_week", None)
        pos = self.pos_rows
        pos.close()
        if week is not None:  # solution.pos needs calendar time
            title = (f"gmis {prep.recipe.dataset.name}: primary antenna, Q from the filter's "
                     "1-sigma (gmis.solution_antenna)")
            blocks = ((pos.read("t", a, a + POS_BLOCK), pos.read("llh", a, a + POS_BLOCK),
                       pos.read("sd", a, a + POS_BLOCK)) for a in range(0, pos.rows, POS_BLOCK))
            write_solution_pos_blocks(self.folder / "solution.pos", blocks, week, gnss,
                                      [title])
        shutil.rmtree(pos.folder)


EPOCH_BLOCK = 1 << 16


def every_step_imu_epoch(imu_row, step: int) -> np.ndarray:
    """np.nonzero(imu_row >= 0)[0][::step] computed in blocks of epochs (imu_row an
    array or a gmis.epochs.RowIndex): no (E,) temporaries."""
    parts, count = [], 0
    for e0 in range(0, len(imu_row), EPOCH_BLOCK):
        on = np.flatnonzero(np.asarray(imu_row[e0:e0 + EPOCH_BLOCK]) >= 0) + e0
        parts.append(on[(-count) % step::step])
        count += on.size
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


def _column_file(path: Path, index) -> Path:
    """path.npy holding np.asarray(index) (as np.save writes it), written in blocks."""
    from gmis.record_spool import _header

    with open(path, "wb") as fh:
        np.lib.format.write_array_header_1_0(fh, _header((len(index),), np.int64))
        fh.writelines(np.ascontiguousarray(index[e0:e0 + EPOCH_BLOCK], dtype=np.int64).data for e0 in range(0, len(index), EPOCH_BLOCK))
    return path


def write_solution(folder: Path, prep, rec: FilterRecords, nav, csv_rate_hz: float = 10.0):
    """solution.npz (every epoch, full state and 1σ), records.npz (innovations, outlier
    flags, VCE terms) and solution.csv decimated to at most csv_rate_hz, from records held
    in memory (SolutionWriter with one chunk). Returns the CSV epochs (for errors.csv)."""
    n = prep.config.n_imu
    writer = SolutionWriter(folder, prep, rec.t, rec.imu_row, n, rec.vw.shape[1],
                            csv_rate_hz)
    writer.add(0, rec, nav)
    writer.close()
    return writer.csv_rows


ERROR_HEADER = ["time_gps_s", "de_m", "dn_m", "du_m", "dve_m_s", "dvn_m_s", "dvu_m_s",
                "dpitch_deg", "droll_deg", "dheading_deg", "nees_position",
                "nees_velocity_body", "nees_attitude"]
NEES_NAMES = ("position", "velocity_body", "attitude")


class StreamedOutputs:
    """The results folder of a forward `gmis run` fed by the filter chunk by chunk (the
    sink of gmis.run_filter.GmikfRunner): per chunk the navigation solution, the solution
    and record files (SolutionWriter), the errors against the reference (errors.csv rows
    and spooled columns for the summary) and the summary totals (RecordTotals)."""

    def __init__(self, folder: Path, prep, csv_rate_hz: float = 10.0,
                 spool_reference: bool = False, reference_from_file: bool = False,
                 t=None, imu_row=None, track=None, errors_at_csv_epochs: bool = True):
        """spool_reference: the reference rows go to a column spool beside the results
        (ReferenceTrack), so that the caller can drop prep.dataset.reference.
        reference_from_file: prep's dataset was read without the reference
        (load_dataset(with_reference=False)); the recipe's reference file is read block by
        block into that spool (ReferenceTrack.from_file), never whole.
        t, imu_row: the epochs the records will come at (default: prep's epochs; the
        smoothed run: its output epochs, gmis.smoothed_stream). track: a ReferenceTrack
        to use (another StreamedOutputs' track, rewound) instead of building one.
        errors_at_csv_epochs: errors.csv rows at the solution.csv epochs only (False: at
        every compared epoch, as the smoothed run writes them)."""
        from gmis.navigation_solution import ReferenceTrack
        from gmis.record_spool import ColumnSpool
        from gmis.run_statistics import RecordTotals
        from gmis.state import n_noise_for

        self.folder, self.prep = Path(folder), prep
        n = prep.config.n_imu
        t = prep.epochs.t if t is None else t
        imu_row = prep.epochs.imu if imu_row is None else imu_row
        self.solution = SolutionWriter(folder, prep, t, imu_row, n, n_noise_for(n),
                                       csv_rate_hz)
        self.totals = RecordTotals()
        self.sink_cpu_s = 0.0
        self.errors_at_csv_epochs = errors_at_csv_epochs
        if track is not None:
            self.track = track
        elif reference_from_file and prep.recipe.paths.reference is not None:
            self.track = ReferenceTrack.from_file(prep.recipe, prep.frame,
                                                  self.folder / REFERENCE_SPOOL_FOLDER)
        else:
            self.track = None if prep.dataset.reference is None else ReferenceTrack(
                prep, self.folder / REFERENCE_SPOOL_FOLDER if spool_reference else None)
        self.errors = None
        if self.track is not None:
            t0, t1 = self.track.t_first, self.track.t_last
            k = int(np.count_nonzero((t >= t0) & (t <= t1) & (imu_row >= 0)))
            if k:
                self.errors = ColumnSpool(self.folder / ".error-columns", k, {
                    "t": ((), np.float64), "idx": ((), np.int64), "pos": ((3,), np.float64),
                    "vel": ((3,), np.float64), "att": ((3,), np.float64),
                    **{f"nees_{k}": ((), np.float64) for k in NEES_NAMES}})
                self.errors_csv = CsvStream(self.folder / "errors.csv", ERROR_HEADER)

    def add(self, e0: int, rec: FilterRecords):
        """The sink: epochs [e0, e0 + len(rec.t)) of the filter records."""
        import time

        from gmis.navigation_solution import navigation_solution, reference_errors

        c0 = time.process_time()
        self.totals.add(rec)
        nav = navigation_solution(self.prep, rec)
        self.solution.add(e0, rec, nav)
        if self.errors is not None:
            errs = reference_errors(self.prep, rec, nav, self.track)
            self.errors.append(t=errs["t"], idx=errs["idx"] + e0, pos=errs["pos"],
                               vel=errs["vel"], att=errs["att"],
                               **{f"nees_{k}": errs["nees"][k] for k in NEES_NAMES})
            _write_error_rows(self.errors_csv, errs,
                              self.solution.csv_epochs(e0, rec.t.size) - e0
                              if self.errors_at_csv_epochs else None)
        self.sink_cpu_s += time.process_time() - c0

    def close(self):
        """Finish the files; returns the errors as a LazyColumns mapping (read back one
        column at a time) or None without a reference."""
        from gmis.record_spool import LazyColumns

        self.solution.close()
        if self.errors is None:
            return None
        self.errors.close()
        self.errors_csv.close()
        cols = {k: k for k in ("t", "idx", "pos", "vel", "att")}
        return LazyColumns(self.errors, cols, nees=LazyColumns(
            self.errors, {k: f"nees_{k}" for k in NEES_NAMES}))

    def remove_spools(self):
        import shutil

        if self.errors is not None:
            shutil.rmtree(self.errors.folder, ignore_errors=True)
        if self.track is not None and self.track.spool is not None:
            shutil.rmtree(self.track.spool.folder, ignore_errors=True)


def _write_error_rows(out: CsvStream, errs, epochs=None):
    """The rows of errs at the given epochs (the numbering of errs["idx"]; None: every
    row)."""
    keep = slice(None) if epochs is None else np.isin(errs["idx"], epochs)
    out.write(errs["t"][keep], errs["pos"][keep], errs["vel"][keep],
              errs["att"][keep] * RAD_TO_DEG, *(errs["nees"][k][keep] for k in NEES_NAMES))


def dd_residual_arrays(tc_rec):
    """Standardized DD residuals of every used observation (for per-group and
    per-satellite histograms): GNSS epoch, group (0 code, 1 L1, 2 L2, 3 Doppler or
    TDCP), PRN, v/σ_v."""
    if not tc_rec.residuals:
        z = np.zeros(0)
        return {"dd_residual_epoch": z.astype(np.int64), "dd_residual_group": z.astype(np.int64),
                "dd_residual_prn": z.astype(np.int64), "dd_residual_std": z}
    g = np.concatenate([np.full(k.size, e) for e, k, _, _ in tc_rec.residuals])
    return {"dd_residual_epoch": g.astype(np.int64),
            "dd_residual_group": np.concatenate([k for _, k, _, _ in tc_rec.residuals]),
            "dd_residual_prn": np.concatenate([p for _, _, p, _ in tc_rec.residuals]),
            "dd_residual_std": np.concatenate([w for _, _, _, w in tc_rec.residuals])}


def fixed_integer_table(tc_rec):
    """(K, 5) rows [GNSS epoch, reference PRN, PRN, frequency, DD integer] of every
    validated fix (cycles)."""
    rows = []
    for g, ints in zip(np.flatnonzero(tc_rec.fixed), tc_rec.integers):
        rows += [(g, tc_rec.ref_prn[g], prn, f, v) for (prn, f), v in sorted(ints.items())]
    return np.array(rows, dtype=np.int64).reshape(-1, 5)


def write_tc_records(folder: Path, tc_rec, tc_info):
    """tc_records.npz: per-GNSS-epoch records of the tightly coupled filter."""
    write_npz(folder / "tc_records.npz", t=tc_rec.t, epoch_index=tc_rec.epoch_index,
              n_sat=tc_rec.n_sat, ref_prn=tc_rec.ref_prn, fixed=tc_rec.fixed,
              ratio=tc_rec.ratio, n_fixed=tc_rec.n_fixed,
              fix_rejected=tc_rec.fix_rejected, rejected_obs=tc_rec.rejected_obs,
              low_success_rate=tc_rec.low_success_rate, success_rate=tc_rec.success_rate,
              unidentifiable=tc_rec.unidentifiable,
              vpv=tc_rec.vpv, redundancy=tc_rec.redundancy, n_obs=tc_rec.n_obs,
              fixed_integers=fixed_integer_table(tc_rec),
              **dd_residual_arrays(tc_rec),
              group_names=np.array(group_names(
                  tc_info.get("velocity_observable", "doppler"))))


def write_errors_csv(folder: Path, errs, epochs=None):
    """errors.csv: solution − reference (m, m/s, deg) and NEES at the compared epochs among
    ``epochs`` (indices of errs["idx"]; None: every compared epoch)."""
    out = CsvStream(folder / "errors.csv", ERROR_HEADER)
    _write_error_rows(out, errs, epochs)
    out.close()


__all__ = ["SolutionWriter", "StreamedOutputs", "dd_residual_arrays", "fixed_integer_table", "write_errors_csv",
           "write_solution", "write_tc_records"]
