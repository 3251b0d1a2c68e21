"""The start of an outage run (stillness, in-motion fit, course heading, initial antenna)
sees only the GNSS epochs the run is given (gmis.run_preparation._gnss_given_to_run)."""

from dataclasses import dataclass, field

import numpy as np

from gmis.run_preparation import _gnss_given_to_run
from gmis.sensor_data import GnssSolution, HeadingData


@dataclass
class _Gnss:
    velocity_time_offset_s: float = 0.0


@dataclass
class _Recipe:
    gnss: _Gnss = field(default_factory=_Gnss)


@dataclass
class _Dataset:
    gnss: GnssSolution
    recipe: _Recipe
    heading: HeadingData | None = None


def _keep(windows):
    def keep_mask(t, count=True):
        keep = np.ones(t.size, bool)
        for a, b in windows:
            keep &= ~((t >= a) & (t <= b))
        return keep
    return keep_mask


def _dataset(offset):
    t = np.arange(0.0, 10.0, 0.25)
    n = t.size
    g = GnssSolution(t=t, llh=np.column_stack([t, 2 * t, 3 * t]), pos_sigma=np.ones((n, 3)),
                     vel_enu=np.column_stack([t, -t, 0 * t]), vel_sigma=np.ones((n, 3)),
                     q=np.ones(n), ns=np.full(n, 20), gps_week=2374)
    return _Dataset(g, _Recipe(_Gnss(offset)))


def test_withheld_fixes_leave_the_start_data():
    ds = _dataset(0.0)
    out = _gnss_given_to_run(ds, _keep([(2.0, 4.0)]))
    assert not np.any((out.gnss.t >= 2.0) & (out.gnss.t <= 4.0))
    assert out.gnss.t.size == ds.gnss.t.size - 9
    for name in ("llh", "pos_sigma", "vel_enu", "vel_sigma", "q", "ns"):
        assert getattr(out.gnss, name).shape[0] == out.gnss.t.size
    np.testing.assert_array_equal(out.gnss.llh[:, 0], out.gnss.t)    # rows stay together
    np.testing.assert_array_equal(out.gnss.vel_enu[:, 0], out.gnss.t)
    assert out.gnss.gps_week == 2374
    assert _gnss_given_to_run(ds, _keep([])) is ds


def test_a_velocity_moved_into_a_window_is_withheld_with_its_epoch():
    # velocity stamped 0.25 s late: the epoch at t = 4.25 s carries the velocity of 4.0 s
    ds = _dataset(-0.25)
    out = _gnss_given_to_run(ds, _keep([(2.0, 4.0)]),
                             velocity_offset_s=ds.recipe.gnss.velocity_time_offset_s)
    assert 4.25 not in out.gnss.t and 2.0 not in out.gnss.t and 4.5 in out.gnss.t


def test_withheld_heading_leaves_the_start_data_when_outages_remove_it():
    t = np.arange(0.0, 10.0, 0.5)
    hdg = HeadingData(t=t, heading=0.1 * t, sigma=np.full(t.size, 0.01))
    ds = _Dataset(_dataset(0.0).gnss, _Recipe(), hdg)
    out = _gnss_given_to_run(ds, _keep([(2.0, 4.0)]))
    assert not np.any((out.heading.t >= 2.0) & (out.heading.t <= 4.0))
    np.testing.assert_array_equal(out.heading.heading, 0.1 * out.heading.t)
    np.testing.assert_array_equal(out.heading.sigma, np.full(out.heading.t.size, 0.01))
    kept = _gnss_given_to_run(ds, _keep([(2.0, 4.0)]), remove_heading=False)
    assert kept.heading is hdg                       # [outages].remove_heading = false
