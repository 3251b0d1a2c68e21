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
frequency f; only their differences are observable (gmis.tc_filter, docs/DESIGN.md). Satellite
clocks cancel in the single difference, receiver clocks in the double difference, and
ionosphere/troposphere in the DD on a short baseline (< 10 km).

Time-differenced carrier phase (TDCP, the selectable alternative to DD Doppler for the 4th
observation group, TcConfig.velocity_observable = "tdcp"). Observed, L1 only, in metres:

    z_kj = λ1 [∇Δφ1,kj(t_k) − ∇Δφ1,kj(t_{k−1})]

both DDs formed against the CURRENT reference j, for satellites with L1 at both epochs and
no slip flagged at t_k on k or j; the ambiguities cancel, so no ambiguity state enters.
Predicted entirely from the CURRENT state (Δt = t_k − t_{k−1} > 0). With ṙ = C v,
r̈ = C a and d³r/dt³ = C j exactly (docs/DESIGN.md, gmis/system_model.py; j = ȧ + ω×a is
the body-frame jerk), the backward Taylor series gives the antenna position at t_{k−1} in
the origin ENU frame

    r_ant,k−1 = r − C (v Δt − a Δt²/2 + ĵ Δt³/6) + C E L,   ĵ = ω×a,  E = exp(−[ω Δt ×])

C = C_b^n(θ) at t_k, the lever arm rotated with C_{k−1} = C_k E (exact for a constant body
rate ω). ĵ = ω×a assumes a body-frame acceleration constant over the interval (ȧ = 0, a
steady manoeuvre) instead of the system model's zero-mean j (a nav-frame acceleration
constant): in a steady 0.26 rad/s turn at 10 m/s, j = ω×a is 0.68 m/s³, and dropping it
would bias the predicted displacement by 1.4 cm at Δt = 0.5 s (≫ the few-mm TDCP noise);
with it the error of a steady turn is 4th order (< 1 mm). What remains is the change of
the body-frame acceleration over Δt (onset of braking, turn entry). Then

    h_kj = ∇Δρ_kj(r_ant,k; s(t_k), ρ_b(t_k)) − ∇Δρ_kj(r_ant,k−1; s(t_{k−1}), ρ_b(t_{k−1}))

with satellite positions and base ranges of both epochs known. The Jacobian is analytic:
∂/∂r = g_k − g_{k−1} (g = −(e_k − e_j) in ENU), ∂/∂v = g_{k−1} C Δt,
∂/∂a = −g_{k−1} C (I Δt²/2 − [ω×] Δt³/6),
∂/∂θ_m = g_k (∂C/∂θ_m) L − g_{k−1} (∂C/∂θ_m)(E L − v Δt + a Δt²/2 − ĵ Δt³/6),
∂/∂ω = −g_{k−1} C (E [L×] J_r(−ωΔt) Δt + [a×] Δt³/6) (J_r: right Jacobian of SO(3));
tested against central differences (tests/test_tc_models.py).

Covariance of the DD TDCP block: 2 σ_tdcp² M (M: the elevation cofactor DD matrix of
001 eq. 5.1.10 at t_k; σ_tdcp defaults to the L1 phase σ90). Ignored on purpose: the
correlation −σ²M between consecutive TDCPs (they share φ(t_{k−1})) and the correlation
+σ²M with the same epoch's DD L1 phase rows (they share φ(t_k)) — see docs/DESIGN.md for
what that does to the group's variance factor.
"""

import numpy as np
from numba import njit

from gmis.earth import FRAME_C_EN, FRAME_ORIGIN_ECEF
from gmis.frames import dcm_body_to_nav, dcm_body_to_nav_into, dcm_body_to_nav_partials_into
from gmis.state import (
    ACC,
    ATT,
    I_ATT,
    I_HEADING,
    I_PITCH,
    I_POS,
    I_RATE,
    I_ROLL,
    I_VEL,
    POS,
    RATE,
    VEL,
)

OBS_CODE, OBS_L1, OBS_L2, OBS_DOPPLER = 0, 1, 2, 3
OBS_TDCP = 3      # the velocity group's column: Doppler or TDCP, one per run
OBS_NAMES = ("code", "phase_l1", "phase_l2", "doppler")
VELOCITY_OBSERVABLES = ("doppler", "tdcp")


def group_names(velocity_observable: str = "doppler") -> tuple:
    """Names of the four observation groups (columns of gmis.tc_filter.TcRecords); the 4th is
    the selected velocity observable, "doppler" or "tdcp"."""
    if velocity_observable not in VELOCITY_OBSERVABLES:
        raise ValueError(f"velocity observable must be one of {VELOCITY_OBSERVABLES}, "
                         f"got {velocity_observable!r}")
    return OBS_NAMES[:3] + (velocity_observable,)


def antenna_ecef(x, lever_arm, frame):
    """Rover antenna ECEF position (m) and velocity (m/s) from the state."""
    c_bn = dcm_body_to_nav(x[I_PITCH], x[I_ROLL], x[I_HEADING])
    c_ne = frame[FRAME_C_EN].reshape(3, 3).T
    v_ant = c_ne @ c_bn @ (x[VEL] + np.cross(x[RATE], lever_arm))
    return _antenna_position(x, lever_arm, frame, c_bn, c_ne), v_ant


def antenna_position_ecef(x, lever_arm, frame):
    """Rover antenna ECEF position (m) from the state (antenna_ecef without the velocity,
    the same numbers)."""
    c_bn = dcm_body_to_nav(x[I_PITCH], x[I_ROLL], x[I_HEADING])
    return _antenna_position(x, lever_arm, frame, c_bn, frame[FRAME_C_EN].reshape(3, 3).T)


def _antenna_position(x, lever_arm, frame, c_bn, c_ne):
    """r_ant^e = r_0^e + C_n^e (r^n + C_b^n L^b)."""
    return frame[FRAME_ORIGIN_ECEF] + c_ne @ (x[POS] + c_bn @ lever_arm)


def dd_model_and_jacobian(x, kinds, sat_k, sat_j, sat_pos, sat_vel, base_range, base_rate,
                          amb_state, wavelengths, lever_arm, frame):
    """Predicted DD observations h (m,) and Jacobian H (m, n) for rows described by
    kinds (m,) ∈ {OBS_CODE, OBS_L1, OBS_L2, OBS_DOPPLER}, sat_k / sat_j (m,) satellite
    indices into sat_pos (n_s, 3), sat_vel, base_range, base_rate (n_s,), amb_state
    (2, n_s) state index of the L1/L2 SD ambiguity of each satellite (-1 none),
    wavelengths (2,) m. Allocates h and H and calls the numba kernel dd_model_into."""
    m = len(kinds)
    h = np.empty(m)
    jac = np.zeros((m, np.asarray(x).shape[0]))
    dd_model_into(np.ascontiguousarray(x, dtype=float), np.asarray(kinds, dtype=np.int64),
                  np.asarray(sat_k, dtype=np.int64), np.asarray(sat_j, dtype=np.int64),
                  np.ascontiguousarray(sat_pos, dtype=float),
                  np.ascontiguousarray(sat_vel, dtype=float),
                  np.ascontiguousarray(base_range, dtype=float),
                  np.ascontiguousarray(base_rate, dtype=float),
                  np.ascontiguousarray(amb_state, dtype=np.int64),
                  np.ascontiguousarray(wavelengths, dtype=float),
                  np.ascontiguousarray(lever_arm, dtype=float),
                  np.ascontiguousarray(frame, dtype=float), h, jac)
    return h, jac


@njit(cache=True)
def _antenna_state_into(x, lever, frame, c_bn, c_ne, r_ant, v_ant, dr_dth, dv_dth):
    """C_b^n, C_ne = C_enᵀ, the antenna's ECEF position r_ant = r0 + C_ne (r + C L) and
    velocity v_ant = C_ne C (v + ω×L), and (∂C/∂θ_m) L, (∂C/∂θ_m) u (u = v + ω×L) as
    columns m of dr_dth, dv_dth (zeroed by the caller)."""
    dcm_body_to_nav_into(x[I_PITCH], x[I_ROLL], x[I_HEADING], c_bn)
    dc = np.empty((3, 3, 3))
    dcm_body_to_nav_partials_into(x[I_PITCH], x[I_ROLL], x[I_HEADING], dc[0], dc[1], dc[2])
    for a in range(3):                    # C_ne = C_enᵀ; frame[6:15] (FRAME_C_EN) is C_en
        for b in range(3):
            c_ne[a, b] = frame[6 + 3 * b + a]
    u_b = np.empty(3)                     # v + ω×L
    w0, w1, w2 = x[I_RATE], x[I_RATE + 1], x[I_RATE + 2]
    u_b[0] = x[I_VEL] + w1 * lever[2] - w2 * lever[1]
    u_b[1] = x[I_VEL + 1] + w2 * lever[0] - w0 * lever[2]
    u_b[2] = x[I_VEL + 2] + w0 * lever[1] - w1 * lever[0]
    r_n = np.empty(3)
    v_n = np.empty(3)
    for a in range(3):
        r_n[a] = x[I_POS + a]
        v_n[a] = 0.0
        for b in range(3):
            r_n[a] += c_bn[a, b] * lever[b]
            v_n[a] += c_bn[a, b] * u_b[b]
    for a in range(3):
        r_ant[a] = frame[3 + a]
        v_ant[a] = 0.0
        for b in range(3):
            r_ant[a] += c_ne[a, b] * r_n[b]
            v_ant[a] += c_ne[a, b] * v_n[b]
    for mth in range(3):
        for a in range(3):
            for b in range(3):
                dr_dth[a, mth] += dc[mth, a, b] * lever[b]
                dv_dth[a, mth] += dc[mth, a, b] * u_b[b]


@njit(cache=True)
def _lines_of_sight_into(sat_pos, sat_vel, r_ant, v_ant, c_ne, rho, rate, e, e_n, rel_v):
    """Per satellite: range ρ, unit vector e (ECEF) and its ENU components e_n, relative
    velocity ṡ − v_ant and range rate ρ̇ = e·(ṡ − v_ant)."""
    for i in range(sat_pos.shape[0]):
        d2 = 0.0
        for a in range(3):
            d2 += (sat_pos[i, a] - r_ant[a]) ** 2
        rho[i] = np.sqrt(d2)
        rate[i] = 0.0
        for a in range(3):
            e[i, a] = (sat_pos[i, a] - r_ant[a]) / rho[i]
            rel_v[i, a] = sat_vel[i, a] - v_ant[a]
            rate[i] += e[i, a] * rel_v[i, a]
        for b in range(3):
            e_n[i, b] = 0.0
            for a in range(3):
                e_n[i, b] += e[i, a] * c_ne[a, b]


@njit(cache=True)
def dd_model_into(x, kinds, sat_k, sat_j, sat_pos, sat_vel, base_range, base_rate,
                  amb_state, wavelengths, lever, frame, h, jac):
    """Kernel of dd_model_and_jacobian: writes h (m,) and the non-zero entries of jac
    (m, n), which the caller has zeroed. Chain rule: r_ant^e = r0 + C_ne (r + C L),
    v_ant^e = C_ne C (v + ω×L); ∂r_ant/∂θ_m = C_ne (∂C/∂θ_m) L, ∂v_ant/∂θ_m = C_ne (∂C/∂θ_m) u."""
    c_bn = np.empty((3, 3))
    c_ne = np.empty((3, 3))
    r_ant = np.empty(3)
    v_ant = np.empty(3)
    dr_dth = np.zeros((3, 3))             # (enu, θ_m) = (∂C/∂θ_m) L
    dv_dth = np.zeros((3, 3))
    _antenna_state_into(x, lever, frame, c_bn, c_ne, r_ant, v_ant, dr_dth, dv_dth)
    n_s = sat_pos.shape[0]
    rho = np.empty(n_s)
    rate = np.empty(n_s)
    e = np.empty((n_s, 3))                # ECEF unit vectors rover → satellite
    e_n = np.empty((n_s, 3))              # their ENU components
    rel_v = np.empty((n_s, 3))
    _lines_of_sight_into(sat_pos, sat_vel, r_ant, v_ant, c_ne, rho, rate, e, e_n, rel_v)
    g_r = np.empty(3)
    g_v = np.empty(3)
    for row in range(kinds.shape[0]):
        k, j = sat_k[row], sat_j[row]
        kind = kinds[row]
        if kind == OBS_DOPPLER:
            h[row] = (rate[k] - base_rate[k]) - (rate[j] - base_rate[j])
            # ρ̇ = e·(ṡ − v): ∂/∂v_ant = −e ; ∂e/∂r_ant = −(I − e eᵀ)/ρ
            for b in range(3):
                g_v[b] = -(e_n[k, b] - e_n[j, b])
                acc = 0.0
                for a in range(3):
                    pk = (rel_v[k, a] - e[k, a] * rate[k]) / rho[k]
                    pj = (rel_v[j, a] - e[j, a] * rate[j]) / rho[j]
                    acc += (pk - pj) * c_ne[a, b]
                g_r[b] = -acc
            for b in range(3):
                jac[row, I_POS + b] = g_r[b]
                th = 0.0
                vb = 0.0
                for a in range(3):
                    th += g_r[a] * dr_dth[a, b] + g_v[a] * dv_dth[a, b]
                    vb += g_v[a] * c_bn[a, b]
                jac[row, I_ATT + b] = th
                jac[row, I_VEL + b] = vb
            # ∂(ω×L)/∂ω = −[L×]: row b of (g_v C) times −[L×]
            gc0 = g_v[0] * c_bn[0, 0] + g_v[1] * c_bn[1, 0] + g_v[2] * c_bn[2, 0]
            gc1 = g_v[0] * c_bn[0, 1] + g_v[1] * c_bn[1, 1] + g_v[2] * c_bn[2, 1]
            gc2 = g_v[0] * c_bn[0, 2] + g_v[1] * c_bn[1, 2] + g_v[2] * c_bn[2, 2]
            jac[row, I_RATE] = -gc1 * lever[2] + gc2 * lever[1]
            jac[row, I_RATE + 1] = gc0 * lever[2] - gc2 * lever[0]
            jac[row, I_RATE + 2] = -gc0 * lever[1] + gc1 * lever[0]
        else:
            h[row] = (rho[k] - base_range[k]) - (rho[j] - base_range[j])
            for b in range(3):
                g_r[b] = -(e_n[k, b] - e_n[j, b])
            for b in range(3):
                jac[row, I_POS + b] = g_r[b]
                th = 0.0
                for a in range(3):
                    th += g_r[a] * dr_dth[a, b]
                jac[row, I_ATT + b] = th
            if kind == OBS_L1 or kind == OBS_L2:
                f = kind - OBS_L1
                ik, ij = amb_state[f, k], amb_state[f, j]
                h[row] += wavelengths[f] * (x[ik] - x[ij])
                jac[row, ik] += wavelengths[f]
                jac[row, ij] -= wavelengths[f]


def _skew(u):
    return np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])


def _so3_exp_and_right_jacobian(phi):
    """exp([φ×]) and the right Jacobian J_r(φ) = I − (1−cos θ)/θ² [φ×] + (θ−sin θ)/θ³ [φ×]²
    (exp([(φ+δ)×]) ≈ exp([φ×]) exp([(J_r δ)×]))."""
    th2 = float(phi @ phi)
    px = _skew(phi)
    px2 = px @ px
    if th2 < 1e-12:
        return np.eye(3) + px + 0.5 * px2, np.eye(3) - 0.5 * px + px2 / 6.0
    th = np.sqrt(th2)
    s, c = np.sin(th), np.cos(th)
    exp_m = np.eye(3) + (s / th) * px + ((1.0 - c) / th2) * px2
    jr = np.eye(3) - ((1.0 - c) / th2) * px + ((th - s) / (th2 * th)) * px2
    return exp_m, jr


def tdcp_model_and_jacobian(x, dt, sat_k, sat_j, sat_pos, base_range, prev_sat_pos,
                            prev_base_range, lever_arm, frame):
    """Predicted DD TDCP h (m,) in metres and Jacobian H (m, n) from the current state x
    (module docstring): rows sat_k vs sat_j (indices into both epochs' arrays, aligned),
    sat_pos / prev_sat_pos (n_s, 3) ECEF at t_k / t_{k−1}, base_range / prev_base_range
    (n_s,) m, dt = t_k − t_{k−1} (s)."""
    n = x.shape[0]
    m = len(sat_k)
    c_bn = dcm_body_to_nav(x[I_PITCH], x[I_ROLL], x[I_HEADING])
    dc = np.empty((3, 3, 3))
    dcm_body_to_nav_partials_into(x[I_PITCH], x[I_ROLL], x[I_HEADING], dc[0], dc[1], dc[2])
    c_ne = frame[FRAME_C_EN].reshape(3, 3).T
    lever = np.asarray(lever_arm, float)
    v, a, om = x[VEL], x[ACC], x[RATE]
    exp_m, jr = _so3_exp_and_right_jacobian(-om * dt)
    lever_prev = exp_m @ lever                              # C_{k−1} L = C E L
    jerk = np.cross(om, a)                                  # ĵ = ω×a (steady manoeuvre)
    dt2, dt3 = dt * dt, dt * dt * dt / 6.0
    back = -(v * dt - 0.5 * a * dt2 + jerk * dt3) + lever_prev   # body-frame offset from r
    r_now = frame[FRAME_ORIGIN_ECEF] + c_ne @ (x[POS] + c_bn @ lever)
    r_prev = frame[FRAME_ORIGIN_ECEF] + c_ne @ (x[POS] + c_bn @ back)

    def unit_enu(sp, r_ant):
        los = sp - r_ant
        rho = np.linalg.norm(los, axis=1)
        return rho, (los / rho[:, None]) @ c_ne

    rho_now, e_now = unit_enu(sat_pos, r_now)
    rho_prev, e_prev = unit_enu(prev_sat_pos, r_prev)
    dr_now = np.stack([dc[i] @ lever for i in range(3)], axis=1)     # (3 enu, 3 θ)
    dr_prev = np.stack([dc[i] @ back for i in range(3)], axis=1)
    om_x = _skew(om)
    d_prev_d_a = c_bn @ (0.5 * dt2 * np.eye(3) - om_x * dt3)        # ∂r_ant,k−1/∂a
    d_prev_d_om = c_bn @ (exp_m @ _skew(lever) @ jr * dt + _skew(a) * dt3)   # ∂/∂ω
    h = np.empty(m)
    jac = np.zeros((m, n))
    for row in range(m):
        k, j = sat_k[row], sat_j[row]
        dd_now = (rho_now[k] - base_range[k]) - (rho_now[j] - base_range[j])
        dd_prev = (rho_prev[k] - prev_base_range[k]) - (rho_prev[j] - prev_base_range[j])
        h[row] = dd_now - dd_prev
        g_now = -(e_now[k] - e_now[j])
        g_prev = -(e_prev[k] - e_prev[j])
        jac[row, POS] = g_now - g_prev
        jac[row, VEL] = g_prev @ c_bn * dt
        jac[row, ACC] = -g_prev @ d_prev_d_a
        jac[row, ATT] = g_now @ dr_now - g_prev @ dr_prev
        jac[row, RATE] = -g_prev @ d_prev_d_om
    return h, jac
