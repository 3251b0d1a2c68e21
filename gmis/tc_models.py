"""Tightly coupled measurement models of the GMIKF: double-differenced GNSS code, carrier
phase (L1, L2) and Doppler between a known base and the rover antenna (001 §4.1.3.2 ii,
eq. 5.1.7-5.1.11).

The rover antenna is the state position plus the lever arm, converted from the origin
ENU frame to ECEF:

    r_ant^e = r_0^e + C_n^e (r^n + C_b^n L^b)
    v_ant^e = C_n^e C_b^n (v^b + ω×L^b)

For satellite k with ECEF position s_k (at the rover's transmit time) and velocity ṡ_k,
ρ_k = |s_k − r_ant^e|, e_k = (s_k − r_ant^e)/ρ_k, ρ̇_k = e_k·(ṡ_k − v_ant^e). With the base
terms ρ_b,k, ρ̇_b,k known, the DD against the reference satellite j are

    code/phase:  ∇Δρ_kj = (ρ_k − ρ_b,k) − (ρ_j − ρ_b,j)  [+ λ_f (N_f,k − N_f,j)]   (m)
    Doppler:     ∇Δρ̇_kj = (ρ̇_k − ρ̇_b,k) − (ρ̇_j − ρ̇_b,j)                         (m/s)

N_f,k are the rover−base single-difference ambiguity states (cycles) of satellite k on
frequency f; only their differences are observable (gmis.tc, docs/DESIGN.md). Satellite
clocks cancel in the single difference, receiver clocks in the double difference, and
ionosphere/troposphere in the DD on a short baseline (< 10 km).
"""

import numpy as np

from gmis.frames import dcm_body_to_nav, dcm_body_to_nav_partials_into

OBS_CODE, OBS_L1, OBS_L2, OBS_DOPPLER = 0, 1, 2, 3
OBS_NAMES = ("code", "phase_l1", "phase_l2", "doppler")


def antenna_ecef(x, lever_arm, frame):
    """Rover antenna ECEF position (m) and velocity (m/s) from the state."""
    c_bn = dcm_body_to_nav(x[9], x[10], x[11])
    c_ne = frame[6:15].reshape(3, 3).T
    r_ant = frame[3:6] + c_ne @ (x[0:3] + c_bn @ lever_arm)
    v_ant = c_ne @ c_bn @ (x[3:6] + np.cross(x[12:15], lever_arm))
    return r_ant, v_ant


def dd_model_and_jacobian(x, kinds, sat_k, sat_j, sat_pos, sat_vel, base_range, base_rate,
                          amb_state, wavelengths, lever_arm, frame):
    """Predicted DD observations h (m,) and Jacobian H (m, n) for rows described by
    kinds (m,) ∈ {OBS_CODE, OBS_L1, OBS_L2, OBS_DOPPLER}, sat_k / sat_j (m,) satellite
    indices into sat_pos (n_s, 3), sat_vel, base_range, base_rate (n_s,), amb_state
    (2, n_s) state index of the L1/L2 SD ambiguity of each satellite (-1 none),
    wavelengths (2,) m."""
    n = x.shape[0]
    m = len(kinds)
    c_bn = dcm_body_to_nav(x[9], x[10], x[11])
    dc = np.empty((3, 3, 3))
    dcm_body_to_nav_partials_into(x[9], x[10], x[11], dc[0], dc[1], dc[2])
    c_en = frame[6:15].reshape(3, 3)
    c_ne = c_en.T
    lever = np.asarray(lever_arm, float)
    u_b = x[3:6] + np.cross(x[12:15], lever)
    r_ant = frame[3:6] + c_ne @ (x[0:3] + c_bn @ lever)
    v_ant = c_ne @ c_bn @ u_b
    los = sat_pos - r_ant
    rho = np.linalg.norm(los, axis=1)
    e = los / rho[:, None]                               # ECEF unit vectors rover → sat
    rel_v = sat_vel - v_ant
    rate = np.einsum("ij,ij->i", e, rel_v)
    e_n = e @ c_ne                                        # ENU components: (C_en e)ᵀ
    # ∂r_ant^e/∂θ_m = C_ne (∂C/∂θ_m) L ;  ∂v_ant^e/∂θ_m = C_ne (∂C/∂θ_m) u_b
    dr_dth = np.stack([dc[k] @ lever for k in range(3)], axis=1)     # (3 enu, 3 θ)
    dv_dth = np.stack([dc[k] @ u_b for k in range(3)], axis=1)
    lx = np.array([[0.0, lever[2], -lever[1]], [-lever[2], 0.0, lever[0]],
                   [lever[1], -lever[0], 0.0]])          # ∂(ω×L)/∂ω = −[L×]
    h = np.empty(m)
    jac = np.zeros((m, n))
    for row in range(m):
        k, j = sat_k[row], sat_j[row]
        kind = kinds[row]
        if kind == OBS_DOPPLER:
            h[row] = (rate[k] - base_rate[k]) - (rate[j] - base_rate[j])
            # ρ̇ = e·(ṡ − v): ∂/∂v_ant = −e ; ∂e/∂r_ant = −(I − e eᵀ)/ρ
            g_v = -(e_n[k] - e_n[j])                     # w.r.t. v_ant in ENU
            proj_k = (rel_v[k] - e[k] * rate[k]) / rho[k]
            proj_j = (rel_v[j] - e[j] * rate[j]) / rho[j]
            g_r = -((proj_k - proj_j) @ c_ne)            # w.r.t. r_ant in ENU
            jac[row, 0:3] = g_r
            jac[row, 9:12] = g_r @ dr_dth + g_v @ dv_dth
            jac[row, 3:6] = g_v @ c_bn
            jac[row, 12:15] = g_v @ c_bn @ lx
        else:
            h[row] = (rho[k] - base_range[k]) - (rho[j] - base_range[j])
            g_r = -(e_n[k] - e_n[j])
            jac[row, 0:3] = g_r
            jac[row, 9:12] = g_r @ dr_dth
            if kind in (OBS_L1, OBS_L2):
                f = kind - OBS_L1
                ik, ij = amb_state[f, k], amb_state[f, j]
                h[row] += wavelengths[f] * (x[ik] - x[ij])
                jac[row, ik] += wavelengths[f]
                jac[row, ij] -= wavelengths[f]
    return h, jac
