"""The block-wise scans of gmis.motion (docs/DESIGN.md "Bounded memory") against the
whole-array forms they replaced: the same results bit for bit."""

import numpy as np
import pytest

from gmis.epochs import merge_streams
from gmis.motion import first_motion, stationary_epochs


def _first_moved_whole(imu_t, gyro, accel, t0, block_s=1.0, da=0.2, dg=0.01):
    """first_motion's IMU test written over all the blocks at once: block means by
    bincount against block 0's mean without the samples beyond 6 scaled MADs of its
    median; the first non-empty block that differs from it and whose next non-empty
    block does too."""
    block = np.floor((imu_t - t0) / block_s).astype(np.int64)
    ok = block >= 0
    if not ok.any():
        return None
    b = block[ok]
    count = np.bincount(b)
    full = np.flatnonzero(count > 0)
    means_a = np.stack([np.bincount(b, accel[ok, j]) for j in range(3)], 1)[full]
    means_g = np.stack([np.bincount(b, gyro[ok, j]) for j in range(3)], 1)[full]
    means_a /= count[full, None]
    means_g /= count[full, None]
    first = ok & (block == full[0])

    def robust(x):       # the rows with every axis within 6 scaled MADs of its median
        med = np.median(x, axis=0)
        mad = 1.4826 * np.median(np.abs(x - med), axis=0)
        keep = (np.abs(x - med) <= 6.0 * np.maximum(mad, 1e-12)).all(axis=1)
        return keep
    keep = robust(np.hstack([accel[first], gyro[first]]))
    ref_a, ref_g = accel[first][keep].mean(axis=0), gyro[first][keep].mean(axis=0)
    moved = ((np.abs(means_a - ref_a).max(axis=1) > da)
             | (np.abs(means_g - ref_g).max(axis=1) > dg))
    k = np.flatnonzero(moved[:-1] & moved[1:])
    return t0 + float(full[k[0]]) * block_s if k.size else None


@pytest.mark.parametrize("seed", range(12))
def test_first_motion_equals_the_whole_array_scan(seed):
    """Motion anywhere (in the first piece, far beyond it, never), gaps, a t0 before the
    first sample or inside the data, blocks longer than a piece."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(50, 300_000))
    t = 5000.0 + np.cumsum(rng.uniform(0.009, 0.011, n))
    if seed % 3 == 0:                       # a gap of some seconds
        t[n // 2:] += rng.uniform(2, 30)
    z = rng.normal(0, 0.02, (n, 6))
    z[:, 5] += 9.81
    if seed % 4 != 3:                       # the vehicle moves from some sample on
        z[int(rng.integers(0, n)):, 3] += rng.uniform(0.1, 0.5)
    gyro, accel = z[:, :3], z[:, 3:]
    block_s = 900.0 if seed == 5 else 1.0  # a block of ~90 000 samples
    for t0 in (t[0], t[0] - 0.37, t[min(n - 1, 777)] + 0.001):
        got = first_motion(t, gyro, accel, t0, block_s=block_s)
        assert got == _first_moved_whole(t, gyro, accel, t0, block_s), (t0, got)


def test_one_wild_sample_is_not_motion():
    """A partial first line of a log that parses as numbers (19 g), or a spike later in
    the static part, moves one block mean: neither dates a start (helper review,
    2026-12-06: the first-line spike turned the drive into a moving start, attitude
    flipped by 180 deg); real motion after it still does."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 120.0, 0.01)
    z = rng.normal(0, 0.02, (t.size, 6))
    z[:, 5] += 9.81
    for at in (0, 4321):
        spiked = z.copy()
        spiked[at, 3:] = [186.0, 0.27, 10.0]
        assert first_motion(t, spiked[:, :3], spiked[:, 3:], 0.0) is None
        spiked[9000:, 3] += 0.3                     # the vehicle starts at t = 90 s
        assert first_motion(t, spiked[:, :3], spiked[:, 3:], 0.0) == 90.0


def _still_brute_force(t, gnss_t, speed, margin=1.0, threshold=0.2):
    """One epoch, written out: every sample within ±margin slow, and samples reaching to
    within one median GNSS interval of both ends of the window."""
    inside = (gnss_t >= t - margin) & (gnss_t <= t + margin)
    if not inside.any():
        return False
    step = np.median(np.diff(gnss_t)) * (1 + 1e-6)
    w = gnss_t[inside]
    return bool(np.all(speed[inside] < threshold) and w[0] <= t - margin + step
                and w[-1] >= t + margin - step)


def test_stationary_epochs_equals_the_brute_force_form():
    rng = np.random.default_rng(3)
    imu_t = np.arange(0.0, 1500.0, 0.01)
    gnss_t = np.arange(0.0, 1500.0, 0.2) + 0.05
    gnss_t = gnss_t[(gnss_t < 400) | (gnss_t > 412)]       # an outage
    stops = np.repeat(rng.random(gnss_t.size // 100 + 1) < 0.4, 100)[:gnss_t.size]
    speed = np.where(stops, 0.05, 3.0)               # stops of 20 s
    ep = merge_streams(imu_t, pos_t=gnss_t, tolerance_s=1e-3)
    got = stationary_epochs(ep, gnss_t, speed)
    assert got.any() and not got.all()
    for e in range(0, ep.t.size, 37):
        assert got[e] == _still_brute_force(ep.t[e], gnss_t, speed), ep.t[e]


def test_an_outage_that_ends_in_a_stop_is_not_still_until_the_window_is_covered():
    """GNSS withheld while the vehicle brakes, back once it stands: the slow samples after
    the gap say nothing about the second before it, so the first second after the outage
    is not stationary (the filter still carries the braking acceleration)."""
    imu_t = np.arange(0.0, 60.0, 0.01)
    gnss_t = np.arange(0.0, 60.0, 0.25)
    speed = np.where(gnss_t < 30.0, 5.0, 0.0)          # stopped from t = 30 s
    keep = (gnss_t < 20.0) | (gnss_t >= 30.0)           # outage 20-30 s
    ep = merge_streams(imu_t, pos_t=gnss_t[keep], tolerance_s=1e-3)
    got = stationary_epochs(ep, gnss_t[keep], speed[keep])
    t_still = ep.t[got]
    assert t_still.size and t_still[0] >= 30.75 - 1e-9
    assert t_still[0] < 30.76
    # without the outage the end of the motion is what keeps the first second out
    ep_full = merge_streams(imu_t, pos_t=gnss_t, tolerance_s=1e-3)
    full = stationary_epochs(ep_full, gnss_t, speed)
    assert ep_full.t[full][0] > 30.75


def test_quantised_samples_keep_a_reference_and_see_the_motion():
    """Coarsely quantised samples (MAD 0 on some axes): the wild-sample test keeps rows
    (a floor under the MAD), so the reference stays finite and the motion is seen, on
    every one of 200 seeds (before the floor: missed on 1 of 200, a NaN reference)."""
    t = np.arange(3000) * 0.01
    for seed in range(200):
        rng = np.random.default_rng(seed)
        acc = np.round((np.array([0, 0, 9.8]) + rng.normal(0, 0.0067, (t.size, 3))) / 0.01) * 0.01
        gyr = np.round(rng.normal(0, 0.00067, (t.size, 3)) / 0.001) * 0.001
        acc[1500:, 0] += 1.0
        assert first_motion(t, gyr, acc, 0.0) == 15.0, seed
