"""Dual-antenna heading: a moving baseline between two rover antennas on the vehicle roof
(001 §4.1.3.2 ii, §6.1; the "DGPS heading" of Table 4-6).

The primary antenna plays the base of a double-difference RTK (gnss.rtk) whose position is
only approximately known (single-point solution, metres): for a baseline of a few metres
the DD geometry changes by |b|/ρ ≈ 1e-7 per metre of base error, so the *relative* vector
b = r_secondary − r_primary comes out at the carrier-phase level regardless. Ambiguities
are fixed with LAMBDA + ratio test (gnss.rtk), and the known antenna separation validates
each fix: a fixed baseline whose length differs from the surveyed length by more than
both ``length_tolerance_m`` and ``length_sigma_factor`` σ_L (below) is rejected (the epoch
is reported as float), which removes the wrong fixes a short baseline is prone to.

Output per epoch (ENU at the primary antenna):
    baseline azimuth  ψ_b = atan2(b_e, b_n)            (rad, clockwise from north)
    baseline pitch    θ_b = atan2(b_u, √(b_e² + b_n²))
    σ_ψ² = g_ψᵀ C_b g_ψ,  g_ψ = (b_n, −b_e, 0) / h²,    h² = b_e² + b_n²
    σ_θ² = g_θᵀ C_b g_θ,  g_θ = (−b_u b_e / h, −b_u b_n / h, h) / |b|²
with C_b the full 3×3 ENU covariance of the fixed baseline (the correlations between the
ENU components are not negligible: the DD geometry couples them); with only the diagonal
σ_ENU given, C_b = diag(σ²).
Known length (baseline-constrained estimation; default ``constrain_length=True``): with
the integers fixed, the observations enter the baseline only through the fixed solution
b̂, C_b (their least-squares quadratic form is (b − b̂)ᵀ C_b⁻¹ (b − b̂) + const), so the
estimate that also uses the surveyed length L = |ΔL| is

    b̌ = argmin (b − b̂)ᵀ C_b⁻¹ (b − b̂)  subject to  |b| = L,
    b̌ = (I + μ C_b)⁻¹ b̂,  μ the root of |b̌(μ)| = L with I + μ C_b positive definite,
    C_b̌ = C_b − C_b u (uᵀ C_b u)⁻¹ uᵀ C_b,  u = b̌ / L      (first order, rank 2)

(``constrain_to_length``). Azimuth, pitch, heading and their σ are then those of b̌, C_b̌;
``baseline_enu`` stays the unconstrained b̂. The gain is the correlation of the length
error with the cross-track error: it cannot remove the cross-track error itself.
The length check compares |b̂| − L with its own σ_L = √(uᵀ C_b u) as well as with
``length_tolerance_m``: a fix is rejected when |b̂| − L exceeds both
``length_tolerance_m`` and ``length_sigma_factor``·σ_L (default 4): a 3 cm window alone
rejected 35 of 1000 correct L1 fixes of the heading scene's weakest geometry (seed 4,
σ_L 12 mm mean, 18 mm max; benchmarks/heading_single_frequency.py).
The vehicle heading ψ = ψ_b − α with α = atan2(ΔL_x, ΔL_y), the azimuth of the antenna
baseline in the body frame (ΔL = L_secondary − L_primary, body RFU), holds for a level
vehicle. With the attitude known (pitch θ, roll γ, e.g. from the GMIKF):
C_b^n(θ, γ, ψ) = R_ψ C_b^n(θ, γ, 0) (001 eq. 2.2.4; R_ψ the rotation about up by ψ), so
ψ = ψ_b − α', α' the azimuth of C_b^n(θ, γ, 0) ΔL (``heading_with_attitude``).

Single-frequency receivers (RtkConfig.frequencies = ("L1",)) use gnss.rtk's L1-only
ambiguity resolution; the length check then also guards the partial fixes.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gnss.double_difference import form_double_differences
from gnss.epoch_matching import nearest_epoch
from gnss.errors import GnssInputError
from gnss.geodesy import ecef_to_enu_matrix, ecef_to_geodetic
from gnss.rinex import NavData, ObsData
from gnss.rtk import (
    Q_FIXED,
    Q_FLOAT,
    RtkConfig,
    dd_slip_flags,
    observed_frequencies,
    process_dd_epochs,
)
from gnss.spp import filled_positions, solve_spp_session


@dataclass
class HeadingSolution:
    t_gps: np.ndarray            # (n,) s
    baseline_enu: np.ndarray     # (n, 3) m, secondary − primary
    baseline_sigma_enu: np.ndarray  # (n, 3) m
    baseline_cov_enu: np.ndarray  # (n, 3, 3) m², full ENU covariance (module doc)
    length_m: np.ndarray         # (n,)
    baseline_azimuth: np.ndarray  # (n,) rad
    baseline_pitch: np.ndarray   # (n,) rad
    heading: np.ndarray          # (n,) rad, vehicle forward axis (level-vehicle conversion)
    sigma_heading: np.ndarray    # (n,) rad
    sigma_pitch: np.ndarray      # (n,) rad
    q: np.ndarray                # (n,) 1 fixed (length-validated), 2 float, 0 none
    ratio: np.ndarray            # (n,)
    length_rejected: np.ndarray  # (n,) bool: a ratio-test fix rejected by the length check
    baseline_constrained_enu: np.ndarray | None = None  # (n, 3) m, b̌ on |b| = L (doc)

    @property
    def fix_rate(self) -> float:
        solved = self.q > 0
        return float((self.q == Q_FIXED).sum() / max(solved.sum(), 1))


def body_baseline_azimuth(primary_lever_arm, secondary_lever_arm) -> float:
    """α: azimuth (rad, from the body y axis towards x) of L_secondary − L_primary."""
    d = np.asarray(secondary_lever_arm, float) - np.asarray(primary_lever_arm, float)
    if np.hypot(d[0], d[1]) < 0.1:
        raise GnssInputError("antennas.secondary_lever_arm_m: the antennas are less than 0.1 m "
                             "apart horizontally; no heading can be derived")
    return float(np.arctan2(d[0], d[1]))


def baseline_to_heading(b_enu, sigma_enu, body_azimuth, cov_enu=None):
    """Azimuth, pitch, vehicle heading and their σ from ENU baselines b_enu (n,3) m (module
    doc). cov_enu (n,3,3) m²: the full baseline covariance; else diag(sigma_enu²)."""
    b = np.asarray(b_enu, float)
    if cov_enu is None:
        s = np.asarray(sigma_enu, float)
        cov = np.zeros((b.shape[0], 3, 3))
        cov[:, [0, 1, 2], [0, 1, 2]] = s ** 2
    else:
        cov = np.asarray(cov_enu, float)
    horiz2 = b[:, 0] ** 2 + b[:, 1] ** 2
    horiz = np.sqrt(horiz2)
    norm2 = horiz2 + b[:, 2] ** 2
    az = np.arctan2(b[:, 0], b[:, 1]) % (2 * np.pi)
    pitch = np.arctan2(b[:, 2], horiz)
    h = np.maximum(horiz, 1e-9)
    g_az = np.column_stack([b[:, 1], -b[:, 0], np.zeros(b.shape[0])]) / h[:, None] ** 2
    g_pitch = np.column_stack([-b[:, 2] * b[:, 0] / h, -b[:, 2] * b[:, 1] / h, horiz]) \
        / norm2[:, None]
    sig_az = np.sqrt(np.einsum("ni,nij,nj->n", g_az, cov, g_az))
    sig_pitch = np.sqrt(np.einsum("ni,nij,nj->n", g_pitch, cov, g_pitch))
    heading = (az - body_azimuth) % (2 * np.pi)
    return az, pitch, heading, sig_az, sig_pitch


def constrain_to_length(b_hat, cov, length: float):
    """b̌ = argmin (b − b̂)ᵀ C⁻¹ (b − b̂) subject to |b| = length (module doc) and its first-
    order covariance C − C u (uᵀ C u)⁻¹ uᵀ C, u = b̌/|b̌|. b_hat (3,) m, cov (3,3) m²
    (positive definite), length m. With C = V diag(λ) Vᵀ and c = Vᵀ b̂ the secular equation
    f(μ) = Σ c_i² / (1 + μ λ_i)² − L² = 0 is solved by Newton's method on the branch
    1 + μ λ_i > 0 (f decreasing and convex there: the global minimum) from μ = 0."""
    b_hat = np.asarray(b_hat, float)
    lam, v = np.linalg.eigh(np.asarray(cov, float))
    c = v.T @ b_hat
    lo = -1.0 / lam.max()                         # f → +∞ as μ → lo⁺ (c of λ_max ≠ 0)
    mu = 0.0
    for _ in range(100):
        d = 1.0 + mu * lam
        f = np.sum(c * c / (d * d)) - length * length
        df = -2.0 * np.sum(c * c * lam / (d * d * d))
        step = f / df
        mu_new = mu - step
        if mu_new <= lo:                          # keep to the branch (Newton from above)
            mu_new = 0.5 * (mu + lo)
        if abs(mu_new - mu) <= 1e-15 * max(1.0, abs(mu)) + 1e-30:
            mu = mu_new
            break
        mu = mu_new
    b = v @ (c / (1.0 + mu * lam))
    u = b / np.linalg.norm(b)
    cu = cov @ u
    return b, cov - np.outer(cu, cu) / (u @ cu)


def heading_with_attitude(baseline_azimuth, primary_lever_arm, secondary_lever_arm, pitch,
                          roll):
    """Vehicle heading ψ = ψ_b − α' (rad) from the baseline azimuth ψ_b (rad) and the known
    pitch θ / roll γ (rad; scalars or arrays like ψ_b): α' is the azimuth of
    C_b^n(θ, γ, 0) ΔL, ΔL = L_secondary − L_primary (body RFU, m; module doc)."""
    d = np.asarray(secondary_lever_arm, float) - np.asarray(primary_lever_arm, float)
    sp, cp = np.sin(pitch), np.cos(pitch)
    sr, cr = np.sin(roll), np.cos(roll)
    east = cr * d[0] + sr * d[2]                       # rows 0 and 1 of C_b^n(θ, γ, 0)
    north = sr * sp * d[0] + cp * d[1] - cr * sp * d[2]
    return (np.asarray(baseline_azimuth) - np.arctan2(east, north)) % (2 * np.pi)


def heading_from_dd_epochs(epochs, x_lin, ref_ecef_per_epoch, baseline_length_m: float,
                           body_azimuth: float, config: RtkConfig | None = None,
                           length_tolerance_m: float = 0.03, row_slip=None, ref_slip=None,
                           progress=None, constrain_length: bool = True,
                           length_sigma_factor: float = 4.0) -> HeadingSolution:
    """Moving-baseline solution from DD epochs (primary = base) linearised at x_lin (n,3)
    ECEF; ref_ecef_per_epoch (n,3): the primary positions the DD were formed with.
    constrain_length: azimuth/pitch/heading of fixed epochs from the length-constrained
    baseline b̌ (module doc); length_sigma_factor: the σ_L multiple of the length check."""
    cfg = config or RtkConfig()
    sol = process_dd_epochs(epochs, x_lin, cfg, row_slip, ref_slip, progress)
    n = len(epochs)
    b_enu = np.full((n, 3), np.nan)
    c_enu = np.full((n, 3, 3), np.nan)
    for i in range(n):
        if sol.q[i] == 0:
            continue
        lat, lon, _ = ecef_to_geodetic(*ref_ecef_per_epoch[i])
        c = ecef_to_enu_matrix(lat, lon)
        b_enu[i] = c @ (sol.ecef[i] - ref_ecef_per_epoch[i])
        # sol.cov_enu is in the ENU frame at the secondary: rotate to the primary's
        lat_s, lon_s, _ = ecef_to_geodetic(*sol.ecef[i])
        r = c @ ecef_to_enu_matrix(lat_s, lon_s).T
        c_enu[i] = r @ sol.cov_enu[i] @ r.T
    s_enu = np.sqrt(np.einsum("nii->ni", c_enu))
    length = np.linalg.norm(b_enu, axis=1)
    q = sol.q.copy()
    u = b_enu / np.where(length > 0, length, 1.0)[:, None]
    sigma_length = np.sqrt(np.einsum("ni,nij,nj->n", u, c_enu, u))
    miss = np.abs(length - baseline_length_m)
    rejected = (q == Q_FIXED) & (miss > length_tolerance_m) & \
        ~(miss <= length_sigma_factor * sigma_length)
    q[rejected] = Q_FLOAT
    b_use, c_use = b_enu.copy(), c_enu.copy()
    if constrain_length:
        for i in np.flatnonzero(q == Q_FIXED):
            b_use[i], c_use[i] = constrain_to_length(b_enu[i], c_enu[i], baseline_length_m)
    az, pitch, heading, sig_az, sig_pitch = baseline_to_heading(b_use, None, body_azimuth,
                                                                c_use)
    return HeadingSolution(t_gps=sol.t_gps, baseline_enu=b_enu, baseline_sigma_enu=s_enu,
                           baseline_cov_enu=c_enu,
                           length_m=length, baseline_azimuth=az, baseline_pitch=pitch,
                           heading=heading, sigma_heading=sig_az, sigma_pitch=sig_pitch, q=q,
                           ratio=sol.ratio, length_rejected=rejected,
                           baseline_constrained_enu=np.where((q == Q_FIXED)[:, None], b_use,
                                                             np.nan) if constrain_length
                           else None)


def dual_antenna_heading(primary: ObsData, secondary: ObsData, nav: NavData,
                         primary_lever_arm, secondary_lever_arm,
                         config: RtkConfig | None = None, length_tolerance_m: float = 0.03,
                         progress=None, primary_spp=None) -> HeadingSolution:
    """Heading and pitch from two rover antennas' RINEX observations (module doc). The
    surveyed separation is |L_secondary − L_primary| from the lever arms (m, body RFU).
    primary_spp: the primary antenna's gnss.spp.SppSession when already solved (else
    solved here)."""
    cfg = config or RtkConfig()
    primary, secondary = observed_frequencies(primary, cfg), observed_frequencies(secondary, cfg)
    length = float(np.linalg.norm(np.asarray(secondary_lever_arm, float)
                                  - np.asarray(primary_lever_arm, float)))
    alpha = body_baseline_azimuth(primary_lever_arm, secondary_lever_arm)
    spp = primary_spp if primary_spp is not None else solve_spp_session(primary, nav)
    if not spp.ok.any():
        raise GnssInputError("no primary-antenna epoch has a single-point solution",
                             source=primary.path)
    prim = filled_positions(spp)
    # rover (secondary) linearisation: the primary's position mapped to secondary epochs
    sec_lin = prim[nearest_epoch(primary.t_gps, secondary.t_gps)]
    dd = form_double_differences(primary, secondary, nav, prim, sec_lin,
                                 elevation_mask_deg=cfg.elevation_mask_deg)
    row_slip, ref_slip = dd_slip_flags(dd, primary, secondary, cfg.slip)
    epochs = [dd.epoch(i) for i in range(dd.n_epochs)]
    rows = [row_slip[dd.start[i]:dd.start[i + 1]] for i in range(dd.n_epochs)]
    ref_pos = prim[nearest_epoch(primary.t_gps, dd.t_gps)]     # the DD's base positions
    return heading_from_dd_epochs(epochs, ref_pos.copy(), ref_pos, length, alpha, cfg,
                                  length_tolerance_m, rows, ref_slip, progress)


def write_heading_csv(path, sol: HeadingSolution, fixed_only: bool = True):
    """The heading solution in the GMIKF's heading file format (docs/formats.md:
    time_gps_s, heading_deg, sigma_heading_deg), fixed epochs only by default."""
    keep = (sol.q == Q_FIXED) if fixed_only else (sol.q > 0)
    keep &= np.isfinite(sol.heading)
    table = np.column_stack([sol.t_gps[keep], np.degrees(sol.heading[keep]),
                             np.degrees(sol.sigma_heading[keep])]).astype(float)
    path = Path(path)
    np.savetxt(path, table, delimiter=",", header="time_gps_s,heading_deg,sigma_heading_deg",
               comments="", fmt="%.9f")
    return path
