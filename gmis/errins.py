"""Conventional loosely coupled INS/GNSS: strapdown mechanization + 15-state error-state EKF
("ErrINSEKF", 001 §2.4 and §2.6.4.3, eq. 2.6.14-2.6.20), the baseline the GMIKF is
compared against (001 §4.2.2, §4.3.5).

Mechanization (001 §2.4) in gmis' earth-fixed ENU tangent frame n (see gmis.earth). In the
local-level form of 001 eq. 2.4.1/2.4.2 the n frame turns at ω_in^n = ω_ie^n + ω_en^n; in
our frame, fixed to the earth at the origin, ω_en^n ≡ 0, so ω_in^n = ω_ie^n (constant) and
the gravity vector g^n(r) carries the position dependence instead (normal gravity along the
local ellipsoid normal, evaluated exactly). With the IMU model of gmis.imu_model
(ω_ib = ω_nb + C_n^b ω_ie, f = C_n^b (r̈ + 2 ω_ie×v − g)) one IMU interval Δt reads

    C_b^n(k+1) = Exp(−ω_ie Δt) C_b^n(k) Exp(ω̂_ib Δt)              (2.4.2, two-step DCM)
    v^n(k+1)   = v^n(k) + [½(C(k)+C(k+1)) f̂ − 2 ω_ie×v^n(k) + g(r(k))] Δt   (2.4.3-2.4.5)
    r^n(k+1)   = r^n(k) + ½ (v^n(k) + v^n(k+1)) Δt                           (2.4.6)

with ω̂_ib = ω_imu − b̂_ω, f̂ = f_imu − b̂_a and, over [t_k, t_k+1], the mean of the two
rate samples (trapezoid; coning/sculling corrections are omitted, < 1e-6 rad per step at
100 Hz for road-vehicle dynamics). Aiding-only epochs between IMU samples are reached by
holding the last IMU sample.

Error state (phi-angle convention, 001 §2.6.4.3), estimate minus truth:
    δx = [δr^n (m), δv^n (m/s), φ (rad, ENU), δb_ω (rad/s), δb_a (m/s²)]
    r̂ = r + δr,  v̂ = v + δv,  Ĉ_b^n = (I − [φ×]) C_b^n,  b̂ = b + δb
Linearising the mechanization (2.6.14-2.6.18 with ω_en = 0, δω_ie = 0, δg = ∂g/∂r δr):
    δṙ = δv
    δv̇ = (∂g/∂r) δr − 2[ω_ie×] δv + [f^n×] φ − C δb_a + C n_a
    φ̇  = −[ω_ie×] φ + C δb_ω − C n_ω
    δḃ = −δb/τ − w_b         (τ = ∞: random walk, the default; finite τ: first-order
                              Gauss-Markov, per axis; b_{k+1} = e^{−Δt/τ} b_k + w with the
                              density q = 2σ²/τ of a stationary 1σ σ: var(w) ≈ σ²(1 − e^{−2Δt/τ}))
Discretised with Φ = I + FΔt + (FΔt)²/2 and Q_d = ½(Φ G Q_c Gᵀ Φᵀ + G Q_c Gᵀ) Δt, where
the white-noise spectral densities follow from the per-sample σ of the IMU (Table 4-3
note: σ = RW/√δt ⇒ q = σ² δt) and the bias drift from the per-step σ = BS √(δt/T)
(q = σ²/δt = BS²/T).

Measurements (loosely coupled, eq. 2.6.19/2.6.20 written as z − h(x̂) = H δx + ε, H the
derivative of h at the corrected state x̂ ⊖ δx, lever arm L^b):
    GNSS position  r_ant = r + C L
    GNSS velocity  v_ant = v + C (ω_ib × L) − ω_ie × (C L)
    heading        ψ = atan2(C_01, C_11)
Updates are processed row by row (diagonal R) with a z-test per row, then fed back
(closed loop): r −= δr, v −= δv, C ← Exp(φ) C, b −= δb, δx ← 0.

The epoch loop is numba-compiled (cache=True) and allocates nothing per epoch.
"""

from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import stats

from gmis.dense import mat3_mul_into, mat_mul_into, mat_mul_transposed_into
from gmis.filter_defaults import OUTLIER_ALPHA
from gmis.frames import dcm_body_to_nav, euler_from_dcm, skew_block_into
from gmis.gravity import gravity_nav_into
from gmis.state import (
    ATT,
    BA,
    BG,
    I_DBA,
    I_DBG,
    I_DR,
    I_DV,
    I_HEADING,
    I_NAV_BA,
    I_NAV_BG,
    I_NAV_C,
    I_NAV_R,
    I_NAV_V,
    I_PHI,
    I_PITCH,
    I_ROLL,
    N_ERR,
    NAV_BA,
    NAV_BG,
    NAV_C,
    NAV_R,
    NAV_SIZE,
    NAV_V,
    POS,
    VEL,
)

N_ROWS = 7     # pos E,N,U, vel E,N,U, heading
ROW_POS, ROW_VEL, ROW_HEADING = 0, 3, 6
REC_R, REC_V, REC_ATT, REC_BG, REC_BA = 0, 3, 6, 9, 12   # columns of ErrInsRecords.nav
ROW_NAMES = ("pos_e", "pos_n", "pos_u", "vel_e", "vel_n", "vel_u", "heading")


# ------------------------------------------------------------------ small numba helpers


@njit(cache=True)
def _rodrigues_into(px, py, pz, out):
    """Exp([φ×]) for φ = (px, py, pz) rad (001 eq. 4.1.22)."""
    a2 = px * px + py * py + pz * pz
    if a2 < 1e-16:
        s = 1.0 - a2 / 6.0
        c = 0.5 - a2 / 24.0
    else:
        a = math.sqrt(a2)
        s = math.sin(a) / a
        c = (1.0 - math.cos(a)) / a2
    out[0, 0] = 1.0 - c * (py * py + pz * pz)
    out[0, 1] = -s * pz + c * px * py
    out[0, 2] = s * py + c * px * pz
    out[1, 0] = s * pz + c * px * py
    out[1, 1] = 1.0 - c * (px * px + pz * pz)
    out[1, 2] = -s * px + c * py * pz
    out[2, 0] = -s * py + c * px * pz
    out[2, 1] = s * px + c * py * pz
    out[2, 2] = 1.0 - c * (px * px + py * py)


@njit(cache=True)
def _load_c(nav, c):
    for i in range(3):
        for j in range(3):
            c[i, j] = nav[I_NAV_C + 3 * i + j]


@njit(cache=True)
def _store_c(c, nav):
    for i in range(3):
        for j in range(3):
            nav[I_NAV_C + 3 * i + j] = c[i, j]


# ------------------------------------------------------------------ mechanization


@njit(cache=True)
def mechanize_into(nav, wx, wy, wz, fx, fy, fz, dt, frame, work3, g, dg):
    """One strapdown step of dt s with the bias-corrected mean rate (rad/s) and specific
    force (m/s²) over the interval (eq. 2.4.2-2.4.6 in the earth-fixed ENU frame).
    work3: (4, 3, 3) scratch; g (3,), dg (3, 3) scratch."""
    w_ie = frame[15:18]
    c_old = work3[0]
    r_b = work3[1]
    r_n = work3[2]
    tmp = work3[3]
    _load_c(nav, c_old)
    _rodrigues_into(wx * dt, wy * dt, wz * dt, r_b)
    _rodrigues_into(-w_ie[0] * dt, -w_ie[1] * dt, -w_ie[2] * dt, r_n)
    mat3_mul_into(c_old, r_b, tmp)
    mat3_mul_into(r_n, tmp, r_b)          # r_b now holds C(k+1)
    gravity_nav_into(frame, nav[I_NAV_R:I_NAV_R + 3], g, dg)
    v0 = nav[I_NAV_V]
    v1 = nav[I_NAV_V + 1]
    v2 = nav[I_NAV_V + 2]
    cor0 = 2.0 * (w_ie[1] * v2 - w_ie[2] * v1)
    cor1 = 2.0 * (w_ie[2] * v0 - w_ie[0] * v2)
    cor2 = 2.0 * (w_ie[0] * v1 - w_ie[1] * v0)
    cor = (cor0, cor1, cor2)
    for i in range(3):
        fn = 0.5 * ((c_old[i, 0] + r_b[i, 0]) * fx + (c_old[i, 1] + r_b[i, 1]) * fy
                    + (c_old[i, 2] + r_b[i, 2]) * fz)
        v_new = nav[I_NAV_V + i] + (fn - cor[i] + g[i]) * dt
        nav[I_NAV_R + i] += 0.5 * (nav[I_NAV_V + i] + v_new) * dt
        nav[I_NAV_V + i] = v_new
    _store_c(r_b, nav)


@njit(cache=True)
def error_state_transition_into(nav, fx, fy, fz, dt, frame, tau_g, tau_a, f_mat, phi,
                                work, dg_scratch, g_scratch):
    """error_state_transition_axes_into with one correlation time per sensor (s, inf =
    random walk; the analysis callers, e.g. gmis.crlb)."""
    tg = np.empty(3)
    ta = np.empty(3)
    tg[:] = tau_g
    ta[:] = tau_a
    error_state_transition_axes_into(nav, fx, fy, fz, dt, frame, tg, ta, f_mat, phi, work,
                                     dg_scratch, g_scratch)


@njit(cache=True)
def error_state_transition_axes_into(nav, fx, fy, fz, dt, frame, tau_g, tau_a, f_mat, phi,
                                     work, dg_scratch, g_scratch):
    """Continuous F (15×15) at the current navigation state for the body specific force
    (fx, fy, fz) m/s² and Φ = I + FΔt + (FΔt)²/2 (into f_mat, phi), its bias diagonal the
    exact e^{−Δt/τ} of the bias decay. tau_g/tau_a: (3,)
    bias correlation times per axis (s, inf = random walk). work: (15, 15) scratch."""
    w_ie = frame[15:18]
    c = nav[I_NAV_C:I_NAV_C + 9]
    gravity_nav_into(frame, nav[I_NAV_R:I_NAV_R + 3], g_scratch, dg_scratch)
    fn0 = c[0] * fx + c[1] * fy + c[2] * fz
    fn1 = c[3] * fx + c[4] * fy + c[5] * fz
    fn2 = c[6] * fx + c[7] * fy + c[8] * fz
    for i in range(N_ERR):
        for j in range(N_ERR):
            f_mat[i, j] = 0.0
    for i in range(3):
        f_mat[I_DR + i, I_DV + i] = 1.0
        for j in range(3):
            f_mat[I_DV + i, I_DR + j] = dg_scratch[i, j]
            f_mat[I_DV + i, I_DBA + j] = -c[3 * i + j]
            f_mat[I_PHI + i, I_DBG + j] = c[3 * i + j]
    skew_block_into(f_mat, I_DV, I_DV, w_ie[0], w_ie[1], w_ie[2], -2.0)    # −2[ω_ie×] δv
    skew_block_into(f_mat, I_PHI, I_PHI, w_ie[0], w_ie[1], w_ie[2], -1.0)  # −[ω_ie×] φ
    skew_block_into(f_mat, I_DV, I_PHI, fn0, fn1, fn2, 1.0)                # [f^n×] φ
    for i in range(3):
        f_mat[I_DBG + i, I_DBG + i] = -1.0 / tau_g[i]
        f_mat[I_DBA + i, I_DBA + i] = -1.0 / tau_a[i]
    mat_mul_into(f_mat, f_mat, work, N_ERR, N_ERR, N_ERR)
    for i in range(N_ERR):
        for j in range(N_ERR):
            phi[i, j] = f_mat[i, j] * dt + 0.5 * work[i, j] * dt * dt
        phi[i, i] += 1.0
    for i in range(3):   # the bias decay exactly (x_b ← e^{−Δt/τ} x_b in predict)
        phi[I_DBG + i, I_DBG + i] = math.exp(-dt / tau_g[i])
        phi[I_DBA + i, I_DBA + i] = math.exp(-dt / tau_a[i])


@njit(cache=True)
def process_noise_into(nav, dt, q_gyro, q_accel, q_bg, q_ba, phi, qd, work, work2):
    """Q_d = ½(Φ M Φᵀ + M), M = G Q_c Gᵀ Δt (spectral densities: q_gyro (rad/s)²·s,
    q_accel (m/s²)²·s, q_bg (rad/s)²/s, q_ba (m/s²)²/s, each (3,))."""
    c = nav[I_NAV_C:I_NAV_C + 9]
    for i in range(N_ERR):
        for j in range(N_ERR):
            work[i, j] = 0.0
    for i in range(3):
        for j in range(3):
            sa = 0.0
            sg = 0.0
            for k in range(3):
                sa += c[3 * i + k] * q_accel[k] * c[3 * j + k]
                sg += c[3 * i + k] * q_gyro[k] * c[3 * j + k]
            work[I_DV + i, I_DV + j] = sa * dt
            work[I_PHI + i, I_PHI + j] = sg * dt
        work[I_DBG + i, I_DBG + i] = q_bg[i] * dt
        work[I_DBA + i, I_DBA + i] = q_ba[i] * dt
    _sandwich_into(phi, work, qd, work2)
    for i in range(N_ERR):
        for j in range(N_ERR):
            qd[i, j] = 0.5 * (qd[i, j] + work[i, j])


@njit(cache=True)
def _sandwich_into(phi, p, out, work):
    """out = Φ P Φᵀ (15×15); work scratch. out must not alias p."""
    mat_mul_into(phi, p, work, N_ERR, N_ERR, N_ERR)
    mat_mul_transposed_into(work, phi, out, N_ERR, N_ERR, N_ERR, True)


@njit(cache=True)
def predict_covariance_into(p, phi, qd, work, work2):
    """P ← Φ P Φᵀ + Q_d."""
    _sandwich_into(phi, p, work2, work)
    for i in range(N_ERR):
        for j in range(N_ERR):
            p[i, j] = work2[i, j] + qd[i, j]


# ------------------------------------------------------------------ measurement models


@njit(cache=True)
def position_rows_into(nav, lever, h_out, jac, row0):
    """r_ant = r + C L (m) and H = ∂h(x̂ ⊖ δx)/∂δx rows (3)."""
    c = nav[I_NAV_C:I_NAV_C + 9]
    for i in range(3):
        cl_i = c[3 * i] * lever[0] + c[3 * i + 1] * lever[1] + c[3 * i + 2] * lever[2]
        h_out[row0 + i] = nav[I_NAV_R + i] + cl_i
        for j in range(N_ERR):
            jac[row0 + i, j] = 0.0
        jac[row0 + i, I_DR + i] = -1.0
    cl0 = c[0] * lever[0] + c[1] * lever[1] + c[2] * lever[2]
    cl1 = c[3] * lever[0] + c[4] * lever[1] + c[5] * lever[2]
    cl2 = c[6] * lever[0] + c[7] * lever[1] + c[8] * lever[2]
    skew_block_into(jac, row0, I_PHI, cl0, cl1, cl2, -1.0)   # −[(C L)×]


@njit(cache=True)
def velocity_rows_into(nav, w_ib, lever, frame, h_out, jac, row0):
    """v_ant = v + C(ω_ib×L) − ω_ie×(C L) (m/s), ω_ib the bias-corrected gyro rate (rad/s),
    and its H rows (3)."""
    c = nav[I_NAV_C:I_NAV_C + 9]
    w_ie = frame[15:18]
    wl0 = w_ib[1] * lever[2] - w_ib[2] * lever[1]
    wl1 = w_ib[2] * lever[0] - w_ib[0] * lever[2]
    wl2 = w_ib[0] * lever[1] - w_ib[1] * lever[0]
    u1_0 = c[0] * wl0 + c[1] * wl1 + c[2] * wl2
    u1_1 = c[3] * wl0 + c[4] * wl1 + c[5] * wl2
    u1_2 = c[6] * wl0 + c[7] * wl1 + c[8] * wl2
    u2_0 = c[0] * lever[0] + c[1] * lever[1] + c[2] * lever[2]
    u2_1 = c[3] * lever[0] + c[4] * lever[1] + c[5] * lever[2]
    u2_2 = c[6] * lever[0] + c[7] * lever[1] + c[8] * lever[2]
    e0 = w_ie[1] * u2_2 - w_ie[2] * u2_1
    e1 = w_ie[2] * u2_0 - w_ie[0] * u2_2
    e2 = w_ie[0] * u2_1 - w_ie[1] * u2_0
    h_out[row0] = nav[I_NAV_V] + u1_0 - e0
    h_out[row0 + 1] = nav[I_NAV_V + 1] + u1_1 - e1
    h_out[row0 + 2] = nav[I_NAV_V + 2] + u1_2 - e2
    for i in range(3):
        for j in range(N_ERR):
            jac[row0 + i, j] = 0.0
        jac[row0 + i, I_DV + i] = -1.0
    # φ: −[u1×] + [ω_ie×][u2×]
    a00 = 0.0
    a01 = u1_2
    a02 = -u1_1
    a10 = -u1_2
    a11 = 0.0
    a12 = u1_0
    a20 = u1_1
    a21 = -u1_0
    a22 = 0.0
    # [w×][u×] = u wᵀ − (w·u) I
    wu = w_ie[0] * u2_0 + w_ie[1] * u2_1 + w_ie[2] * u2_2
    u2 = (u2_0, u2_1, u2_2)
    jac[row0, I_PHI + 0] = a00 + u2[0] * w_ie[0] - wu
    jac[row0, I_PHI + 1] = a01 + u2[0] * w_ie[1]
    jac[row0, I_PHI + 2] = a02 + u2[0] * w_ie[2]
    jac[row0 + 1, I_PHI + 0] = a10 + u2[1] * w_ie[0]
    jac[row0 + 1, I_PHI + 1] = a11 + u2[1] * w_ie[1] - wu
    jac[row0 + 1, I_PHI + 2] = a12 + u2[1] * w_ie[2]
    jac[row0 + 2, I_PHI + 0] = a20 + u2[2] * w_ie[0]
    jac[row0 + 2, I_PHI + 1] = a21 + u2[2] * w_ie[1]
    jac[row0 + 2, I_PHI + 2] = a22 + u2[2] * w_ie[2] - wu
    # δb_ω: −C [L×]
    for i in range(3):
        ci0 = c[3 * i]
        ci1 = c[3 * i + 1]
        ci2 = c[3 * i + 2]
        # row i of C [L×]: [L×] = [[0,-L2,L1],[L2,0,-L0],[-L1,L0,0]]
        jac[row0 + i, I_DBG] = -(ci1 * lever[2] - ci2 * lever[1])
        jac[row0 + i, I_DBG + 1] = -(-ci0 * lever[2] + ci2 * lever[0])
        jac[row0 + i, I_DBG + 2] = -(ci0 * lever[1] - ci1 * lever[0])


@njit(cache=True)
def heading_row_into(nav, h_out, jac, row0):
    """ψ = atan2(C_01, C_11) (rad, azimuth) and its H row."""
    c01 = nav[I_NAV_C + 1]
    c11 = nav[I_NAV_C + 4]
    c21 = nav[I_NAV_C + 7]
    h_out[row0] = math.atan2(c01, c11) % (2.0 * math.pi)
    den = c01 * c01 + c11 * c11
    for j in range(N_ERR):
        jac[row0, j] = 0.0
    jac[row0, I_PHI] = c01 * c21 / den
    jac[row0, I_PHI + 1] = c11 * c21 / den
    jac[row0, I_PHI + 2] = -1.0


@njit(cache=True)
def apply_correction_into(nav, dx, scratch):
    """Closed-loop feedback x̂ ⊖ δx: r −= δr, v −= δv, C ← Exp(φ) C, b −= δb.
    scratch: (4, 3, 3)."""
    for i in range(6):   # r, v
        nav[I_NAV_R + i] -= dx[I_DR + i]
    c = scratch[0]
    rot = scratch[1]
    out = scratch[2]
    _load_c(nav, c)
    _rodrigues_into(dx[I_PHI], dx[I_PHI + 1], dx[I_PHI + 2], rot)
    mat3_mul_into(rot, c, out)
    _store_c(out, nav)
    for i in range(6):   # b_ω, b_a
        nav[I_NAV_BG + i] -= dx[I_DBG + i]


# ------------------------------------------------------------------ the epoch loop

# the IMU sample carried between epochs and chunks: [t_state, have_sample, ω (3), f (3)]
CARRY_T, CARRY_HAVE, CARRY_W, CARRY_F, CARRY_SIZE = 0, 1, 2, 5, 8

ErrInsInputs = namedtuple("ErrInsInputs", (
    "t", "imu_idx", "pos_idx", "vel_idx", "hdg_idx",   # (E,) s; rows or -1
    "imu_z",                                            # (N, 6) rad/s, m/s²
    "pos_z", "pos_sd", "vel_z", "vel_sd",               # (M, 3) m, m/s
    "hdg_z", "hdg_sd"))                                 # (H,) rad
ErrInsSettings = namedtuple("ErrInsSettings", (
    "q_gyro", "q_accel", "q_bg", "q_ba",   # (3,) spectral densities (process_noise_into)
    "tau_g", "tau_a",                      # (3,) bias correlation times, s (inf: random walk)
    "lever", "frame", "z_crit"))
ErrInsRecordArrays = namedtuple("ErrInsRecordArrays", (
    "nav", "sd", "cov_blocks", "innov", "innov_var", "rejected"))
ErrInsWorkspace = namedtuple("ErrInsWorkspace", (
    "f_mat", "phi", "qd", "work", "work2", "work3", "g", "dg", "h_all", "jac", "z_all",
    "r_all", "present", "dx", "ph", "w_ib", "cmat", "rate", "force"))


@njit(cache=True)
def make_errins_workspace():
    return ErrInsWorkspace(
        np.zeros((N_ERR, N_ERR)), np.zeros((N_ERR, N_ERR)), np.zeros((N_ERR, N_ERR)),
        np.zeros((N_ERR, N_ERR)), np.zeros((N_ERR, N_ERR)), np.zeros((4, 3, 3)),
        np.zeros(3), np.zeros((3, 3)), np.zeros(N_ROWS), np.zeros((N_ROWS, N_ERR)),
        np.zeros(N_ROWS), np.zeros(N_ROWS), np.zeros(N_ROWS, dtype=np.bool_),
        np.zeros(N_ERR), np.zeros(N_ERR), np.zeros(3), np.zeros((3, 3)), np.zeros(3),
        np.zeros(3))


@njit(cache=True, inline="always")
def interval_imu_sample(e, inp, carry, nav, ws):
    """Bias-corrected mean rate ω̂ (rad/s) and specific force f̂ (m/s²) over the interval
    ending at epoch e into ws.rate / ws.force: the trapezoid of the held and the new IMU
    sample, or the held sample when e has none."""
    k = inp.imu_idx[e]
    for i in range(3):
        if k >= 0:
            ws.rate[i] = 0.5 * (carry[CARRY_W + i] + inp.imu_z[k, i])
            ws.force[i] = 0.5 * (carry[CARRY_F + i] + inp.imu_z[k, 3 + i])
        else:
            ws.rate[i] = carry[CARRY_W + i]
            ws.force[i] = carry[CARRY_F + i]
        ws.rate[i] -= nav[I_NAV_BG + i]
        ws.force[i] -= nav[I_NAV_BA + i]


@njit(cache=True, inline="always")
def predict(nav, p, dt, cfg, ws):
    """Mechanize over dt s (001 eq. 2.4.2-2.4.6), decay the biases, P ← Φ P Φᵀ + Q_d
    (eq. 2.6.14-2.6.18 discretised)."""
    mechanize_into(nav, ws.rate[0], ws.rate[1], ws.rate[2], ws.force[0], ws.force[1],
                   ws.force[2], dt, cfg.frame, ws.work3, ws.g, ws.dg)
    for i in range(3):
        nav[I_NAV_BG + i] *= math.exp(-dt / cfg.tau_g[i])
        nav[I_NAV_BA + i] *= math.exp(-dt / cfg.tau_a[i])
    error_state_transition_axes_into(nav, ws.force[0], ws.force[1], ws.force[2], dt,
                                     cfg.frame, cfg.tau_g, cfg.tau_a, ws.f_mat, ws.phi,
                                     ws.work, ws.dg, ws.g)
    process_noise_into(nav, dt, cfg.q_gyro, cfg.q_accel, cfg.q_bg, cfg.q_ba, ws.phi, ws.qd,
                       ws.work, ws.work2)
    predict_covariance_into(p, ws.phi, ws.qd, ws.work, ws.work2)


@njit(cache=True, inline="always")
def hold_imu_sample(e, inp, carry):
    """Keep epoch e's IMU sample for the next interval; the first one starts the clock."""
    k = inp.imu_idx[e]
    for i in range(6):
        carry[CARRY_W + i] = inp.imu_z[k, i]
    if carry[CARRY_HAVE] == 0.0:
        carry[CARRY_T] = inp.t[e]
    carry[CARRY_HAVE] = 1.0


@njit(cache=True, inline="always")
def _take_rows(z_src, sd_src, row, row0, ws):
    for i in range(3):
        ws.z_all[row0 + i] = z_src[row, i]
        ws.r_all[row0 + i] = sd_src[row, i] ** 2
        ws.present[row0 + i] = True


@njit(cache=True, inline="always")
def assemble_aiding_rows(e, nav, inp, cfg, carry, ws):
    """z, h(x̂), H and R of the aiding present at epoch e (eq. 2.6.19/2.6.20): GNSS
    position (rows 0-2), velocity (3-5), heading (6)."""
    for i in range(N_ROWS):
        ws.present[i] = False
    if carry[CARRY_HAVE] == 0.0:
        return
    for i in range(3):
        ws.w_ib[i] = carry[CARRY_W + i] - nav[I_NAV_BG + i]
    if inp.pos_idx[e] >= 0:
        position_rows_into(nav, cfg.lever, ws.h_all, ws.jac, ROW_POS)
        _take_rows(inp.pos_z, inp.pos_sd, inp.pos_idx[e], ROW_POS, ws)
    if inp.vel_idx[e] >= 0:
        velocity_rows_into(nav, ws.w_ib, cfg.lever, cfg.frame, ws.h_all, ws.jac, ROW_VEL)
        _take_rows(inp.vel_z, inp.vel_sd, inp.vel_idx[e], ROW_VEL, ws)
    if inp.hdg_idx[e] >= 0:
        heading_row_into(nav, ws.h_all, ws.jac, ROW_HEADING)
        ws.z_all[ROW_HEADING] = inp.hdg_z[inp.hdg_idx[e]]
        ws.r_all[ROW_HEADING] = inp.hdg_sd[inp.hdg_idx[e]] ** 2
        ws.present[ROW_HEADING] = True


@njit(cache=True, inline="always")
def sequential_update(e, p, z_crit, ws, rec):
    """Scalar EKF updates row by row (R diagonal) with a z-test per row; the error-state
    estimate accumulates in ws.dx. Returns True when any row was used."""
    any_update = False
    for i in range(N_ERR):
        ws.dx[i] = 0.0
    for row in range(N_ROWS):
        rec.innov[e, row] = np.nan
        rec.innov_var[e, row] = np.nan
        rec.rejected[e, row] = 0
        if not ws.present[row]:
            continue
        d = ws.z_all[row] - ws.h_all[row]
        if row == ROW_HEADING:
            d = (d + math.pi) % (2.0 * math.pi) - math.pi
        for j in range(N_ERR):
            d -= ws.jac[row, j] * ws.dx[j]
        for i in range(N_ERR):
            s = 0.0
            for j in range(N_ERR):
                s += p[i, j] * ws.jac[row, j]
            ws.ph[i] = s
        s_var = ws.r_all[row]
        for j in range(N_ERR):
            s_var += ws.jac[row, j] * ws.ph[j]
        rec.innov[e, row] = d
        rec.innov_var[e, row] = s_var
        if abs(d) > z_crit * math.sqrt(s_var):
            rec.rejected[e, row] = 1
            continue
        for i in range(N_ERR):
            ws.dx[i] += ws.ph[i] / s_var * d
        for i in range(N_ERR):
            for j in range(i, N_ERR):
                p[i, j] -= ws.ph[i] * ws.ph[j] / s_var
                p[j, i] = p[i, j]
        any_update = True
    return any_update


@njit(cache=True, inline="always")
def record_nav(e, nav, p, ws, rec):
    """r, v^n, Euler θ (001 eq. 2.2.5), b_ω, b_a; √diag P; δr, δv, φ covariance blocks."""
    for i in range(6):
        rec.nav[e, REC_R + i] = nav[I_NAV_R + i]
    _load_c(nav, ws.cmat)
    sp = min(1.0, max(-1.0, ws.cmat[2, 1]))
    rec.nav[e, REC_ATT] = math.asin(sp)
    rec.nav[e, REC_ATT + 1] = math.atan2(-ws.cmat[2, 0], ws.cmat[2, 2])
    rec.nav[e, REC_ATT + 2] = math.atan2(ws.cmat[0, 1], ws.cmat[1, 1]) % (2.0 * math.pi)
    for i in range(6):
        rec.nav[e, REC_BG + i] = nav[I_NAV_BG + i]
    for i in range(N_ERR):
        rec.sd[e, i] = math.sqrt(max(p[i, i], 0.0))
    for b in range(3):
        for i in range(3):
            for j in range(3):
                rec.cov_blocks[e, b, i, j] = p[3 * b + i, 3 * b + j]


@njit(cache=True)
def errins_chunk(e0, e1, inp, cfg, nav, p, carry, rec):
    """Run epochs [e0, e1) of the ErrINSEKF (inputs ``inp``: ErrInsInputs, settings
    ``cfg``: ErrInsSettings, records ``rec``: ErrInsRecordArrays). nav (21,) and p (15, 15)
    are updated in place; carry (CARRY_SIZE,) holds the last IMU sample between chunks.
    Records per epoch after the update: nav (E, 15) = r, v^n, Euler θ, b_ω, b_a;
    sd (E, 15) = √diag P; cov_blocks (E, 3, 3, 3) of δr, δv, φ; innovations (E, 7) and
    their variances, NaN when absent; rejected (E, 7) z-test flags."""
    ws = make_errins_workspace()
    for e in range(e0, e1):
        if carry[CARRY_HAVE] > 0.0:
            dt = inp.t[e] - carry[CARRY_T]
            if dt > 0.0:
                interval_imu_sample(e, inp, carry, nav, ws)
                predict(nav, p, dt, cfg, ws)
            carry[CARRY_T] = inp.t[e]
        if inp.imu_idx[e] >= 0:
            hold_imu_sample(e, inp, carry)
        assemble_aiding_rows(e, nav, inp, cfg, carry, ws)
        if sequential_update(e, p, cfg.z_crit, ws, rec):
            apply_correction_into(nav, ws.dx, ws.work3)
        record_nav(e, nav, p, ws, rec)


# ------------------------------------------------------------------ Python driver


@dataclass
class ErrInsConfig:
    """ErrINSEKF settings (SI, rad). imu_sd: per-sample white-noise 1σ [gyro(3) rad/s,
    accel(3) m/s²] at imu_rate_hz; bias_drift_sd: per-step 1σ [b_ω(3) rad/s, b_a(3) m/s²]
    (= BS √(δt/T), 001 Table 4-3; for a Gauss-Markov bias of stationary 1σ σ the driving
    σ√(2δt/τ)); bias_tau_s: correlation times (s, inf = random walk), (gyro, accel) or per
    axis (gyro x y z, accel x y z); p0_sd: (15,) initial 1σ of δr, δv, φ, δb_ω, δb_a."""
    imu_sd: np.ndarray
    bias_drift_sd: np.ndarray
    imu_rate_hz: float
    p0_sd: np.ndarray
    lever_arm: np.ndarray
    bias_tau_s: tuple = (math.inf, math.inf)
    outlier_alpha: float = OUTLIER_ALPHA
    chunk: int = 50000

    def __post_init__(self):
        self.imu_sd = np.asarray(self.imu_sd, float).reshape(6)
        self.bias_drift_sd = np.asarray(self.bias_drift_sd, float).reshape(6)
        self.p0_sd = np.asarray(self.p0_sd, float).reshape(N_ERR)
        self.lever_arm = np.asarray(self.lever_arm, float).reshape(3)
        if not self.imu_rate_hz > 0:
            raise ValueError("imu_rate_hz must be > 0")
        tau = np.asarray(self.bias_tau_s, float).ravel()
        if tau.size == 2:
            tau = np.repeat(tau, 3)
        if tau.size != 6 or not np.all(tau > 0):
            raise ValueError(f"bias_tau_s: 2 or 6 values > 0 (inf = random walk), got "
                             f"{self.bias_tau_s}")
        self.bias_tau_s = tau

    def spectral_densities(self):
        """(q_gyro, q_accel, q_bg, q_ba): white noise q = σ² δt, bias drift q = σ²/δt."""
        dt = 1.0 / self.imu_rate_hz
        return (self.imu_sd[:3] ** 2 * dt, self.imu_sd[3:] ** 2 * dt,
                self.bias_drift_sd[:3] ** 2 / dt, self.bias_drift_sd[3:] ** 2 / dt)


def nav_state(r_enu, v_enu, euler, gyro_bias=(0, 0, 0), accel_bias=(0, 0, 0)):
    """Pack the navigation state (21,): r^n, v^n, C_b^n(θ) row-major, b_ω, b_a."""
    nav = np.zeros(NAV_SIZE)
    nav[NAV_R] = r_enu
    nav[NAV_V] = v_enu
    nav[NAV_C] = dcm_body_to_nav(float(euler[0]), float(euler[1]), float(euler[2])).ravel()
    nav[NAV_BG] = gyro_bias
    nav[NAV_BA] = accel_bias
    return nav


def nav_from_gmikf_state(x):
    """The ErrINSEKF's start from a GMIKF state vector (same r, v^n = C v^b, θ, b)."""
    x = np.asarray(x, float)
    c = dcm_body_to_nav(x[I_PITCH], x[I_ROLL], x[I_HEADING])
    return nav_state(x[POS], c @ x[VEL], x[ATT], x[BG], x[BA])


@dataclass
class ErrInsRecords:
    t: np.ndarray
    nav: np.ndarray          # (E, 15) r^n, v^n, θ, b_ω, b_a after the update
    sd: np.ndarray           # (E, 15) 1σ of δr, δv, φ, δb_ω, δb_a
    cov_blocks: np.ndarray   # (E, 3, 3, 3) covariance of δr, δv, φ
    innov: np.ndarray        # (E, 7)
    innov_var: np.ndarray    # (E, 7)
    rejected: np.ndarray     # (E, 7) int8
    imu_row: np.ndarray      # (E,)


def run_errins(epochs, meas, nav0, config: ErrInsConfig, frame, progress=None):
    """Run the ErrINSEKF over an EpochIndex + Measurements (gmis.run_filter) from nav0."""
    e_total = len(epochs)
    nav = np.array(nav0, float)
    p = np.diag(config.p0_sd ** 2)
    carry = np.zeros(CARRY_SIZE)
    carry[CARRY_T] = np.nan
    qg, qa, qbg, qba = config.spectral_densities()
    z_crit = (float(stats.norm.ppf(1 - config.outlier_alpha / 2))
              if config.outlier_alpha > 0 else np.inf)
    rec = ErrInsRecords(t=epochs.t, nav=np.empty((e_total, 15)), sd=np.empty((e_total, 15)),
                        cov_blocks=np.empty((e_total, 3, 3, 3)),
                        innov=np.empty((e_total, N_ROWS)), innov_var=np.empty((e_total, N_ROWS)),
                        rejected=np.zeros((e_total, N_ROWS), np.int8), imu_row=epochs.imu)
    f64 = lambda a, shape: np.ascontiguousarray(a, dtype=float).reshape(shape)
    inp = ErrInsInputs(epochs.t, epochs.imu, epochs.pos, epochs.vel, epochs.heading,
                       f64(meas.imu_z, (-1, 6)), f64(meas.pos_enu, (-1, 3)),
                       f64(meas.pos_sd, (-1, 3)), f64(meas.vel_enu, (-1, 3)),
                       f64(meas.vel_sd, (-1, 3)), f64(meas.heading, (-1,)),
                       f64(meas.heading_sd, (-1,)))
    cfg = ErrInsSettings(qg, qa, qbg, qba, config.bias_tau_s[:3].copy(),
                         config.bias_tau_s[3:].copy(), config.lever_arm,
                         np.asarray(frame, float), float(z_crit))
    rec_arrays = ErrInsRecordArrays(rec.nav, rec.sd, rec.cov_blocks, rec.innov,
                                    rec.innov_var, rec.rejected)
    for e0 in range(0, e_total, config.chunk):
        e1 = min(e_total, e0 + config.chunk)
        errins_chunk(e0, e1, inp, cfg, nav, p, carry, rec_arrays)
        if progress is not None:
            progress(e1 / e_total)
    return rec


def run_errins_prepared(prep, config: ErrInsConfig | None = None, progress=None):
    """ErrINSEKF on a gmis.pipeline.PreparedRun, started from the same x0 as the GMIKF."""
    cfg = config or prep.errins_config()
    return run_errins(prep.epochs, prep.meas, nav_from_gmikf_state(prep.x0), cfg, prep.frame,
                      progress=progress)


# ------------------------------------------------------------------ analysis helpers


def error_state_transition(nav, f_b, dt, frame, bias_tau_s=(math.inf, math.inf)):
    """(F, Φ) at nav for body specific force f_b (m/s², bias-corrected); bias_tau_s:
    (gyro, accel) or 6 per-axis correlation times (s)."""
    tau = np.asarray(bias_tau_s, float).ravel()
    tau = np.repeat(tau, 3) if tau.size == 2 else tau
    f_mat = np.zeros((N_ERR, N_ERR))
    phi = np.zeros((N_ERR, N_ERR))
    error_state_transition_axes_into(np.asarray(nav, float), float(f_b[0]), float(f_b[1]),
                                     float(f_b[2]), dt, np.asarray(frame, float),
                                     tau[:3].copy(), tau[3:].copy(), f_mat, phi,
                                     np.zeros((N_ERR, N_ERR)), np.zeros((3, 3)), np.zeros(3))
    return f_mat, phi


def mechanize(nav, w_b, f_b, dt, frame):
    """One mechanization step (copy): bias-corrected mean rate w_b, specific force f_b."""
    out = np.array(nav, float)
    mechanize_into(out, float(w_b[0]), float(w_b[1]), float(w_b[2]), float(f_b[0]),
                   float(f_b[1]), float(f_b[2]), dt, np.asarray(frame, float),
                   np.zeros((4, 3, 3)), np.zeros(3), np.zeros((3, 3)))
    return out


def apply_correction(nav, dx):
    out = np.array(nav, float)
    apply_correction_into(out, np.asarray(dx, float), np.zeros((4, 3, 3)))
    return out


def attitude_error(c_est, c_true):
    """φ (rad) with Ĉ = (I − [φ×]) C to first order, i.e. C = Exp(φ) Ĉ: φ = log(C Ĉᵀ)."""
    m = np.asarray(c_true) @ np.asarray(c_est).T
    cos_a = np.clip((np.trace(m) - 1.0) / 2.0, -1.0, 1.0)
    a = math.acos(cos_a)
    v = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]) / 2.0
    return v if a < 1e-12 else v * (a / math.sin(a))


def nav_dcm(nav):
    return np.asarray(nav, float)[NAV_C].reshape(3, 3).copy()


def euler_of(nav):
    return euler_from_dcm(nav_dcm(nav))


__all__ = [
    "N_ERR",
    "ROW_NAMES",
    "ErrInsConfig",
    "ErrInsRecords",
    "apply_correction",
    "attitude_error",
    "errins_chunk",
    "error_state_transition",
    "heading_row_into",
    "mechanize",
    "nav_from_gmikf_state",
    "nav_state",
    "position_rows_into",
    "predict_covariance_into",
    "process_noise_into",
    "run_errins",
    "run_errins_prepared",
    "velocity_rows_into",
]
