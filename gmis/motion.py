"""Stationary-epoch detection for the GMIKF (001 Table 4-3: jerk and angular-acceleration
process noise are zero while the vehicle is static) and for VCE (dynamics components
pause while stationary).

An epoch is stationary when the GNSS horizontal speed — from the velocity solution, or
from central differences of positions over 1 s when there is none — stays below
``speed_threshold_m_s`` for every GNSS sample within ±``margin_s`` of it. The margin keeps
the start and the end of a stop out, so the filter's dynamics are never frozen while the
vehicle moves. The GNSS samples must cover the whole window (up to one nominal GNSS
interval at each end): next to a gap — an outage, withheld epochs — the slow samples on one
side say nothing about the other, and an epoch right after an outage that ended in a stop
would freeze the acceleration the filter still carries from the braking (on the Boulder
drive with VCE-tuned noise that froze a^b at ~−2 m/s², ran the pitch to 80° and the
position 290 m away). Epochs without GNSS within the margin are not stationary.

Stop detection for ZUPT/ZARU (000 §5, eq. 5.44-5.46): :func:`stop_epochs` from the IMU
(per-axis specific-force spread and mean angular rate over a window) and, when present, the GNSS
speed (:class:`StopDetector` holds the thresholds).
"""

from dataclasses import dataclass

import numpy as np

from gmis.epochs import EpochIndex


def gnss_horizontal_speed(t, pos_enu, vel_enu=None):
    """Horizontal speed (m/s) at the GNSS epochs."""
    if vel_enu is not None and len(vel_enu) == len(t):
        return np.hypot(vel_enu[:, 0], vel_enu[:, 1])
    speed = np.full(t.size, np.inf)
    if t.size < 3:
        return speed
    j_hi = np.searchsorted(t, t + 0.5)
    j_lo = np.searchsorted(t, t - 0.5, side="right") - 1
    ok = (j_lo >= 0) & (j_hi < t.size)
    a, b = np.clip(j_lo, 0, t.size - 1), np.clip(j_hi, 0, t.size - 1)
    dt = t[b] - t[a]
    ok &= dt > 0
    d = np.hypot(pos_enu[b, 0] - pos_enu[a, 0], pos_enu[b, 1] - pos_enu[a, 1])
    speed[ok] = d[ok] / dt[ok]
    return speed


STILL_MAX_RATE_RAD_S = float(np.radians(2.0))   # the IMU's veto: turning, not at rest


def stationary_epochs(epochs: EpochIndex, gnss_t, speed, speed_threshold_m_s=0.2,
                      margin_s=1.0, imu=None, max_rate_rad_s=STILL_MAX_RATE_RAD_S):
    """(E,) bool: epochs at rest (see module docstring): every GNSS sample within
    ±margin_s slow, and the samples covering the whole window up to one nominal GNSS
    interval (the median spacing) at each end. imu = (t (N,) s, gyro (N, 3) rad/s): an
    epoch whose mean angular rate over the IMU samples within ±margin_s exceeds
    max_rate_rad_s is not at rest either — a vehicle turning on the spot moves its antenna
    slower than any speed threshold (a 90° turn at 10°/s froze the dynamics and ran the
    gyro-z bias to 40σ; helper review 2026-12-06). 2°/s lies above MEMS gyro biases and far
    below a manoeuvre."""
    e_t = epochs.t
    if gnss_t.size == 0:
        return np.zeros(e_t.size, dtype=bool)
    moving = ~(speed < speed_threshold_m_s)
    interval = float(np.median(np.diff(gnss_t))) if gnss_t.size > 1 else margin_s
    reach = margin_s - interval * (1.0 + 1e-6)
    # for each epoch, any moving GNSS sample or no sample at all within ±margin → not still
    c_moving = np.r_[0, np.cumsum(moving)]
    out = np.empty(e_t.size, dtype=bool)
    for k in range(0, e_t.size, EPOCH_BLOCK):   # blocks of epochs: no (E,) temporaries
        t = e_t[k:k + EPOCH_BLOCK]
        lo = np.searchsorted(gnss_t, t - margin_s, side="left")
        hi = np.searchsorted(gnss_t, t + margin_s, side="right")
        some = hi > lo
        first = gnss_t[np.minimum(lo, gnss_t.size - 1)]
        last = gnss_t[np.maximum(hi - 1, 0)]
        covered = (first <= t - reach) & (last >= t + reach)
        still = some & covered & (c_moving[hi] == c_moving[lo])
        if imu is not None and still.any():
            still &= ~_turning(t, imu[0], imu[1], margin_s, max_rate_rad_s)
        out[k:k + EPOCH_BLOCK] = still
    return out


def _turning(t, imu_t, gyro, margin_s, max_rate):
    """(K,) bool for the epoch times t (increasing): the mean angular rate (rad/s) of the IMU
    samples within ±margin_s has a norm above max_rate (no samples: False). Reads only
    the IMU rows of this block of epochs (gyro may be on disk, gmis.imu_spool)."""
    lo = np.searchsorted(imu_t, t - margin_s, side="left")
    hi = np.searchsorted(imu_t, t + margin_s, side="right")
    a, b = int(lo.min()), int(hi.max())
    if b <= a:
        return np.zeros(t.size, dtype=bool)
    g = np.asarray(gyro[a:b], dtype=float)
    c = np.vstack([np.zeros((1, 3)), np.cumsum(g, axis=0)])
    n = hi - lo
    mean = (c[hi - a] - c[lo - a]) / np.maximum(n, 1)[:, None]
    return (n > 0) & (np.linalg.norm(mean, axis=1) > max_rate)


EPOCH_BLOCK = 1 << 16   # epochs / IMU samples per step of the block-wise scans below


def first_motion(imu_t, gyro, accel, t0, gnss_t=None, gnss_speed=None,
                 speed_threshold_m_s=0.2, block_s=1.0, accel_change_m_s2=0.2,
                 gyro_change_rad_s=0.01):
    """Time (s) of the first motion after t0, or None: the earliest of (a) the first GNSS
    epoch after t0 with horizontal speed ≥ speed_threshold_m_s at it AND at the next GNSS
    epoch (a lone epoch above it is the velocity noise of a parked receiver: with 5 cm/s
    per axis the Rayleigh speed passes 0.2 m/s with probability e⁻⁸ per epoch, so a 300 s
    window at 5 Hz cut itself somewhere in ~40 % of the simulated drives; two in a row,
    ~1e-7 per pair of epochs if independent — a receiver's filtered velocity is correlated,
    so more often; a real start keeps moving and is dated at its first epoch; a NaN speed
    is not motion, nor is the last epoch alone) and (b) the start of the
    first block_s IMU block whose mean specific force (m/s²) or mean angular rate (rad/s)
    differs from the at-rest reference (block 0's mean without wild samples) by more
    than accel_change_m_s2 / gyro_change_rad_s on any axis, and so does the next block's
    (_first_moved_block: one wild sample is not motion). Block means average out engine
    vibration."""
    candidates = []
    if gnss_t is not None and gnss_speed is not None and len(gnss_t):
        fast = np.asarray(gnss_speed) >= speed_threshold_m_s     # NaN (unknown): not fast
        sustained = fast & np.r_[fast[1:], False]     # the last epoch cannot be confirmed
        k = np.flatnonzero((gnss_t >= t0) & sustained)
        if k.size:
            candidates.append(float(gnss_t[k[0]]))
    k = _first_moved_block(imu_t, gyro, accel, t0, block_s, accel_change_m_s2,
                           gyro_change_rad_s)
    if k is not None:
        candidates.append(t0 + float(k) * block_s)
    return min(candidates) if candidates else None


def _block_means(imu_t, gyro, accel, t0, block_s):
    """Per block_s block since t0, in order: (block number, mean specific force (3,),
    mean angular rate (3,)) of the non-empty blocks. Scanned in pieces of about
    EPOCH_BLOCK samples cut between blocks (a generator: the caller stops it at the first
    motion): every block's sums are the same bincount sums, in the same order, as over
    the whole arrays, with no (N,) temporaries."""
    n = imu_t.size
    i0 = int(np.searchsorted(imu_t, t0, side="left"))
    while i0 < n and np.floor((imu_t[i0] - t0) / block_s) < 0:
        i0 += 1                       # the rows of block < 0 (t < t0 by rounding) skipped
    while i0 < n:
        i1 = min(i0 + EPOCH_BLOCK, n)
        block = np.floor((imu_t[i0:i1] - t0) / block_s).astype(np.int64)
        if i1 < n:                    # end the piece before the block that goes on
            cut = int(np.searchsorted(block, block[-1], side="left"))
            if cut > 0:
                i1, block = i0 + cut, block[:cut]
            else:                     # one block longer than the piece: take it whole
                nxt = np.floor((imu_t[i1:] - t0) / block_s).astype(np.int64)
                i1 += int(np.searchsorted(nxt, block[-1], side="right"))
                block = np.floor((imu_t[i0:i1] - t0) / block_s).astype(np.int64)
        b = block - block[0]
        count = np.bincount(b)
        means_a = np.stack([np.bincount(b, accel[i0:i1, j]) for j in range(3)], 1)
        means_g = np.stack([np.bincount(b, gyro[i0:i1, j]) for j in range(3)], 1)
        for k in np.flatnonzero(count > 0):
            yield int(block[0] + k), means_a[k] / count[k], means_g[k] / count[k]
        i0 = i1


SPIKE_MADS = 6.0   # block 0's samples further than this (scaled MADs) are not rest


def tame_rows(x, mads: float = SPIKE_MADS, floor=0.0) -> np.ndarray:
    """(N,) bool: the rows of x (N, k) with every column within ``mads`` scaled median
    absolute deviations (1.4826·MAD, σ for normal noise; at least ``floor``, per column or
    one value: quantised samples have a MAD of 0) of the column's median — all of them
    for normal noise (a 6σ sample: 2e-9), not a wild sample (a partial line of a log that
    parses as numbers, a spike). All rows when that would keep none."""
    x = np.asarray(x, dtype=float)
    med = np.median(x, axis=0)
    dev = np.abs(x - med)
    mad = np.maximum(1.4826 * np.median(dev, axis=0), floor)
    keep = (dev <= mads * np.maximum(mad, 1e-12)).all(axis=1)
    return keep if keep.any() else np.ones(x.shape[0], dtype=bool)


def _rest_reference(imu_t, gyro, accel, t0, block_s):
    """The at-rest reference of _first_moved_block: the mean specific force / angular rate
    of the first block's samples (tame_rows: for normal noise all of them;
    a wild sample — a partial first line of a log that parses as numbers — left out).
    None without samples."""
    i0 = int(np.searchsorted(imu_t, t0, side="left"))
    if i0 >= imu_t.size:
        return None
    k0 = np.floor((imu_t[i0] - t0) / block_s)
    i1 = int(np.searchsorted(imu_t, t0 + (k0 + 1) * block_s, side="left"))
    i1 = max(i1, i0 + 1)

    a, g = np.asarray(accel[i0:i1], float), np.asarray(gyro[i0:i1], float)
    # floors: the first-motion thresholds' scale (0.2 m/s², 0.01 rad/s) / 20
    keep = tame_rows(np.hstack([a, g]), SPIKE_MADS, floor=[0.01] * 3 + [0.0005] * 3)
    return a[keep].mean(axis=0), g[keep].mean(axis=0)


def _first_moved_block(imu_t, gyro, accel, t0, block_s, accel_change, gyro_change):
    """The first block_s block (number since t0) that starts motion, or None: its mean
    specific force / angular rate and that of the next non-empty block both differ from
    the at-rest reference (_rest_reference: block 0 without its wild samples) by more
    than accel_change / gyro_change on an axis. One moved block alone is not motion: a
    single wild sample moves one block mean and must neither date a start nor, in block
    0, shift the reference."""
    ref = _rest_reference(imu_t, gyro, accel, t0, block_s)
    if ref is None:
        return None
    prev = None                       # the number of a moved block not yet confirmed
    for k, mean_a, mean_g in _block_means(imu_t, gyro, accel, t0, block_s):
        moved = (np.abs(mean_a - ref[0]).max() > accel_change
                 or np.abs(mean_g - ref[1]).max() > gyro_change)
        if moved and prev is not None:
            return prev
        prev = k if moved else None
    return None


@dataclass(frozen=True)
class StopDetector:
    """Thresholds of the stop detection that gates ZUPT/ZARU ([zupt] in the recipe).

    IMU test over a centred window of window_s: the largest per-axis standard deviation of
    the specific force below accel_std_m_s2 and the norm of the window-mean angular rate below
    gyro_rate_rad_s (the gyro bias and the earth rate, ~1e-4 rad/s, stay well below it).
    GNSS test: any GNSS speed ≥ gnss_speed_m_s within ±gnss_margin_s means moving; without
    GNSS in that margin (outage, garage) the IMU decides alone."""
    window_s: float = 1.0
    accel_std_m_s2: float = 0.05
    gyro_rate_rad_s: float = 0.005
    gnss_speed_m_s: float = 0.2
    gnss_margin_s: float = 1.0


def _window_sums(t, values, half_s):
    """Per sample: sum of values (N, k) and count over the samples within ±half_s."""
    c = np.vstack([np.zeros((1, values.shape[1])), np.cumsum(values, axis=0)])
    lo = np.searchsorted(t, t - half_s, side="left")
    hi = np.searchsorted(t, t + half_s, side="right")
    return c[hi] - c[lo], (hi - lo).astype(float)


def imu_stopped(t, gyro, accel, det: StopDetector):
    """(N,) bool per IMU sample: the IMU test of StopDetector (rad/s, m/s² inputs)."""
    t = np.asarray(t, dtype=float)
    f = np.asarray(accel, dtype=float)
    s1, n = _window_sums(t, np.hstack([f, f * f]), 0.5 * det.window_s)
    mean_f = s1[:, :3] / n[:, None]
    spread = np.sqrt(np.maximum(s1[:, 3:] / n[:, None] - mean_f ** 2, 0.0)).max(axis=1)
    g, _ = _window_sums(t, np.asarray(gyro, dtype=float), 0.5 * det.window_s)
    rate = np.linalg.norm(g / n[:, None], axis=1)
    return (spread < det.accel_std_m_s2) & (rate < det.gyro_rate_rad_s) & (n >= 3)


def stop_epochs(epochs: EpochIndex, imu_z, gnss_t, gnss_speed, det: StopDetector):
    """(E,) bool: epochs with an IMU sample at which the vehicle is stopped — the IMU test
    passes and no GNSS speed within ±gnss_margin_s says it moves (StopDetector)."""
    e_t = epochs.t
    has_imu = epochs.imu >= 0
    out = np.zeros(e_t.size, dtype=bool)
    if not has_imu.any():
        return out
    rows = epochs.imu[has_imu]
    still = imu_stopped(e_t[has_imu], imu_z[rows, :3], imu_z[rows, 3:6], det)
    out[has_imu] = still
    if gnss_t is not None and len(gnss_t):
        moving = ~(np.asarray(gnss_speed) < det.gnss_speed_m_s)
        c = np.r_[0, np.cumsum(moving)]
        lo = np.searchsorted(gnss_t, e_t - det.gnss_margin_s, side="left")
        hi = np.searchsorted(gnss_t, e_t + det.gnss_margin_s, side="right")
        out &= (c[hi] - c[lo]) == 0
    return out
