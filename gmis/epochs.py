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
                  sog_t=None):
    """Build the epoch sequence. Times in s on one time base; each stream increasing.
    sog_t: GNSS speed/course times (gmis.speed_course).

    Memory (docs/DESIGN.md "Bounded memory"): the IMU and the aiding epochs of their own
    are merged by position (searchsorted, no argsort of the whole time base); when every
    aiding sample joins an IMU epoch the epoch times ARE imu_t (the same array, not a
    copy), and streams with the same times (GNSS velocity and speed/course at the
    position's epochs) or none at all share one index array. The arrays are read only by
    convention: nothing writes into an EpochIndex."""
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
