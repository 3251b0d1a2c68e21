"""Merge the IMU and aiding streams into one time-ordered epoch sequence.

IMU epochs are the backbone. An aiding sample (GNSS position/velocity, heading) within
``tolerance_s`` of an IMU epoch joins that epoch, so coincident sensors form ONE update;
otherwise it gets an epoch of its own at its own time (the total-state filter predicts
to any time). Without IMU epochs (gmis.tc_gnss_only) every aiding sample is its own epoch. Index arrays map epochs to rows of each stream (-1 = absent).
"""

from dataclasses import dataclass

import numpy as np

from gmis.errors import GmisInputError


@dataclass(frozen=True)
class EpochIndex:
    t: np.ndarray          # (E,) epoch times, s
    imu: np.ndarray        # (E,) row in the IMU arrays or -1
    pos: np.ndarray        # (E,) row in the GNSS position arrays or -1
    vel: np.ndarray        # (E,) row in the GNSS velocity arrays or -1
    heading: np.ndarray    # (E,) row in the heading arrays or -1
    # (E,) row in the speed/course arrays or -1; empty (0,) when there is no speed/course
    # stream (None → empty): the kernel reads sog only where it has epochs
    # (gmis.gmikf.EpochInputs.sog_idx), 8 bytes per epoch saved
    sog: np.ndarray | None = None

    def __post_init__(self):
        if self.sog is None:
            object.__setattr__(self, "sog", np.empty(0, dtype=np.int64))

    def __len__(self):
        return self.t.size


class RowIndex:
    """An (E,) int64 index array epoch → stream row (-1 = absent) held compactly (the
    streamed run: docs/DESIGN.md "Bounded memory"): either a sparse stream whose rows
    0..M−1 sit at the increasing epochs ``at`` (M entries), or a stream with a row at
    every epoch but the increasing epochs ``gaps`` (the IMU, rows in epoch order).
    :meth:`dense` builds the rows of an epoch range; slicing gives that ndarray,
    comparisons give (E,) bool built block by block, ``np.asarray`` the whole array."""

    dtype = np.dtype(np.int64)
    ndim = 1

    def __init__(self, n_epochs: int, at=None, gaps=None):
        if (at is None) == (gaps is None):
            raise ValueError("RowIndex: give exactly one of at, gaps")
        self.n = int(n_epochs)
        self.at = None if at is None else np.ascontiguousarray(at, dtype=np.int64)
        self.gaps = None if gaps is None else np.ascontiguousarray(gaps, dtype=np.int64)

    @property
    def shape(self):
        return (self.n,)

    @property
    def size(self):
        return self.n

    def __len__(self):
        return self.n

    def dense(self, e0: int, e1: int) -> np.ndarray:
        """The index entries of epochs [e0, e1) (clipped to [0, E)): a fresh array."""
        e1 = min(max(int(e1), 0), self.n)
        e0 = min(max(int(e0), 0), e1)
        if self.at is not None:
            out = np.full(e1 - e0, -1, dtype=np.int64)
            j0, j1 = np.searchsorted(self.at, [e0, e1])
            out[self.at[j0:j1] - e0] = np.arange(j0, j1, dtype=np.int64)
            return out
        out = np.arange(e0, e1, dtype=np.int64)
        out -= np.searchsorted(self.gaps, out, side="left")
        g0, g1 = np.searchsorted(self.gaps, [e0, e1])
        out[self.gaps[g0:g1] - e0] = -1
        return out

    def __getitem__(self, key):
        if isinstance(key, slice):
            start, stop, step = key.indices(self.n)
            if step == 1:
                return self.dense(start, max(start, stop))
        elif isinstance(key, (int, np.integer)):
            k = int(key) + (self.n if key < 0 else 0)
            if not 0 <= k < self.n:
                raise IndexError(f"epoch {key} out of range for {self.n} epochs")
            return self.dense(k, k + 1)[0]
        return np.asarray(self)[key]

    def __array__(self, dtype=None, copy=None):
        whole = self.dense(0, self.n)
        return whole if dtype is None else whole.astype(dtype, copy=False)

    def _compare(self, op, other) -> np.ndarray:
        out = np.empty(self.n, dtype=bool)
        for e0 in range(0, self.n, BLOCK):
            out[e0:e0 + BLOCK] = op(self.dense(e0, e0 + BLOCK), other)
        return out

    def __ge__(self, other):
        return self._compare(np.greater_equal, other)

    def __gt__(self, other):
        return self._compare(np.greater, other)

    def __lt__(self, other):
        return self._compare(np.less, other)

    def __le__(self, other):
        return self._compare(np.less_equal, other)

    def __eq__(self, other):
        return self._compare(np.equal, other)

    def __ne__(self, other):
        return self._compare(np.not_equal, other)

    __hash__ = None


BLOCK = 1 << 16   # epochs per step of RowIndex's comparisons


def dense_epochs(epochs: EpochIndex) -> EpochIndex:
    """epochs with every RowIndex as its whole ndarray (for the engines that take the
    arrays as they are: numba loops, the smoother)."""
    def dense(a):
        return np.asarray(a) if isinstance(a, RowIndex) else a
    return EpochIndex(t=epochs.t, imu=dense(epochs.imu), pos=dense(epochs.pos),
                      vel=dense(epochs.vel), heading=dense(epochs.heading),
                      sog=dense(epochs.sog))


def _attach(imu_t, aid_t, tolerance_s, name):
    """For each aiding time: the IMU row it joins, or -1 when it needs its own epoch."""
    if aid_t.size == 0:
        return np.empty(0, dtype=np.int64)
    if imu_t.size == 0:
        return np.full(aid_t.size, -1, dtype=np.int64)
    j = np.searchsorted(imu_t, aid_t)
    j_lo = np.clip(j - 1, 0, imu_t.size - 1)
    j_hi = np.clip(j, 0, imu_t.size - 1)
    pick = np.where(np.abs(imu_t[j_lo] - aid_t) <= np.abs(imu_t[j_hi] - aid_t), j_lo, j_hi)
    ok = np.abs(imu_t[pick] - aid_t) <= tolerance_s
    row = np.where(ok, pick, -1)
    attached = row[row >= 0]
    if np.unique(attached).size != attached.size:
        raise GmisInputError(f"two {name} samples fall on the same IMU epoch "
                             f"(tolerance {tolerance_s} s); check the {name} time column")
    return row


def merge_streams(imu_t, pos_t=None, vel_t=None, heading_t=None, tolerance_s=1e-3,
                  sog_t=None, compact: bool = False):
    """Build the epoch sequence. Times in s on one time base; each stream increasing.
    sog_t: GNSS speed/course times (gmis.speed_course).

    Memory (docs/DESIGN.md "Bounded memory"): the IMU and the aiding epochs of their own
    are merged by position (searchsorted, no argsort of the whole time base); when every
    aiding sample joins an IMU epoch the epoch times ARE imu_t (the same array, not a
    copy), and streams with the same times (GNSS velocity and speed/course at the
    position's epochs) or none at all share one index array. The arrays are read only by
    convention: nothing writes into an EpochIndex.

    compact: the imu, pos, vel and heading indices as RowIndex (the same entries; a few
    bytes per aiding sample and per epoch of its own instead of 8 bytes per epoch each);
    the speed/course index stays an array."""
    imu_t = np.asarray(imu_t, dtype=float)
    streams = {"pos": pos_t, "vel": vel_t, "heading": heading_t, "sog": sog_t}
    extra_t = [np.empty(0)]
    attach = {}
    for name, st in streams.items():
        st = np.empty(0) if st is None else np.asarray(st, dtype=float)
        attach[name] = (st, _attach(imu_t, st, tolerance_s, name))
        extra_t.append(st[attach[name][1] < 0])
    own = np.unique(np.concatenate(extra_t))
    del extra_t
    n_imu = imu_t.size
    if own.size == 0:
        t = imu_t
        at_imu = None                                  # epoch of IMU row i: i
        imu_idx = np.arange(n_imu, dtype=np.int64)
    else:
        # the order of a stable sort of [imu_t, own] (an IMU epoch before an own epoch of
        # the same time): IMU row i has i IMU rows and the own times < imu_t[i] before it,
        # own time j has j own times and the IMU times <= own[j] before it
        at_imu = np.arange(n_imu, dtype=np.int64)
        at_imu += np.searchsorted(own, imu_t, side="left")
        at_own = np.arange(own.size, dtype=np.int64)
        at_own += np.searchsorted(imu_t, own, side="right")
        t = np.empty(n_imu + own.size)
        t[at_imu] = imu_t
        t[at_own] = own
        imu_idx = np.full(t.size, -1, dtype=np.int64)
        imu_idx[at_imu] = np.arange(n_imu)
    if compact:
        return _compact_index(t, n_imu, own, at_own if own.size else None, attach, sog_t)
    out = {}
    done = []                                          # (stream times, index) built
    for name, (st, row) in attach.items():
        if name == "sog" and sog_t is None:           # no speed/course stream
            out[name] = None
            continue
        same = next((idx for st_k, idx in done if st_k.size == st.size
                     and np.array_equal(st_k, st)), None)
        if same is not None:      # the same times: the same rows at the same epochs
            out[name] = same
            continue
        idx = np.full(t.size, -1, dtype=np.int64)
        if st.size:
            on_imu = row >= 0
            rows_on = np.flatnonzero(on_imu)
            idx[row[rows_on] if at_imu is None else at_imu[row[rows_on]]] = rows_on
            own_rows = np.flatnonzero(~on_imu)
            if own_rows.size:
                idx[at_own[np.searchsorted(own, st[own_rows])]] = own_rows
        out[name] = idx
        done.append((st, idx))
    return EpochIndex(t=t, imu=imu_idx, pos=out["pos"], vel=out["vel"],
                      heading=out["heading"], sog=out["sog"])


def _compact_index(t, n_imu, own, at_own, attach, sog_t) -> EpochIndex:
    """merge_streams' EpochIndex with RowIndex entries (compact=True): the epoch of IMU
    row j is j + (own times < imu_t[j]) (the stable-sort order of merge_streams), that of
    an own time its position at_own; only the aiding rows' epochs are computed."""
    e_total = t.size
    gaps = np.empty(0, dtype=np.int64) if at_own is None else at_own
    imu_idx = RowIndex(e_total, gaps=gaps)
    out = {}
    done = []
    for name, (st, row) in attach.items():
        if name == "sog":
            if sog_t is None:
                out[name] = None
            else:                                  # dense, as merge_streams builds it
                out[name] = np.asarray(_stream_index(e_total, st, row, own, at_own,
                                                     imu_idx))
            continue
        same = next((idx for st_k, idx in done if st_k.size == st.size
                     and np.array_equal(st_k, st)), None)
        if same is not None:
            out[name] = same
            continue
        idx = _stream_index(e_total, st, row, own, at_own, imu_idx)
        out[name] = idx
        done.append((st, idx))
    return EpochIndex(t=t, imu=imu_idx, pos=out["pos"], vel=out["vel"],
                      heading=out["heading"], sog=out["sog"])


def _stream_index(e_total, st, row, own, at_own, imu_idx) -> RowIndex:
    """RowIndex of one aiding stream: the epoch of each of its rows."""
    at = np.empty(st.size, dtype=np.int64)
    if st.size:
        on_imu = row >= 0
        # the epoch of IMU row j: j + the own epochs before it (gaps of imu_idx)
        j = row[on_imu]
        at[on_imu] = j + _gaps_before_row(imu_idx.gaps, j)
        if (~on_imu).any():
            at[~on_imu] = at_own[np.searchsorted(own, st[~on_imu])]
    return RowIndex(e_total, at=at)


def _gaps_before_row(gaps, j):
    """For IMU rows j: the number of gaps (own epochs) before the epoch of row j, i.e.
    the k with gaps[k−1] < j + k ≤ … (gaps[i] − i is the number of IMU rows before gap
    i, non-decreasing): k = #(gaps[i] − i ≤ j)."""
    if gaps.size == 0:
        return np.zeros(j.size, dtype=np.int64)
    rows_before_gap = gaps - np.arange(gaps.size, dtype=np.int64)
    return np.searchsorted(rows_before_gap, j, side="right")
