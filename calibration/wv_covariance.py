"""Model-implied covariance of the Haar WV estimator, for the GMWM's standard errors.

For a Gaussian process the level-j MODWT coefficients W_{j,t} = Σ_u h_{j,u} X_{t−u} give
cov(W²_{j,t}, W²_{k,s}) = 2 c_jk(t−s)², c_jk the cross-covariance of the two coefficient
series. Summing over the M_j × M_k coefficient pairs, for M ≫ the coefficients'
correlation length (Percival & Walden 2000 §8.3, the asymptotic form behind 000 eq. 3.18),

    V_jk = cov(ν̂²_j, ν̂²_k) ≈ 2 / max(M_j, M_k) · Σ_h c_jk(h)²
         = 2 / max(M_j, M_k) · ∫_{−1/2}^{1/2} |H_j(f)|² |H_k(f)|² S(f)² df      (Parseval)

with the Haar gain |H_j(f)|² = 4 sin⁴(π f τ_j/2) / (τ_j² sin²(π f)) (τ_j = 2^j samples)
and S(f) the model's spectral density per sample (f in cycles/sample, ∫S df = variance):

=====  ===========================================================
WN     σ²
QN     4 Q² sin²(π f)                  (Q²(U_t − U_{t−1}), var U = 1)
RW     γ² / (4 sin²(π f))              (|H_j|² S stays finite at f → 0)
AR1    ξ² / ((1 − φ)² + 4 φ sin²(π f)) (= ξ²/|1 − φ e^{−2πif}|², no cancellation as φ → 1)
DR     0 (deterministic; its mean term 4 μ_j μ_k Σ_h c_jk(h) is left out)
=====  ===========================================================

The integral is a midpoint sum on a uniform grid of f ∈ (0, 1/2) with ≥ 8 points per
period 2/τ_J of the top level's gain (a numba loop, J-vector workspace). Unlike the
χ²(η₃) diagonal of wavelet_variance, V has the between-scale correlations (neighbouring
levels share samples, ρ ≈ 0.4-0.9 for RW- and AR1-dominated scales) and the exact
diagonal (η₃ = M/τ under-counts the degrees of freedom of white-noise-dominated levels
by ≈ 3). Quantisation noise is not Gaussian (uniform U): its fourth cumulant is left out.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from calibration import processes as P

_POINTS_PER_PERIOD = 8


def haar_gain2(tau: np.ndarray, f: np.ndarray) -> np.ndarray:
    """|H_j(f)|² of the MODWT Haar filter (W = (Σ last τ/2 − Σ previous τ/2)/τ), (J, F)."""
    tau = np.asarray(tau, float)[:, None]
    s = np.sin(np.pi * f)[None, :]
    return 4.0 * np.sin(np.pi * f[None, :] * tau / 2.0) ** 4 / (tau ** 2 * s ** 2)


def spectral_density_terms(model, theta, f: np.ndarray):
    """(S without RW, RW's γ² or 0): S(f) = S_rest(f) + γ²/(4 sin²(πf)), per sample."""
    s2 = np.sin(np.pi * f) ** 2
    rest = np.zeros_like(f)
    gamma2 = 0.0
    for p, b in zip(model, P.split_theta(model, theta)):
        if p == "WN":
            rest += b[0]
        elif p == "QN":
            rest += 4.0 * b[0] * s2
        elif p == "AR1":
            phi, xi2 = float(b[0]), float(b[1])
            rest += xi2 / ((1.0 - phi) ** 2 + 4.0 * phi * s2)
        elif p == "RW":
            gamma2 = float(b[0])
    return rest, gamma2


@njit(cache=True)
def _gain_spectrum_products(levels, n_grid, wn, qn, gamma2, ar_phi, ar_xi2, out):
    """out[p, q] += Σ_f a_p(f) a_q(f), a_p = |H_p|² S at the midpoints f of (0, 1/2)
    (lower triangle). sin(π f τ/2) for τ = 2, 4, 8, … by angle doubling from sin(πf)."""
    J = levels.size
    jmax = levels[J - 1]
    a = np.empty(J)
    df = 0.5 / n_grid
    for i in range(n_grid):
        x = np.pi * (i + 0.5) * df
        s = np.sin(x)
        c = np.cos(x)
        s2 = s * s
        rest = wn + 4.0 * qn * s2
        for r in range(ar_phi.size):
            rest += ar_xi2[r] / ((1.0 - ar_phi[r]) ** 2 + 4.0 * ar_phi[r] * s2)
        sj, cj, k = s, c, 0
        for j in range(1, jmax + 1):
            if j == levels[k]:
                tau2 = 4.0 ** j
                s4 = (sj * sj) ** 2
                a[k] = 4.0 * s4 / (tau2 * s2) * rest + gamma2 * s4 / (tau2 * s2 * s2)
                k += 1
                if k == J:
                    break
            sj, cj = 2.0 * sj * cj, cj * cj - sj * sj
        for p in range(J):
            for q in range(p + 1):
                out[p, q] += a[p] * a[q]


def wv_covariance(model, theta, tau, n: int, replicates: float = 1.0) -> np.ndarray:
    """V = cov(ν̂²) (J × J) of the unbiased MODWT Haar WV of n samples at scales ``tau``
    (samples, powers of 2, increasing) under ``model``/``theta``; divided by
    ``replicates`` for the mean WV of that many independent records (AWV)."""
    model = P.canonical(model)
    tau = np.asarray(tau, float)
    levels = np.round(np.log2(tau)).astype(np.int64)
    if np.any(2.0 ** levels != tau) or np.any(np.diff(levels) <= 0):
        raise ValueError("wv_covariance needs increasing power-of-two scales")
    wn = qn = gamma2 = 0.0
    phis, xi2s = [], []
    for p, b in zip(model, P.split_theta(model, theta)):
        if p == "WN":
            wn += float(b[0])
        elif p == "QN":
            qn += float(b[0])
        elif p == "RW":
            gamma2 = float(b[0])
        elif p == "AR1":
            phis.append(float(b[0]))
            xi2s.append(float(b[1]))
    n_grid = int(max(_POINTS_PER_PERIOD * tau[-1] / 4.0, 4096))
    V = np.zeros((tau.size, tau.size))
    _gain_spectrum_products(levels, n_grid, wn, qn, gamma2, np.array(phis, float),
                            np.array(xi2s, float), V)
    V = V + np.tril(V, -1).T
    V *= 2.0 * 0.5 / n_grid  # midpoint sum × df, doubled for (−1/2, 0)
    m = n - tau + 1.0
    return 2.0 * V / np.maximum.outer(m, m) / replicates
