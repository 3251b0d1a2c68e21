"""Time-correlated GNSS fix errors as first-order Gauss-Markov states (issue 20 item 5).

A receiver that outputs its own filtered fix at 5-10 Hz has position errors correlated
over seconds; treated as white, the filter trusts 10 fixes per second as 10 independent
looks and its σ collapses (position NEES 137 on the issue's drive). Model, per ENU axis i:

    z_r = r + C_b^n L + b + v,      v ~ N(0, σ_file²)                  (fix, m)
    b_{k+1} = φ b_k + w_k,   φ = e^{−Δt/τ},   w_k ~ N(0, σ_b² (1 − φ²))   (m)

b = [b_E, b_N, b_U] are three states appended after the IMU states (indices n_imu ..
n_imu + 2), started at 0 with variance σ_b² (the stationary variance), so that b is a
stationary process with E[b_k b_{k+j}] = σ_b² e^{−|t_j − t_k|/τ}. σ_b and τ come from
[gnss].error_sigma_m and [gnss].error_correlation_time_s; the per-epoch file (or recipe)
σ is then the white part v. The prediction step is exact for any Δt (no discretisation
error): x_b ← φ x_b, row and column b of P scaled by φ, P_bb += σ_b² (1 − φ²).
The position rows gain ∂z_r/∂b = I (gmis.gmikf.assemble_epoch_rows).
Backward (gmis.smoother) runs with these states are refused (gmis.run_filter).

VCE of σ_b (vce.components, docs/DESIGN.md "VCE as implemented"): the driving noise w is a
process-noise pseudo-observation like jerk (001 eq. 2.7.17-2.7.20) with the cofactor
q h hᵀ, h = H e_b the position rows' column of b. Between two epochs whose update uses a
position row nothing observes b, so the noise of all the steps in between enters the
next such update as ONE pseudo-observation with the accumulated variance
q_acc = σ_b² (1 − e^{−2 Δt/τ}) (Δt since that last update; P⁻ = P_rest + e_b q_acc e_bᵀ
exactly, as no intermediate row correlates it with another state):
:func:`accumulate_gnss_error_noise` keeps it in the VCE's per-axis variances after the
IMU process-noise axes, :func:`reset_gnss_error_noise` clears it once a position row
has entered an update. q_acc is linear in σ_b² (τ fixed), so σ_b² is a linear variance
component; τ is not (it stays the recipe's).
"""

import numpy as np
from numba import njit

N_GNSS_ERROR_STATES = 3


@njit(cache=True, inline="always")
def predict_gnss_error_states(x, p, dt, i0, inv_tau, var):
    """The Gauss-Markov step of the three states at i0 over dt s (module doc): inv_tau
    (3,) 1/s, var (3,) stationary σ_b² m²."""
    n = p.shape[0]
    for i in range(N_GNSS_ERROR_STATES):
        d = np.exp(-abs(dt) * inv_tau[i])
        s = i0 + i
        x[s] *= d
        for j in range(n):
            p[s, j] *= d
            p[j, s] *= d
        p[s, s] += var[i] * (1.0 - d * d)


@njit(cache=True, inline="always")
def add_gnss_error_to_position_rows(x, i0, hx, jac, row0):
    """h_r += b and ∂h_r/∂b = I for the three position rows at row0."""
    for i in range(N_GNSS_ERROR_STATES):
        hx[row0 + i] += x[i0 + i]
        jac[row0 + i, i0 + i] = 1.0


@njit(cache=True, inline="always")
def accumulate_gnss_error_noise(dt, inv_tau, var, q_var, k0):
    """q_var[k0 + i] ← φ² q_var[k0 + i] + σ_b² (1 − φ²), φ = e^{−|dt|/τ}: the variance of
    the Gauss-Markov driving noise accumulated since the last update that used a position
    row (module doc), per ENU axis; m²."""
    for i in range(N_GNSS_ERROR_STATES):
        d2 = np.exp(-2.0 * abs(dt) * inv_tau[i])
        q_var[k0 + i] = d2 * q_var[k0 + i] + var[i] * (1.0 - d2)


@njit(cache=True, inline="always")
def reset_gnss_error_noise(q_var, k0, used, m, slot_pos):
    """Clear the accumulated driving-noise variances once an update used a position row
    (slots slot_pos .. slot_pos + 2 among used[:m])."""
    for a in range(m):
        if slot_pos <= used[a] < slot_pos + N_GNSS_ERROR_STATES:
            for i in range(N_GNSS_ERROR_STATES):
                q_var[k0 + i] = 0.0
            return
