"""Latency of a GNSS solution's velocity behind its own positions, from the solution file
alone ([gnss].estimate_velocity_time_offset; docs/DESIGN.md "Time-correlated aiding
errors").

Many receivers output a velocity that describes the antenna some time δ before its time
stamp (δ > 0: the velocity lags): a Doppler velocity averaged over the last measurement
interval, a navigation filter's smoothed velocity. The Boulder drive's u-blox real-time
RTK lags by ~0.13 s at 4 Hz, which makes a filter's velocity innovations strongly
correlated in time (lag-1 ρ 0.6-0.7) and turns an acceleration a into a velocity error a·δ.

With positions of RTK quality the central difference of the track

    ṙ_k = (r_{k+1} − r_{k−1}) / (t_{k+1} − t_{k−1})   at τ_k = (t_{k+1} + t_{k−1}) / 2     (1)

is the velocity at τ_k to O(Δt²·d³r/dt³). The velocity v_k stamped t_k is compared with ṙ
interpolated linearly at t_k − δ, horizontally (E, N; the vertical of a car carries
little signal):

    c(δ) = Σ_{k∈K} |v_k − ṙ(t_k − δ)|²                                                  (2)

over a fixed set K of epochs (moving faster than MIN_SPEED_M_S, with ṙ defined without a
gap at t_k − δ for every δ searched, so that c is comparable across δ). δ̂ minimises
c: a grid of GRID_STEP_S over centre ± SEARCH_HALF_WIDTH_S, then a least-squares parabola
through the grid points within ± FINE_HALF_WIDTH_S of the best one (vertex inside that
span, else the grid node). Its 1σ is a delete-one-block jackknife over JACKKNIFE_BLOCKS
contiguous blocks of K,

    σ_δ² = (B − 1)/B · Σ_b (δ̂_(−b) − δ̄)²                                                 (3)

which stays honest when the mismatch is correlated in time (a Fisher-information σ from
c'' would count 4 Hz samples as independent). The velocity's recipe offset is then
[gnss].velocity_time_offset_s = −δ̂ (the velocity moved to its own epochs, gmis.run_preparation).

Not estimated (the recipe's value kept, a note printed): too few moving epochs
(< MIN_EPOCHS), the minimum at the edge of the search range, or a parabola that is not
convex. The estimate needs positions far better than v·δ over one interval: with metre-level
fixes ṙ is noise and σ_δ says so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MIN_SPEED_M_S = 1.0          # epochs slower than this carry no lag signal (and course noise)
SEARCH_HALF_WIDTH_S = 0.5    # δ searched within centre ± this
GRID_STEP_S = 0.005
FINE_HALF_WIDTH_S = 0.04     # parabola through the grid points within ± this of the best
MIN_EPOCHS = 40
JACKKNIFE_BLOCKS = 10
GAP_FACTOR = 2.5             # a step > GAP_FACTOR × the median step is a gap


@dataclass(frozen=True)
class VelocityLagEstimate:
    """δ̂ (s, the velocity describes the antenna at t − δ̂), its 1σ (eq. 3), the epochs of
    K, the horizontal RMS mismatch |v − ṙ| (m/s, per component) at δ = 0 and at δ̂, and
    whether it is applied (else ``reason``)."""

    lag_s: float
    sigma_s: float
    epochs: int
    rms_at_zero_m_s: float
    rms_at_lag_m_s: float
    applied: bool
    reason: str = ""

    @property
    def velocity_time_offset_s(self) -> float:
        """The [gnss].velocity_time_offset_s that undoes the lag: −δ̂."""
        return -self.lag_s

    def summary(self, used_offset_s: float) -> dict:
        out = {"method": "velocity against the central difference of the positions "
                         "(gmis.gnss_velocity_lag)",
               "applied": self.applied,
               "velocity_time_offset_s": used_offset_s,
               "lag_s": self.lag_s, "sigma_s": self.sigma_s, "epochs": self.epochs,
               "rms_mismatch_at_zero_m_s": self.rms_at_zero_m_s,
               "rms_mismatch_at_lag_m_s": self.rms_at_lag_m_s}
        if not self.applied:
            out["reason"] = self.reason
        return out


def central_difference_velocity(t, pos):
    """Eq. 1: (τ_k, ṙ_k) for the interior epochs k = 1..M−2 of (M,) times t (s) and (M, 3)
    positions (m), and a (M−2,) bool that is False where t_{k+1} − t_{k−1} spans a gap
    (> 2·GAP_FACTOR × the median step)."""
    t = np.asarray(t, dtype=float)
    pos = np.asarray(pos, dtype=float)
    span = t[2:] - t[:-2]
    rdot = (pos[2:] - pos[:-2]) / span[:, None]
    tau = 0.5 * (t[2:] + t[:-2])
    step = np.median(np.diff(t)) if t.size > 1 else np.inf
    return tau, rdot, span <= 2.0 * GAP_FACTOR * step


def _interp_rows(tq, tau, rdot):
    return np.column_stack([np.interp(tq, tau, rdot[:, i]) for i in range(rdot.shape[1])])


def _bracket_ok(tq, tau, valid):
    """True where tq lies inside [τ_0, τ_last] and both ends of its interpolation bracket
    are valid central differences whose spacing is no gap."""
    j = np.searchsorted(tau, tq, side="right") - 1
    inside = (j >= 0) & (j < tau.size - 1)
    j = np.clip(j, 0, max(tau.size - 2, 0))
    step = np.median(np.diff(tau)) if tau.size > 1 else np.inf
    ok = valid[j] & valid[np.minimum(j + 1, tau.size - 1)] \
        & (tau[np.minimum(j + 1, tau.size - 1)] - tau[j] <= GAP_FACTOR * step)
    return inside & ok


def _best_lag(grid, cost):
    """Grid minimum refined by a least-squares parabola (eq. 2's vertex); None when the
    minimum is at the edge of the grid or the parabola is not convex."""
    i = int(np.argmin(cost))
    if i == 0 or i == grid.size - 1:
        return None
    near = np.abs(grid - grid[i]) <= FINE_HALF_WIDTH_S + 1e-12
    x = grid[near] - grid[i]
    a, b, _ = np.polyfit(x, cost[near], 2)
    if not a > 0:
        return None
    vertex = -b / (2 * a)
    return float(grid[i] + vertex) if abs(vertex) <= FINE_HALF_WIDTH_S else float(grid[i])


def estimate_velocity_lag(t, pos_enu, vel_enu, centre_s: float = 0.0) -> VelocityLagEstimate:
    """δ̂ of eq. 2 for a GNSS solution: times t (M,) s, strictly increasing; ENU positions
    (M, 3) m; ENU velocities (M, 3) m/s; δ searched within centre_s ± SEARCH_HALF_WIDTH_S."""
    t = np.asarray(t, dtype=float)
    vel = np.asarray(vel_enu, dtype=float)
    pos = np.asarray(pos_enu, dtype=float)
    nothing = VelocityLagEstimate(0.0, float("inf"), 0, float("nan"), float("nan"), False,
                                  "fewer than 3 GNSS epochs")
    if t.size < 3:
        return nothing
    tau, rdot, valid = central_difference_velocity(t, pos[:, :2])
    grid = centre_s + np.arange(-SEARCH_HALF_WIDTH_S, SEARCH_HALF_WIDTH_S + GRID_STEP_S / 2,
                                GRID_STEP_S)
    moving = np.hypot(vel[:, 0], vel[:, 1]) > MIN_SPEED_M_S
    keep = moving & np.isfinite(vel[:, :2]).all(axis=1)
    for d in grid:                         # ṙ defined at t − δ for every δ searched
        keep &= _bracket_ok(t - d, tau, valid)
    k = np.flatnonzero(keep)
    if k.size < MIN_EPOCHS:
        return VelocityLagEstimate(0.0, float("inf"), int(k.size), float("nan"),
                                   float("nan"), False,
                                   f"{k.size} moving GNSS epochs with a gap-free track "
                                   f"(at least {MIN_EPOCHS} needed)")
    v = vel[k, :2]
    block_of = np.repeat(np.arange(JACKKNIFE_BLOCKS),
                         [b.size for b in np.array_split(np.arange(k.size), JACKKNIFE_BLOCKS)])
    by_block = np.empty((grid.size, JACKKNIFE_BLOCKS))   # eq. 2 per block of K
    for g, d in enumerate(grid):
        e = v - _interp_rows(t[k] - d, tau, rdot)
        by_block[g] = np.bincount(block_of, (e * e).sum(axis=1), JACKKNIFE_BLOCKS)
    rms0 = float(np.sqrt(np.mean((v - _interp_rows(t[k], tau, rdot)) ** 2)))
    total = by_block.sum(axis=1)
    lag = _best_lag(grid, total)
    if lag is None:
        return VelocityLagEstimate(0.0, float("inf"), int(k.size), rms0, float("nan"),
                                   False, "no minimum inside "
                                   f"{centre_s - SEARCH_HALF_WIDTH_S:+.3f}.."
                                   f"{centre_s + SEARCH_HALF_WIDTH_S:+.3f} s")
    loo = [_best_lag(grid, total - by_block[:, b]) for b in range(JACKKNIFE_BLOCKS)]
    if any(x is None for x in loo):
        sigma = float("inf")
    else:
        loo = np.array(loo)
        sigma = float(np.sqrt((loo.size - 1) / loo.size * ((loo - loo.mean()) ** 2).sum()))
    rms = float(np.sqrt(np.mean((v - _interp_rows(t[k] - lag, tau, rdot)) ** 2)))
    return VelocityLagEstimate(lag, sigma, int(k.size), rms0, rms, True)


__all__ = ["VelocityLagEstimate", "central_difference_velocity", "estimate_velocity_lag"]
