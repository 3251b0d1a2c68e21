"""The outlier-test truncation weights of the loop (gmis.gmikf.truncation_terms) against a
Monte Carlo of the z-test itself: draw d ~ N(0, D), reject the tested rows with
|d_a|/√D_aa > c, drop them, and form the Helmert quadratic forms and traces of the kept
system as the loop does. Their mean difference must be −τ w (vce.estimate.
truncation_deficit) for every elementary component, the untested rows included: those
lose nothing of their own but gain the tails of the rejected rows they are correlated
with (the reason κ may not divide their quadratic forms).

With one tested row per epoch the weights are exact at any α (kept: E[ddᵀ | kept] =
D − (1 − κ) D e_a e_aᵀ D / D_aa, rejected: the kept rows' conditional covariance; both
weighted by their probabilities give τ exactly), so the Monte Carlo must agree within its
own error. Several correlated tested rows add the overlap of their tails, which the
first-order sum ignores (docs/DESIGN.md)."""

import numpy as np
from scipy import stats

from gmis import gmikf
from vce.estimate import truncation_deficit

ALPHA = 0.01          # large enough for the effect to stand out of the MC error
SLOTS = [0, 1, 2, 3, 4, 5, 12]   # IMU rows (untested), heading row (tested)
N_NOISE = 2


def _epoch(rng):
    m = len(SLOTS)
    r = rng.uniform(0.5, 2.0, m)
    q = rng.uniform(0.2, 1.0, N_NOISE)
    h = rng.normal(size=(m, N_NOISE))                 # HΛ columns of the noise axes
    a = 1.5 * rng.normal(size=(m, 3))                  # predicted-state part
    d_cov = np.diag(r) + (h * q) @ h.T + a @ a.T
    return r, q, h, d_cov


def _kernel_weights(r, q, h, d_cov):
    m = len(SLOTS)
    ws = gmikf.make_workspace(21, 18)
    for k, i in enumerate(SLOTS):
        ws.used[k] = i
        ws.r_all[i] = r[k]
    dinv = np.linalg.inv(d_cov)
    ws.s[:m, :m] = d_cov
    ws.dinv[:m, :m] = dinv
    ws.hl[:m, :N_NOISE] = h
    ws.sinv_hl[:m, :N_NOISE] = dinv @ h
    q_var = np.zeros(18 + 3)
    q_var[:N_NOISE] = q
    trunc = np.zeros(gmikf.N_SLOTS + 18 + 1)
    gmikf.truncation_terms(m, q_var, N_NOISE, False, ws, trunc)
    return np.r_[trunc[SLOTS], trunc[gmikf.N_SLOTS:gmikf.N_SLOTS + N_NOISE], trunc[-1]]


def _forms(d, keep, r, q, h, d_cov):
    """(quadratic forms − traces) of the kept rows: slots, noise axes, total."""
    idx = np.flatnonzero(keep)
    dk = d_cov[np.ix_(idx, idx)]
    dinv = np.linalg.inv(dk)
    u = d[:, idx] @ dinv                               # (D⁻¹d)ᵀ per draw
    out = np.zeros((d.shape[0], len(SLOTS) + N_NOISE + 1))
    for j, a in enumerate(idx):
        out[:, a] = r[a] * u[:, j] ** 2 - r[a] * dinv[j, j]
    hk = h[idx]
    out[:, len(SLOTS):-1] = q * (u @ hk) ** 2 - q * np.einsum("ak,ab,bk->k", hk, dinv, hk)
    out[:, -1] = np.einsum("na,na->n", u, d[:, idx]) - idx.size
    return out


def test_truncation_weights_match_a_monte_carlo_of_the_z_test():
    rng = np.random.default_rng(7)
    r, q, h, d_cov = _epoch(rng)
    w = _kernel_weights(r, q, h, d_cov)
    tau = truncation_deficit(ALPHA)
    c = stats.norm.ppf(1 - ALPHA / 2)
    n = 400_000
    d = rng.multivariate_normal(np.zeros(len(SLOTS)), d_cov, size=n)
    tested = np.array([i >= 6 for i in SLOTS])
    assert tested.sum() == 1
    keep = ~(tested & (np.abs(d) / np.sqrt(np.diag(d_cov)) > c))
    # the kept system's forms minus those of all rows (mean 0 without tests): zero but in
    # the draws with a rejection, so the Monte-Carlo error is that of the tails only
    diff = -_forms(d, np.ones(len(SLOTS), bool), r, q, h, d_cov)
    patterns, inverse = np.unique(keep, axis=0, return_inverse=True)
    for p_idx, pattern in enumerate(patterns):
        sel = inverse.ravel() == p_idx
        diff[sel] += _forms(d[sel], pattern, r, q, h, d_cov)
    mean, se = diff.mean(axis=0), diff.std(axis=0, ddof=1) / np.sqrt(n)
    # E[Σ q_i] − Σ r_i = −τ w_i (exact with one tested row)
    assert np.all(np.abs(mean + tau * w) < 4 * se), (mean, -tau * w, se)
    # the untested IMU rows do shift (w < 0: they take the rejected rows' tails) and
    # the shift is resolved by the Monte Carlo — dividing them by κ, or leaving them
    # alone, would both fail
    imu = slice(0, 6)
    assert np.all(w[imu] < 0)
    assert np.abs(tau * w[imu]).max() > 4 * se[imu].max()
