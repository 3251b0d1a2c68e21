"""gmis.critical_values: the tabulated default-level quantiles equal scipy's bit for bit,
other levels fall through to scipy.special, and a default run's values need no scipy."""

import subprocess
import sys

import numpy as np
from scipy import stats
from scipy.special import gammaincinv, ndtri

from gmis.critical_values import _CHI2_TABLE, chi2_quantile, normal_quantile
from gmis.filter_defaults import OUTLIER_ALPHA
from gmis.gmikf import N_SLOTS


def test_table_equals_scipy_exactly():
    alpha = OUTLIER_ALPHA
    dof = np.arange(1, N_SLOTS + 1)
    assert _CHI2_TABLE.size == N_SLOTS
    got = chi2_quantile(1 - alpha, dof)
    assert np.array_equal(got, 2.0 * gammaincinv(dof / 2.0, 1 - alpha))
    assert np.array_equal(got, stats.chi2.ppf(1 - alpha, dof))
    assert normal_quantile(1 - alpha / 2) == ndtri(1 - alpha / 2) == stats.norm.ppf(
        1 - alpha / 2)
    assert chi2_quantile(1 - alpha, 7) == stats.chi2.ppf(1 - alpha, 7)


def test_other_levels_and_dof_from_scipy():
    assert np.array_equal(chi2_quantile(0.99, np.arange(1, 30)),
                          stats.chi2.ppf(0.99, np.arange(1, 30)))
    assert chi2_quantile(1 - OUTLIER_ALPHA, 40) == stats.chi2.ppf(1 - OUTLIER_ALPHA, 40)
    assert chi2_quantile(1 - OUTLIER_ALPHA, 2.5) == stats.chi2.ppf(1 - OUTLIER_ALPHA, 2.5)
    assert normal_quantile(0.975) == stats.norm.ppf(0.975)


def test_default_values_import_no_scipy():
    code = ("import sys, numpy as np; from gmis.critical_values import chi2_quantile, "
            "normal_quantile; chi2_quantile(1 - 0.001, np.arange(1, 24)); "
            "normal_quantile(1 - 0.001 / 2); print('scipy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"
