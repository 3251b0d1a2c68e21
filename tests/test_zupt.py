"""ZUPT/ZARU (000 eq. 5.44-5.46): the linear rows against finite differences, the stop
detector (gmis.motion), the [zupt] recipe table, and a simulated 60 s stop with GNSS and
heading withheld (benchmarks/zupt_stop.py)."""

from pathlib import Path

import numpy as np
import pytest

from benchmarks.zupt_stop import run_stop_case
from gmis.epochs import merge_streams
from gmis.errors import GmisInputError
from gmis.gmikf import GROUP_NAMES, SLOT_NAMES, SLOT_ZARU, SLOT_ZUPT
from gmis.measurement_models import zero_motion_model_and_jacobian_into
from gmis.motion import StopDetector, imu_stopped, stop_epochs
from gmis.recipe import load_recipe
from tests.test_system_model import central_difference, random_state


@pytest.mark.parametrize("n", [21, 27])
def test_zero_motion_jacobian_matches_central_differences(n):
    def h(x):
        out = np.zeros(6)
        zero_motion_model_and_jacobian_into(x, out, 0, np.zeros((6, n)), 0)
        return out

    rng = np.random.default_rng(2)
    for _ in range(5):
        x = random_state(rng, n)
        jac = np.full((6, n), 7.0)            # stale rows must be cleared
        zero_motion_model_and_jacobian_into(x, np.zeros(6), 0, jac, 0)
        fd = central_difference(h, x, np.full(n, 1e-6))
        assert np.abs(jac - fd).max() < 1e-8
        np.testing.assert_array_equal(h(x), np.r_[x[3:6], x[12:15]])


def test_slots_and_groups():
    assert SLOT_NAMES[SLOT_ZUPT:SLOT_ZUPT + 3] == ("zupt_x", "zupt_y", "zupt_z")
    assert SLOT_NAMES[SLOT_ZARU:SLOT_ZARU + 3] == ("zaru_x", "zaru_y", "zaru_z")
    assert {"zupt", "zaru"} <= set(GROUP_NAMES)


def _imu(rate=100.0, duration=20.0, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1.0 / rate)
    gyro = rng.normal(0.0, 0.005, (t.size, 3)) + 1e-4
    accel = rng.normal(0.0, 0.05, (t.size, 3)) + [0.0, 0.0, 9.81]
    return t, gyro, accel


def test_imu_stop_test_sees_acceleration_and_turns():
    t, gyro, accel = _imu()
    det = StopDetector(accel_std_m_s2=0.12, gyro_rate_rad_s=0.005)
    assert imu_stopped(t, gyro, accel, det)[100:-100].all()
    moving = (t > 8.0) & (t < 12.0)
    acc = accel.copy()
    acc[moving, 1] += 1.5 * np.clip((t[moving] - 8.0), 0.0, 1.0)   # drive-off ramp
    assert not imu_stopped(t, gyro, acc, det)[(t > 8.5) & (t < 9.0)].any()
    gyr = gyro.copy()
    gyr[moving, 2] += 0.05                                        # 3 °/s turn
    assert not imu_stopped(t, gyr, accel, det)[(t > 8.5) & (t < 11.5)].any()


def test_gnss_speed_vetoes_and_gaps_leave_the_imu_to_decide():
    t, gyro, accel = _imu()
    gnss_t = np.arange(0.0, 20.0, 0.2)
    ep = merge_streams(t, gnss_t, None, None)
    speed = np.where(gnss_t < 10.0, 0.0, 5.0)   # "moving" after 10 s (constant speed)
    gnss_t_kept, speed_kept = gnss_t[gnss_t < 15.0], speed[gnss_t < 15.0]
    on = stop_epochs(ep, np.hstack([gyro, accel]), gnss_t_kept, speed_kept,
                     StopDetector(accel_std_m_s2=0.12))
    assert on[(ep.t > 1.0) & (ep.t < 8.5)].all()
    assert not on[(ep.t > 11.0) & (ep.t < 15.0)].any()
    assert on[ep.t > 17.0].all()                # no GNSS: the IMU decides


def test_recipe_zupt_table(dataset):
    doc = dataset.modified("zupt", sigma_velocity_m_s=0.02, sigma_rate_deg_s=0.05)
    recipe = load_recipe(dataset.write(doc))
    assert recipe.zupt.sigma_velocity_m_s == 0.02
    assert recipe.zupt.sigma_rate_rad_s == pytest.approx(np.radians(0.05))
    bad = dataset.modified("zupt", sigma_velocity_m_s=-1.0)
    with pytest.raises(GmisInputError, match="zupt.sigma_velocity_m_s"):
        load_recipe(dataset.write(bad, "bad.toml"))


def test_sixty_second_stop_without_gnss(tmp_path):
    out = run_stop_case(tmp_path)
    pos, hdg = out["with"]
    pos0, hdg0 = out["without"]
    assert pos < 0.1 and hdg < 0.05, out["with"]
    assert pos0 > 10 * pos and hdg0 > 10 * hdg, out["without"]   # ZUPT/ZARU do the work
    assert out["summary_with"]["rejected_observations"]["zupt_x"] == 0



def test_false_stops_at_speed_are_refuted_as_a_whole():
    """The real drive, [zupt] on, its 5th outage window (11 m/s on a straight road): the IMU
    stop detector passes two windows at 11.1 m/s. Their forward v^b row fails its test, so
    the stop hypothesis is refuted and all six ZUPT/ZARU rows are dropped
    (gmis.gmikf.refute_stop); before, the lateral/vertical v^b and the ZARU rows were
    accepted with a stop's σ and the window's error grew from 1.4 to 2.2 m."""
    from tests.shared_data import DRIVE_BOULDER, require

    require(DRIVE_BOULDER)
    import dataclasses

    from gmis.recipe import ZuptSection
    from gmis.run_preparation import prepare_run, run_prepared

    recipe = load_recipe(Path(__file__).resolve().parents[1]
                         / "datasets" / "drive-boulder-0708" / "recipe.toml")
    recipe = dataclasses.replace(recipe, zupt=ZuptSection())
    prep = prepare_run(recipe, gnss_outages=[(243478.499, 243493.499)])
    rec = run_prepared(prep)
    g = prep.dataset.gnss
    speed = np.interp(rec.t, g.t, np.linalg.norm(g.vel_enu, axis=1))
    stop_rows = np.isfinite(rec.innov[:, SLOT_ZUPT:SLOT_ZARU + 3]).any(axis=1)
    moving = stop_rows & (speed > 2.0)
    assert moving.sum() >= 1                                   # the detector was fooled
    assert np.all(rec.rejected[moving, SLOT_ZUPT:SLOT_ZARU + 3] == 1)
    still = stop_rows & (speed < 0.05)
    assert still.sum() > 100 and rec.rejected[still, SLOT_ZUPT:SLOT_ZARU + 3].mean() < 0.05


def test_release_stop_clears_still_up_to_the_next_zupt_epoch():
    from gmis.gmikf import release_stop

    still = np.ones(12, dtype=np.bool_)
    still[10] = False                      # the detected stop ends before epoch 10
    zupt_on = np.zeros(12, dtype=np.bool_)
    zupt_on[[0, 4, 8, 11]] = True
    release_stop(0, still, zupt_on)
    np.testing.assert_array_equal(still[:6], [True, False, False, False, False, True])
    release_stop(8, still, zupt_on)         # stops at the end of the stop, not at 11
    np.testing.assert_array_equal(still[8:], [True, False, False, True])


def test_a_refuted_stop_does_not_freeze_the_process_noise():
    """The false stops of test_false_stops_at_speed_are_refuted_as_a_whole: after a refuted
    ZUPT/ZARU epoch the predictions up to and including the next ZUPT/ZARU epoch are not
    treated as at rest (gmis.gmikf.release_stop); before, ``still`` stayed set and the
    at-rest factor froze the jerk/angular-acceleration noise of a car at 11 m/s."""
    from tests.shared_data import DRIVE_BOULDER, require

    require(DRIVE_BOULDER)
    import dataclasses

    from gmis.recipe import ZuptSection
    from gmis.run_filter import zupt_update_epochs
    from gmis.run_preparation import prepare_run, run_prepared

    recipe = load_recipe(Path(__file__).resolve().parents[1]
                         / "datasets" / "drive-boulder-0708" / "recipe.toml")
    recipe = dataclasses.replace(recipe, zupt=ZuptSection())
    prep = prepare_run(recipe, gnss_outages=[(243478.499, 243493.499)])
    stopped, zupt_on = zupt_update_epochs(prep.epochs, prep.meas, prep.config)
    rec = run_prepared(prep)
    refuted = np.flatnonzero(zupt_on & (rec.rejected[:, SLOT_ZUPT:SLOT_ZARU + 3] == 1).all(1))
    assert refuted.size >= 1
    at_rest = stopped | prep.stationary          # the flags before the run
    on = np.flatnonzero(zupt_on)
    moving = np.flatnonzero(~at_rest)
    for e in refuted:
        nxt, ends = on[on > e], moving[moving > e]
        end = min(nxt[0] if nxt.size else len(rec.t) - 1,
                  ends[0] - 1 if ends.size else len(rec.t) - 1)   # last epoch released
        assert at_rest[e + 1:end + 1].all()              # detected as stopped there ...
        assert not rec.still[e + 1:end + 1].any()        # ... but not treated as at rest
    accepted = np.flatnonzero(zupt_on & (rec.rejected[:, SLOT_ZUPT:SLOT_ZARU + 3] == 0)
                              .all(1))
    accepted = accepted[accepted + 1 < len(rec.t)]
    assert rec.still[accepted + 1].mean() > 0.9           # real stops stay at rest
