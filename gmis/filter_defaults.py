"""Defaults shared by every filter engine and the recipe loader.

OUTLIER_ALPHA: significance level of the per-observation outlier tests (001 §5.2.3.1,
two-sided normal test of the standardized innovation); the recipe's
``[filter].outlier_alpha`` default and the default of every engine config
(GmikfConfig, TcConfig, ErrInsConfig).


REOPEN_AFTER_EPOCHS: an aiding group (GNSS position, GNSS velocity, heading) rejected at this
many consecutive epochs re-opens the filter covariance and is accepted again
(gmis.lockout_recovery; ``[filter].reopen_after_epochs``, 0 = never).

IMU_OUTLIER_TEST: whether the IMU rows take part in those tests
(``[filter].imu_outlier_test``).

Q_RATE_HZ: the recipe's per-step process noise ([noise] jerk, angular acceleration, bias
and scale drift) is 1σ per step of 1/Q_RATE_HZ s whatever the IMU rate (001 Table 6-2's
100 Hz; GmikfConfig.q_rate_hz, docs/DESIGN.md "Process noise from Δt").
"""

OUTLIER_ALPHA = 0.001
REOPEN_AFTER_EPOCHS = 2
IMU_OUTLIER_TEST = False
Q_RATE_HZ = 100.0

__all__ = ["IMU_OUTLIER_TEST", "OUTLIER_ALPHA", "Q_RATE_HZ", "REOPEN_AFTER_EPOCHS"]
