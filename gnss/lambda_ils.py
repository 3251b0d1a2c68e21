"""LAMBDA integer ambiguity resolution: LDL^T factorisation, decorrelation, MLAMBDA search.

Integer least squares (ILS) problem (Teunissen 1995, J. Geod. 70:65-82):

    z_best = argmin_{z in Z^n} (a - z)^T Q_a^{-1} (a - z)                      (ILS)

solved in three steps, as in RTKLIB's ``lambda.c`` (behaviour reference only):

1. ``ldl_decompose``   Q = L^T diag(D) L, L unit *lower* triangular (RTKLIB convention; the
   factorisation runs from the last row upwards, so D[n-1] = Q[n-1, n-1]).
2. ``decorrelate``     LAMBDA reduction (de Jonge & Tiberius 1996, LGR-12): integer Gauss
   transformations make |L[i, j]| <= 1/2, symmetric permutations order D so that the
   conditional variances are as flat as possible.  The result is a unimodular integer Z with
   Q_z = Z^T Q Z = L_z^T diag(D_z) L_z and z = Z^T a.
3. ``search``          depth-first MLAMBDA search with shrinking ellipsoid
   (Chang, Yang & Zhou 2005, J. Geod. 79:552-565) for the m best integer vectors of
   (z_hat - z)^T Q_z^{-1} (z_hat - z).

The fixed solution is mapped back with a = Z^{-T} z.  The ratio test uses the RTKLIB
convention ratio = s_second / s_best (accept when ratio >= threshold, default 3.0).

Units: ambiguities and their covariance in cycles and cycles^2.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import erf, sqrt

import numpy as np
from numba import njit

from gnss.errors import GnssInputError

__all__ = [
    "LambdaInputError",
    "LambdaResult",
    "PartialFixResult",
    "bootstrap_success_rate",
    "decorrelate",
    "ldl_decompose",
    "partial_fix",
    "ratio_test",
    "resolve_integers",
    "search",
]

_SEARCH_LOOP_MAX = 10_000_000  # node visits; RTKLIB uses 10 000, generous here for n ~ 30-40


class LambdaInputError(GnssInputError, ValueError):
    """Bad ILS input (not SPD, NaN, shape).  Both a GnssInputError (CLI one-liner) and a
    ValueError (the usual numpy-style contract)."""


# --------------------------------------------------------------------------- kernels (numba)


@njit(cache=True)
def _ldl_kernel(Q):
    """Q = L^T diag(D) L with L unit lower triangular; returns (L, D, failed_row or -1)."""
    n = Q.shape[0]
    A = Q.copy()
    L = np.zeros((n, n))
    D = np.zeros(n)
    scale = 0.0
    for i in range(n):
        scale = max(scale, abs(Q[i, i]))
    for i in range(n - 1, -1, -1):
        d = A[i, i]
        if not d > 1e-14 * scale:
            return L, D, i
        D[i] = d
        for j in range(i + 1):
            L[i, j] = A[i, j] / d
        for j in range(i):
            for k in range(j + 1):
                A[j, k] -= L[i, k] * L[i, j] * d
    return L, D, -1


@njit(cache=True)
def _round_half_up(x):
    return np.floor(x + 0.5)


@njit(cache=True)
def _integer_gauss(L, Z, i, j):
    """Integer Gauss transformation: column j -= mu * column i, mu = round(L[i, j])."""
    n = L.shape[0]
    mu = _round_half_up(L[i, j])
    if mu != 0.0:
        for k in range(i, n):
            L[k, j] -= mu * L[k, i]
        for k in range(n):
            Z[k, j] -= mu * Z[k, i]


@njit(cache=True)
def _permute(L, D, Z, j, delta):
    """Swap ambiguities j and j+1 and update the factors (de Jonge & Tiberius 1996, 3.3)."""
    n = L.shape[0]
    eta = D[j] / delta
    lam = D[j + 1] * L[j + 1, j] / delta
    D[j] = eta * D[j + 1]
    D[j + 1] = delta
    for k in range(j):
        a0 = L[j, k]
        a1 = L[j + 1, k]
        L[j, k] = -L[j + 1, j] * a0 + a1
        L[j + 1, k] = eta * a0 + lam * a1
    L[j + 1, j] = lam
    for k in range(j + 2, n):
        tmp = L[k, j]
        L[k, j] = L[k, j + 1]
        L[k, j + 1] = tmp
    for k in range(n):
        tmp = Z[k, j]
        Z[k, j] = Z[k, j + 1]
        Z[k, j + 1] = tmp


@njit(cache=True)
def _reduction_kernel(L_in, D_in):
    """LAMBDA reduction; returns (Z, L_z, D_z) with Z^T Q Z = L_z^T diag(D_z) L_z."""
    n = L_in.shape[0]
    L = L_in.copy()
    D = D_in.copy()
    Z = np.eye(n)
    j = n - 2
    k = n - 2
    while j >= 0:
        if j <= k:
            for i in range(j + 1, n):
                _integer_gauss(L, Z, i, j)
        delta = D[j] + L[j + 1, j] * L[j + 1, j] * D[j + 1]
        # relative margin: a swap must shrink D[j+1] by more than rounding noise, else cycling
        if delta < D[j + 1] * (1.0 - 1e-10):
            _permute(L, D, Z, j, delta)
            k = j
            j = n - 2
        else:
            j -= 1
    return Z, L, D


@njit(cache=True)
def _sign(x):
    return -1.0 if x <= 0.0 else 1.0


@njit(cache=True)
def _search_kernel(zs, L, D, m):
    """MLAMBDA depth-first search (Chang et al. 2005, alg. 'SEARCH') for the m integer vectors
    minimising (zs - z)^T (L^T D L)^{-1} (zs - z).  Level k is conditioned on levels > k:
    zb[k] = zs[k] + sum_{i>k} L[i, k] (z[i] - zb[i]).  Returns (cands (n, m), s (m,), status)."""
    n = zs.shape[0]
    cands = np.zeros((n, m))
    s = np.full(m, np.inf)
    S = np.zeros((n, n))
    dist = np.zeros(n)
    zb = np.zeros(n)
    z = np.zeros(n)
    step = np.zeros(n)
    n_found = 0
    i_max = 0
    max_dist = np.inf
    k = n - 1
    zb[k] = zs[k]
    z[k] = _round_half_up(zb[k])
    y = zb[k] - z[k]
    step[k] = _sign(y)
    status = 1
    for _ in range(_SEARCH_LOOP_MAX):
        new_dist = dist[k] + y * y / D[k]
        if new_dist < max_dist:
            if k != 0:
                k -= 1
                dist[k] = new_dist
                for i in range(k + 1):
                    S[k, i] = S[k + 1, i] + (z[k + 1] - zb[k + 1]) * L[k + 1, i]
                zb[k] = zs[k] + S[k, k]
                z[k] = _round_half_up(zb[k])
                y = zb[k] - z[k]
                step[k] = _sign(y)
            else:
                if n_found < m:
                    for i in range(n):
                        cands[i, n_found] = z[i]
                    s[n_found] = new_dist
                    n_found += 1
                    if n_found == m:
                        i_max = 0
                        for i in range(m):
                            if s[i] > s[i_max]:
                                i_max = i
                        max_dist = s[i_max]
                else:
                    for i in range(n):
                        cands[i, i_max] = z[i]
                    s[i_max] = new_dist
                    i_max = 0
                    for i in range(m):
                        if s[i] > s[i_max]:
                            i_max = i
                    max_dist = s[i_max]
                # zig-zag to the next integer at level 0
                z[0] += step[0]
                y = zb[0] - z[0]
                step[0] = -step[0] - _sign(step[0])
        else:
            if k == n - 1:
                status = 0
                break
            k += 1
            z[k] += step[k]
            y = zb[k] - z[k]
            step[k] = -step[k] - _sign(step[k])
    order = np.argsort(s)
    return cands[:, order], s[order], status


# --------------------------------------------------------------------------- validation


def _check_vector(a, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=float)
    if arr.ndim != 1 or arr.size == 0:
        raise LambdaInputError(f"{name} must be a non-empty 1-D array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise LambdaInputError(f"{name} contains NaN or infinite values")
    return arr


def _check_covariance(Q, n: int | None = None, name: str = "Q_a") -> np.ndarray:
    arr = np.asarray(Q, dtype=float)
    if arr.ndim != 2 or arr.shape[0] != arr.shape[1] or arr.shape[0] == 0:
        raise LambdaInputError(f"{name} must be a square non-empty matrix, got shape {arr.shape}")
    if n is not None and arr.shape[0] != n:
        raise LambdaInputError(f"{name} is {arr.shape[0]}x{arr.shape[0]} but there are {n} ambiguities")
    if not np.all(np.isfinite(arr)):
        raise LambdaInputError(f"{name} contains NaN or infinite values")
    scale = np.max(np.abs(arr))
    if np.max(np.abs(arr - arr.T)) > 1e-9 * max(scale, 1e-300):
        raise LambdaInputError(f"{name} is not symmetric (max |Q - Q^T| = "
                               f"{np.max(np.abs(arr - arr.T)):.3g})")
    return 0.5 * (arr + arr.T)


# --------------------------------------------------------------------------- public API


def ldl_decompose(Q) -> tuple[np.ndarray, np.ndarray]:
    """Factor Q = L^T diag(D) L (L unit lower triangular, D > 0), RTKLIB's ``LD`` convention.

    Q: (n, n) symmetric positive definite covariance [cycles^2].
    Returns L (n, n) and D (n,) = conditional variances, D[i] = var(a_i | a_{i+1..n-1}).
    Raises LambdaInputError (a ValueError) when Q is not symmetric positive definite."""
    Qs = _check_covariance(Q)
    L, D, failed = _ldl_kernel(Qs)
    if failed >= 0:
        raise LambdaInputError(
            f"Q_a is not positive definite (non-positive pivot at row {failed} of the "
            "L^T D L factorisation)")
    return L, D


def decorrelate(L, D) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """LAMBDA reduction of Q = L^T diag(D) L (de Jonge & Tiberius 1996).

    Returns (Z, L_z, D_z): Z (n, n) int64 unimodular, Z^T Q Z = L_z^T diag(D_z) L_z with
    |L_z[i, j]| <= 1/2 (i > j) and D_z ordered by the LAMBDA swap rule.  Transformed
    ambiguities are z = Z^T a."""
    L = np.asarray(L, dtype=float)
    D = _check_vector(D, "D")
    if L.shape != (D.size, D.size):
        raise LambdaInputError(f"L must be {D.size}x{D.size}, got shape {L.shape}")
    if np.any(D <= 0.0):
        raise LambdaInputError("D must be strictly positive")
    Z, Lz, Dz = _reduction_kernel(L, D)
    return np.rint(Z).astype(np.int64), Lz, Dz


def search(zs, L, D, n_cands: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """MLAMBDA integer least-squares search (Chang et al. 2005).

    zs: (n,) float ambiguities; L, D: factors of their covariance (Q = L^T diag(D) L).
    Returns candidates (n, n_cands) int64, columns sorted by sq_norms (n_cands,) ascending,
    sq_norm = (zs - z)^T Q^{-1} (zs - z) [dimensionless]."""
    zs = _check_vector(zs, "zs")
    n = zs.size
    L = np.asarray(L, dtype=float)
    D = _check_vector(D, "D")
    if L.shape != (n, n) or D.size != n:
        raise LambdaInputError(f"L must be {n}x{n} and D length {n}, got {L.shape} and {D.size}")
    if n_cands < 1:
        raise LambdaInputError(f"n_cands must be >= 1, got {n_cands}")
    # search around zero for accuracy; integer shifts commute with ILS
    shift = np.rint(zs)
    cands, s, status = _search_kernel(zs - shift, L, D, int(n_cands))
    if status != 0:
        raise RuntimeError(f"LAMBDA search exceeded {_SEARCH_LOOP_MAX} node visits (n={n})")
    return np.rint(cands + shift[:, None]).astype(np.int64), s


@dataclass(frozen=True)
class LambdaResult:
    """Output of resolve_integers.  fixed/second: best and second-best integer vectors (n,)
    [cycles]; sq_norm_*: (a - z)^T Q_a^{-1} (a - z); ratio = sq_norm_second / sq_norm_best
    (RTKLIB convention, inf when the float vector is already integer); Z: decorrelating
    unimodular matrix; candidates (n, m) / sq_norms (m,): all m requested candidates."""

    fixed: np.ndarray
    second: np.ndarray
    sq_norm_best: float
    sq_norm_second: float
    ratio: float
    Z: np.ndarray
    candidates: np.ndarray
    sq_norms: np.ndarray


def resolve_integers(a_float, Q_a, n_cands: int = 2) -> LambdaResult:
    """LAMBDA: float ambiguities a_float (n,) [cycles] with covariance Q_a (n, n) [cycles^2]
    -> best n_cands (>= 2) integer solutions of (ILS).  Raises LambdaInputError for NaN input,
    shape mismatch or a Q_a that is not symmetric positive definite."""
    a = _check_vector(a_float, "a_float")
    Q = _check_covariance(Q_a, a.size)
    if n_cands < 2:
        raise LambdaInputError(f"n_cands must be >= 2 for the ratio test, got {n_cands}")
    L, D = ldl_decompose(Q)
    Z, Lz, Dz = decorrelate(L, D)
    shift = np.rint(a)
    z_hat = Z.T.astype(float) @ (a - shift)
    cands_z, s = search(z_hat, Lz, Dz, n_cands)
    # Z is unimodular, so Z^{-T} maps integer vectors to integer vectors exactly
    cands = np.rint(np.linalg.solve(Z.T.astype(float), cands_z.astype(float))).astype(np.int64)
    cands += shift.astype(np.int64)[:, None]
    ratio = float(s[1] / s[0]) if s[0] > 0.0 else np.inf
    return LambdaResult(fixed=cands[:, 0].copy(), second=cands[:, 1].copy(),
                        sq_norm_best=float(s[0]), sq_norm_second=float(s[1]), ratio=ratio,
                        Z=Z, candidates=cands, sq_norms=s)


def bootstrap_success_rate(Q_a) -> float:
    """Integer-bootstrapping success rate of the float ambiguities with covariance Q_a (n, n)
    [cycles^2] (Teunissen 1998, J. Geod. 72:606-612; 1999, J. Geod. 73:587-593):

        P_s = prod_i ( 2 Phi(1 / (2 sigma_i|I)) - 1 ) = prod_i erf(1 / (sqrt(8) sigma_i|I))   (PS)

    sigma_i|I^2 = D_z[i]: the conditional variances of the LAMBDA-decorrelated ambiguities
    z = Z^T a (ldl_decompose + decorrelate; D_z[i] = var(z_i | z_{i+1..n-1}), the order in
    which the bootstrap rounds and conditions, as the search does). Exact for bootstrapping
    (round z_{n-1}, condition, round z_{n-2}, ...) under Gaussian float errors, and a lower
    bound of the integer least-squares (LAMBDA) success rate, so a gate P_s >= P_0 on it
    bounds the probability of a wrong fix by 1 - P_0 when Q_a is honest. Dimensionless in
    [0, 1]; raises LambdaInputError when Q_a is not symmetric positive definite."""
    L, D = ldl_decompose(Q_a)
    _, _, Dz = decorrelate(L, D)
    p = 1.0
    for d in Dz:
        p *= erf(1.0 / sqrt(8.0 * d))
    return float(p)


def ratio_test(result: LambdaResult, threshold: float = 3.0) -> bool:
    """RTKLIB acceptance rule: fix when s_best <= 0 or s_second / s_best >= threshold."""
    if threshold < 1.0:
        raise LambdaInputError(f"ratio threshold must be >= 1, got {threshold}")
    return bool(result.sq_norm_best <= 0.0 or result.ratio >= threshold)


@dataclass(frozen=True)
class PartialFixResult:
    """Output of partial_fix.  fixed_mask (n,) bool: ambiguities held at integers;
    a_fixed (n,): integers where fixed, elsewhere the float ambiguities conditioned on the
    fixed subset (a_f - Q_fs Q_ss^{-1}(a_s - z_s)); passed: ratio test accepted a subset of
    at least min_fixed ambiguities; result: the LambdaResult of the accepted (or last tried)
    subset, indices in `subset`."""

    fixed_mask: np.ndarray
    a_fixed: np.ndarray
    passed: bool
    ratio: float
    subset: np.ndarray
    result: LambdaResult


def partial_fix(a_float, Q_a, threshold: float = 3.0, min_fixed: int = 4) -> PartialFixResult:
    """Partial ambiguity resolution by variance-ordered subset shrinking.

    Strategy: try the full set; while the ratio test fails and more than min_fixed
    ambiguities remain, drop the remaining ambiguity with the largest float variance
    Q_a[i, i] (the least determined one, typically a low-elevation satellite) and resolve the
    subset again.  The first subset that passes is fixed and the dropped floats are
    conditioned on it.  If none passes, nothing is fixed (passed=False, a_fixed = a_float)."""
    a = _check_vector(a_float, "a_float")
    Q = _check_covariance(Q_a, a.size)
    n = a.size
    if min_fixed < 1:
        raise LambdaInputError(f"min_fixed must be >= 1, got {min_fixed}")
    subset = np.arange(n)
    last = None
    last_subset = subset
    while subset.size >= max(min_fixed, 2):
        res = resolve_integers(a[subset], Q[np.ix_(subset, subset)])
        last = res
        last_subset = subset
        if ratio_test(res, threshold):
            mask = np.zeros(n, dtype=bool)
            mask[subset] = True
            a_out = a.copy()
            a_out[subset] = res.fixed
            free = ~mask
            if np.any(free):
                dz = a[subset] - res.fixed
                a_out[free] = a[free] - Q[np.ix_(free, subset)] @ np.linalg.solve(
                    Q[np.ix_(subset, subset)], dz)
            return PartialFixResult(mask, a_out, True, res.ratio, subset, res)
        worst = int(np.argmax(np.diag(Q)[subset]))
        subset = np.delete(subset, worst)
    if last is None:
        raise LambdaInputError(f"partial_fix needs at least max(min_fixed, 2) = "
                               f"{max(min_fixed, 2)} ambiguities, got {n}")
    return PartialFixResult(np.zeros(n, dtype=bool), a.copy(), False, last.ratio,
                            last_subset, last)
