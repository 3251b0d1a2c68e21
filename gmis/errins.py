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
    δḃ = −δb/τ − w_b         (τ = ∞: random walk, the default; finite τ: Gauss-Markov)
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
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import stats

from gmis.earth import ecef_to_geodetic, normal_gravity, WGS84_A
from gmis.filter_defaults import OUTLIER_ALPHA
from gmis.frames import dcm_body_to_nav, euler_from_dcm

N_ERR = 15
I_DR, I_DV, I_PHI, I_DBG, I_DBA = 0, 3, 6, 9, 12
NAV_SIZE = 21  # r(3) v^n(3) C_b^n row-major(9) b_ω(3) b_a(3)
N_ROWS = 7     # pos E,N,U, vel E,N,U, heading
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
def _mat3_mul_into(a, b, out):
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]


@njit(cache=True)
def _load_c(nav, c):
    for i in range(3):
        for j in range(3):
            c[i, j] = nav[6 + 3 * i + j]


@njit(cache=True)
def _store_c(c, nav):
    for i in range(3):
        for j in range(3):
            nav[6 + 3 * i + j] = c[i, j]


@njit(cache=True)
def gravity_and_gradient_into(frame, r, g_out, dg_out):
    """Normal gravity g^n(r) (m/s²) and ∂g/∂r (1/s²) without heap allocation; the same
    model as gmis.earth.gravity_nav_into (tested equal)."""
    c = frame[6:15]
    ex = frame[3] + c[0] * r[0] + c[3] * r[1] + c[6] * r[2]
    ey = frame[4] + c[1] * r[0] + c[4] * r[1] + c[7] * r[2]
    ez = frame[5] + c[2] * r[0] + c[5] * r[1] + c[8] * r[2]
    lat, lon, h = ecef_to_geodetic(ex, ey, ez)
    g = normal_gravity(lat, h)
    u0e = math.cos(lat) * math.cos(lon)
    u1e = math.cos(lat) * math.sin(lon)
    u2e = math.sin(lat)
    k = g / (WGS84_A + h)
    for i in range(3):
        ui = c[3 * i] * u0e + c[3 * i + 1] * u1e + c[3 * i + 2] * u2e
        g_out[i] = -g * ui
    for i in range(3):
        ui = -g_out[i] / g
        for j in range(3):
            uj = -g_out[j] / g
            dg_out[i, j] = k * (3.0 * ui * uj - (1.0 if i == j else 0.0))


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
    _mat3_mul_into(c_old, r_b, tmp)
    _mat3_mul_into(r_n, tmp, r_b)          # r_b now holds C(k+1)
    gravity_and_gradient_into(frame, nav[0:3], g, dg)
    v0 = nav[3]
    v1 = nav[4]
    v2 = nav[5]
    cor0 = 2.0 * (w_ie[1] * v2 - w_ie[2] * v1)
    cor1 = 2.0 * (w_ie[2] * v0 - w_ie[0] * v2)
    cor2 = 2.0 * (w_ie[0] * v1 - w_ie[1] * v0)
    cor = (cor0, cor1, cor2)
    for i in range(3):
        fn = 0.5 * ((c_old[i, 0] + r_b[i, 0]) * fx + (c_old[i, 1] + r_b[i, 1]) * fy
                    + (c_old[i, 2] + r_b[i, 2]) * fz)
        v_new = nav[3 + i] + (fn - cor[i] + g[i]) * dt
        nav[i] += 0.5 * (nav[3 + i] + v_new) * dt
        nav[3 + i] = v_new
    _store_c(r_b, nav)


@njit(cache=True)
def error_state_transition_into(nav, fx, fy, fz, dt, frame, tau_g, tau_a, f_mat, phi,
                                work, dg_scratch, g_scratch):
    """Continuous F (15×15) at the current navigation state for the body specific force
    (fx, fy, fz) m/s² and Φ = I + FΔt + (FΔt)²/2 (into f_mat, phi). tau_g/tau_a: bias
    correlation times (s, inf = random walk). work: (15, 15) scratch."""
    w_ie = frame[15:18]
    c = nav[6:15]
    gravity_and_gradient_into(frame, nav[0:3], g_scratch, dg_scratch)
    fn0 = c[0] * fx + c[1] * fy + c[2] * fz
    fn1 = c[3] * fx + c[4] * fy + c[5] * fz
    fn2 = c[6] * fx + c[7] * fy + c[8] * fz
    for i in range(N_ERR):
        for j in range(N_ERR):
            f_mat[i, j] = 0.0
    for i in range(3):
        f_mat[i, 3 + i] = 1.0
        for j in range(3):
            f_mat[3 + i, j] = dg_scratch[i, j]
            f_mat[3 + i, 12 + j] = -c[3 * i + j]
            f_mat[6 + i, 9 + j] = c[3 * i + j]
    # −2[ω_ie×] and −[ω_ie×]
    f_mat[3, 4] = 2.0 * w_ie[2]
    f_mat[3, 5] = -2.0 * w_ie[1]
    f_mat[4, 3] = -2.0 * w_ie[2]
    f_mat[4, 5] = 2.0 * w_ie[0]
    f_mat[5, 3] = 2.0 * w_ie[1]
    f_mat[5, 4] = -2.0 * w_ie[0]
    f_mat[6, 7] = w_ie[2]
    f_mat[6, 8] = -w_ie[1]
    f_mat[7, 6] = -w_ie[2]
    f_mat[7, 8] = w_ie[0]
    f_mat[8, 6] = w_ie[1]
    f_mat[8, 7] = -w_ie[0]
    # [f^n×]
    f_mat[3, 7] = -fn2
    f_mat[3, 8] = fn1
    f_mat[4, 6] = fn2
    f_mat[4, 8] = -fn0
    f_mat[5, 6] = -fn1
    f_mat[5, 7] = fn0
    for i in range(3):
        f_mat[9 + i, 9 + i] = -1.0 / tau_g
        f_mat[12 + i, 12 + i] = -1.0 / tau_a
    for i in range(N_ERR):
        for j in range(N_ERR):
            s = 0.0
            for k in range(N_ERR):
                s += f_mat[i, k] * f_mat[k, j]
            work[i, j] = s
    for i in range(N_ERR):
        for j in range(N_ERR):
            phi[i, j] = f_mat[i, j] * dt + 0.5 * work[i, j] * dt * dt
        phi[i, i] += 1.0


@njit(cache=True)
def process_noise_into(nav, dt, q_gyro, q_accel, q_bg, q_ba, phi, qd, work, work2):
    """Q_d = ½(Φ M Φᵀ + M), M = G Q_c Gᵀ Δt (spectral densities: q_gyro (rad/s)²·s,
    q_accel (m/s²)²·s, q_bg (rad/s)²/s, q_ba (m/s²)²/s, each (3,))."""
    c = nav[6:15]
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
            work[3 + i, 3 + j] = sa * dt
            work[6 + i, 6 + j] = sg * dt
        work[9 + i, 9 + i] = q_bg[i] * dt
        work[12 + i, 12 + i] = q_ba[i] * dt
    _sandwich_into(phi, work, qd, work2)
    for i in range(N_ERR):
        for j in range(N_ERR):
            qd[i, j] = 0.5 * (qd[i, j] + work[i, j])


@njit(cache=True)
def _sandwich_into(phi, p, out, work):
    """out = Φ P Φᵀ (15×15); work scratch. out must not alias p."""
    for i in range(N_ERR):
        for j in range(N_ERR):
            s = 0.0
            for k in range(N_ERR):
                s += phi[i, k] * p[k, j]
            work[i, j] = s
    for i in range(N_ERR):
        for j in range(i, N_ERR):
            s = 0.0
            for k in range(N_ERR):
                s += work[i, k] * phi[j, k]
            out[i, j] = s
            out[j, i] = s


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
    c = nav[6:15]
    for i in range(3):
        cl_i = c[3 * i] * lever[0] + c[3 * i + 1] * lever[1] + c[3 * i + 2] * lever[2]
        h_out[row0 + i] = nav[i] + cl_i
        for j in range(N_ERR):
            jac[row0 + i, j] = 0.0
        jac[row0 + i, i] = -1.0
    cl0 = c[0] * lever[0] + c[1] * lever[1] + c[2] * lever[2]
    cl1 = c[3] * lever[0] + c[4] * lever[1] + c[5] * lever[2]
    cl2 = c[6] * lever[0] + c[7] * lever[1] + c[8] * lever[2]
    # −[(C L)×]
    jac[row0, 7] = cl2
    jac[row0, 8] = -cl1
    jac[row0 + 1, 6] = -cl2
    jac[row0 + 1, 8] = cl0
    jac[row0 + 2, 6] = cl1
    jac[row0 + 2, 7] = -cl0


@njit(cache=True)
def velocity_rows_into(nav, w_ib, lever, frame, h_out, jac, row0):
    """v_ant = v + C(ω_ib×L) − ω_ie×(C L) (m/s), ω_ib the bias-corrected gyro rate (rad/s),
    and its H rows (3)."""
    c = nav[6:15]
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
    h_out[row0] = nav[3] + u1_0 - e0
    h_out[row0 + 1] = nav[4] + u1_1 - e1
    h_out[row0 + 2] = nav[5] + u1_2 - e2
    for i in range(3):
        for j in range(N_ERR):
            jac[row0 + i, j] = 0.0
        jac[row0 + i, 3 + i] = -1.0
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
    jac[row0, 6] = a00 + u2[0] * w_ie[0] - wu
    jac[row0, 7] = a01 + u2[0] * w_ie[1]
    jac[row0, 8] = a02 + u2[0] * w_ie[2]
    jac[row0 + 1, 6] = a10 + u2[1] * w_ie[0]
    jac[row0 + 1, 7] = a11 + u2[1] * w_ie[1] - wu
    jac[row0 + 1, 8] = a12 + u2[1] * w_ie[2]
    jac[row0 + 2, 6] = a20 + u2[2] * w_ie[0]
    jac[row0 + 2, 7] = a21 + u2[2] * w_ie[1]
    jac[row0 + 2, 8] = a22 + u2[2] * w_ie[2] - wu
    # δb_ω: −C [L×]
    for i in range(3):
        ci0 = c[3 * i]
        ci1 = c[3 * i + 1]
        ci2 = c[3 * i + 2]
        # row i of C [L×]: [L×] = [[0,-L2,L1],[L2,0,-L0],[-L1,L0,0]]
        jac[row0 + i, 9] = -(ci1 * lever[2] - ci2 * lever[1])
        jac[row0 + i, 10] = -(-ci0 * lever[2] + ci2 * lever[0])
        jac[row0 + i, 11] = -(ci0 * lever[1] - ci1 * lever[0])


@njit(cache=True)
def heading_row_into(nav, h_out, jac, row0):
    """ψ = atan2(C_01, C_11) (rad, azimuth) and its H row."""
    c01 = nav[7]
    c11 = nav[10]
    c21 = nav[13]
    h_out[row0] = math.atan2(c01, c11) % (2.0 * math.pi)
    den = c01 * c01 + c11 * c11
    for j in range(N_ERR):
        jac[row0, j] = 0.0
    jac[row0, 6] = c01 * c21 / den
    jac[row0, 7] = c11 * c21 / den
    jac[row0, 8] = -1.0


@njit(cache=True)
def apply_correction_into(nav, dx, scratch):
    """Closed-loop feedback x̂ ⊖ δx: r −= δr, v −= δv, C ← Exp(φ) C, b −= δb.
    scratch: (4, 3, 3)."""
    for i in range(6):
        nav[i] -= dx[i]
    c = scratch[0]
    rot = scratch[1]
    out = scratch[2]
    _load_c(nav, c)
    _rodrigues_into(dx[6], dx[7], dx[8], rot)
    _mat3_mul_into(rot, c, out)
    _store_c(out, nav)
    for i in range(6):
        nav[15 + i] -= dx[9 + i]


# ------------------------------------------------------------------ the epoch loop


@njit(cache=True)
def errins_chunk(e0, e1, t, imu_idx, pos_idx, vel_idx, hdg_idx, imu_z,
                 pos_z, pos_sd, vel_z, vel_sd, hdg_z, hdg_sd,
                 nav, p, state, q_gyro, q_accel, q_bg, q_ba, tau_g, tau_a, lever, frame,
                 z_crit, rec_nav, rec_sd, rec_cov_blocks, rec_innov, rec_innov_var,
                 rec_rejected):
    """Run epochs [e0, e1) of the ErrINSEKF. nav (21,) and p (15, 15) are updated in place.
    state (8,): [t_state, have_sample, last ω (3), last f (3)] carried between chunks.
    Records per epoch after the update: rec_nav (E, 15) = r, v^n, Euler θ, b_ω, b_a;
    rec_sd (E, 15) = √diag P; rec_cov_blocks (E, 3, 3, 3) of δr, δv, φ; innovations
    (E, 7) and their variances, NaN when absent; rejected (E, 7) z-test flags."""
    f_mat = np.zeros((N_ERR, N_ERR))
    phi = np.zeros((N_ERR, N_ERR))
    qd = np.zeros((N_ERR, N_ERR))
    work = np.zeros((N_ERR, N_ERR))
    work2 = np.zeros((N_ERR, N_ERR))
    work3 = np.zeros((4, 3, 3))
    g = np.zeros(3)
    dg = np.zeros((3, 3))
    h_all = np.zeros(N_ROWS)
    jac = np.zeros((N_ROWS, N_ERR))
    z_all = np.zeros(N_ROWS)
    r_all = np.zeros(N_ROWS)
    present = np.zeros(N_ROWS, dtype=np.bool_)
    dx = np.zeros(N_ERR)
    ph = np.zeros(N_ERR)
    w_ib = np.zeros(3)
    cmat = np.zeros((3, 3))
    for e in range(e0, e1):
        have_imu = imu_idx[e] >= 0
        if state[1] > 0.0:
            dt = t[e] - state[0]
            if dt > 0.0:
                if have_imu:
                    k = imu_idx[e]
                    wx = 0.5 * (state[2] + imu_z[k, 0])
                    wy = 0.5 * (state[3] + imu_z[k, 1])
                    wz = 0.5 * (state[4] + imu_z[k, 2])
                    fx = 0.5 * (state[5] + imu_z[k, 3])
                    fy = 0.5 * (state[6] + imu_z[k, 4])
                    fz = 0.5 * (state[7] + imu_z[k, 5])
                else:
                    wx, wy, wz = state[2], state[3], state[4]
                    fx, fy, fz = state[5], state[6], state[7]
                wx -= nav[15]
                wy -= nav[16]
                wz -= nav[17]
                fx -= nav[18]
                fy -= nav[19]
                fz -= nav[20]
                mechanize_into(nav, wx, wy, wz, fx, fy, fz, dt, frame, work3, g, dg)
                decay_g = math.exp(-dt / tau_g)
                decay_a = math.exp(-dt / tau_a)
                for i in range(3):
                    nav[15 + i] *= decay_g
                    nav[18 + i] *= decay_a
                error_state_transition_into(nav, fx, fy, fz, dt, frame, tau_g, tau_a,
                                            f_mat, phi, work, dg, g)
                process_noise_into(nav, dt, q_gyro, q_accel, q_bg, q_ba, phi, qd, work,
                                   work2)
                predict_covariance_into(p, phi, qd, work, work2)
            state[0] = t[e]
        if have_imu:
            k = imu_idx[e]
            for i in range(6):
                state[2 + i] = imu_z[k, i]
            if state[1] == 0.0:
                state[0] = t[e]
            state[1] = 1.0
        # ---- aiding update (rows processed one at a time, R diagonal)
        for i in range(N_ROWS):
            present[i] = False
            rec_innov[e, i] = np.nan
            rec_innov_var[e, i] = np.nan
            rec_rejected[e, i] = 0
        if state[1] > 0.0:
            for i in range(3):
                w_ib[i] = state[2 + i] - nav[15 + i]
            if pos_idx[e] >= 0:
                position_rows_into(nav, lever, h_all, jac, 0)
                for i in range(3):
                    z_all[i] = pos_z[pos_idx[e], i]
                    r_all[i] = pos_sd[pos_idx[e], i] ** 2
                    present[i] = True
            if vel_idx[e] >= 0:
                velocity_rows_into(nav, w_ib, lever, frame, h_all, jac, 3)
                for i in range(3):
                    z_all[3 + i] = vel_z[vel_idx[e], i]
                    r_all[3 + i] = vel_sd[vel_idx[e], i] ** 2
                    present[3 + i] = True
            if hdg_idx[e] >= 0:
                heading_row_into(nav, h_all, jac, 6)
                z_all[6] = hdg_z[hdg_idx[e]]
                r_all[6] = hdg_sd[hdg_idx[e]] ** 2
                present[6] = True
        any_update = False
        for i in range(N_ERR):
            dx[i] = 0.0
        for row in range(N_ROWS):
            if not present[row]:
                continue
            d = z_all[row] - h_all[row]
            if row == 6:
                d = (d + math.pi) % (2.0 * math.pi) - math.pi
            for j in range(N_ERR):
                d -= jac[row, j] * dx[j]
            for i in range(N_ERR):
                s = 0.0
                for j in range(N_ERR):
                    s += p[i, j] * jac[row, j]
                ph[i] = s
            s_var = r_all[row]
            for j in range(N_ERR):
                s_var += jac[row, j] * ph[j]
            rec_innov[e, row] = d
            rec_innov_var[e, row] = s_var
            if abs(d) > z_crit * math.sqrt(s_var):
                rec_rejected[e, row] = 1
                continue
            for i in range(N_ERR):
                dx[i] += ph[i] / s_var * d
            for i in range(N_ERR):
                for j in range(i, N_ERR):
                    p[i, j] -= ph[i] * ph[j] / s_var
                    p[j, i] = p[i, j]
            any_update = True
        if any_update:
            apply_correction_into(nav, dx, work3)
        # ---- records
        for i in range(6):
            rec_nav[e, i] = nav[i]
        _load_c(nav, cmat)
        sp = min(1.0, max(-1.0, cmat[2, 1]))
        rec_nav[e, 6] = math.asin(sp)
        rec_nav[e, 7] = math.atan2(-cmat[2, 0], cmat[2, 2])
        rec_nav[e, 8] = math.atan2(cmat[0, 1], cmat[1, 1]) % (2.0 * math.pi)
        for i in range(6):
            rec_nav[e, 9 + i] = nav[15 + i]
        for i in range(N_ERR):
            rec_sd[e, i] = math.sqrt(max(p[i, i], 0.0))
        for b in range(3):
            for i in range(3):
                for j in range(3):
                    rec_cov_blocks[e, b, i, j] = p[3 * b + i, 3 * b + j]


# ------------------------------------------------------------------ Python driver


@dataclass
class ErrInsConfig:
    """ErrINSEKF settings (SI, rad). imu_sd: per-sample white-noise 1σ [gyro(3) rad/s,
    accel(3) m/s²] at imu_rate_hz; bias_drift_sd: per-step 1σ [b_ω(3) rad/s, b_a(3) m/s²]
    (= BS √(δt/T), 001 Table 4-3); bias_tau_s: (gyro, accel) correlation times, inf =
    random walk; p0_sd: (15,) initial 1σ of δr, δv, φ, δb_ω, δb_a."""
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

    def spectral_densities(self):
        """(q_gyro, q_accel, q_bg, q_ba): white noise q = σ² δt, bias drift q = σ²/δt."""
        dt = 1.0 / self.imu_rate_hz
        return (self.imu_sd[:3] ** 2 * dt, self.imu_sd[3:] ** 2 * dt,
                self.bias_drift_sd[:3] ** 2 / dt, self.bias_drift_sd[3:] ** 2 / dt)


def nav_state(r_enu, v_enu, euler, gyro_bias=(0, 0, 0), accel_bias=(0, 0, 0)):
    """Pack the navigation state (21,): r^n, v^n, C_b^n(θ) row-major, b_ω, b_a."""
    nav = np.zeros(NAV_SIZE)
    nav[0:3] = r_enu
    nav[3:6] = v_enu
    nav[6:15] = dcm_body_to_nav(float(euler[0]), float(euler[1]), float(euler[2])).ravel()
    nav[15:18] = gyro_bias
    nav[18:21] = accel_bias
    return nav


def nav_from_gmikf_state(x):
    """The ErrINSEKF's start from a GMIKF state vector (same r, v^n = C v^b, θ, b)."""
    x = np.asarray(x, float)
    c = dcm_body_to_nav(x[9], x[10], x[11])
    return nav_state(x[0:3], c @ x[3:6], x[9:12], x[15:18], x[18:21])


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
    state = np.zeros(8)
    state[0] = np.nan
    qg, qa, qbg, qba = config.spectral_densities()
    z_crit = (float(stats.norm.ppf(1 - config.outlier_alpha / 2))
              if config.outlier_alpha > 0 else np.inf)
    rec = ErrInsRecords(t=epochs.t, nav=np.empty((e_total, 15)), sd=np.empty((e_total, 15)),
                        cov_blocks=np.empty((e_total, 3, 3, 3)),
                        innov=np.empty((e_total, N_ROWS)), innov_var=np.empty((e_total, N_ROWS)),
                        rejected=np.zeros((e_total, N_ROWS), np.int8), imu_row=epochs.imu)
    f64 = lambda a, shape: np.ascontiguousarray(a, dtype=float).reshape(shape)  # noqa: E731
    args = (epochs.t, epochs.imu, epochs.pos, epochs.vel, epochs.heading,
            f64(meas.imu_z, (-1, 6)), f64(meas.pos_enu, (-1, 3)), f64(meas.pos_sd, (-1, 3)),
            f64(meas.vel_enu, (-1, 3)), f64(meas.vel_sd, (-1, 3)), f64(meas.heading, (-1,)),
            f64(meas.heading_sd, (-1,)))
    tau_g, tau_a = (float(v) for v in config.bias_tau_s)
    for e0 in range(0, e_total, config.chunk):
        e1 = min(e_total, e0 + config.chunk)
        errins_chunk(e0, e1, *args, nav, p, state, qg, qa, qbg, qba, tau_g, tau_a,
                     config.lever_arm, np.asarray(frame, float), z_crit, rec.nav, rec.sd,
                     rec.cov_blocks, rec.innov, rec.innov_var, rec.rejected)
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
    """(F, Φ) at nav for body specific force f_b (m/s², bias-corrected)."""
    f_mat = np.zeros((N_ERR, N_ERR))
    phi = np.zeros((N_ERR, N_ERR))
    error_state_transition_into(np.asarray(nav, float), float(f_b[0]), float(f_b[1]),
                                float(f_b[2]), dt, np.asarray(frame, float),
                                float(bias_tau_s[0]), float(bias_tau_s[1]), f_mat, phi,
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
    return np.asarray(nav, float)[6:15].reshape(3, 3).copy()


def euler_of(nav):
    return euler_from_dcm(nav_dcm(nav))


__all__ = ["ErrInsConfig", "ErrInsRecords", "run_errins",
           "run_errins_prepared", "nav_state", "nav_from_gmikf_state", "mechanize",
           "error_state_transition", "apply_correction", "attitude_error",
           "position_rows_into", "velocity_rows_into", "heading_row_into",
           "process_noise_into", "predict_covariance_into", "errins_chunk", "N_ERR",
           "ROW_NAMES"]
