"""The GMIKF epoch loop: total-state EKF in which every sensor, the IMU included, is a
measurement update (001 ch. 4-5). Numba-compiled; processes a chunk of epochs per call
so Python can report progress between chunks; no allocation inside the epoch loop.

One epoch is a chain of stages named after the equations they compute:

    predict                 x⁻ = f(x), P⁻ = Φ P Φᵀ + Λ Q(Δt) Λᵀ        (5.1.1, 5.1.2)
    assemble_epoch_rows     z, h(x⁻), H, R of every sensor present     (4.1.39-4.1.49)
    innovations             d = z − h(x⁻), D = H P⁻ Hᵀ + R
    group_outlier_tests     local χ² per group and z per observation    (§5.2.3.1)
    kalman_update           K = P⁻ Hᵀ D⁻¹, x = x⁻ + K d, P = P⁻ − K H P⁻
    vce_terms               v_z, r_z, v_w, r_w, r_x, Helmert sums     (2.7.13-2.7.23)
    record_state            x, √diag P, covariance blocks

The per-epoch inputs, settings, scratch buffers and records each travel as one numba
namedtuple (:data:`EpochInputs`, :data:`KernelSettings`, :data:`Workspace`,
:data:`EpochRecords`): a namedtuple of arrays is a plain struct of pointers in numba, so
the stages take a handful of arguments, compile with cache=True and inline like the
former single body.

Measurement slots of one epoch (``SLOT_*``): 0-5 IMU gyro x,y,z / accel x,y,z, 6-8 GNSS
position E,N,U, 9-11 GNSS velocity E,N,U, 12 heading, 13-15 zero-velocity update v^b = 0
and 16-18 zero-angular-rate update ω = 0 (ZUPT/ZARU, 000 eq. 5.44-5.46, at the epochs
flagged in ``zupt_on``), 19-20 GNSS speed over ground and course (gmis.speed_course),
21-22 non-holonomic constraint (lateral, vertical;
pseudo-observations z = 0 at the epochs flagged in ``nhc_on``). All
sensors present at an epoch are stacked into ONE update. Outlier tests per group (001
§5.2.3.1): local χ² on the group's innovations with the group block of D = HP⁻Hᵀ + R, and
a z-test per observation; an observation failing its z-test is rejected; a group failing
χ² with no single z failure is rejected whole. Rejected observations do not update the
state and are flagged.

Per-epoch records hold what VCE needs (001 eq. 2.7.13-2.7.23, see vce/): measurement
residuals v_z = ẑ − z = −R D⁻¹ d and redundancy r_z = diag(R D⁻¹), process-noise
residuals v_w = Q Λᵀ Hᵀ D⁻¹ d and redundancy r_w = diag(Q Λᵀ Hᵀ D⁻¹ H Λ), and r_x, computed from
the innovation without inverting P⁻; r_z + r_w + r_x equals the number of observations.
"""

from collections import namedtuple

import numpy as np
from numba import njit

from gmis.dense import (
    back_substitute_row,
    cholesky_inplace,
    cholesky_solve_inplace,
)
from gmis.gnss_error_states import (
    N_GNSS_ERROR_STATES,
    accumulate_gnss_error_noise,
    add_gnss_error_to_position_rows,
    predict_gnss_error_states,
    reset_gnss_error_noise,
)
from gmis.lockout_recovery import recover_lockout
from gmis.measurement_models import (
    baseline_heading_model_and_jacobian_into,
    gnss_position_model_and_jacobian_into,
    gnss_velocity_model_and_jacobian_into,
    imu_model_and_jacobian_into,
    imu_scale_column_from_neighbours,
    nonholonomic_model_and_jacobian_into,
    zero_motion_model_and_jacobian_into,
)
from gmis.reverse_step import invert_forward_step
from gmis.speed_course import speed_course_model_and_jacobian_into
from gmis.state import (
    I_ATT,
    I_HEADING,
    I_POS,
    I_SG,
    I_VEL,
    I_W_DRIFT,
    N_DYNAMIC,
    N_KINEMATIC_NOISE,
    N_STATES_27,
)
from gmis.system_model import (
    decay_drift_states_into,
    drift_noise_variance,
    propagate_state_into,
    transition_jacobians_into,
)

N_SLOTS = 23
SLOT_IMU = 0
SLOT_POS = 6
SLOT_VEL = 9
SLOT_HEADING = 12
SLOT_ZUPT = 13
SLOT_ZARU = 16
SLOT_SPEED = 19
SLOT_COURSE = 20
SLOT_NHC = 21
GROUP_START = np.array([0, 6, 9, 12, 13, 16, 19, 21], dtype=np.int64)
GROUP_SIZE = np.array([6, 3, 3, 1, 3, 3, 2, 2], dtype=np.int64)
# GNSS position, velocity, heading, speed/course
AIDING_GROUPS = np.array([1, 2, 3, 6], dtype=np.int64)
GROUP_NAMES = ("imu", "gnss_position", "gnss_velocity", "heading", "zupt", "zaru",
               "gnss_speed_course", "nonholonomic")
SLOT_NAMES = ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z",
              "pos_e", "pos_n", "pos_u", "vel_e", "vel_n", "vel_u", "heading",
              "zupt_x", "zupt_y", "zupt_z", "zaru_x", "zaru_y", "zaru_z",
              "speed", "course", "nhc_lateral", "nhc_vertical")
COV_BLOCK_START = np.array([I_POS, I_VEL, I_ATT], dtype=np.int64)  # r^n, v^b, θ

EpochInputs = namedtuple("EpochInputs", (
    "t",          # (E,) epoch times, s
    "imu_idx", "pos_idx", "vel_idx", "hdg_idx",   # (E,) rows of the streams, -1 absent
    "imu_z",      # (N, 6) gyro rad/s, accel m/s²
    "imu_sd",     # (6,) 1σ
    "pos_z", "pos_sd", "vel_z", "vel_sd",         # (M, 3) m, m/s
    "hdg_z", "hdg_sd",                            # (H,) rad
    "still",      # (E,) bool, vehicle at rest
    "nhc_on",     # (E,) bool, apply the non-holonomic pseudo-observations
    "zupt_on",    # (E,) bool, apply ZUPT/ZARU (vehicle stopped, gmis.motion)
    "sog_idx",    # (E,) row of the speed/course stream, -1 absent (empty: no stream)
    "sog_z", "sog_sd",                            # (S, 2) [m/s, rad]; course σ ≤ 0 or
                                                  # NaN = course absent
), defaults=(np.zeros(0, dtype=np.int64), np.zeros((0, 2)), np.zeros((0, 2))))
KernelSettings = namedtuple("KernelSettings", (
    "n_imu",           # 21 or 27 IMU states
    "q_psd",           # (nw,) process-noise spectral densities (state.py noise layout):
                       # jerk (m/s³)²·s, ω̇ (rad/s²)²·s, drifts unit²/s
    "q_step_var",      # (nw,) the configured per-step variances q_sd², which VCE divides
                       # v_w² by
    "static_q_scale",  # jerk / angular-acceleration factor at rest (001 Table 4-3)
    "lever_arm",       # (3,) GNSS antenna, m body
    "frame",           # navigation frame vector (gmis.earth.make_nav_frame)
    "nhc_sd",          # (2,) m/s
    "nhc_lever_arm",   # (3,) m body
    "chi2_crit",       # (N_SLOTS + 1,) χ²(m) critical values
    "z_crit",          # z-test critical value
    "outlier_on",      # bool
    "compute_vce",     # 0 plain, 1 VCE records + Helmert sums, 2 also r_x
    "n_vce_noise",     # process-noise axes with VCE residuals
    "consider_scale_imu",  # bool: the IMU rows do not update S (drop_imu_scale_gain)
    "zupt_sd",         # (3,) m/s, ZUPT 1σ of v^b (000 eq. 5.46)
    "zaru_sd",         # (3,) rad/s, ZARU 1σ of ω
    "reopen_after",    # consecutive rejected epochs of an aiding group before its
                       # covariance is re-opened (gmis.lockout_recovery); 0 = never
    "p0_var",          # (n,) initial variances, the floor of a re-opened covariance
    "test_imu",        # bool: the IMU group takes part in the outlier tests
    "drift_inv_tau",   # (≥ n_imu − 15,) 1/τ (1/s) of Gauss-Markov drift states, 0 = random
                       # walk (gmis.system_model.decay_drift_states_into)
    "heading_baseline",  # (3,) m body: dual-antenna baseline of the heading row, 0 = ψ
    "gnss_err_inv_tau",  # (3,) 1/τ (1/s) of the GNSS fix-error states at n_imu..n_imu+2
                         # (gmis.gnss_error_states); zeros = no such states
    "gnss_err_var",      # (3,) their stationary variance σ_b², m²
), defaults=(np.zeros(12), np.zeros(3), np.zeros(3), np.zeros(3)))
EpochRecords = namedtuple("EpochRecords", (
    "x", "sd", "cov_blocks", "innov", "innov_var", "rejected", "vz", "rz", "vw", "rw",
    "rx", "nobs", "rvar", "helmert_s", "helmert_totals",
    "streak",     # (n_groups,) int64: current run of rejected epochs per group (carried
                  # across chunks)
    "reopened",   # (E,) int8 bitmask: groups whose covariance was re-opened at epoch e
    "nll",        # (E,) log det D + dᵀD⁻¹d of the epoch's update (gmis.latency_estimation);
                  # empty = not recorded
    "helmert_trunc",  # (N_SLOTS + nw + 1,) outlier-test truncation weights w_i of the
                      # elementary components, then w of Σ dᵀD⁻¹d (truncation_terms);
                      # empty = not accumulated
), defaults=(np.zeros(0), np.zeros(0)))
Workspace = namedtuple("Workspace", (
    "q_var", "phi", "lam", "work", "x_new", "w_zero", "h_all",
    "hx_all", "z_all", "r_all", "present", "used", "d", "hp", "s", "sl", "sinv_d",
    "gblock", "gvec", "l_inv_hp", "hl", "sinv_hl", "p_prior_pred", "dinv", "sf_work",
    "h_cols", "h_ncols", "l_inv_d", "row", "gain_scale"))
# H rows are used through their non-zero columns (h_cols[slot, :h_ncols[slot]]), found
# from the numbers each epoch; skipping an exact zero term leaves every sum unchanged.


# Block structure of phi_dyn (system_model.transition_jacobians_into; 3-blocks r, v, a,
# θ, ω): row block b has non-zero columns only in [PHI_LO1, PHI_HI1) ∪ [PHI_LO2, PHI_HI2)
# (propagate_covariance spells the same ranges as literals).
PHI_LO1 = np.array([0, 3, 6, 9, 12], dtype=np.int64)
PHI_HI1 = np.array([12, 9, 9, 15, 15], dtype=np.int64)
PHI_LO2 = np.array([12, 12, 12, 15, 15], dtype=np.int64)
PHI_HI2 = np.array([12, 15, 15, 15, 15], dtype=np.int64)
# Noise columns [LAM_LO, LAM_HI) of Λ_dyn's row block b (r v a θ ω) that can be non-zero:
# jerk 0-2, angular acceleration 3-5 (tests/test_kernel_structure.py checks the pattern)
LAM_LO = np.array([0, 0, 0, 3, 3], dtype=np.int64)
LAM_HI = np.array([3, 6, 6, 6, 6], dtype=np.int64)


@njit(cache=True, inline="always")
def _phi_rows_times(phi, p, work, r0, lo1, hi1, lo2, hi2, n):
    """work[r0:r0+3, :n] = phi[r0:r0+3, cols] p[cols, :n], cols = [lo1, hi1) ∪ [lo2, hi2)."""
    for i in range(r0, r0 + 3):
        for j in range(n):
            acc = 0.0
            for k in range(lo1, hi1):
                acc += phi[i, k] * p[k, j]
            for k in range(lo2, hi2):
                acc += phi[i, k] * p[k, j]
            work[i, j] = acc


@njit(cache=True, inline="always")
def _times_phi_rows(work, phi, p, i, r0, lo1, hi1, lo2, hi2):
    """p[i, j] = work[i, cols] phi[j, cols]ᵀ for the rows j ≥ i of the block at r0."""
    for j in range(max(i, r0), r0 + 3):
        acc = 0.0
        for k in range(lo1, hi1):
            acc += work[i, k] * phi[j, k]
        for k in range(lo2, hi2):
            acc += work[i, k] * phi[j, k]
        p[i, j] = acc


@njit(cache=True, inline="always")
def _r_rows_times(phi, p, work, n):
    """work[0:3, :n] = phi[0:3, 0:12] p[0:12, :n] with Φ_rr = I: of the r columns only
    the diagonal 1 (1·p exact; the two zeros add nothing), then v a θ."""
    for i in range(3):
        for j in range(n):
            acc = 0.0 + p[i, j]
            for k in range(3, 12):
                acc += phi[i, k] * p[k, j]
            work[i, j] = acc


@njit(cache=True, inline="always")
def _times_r_rows(work, phi, p, i):
    """p[i, j] = work[i, 0:12] phi[j, 0:12]ᵀ for j ≥ i of the r block (Φ_rr = I)."""
    for j in range(i, 3):
        acc = 0.0 + work[i, j]
        for k in range(3, 12):
            acc += work[i, k] * phi[j, k]
        p[i, j] = acc


@njit(cache=True, inline="always")
def propagate_covariance(p, n, phi, work):
    """P ← Φ P Φᵀ with Φ = blockdiag(phi_dyn (15×15), I) (001 eq. 5.1.2), over the
    non-zero blocks of phi_dyn only (108 of its 225 entries; 3-blocks r v a θ ω):
    r' ← r v a θ, v' ← v a ω, a' ← a ω, θ' ← θ ω, ω' ← ω (tests/test_kernel_structure.py
    checks the pattern against system_model). work (15, n) = Φ_dyn P[dyn, :]; only the
    upper triangle of the dynamic block is formed (add_process_noise mirrors it). The
    identity blocks Φ_rr = I and Φ_ωω = I (also checked there) give their row as
    0.0 + the other factor's entry. The sums run over the dense product's terms in its
    order less exact zeros (x + ±0 = x for a sum started at +0.0; 1·y = y), so P is
    unchanged bit for bit."""
    _r_rows_times(phi, p, work, n)
    _phi_rows_times(phi, p, work, 3, 3, 9, 12, 15, n)
    _phi_rows_times(phi, p, work, 6, 6, 9, 12, 15, n)
    _phi_rows_times(phi, p, work, 9, 9, 15, 15, 15, n)
    for i in range(12, 15):          # ω' ← ω: Φ_ωω = I
        for j in range(n):
            work[i, j] = 0.0 + p[i, j]
    for i in range(N_DYNAMIC):
        if i < 3:
            _times_r_rows(work, phi, p, i)
        if i < 6:
            _times_phi_rows(work, phi, p, i, 3, 3, 9, 12, 15)
        if i < 9:
            _times_phi_rows(work, phi, p, i, 6, 6, 9, 12, 15)
        if i < 12:
            _times_phi_rows(work, phi, p, i, 9, 9, 15, 15, 15)
        for j in range(max(i, 12), 15):
            p[i, j] = 0.0 + work[i, j]
        for j in range(N_DYNAMIC, n):
            p[i, j] = work[i, j]
            p[j, i] = work[i, j]


@njit(cache=True, inline="always")
def add_process_noise(p, lam, q_var, n_imu):
    """P ← P + Λ Q Λᵀ: the jerk/angular-acceleration part through lam (15×6), bias and
    scale-factor drifts on the diagonal (q_var: per-step variances, 001 Table 6-2).
    Mirrors the upper triangle of the dynamic block into the lower. Λ's row blocks take
    only part of the noise (system_model.transition_jacobians_into; LAM_LO/LAM_HI): r, v, a
    (rows < 9) the jerk (columns 0-2), v, a, θ, ω (rows ≥ 3) the angular acceleration
    (columns 3-5). Each sum (i ≤ j) runs over the columns both rows have: the terms left
    out are exact zeros, so the sums are the dense ones bit for bit."""
    for i in range(N_DYNAMIC):
        for j in range(i, N_DYNAMIC):
            s = 0.0
            if j < 9:
                for k in range(3):
                    s += lam[i, k] * q_var[k] * lam[j, k]
            if i >= 3:
                for k in range(3, N_KINEMATIC_NOISE):
                    s += lam[i, k] * q_var[k] * lam[j, k]
            p[i, j] += s
            if j != i:
                p[j, i] = p[i, j]
    for i in range(n_imu - N_DYNAMIC):
        p[N_DYNAMIC + i, N_DYNAMIC + i] += q_var[I_W_DRIFT + i]


@njit(cache=True, inline="always")
def process_noise_variances(dt, kin_scale, q_psd, drift_inv_tau, q_var):
    """Q(Δt) of one step of dt s from the spectral densities (docs/DESIGN.md "Process
    noise from Δt"): the jerk / angular acceleration held over the step with variance
    q/dt (times kin_scale, the at-rest factor), so a^b and ω random-walk by q·dt; the
    drifts random-walk by q·dt, or are Gauss-Markov (drift_noise_variance). A negative dt
    (the backward filter of gmis.smoother runs over reversed epochs) gets the variances of
    |dt|."""
    adt = abs(dt)
    for k in range(q_psd.shape[0]):
        if k < N_KINEMATIC_NOISE:
            q_var[k] = q_psd[k] / adt * kin_scale
        else:
            q_var[k] = drift_noise_variance(q_psd[k], adt, drift_inv_tau[k - N_KINEMATIC_NOISE])


@njit(cache=True, inline="always")
def _innovation_covariance(ws, m):
    """D = H P Hᵀ + R for the m slots listed in ws.used, from ws.hp = H P over the
    non-zero columns of each H row."""
    h_all, r_all, used, hp, s, h_cols = ws.h_all, ws.r_all, ws.used, ws.hp, ws.s, ws.h_cols
    h_ncols = ws.h_ncols
    for a in range(m):
        i = used[a]
        for b in range(a, m):
            acc = 0.0
            for q in range(h_ncols[i]):
                k = h_cols[i, q]
                acc += h_all[i, k] * hp[b, k]
            s[a, b] = acc
            s[b, a] = acc
        s[a, a] += r_all[i]


@njit(cache=True)
def make_workspace(n, nw):
    """Every scratch buffer of the epoch loop, allocated once per chunk; q_var holds the
    last prediction's per-step variances Q(Δt), then the GNSS fix-error driving noise
    accumulated for VCE (gmis.gnss_error_states)."""
    return Workspace(
        np.zeros(nw + N_GNSS_ERROR_STATES), np.zeros((N_DYNAMIC, N_DYNAMIC)),
        np.zeros((N_DYNAMIC, N_KINEMATIC_NOISE)), np.zeros((N_DYNAMIC, n)), np.zeros(n),
        np.zeros(nw), np.zeros((N_SLOTS, n)), np.zeros(N_SLOTS), np.zeros(N_SLOTS),
        np.zeros(N_SLOTS), np.zeros(N_SLOTS, dtype=np.bool_),
        np.zeros(N_SLOTS, dtype=np.int64), np.zeros(N_SLOTS), np.zeros((N_SLOTS, n)),
        np.zeros((N_SLOTS, N_SLOTS)), np.zeros((N_SLOTS, N_SLOTS)), np.zeros((N_SLOTS, 1)),
        np.zeros((N_SLOTS, N_SLOTS)), np.zeros((N_SLOTS, 1)), np.zeros((N_SLOTS, n)),
        np.zeros((N_SLOTS, 18 + N_GNSS_ERROR_STATES)),
        np.zeros((N_SLOTS, 18 + N_GNSS_ERROR_STATES)), np.zeros((n, n)),
        np.zeros((N_SLOTS, N_SLOTS)), np.zeros(N_SLOTS),
        np.zeros((N_SLOTS, n), dtype=np.int64), np.zeros(N_SLOTS, dtype=np.int64),
        np.zeros(N_SLOTS), np.zeros(n), np.zeros((6, N_SLOTS)))


# ------------------------------------------------------------------ the stages


@njit(cache=True, inline="always")
def predict(x, p, dt, n_imu, q_psd, kin_scale, keep_prior, ws, drift_inv_tau):
    """x ← f(x, 0), P ← Φ P Φᵀ + Λ Q(dt) Λᵀ over dt s (001 eq. 5.1.1/5.1.2), Q(dt) from
    the spectral densities q_psd (process_noise_variances, into ws.q_var). keep_prior:
    also keep Φ P Φᵀ (without Q) in ws.p_prior_pred for the independent r_x.
    drift_inv_tau: 1/τ of Gauss-Markov drift states (0 = random walk)."""
    q_var, phi, lam, work, x_new = ws.q_var, ws.phi, ws.lam, ws.work, ws.x_new
    w_zero, p_prior_pred = ws.w_zero, ws.p_prior_pred
    n = x.shape[0]
    process_noise_variances(dt, kin_scale, q_psd, drift_inv_tau, q_var)
    transition_jacobians_into(x, dt, phi, lam)
    propagate_state_into(x, w_zero, dt, n_imu, x_new)
    for i in range(n):
        x[i] = x_new[i]
    propagate_covariance(p, n, phi, work)
    decay_drift_states_into(x, p, dt, drift_inv_tau, n_imu)
    if keep_prior:
        for i in range(n):
            for j in range(n):
                p_prior_pred[i, j] = p[i, j] if j >= i or i >= N_DYNAMIC else p[j, i]
    add_process_noise(p, lam, q_var, n_imu)


@njit(cache=True, inline="always")
def _take_rows(z_src, sd_src, row, slot0, count, ws):
    """z and R = σ² of one sensor's rows into the epoch's slots slot0..slot0+count."""
    z_all, r_all, present = ws.z_all, ws.r_all, ws.present
    for i in range(count):
        z_all[slot0 + i] = z_src[row, i]
        r_all[slot0 + i] = sd_src[row, i] ** 2
        present[slot0 + i] = True


@njit(cache=True, inline="always")
def assemble_epoch_rows(e, x, inp, cfg, ws):
    """z, h(x⁻), H and R of every sensor present at epoch e into the slot arrays: IMU
    (001 eq. 4.1.39/4.1.40), GNSS position/velocity (4.1.41/4.1.42), heading (4.1.43),
    ZUPT/ZARU (000 eq. 5.44-5.46), non-holonomic pseudo-observations (000 eq. 5.41)."""
    h_all, hx_all, z_all, r_all, present = ws.h_all, ws.hx_all, ws.z_all, ws.r_all, ws.present
    imu_idx, pos_idx, vel_idx, hdg_idx = inp.imu_idx, inp.pos_idx, inp.vel_idx, inp.hdg_idx
    imu_z, imu_sd, pos_z, pos_sd = inp.imu_z, inp.imu_sd, inp.pos_z, inp.pos_sd
    vel_z, vel_sd, hdg_z, hdg_sd = inp.vel_z, inp.vel_sd, inp.hdg_z, inp.hdg_sd
    nhc_on, zupt_on = inp.nhc_on, inp.zupt_on
    lever_arm, frame, nhc_sd = cfg.lever_arm, cfg.frame, cfg.nhc_sd
    nhc_lever_arm, zupt_sd, zaru_sd = cfg.nhc_lever_arm, cfg.zupt_sd, cfg.zaru_sd
    for i in range(N_SLOTS):
        present[i] = False
    if imu_idx[e] >= 0:
        imu_model_and_jacobian_into(x, cfg.n_imu, frame, hx_all, SLOT_IMU, h_all,
                                    SLOT_IMU)
        if cfg.consider_scale_imu and cfg.n_imu >= N_STATES_27 and not inp.still[e]:
            imu_scale_column_from_neighbours(x, imu_z, imu_idx[e], h_all, SLOT_IMU)
        for i in range(6):
            z_all[SLOT_IMU + i] = imu_z[imu_idx[e], i]
            r_all[SLOT_IMU + i] = imu_sd[i] * imu_sd[i]
            present[SLOT_IMU + i] = True
    if pos_idx[e] >= 0:
        gnss_position_model_and_jacobian_into(x, lever_arm, hx_all, SLOT_POS,
                                              h_all, SLOT_POS)
        if cfg.gnss_err_inv_tau[0] > 0.0:
            add_gnss_error_to_position_rows(x, cfg.n_imu, hx_all, h_all, SLOT_POS)
        _take_rows(pos_z, pos_sd, pos_idx[e], SLOT_POS, 3, ws)
    if vel_idx[e] >= 0:
        gnss_velocity_model_and_jacobian_into(x, lever_arm, hx_all, SLOT_VEL,
                                              h_all, SLOT_VEL)
        _take_rows(vel_z, vel_sd, vel_idx[e], SLOT_VEL, 3, ws)
    if hdg_idx[e] >= 0:
        baseline_heading_model_and_jacobian_into(x, cfg.heading_baseline, hx_all,
                                                 SLOT_HEADING, h_all, SLOT_HEADING)
        z_all[SLOT_HEADING] = hdg_z[hdg_idx[e]]
        r_all[SLOT_HEADING] = hdg_sd[hdg_idx[e]] ** 2
        present[SLOT_HEADING] = True
    sog_idx = inp.sog_idx
    if sog_idx.shape[0] > e and sog_idx[e] >= 0:
        row = sog_idx[e]
        if speed_course_model_and_jacobian_into(x, lever_arm, hx_all, SLOT_SPEED, h_all,
                                                SLOT_SPEED):
            z_all[SLOT_SPEED] = inp.sog_z[row, 0]
            r_all[SLOT_SPEED] = inp.sog_sd[row, 0] ** 2
            present[SLOT_SPEED] = True
            if inp.sog_sd[row, 1] > 0.0:          # False for NaN: course absent
                z_all[SLOT_COURSE] = inp.sog_z[row, 1]
                r_all[SLOT_COURSE] = inp.sog_sd[row, 1] ** 2
                present[SLOT_COURSE] = True
    if zupt_on[e]:
        zero_motion_model_and_jacobian_into(x, hx_all, SLOT_ZUPT, h_all, SLOT_ZUPT)
        for i in range(6):
            z_all[SLOT_ZUPT + i] = 0.0
            sd = zupt_sd[i] if i < 3 else zaru_sd[i - 3]
            r_all[SLOT_ZUPT + i] = sd * sd
            present[SLOT_ZUPT + i] = True
    if nhc_on[e]:
        nonholonomic_model_and_jacobian_into(x, nhc_lever_arm, hx_all, SLOT_NHC,
                                             h_all, SLOT_NHC)
        for i in range(2):
            z_all[SLOT_NHC + i] = 0.0
            r_all[SLOT_NHC + i] = nhc_sd[i] * nhc_sd[i]
            present[SLOT_NHC + i] = True


@njit(cache=True, inline="always")
def clear_epoch_records(e, nw, ws, rec):
    """NaN / 0 for everything epoch e may not reach; R of the present slots."""
    r_all, present = ws.r_all, ws.present
    innov, innov_var, rejected, vz, rz = rec.innov, rec.innov_var, rec.rejected, rec.vz, rec.rz
    vw, rw, rx, nobs, rvar = rec.vw, rec.rw, rec.rx, rec.nobs, rec.rvar
    for i in range(N_SLOTS):
        innov[e, i] = np.nan
        innov_var[e, i] = np.nan
        rejected[e, i] = 0
        rvar[e, i] = r_all[i] if present[i] else np.nan
        vz[e, i] = np.nan
        rz[e, i] = np.nan
    for i in range(vw.shape[1]):    # nw, + the fix-error axes with VCE
        vw[e, i] = np.nan
        rw[e, i] = np.nan
    rx[e] = np.nan
    nobs[e] = 0


@njit(cache=True, inline="always")
def _h_row_times_p(ws, a, i, p, n):
    """Row a of H P from slot i's H row over its non-zero columns (listed into
    ws.h_cols[i, :ws.h_ncols[i]])."""
    h_all, hp, h_cols, h_ncols = ws.h_all, ws.hp, ws.h_cols, ws.h_ncols
    cnt = 0
    for k in range(n):
        if h_all[i, k] != 0.0:
            h_cols[i, cnt] = k
            cnt += 1
    h_ncols[i] = cnt
    for j in range(n):
        hp[a, j] = 0.0
    for q in range(cnt):
        k = h_cols[i, q]
        hk = h_all[i, k]
        for j in range(n):
            hp[a, j] += p[k, j] * hk


@njit(cache=True, inline="always")
def innovations(e, p, ws, rec):
    """d = z − h(x⁻) (heading wrapped to [−π, π)), H P⁻ (= (P⁻ Hᵀ)ᵀ, P symmetric) over
    the non-zero columns of each H row, and D = H P⁻ Hᵀ + R for the present slots,
    listed in ws.used; returns their number m."""
    hx_all, z_all, present, used, d, s = ws.hx_all, ws.z_all, ws.present, ws.used, ws.d, ws.s
    innov, innov_var = rec.innov, rec.innov_var
    n = p.shape[0]
    m = 0
    for i in range(N_SLOTS):
        if present[i]:
            used[m] = i
            m += 1
    if m == 0:
        return 0
    for a in range(m):
        i = used[a]
        dd = z_all[i] - hx_all[i]
        if i == SLOT_HEADING or i == SLOT_COURSE:
            dd = (dd + np.pi) % (2.0 * np.pi) - np.pi
        d[a] = dd
        _h_row_times_p(ws, a, i, p, n)
    _innovation_covariance(ws, m)
    for a in range(m):
        innov[e, used[a]] = d[a]
        innov_var[e, used[a]] = s[a, a]
    return m


@njit(cache=True, inline="always")
def _in_group(slot, g0, gn):
    return slot >= g0 and slot < g0 + gn


@njit(cache=True, inline="always")
def group_outlier_test(e, g0, gn, m, chi2_crit, z_crit, ws, rec):
    """001 §5.2.3.1 for the group of slots g0..g0+gn: z-test per observation, then the
    local χ² dᵀ D_g⁻¹ d with the group block of D; flags rejections in rec.rejected."""
    used, d, s, gblock, gvec, rejected = ws.used, ws.d, ws.s, ws.gblock, ws.gvec, rec.rejected
    cnt = 0
    for a in range(m):
        if _in_group(used[a], g0, gn):
            cnt += 1
    if cnt == 0:
        return
    any_z = False
    ia = 0
    for a in range(m):
        if _in_group(used[a], g0, gn):
            ib = 0
            for b in range(m):
                if _in_group(used[b], g0, gn):
                    gblock[ia, ib] = s[a, b]
                    ib += 1
            gvec[ia, 0] = d[a]
            ia += 1
            if abs(d[a]) / np.sqrt(s[a, a]) > z_crit:
                rejected[e, used[a]] = 1
                any_z = True
    if cholesky_inplace(gblock, cnt):
        cholesky_solve_inplace(gblock, cnt, gvec, 1)
        chi2 = 0.0
        ia = 0
        for a in range(m):
            if _in_group(used[a], g0, gn):
                chi2 += d[a] * gvec[ia, 0]
                ia += 1
        if chi2 > chi2_crit[cnt] and not any_z:
            for a in range(m):
                if _in_group(used[a], g0, gn):
                    rejected[e, used[a]] = 1


@njit(cache=True, inline="always")
def refute_stop(e, m, ws, rec):
    """A stop is one hypothesis, v^b = 0 and ω = 0 (000 eq. 5.44-5.46): when any of its
    ZUPT/ZARU rows is rejected, the vehicle is not stopped and all six are dropped (else
    the rows that pass — lateral/vertical v^b and ω ≈ 0 on a straight road at speed —
    would pull the gyro biases and velocity with σ of a stop)."""
    used, rejected = ws.used, rec.rejected
    refuted = False
    for a in range(m):
        if _in_group(used[a], SLOT_ZUPT, 6) and rejected[e, used[a]] != 0:
            refuted = True
    if refuted:
        for a in range(m):
            if _in_group(used[a], SLOT_ZUPT, 6):
                rejected[e, used[a]] = 1
    return refuted


@njit(cache=True, inline="always")
def release_stop(e, still, zupt_on):
    """After a refuted stop at e the vehicle is moving: the epochs after e up to and
    including the next ZUPT/ZARU epoch (or the end of the detected stop) are not ``still``
    (their predictions get the full process noise, not the at-rest factor); the next
    ZUPT/ZARU test decides again."""
    for k in range(e + 1, still.shape[0]):
        if not still[k]:
            break
        still[k] = False
        if zupt_on[k]:
            break


@njit(cache=True, inline="always")
def drop_rejected(e, m, ws, rec):
    """Keep only the accepted observations (in order) and rebuild D; returns their count."""
    used, d, hp = ws.used, ws.d, ws.hp
    rejected = rec.rejected
    n = hp.shape[1]
    mm = 0
    for a in range(m):
        if rejected[e, used[a]] == 0:
            if mm < a:
                used[mm] = used[a]
                d[mm] = d[a]
                for j in range(n):
                    hp[mm, j] = hp[a, j]
            mm += 1
    if mm < m:
        _innovation_covariance(ws, mm)
    return mm


@njit(cache=True, inline="always")
def kalman_update(x, p, m, ws):
    """K = P Hᵀ D⁻¹, x += K d, P −= K H P, heading wrapped to [0, 2π), in the factored
    form: with D = L Lᵀ, W = L⁻¹ H P (m × n) and u = L⁻¹ d,  K d = Wᵀ u and
    K H P = Wᵀ W, so the update costs m forward substitutions of a row of n and one
    symmetric rank-m product (no n × m gain). Leaves L in ws.sl, W in ws.l_inv_hp, u in
    ws.l_inv_d and D⁻¹ d in ws.sinv_d. False if D is not PD."""
    n = x.shape[0]
    # one body for every state count: literal 27 / 21 copies (unrolled row loops) were
    # 4-6 % faster per epoch and cost 20 s of the cold compile (54 → 34 s for the kernel)
    return _kalman_update_n(x, p, m, ws, n)


@njit(cache=True, inline="always")
def _kalman_update_n(x, p, m, ws, n):
    """kalman_update for n states."""
    d, hp, s, sl, sinv_d, l_inv_hp = ws.d, ws.hp, ws.s, ws.sl, ws.sinv_d, ws.l_inv_hp
    l_inv_d, ws_row = ws.l_inv_d, ws.row
    for a in range(m):
        for b in range(m):
            sl[a, b] = s[a, b]
    if not cholesky_inplace(sl, m):
        return False
    for a in range(m):
        sinv_d[a, 0] = d[a]
    cholesky_solve_inplace(sl, m, sinv_d, 1)
    w = l_inv_hp
    if m == 6:     # an IMU-only epoch: W and x += Wᵀu one column at a time in registers
        _gain_terms_six(x, d, hp, sl, w, l_inv_d, n)
        _subtract_wtw(p, m, w, ws_row, n)
        x[I_HEADING] = x[I_HEADING] % (2.0 * np.pi)
        return True
    for a in range(m):
        for j in range(n):
            w[a, j] = hp[a, j]
        acc = d[a]
        for b in range(a):
            f = sl[a, b]
            acc -= f * l_inv_d[b]
            for j in range(n):
                w[a, j] -= f * w[b, j]
        diag = sl[a, a]
        l_inv_d[a] = acc / diag
        for j in range(n):
            w[a, j] /= diag
    for j in range(n):
        acc = 0.0
        for a in range(m):
            acc += w[a, j] * l_inv_d[a]
        x[j] += acc
    _subtract_wtw(p, m, w, ws_row, n)
    x[I_HEADING] = x[I_HEADING] % (2.0 * np.pi)
    return True


@njit(cache=True, inline="always")
def _gain_terms_six(x, d, hp, sl, w, l_inv_d, n):
    """_kalman_update_n's u = L⁻¹ d, W = L⁻¹ H P and x += Wᵀ u for m = 6: the forward
    substitution of each column of H P runs in six registers (column j of W is
    ((hp_aj − L_a0 w_0j) − L_a1 w_1j − …) / L_aa, as the row-wise loop forms it) and its
    x term (0.0 + w_0j u_0 + … + w_5j u_5) follows at once; the same operations in the same
    order as the general loop, so W, u and x are unchanged bit for bit."""
    for a in range(6):
        acc = d[a]
        for b in range(a):
            acc -= sl[a, b] * l_inv_d[b]
        l_inv_d[a] = acc / sl[a, a]
    l00, l11, l22, l33, l44, l55 = sl[0, 0], sl[1, 1], sl[2, 2], sl[3, 3], sl[4, 4], sl[5, 5]
    l10, l20, l21, l30, l31, l32 = sl[1, 0], sl[2, 0], sl[2, 1], sl[3, 0], sl[3, 1], sl[3, 2]
    l40, l41, l42, l43 = sl[4, 0], sl[4, 1], sl[4, 2], sl[4, 3]
    l50, l51, l52, l53, l54 = sl[5, 0], sl[5, 1], sl[5, 2], sl[5, 3], sl[5, 4]
    u0, u1, u2 = l_inv_d[0], l_inv_d[1], l_inv_d[2]
    u3, u4, u5 = l_inv_d[3], l_inv_d[4], l_inv_d[5]
    for j in range(n):
        w0 = hp[0, j] / l00
        w1 = (hp[1, j] - l10 * w0) / l11
        w2 = ((hp[2, j] - l20 * w0) - l21 * w1) / l22
        w3 = (((hp[3, j] - l30 * w0) - l31 * w1) - l32 * w2) / l33
        w4 = ((((hp[4, j] - l40 * w0) - l41 * w1) - l42 * w2) - l43 * w3) / l44
        w5 = (((((hp[5, j] - l50 * w0) - l51 * w1) - l52 * w2) - l53 * w3) - l54 * w4) / l55
        w[0, j] = w0
        w[1, j] = w1
        w[2, j] = w2
        w[3, j] = w3
        w[4, j] = w4
        w[5, j] = w5
        x[j] += (((((0.0 + w0 * u0) + w1 * u1) + w2 * u2) + w3 * u3) + w4 * u4) + w5 * u5


@njit(cache=True, inline="always")
def _subtract_wtw(p, m, w, row, n):
    """P −= Wᵀ W (W: m × n) on the upper triangle, mirrored into the lower. Each entry's
    m products are summed in the order a = 0 … m − 1 starting from 0.0, six rows of W at a
    time in one register accumulator per column (an IMU-only epoch, m = 6, is one pass
    straight into P); a rest of fewer than six goes one row at a time through ``row``.
    Same sums in the same order as one row of W at a time, so P is unchanged bit for bit;
    ~0.6 µs less per IMU-only epoch at 27 states (the accumulator no longer goes through
    memory for every row of W)."""
    for i in range(n):
        if m == 6:
            w0, w1, w2 = w[0, i], w[1, i], w[2, i]
            w3, w4, w5 = w[3, i], w[4, i], w[5, i]
            for j in range(i, n):
                acc = 0.0 + w0 * w[0, j]
                acc += w1 * w[1, j]
                acc += w2 * w[2, j]
                acc += w3 * w[3, j]
                acc += w4 * w[4, j]
                acc += w5 * w[5, j]
                p[i, j] -= acc
            for j in range(i + 1, n):
                p[j, i] = p[i, j]
            continue
        a0 = 0
        while a0 + 6 <= m:
            w0, w1, w2 = w[a0, i], w[a0 + 1, i], w[a0 + 2, i]
            w3, w4, w5 = w[a0 + 3, i], w[a0 + 4, i], w[a0 + 5, i]
            for j in range(i, n):
                acc = row[j] if a0 > 0 else 0.0
                acc += w0 * w[a0, j]
                acc += w1 * w[a0 + 1, j]
                acc += w2 * w[a0 + 2, j]
                acc += w3 * w[a0 + 3, j]
                acc += w4 * w[a0 + 4, j]
                acc += w5 * w[a0 + 5, j]
                row[j] = acc
            a0 += 6
        for a in range(a0, m):
            wi = w[a, i]
            for j in range(i, n):
                acc = row[j] if a > 0 else 0.0
                row[j] = acc + wi * w[a, j]
        for j in range(i, n):
            p[i, j] -= row[j]
            p[j, i] = p[i, j]


@njit(cache=True, inline="always")
def innovation_nll(m, ws):
    """log det D + dᵀ D⁻¹ d of the update just made, from its factor D = L Lᵀ (ws.sl) and
    u = L⁻¹ d (ws.l_inv_d): 2 Σ log L_aa + Σ u_a² (−2 log of the Gaussian innovation
    density less m log 2π; gmis.latency_estimation)."""
    acc = 0.0
    for a in range(m):
        acc += 2.0 * np.log(ws.sl[a, a]) + ws.l_inv_d[a] * ws.l_inv_d[a]
    return acc


@njit(cache=True, inline="always")
def drop_imu_scale_gain(x, p, m, ws):
    """Scale factors S (27 states) take no update from the IMU rows of an epoch.

    The IMU rows are the only sensor of ω and a, so their S column h_S = ω⁻ + C_n^b ω_ie
    (resp. a⁻ + …) is evaluated at a prediction that carries the previous sample's noise,
    which also enters the innovation: the update S += K_S,imu d then drifts systematically
    (errors in variables; −9 000 ppm against +1 000 ppm on the default drive, z ≈ −3.5,
    growing with the IMU noise and rate). The gain block Δ = K[S, imu] is therefore dropped
    after the optimal update (kalman_update): x_S −= Δ d_imu and, Joseph form for the
    changed gain (P(K) = P(K_opt) + (K − K_opt) D (K − K_opt)ᵀ), P_SS += Δ D_imu Δᵀ. S is
    then estimated from the aiding rows through its correlation with attitude and velocity
    (a Schmidt 'consider' treatment of S in the IMU rows); unobservable scale factors stay
    at their prior. The IMU rows are the first entries of ws.used (slots 0-5)."""
    used, d, hp, s, sl, l_inv_hp = ws.used, ws.d, ws.hp, ws.s, ws.sl, ws.l_inv_hp
    sf_work, gain_scale = ws.sf_work, ws.gain_scale
    mi = 0
    while mi < m and used[mi] < 6:
        mi += 1
    if mi == 0:
        return
    k_s = gain_scale           # K[S, :] (6 × m): row i = L⁻ᵀ W[:, S_i]
    for i in range(6):
        for a in range(m):
            k_s[i, a] = l_inv_hp[a, I_SG + i]
        back_substitute_row(sl, m, k_s, i)
    t = sf_work
    for i in range(6):
        acc = 0.0
        for a in range(mi):
            acc += k_s[i, a] * d[a]
        x[I_SG + i] -= acc
    for j in range(6):
        for a in range(mi):
            if mi == m:       # IMU-only epoch: (D Kᵀ)[a, j] = (H P)[a, S_j]
                t[a] = hp[a, I_SG + j]
            else:
                acc = 0.0
                for b in range(mi):
                    acc += s[a, b] * k_s[j, b]
                t[a] = acc
        for i in range(6):
            acc = 0.0
            for a in range(mi):
                acc += k_s[i, a] * t[a]
            p[I_SG + i, I_SG + j] += acc


@njit(cache=True, inline="always")
def measurement_redundancy(e, m, ws, rec):
    """D⁻¹ into ws.dinv; r_z = R_ii (D⁻¹)_ii, v_z = −R D⁻¹ d (001 eq. 2.7.14-2.7.16);
    returns dᵀ D⁻¹ d."""
    r_all, used, d, sl, sinv_d, dinv = ws.r_all, ws.used, ws.d, ws.sl, ws.sinv_d, ws.dinv
    vz, rz = rec.vz, rec.rz
    for a in range(m):
        for b in range(m):
            dinv[a, b] = 1.0 if a == b else 0.0
    cholesky_solve_inplace(sl, m, dinv, m)
    chi2_all = 0.0
    for a in range(m):
        i = used[a]
        rz[e, i] = r_all[i] * dinv[a, a]
        vz[e, i] = -r_all[i] * sinv_d[a, 0]
        chi2_all += d[a] * sinv_d[a, 0]
    return chi2_all


@njit(cache=True, inline="always")
def process_noise_redundancy(e, m, q_var, q_step_var, n_vce_noise, ws, rec):
    """HΛ (m × n_vce_noise; Λ = [lam; I for the drift rows]) into ws.hl, D⁻¹HΛ into
    ws.sinv_hl; v_w = q Λᵀ Hᵀ D⁻¹ d and r_w = q diag(Λᵀ Hᵀ D⁻¹ H Λ) (eq. 2.7.17-2.7.20)
    with q = Q(Δt) of this step. v_w is recorded as v_w √(q_step_var / q) so that
    v_w²/q_step_var — what vce.estimate forms from the configured q_sd² — is v_w²/q."""
    lam, h_all, used, sl, sinv_d, hl = ws.lam, ws.h_all, ws.used, ws.sl, ws.sinv_d, ws.hl
    sinv_hl = ws.sinv_hl
    rec_vw, rec_rw = rec.vw, rec.rw
    for a in range(m):
        i = used[a]
        for k in range(n_vce_noise):
            acc = 0.0
            if k < N_KINEMATIC_NOISE:
                for r in range(N_DYNAMIC):
                    acc += h_all[i, r] * lam[r, k]
            else:
                acc = h_all[i, N_DYNAMIC + (k - I_W_DRIFT)]
            hl[a, k] = acc
            sinv_hl[a, k] = acc
    cholesky_solve_inplace(sl, m, sinv_hl, n_vce_noise)
    for k in range(n_vce_noise):
        vw = 0.0
        rw = 0.0
        for a in range(m):
            vw += hl[a, k] * sinv_d[a, 0]
            rw += hl[a, k] * sinv_hl[a, k]
        rec_vw[e, k] = np.sqrt(q_var[k] * q_step_var[k]) * vw
        rec_rw[e, k] = q_var[k] * rw


@njit(cache=True, inline="always")
def helmert_terms(m, q_var, n_vce_noise, ws, helmert_s):
    """Add S_ij = tr(D⁻¹ C_i D⁻¹ C_j) (001 eq. 2.7.21-2.7.23) of the elementary components
    (slots, noise axes): C = R_a e_a e_aᵀ or q_k h_k h_kᵀ with h_k = (HΛ)_k, so every
    S_ij is a scalar product."""
    r_all, used, hl, sinv_hl, dinv = ws.r_all, ws.used, ws.hl, ws.sinv_hl, ws.dinv
    for a in range(m):
        ia = used[a]
        for b in range(a, m):
            ib = used[b]
            val = r_all[ia] * r_all[ib] * dinv[a, b] * dinv[a, b]
            helmert_s[ia, ib] += val
            if ib != ia:
                helmert_s[ib, ia] += val
        for k in range(n_vce_noise):
            u = sinv_hl[a, k]   # e_aᵀ D⁻¹ h_k
            val = r_all[ia] * q_var[k] * u * u
            helmert_s[ia, N_SLOTS + k] += val
            helmert_s[N_SLOTS + k, ia] += val
    for k in range(n_vce_noise):
        for l2 in range(k, n_vce_noise):
            acc = 0.0
            for a in range(m):
                acc += hl[a, k] * sinv_hl[a, l2]
            val = q_var[k] * q_var[l2] * acc * acc
            helmert_s[N_SLOTS + k, N_SLOTS + l2] += val
            if l2 != k:
                helmert_s[N_SLOTS + l2, N_SLOTS + k] += val


@njit(cache=True, inline="always")
def truncation_terms(m, q_var, n_vce_noise, test_imu, ws, trunc):
    """Add the weights w_i through which the outlier z-tests shift E[dᵀD⁻¹C_iD⁻¹d] away
    from the trace r_i = tr(D⁻¹C_i) (vce.estimate.truncation_deficit; docs/DESIGN.md).

    A tested row a (the aiding rows; the IMU rows when test_imu) is kept when
    |d_a|/√D_aa ≤ c. With d ~ N(0, D) and τ = 2cφ(c), to first order in the test level:
    kept (probability 1 − α), E[ddᵀ] = D − (1 − κ) D e_a e_aᵀ D / D_aa with
    (1 − α)(1 − κ) = τ, which lowers E[dᵀD⁻¹C_iD⁻¹d] by τ (C_i)_aa / D_aa; rejected
    (probability α), row a is dropped and the kept rows carry its tail,
    E[d_{−a}d_{−a}ᵀ] = D_{−a} + (E[z_a² | |z_a| > c] − 1) D_{−a,a}D_{a,−a}/D_aa with
    α (E[z²| tail] − 1) = τ, which raises the quadratic form of the dropped system by
    τ u_{−a}ᵀ C_i u_{−a} / (u_a² D_aa), u = D⁻¹ e_a (partitioned inverse:
    D_{−a}⁻¹ D_{−a,a} = −u_{−a}/u_a). Per kept tested row, therefore

        w_i += (C_i)_aa / D_aa − u_{−a}ᵀ C_i u_{−a} / (u_a² D_aa),
        E[Σ dᵀD⁻¹C_iD⁻¹d] = Σ r_i − τ Σ w_i,

    with C_i = R_i e_i e_iᵀ (slot i) or q_k h_k h_kᵀ (noise axis k, h_k = (HΛ)_k,
    D⁻¹h_k in ws.sinv_hl); for C = D the weight is 1 − ρ_a² = 1/(D_aa u_a) (trunc[-1],
    ρ_a the multiple correlation of d_a with the epoch's other innovations). An untested
    slot i gets only the second (negative) term. Uses ws.dinv (measurement_redundancy),
    ws.hl and ws.sinv_hl (process_noise_redundancy) of the kept rows; ws.s holds their D."""
    r_all, used, hl, sinv_hl, dinv, s = ws.r_all, ws.used, ws.hl, ws.sinv_hl, ws.dinv, ws.s
    n_tot = trunc.shape[0] - 1
    for a in range(m):
        ia = used[a]
        if ia < SLOT_POS and not test_imu:    # the IMU rows (slots 0-5) are untested
            continue
        daa = s[a, a]
        ua = dinv[a, a]
        g = 1.0 / (ua * ua * daa)
        trunc[n_tot] += 1.0 / (daa * ua)
        for b in range(m):
            ib = used[b]
            if b == a:
                trunc[ib] += r_all[ib] / daa
            else:
                trunc[ib] -= r_all[ib] * dinv[b, a] * dinv[b, a] * g
        for k in range(n_vce_noise):
            h_ak = hl[a, k]
            rest = sinv_hl[a, k] - ua * h_ak       # Σ_{b≠a} u_b h_bk
            trunc[N_SLOTS + k] += q_var[k] * (h_ak * h_ak / daa - rest * rest * g)


@njit(cache=True, inline="always")
def state_prediction_redundancy(m, ws):
    """r_x = tr(Φ P Φᵀ Hᵀ D⁻¹ H), independently of r_z and r_w (test mode)."""
    h_all, used, p_prior_pred, dinv = ws.h_all, ws.used, ws.p_prior_pred, ws.dinv
    n = p_prior_pred.shape[0]
    rx = 0.0
    for a in range(m):
        ia = used[a]
        for b in range(m):
            ib = used[b]
            acc = 0.0
            for k in range(n):
                hk = h_all[ia, k]
                if hk != 0.0:
                    for j in range(n):
                        acc += hk * p_prior_pred[k, j] * h_all[ib, j]
            rx += acc * dinv[b, a]
    return rx


@njit(cache=True, inline="always")
def vce_terms(e, m, have_lam, cfg, ws, rec):
    """Everything VCE needs from epoch e's update (001 eq. 2.7.13-2.7.23, no P⁻ inverse)."""
    q_var = ws.q_var
    rx, helmert_s, helmert_totals = rec.rx, rec.helmert_s, rec.helmert_totals
    q_step_var = cfg.q_step_var
    chi2_all = measurement_redundancy(e, m, ws, rec)
    if not have_lam:
        return
    helmert_totals[0] += chi2_all      # Σ dᵀ D⁻¹ d
    helmert_totals[1] += m             # Σ m
    process_noise_redundancy(e, m, q_var, q_step_var, cfg.n_vce_noise, ws, rec)
    helmert_terms(m, q_var, cfg.n_vce_noise, ws, helmert_s)
    if cfg.outlier_on and rec.helmert_trunc.shape[0] > 0:
        truncation_terms(m, q_var, cfg.n_vce_noise, cfg.test_imu, ws, rec.helmert_trunc)
    if cfg.compute_vce == 2:
        rx[e] = state_prediction_redundancy(m, ws)


@njit(cache=True, inline="always")
def record_state(e, x, p, rec):
    """x, √diag P and the r^n, v^b, θ covariance blocks after epoch e's update."""
    rec_x, sd, cov_blocks = rec.x, rec.sd, rec.cov_blocks
    n = x.shape[0]
    for i in range(n):
        rec_x[e, i] = x[i]
        sd[e, i] = np.sqrt(max(p[i, i], 0.0))
    for b in range(COV_BLOCK_START.shape[0]):
        i0 = COV_BLOCK_START[b]
        for i in range(3):
            for j in range(3):
                cov_blocks[e, b, i, j] = p[i0 + i, i0 + j]


# ------------------------------------------------------------------ the epoch loop


@njit(cache=True)
def retest_after_reopening(e, p, reopened, cfg, ws, rec):
    """After gmis.lockout_recovery re-opened the covariance (bit g of ``reopened``: group
    g's states): the innovations again, the rejection flags cleared and the groups not
    re-opened tested again; returns the number of rows. A call, not inlined into the
    kernel (a rare path: inlined, its second copies of innovations and the outlier test
    cost compile time)."""
    m = innovations(e, p, ws, rec)
    for i in range(N_SLOTS):
        rec.rejected[e, i] = 0
    for g in range(0 if cfg.test_imu else 1, GROUP_START.shape[0]):
        if (reopened >> g) & 1 == 0:
            group_outlier_test(e, GROUP_START[g], GROUP_SIZE[g], m, cfg.chi2_crit,
                               cfg.z_crit, ws, rec)
    return m


@njit(cache=True)
def gmikf_chunk(e0, e1, inp, cfg, x, p, rec, prev_t):
    """gmikf_chunk_ws with scratch buffers of its own (make_workspace)."""
    return gmikf_chunk_ws(e0, e1, inp, cfg, x, p, rec, prev_t,
                          make_workspace(x.shape[0], cfg.q_psd.shape[0]))


@njit(cache=True)
def gmikf_chunk_ws(e0, e1, inp, cfg, x, p, rec, prev_t, ws):
    """Run epochs [e0, e1) (inputs ``inp``: EpochInputs, settings ``cfg``: KernelSettings,
    records ``rec``: EpochRecords). x (n,), p (n, n) are updated in place and hold the
    filter state after the chunk. Returns the time of the last processed epoch.

    q_psd: process-noise spectral densities [j(3) (m/s³)²·s, ω̇(3) (rad/s²)²·s, b_ω(3),
    b_a(3), S_ω(3), S_a(3) drift unit²/s]; every prediction builds Q from its own Δt.
    At epochs flagged ``still`` the jerk and angular-acceleration variances are scaled by
    static_q_scale² (001 Table 4-3: zero while static). compute_vce: 0 = plain filter,
    1 = also residuals/redundancies for VCE and the accumulated Helmert matrix
    rec.helmert_s ((N_SLOTS + nw)², slots then noise axes, added to) for the first
    n_vce_noise process-noise axes (6 = jerk and angular acceleration; the drifts, when not
    estimated, are left to the predicted-state group), 2 = also r_x from Φ P Φᵀ (test mode:
    the redundancy identity). ws: make_workspace(n, nw), reusable across calls (every
    entry is written before it is read; gmis.smoother runs many short chunks on one).
    """
    nobs = rec.nobs
    t, still = inp.t, inp.still
    q_psd, chi2_crit = cfg.q_psd, cfg.chi2_crit
    nw = q_psd.shape[0]
    x_next, x_work = np.empty(x.shape[0]), np.empty(x.shape[0])   # backward steps
    p_none = np.empty((0, 0))
    still_scale = cfg.static_q_scale * cfg.static_q_scale
    have_lam = False
    t_prev = prev_t
    for e in range(e0, e1):
        if not np.isnan(t_prev):
            dt = t[e] - t_prev   # < 0 in the backward filter (gmis.smoother)
            if dt != 0.0:
                if dt < 0.0:
                    x_next[:] = x
                predict(x, p, dt, cfg.n_imu, q_psd, still_scale if still[e] else 1.0,
                        cfg.compute_vce == 2, ws, cfg.drift_inv_tau)
                if cfg.gnss_err_inv_tau[0] > 0.0:   # fix-error states after the IMU states
                    predict_gnss_error_states(x, p, dt, cfg.n_imu, cfg.gnss_err_inv_tau,
                                              cfg.gnss_err_var)
                    accumulate_gnss_error_noise(dt, cfg.gnss_err_inv_tau, cfg.gnss_err_var,
                                                ws.q_var, nw)
                if dt < 0.0:
                    invert_forward_step(x_next, x, -dt, cfg.n_imu, ws.w_zero, x_work)
                    # the exact inverse above is of the random-walk step: the Gauss-Markov
                    # drift states get their inverse decay e^{|dt|/τ} (state only)
                    decay_drift_states_into(x, p_none, dt, cfg.drift_inv_tau, cfg.n_imu)
                have_lam = True
        t_prev = t[e]
        assemble_epoch_rows(e, x, inp, cfg, ws)
        clear_epoch_records(e, nw, ws, rec)
        m = innovations(e, p, ws, rec)
        if m > 0 and cfg.outlier_on:
            for g in range(0 if cfg.test_imu else 1, GROUP_START.shape[0]):
                group_outlier_test(e, GROUP_START[g], GROUP_SIZE[g], m, chi2_crit,
                                   cfg.z_crit, ws, rec)
            if cfg.reopen_after > 0:
                reopened = recover_lockout(
                    e, m, p, cfg.reopen_after, cfg.p0_var, AIDING_GROUPS, GROUP_START,
                    GROUP_SIZE, ws.used, ws.d, ws.h_all, ws.r_all, rec.rejected[e],
                    rec.streak, rec.reopened, ws.x_new)
                if reopened != 0:
                    m = retest_after_reopening(e, p, reopened, cfg, ws, rec)
            if refute_stop(e, m, ws, rec):
                release_stop(e, still, inp.zupt_on)
            m = drop_rejected(e, m, ws, rec)
        nobs[e] = m
        record_nll = rec.nll.shape[0] > e
        if record_nll:
            rec.nll[e] = 0.0
        if m > 0 and kalman_update(x, p, m, ws):
            if record_nll:
                rec.nll[e] = innovation_nll(m, ws)
            if cfg.consider_scale_imu and cfg.n_imu >= N_STATES_27:
                drop_imu_scale_gain(x, p, m, ws)
            if cfg.compute_vce > 0:
                vce_terms(e, m, have_lam, cfg, ws, rec)
            if cfg.gnss_err_inv_tau[0] > 0.0:
                reset_gnss_error_noise(ws.q_var, nw, ws.used, m, SLOT_POS)
        record_state(e, x, p, rec)
    return t_prev


def discrete_process_noise(x, dt, q_psd, n_imu, kin_scale=1.0, drift_inv_tau=None):
    """Λ Q(dt) Λᵀ (n × n) of one prediction step of dt s at the state x, exactly as the
    kernel adds it (analysis and test helper). q_psd: GmikfConfig.q_psd()."""
    x = np.ascontiguousarray(x, dtype=float)
    q_psd = np.ascontiguousarray(q_psd, dtype=float)
    inv_tau = np.zeros(12) if drift_inv_tau is None else np.asarray(drift_inv_tau, float)
    ws = make_workspace(x.shape[0], q_psd.shape[0])
    transition_jacobians_into(x, dt, ws.phi, ws.lam)
    process_noise_variances(dt, kin_scale, q_psd, inv_tau, ws.q_var)
    q = np.zeros((x.shape[0], x.shape[0]))
    add_process_noise(q, ws.lam, ws.q_var, n_imu)
    return q
