"""The default drive with a 200 Hz IMU and 1 Hz GNSS / heading (issue 13): the filter must
be consistent at the other rate — ensemble NEES of r^n, v^b, θ over 8 seeds inside the
χ²(24)/8 band on ≥ 90 % of the moving, aided 1 Hz epochs (tests/simulated_drives.py,
assert_ensemble_nees_in_band, for the statistic, the drive and the choice of biases).

This replaces a single-seed test (NEES sampled every 10 s, time-averaged against χ²(3K)/K)
that was a strict xfail: its samples are not independent for the tilt, and it fell outside
its band on 20 % of seeds of this scenario with a consistent filter (docs/DESIGN.md
"Ensemble NEES tests")."""

from tests.simulated_drives import assert_ensemble_nees_in_band


def test_ensemble_nees_within_chi2_band_at_200hz_1hz():
    assert_ensemble_nees_in_band(imu_rate=200.0, gnss_rate=1.0)
