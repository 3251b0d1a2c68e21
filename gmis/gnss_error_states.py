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
