"""Attitude conventions: body frame Right-Forward-Up, navigation frame ENU.

Euler angles θ = [pitch p, roll γ, heading ψ] (rad); ψ is an azimuth, clockwise from
north. All functions are numba-compiled; the ``*_into`` variants write into a caller's
buffer so the filter's hot path allocates nothing.

References: 001 eq. 2.2.3-2.2.6 (the middle factor of the printed 2.2.3 has ψ where p
belongs; the printed product and 2.2.4 are right).
"""

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def skew_rows(vx, vy, vz, scale):
    """scale [v×] for v = (vx, vy, vz) as three row tuples: the (scaled) cross-product
    matrix, [v×] u = v × u; the one skew formula of the kernels (scale ±1, ±2 exact)."""
    return ((0.0, scale * -vz, scale * vy), (scale * vz, 0.0, scale * -vx),
            (scale * -vy, scale * vx, 0.0))


@njit(cache=True)
def skew_block_into(m, r0, c0, vx, vy, vz, scale):
    """m[r0:r0+3, c0:c0+3] = scale [v×] (skew_rows)."""
    rows = skew_rows(vx, vy, vz, scale)
    for i in range(3):
        for k in range(3):
            m[r0 + i, c0 + k] = rows[i][k]


@njit(cache=True)
def skew_into(v, out):
    """[v×], the 3×3 cross-product matrix: [v×] u = v × u."""
    skew_block_into(out, 0, 0, v[0], v[1], v[2], 1.0)


@njit(cache=True)
def skew(v):
    out = np.empty((3, 3))
    skew_into(v, out)
    return out


@njit(cache=True, inline="always")
def rows_into(rows, out):
    """out[i, k] = rows[i][k] for a 3×3 matrix held as three row tuples."""
    for i in range(3):
        for k in range(3):
            out[i, k] = rows[i][k]


@njit(cache=True, inline="always")
def attitude_trig(pitch, roll, heading):
    """(sin p, cos p, sin γ, cos γ, sin ψ, cos ψ): computed once, shared by the *_trig
    matrices of one attitude."""
    return (np.sin(pitch), np.cos(pitch), np.sin(roll), np.cos(roll), np.sin(heading),
            np.cos(heading))


@njit(cache=True, inline="always")
def dcm_body_to_nav_rows(pitch, roll, heading):
    """C_b^n of 001 eq. 2.2.4 (body RFU → ENU) as three row tuples: c[i][k] (no
    allocation; the form the kernels' hot path uses)."""
    return dcm_rows_trig(attitude_trig(pitch, roll, heading))


@njit(cache=True, inline="always")
def dcm_rows_trig(trig):
    """dcm_body_to_nav_rows from attitude_trig."""
    sp, cp, sr, cr, sh, ch = trig
    return ((cr * ch + sr * sh * sp, sh * cp, sr * ch - cr * sh * sp),
            (-cr * sh + sr * ch * sp, ch * cp, -sr * sh - cr * ch * sp),
            (-sr * cp, sp, cr * cp))


@njit(cache=True)
def dcm_body_to_nav_into(pitch, roll, heading, out):
    """C_b^n of 001 eq. 2.2.4 (body RFU → ENU)."""
    rows_into(dcm_body_to_nav_rows(pitch, roll, heading), out)


@njit(cache=True)
def dcm_body_to_nav(pitch, roll, heading):
    out = np.empty((3, 3))
    dcm_body_to_nav_into(pitch, roll, heading, out)
    return out


@njit(cache=True, inline="always")
def dcm_body_to_nav_partials_rows(pitch, roll, heading):
    """∂C_b^n/∂p, ∂C_b^n/∂γ, ∂C_b^n/∂ψ (element-wise derivatives of eq. 2.2.4), each as
    three row tuples (no allocation)."""
    return dcm_partials_rows_trig(attitude_trig(pitch, roll, heading))


@njit(cache=True, inline="always")
def dcm_partials_rows_trig(trig):
    """dcm_body_to_nav_partials_rows from attitude_trig."""
    sp, cp, sr, cr, sh, ch = trig
    d_pitch = ((sr * sh * cp, -sh * sp, -cr * sh * cp),
               (sr * ch * cp, -ch * sp, -cr * ch * cp),
               (sr * sp, cp, -cr * sp))
    d_roll = ((-sr * ch + cr * sh * sp, 0.0, cr * ch + sr * sh * sp),
              (sr * sh + cr * ch * sp, 0.0, -cr * sh + sr * ch * sp),
              (-cr * cp, 0.0, -sr * cp))
    d_heading = ((-cr * sh + sr * ch * sp, ch * cp, -sr * sh - cr * ch * sp),
                 (-cr * ch - sr * sh * sp, -sh * cp, -sr * ch + cr * sh * sp),
                 (0.0, 0.0, 0.0))
    return d_pitch, d_roll, d_heading


@njit(cache=True)
def dcm_body_to_nav_partials_into(pitch, roll, heading, d_pitch, d_roll, d_heading):
    """∂C_b^n/∂p, ∂C_b^n/∂γ, ∂C_b^n/∂ψ (element-wise derivatives of eq. 2.2.4)."""
    dp, dr, dh = dcm_body_to_nav_partials_rows(pitch, roll, heading)
    rows_into(dp, d_pitch)
    rows_into(dr, d_roll)
    rows_into(dh, d_heading)


@njit(cache=True)
def euler_from_dcm(c):
    """θ = [p, γ, ψ] from C_b^n, 001 eq. 2.2.5; ψ wrapped to [0, 2π)."""
    out = np.empty(3)
    s = min(1.0, max(-1.0, c[2, 1]))
    out[0] = np.arcsin(s)
    out[1] = np.arctan2(-c[2, 0], c[2, 2])
    out[2] = np.arctan2(c[0, 1], c[1, 1]) % (2.0 * np.pi)
    return out


@njit(cache=True, inline="always")
def euler_rate_matrix_rows(pitch, roll):
    """C(θ) of 001 eq. 2.2.6 (θ̇ = C(θ) ω_nb^b, singular at |p| = 90°) as three row
    tuples (no allocation)."""
    return euler_rate_rows_trig(np.cos(pitch), np.sin(roll), np.cos(roll), np.tan(pitch))


@njit(cache=True, inline="always")
def euler_rate_rows_trig(cp, sr, cr, tp):
    """euler_rate_matrix_rows from cos p, sin γ, cos γ and tan p."""
    secp = 1.0 / cp
    return ((cr, 0.0, sr), (sr * tp, 1.0, -cr * tp), (sr * secp, 0.0, -cr * secp))


@njit(cache=True)
def euler_rate_matrix_into(pitch, roll, out):
    """C(θ) of 001 eq. 2.2.6: θ̇ = C(θ) ω_nb^b (singular at |p| = 90°)."""
    rows_into(euler_rate_matrix_rows(pitch, roll), out)


@njit(cache=True)
def euler_rate_matrix(pitch, roll):
    out = np.empty((3, 3))
    euler_rate_matrix_into(pitch, roll, out)
    return out


@njit(cache=True)
def wrap_pi(angle):
    """Wrap an angle (rad) to [-π, π)."""
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


@njit(cache=True)
def rotation_vector_to_dcm(phi):
    """Exact DCM of a rotation vector φ (rad), Rodrigues' formula (001 eq. 4.1.22)."""
    angle = np.sqrt(phi[0] ** 2 + phi[1] ** 2 + phi[2] ** 2)
    k = skew(phi)
    if angle < 1e-8:
        return np.eye(3) + k + 0.5 * (k @ k)
    return (np.eye(3) + (np.sin(angle) / angle) * k
            + ((1.0 - np.cos(angle)) / angle ** 2) * (k @ k))


def dcm_body_to_nav_array(euler):
    """Vectorised C_b^n (eq. 2.2.4) for euler (N, 3) [pitch, roll, heading] → (N, 3, 3)."""
    euler = np.asarray(euler, dtype=float)
    sp, cp = np.sin(euler[:, 0]), np.cos(euler[:, 0])
    sr, cr = np.sin(euler[:, 1]), np.cos(euler[:, 1])
    sh, ch = np.sin(euler[:, 2]), np.cos(euler[:, 2])
    c = np.empty((euler.shape[0], 3, 3))
    c[:, 0, 0] = cr * ch + sr * sh * sp
    c[:, 0, 1] = sh * cp
    c[:, 0, 2] = sr * ch - cr * sh * sp
    c[:, 1, 0] = -cr * sh + sr * ch * sp
    c[:, 1, 1] = ch * cp
    c[:, 1, 2] = -sr * sh - cr * ch * sp
    c[:, 2, 0] = -sr * cp
    c[:, 2, 1] = sp
    c[:, 2, 2] = cr * cp
    return c
