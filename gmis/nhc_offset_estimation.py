"""Forward position of the non-holonomic constraint point from the data: a profile
likelihood of the GMIKF's innovations over the constraint point's along-track offset
(docs/DESIGN.md "Non-holonomic constraint point from the data").

The constraint (000 eq. 5.41) says the lateral and vertical velocity of one body point,
u = v^b + ω×l (l: IMU → point, body RFU), is zero. On a car that point is near the rear
axle (the wheels that do not steer); the IMU sits elsewhere, and with l wrong by Δl_y
along the track the constraint claims a lateral velocity ω_z Δl_y that is not there in
every turn (0.15 m/s at 0.3 rad/s and 0.5 m: 1.5σ of the default 0.1 m/s, always on
the same side of the turn). l_y is usually not documented, so it is estimated: with the
constraint point at l(y) = [l_x, y, l_z] (l_x, l_z from [nonholonomic].lever_arm_m), the
innovations d_k and covariances D_k of the whole run give, by the prediction-error
decomposition (as gmis.latency_estimation eq. 1),

    c(y) = −2 log L(y) = Σ_k [ log det D_k(y) + d_k(y)ᵀ D_k(y)⁻¹ d_k(y) ] + const       (1)

over every update of the run (IMU, GNSS and constraint rows; outlier tests off, so c is
smooth in y). ŷ minimises c: a coarse grid of GRID_NODES over center ± half_width, then a
least-squares parabola through FINE_NODES points within ± FINE_HALF_WIDTH_M of the best
node, re-centred while its vertex lies outside the middle half,

    c(y) ≈ α (y − m)² + β (y − m) + γ,   ŷ = m − β / (2α),   σ_y² = 1 / α              (2)

(σ from the curvature: the observed Fisher information of the profile). It uses only what
the filter is given (the GNSS epochs of the run, none withheld ones), so it is not tuned
to any outage truth. Observability: y shows only in turns (ω_z ≠ 0) and, through the
vertical row ω_x y, in pitching; on a straight road c is flat and σ_y large. σ_y is only
as honest as the noise model: the constraint's real violation is time-correlated, so σ_y
is optimistic (use it to compare, not as a calibrated 1σ).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from gmis.errors import GmisInputError
from gmis.run_filter import GmikfRunner

GRID_NODES = 9
FINE_HALF_WIDTH_M = 0.2
FINE_NODES = 5
MAX_RECENTRE = 4


@dataclass(frozen=True)
class NhcOffsetEstimate:
    """ŷ (m, body forward, IMU → constraint point; < 0: behind the IMU), its 1σ (m,
    eq. 2), the coarse grid (m) and its costs c(y) (eq. 1), the number of filter runs,
    and whether the run uses it."""

    forward_m: float
    sigma_m: float
    grid_m: np.ndarray
    cost: np.ndarray
    runs: int
    applied: bool = True     # False: no clear minimum, the recipe's lever arm kept

    def summary(self) -> dict:
        return {"method": "profile likelihood of the innovations "
                          "(gmis.nhc_offset_estimation)",
                "forward_offset_m": self.forward_m, "sigma_m": self.sigma_m,
                "filter_runs": self.runs, "applied": self.applied}


def nhc_innovation_cost(prep, forward_m: float, axis: int = 1, window_s=None) -> float:
    """c(y) of eq. (1) for a gmis.run_preparation.PreparedRun with the constraint point at
    forward_m (m) along the body y axis from the IMU (axis 2: along the body up axis);
    window_s (lo, hi): only the updates at lo ≤ t < hi (s) are summed (split-drive
    checks, benchmarks/nhc_point_real_drive.py)."""
    lever = np.array(prep.config.nhc_lever_arm, dtype=float)
    lever[axis] = forward_m
    config = replace(prep.config, nhc_lever_arm=lever, outlier_alpha=0.0, reopen_after=0)
    runner = GmikfRunner(prep.epochs, prep.meas, prep.x0, config, prep.frame,
                         prep.stationary)
    runner.advance(runner.e_total)
    if window_s is None:
        return float(runner.rec.nll.sum())
    t = runner.rec.t
    return float(runner.rec.nll[(t >= window_s[0]) & (t < window_s[1])].sum())


def estimate_nhc_offset(prep, half_width_m: float = 2.0, center_m: float | None = None,
                        cost=nhc_innovation_cost) -> NhcOffsetEstimate:
    """ŷ and σ_y of eqs. (1)-(2) over center_m ± half_width_m (center: the recipe's
    lever_arm_m[1])."""
    if not prep.config.nhc_enabled:
        raise GmisInputError("nonholonomic.estimate_lever_arm: the constraint is off")
    if center_m is None:
        center_m = float(prep.config.nhc_lever_arm[1])
    cache = {}

    def c(y):
        y = round(float(y), 9)
        if y not in cache:
            cache[y] = cost(prep, y)
        return cache[y]

    grid = center_m + np.linspace(-half_width_m, half_width_m, GRID_NODES)
    costs = np.array([c(y) for y in grid])
    mid = float(grid[int(np.argmin(costs))])
    for _ in range(MAX_RECENTRE):
        fine = mid + np.linspace(-FINE_HALF_WIDTH_M, FINE_HALF_WIDTH_M, FINE_NODES)
        a, b, _ = np.polyfit(fine - mid, np.array([c(y) for y in fine]), 2)
        if a <= 0:
            break
        vertex = mid - b / (2.0 * a)
        if abs(vertex - mid) <= FINE_HALF_WIDTH_M / 2:
            return NhcOffsetEstimate(float(vertex), float(np.sqrt(1.0 / a)), grid, costs,
                                     len(cache))
        mid = float(np.clip(vertex, mid - FINE_HALF_WIDTH_M, mid + FINE_HALF_WIDTH_M))
    return NhcOffsetEstimate(mid, float("inf"), grid, costs, len(cache))


def with_estimated_nhc_offset(prep, half_width_m: float = 2.0):
    """(prep with its constraint point at ŷ, the estimate)."""
    est = estimate_nhc_offset(prep, half_width_m)
    lever = np.array(prep.config.nhc_lever_arm, dtype=float)
    lever[1] = est.forward_m
    return replace(prep, config=replace(prep.config, nhc_lever_arm=lever)), est


def with_estimated_nhc_point(first, nhc):
    """[nonholonomic].estimate_lever_arm: ``first`` is the run prepared as without it
    (every GNSS epoch the run is given, outages removed; gmis.run_preparation.prepare_run
    does that), then ŷ of its data is searched within lever_arm_m[1] ± lever_arm_search_m
    of ``nhc`` (the recipe's NonholonomicSection); the prepared run returned carries the
    constraint point at ŷ and the estimate (nhc_offset), and a note is printed."""
    from gmis.plausibility import announce

    prep, est = with_estimated_nhc_offset(first, nhc.lever_arm_search_m)
    note = (f"non-holonomic constraint point estimated from the data: "
            f"[nonholonomic].lever_arm_m[1] = {est.forward_m:+.3f} m (body forward; 1 sigma "
            f"{est.sigma_m:.3f} m from the profile curvature, optimistic; {est.runs} filter "
            "runs)")
    if not np.isfinite(est.sigma_m) or abs(est.forward_m - nhc.lever_arm_m[1]) > \
            0.95 * nhc.lever_arm_search_m:
        note += ("; the profile has no clear minimum inside the search range "
                 "(too few turns?), [nonholonomic].lever_arm_m kept")
        prep, est = first, replace(est, applied=False)
    prep = replace(prep, dataset=replace(prep.dataset,
                                         warnings=prep.dataset.warnings + (note,)))
    prep.nhc_offset = est
    announce([note])
    return prep


__all__ = ["NhcOffsetEstimate", "estimate_nhc_offset", "nhc_innovation_cost",
           "with_estimated_nhc_offset", "with_estimated_nhc_point"]
