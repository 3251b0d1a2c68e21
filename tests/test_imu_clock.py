"""IMU sample times from a uniform clock when the logged tags jitter (gmis.imu_clock)."""

import numpy as np
import pytest

from gmis.imu_clock import uniform_clock_times


def host_ticks(n, rate_hz=99.97, seed=0, delay_ms=1.5):
    """True sample instants of a uniform clock and the millisecond ticks a host logs for
    them: arrival after a random delay in [0, delay_ms), floored to whole ms."""
    rng = np.random.default_rng(seed)
    true = 243000.0 + np.arange(n) / rate_hz
    ticks = np.floor((true - true[0]) * 1e3 + rng.uniform(0.0, delay_ms, n)) / 1e3 + true[0]
    return true, ticks


@pytest.mark.parametrize("gap", [0, 11, 300])
def test_uniform_tags_are_returned_unchanged(gap):
    t = 100.0 + np.arange(5000) * 0.01
    t = np.delete(t, np.s_[1000:1000 + gap])            # dropped samples / a long gap
    out, fit = uniform_clock_times(t)
    assert out is t
    assert not fit.applied and fit.note("imu.csv") is None


def test_jittered_ticks_recover_the_sample_clock():
    true, ticks = host_ticks(20000)
    assert np.ptp(np.diff(ticks)) >= 1.5e-3          # the logged intervals really jitter
    out, fit = uniform_clock_times(ticks)
    assert fit.applied and fit.pieces == 1
    err = out - true
    # a constant offset (the mean logging delay) is the time_offset_s business, not this fit
    assert np.std(err) < 2e-5
    assert abs(np.mean(err) - np.mean(ticks - true)) < 2e-5
    assert fit.rate_hz == pytest.approx(99.97, rel=1e-6)
    assert np.max(np.abs(np.diff(out) - 1 / 99.97)) < 1e-7
    assert "uniform 99.97" in fit.note("imu.csv")


def test_dropped_samples_and_long_gaps_keep_their_time():
    true, ticks = host_ticks(30000, seed=1)
    keep = np.ones(true.size, bool)
    keep[5000:5003] = False                       # three dropped samples: counted
    keep[12000:12300] = False                     # a 3 s gap: a new clock piece
    out, fit = uniform_clock_times(ticks[keep])
    assert fit.applied and fit.pieces == 2
    err = out - true[keep]
    assert np.std(err) < 3e-5


@pytest.mark.parametrize("kind", ["jump", "ambiguous"])
def test_tags_that_are_not_one_clock_are_kept_with_a_reason(kind):
    true, ticks = host_ticks(10000, seed=2)
    if kind == "jump":                            # the host clock slews by 10 ms
        ticks = ticks + 0.010 * np.sin(2 * np.pi * (true - true[0]) / 60.0)
    else:
        ticks[4000:] += 0.005                     # one interval of 1.5 samples
    out, fit = uniform_clock_times(ticks)
    assert out is ticks and not fit.applied
    note = fit.note("imu.csv")
    assert "kept" in note and ("wander" in note if kind == "jump" else "whole number" in note)


def test_reader_applies_the_clock_unless_the_recipe_says_no(tmp_path):
    from gmis.readers import read_imu
    from gmis.recipe import ImuSection

    true, ticks = host_ticks(3000, rate_hz=100.0, seed=3)
    path = tmp_path / "imu.csv"
    rows = np.column_stack([ticks, np.zeros((ticks.size, 5)), np.full(ticks.size, 9.81)])
    with open(path, "w") as fh:
        fh.write("time_gps_s,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z\n")
        np.savetxt(fh, rows, delimiter=",", fmt="%.6f")
    on = read_imu(path, ImuSection(rate_hz=100.0))
    off = read_imu(path, ImuSection(rate_hz=100.0, uniform_clock=False))
    assert np.std(on.t - true) < 3e-5 and any("sample clock" in w for w in on.warnings)
    np.testing.assert_allclose(off.t, ticks, atol=1e-9)


def test_recipe_key_must_be_a_boolean(dataset):
    from gmis.errors import GmisInputError
    from gmis.recipe import load_recipe

    assert load_recipe(dataset.write(dataset.modified("imu", uniform_clock=False))
                       ).imu.uniform_clock is False
    path = dataset.write(dataset.modified("imu", uniform_clock="yes"))
    with pytest.raises(GmisInputError, match="imu.uniform_clock: expected true or false"):
        load_recipe(path)
