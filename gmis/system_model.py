"""Discrete kinematic system model of the GMIKF (001 eq. 4.1.14-4.1.38, 5.1.1-5.1.2).

Continuous model (4.1.14-4.1.20): ṙ = C_b^n v, v̇ = a − ω×v, ȧ = j − ω×a, θ̇ = C(θ) ω,
ω̇ = noise, biases and scale factors random walks. One step Δt (s) of the discrete model
with per-step noise w = [j (m/s³), ω̇ (rad/s²), w_bω, w_ba, w_sω, w_sa] (001 Table 6-2
values are per-step 1σ of j and ω̇):

    r' = r + C_b^n (v Δt + a Δt²/2) + C_b^n j Δt³/6
    v' = (I − [ω×]Δt + [ω×]²Δt²/2) v + (I Δt − [ω×]Δt²) a + j Δt²/2 + [v×] ω̇ Δt²/2   (4.1.34)
    a' = (I − [ω×]Δt + [ω×]²Δt²/2) a + (I Δt − [ω×]Δt²/2) j + [a×] ω̇ Δt²/2           (4.1.36)
    θ' = θ + C(θ) ω Δt + C(θ) ω̇ Δt²/2                                                (4.1.37)
    ω' = ω + ω̇ Δt,   b' = e^{−Δt/τ} b + w_b,   S' = S + w_S

Each bias / scale-factor state is a random walk (1/τ = 0, the default) or a first-order
Gauss-Markov process with correlation time τ (002 §IV: sampled at Δt the GM is the AR1
of the calibration's composite model with φ = e^{−Δt/τ}); with the continuous driving density q = 2σ²/τ of a GM
of steady-state variance σ², var(w_b) = σ²(1 − e^{−2Δt/τ}) = q (1 − e^{−2Δt/τ}) τ/2,
which tends to the random walk's q Δt as 1/τ → 0 (drift_noise_variance).

Position differs from the printed 4.1.28/5.1.1 on purpose: with a^b defined by 4.1.15,
d²r/dt² = C_b^n a and d³r/dt³ = C_b^n j exactly, so the (ω×v)Δt²/2 and (ω×a)Δt³/3 terms
of 5.1.1 count the body rotation twice (they would bias position by ~1.5 cm/s in a
0.3 rad/s turn at 10 m/s). The jerk enters a' with Δt²/2 (Taylor term ω×ȧ·Δt²/2), not
Δt² as printed. Φ = ∂f/∂x and Λ = ∂f/∂w are derived from these formulas and tested
against central differences (tests/test_system_model.py); docs/DESIGN.md has the details.
"""

import numpy as np
from numba import njit

from gmis.frames import (
    attitude_trig,
    dcm_partials_rows_trig,
    dcm_rows_trig,
    euler_rate_rows_trig,
    skew_rows,
)
from gmis.state import (
    I_ACC,
    I_ATT,
    I_HEADING,
    I_PITCH,
    I_POS,
    I_RATE,
    I_ROLL,
    I_VEL,
    I_W_ANGACC,
    I_W_DRIFT,
    I_W_JERK,
    N_DYNAMIC,
    N_KINEMATIC_NOISE,
)

# The kernels' hot path allocates nothing: 3-vectors and 3×3 matrices of one step are
# tuples (c[i][k]; registers/stack in numba), not np.empty temporaries.


@njit(cache=True, inline="always")
def _cross(a, b):
    """a × b as a tuple (a, b: 3-vectors or tuples)."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True)
def propagate_state_into(x, w, dt, n_imu, out):
    """x_{k+1} = f(x_k, w_k) for one step of dt seconds (eq. 5.1.1 as corrected above).

    x: state whose first n_imu (21 or 27) entries follow state.py; further entries
    (ambiguities) are carried over unchanged. w: (n_imu − 9,) per-step noise sample
    (zeros for the prediction). out: same shape as x. Allocation-free."""
    trig = attitude_trig(x[I_PITCH], x[I_ROLL], x[I_HEADING])
    c = dcm_rows_trig(trig)
    cr = euler_rate_rows_trig(trig[1], trig[2], trig[3], np.tan(x[I_PITCH]))
    v = x[I_VEL:I_VEL + 3]
    a = x[I_ACC:I_ACC + 3]
    om = x[I_RATE:I_RATE + 3]
    j = w[I_W_JERK:I_W_JERK + 3]
    al = w[I_W_ANGACC:I_W_ANGACC + 3]
    dt2 = dt * dt
    wv = _cross(om, v)
    wwv = _cross(om, wv)
    wa = _cross(om, a)
    wwa = _cross(om, wa)
    wj = _cross(om, j)
    val = _cross(v, al)
    aal = _cross(a, al)
    for i in range(3):
        d = 0.0
        for k in range(3):
            d += c[i][k] * (v[k] * dt + 0.5 * a[k] * dt2 + j[k] * dt2 * dt / 6.0)
        out[I_POS + i] = x[I_POS + i] + d
        out[I_VEL + i] = (v[i] - wv[i] * dt + 0.5 * wwv[i] * dt2 + a[i] * dt - wa[i] * dt2
                      + 0.5 * j[i] * dt2 + 0.5 * val[i] * dt2)
        out[I_ACC + i] = (a[i] - wa[i] * dt + 0.5 * wwa[i] * dt2 + j[i] * dt - 0.5 * wj[i] * dt2
                      + 0.5 * aal[i] * dt2)
        th = 0.0
        for k in range(3):
            th += cr[i][k] * (om[k] * dt + 0.5 * al[k] * dt2)
        out[I_ATT + i] = x[I_ATT + i] + th
        out[I_RATE + i] = om[i] + al[i] * dt
    for i in range(N_DYNAMIC, x.shape[0]):
        out[i] = x[i]
    for i in range(n_imu - N_DYNAMIC):
        out[N_DYNAMIC + i] += w[I_W_DRIFT + i]


@njit(cache=True)
def _propagate_state(x, w, dt, n_imu, inv_tau):
    out = np.empty(x.shape[0])
    propagate_state_gm_into(x, w, dt, n_imu, inv_tau, out)
    return out


def propagate_state(x, w, dt, n_imu, drift_inv_tau=None):
    """f(x, w) (copy); drift_inv_tau as in transition_jacobians."""
    inv_tau = (np.zeros(n_imu - N_DYNAMIC) if drift_inv_tau is None
               else np.ascontiguousarray(drift_inv_tau, dtype=np.float64))
    return _propagate_state(np.ascontiguousarray(x, dtype=np.float64),
                            np.ascontiguousarray(w, dtype=np.float64), dt, n_imu, inv_tau)


@njit(cache=True, inline="always")
def _outer_rate_term(om, u, i, k):
    """Entry (i, k) of ∂(ω×(ω×u))/∂ω = (ω·u) I + ω uᵀ − 2 u ωᵀ."""
    out = om[i] * u[k] - 2.0 * u[i] * om[k]
    if i == k:
        out += om[0] * u[0] + om[1] * u[1] + om[2] * u[2]
    return out


@njit(cache=True)
def transition_jacobians_into(x, dt, phi_dyn, lam_dyn):
    """Φ and Λ of the dynamic block (eq. 5.1.2, derived from f above).

    phi_dyn: (15, 15) = ∂[r v a θ ω]'/∂[r v a θ ω]; the full Φ is block-diag(phi_dyn, I).
    lam_dyn: (15, 6) = ∂[r v a θ ω]'/∂[j ω̇]; bias/scale drifts enter through I.
    Allocation-free.
    """
    trig = attitude_trig(x[I_PITCH], x[I_ROLL], x[I_HEADING])   # sin, cos once
    c = dcm_rows_trig(trig)
    dcp, dcr, dch = dcm_partials_rows_trig(trig)
    tp = np.tan(x[I_PITCH])
    cr = euler_rate_rows_trig(trig[1], trig[2], trig[3], tp)
    v = x[I_VEL:I_VEL + 3]
    a = x[I_ACC:I_ACC + 3]
    om = x[I_RATE:I_RATE + 3]
    dt2 = dt * dt
    phi_dyn[:, :] = 0.0
    lam_dyn[:, :] = 0.0
    for i in range(N_DYNAMIC):
        phi_dyn[i, i] = 1.0
    d = (v[0] * dt + 0.5 * a[0] * dt2, v[1] * dt + 0.5 * a[1] * dt2,
         v[2] * dt + 0.5 * a[2] * dt2)
    # position row
    for i in range(3):
        r = I_POS + i
        for k in range(3):
            phi_dyn[r, I_VEL + k] = c[i][k] * dt
            phi_dyn[r, I_ACC + k] = c[i][k] * 0.5 * dt2
            lam_dyn[r, I_W_JERK + k] = c[i][k] * dt2 * dt / 6.0
        phi_dyn[r, I_PITCH] = dcp[i][0] * d[0] + dcp[i][1] * d[1] + dcp[i][2] * d[2]
        phi_dyn[r, I_ROLL] = dcr[i][0] * d[0] + dcr[i][1] * d[1] + dcr[i][2] * d[2]
        phi_dyn[r, I_HEADING] = dch[i][0] * d[0] + dch[i][1] * d[1] + dch[i][2] * d[2]
    # velocity and acceleration rows
    wx = skew_rows(om[0], om[1], om[2], 1.0)
    # [u×] as a function: [u×]_{ik}
    for i in range(3):
        for k in range(3):
            eye = 1.0 if i == k else 0.0
            wx2_ik = wx[i][0] * wx[0][k] + wx[i][1] * wx[1][k] + wx[i][2] * wx[2][k]
            a_mat = eye - wx[i][k] * dt + 0.5 * wx2_ik * dt2
            phi_dyn[I_VEL + i, I_VEL + k] = a_mat
            phi_dyn[I_VEL + i, I_ACC + k] = eye * dt - wx[i][k] * dt2
            phi_dyn[I_ACC + i, I_ACC + k] = a_mat
            lam_dyn[I_VEL + i, I_W_JERK + k] = 0.5 * eye * dt2
            lam_dyn[I_ACC + i, I_W_JERK + k] = eye * dt - 0.5 * wx[i][k] * dt2
    vx = skew_rows(v[0], v[1], v[2], 1.0)
    ax = skew_rows(a[0], a[1], a[2], 1.0)
    for i in range(3):
        for k in range(3):
            # ∂(−ω×v Δt)/∂ω = [v×]Δt; ∂(ω×(ω×v))Δt²/2; ∂(−ω×a Δt²)/∂ω = [a×]Δt²
            phi_dyn[I_VEL + i, I_RATE + k] = (vx[i][k] * dt
                                              + 0.5 * _outer_rate_term(om, v, i, k) * dt2
                                              + ax[i][k] * dt2)
            phi_dyn[I_ACC + i, I_RATE + k] = (ax[i][k] * dt
                                              + 0.5 * _outer_rate_term(om, a, i, k) * dt2)
            lam_dyn[I_VEL + i, I_W_ANGACC + k] = 0.5 * vx[i][k] * dt2
            lam_dyn[I_ACC + i, I_W_ANGACC + k] = 0.5 * ax[i][k] * dt2
    # attitude row: θ' = θ + C(θ)ωΔt
    sg, cg = trig[2], trig[3]      # sin γ, cos γ
    cp = trig[1]
    sec2 = 1.0 / (cp * cp)
    sp_c2 = trig[0] / (cp * cp)
    wxv, wzv = om[0], om[2]
    # ∂(C ω)/∂p
    phi_dyn[I_PITCH, I_PITCH] = 1.0
    phi_dyn[I_ROLL, I_PITCH] = (sg * wxv - cg * wzv) * sec2 * dt
    phi_dyn[I_HEADING, I_PITCH] = (sg * wxv - cg * wzv) * sp_c2 * dt
    # ∂(C ω)/∂γ
    phi_dyn[I_PITCH, I_ROLL] = (-sg * wxv + cg * wzv) * dt
    phi_dyn[I_ROLL, I_ROLL] = 1.0 + (cg * wxv + sg * wzv) * tp * dt
    phi_dyn[I_HEADING, I_ROLL] = (cg * wxv + sg * wzv) / cp * dt
    for i in range(3):
        for k in range(3):
            phi_dyn[I_ATT + i, I_RATE + k] = cr[i][k] * dt
            lam_dyn[I_ATT + i, I_W_ANGACC + k] = 0.5 * cr[i][k] * dt2
        lam_dyn[I_RATE + i, I_W_ANGACC + i] = dt


@njit(cache=True, inline="always")
def drift_decay(dt, inv_tau):
    """φ = e^{−Δt/τ} of a drift state (1 for a random walk, inv_tau = 1/τ = 0; 1/s)."""
    return np.exp(-dt * inv_tau) if inv_tau > 0.0 else 1.0


@njit(cache=True, inline="always")
def drift_noise_variance(q, dt, inv_tau):
    """Per-step variance of a drift state's noise w_b over dt s from its spectral density
    q (unit²/s): q Δt for a random walk (inv_tau = 0), q (1 − e^{−2Δt/τ}) τ/2 for a
    Gauss-Markov state (= σ²(1 − e^{−2Δt/τ}) with q = 2σ²/τ)."""
    if inv_tau > 0.0:
        return q * (-np.expm1(-2.0 * dt * inv_tau)) * 0.5 / inv_tau
    return q * dt


@njit(cache=True, inline="always")
def decay_drift_states_into(x, p, dt, inv_tau, n_imu):
    """The Gauss-Markov part of x' = f(x) and P' = Φ P Φᵀ: with Φ = Φ_dyn-block ·
    diag(1, …, φ_i, …) (the two commute, the drift block of the kinematic Φ being I),
    x_b ← φ x_b and row and column b of P scaled by φ_b. inv_tau: (n_imu − 15,) 1/τ per
    drift state (0 = random walk: untouched). p may be an empty (0, 0) array (state only)."""
    n = p.shape[0]
    for i in range(n_imu - N_DYNAMIC):
        if inv_tau[i] > 0.0:
            d = np.exp(-dt * inv_tau[i])
            s = N_DYNAMIC + i
            x[s] *= d
            for j in range(n):
                p[s, j] *= d
                p[j, s] *= d


@njit(cache=True)
def propagate_state_gm_into(x, w, dt, n_imu, inv_tau, out):
    """x_{k+1} = f(x_k, w_k) with Gauss-Markov drift states: b' = e^{−Δt/τ} b + w_b."""
    propagate_state_into(x, w, dt, n_imu, out)
    for i in range(n_imu - N_DYNAMIC):
        s = N_DYNAMIC + i
        out[s] -= (1.0 - drift_decay(dt, inv_tau[i])) * x[s]


def transition_jacobians(x, dt, drift_inv_tau=None):
    """Full Φ (n×n) and Λ (n×n_noise) for a 21- or 27-state x (testing/analysis helper).
    drift_inv_tau: (n_imu − 15,) 1/τ of Gauss-Markov drift states (None: random walks)."""
    from gmis.state import n_noise_for
    n = x.shape[0]
    nw = n_noise_for(n)
    phi_dyn = np.empty((N_DYNAMIC, N_DYNAMIC))
    lam_dyn = np.empty((N_DYNAMIC, N_KINEMATIC_NOISE))
    transition_jacobians_into(np.ascontiguousarray(x, dtype=np.float64), dt, phi_dyn, lam_dyn)
    phi = np.eye(n)
    phi[:N_DYNAMIC, :N_DYNAMIC] = phi_dyn
    lam = np.zeros((n, nw))
    lam[:N_DYNAMIC, :N_KINEMATIC_NOISE] = lam_dyn
    for i in range(nw - N_KINEMATIC_NOISE):
        lam[N_DYNAMIC + i, I_W_DRIFT + i] = 1.0
        if drift_inv_tau is not None:
            phi[N_DYNAMIC + i, N_DYNAMIC + i] = drift_decay(dt, float(drift_inv_tau[i]))
    return phi, lam
