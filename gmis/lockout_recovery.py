"""Lock-out recovery: a sensor group rejected at many consecutive epochs re-opens the
covariance and is accepted again (numba stage of the GMIKF epoch loop, gmis.gmikf).

The outlier tests of 001 §5.2.3.1 compare each innovation with D = H P⁻ Hᵀ + R. Once the
state has drifted away from an aiding sensor by more than D allows — a wrong bias learnt at
rest, a manoeuvre the process noise did not cover, an outage — every later epoch of that
sensor fails too, the filter never sees it again, and the solution diverges while the
sensor is present (the real-drive failure of issue 14). The test cannot tell "the sensor is
wrong" from "the filter is wrong"; persistence can: a run of ``reopen_after`` consecutive
epochs at which an aiding group (GNSS position, GNSS velocity, heading) is rejected is taken
as the filter being wrong, and at that epoch

1. (not done: raising every variance to its initial value, P ← S P S, was tried on the
   real drive and destroyed the bias and attitude knowledge at every GNSS step;
   ``inflate_to_initial`` is kept for a full restart)
2. for each observation a of the group, in turn, P ← P + c hₐ hₐᵀ with
   c = max(0, dₐ² − Dₐₐ) / (hₐᵀ hₐ)²: the variance of the states the observation depends
   on (weighted by its Jacobian row — position for a GNSS position, body velocity and
   attitude for a GNSS velocity) is raised just enough for its innovation variance to
   cover the innovation (Dₐₐ ≥ dₐ², |z| ≤ 1). Inflating along P hₐ instead would also
   raise the states merely correlated with it and turn a position step into a velocity
   jump that overshoots;
3. the group is accepted at this epoch without its test; the other groups are re-tested
   with the re-opened covariance (by the caller).

Each event sets the group's bit in ``rec.reopened[e]``; the Python side reports the events
(summary.json and a printed warning). The IMU group is never re-opened this way: it is
present at every epoch and drives the prediction.
"""

import numpy as np
from numba import njit


@njit(cache=True)
def inflate_to_initial(p, p0_var):
    """P ← S P S, S_ii = max(1, √(p0_var_i / P_ii)): every variance at least its initial
    value, correlations unchanged."""
    n = p.shape[0]
    s = np.empty(n)
    for i in range(n):
        pii = p[i, i]
        s[i] = np.sqrt(p0_var[i] / pii) if (pii > 0.0 and pii < p0_var[i]) else 1.0
        if pii <= 0.0:
            s[i] = 1.0
            p[i, i] = p0_var[i]
    for i in range(n):
        for j in range(n):
            p[i, j] *= s[i] * s[j]


@njit(cache=True)
def inflate_along_observation(p, h_row, d, r, u):
    """P ← P + c h hᵀ, c = max(0, d² − (hᵀPh + r)) / (hᵀh)² (module docstring, step 2);
    u: (n,) scratch. Returns the innovation variance after the inflation."""
    n = p.shape[0]
    hph = 0.0
    hh = 0.0
    for i in range(n):
        acc = 0.0
        for k in range(n):
            hk = h_row[k]
            if hk != 0.0:
                acc += p[i, k] * hk
        u[i] = acc
        hph += h_row[i] * acc
        hh += h_row[i] * h_row[i]
    if hh <= 0.0:
        return hph + r
    c = (d * d - hph - r) / (hh * hh)
    if c <= 0.0:
        return hph + r
    for i in range(n):
        hi = h_row[i]
        if hi != 0.0:
            for j in range(n):
                p[i, j] += c * hi * h_row[j]
    return d * d


@njit(cache=True)
def recover_lockout(e, m, p, reopen_after, p0_var, aiding_groups, group_start, group_size,
                    used, d, h_all, r_all, rejected, streak, reopened, u):
    """Update the rejection streak of every aiding group present at epoch e (rejected =
    rec.rejected[e], after the outlier tests) and re-open the covariance of the groups whose
    streak reaches reopen_after (module docstring). Returns the bitmask of re-opened groups
    (bit g = group g), 0 when none."""
    mask = 0
    for gi in range(aiding_groups.shape[0]):
        g = aiding_groups[gi]
        g0 = group_start[g]
        gn = group_size[g]
        present = False
        any_rejected = False
        for a in range(m):
            slot = used[a]
            if slot >= g0 and slot < g0 + gn:
                present = True
                if rejected[slot] != 0:
                    any_rejected = True
        if not present:
            continue
        if not any_rejected:
            streak[g] = 0
            continue
        streak[g] += 1
        if streak[g] < reopen_after:
            continue
        for a in range(m):
            slot = used[a]
            if slot >= g0 and slot < g0 + gn:
                inflate_along_observation(p, h_all[slot], d[a], r_all[slot], u)
        streak[g] = 0
        mask |= 1 << g
    if mask != 0:
        reopened[e] = mask
    return mask
