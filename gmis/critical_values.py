"""Critical values of the outlier tests (001 §5.2.3.1) from scipy.special alone.

scipy.stats costs ~0.6 s of import (its distribution classes); the two quantiles the
filters need are one special function each, and these are the formulas scipy.stats
itself evaluates (``norm._ppf`` = ndtri, ``chi2._ppf`` = 2·gammaincinv(ν/2, q); its
``ppf`` then multiplies by scale 1 and adds loc 0), so the values are bit-identical.
"""

import numpy as np
from scipy.special import gammaincinv, ndtri


def normal_quantile(q):
    """Φ⁻¹(q), the standard normal quantile (= scipy.stats.norm.ppf(q))."""
    return ndtri(q)


def chi2_quantile(q, dof):
    """χ²(q; ν) quantile with ν = dof degrees of freedom (= scipy.stats.chi2.ppf(q, dof))."""
    return 2.0 * gammaincinv(np.asarray(dof, dtype=float) / 2.0, q)
