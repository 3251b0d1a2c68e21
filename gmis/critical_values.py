"""Critical values of the outlier tests (001 §5.2.3.1) from scipy.special alone.

scipy.stats costs ~0.6 s of import (its distribution classes); the two quantiles the
filters need are one special function each, and these are the formulas scipy.stats
itself evaluates (``norm._ppf`` = ndtri, ``chi2._ppf`` = 2·gammaincinv(ν/2, q); its
``ppf`` then multiplies by scale 1 and adds loc 0), so the values are bit-identical.

Importing scipy.special itself costs ~0.3-0.5 s CPU with scipy ≥ 1.15 (its array-API
layer imports numpy.f2py, numpy.testing, …), a fifth of a whole `gmis run`. The values
at the default level α = OUTLIER_ALPHA — the only ones a default run asks for: χ²(1 − α,
ν) for ν = 1 … 23 (the GMIKF's measurement slots) and Φ⁻¹(1 − α/2) — are therefore
tabulated below, exactly as scipy.special computed them (``repr`` round-trips a float;
tests/test_critical_values.py checks every entry against scipy for equality); any other
(q, ν) imports scipy.special on first use (docs/DESIGN.md "Start-up time").
"""

import numpy as np

from gmis.filter_defaults import OUTLIER_ALPHA

TABLE_ALPHA = 0.001  # the level the two tables below were computed at
if OUTLIER_ALPHA != TABLE_ALPHA:
    raise ImportError(f"gmis.critical_values tabulates α = {TABLE_ALPHA}, but OUTLIER_ALPHA "
                      f"is {OUTLIER_ALPHA}: recompute the tables (tests/test_critical_values.py)")
# 2·gammaincinv(ν/2, 1 − TABLE_ALPHA), ν = 1 … 23
_CHI2_Q = 1 - TABLE_ALPHA
_CHI2_TABLE = np.array([
    10.827566170662733, 13.815510557964274, 16.26623619623813, 18.46682695290317,
    20.515005652432873, 22.457744484825323, 24.321886347856854, 26.12448155837614,
    27.877164871256568, 29.58829844507442, 31.264133620239985, 32.90949040736021,
    34.52817897487089, 36.12327368039813, 37.69729821835383, 39.252354790768464,
    40.79021670690253, 42.31239633167996, 43.82019596451753, 45.31474661812586,
    46.797038041561315, 48.26794229083518, 49.7282324664315,
])
# ndtri(1 − TABLE_ALPHA / 2)
_NORMAL_Q = 1 - TABLE_ALPHA / 2
_NORMAL_VALUE = 3.2905267314919255


def normal_quantile(q):
    """Φ⁻¹(q), the standard normal quantile (= scipy.stats.norm.ppf(q))."""
    if np.ndim(q) == 0 and q == _NORMAL_Q:
        return np.float64(_NORMAL_VALUE)
    from scipy.special import ndtri
    return ndtri(q)


def chi2_quantile(q, dof):
    """χ²(q; ν) quantile with ν = dof degrees of freedom (= scipy.stats.chi2.ppf(q, dof))."""
    nu = np.asarray(dof, dtype=float)
    if np.ndim(q) == 0 and q == _CHI2_Q and nu.size and np.all(
            (nu >= 1) & (nu <= _CHI2_TABLE.size) & (nu == np.round(nu))):
        out = _CHI2_TABLE[nu.astype(np.int64) - 1]
        return out if out.ndim else np.float64(out)
    from scipy.special import gammaincinv
    return 2.0 * gammaincinv(nu / 2.0, q)
