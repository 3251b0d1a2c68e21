"""Navigation quantities of a GMIKF run and their errors against a reference:
ENU/geodetic position, ENU and body velocity with 1σ (001 eq. 4.1.29-4.1.31), attitude,
and the NEES of the filter's position, body-velocity and attitude blocks."""

from __future__ import annotations

import numpy as np

from gmis.enu_rows import enu_to_geodetic_rows, geodetic_to_enu_rows
from gmis.frames import dcm_body_to_nav_array, wrap_pi
from gmis.run_filter import FilterRecords
from gmis.state import ATT, I_PITCH, I_ROLL, POS, VEL


def _t_matrix_array(pitch, roll):
    """T of 001 eq. 4.1.29 (attitude error φ in ENU = T δθ), vectorised → (N, 3, 3)."""
    sp, cp, sr, cr = np.sin(pitch), np.cos(pitch), np.sin(roll), np.cos(roll)
    t = np.zeros((pitch.size, 3, 3))
    t[:, 0, 0] = cr
    t[:, 0, 2] = cp * sr
    t[:, 1, 1] = 1.0
    t[:, 1, 2] = -sp
    t[:, 2, 0] = sr
    t[:, 2, 2] = -cp * cr
    return t


def _skew_array(v):
    """[v×] of each row of v (N, 3) → (N, 3, 3); gmis.frames has the single-vector
    skew/skew_into only (numba)."""
    s = np.zeros((v.shape[0], 3, 3))
    s[:, 0, 1], s[:, 0, 2] = -v[:, 2], v[:, 1]
    s[:, 1, 0], s[:, 1, 2] = v[:, 2], -v[:, 0]
    s[:, 2, 0], s[:, 2, 1] = -v[:, 1], v[:, 0]
    return s


def navigation_solution(prep, rec: FilterRecords):
    """Per-epoch navigation quantities with 1σ (dict of arrays, SI/rad) of a run prepared
    by gmis.run_preparation. ENU velocity covariance by eq. 4.1.31:
    C cov(v^b) Cᵀ + [v^n×] T cov(θ) Tᵀ [v^n×]ᵀ."""
    x, sd = rec.x, rec.sd
    enu = x[:, POS]
    llh = enu_to_geodetic_rows(prep.frame, np.ascontiguousarray(enu))
    c = dcm_body_to_nav_array(x[:, ATT])
    v_n = np.einsum("kij,kj->ki", c, x[:, VEL])
    tm = _skew_array(v_n) @ _t_matrix_array(x[:, I_PITCH], x[:, I_ROLL])
    cov = (c @ rec.cov_blocks[:, 1] @ np.transpose(c, (0, 2, 1))
           + tm @ rec.cov_blocks[:, 2] @ np.transpose(tm, (0, 2, 1)))
    v_n_sd = np.sqrt(np.maximum(np.diagonal(cov, axis1=1, axis2=2), 0.0))
    return {"t": rec.t, "llh": llh, "enu": enu, "enu_sd": sd[:, POS], "vel_enu": v_n,
            "vel_enu_sd": v_n_sd, "vel_body": x[:, VEL], "vel_body_sd": sd[:, VEL],
            "euler": x[:, ATT], "euler_sd": sd[:, ATT], "x": x, "sd": sd}


def reference_track(prep):
    """(ENU position (N, 3) m, unwrapped Euler angles (N, 3) rad) of the whole reference
    (the in-memory run); None without a reference. A streamed run uses ReferenceTrack."""
    ref = prep.dataset.reference
    if ref is None:
        return None
    return (geodetic_to_enu_rows(prep.frame, np.ascontiguousarray(ref.llh)),
            np.unwrap(ref.euler, axis=0))


def unwrap_continued(p_prev, p_new, s_prev):
    """np.unwrap(·, axis=0) of rows p_new (K, 3) continuing a stream whose previous raw row
    was p_prev (3,) and whose accumulated correction there was s_prev (3,): (unwrapped
    rows, accumulated correction at the last row). The same operations as np.unwrap
    (period 2π, discont π); the running sum is continued by accumulating after s_prev,
    so a stream unwrapped window by window equals np.unwrap of the whole, bit for bit."""
    if len(p_new) == 0:
        return np.empty((0, 3)), np.asarray(s_prev, dtype=float)
    dd = np.diff(np.vstack([p_prev, p_new]), axis=0)
    period, high = 2 * np.pi, np.pi
    ddmod = np.mod(dd + high, period) - high
    np.copyto(ddmod, high, where=(ddmod == -high) & (dd > 0))
    ph_correct = ddmod - dd
    np.copyto(ph_correct, 0, where=np.abs(dd) < high)
    s = np.cumsum(np.vstack([s_prev, ph_correct]), axis=0)[1:]
    return p_new + s, s[-1]


class ReferenceTrack:
    """The reference for a streamed run, chunk by chunk in increasing time (docs/DESIGN.md
    "Bounded memory"): its ENU position and unwrapped Euler angles are computed for the
    rows that the interpolation at one chunk's epochs reads (row-wise ENU;
    unwrap_continued), equal to reference_track's rows bit for bit. With ``spool`` (a
    folder) the llh / vel_enu / euler rows go to column files there (gmis.record_spool)
    and are read back window by window: memory then holds the reference's times (8 bytes
    per row) and one window, and the caller may drop the dataset's reference array.
    :meth:`from_file` spools the times too and holds one window and two blocks of them."""

    COLUMNS = ("llh", "vel_enu", "euler")

    def __init__(self, prep, spool=None):
        ref = prep.dataset.reference
        self.frame = prep.frame
        self.t = np.asarray(ref.t, dtype=float)   # the reader's own compact copy
        self.n, self.t_first, self.t_last = self.t.size, *self._ends(self.t)
        self.spool = None
        if spool is None:
            self._rows = {name: getattr(ref, name) for name in self.COLUMNS}
        else:
            from gmis.record_spool import ColumnSpool
            self.spool = ColumnSpool(spool, self.t.size,
                                     {name: ((3,), np.float64) for name in self.COLUMNS})
            for k in range(0, self.t.size, SPOOL_BLOCK_ROWS):
                self.spool.append(**{name: getattr(ref, name)[k:k + SPOOL_BLOCK_ROWS]
                                     for name in self.COLUMNS})
            self.spool.close()
        self._start_windows()

    @classmethod
    def from_file(cls, recipe, frame, spool):
        """The track of the recipe's reference file cropped to its [time] window, read
        block by block into column files in the folder spool
        (gmis.readers.read_reference_blocks: read_reference's checks and values, never
        the whole table), its times as well: memory holds one window and two blocks of
        TIME_BLOCK_ROWS times (``t`` is None), not 8 bytes per row."""
        from gmis.readers import read_reference_blocks
        from gmis.record_spool import GrowingColumns

        self = cls.__new__(cls)
        self.frame = frame
        self.t = None
        self.spool = GrowingColumns(spool, {"t": ((), np.float64),
                                            **{name: ((3,), np.float64)
                                               for name in cls.COLUMNS}})
        ends = []

        def consume(t, llh, vel, euler):
            if t.size:
                ends[:] = [ends[0] if ends else float(t[0]), float(t[-1])]
            self.spool.append(t=t, llh=llh, vel_enu=vel, euler=euler)

        try:
            self.n = read_reference_blocks(recipe.paths.reference, consume,
                                           recipe.time.start_gps_s, recipe.time.end_gps_s,
                                           REFERENCE_BLOCK_BYTES)
        finally:
            self.spool.close()
        self.t_first, self.t_last = ends if ends else (np.nan, np.nan)
        self._start_windows()
        return self

    @staticmethod
    def _ends(t):
        return (float(t[0]), float(t[-1])) if t.size else (np.nan, np.nan)

    def times(self, j0: int, j1: int) -> np.ndarray:
        """The times of rows [j0, j1)."""
        return self.t[j0:j1] if self.t is not None else self.spool.read("t", j0, j1)

    def _count_le(self, x: float, cursor: str) -> int:
        """np.searchsorted(t, x, "right") of the whole times; with the times spooled, a
        forward cursor (x not below the previous call's with the same cursor) over blocks
        of TIME_BLOCK_ROWS: every row before the cursor's block is ≤ an earlier x ≤ x."""
        if self.t is not None:
            return int(np.searchsorted(self.t, x, "right"))
        if cursor not in self._cursors:
            self._cursors[cursor] = (0, self.spool.read("t", 0, TIME_BLOCK_ROWS))
        b0, tb = self._cursors[cursor]
        while b0 + tb.size < self.n and tb.size and tb[-1] <= x:
            b0 += tb.size
            tb = self.spool.read("t", b0, b0 + TIME_BLOCK_ROWS)
        self._cursors[cursor] = (b0, tb)
        return b0 + int(np.searchsorted(tb, x, "right"))

    def rewind(self):
        """Start again at the first reference row (another pass over the run's times, e.g.
        the smoothed solution after the forward one)."""
        self._start_windows()

    def _start_windows(self):
        self.done = 0                       # reference rows unwrapped so far
        self.last = None                    # (raw row, accumulated correction) at done − 1
        self.base, self.unwrapped = 0, np.empty((0, 3))   # rows [base, done)
        self._cursors = {}

    def rows(self, name: str, j0: int, j1: int) -> np.ndarray:
        """Rows [j0, j1) of llh, vel_enu or euler."""
        if self.spool is not None:
            return self.spool.read(name, j0, j1)
        return self._rows[name][j0:j1]

    def window(self, t_lo: float, t_hi: float):
        """(j0, j1, ENU, velocity ENU, unwrapped Euler; each (j1 − j0, 3)): rows [j0, j1)
        hold both neighbours of every time in [t_lo, t_hi] inside the reference's span;
        t_lo not below the previous call's."""
        j0 = max(self._count_le(t_lo, "lo") - 2, 0)
        j1 = min(self._count_le(t_hi, "hi") + 2, self.n)
        if j0 < self.base:
            raise ValueError("ReferenceTrack.window: times must not go back")
        if j1 > self.done:
            if self.done == 0:
                p = self.rows("euler", 0, j1)
                rest, s = unwrap_continued(p[0], p[1:], np.zeros(3))
                new = np.vstack([p[:1], rest])
            else:
                p = self.rows("euler", self.done, j1)
                new, s = unwrap_continued(self.last[0], p, self.last[1])
            self.unwrapped = np.vstack([self.unwrapped, new])
            self.last = (p[-1].copy(), s)
            self.done = j1
        self.unwrapped = self.unwrapped[j0 - self.base:]    # later windows start ≥ j0
        self.base = j0
        unw = self.unwrapped[:j1 - j0]
        enu = geodetic_to_enu_rows(self.frame, np.ascontiguousarray(self.rows("llh", j0, j1)))
        return j0, j1, enu, self.rows("vel_enu", j0, j1), unw


SPOOL_BLOCK_ROWS = 100_000   # rows per append when ReferenceTrack spools the reference
TIME_BLOCK_ROWS = 1 << 16   # reference times per block read by a spooled track's cursor
REFERENCE_BLOCK_BYTES = 1 << 20   # text per block when ReferenceTrack.from_file reads


def reference_errors(prep, rec: FilterRecords, nav, track=None):
    """Errors of the solution against the reference at the IMU epochs inside its span:
    ENU position (m), ENU velocity (m/s), attitude (rad), and NEES of r^n, v^b, θ.
    track: reference_track(prep), when computed once for many calls, or a ReferenceTrack
    (a streamed run's chunks, in time order)."""
    streamed = isinstance(track, ReferenceTrack)
    ref = prep.dataset.reference
    if ref is None and not streamed:
        return None
    t = rec.t
    ref_t = None if streamed else ref.t
    t_first, t_last = (track.t_first, track.t_last) if streamed else (ref_t[0], ref_t[-1])
    inside = (t >= t_first) & (t <= t_last) & (rec.imu_row >= 0)
    idx = np.nonzero(inside)[0]
    if idx.size == 0:       # e.g. a streamed chunk wholly before or after the reference
        empty = np.empty((0, 3))
        return {"t": t[idx], "idx": idx, "pos": empty, "vel": empty, "att": empty,
                "nees": {name: np.empty(0) for name in
                         ("position", "velocity_body", "attitude")}}
    if streamed:
        j0, j1, ref_enu, ref_vel, unwrapped = track.window(t[idx[0]], t[idx[-1]])
        ref_t = track.times(j0, j1)
    else:
        ref_vel = ref.vel_enu
        ref_enu, unwrapped = reference_track(prep) if track is None else track

    def interp(a):
        return np.column_stack([np.interp(t[idx], ref_t, a[:, i]) for i in range(a.shape[1])])

    r_true = interp(ref_enu)
    v_true = interp(ref_vel)
    th_true = interp(unwrapped)
    d_pos = nav["enu"][idx] - r_true
    d_vel = nav["vel_enu"][idx] - v_true
    d_att = wrap_pi(nav["euler"][idx] - th_true)
    # NEES on the filter's own state blocks
    vb_true = np.einsum("kji,kj->ki", dcm_body_to_nav_array(th_true), v_true)
    d_vb = rec.x[idx, VEL] - vb_true
    nees = {}
    for name, err, b in (("position", d_pos, 0), ("velocity_body", d_vb, 1),
                         ("attitude", d_att, 2)):
        cov = rec.cov_blocks[idx, b]
        nees[name] = np.einsum("ki,ki->k", err, np.linalg.solve(cov, err[..., None])[..., 0])
    return {"t": t[idx], "idx": idx, "pos": d_pos, "vel": d_vel, "att": d_att, "nees": nees}


__all__ = ["ReferenceTrack", "navigation_solution", "reference_errors", "reference_track",
           "unwrap_continued"]
