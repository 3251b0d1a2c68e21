"""The GMIKF epoch loop: total-state EKF in which every sensor, the IMU included, is a
measurement update (001 ch. 4-5). Numba-compiled; processes a chunk of epochs per call
so Python can report progress between chunks; no allocation inside the epoch loop.

Measurement slots of one epoch (``SLOT_*``): 0-5 IMU gyro x,y,z / accel x,y,z, 6-8 GNSS
position E,N,U, 9-11 GNSS velocity E,N,U, 12 heading, 13-14 non-holonomic constraint
(lateral, vertical; pseudo-observations z = 0 at the epochs flagged in ``nhc_on``). All sensors present at an epoch are
stacked into ONE update. Outlier tests per group (001 §5.2.3.1): local χ² on the group's
innovations with the group block of D = HP⁻Hᵀ + R, and a z-test per observation; an
observation failing its z-test is rejected; a group failing χ² with no single z failure
is rejected whole. Rejected observations do not update the state and are flagged.

Per-epoch records hold what VCE needs (001 eq. 2.7.13-2.7.23, see vce/): measurement
residuals v_z = ẑ − z = −R D⁻¹ d and redundancy r_z = diag(R D⁻¹), process-noise
residuals v_w = Q Λᵀ Hᵀ D⁻¹ d and redundancy r_w = diag(Q Λᵀ Hᵀ D⁻¹ H Λ), and r_x, computed from
the innovation without inverting P⁻; r_z + r_w + r_x equals the number of observations.
"""

import numpy as np
from numba import njit

from gmis.measurement_models import (
    gnss_position_model_and_jacobian_into,
    gnss_velocity_model_and_jacobian_into,
    heading_model_and_jacobian_into,
    imu_model_and_jacobian_into,
    nonholonomic_model_and_jacobian_into,
)
from gmis.system_model import propagate_state_into, transition_jacobians_into

N_SLOTS = 15
SLOT_IMU = 0
SLOT_POS = 6
SLOT_VEL = 9
SLOT_HEADING = 12
SLOT_NHC = 13
GROUP_START = np.array([0, 6, 9, 12, 13], dtype=np.int64)
GROUP_SIZE = np.array([6, 3, 3, 1, 2], dtype=np.int64)
GROUP_NAMES = ("imu", "gnss_position", "gnss_velocity", "heading", "nonholonomic")
SLOT_NAMES = ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z",
              "pos_e", "pos_n", "pos_u", "vel_e", "vel_n", "vel_u", "heading",
              "nhc_lateral", "nhc_vertical")


@njit(cache=True)
def _cholesky_inplace(a, m):
    """Lower Cholesky factor of the leading m×m block of a, in place. False if not PD."""
    for j in range(m):
        s = a[j, j]
        for k in range(j):
            s -= a[j, k] * a[j, k]
        if s <= 0.0:
            return False
        a[j, j] = np.sqrt(s)
        for i in range(j + 1, m):
            s = a[i, j]
            for k in range(j):
                s -= a[i, k] * a[j, k]
            a[i, j] = s / a[j, j]
    return True


@njit(cache=True)
def _cholesky_solve_inplace(l, m, b, ncol):
    """Solve (L Lᵀ) X = B for the leading m rows of b (m × ncol), in place."""
    for c in range(ncol):
        for i in range(m):
            s = b[i, c]
            for k in range(i):
                s -= l[i, k] * b[k, c]
            b[i, c] = s / l[i, i]
        for i in range(m - 1, -1, -1):
            s = b[i, c]
            for k in range(i + 1, m):
                s -= l[k, i] * b[k, c]
            b[i, c] = s / l[i, i]


@njit(cache=True)
def propagate_covariance(p, n, phi, work):
    """P ← Φ P Φᵀ with Φ = blockdiag(phi_dyn (15×15), I) (001 eq. 5.1.2); work (15, n)."""
    for i in range(15):
        for j in range(n):
            s = 0.0
            for k in range(15):
                s += phi[i, k] * p[k, j]
            work[i, j] = s
    for i in range(15):
        for j in range(15):
            s = 0.0
            for k in range(15):
                s += work[i, k] * phi[j, k]
            p[i, j] = s
        for j in range(15, n):
            p[i, j] = work[i, j]
            p[j, i] = work[i, j]


@njit(cache=True)
def add_process_noise(p, lam, q_var, n_imu):
    """P ← P + Λ Q Λᵀ: the jerk/angular-acceleration part through lam (15×6), bias and
    scale-factor drifts on the diagonal (q_var: per-step variances, 001 Table 6-2)."""
    for i in range(15):
        for j in range(i, 15):
            s = 0.0
            for k in range(6):
                s += lam[i, k] * q_var[k] * lam[j, k]
            p[i, j] += s
            if j != i:
                p[j, i] = p[i, j]
    for i in range(n_imu - 15):
        p[15 + i, 15 + i] += q_var[6 + i]


@njit(cache=True)
def _innovation_covariance(h_all, used, m, n, pht, r_all, s):
    """D = H P Hᵀ + R for the m slots listed in used, from pht = P Hᵀ (sparse H rows)."""
    for a in range(m):
        i = used[a]
        for b in range(a, m):
            acc = 0.0
            for k in range(n):
                hk = h_all[i, k]
                if hk != 0.0:
                    acc += hk * pht[k, b]
            s[a, b] = acc
            s[b, a] = acc
        s[a, a] += r_all[i]


@njit(cache=True)
def _drop_imu_scale_gain(x, p, kmat, pht, d, s, used, m, t):
    """Scale factors S (states 21-26) take no update from the IMU rows of an epoch.

    The IMU rows are the only sensor of ω and a, so their S column h_S = ω⁻ + C_n^b ω_ie
    (resp. a⁻ + …) is evaluated at a prediction that carries the previous sample's noise,
    which also enters the innovation: the update S += K_S,imu d then drifts systematically
    (errors in variables; −9 000 ppm against +1 000 ppm on the default drive, z ≈ −3.5,
    growing with the IMU noise and rate). The gain block Δ = K[S, imu] is therefore dropped
    after the optimal update: x_S −= Δ d_imu and, Joseph form for the changed gain
    (P(K) = P(K_opt) + (K − K_opt) D (K − K_opt)ᵀ), P_SS += Δ D_imu Δᵀ. S is then estimated
    from the aiding rows through its correlation with attitude and velocity (a Schmidt
    'consider' treatment of S in the IMU rows); unobservable scale factors stay at their
    prior. The IMU rows are the first ``mi`` entries of ``used`` (slots 0-5); t (6,)
    scratch."""
    mi = 0
    while mi < m and used[mi] < 6:
        mi += 1
    if mi == 0:
        return
    for i in range(6):
        acc = 0.0
        for a in range(mi):
            acc += kmat[21 + i, a] * d[a]
        x[21 + i] -= acc
    for j in range(6):
        for a in range(mi):
            if mi == m:       # IMU-only epoch: (D Kᵀ)[a, j] = (P Hᵀ)[S_j, a]
                t[a] = pht[21 + j, a]
            else:
                acc = 0.0
                for b in range(mi):
                    acc += s[a, b] * kmat[21 + j, b]
                t[a] = acc
        for i in range(6):
            acc = 0.0
            for a in range(mi):
                acc += kmat[21 + i, a] * t[a]
            p[21 + i, 21 + j] += acc


@njit(cache=True)
def gmikf_chunk(e0, e1, t, imu_idx, pos_idx, vel_idx, hdg_idx,
                imu_z, imu_sd, pos_z, pos_sd, vel_z, vel_sd, hdg_z, hdg_sd,
                x, p, n_imu, q_sd, still, static_q_scale, lever_arm, frame,
                nhc_on, nhc_sd, nhc_lever_arm,
                chi2_crit, z_crit, outlier_on, compute_vce,
                rec_x, rec_sd, rec_cov_blocks, rec_innov, rec_innov_var, rec_rejected,
                rec_vz, rec_rz, rec_vw, rec_rw, rec_rx, rec_nobs, rec_rvar,
                helmert_s, helmert_totals, n_vce_noise, prev_t, consider_scale_imu=False):
    """Run epochs [e0, e1). x (n,), p (n, n) are updated in place and hold the filter
    state after the chunk. Returns the time of the last processed epoch.

    Indices (-1 = absent) map epochs to rows of the measurement arrays. Standard
    deviations: imu_sd (6,) rad/s, m/s²; pos_sd/vel_sd (M, 3) m, m/s; hdg_sd (H,) rad.
    q_sd: per-step process-noise 1σ [j(3) m/s³, ω̇(3) rad/s², b_ω(3), b_a(3), S_ω(3), S_a(3)].
    nhc_on: (E,) bool, apply the non-holonomic pseudo-observations (slots 13-14, z = 0,
    1σ nhc_sd (2,) m/s, constraint point nhc_lever_arm (3,) m body) at this epoch.
    still: (E,) bool, vehicle at rest: jerk and angular-acceleration noise are scaled by
    static_q_scale there (001 Table 4-3: zero while static).
    chi2_crit[m]: χ²(m) critical value for a group of m observations.
    compute_vce: 0 = plain filter, 1 = also residuals/redundancies for VCE and the
    accumulated Helmert matrix helmert_s ((N_SLOTS + nw)², slots then noise axes, added to),
    for the first n_vce_noise process-noise axes (6 = jerk and angular acceleration; the
    drifts, when not estimated, are left to the predicted-state group),
    2 = also r_x from Φ P Φᵀ (test mode: the redundancy identity).
    consider_scale_imu: the IMU rows do not update the scale factors (27 states; see
    _drop_imu_scale_gain); False = the plain EKF update of every state.
    """
    n = x.shape[0]
    nw = q_sd.shape[0]
    q_var_moving = q_sd * q_sd
    q_var_still = q_var_moving.copy()
    for k in range(6):
        q_var_still[k] *= static_q_scale * static_q_scale
    q_var = q_var_moving
    phi = np.zeros((15, 15))
    lam = np.zeros((15, 6))
    work = np.zeros((15, n))
    x_new = np.zeros(n)
    w_zero = np.zeros(nw)
    h_all = np.zeros((N_SLOTS, n))
    hx_all = np.zeros(N_SLOTS)
    z_all = np.zeros(N_SLOTS)
    r_all = np.zeros(N_SLOTS)
    present = np.zeros(N_SLOTS, dtype=np.bool_)
    used = np.zeros(N_SLOTS, dtype=np.int64)
    d = np.zeros(N_SLOTS)
    pht = np.zeros((n, N_SLOTS))
    s = np.zeros((N_SLOTS, N_SLOTS))
    sl = np.zeros((N_SLOTS, N_SLOTS))
    sinv_d = np.zeros((N_SLOTS, 1))
    gblock = np.zeros((N_SLOTS, N_SLOTS))
    gvec = np.zeros((N_SLOTS, 1))
    kmat = np.zeros((n, N_SLOTS))
    hl = np.zeros((N_SLOTS, 18))
    sinv_hl = np.zeros((N_SLOTS, 18))
    p_prior_pred = np.zeros((n, n))
    dinv = np.zeros((N_SLOTS, N_SLOTS))
    sf_work = np.zeros(6)
    have_lam = False
    t_prev = prev_t
    for e in range(e0, e1):
        # ---- prediction (eq. 5.1.1/5.1.2)
        if not np.isnan(t_prev):
            dt = t[e] - t_prev
            q_var = q_var_still if still[e] else q_var_moving
            if dt > 0.0:
                transition_jacobians_into(x, dt, phi, lam)
                propagate_state_into(x, w_zero, dt, n_imu, x_new)
                for i in range(n):
                    x[i] = x_new[i]
                propagate_covariance(p, n, phi, work)
                if compute_vce == 2:
                    # keep Φ P_{k-1} Φᵀ (without Q) for the independent r_x
                    for i in range(n):
                        for j in range(n):
                            p_prior_pred[i, j] = p[i, j]
                add_process_noise(p, lam, q_var, n_imu)
                have_lam = True
        t_prev = t[e]
        # ---- assemble all measurements of this epoch
        for i in range(N_SLOTS):
            present[i] = False
        if imu_idx[e] >= 0:
            imu_model_and_jacobian_into(x, n_imu, frame, hx_all, 0, h_all, 0)
            for i in range(6):
                z_all[i] = imu_z[imu_idx[e], i]
                r_all[i] = imu_sd[i] * imu_sd[i]
                present[i] = True
        if pos_idx[e] >= 0:
            gnss_position_model_and_jacobian_into(x, lever_arm, hx_all, SLOT_POS, h_all,
                                                  SLOT_POS)
            for i in range(3):
                z_all[SLOT_POS + i] = pos_z[pos_idx[e], i]
                r_all[SLOT_POS + i] = pos_sd[pos_idx[e], i] ** 2
                present[SLOT_POS + i] = True
        if vel_idx[e] >= 0:
            gnss_velocity_model_and_jacobian_into(x, lever_arm, hx_all, SLOT_VEL, h_all,
                                                  SLOT_VEL)
            for i in range(3):
                z_all[SLOT_VEL + i] = vel_z[vel_idx[e], i]
                r_all[SLOT_VEL + i] = vel_sd[vel_idx[e], i] ** 2
                present[SLOT_VEL + i] = True
        if hdg_idx[e] >= 0:
            heading_model_and_jacobian_into(x, hx_all, SLOT_HEADING, h_all, SLOT_HEADING)
            z_all[SLOT_HEADING] = hdg_z[hdg_idx[e]]
            r_all[SLOT_HEADING] = hdg_sd[hdg_idx[e]] ** 2
            present[SLOT_HEADING] = True
        if nhc_on[e]:
            nonholonomic_model_and_jacobian_into(x, nhc_lever_arm, hx_all, SLOT_NHC, h_all,
                                                 SLOT_NHC)
            for i in range(2):
                z_all[SLOT_NHC + i] = 0.0
                r_all[SLOT_NHC + i] = nhc_sd[i] * nhc_sd[i]
                present[SLOT_NHC + i] = True
        for i in range(N_SLOTS):
            rec_innov[e, i] = np.nan
            rec_innov_var[e, i] = np.nan
            rec_rejected[e, i] = 0
            rec_rvar[e, i] = r_all[i] if present[i] else np.nan
            rec_vz[e, i] = np.nan
            rec_rz[e, i] = np.nan
        for i in range(nw):
            rec_vw[e, i] = np.nan
            rec_rw[e, i] = np.nan
        rec_rx[e] = np.nan
        rec_nobs[e] = 0
        # ---- innovations and their covariance for all present slots
        m = 0
        for i in range(N_SLOTS):
            if present[i]:
                used[m] = i
                m += 1
        if m > 0:
            for a in range(m):
                i = used[a]
                dd = z_all[i] - hx_all[i]
                if i == SLOT_HEADING:
                    dd = (dd + np.pi) % (2.0 * np.pi) - np.pi
                d[a] = dd
                for j in range(n):
                    pht[j, a] = 0.0
                for k in range(n):
                    hk = h_all[i, k]
                    if hk != 0.0:
                        for j in range(n):
                            pht[j, a] += p[j, k] * hk
            _innovation_covariance(h_all, used, m, n, pht, r_all, s)
            for a in range(m):
                rec_innov[e, used[a]] = d[a]
                rec_innov_var[e, used[a]] = s[a, a]
            # ---- outlier tests per group (001 §5.2.3.1)
            if outlier_on:
                for g in range(GROUP_START.shape[0]):
                    g0 = GROUP_START[g]
                    gn = GROUP_SIZE[g]
                    # positions (in 0..m) of this group's present observations
                    cnt = 0
                    any_z = False
                    for a in range(m):
                        if used[a] >= g0 and used[a] < g0 + gn:
                            cnt += 1
                    if cnt == 0:
                        continue
                    ia = 0
                    for a in range(m):
                        if used[a] >= g0 and used[a] < g0 + gn:
                            ib = 0
                            for b in range(m):
                                if used[b] >= g0 and used[b] < g0 + gn:
                                    gblock[ia, ib] = s[a, b]
                                    ib += 1
                            gvec[ia, 0] = d[a]
                            ia += 1
                            if abs(d[a]) / np.sqrt(s[a, a]) > z_crit:
                                rec_rejected[e, used[a]] = 1
                                any_z = True
                    if _cholesky_inplace(gblock, cnt):
                        _cholesky_solve_inplace(gblock, cnt, gvec, 1)
                        chi2 = 0.0
                        ia = 0
                        for a in range(m):
                            if used[a] >= g0 and used[a] < g0 + gn:
                                chi2 += d[a] * gvec[ia, 0]
                                ia += 1
                        if chi2 > chi2_crit[cnt] and not any_z:
                            for a in range(m):
                                if used[a] >= g0 and used[a] < g0 + gn:
                                    rec_rejected[e, used[a]] = 1
                # compact: keep only accepted observations
                mm = 0
                for a in range(m):
                    if rec_rejected[e, used[a]] == 0:
                        used[mm] = used[a]
                        d[mm] = d[a]
                        for j in range(n):
                            pht[j, mm] = pht[j, a]
                        mm += 1
                if mm < m:
                    _innovation_covariance(h_all, used, mm, n, pht, r_all, s)
                m = mm
        rec_nobs[e] = m
        if m > 0:
            # ---- Kalman update: K = P Hᵀ D⁻¹, x += K d, P -= K (P Hᵀ)ᵀ
            for a in range(m):
                for b in range(m):
                    sl[a, b] = s[a, b]
            if not _cholesky_inplace(sl, m):
                m = 0
            else:
                for a in range(m):
                    sinv_d[a, 0] = d[a]
                _cholesky_solve_inplace(sl, m, sinv_d, 1)
                # K = pht S⁻¹ : solve S Kᵀ = phtᵀ row by row
                for j in range(n):
                    for a in range(m):
                        gvec[a, 0] = pht[j, a]
                    _cholesky_solve_inplace(sl, m, gvec, 1)
                    for a in range(m):
                        kmat[j, a] = gvec[a, 0]
                for j in range(n):
                    acc = 0.0
                    for a in range(m):
                        acc += kmat[j, a] * d[a]
                    x[j] += acc
                for i in range(n):
                    for j in range(i, n):
                        acc = 0.0
                        for a in range(m):
                            acc += kmat[i, a] * pht[j, a]
                        p[i, j] -= acc
                        p[j, i] = p[i, j]
                x[11] = x[11] % (2.0 * np.pi)
                if consider_scale_imu and n_imu >= 27:
                    _drop_imu_scale_gain(x, p, kmat, pht, d, s, used, m, sf_work)
                # ---- VCE quantities (001 eq. 2.7.14-2.7.23 without P⁻ inverse)
                if compute_vce > 0:
                    # full D⁻¹ (m × m)
                    for a in range(m):
                        for b in range(m):
                            dinv[a, b] = 1.0 if a == b else 0.0
                    _cholesky_solve_inplace(sl, m, dinv, m)
                    chi2_all = 0.0
                    for a in range(m):
                        i = used[a]
                        rec_rz[e, i] = r_all[i] * dinv[a, a]
                        rec_vz[e, i] = -r_all[i] * sinv_d[a, 0]
                        chi2_all += d[a] * sinv_d[a, 0]
                    if have_lam:
                        helmert_totals[0] += chi2_all      # Σ dᵀ D⁻¹ d
                        helmert_totals[1] += m             # Σ m
                    if have_lam:
                        # HΛ (m × nw): Λ = [lam (15×6); I for bias/scale rows]
                        for a in range(m):
                            i = used[a]
                            for k in range(n_vce_noise):
                                acc = 0.0
                                if k < 6:
                                    for r in range(15):
                                        acc += h_all[i, r] * lam[r, k]
                                else:
                                    acc = h_all[i, 15 + (k - 6)]
                                hl[a, k] = acc
                                sinv_hl[a, k] = acc
                        _cholesky_solve_inplace(sl, m, sinv_hl, n_vce_noise)
                        for k in range(n_vce_noise):
                            vw = 0.0
                            rw = 0.0
                            for a in range(m):
                                vw += hl[a, k] * sinv_d[a, 0]
                                rw += hl[a, k] * sinv_hl[a, k]
                            rec_vw[e, k] = q_var[k] * vw
                            rec_rw[e, k] = q_var[k] * rw
                        # Helmert matrix terms S_ij = tr(D⁻¹ C_i D⁻¹ C_j) for the
                        # elementary components (slots, noise axes): C = R_a e_a e_aᵀ or
                        # q_k h_k h_kᵀ with h_k = (HΛ)_k, so every S_ij is a scalar product
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
                    if have_lam and compute_vce == 2:
                        # r_x = tr(Φ P Φᵀ Hᵀ D⁻¹ H), independently of r_z and r_w
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
                        rec_rx[e] = rx
                rec_nobs[e] = m
        # ---- records
        for i in range(n):
            rec_x[e, i] = x[i]
            rec_sd[e, i] = np.sqrt(max(p[i, i], 0.0))
        for b in range(3):
            for i in range(3):
                for j in range(3):
                    rec_cov_blocks[e, b, i, j] = p[3 * b + i if b < 2 else 9 + i,
                                                   3 * b + j if b < 2 else 9 + j]
    return t_prev
