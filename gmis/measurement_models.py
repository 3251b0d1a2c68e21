"""Measurement models h(x) and Jacobians H = ∂h/∂x of the GMIKF.

IMU (001 eq. 4.1.39/4.1.40, 5.1.3-5.1.6): see :mod:`gmis.imu_model` for the model.
Loosely coupled GNSS (001 eq. 4.1.41-4.1.43), antenna lever arm L^b (m, body RFU):
    r_ant = r + C_b^n L                       (m, ENU)
    v_ant = C_b^n (v^b + ω×L)                 (m/s, ENU)
    ψ_gnss = ψ                                (rad, wrapped innovation)
  or, with the body baseline ΔL = L_secondary − L_primary of the two heading antennas
  known (gnss.heading's level-converted ψ_b − α, exact for a tilted vehicle):
    ψ_gnss = az(C_b^n(p, γ, ψ) ΔL) − az(ΔL),  az(v) = atan2(v_e, v_n)   (rad, wrapped)
Non-holonomic constraint (000 eq. 5.41-5.43 with identity boresight), constraint point at
l^b from the IMU (m, body RFU; e.g. the rear-axle centre):
    0 ≈ [(v^b + ω×l)_x, (v^b + ω×l)_z]         (m/s, lateral and vertical)
Zero-velocity / zero-angular-rate updates at a stop (000 eq. 5.44-5.46; v^b and ω = ω_nb^b
are GMIKF states, so h is linear):
    0 ≈ [v^b, ω]                              (m/s, rad/s)

Every function writes its rows into a caller-provided stacked H (rows ``row0..``) so one
EKF update can carry all sensors of an epoch. Tested against central differences in
tests/test_measurement_models.py.
"""

import numpy as np
from numba import njit

from gmis.frames import attitude_trig, dcm_partials_rows_trig, dcm_rows_trig, skew_rows
from gmis.gravity import gravity_nav
from gmis.state import (
    I_ACC,
    I_BA,
    I_BG,
    I_HEADING,
    I_PITCH,
    I_POS,
    I_RATE,
    I_ROLL,
    I_SA,
    I_SG,
    I_VEL,
    N_STATES_27,
)


@njit(cache=True, inline="always")
def _attitude_rows(x):
    """C_b^n(θ) and ∂C_b^n/∂(p, γ, ψ) as row tuples: c[i][k], dc[m][i][k]."""
    trig = attitude_trig(x[I_PITCH], x[I_ROLL], x[I_HEADING])   # sin, cos once
    return dcm_rows_trig(trig), dcm_partials_rows_trig(trig)


@njit(cache=True, inline="always")
def _mat3_vec(a, v):
    """a v as a tuple, a: three row tuples, v: 3-vector (the sums of dense.mat3_vec_into)."""
    return (a[0][0] * v[0] + a[0][1] * v[1] + a[0][2] * v[2],
            a[1][0] * v[0] + a[1][1] * v[1] + a[1][2] * v[2],
            a[2][0] * v[0] + a[2][1] * v[1] + a[2][2] * v[2])


@njit(cache=True)
def imu_model_and_jacobian_into(x, n_imu, frame, h_out, h_row0, jac, row0):
    """Predicted IMU outputs h (gyro rad/s, accel m/s²) into h_out[h_row0:h_row0+6] and
    their Jacobian into jac[row0:row0+6, :] (columns beyond the IMU states left 0).

    n_imu = 21 ignores scale factors (S = 0). Allocation-free (3-vectors and 3×3 matrices
    as tuples, c[l][i])."""
    c, dc = _attitude_rows(x)
    g, dg = gravity_nav(frame, x[I_POS:I_POS + 3])
    w_ie = frame[15:18]
    v = x[I_VEL:I_VEL + 3]
    # v^n, Coriolis term k = 2 ω_ie × v^n and its partials
    vn = _mat3_vec(c, v)
    kx = skew_rows(w_ie[0], w_ie[1], w_ie[2], 2.0)   # [2ω_ie ×]
    cor = _mat3_vec(kx, vn)
    spec = (cor[0] - g[0], cor[1] - g[1], cor[2] - g[2])   # nav-frame part of 4.1.40
    # row m: [2ω_ie×] ∂C_b^n/∂θ_m v
    dkv = (_mat3_vec(kx, _mat3_vec(dc[0], v)), _mat3_vec(kx, _mat3_vec(dc[1], v)),
           _mat3_vec(kx, _mat3_vec(dc[2], v)))
    for r in range(6):
        for col in range(jac.shape[1]):
            jac[row0 + r, col] = 0.0
    for i in range(3):
        sw = x[I_SG + i] if n_imu >= N_STATES_27 else 0.0
        sa = x[I_SA + i] if n_imu >= N_STATES_27 else 0.0
        wie_b = c[0][i] * w_ie[0] + c[1][i] * w_ie[1] + c[2][i] * w_ie[2]
        spec_b = c[0][i] * spec[0] + c[1][i] * spec[1] + c[2][i] * spec[2]
        gyro_core = x[I_RATE + i] + wie_b
        acc_core = x[I_ACC + i] + spec_b
        h_out[h_row0 + i] = (1.0 + sw) * gyro_core + x[I_BG + i]
        h_out[h_row0 + 3 + i] = (1.0 + sa) * acc_core + x[I_BA + i]
        rg = row0 + i
        ra = row0 + 3 + i
        # gyro
        jac[rg, I_RATE + i] = 1.0 + sw
        jac[rg, I_BG + i] = 1.0
        if n_imu >= N_STATES_27:
            jac[rg, I_SG + i] = gyro_core
            jac[ra, I_SA + i] = acc_core
        # accel
        jac[ra, I_ACC + i] = 1.0 + sa
        jac[ra, I_BA + i] = 1.0
        for m in range(3):
            # attitude: ∂(C^T u)_i/∂θ_m = Σ_l dC_m[l, i] u_l (+ C^T kx dC_m v for Coriolis)
            dcm = dc[m]
            jac[rg, I_PITCH + m] = (1.0 + sw) * (dcm[0][i] * w_ie[0] + dcm[1][i] * w_ie[1]
                                           + dcm[2][i] * w_ie[2])
            jac[ra, I_PITCH + m] = (1.0 + sa) * (dcm[0][i] * spec[0] + dcm[1][i] * spec[1]
                                           + dcm[2][i] * spec[2]
                                           + c[0][i] * dkv[m][0] + c[1][i] * dkv[m][1]
                                           + c[2][i] * dkv[m][2])
        for col in range(3):
            # velocity: C^T kx C;  position: −C^T ∂g/∂r
            kc0 = kx[0][0] * c[0][col] + kx[0][1] * c[1][col] + kx[0][2] * c[2][col]
            kc1 = kx[1][0] * c[0][col] + kx[1][1] * c[1][col] + kx[1][2] * c[2][col]
            kc2 = kx[2][0] * c[0][col] + kx[2][1] * c[1][col] + kx[2][2] * c[2][col]
            jac[ra, I_VEL + col] = (1.0 + sa) * (c[0][i] * kc0 + c[1][i] * kc1
                                                 + c[2][i] * kc2)
            jac[ra, I_POS + col] = -(1.0 + sa) * (c[0][i] * dg[0][col] + c[1][i] * dg[1][col]
                                          + c[2][i] * dg[2][col])


SCALE_REGRESSOR_GAP = 1    # samples k−1 … k+1 left out of the S regressor of sample k
SCALE_REGRESSOR_HALF = 25  # … which averages samples k−25 … k−2 and k+2 … k+25


@njit(cache=True, inline="always")
def _plus_pair(acc, z, lo, hi, i):
    """(acc + z[lo, i]) + z[hi, i]: the two additions of the neighbour sum in their order."""
    return acc + z[lo, i] + z[hi, i]


@njit(cache=True)
def imu_scale_column_from_neighbours(x, imu_z, k, jac, row0):
    """The scale-factor entries ∂h_i/∂S_i of the IMU rows of sample k (eq. 4.1.39/4.1.40:
    the core u = ω + C_n^b ω_ie, resp. a + C_n^b(2ω_ie × v − g)) evaluated at the mean of
    the sensor's neighbouring samples instead of the prediction:

        u_i = (mean_j y_j,i − b_i) / (1 + S_i),   2 ≤ |j − k| ≤ 25

    (y the raw gyro/accel output, rad/s or m/s²; b, S the predicted states; samples
    outside the data left out). The prediction ω⁻, a⁻ carries the noise of sample k−1
    (its per-step process noise is far above the IMU noise), which the innovation of
    sample k carries with the opposite sign (errors in variables), and it jitters from
    sample to sample although the true ω, a do not; leaving out k−1, k, k+1 (the forward
    and the backward filter) and averaging 48 samples removes both (docs/DESIGN.md
    "Scale factors in the IMU rows"). The symmetric window cancels a linear trend of u.
    For moving epochs only: at rest ω⁻ and a⁻ are frozen and the model's column is kept.
    Writes jac[row0 + i, I_SG + i], i = 0..5 (gyro x, y, z, accel x, y, z)."""
    n = imu_z.shape[0]
    if k - SCALE_REGRESSOR_HALF >= 0 and k + SCALE_REGRESSOR_HALF < n:
        # the whole window inside the data (every epoch but the first and last 25): the six
        # sums side by side, each in the order of the general loop below (bit for bit)
        a0 = a1 = a2 = a3 = a4 = a5 = 0.0
        for off in range(SCALE_REGRESSOR_GAP + 1, SCALE_REGRESSOR_HALF + 1):
            lo, hi = k - off, k + off
            a0 = _plus_pair(a0, imu_z, lo, hi, 0)
            a1 = _plus_pair(a1, imu_z, lo, hi, 1)
            a2 = _plus_pair(a2, imu_z, lo, hi, 2)
            a3 = _plus_pair(a3, imu_z, lo, hi, 3)
            a4 = _plus_pair(a4, imu_z, lo, hi, 4)
            a5 = _plus_pair(a5, imu_z, lo, hi, 5)
        cnt = 2 * (SCALE_REGRESSOR_HALF - SCALE_REGRESSOR_GAP)
        sums = (a0, a1, a2, a3, a4, a5)
        for i in range(6):
            b = x[I_BG + i] if i < 3 else x[I_BA + i - 3]
            jac[row0 + i, I_SG + i] = (sums[i] / cnt - b) / (1.0 + x[I_SG + i])
        return
    for i in range(6):
        acc = 0.0
        cnt = 0
        for off in range(SCALE_REGRESSOR_GAP + 1, SCALE_REGRESSOR_HALF + 1):
            if k - off >= 0:
                acc += imu_z[k - off, i]
                cnt += 1
            if k + off < n:
                acc += imu_z[k + off, i]
                cnt += 1
        if cnt > 0:
            b = x[I_BG + i] if i < 3 else x[I_BA + i - 3]
            jac[row0 + i, I_SG + i] = (acc / cnt - b) / (1.0 + x[I_SG + i])


@njit(cache=True)
def gnss_position_model_and_jacobian_into(x, lever_arm, h_out, h_row0, jac, row0):
    """r_ant = r + C_b^n L (eq. 4.1.41) and its Jacobian rows (3 rows)."""
    c, dc = _attitude_rows(x)
    for r in range(3):
        for col in range(jac.shape[1]):
            jac[row0 + r, col] = 0.0
    for i in range(3):
        h_out[h_row0 + i] = x[I_POS + i] + c[i][0] * lever_arm[0] + c[i][1] * lever_arm[1] \
            + c[i][2] * lever_arm[2]
        jac[row0 + i, I_POS + i] = 1.0
        for m in range(3):
            jac[row0 + i, I_PITCH + m] = (dc[m][i][0] * lever_arm[0] + dc[m][i][1] * lever_arm[1]
                                    + dc[m][i][2] * lever_arm[2])


@njit(cache=True)
def gnss_velocity_model_and_jacobian_into(x, lever_arm, h_out, h_row0, jac, row0):
    """v_ant = C_b^n (v^b + ω×L) (eq. 4.1.42) and its Jacobian rows (3 rows)."""
    c, dc = _attitude_rows(x)
    om = x[I_RATE:I_RATE + 3]
    u = (x[I_VEL] + om[1] * lever_arm[2] - om[2] * lever_arm[1],
         x[I_VEL + 1] + om[2] * lever_arm[0] - om[0] * lever_arm[2],
         x[I_VEL + 2] + om[0] * lever_arm[1] - om[1] * lever_arm[0])
    lx = skew_rows(lever_arm[0], lever_arm[1], lever_arm[2], -1.0)  # ∂(ω×L)/∂ω
    for r in range(3):
        for col in range(jac.shape[1]):
            jac[row0 + r, col] = 0.0
    for i in range(3):
        h_out[h_row0 + i] = c[i][0] * u[0] + c[i][1] * u[1] + c[i][2] * u[2]
        for k in range(3):
            jac[row0 + i, I_VEL + k] = c[i][k]
            jac[row0 + i, I_RATE + k] = c[i][0] * lx[0][k] + c[i][1] * lx[1][k] + c[i][2] * lx[2][k]
        for m in range(3):
            jac[row0 + i, I_PITCH + m] = dc[m][i][0] * u[0] + dc[m][i][1] * u[1] + dc[m][i][2] * u[2]


@njit(cache=True)
def heading_model_and_jacobian_into(x, h_out, h_row0, jac, row0):
    """ψ_gnss = ψ (eq. 4.1.43); the innovation must be wrapped to [-π, π)."""
    for col in range(jac.shape[1]):
        jac[row0, col] = 0.0
    h_out[h_row0] = x[I_HEADING]
    jac[row0, I_HEADING] = 1.0


@njit(cache=True)
def baseline_heading_model_and_jacobian_into(x, baseline, h_out, h_row0, jac, row0):
    """Dual-antenna heading ψ_gnss = az(C_b^n ΔL) − α (module doc), α = atan2(ΔL_x, ΔL_y)
    the baseline's body azimuth, ΔL = baseline (3,) m body RFU; the measurement is the
    level-vehicle conversion ψ_b − α of gnss.heading, so a level vehicle gives h = ψ.
    H: ∂az/∂b = (b_n, −b_e, 0)/h², ∂b/∂(p, γ, ψ) = ∂C_b^n/∂(p, γ, ψ) ΔL (∂h/∂ψ = 1). A
    baseline without horizontal extent (all zeros: not known) gives ψ_gnss = ψ
    (heading_model_and_jacobian_into)."""
    if baseline[0] * baseline[0] + baseline[1] * baseline[1] == 0.0:
        heading_model_and_jacobian_into(x, h_out, h_row0, jac, row0)
        return
    for col in range(jac.shape[1]):
        jac[row0, col] = 0.0
    c, dc = _attitude_rows(x)
    be = c[0][0] * baseline[0] + c[0][1] * baseline[1] + c[0][2] * baseline[2]
    bn = c[1][0] * baseline[0] + c[1][1] * baseline[1] + c[1][2] * baseline[2]
    h2 = be * be + bn * bn
    h_out[h_row0] = np.arctan2(be, bn) - np.arctan2(baseline[0], baseline[1])
    for m in range(3):
        de = dc[m][0][0] * baseline[0] + dc[m][0][1] * baseline[1] + dc[m][0][2] * baseline[2]
        dn = dc[m][1][0] * baseline[0] + dc[m][1][1] * baseline[1] + dc[m][1][2] * baseline[2]
        jac[row0, I_PITCH + m] = (bn * de - be * dn) / h2


@njit(cache=True)
def nonholonomic_model_and_jacobian_into(x, lever_arm, h_out, h_row0, jac, row0):
    """Lateral and vertical body velocity of the constraint point, u = v^b + ω×l (000 eq.
    5.41; v^b and ω are GMIKF states, so H is linear: ∂u/∂v = I, ∂u/∂ω = −[l×])."""
    lx, ly, lz = lever_arm[0], lever_arm[1], lever_arm[2]
    for r in range(2):
        for col in range(jac.shape[1]):
            jac[row0 + r, col] = 0.0
    # (ω×l)_x = ω_y l_z − ω_z l_y ;  (ω×l)_z = ω_x l_y − ω_y l_x
    wx, wy, wz = I_RATE, I_RATE + 1, I_RATE + 2
    h_out[h_row0] = x[I_VEL] + x[wy] * lz - x[wz] * ly
    h_out[h_row0 + 1] = x[I_VEL + 2] + x[wx] * ly - x[wy] * lx
    jac[row0, I_VEL] = 1.0
    jac[row0, wy] = lz
    jac[row0, wz] = -ly
    jac[row0 + 1, I_VEL + 2] = 1.0
    jac[row0 + 1, wx] = ly
    jac[row0 + 1, wy] = -lx


@njit(cache=True)
def zero_motion_model_and_jacobian_into(x, h_out, h_row0, jac, row0):
    """ZUPT and ZARU rows (000 eq. 5.44-5.46): h = [v^b (3), ω (3)], H = [0 I 0 …] for v^b
    (eq. 5.45) and the same for ω."""
    for r in range(6):
        for col in range(jac.shape[1]):
            jac[row0 + r, col] = 0.0
    for i in range(3):
        h_out[h_row0 + i] = x[I_VEL + i]
        h_out[h_row0 + 3 + i] = x[I_RATE + i]
        jac[row0 + i, I_VEL + i] = 1.0
        jac[row0 + 3 + i, I_RATE + i] = 1.0
