"""Attitude conventions: body frame Right-Forward-Up, navigation frame ENU.

Euler angles θ = [pitch p, roll γ, heading ψ] (rad); ψ is an azimuth, clockwise from
north. All functions are numba-compiled; the ``*_into`` variants write into a caller's
buffer so the filter's hot path allocates nothing.

References: 001 eq. 2.2.3-2.2.6 (the middle factor of the printed 2.2.3 has ψ where p
belongs; the printed product and 2.2.4 are right).
"""

import numpy as np
from numba import njit


@njit(cache=True)
def skew_block_into(m, r0, c0, vx, vy, vz, scale):
    """m[r0:r0+3, c0:c0+3] = scale [v×] for v = (vx, vy, vz): the (scaled) cross-product
    matrix, [v×] u = v × u; the one skew helper of the kernels (scale ±1, ±2 exact)."""
    m[r0, c0] = 0.0
    m[r0, c0 + 1] = scale * -vz
    m[r0, c0 + 2] = scale * vy
    m[r0 + 1, c0] = scale * vz
    m[r0 + 1, c0 + 1] = 0.0
    m[r0 + 1, c0 + 2] = scale * -vx
    m[r0 + 2, c0] = scale * -vy
    m[r0 + 2, c0 + 1] = scale * vx
    m[r0 + 2, c0 + 2] = 0.0


@njit(cache=True)
def skew_into(v, out):
    """[v×], the 3×3 cross-product matrix: [v×] u = v × u."""
    skew_block_into(out, 0, 0, v[0], v[1], v[2], 1.0)


@njit(cache=True)
def skew(v):
    out = np.empty((3, 3))
    skew_into(v, out)
    return out


@njit(cache=True)
def dcm_body_to_nav_into(pitch, roll, heading, out):
    """C_b^n of 001 eq. 2.2.4 (body RFU → ENU)."""
    sp, cp = np.sin(pitch), np.cos(pitch)
    sr, cr = np.sin(roll), np.cos(roll)
    sh, ch = np.sin(heading), np.cos(heading)
    out[0, 0] = cr * ch + sr * sh * sp
    out[0, 1] = sh * cp
    out[0, 2] = sr * ch - cr * sh * sp
    out[1, 0] = -cr * sh + sr * ch * sp
    out[1, 1] = ch * cp
    out[1, 2] = -sr * sh - cr * ch * sp
    out[2, 0] = -sr * cp
    out[2, 1] = sp
    out[2, 2] = cr * cp


@njit(cache=True)
def dcm_body_to_nav(pitch, roll, heading):
    out = np.empty((3, 3))
    dcm_body_to_nav_into(pitch, roll, heading, out)
    return out


@njit(cache=True)
def dcm_body_to_nav_partials_into(pitch, roll, heading, d_pitch, d_roll, d_heading):
    """∂C_b^n/∂p, ∂C_b^n/∂γ, ∂C_b^n/∂ψ (element-wise derivatives of eq. 2.2.4)."""
    sp, cp = np.sin(pitch), np.cos(pitch)
    sr, cr = np.sin(roll), np.cos(roll)
    sh, ch = np.sin(heading), np.cos(heading)
    d_pitch[0, 0] = sr * sh * cp
    d_pitch[0, 1] = -sh * sp
    d_pitch[0, 2] = -cr * sh * cp
    d_pitch[1, 0] = sr * ch * cp
    d_pitch[1, 1] = -ch * sp
    d_pitch[1, 2] = -cr * ch * cp
    d_pitch[2, 0] = sr * sp
    d_pitch[2, 1] = cp
    d_pitch[2, 2] = -cr * sp

    d_roll[0, 0] = -sr * ch + cr * sh * sp
    d_roll[0, 1] = 0.0
    d_roll[0, 2] = cr * ch + sr * sh * sp
    d_roll[1, 0] = sr * sh + cr * ch * sp
    d_roll[1, 1] = 0.0
    d_roll[1, 2] = -cr * sh + sr * ch * sp
    d_roll[2, 0] = -cr * cp
    d_roll[2, 1] = 0.0
    d_roll[2, 2] = -sr * cp

    d_heading[0, 0] = -cr * sh + sr * ch * sp
    d_heading[0, 1] = ch * cp
    d_heading[0, 2] = -sr * sh - cr * ch * sp
    d_heading[1, 0] = -cr * ch - sr * sh * sp
    d_heading[1, 1] = -sh * cp
    d_heading[1, 2] = -sr * ch + cr * sh * sp
    d_heading[2, 0] = 0.0
    d_heading[2, 1] = 0.0
    d_heading[2, 2] = 0.0


@njit(cache=True)
def euler_from_dcm(c):
    """θ = [p, γ, ψ] from C_b^n, 001 eq. 2.2.5; ψ wrapped to [0, 2π)."""
    out = np.empty(3)
    s = min(1.0, max(-1.0, c[2, 1]))
    out[0] = np.arcsin(s)
    out[1] = np.arctan2(-c[2, 0], c[2, 2])
    out[2] = np.arctan2(c[0, 1], c[1, 1]) % (2.0 * np.pi)
    return out


@njit(cache=True)
def euler_rate_matrix_into(pitch, roll, out):
    """C(θ) of 001 eq. 2.2.6: θ̇ = C(θ) ω_nb^b (singular at |p| = 90°)."""
    sr, cr = np.sin(roll), np.cos(roll)
    tp = np.tan(pitch)
    secp = 1.0 / np.cos(pitch)
    out[0, 0] = cr
    out[0, 1] = 0.0
    out[0, 2] = sr
    out[1, 0] = sr * tp
    out[1, 1] = 1.0
    out[1, 2] = -cr * tp
    out[2, 0] = sr * secp
    out[2, 1] = 0.0
    out[2, 2] = -cr * secp


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
