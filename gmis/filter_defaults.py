"""Defaults shared by every filter engine and the recipe loader.

OUTLIER_ALPHA: significance level of the per-observation outlier tests (001 §5.2.3.1,
two-sided normal test of the standardized innovation); the recipe's
``[filter].outlier_alpha`` default and the default of every engine config
(GmikfConfig, TcConfig, ErrInsConfig).
"""

OUTLIER_ALPHA = 0.001

__all__ = ["OUTLIER_ALPHA"]
