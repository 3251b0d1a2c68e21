"""GNSS time offset (receiver latency) from the data: a profile-likelihood search outside
the filter (issue 20 item 4; docs/DESIGN.md "GNSS latency from the data").

A fix stamped t carries the antenna state at t − δ (δ > 0: late). With the GNSS stream
times shifted by an offset o (the [gnss].time_offset_s convention: t_used = t_file + o,
so o = −δ undoes a latency δ), the GMIKF's innovations d_k and their covariances D_k over
the whole run give the Gaussian log-likelihood by the prediction-error decomposition

    −2 log L(o) = Σ_k [ log det D_k(o) + d_k(o)ᵀ D_k(o)⁻¹ d_k(o) ] + const        (1)

(every update of the run, IMU rows included; gmis.gmikf.innovation_nll per epoch). The
offset is the minimiser ô of the cost c(o) = −2 log L(o), searched on offsets that are
whole multiples of the IMU sample period T from the search centre (phase-locked, below):
a coarse grid (GRID_NODES over center ± half_width, snapped to the T lattice), then a
least-squares parabola through c on the lattice points within ± FINE_HALF_WIDTH_S of the
best node (re-centred on the vertex while that lies outside the middle half, widened up
to MAX_FINE_HALF_WIDTH_S while the fitted curvature is not positive; σ = ∞ when it never
is):

    c(o) ≈ α (o − m)² + β (o − m) + γ,    ô = m − β / (2α)                           (2)

and its 1σ from the curvature (the observed Fisher information of the profile):

    σ_o² = 2 / c''(ô) = 1 / α                                                         (3)

Why phase-locked: c(o) carries a ripple with the period T of the IMU samples. Its cause
is the kernel's process-noise discretisation (gmis.gmikf.process_noise_variances): the
jerk / angular acceleration is held constant over each prediction step, Q(Δt) =
Λ(Δt) (q/Δt) Λ(Δt)ᵀ, which is not additive when a step is split — a fix placed between
two IMU samples splits their step in two, and the split step carries more velocity and
attitude variance than the unsplit one (1-D constant jerk split in half: Q_vv
0.3125 q Δt³ against 0.25 q Δt³; continuous white jerk: 1/3), by an amount that depends
on where in the interval the fix falls (zero at either end, largest in the middle). The
ripple scales with q: on seed 6 of benchmarks/consumer_receiver_drive.py it is ~5 units
of c at the recipe's q, ~1900 with q × 100 and gone with q × 0.01. Shifting every fix by
a whole number of IMU periods keeps each fix's phase in its IMU interval (for a uniform
IMU clock, gmis.imu_clock), so every evaluated o sees the same splits and the ripple is
not sampled at all; the lattice step T (10 ms at 100 Hz) is fine enough for a parabola
over ±60 ms (13 points).

The search runs with the outlier tests off (a rejection switching on or off with o would
make c jump) and with the epoch-merge tolerance 0 (a shifted fix within 1 ms of an IMU
sample is not snapped onto it), over the same fixes at every o (those inside the IMU span
for the whole search range: a fix entering or leaving the run would make c jump). The
likelihood, and so σ_o, is only as honest as the
noise model: with time-correlated fixes (a receiver's own filtered fix) the Gauss-Markov
error states of gmis.gnss_error_states must be on, otherwise the fixes count as
independent and σ_o is too small. Observability: δ shows only where the antenna velocity
changes (accelerations, turns; δ·v along the track is otherwise a constant position
offset against zero-mean fix errors).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from gmis.epochs import EpochIndex, merge_streams
from gmis.motion import gnss_horizontal_speed, stationary_epochs
from gmis.run_filter import GmikfRunner

GRID_NODES = 13
FINE_HALF_WIDTH_S = 0.06
MAX_FINE_HALF_WIDTH_S = 0.24


@dataclass(frozen=True)
class TimeOffsetEstimate:
    """ô (s, to add to the GNSS times on top of the recipe's offset), its 1σ (s), the
    profile grid (s) and its costs c(o) (eq. 1), and the number of filter runs."""

    offset_s: float
    sigma_s: float
    grid_s: np.ndarray
    cost: np.ndarray
    runs: int
    applied: bool = True
    reason: str = ""        # why not applied

    def summary(self, base_offset_s: float = 0.0) -> dict:
        out = {"method": "profile likelihood of the innovations (gmis.latency_estimation)",
               "applied": self.applied, "time_offset_s": base_offset_s + self.offset_s,
               "estimated_shift_s": self.offset_s, "sigma_s": self.sigma_s,
               "filter_runs": self.runs}
        if not self.applied:
            out["reason"] = self.reason
        return out


MIN_MOVING_FIXES = 40      # the offset shows only where the antenna velocity changes
MOVING_SPEED_M_S = 1.0


def _stream_times(idx, t):
    """Times of the rows of one stream from its epoch index (rows in stream order)."""
    have = idx >= 0
    out = np.empty(int(have.sum()))
    out[idx[have]] = t[have]
    return out


def shifted_epochs(epochs: EpochIndex, imu_t, offset_s: float, rows_window=None) -> EpochIndex:
    """The epoch sequence with the GNSS position, velocity and speed/course streams moved
    by offset_s (heading unchanged), merge tolerance 0. rows_window (lo, hi): only GNSS
    rows whose unshifted time lies in it are used (default: those landing inside the IMU
    span at this offset); epochs before the first IMU sample are dropped (the initial state
    is for imu_t[0])."""
    if rows_window is None:
        rows_window = (imu_t[0] - offset_s, imu_t[-1] - offset_s)
    lo, hi = rows_window

    def times(idx):
        if not (idx >= 0).any():
            return None, None
        t = _stream_times(idx, epochs.t)
        rows = np.flatnonzero((t >= lo) & (t <= hi))
        return t[rows] + offset_s, rows

    (pos_t, pos_rows), (vel_t, vel_rows), (sog_t, sog_rows) = (
        times(epochs.pos), times(epochs.vel), times(epochs.sog))
    heading = _stream_times(epochs.heading, epochs.t) if (epochs.heading >= 0).any() else None
    ep = merge_streams(imu_t, pos_t, vel_t, heading, 0.0, sog_t=sog_t)

    def original(idx, rows):
        return idx if rows is None else np.where(idx >= 0, rows[np.maximum(idx, 0)], -1)

    k0 = int(np.searchsorted(ep.t, imu_t[0]))
    return EpochIndex(t=ep.t[k0:], imu=ep.imu[k0:], pos=original(ep.pos, pos_rows)[k0:],
                      vel=original(ep.vel, vel_rows)[k0:], heading=ep.heading[k0:],
                      sog=original(ep.sog, sog_rows)[k0:])


def innovation_cost(prep, offset_s: float, rows_window=None) -> float:
    """c(o) of eq. (1) for the GNSS streams of a gmis.run_preparation.PreparedRun shifted
    by offset_s (s); rows_window: see shifted_epochs (the same rows for every o of one
    search, so that c does not jump when a fix enters or leaves the IMU span)."""
    imu_t = prep.dataset.imu.t
    ep = shifted_epochs(prep.epochs, imu_t, offset_s, rows_window)
    meas = prep.meas
    pos_t = _stream_times(prep.epochs.pos, prep.epochs.t)
    still = np.zeros(len(ep), dtype=bool)
    if pos_t.size:    # stillness as gmis.run_preparation, at the shifted times
        vel = meas.vel_enu if len(meas.vel_enu) == pos_t.size else None
        speed = gnss_horizontal_speed(pos_t, np.asarray(meas.pos_enu).reshape(-1, 3), vel)
        still = stationary_epochs(ep, pos_t + offset_s, speed,
                                  imu=(imu_t, prep.dataset.imu.gyro))
    config = replace(prep.config, outlier_alpha=0.0, reopen_after=0)
    runner = GmikfRunner(ep, meas, prep.x0, config, prep.frame, still)
    runner.advance(len(ep))
    return float(runner.rec.nll.sum())


def imu_period(imu_t) -> float:
    """The IMU sample period T (s): the median sample interval."""
    return float(np.median(np.diff(np.asarray(imu_t, float))))


def estimate_time_offset(prep, half_width_s: float = 0.3, center_s: float = 0.0
                         ) -> TimeOffsetEstimate:
    """ô and σ_o of eqs. (1)-(3) over center_s ± half_width_s (s), c evaluated only at
    center_s + k T (the phase-locked lattice of the module doc)."""
    imu_t = prep.dataset.imu.t
    step = imu_period(imu_t)

    def lattice(o):
        return center_s + step * np.round((np.asarray(o, float) - center_s) / step)

    grid = np.unique(lattice(center_s + np.linspace(-half_width_s, half_width_s,
                                                    GRID_NODES)))
    reach = half_width_s + 2 * MAX_FINE_HALF_WIDTH_S + step
    window = (imu_t[0] - center_s + reach, imu_t[-1] - center_s - reach)
    cache = {}

    def cost(o):
        k = round((float(o) - center_s) / step)
        if k not in cache:
            cache[k] = innovation_cost(prep, center_s + k * step, window)
        return cache[k]

    costs = np.array([cost(o) for o in grid])
    mid = float(grid[int(np.argmin(costs))])
    width = FINE_HALF_WIDTH_S
    for _ in range(6):
        n_half = max(2, round(width / step))
        fine = mid + step * np.arange(-n_half, n_half + 1)
        c = np.array([cost(o) for o in fine])
        a, b, _c0 = np.polyfit(fine - mid, c, 2)
        if a <= 0:                  # flat profile: a wider window
            if width * 2 > MAX_FINE_HALF_WIDTH_S:
                break
            width *= 2
            continue
        vertex = mid - b / (2.0 * a)
        if abs(vertex - mid) <= width / 2:
            return TimeOffsetEstimate(float(vertex), float(np.sqrt(1.0 / a)), grid, costs,
                                      len(cache))
        mid = float(lattice(np.clip(vertex, mid - width, mid + width)))
    return TimeOffsetEstimate(mid, float("inf"), grid, costs, len(cache))
