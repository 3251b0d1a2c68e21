"""Broadcast ephemeris against IGS final orbits/clocks (2010 day 182), velocity, timing."""


import numpy as np
import pytest

from gnss.constants import C_LIGHT, OMEGA_EARTH
from gnss.ephemeris import (
    earth_rotation_correction,
    satellite_position_velocity_clock,
    select_ephemeris,
    transmit_time,
)
from gnss.rinex import read_nav
from gnss.sp3 import read_sp3
from tests.shared_data import RTKLIB_TEST as DATA

pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"real data folder {DATA} absent")


@pytest.fixture(scope="module")
def nav(tmp_path_factory):
    return read_nav(DATA / "brdc1820.10n", cache_dir=tmp_path_factory.mktemp("c"))


@pytest.fixture(scope="module")
def sp3():
    return read_sp3(DATA / "igs15904.sp3")


@pytest.fixture(scope="module")
def comparison(nav, sp3):
    """Broadcast states at every 15-min SP3 epoch for every PRN, and the usable mask.

    PRN01 (SVN49, unhealthy all 2010) is excluded: IGS gives it no clock for the whole
    day, and the brdc file's single health-0 PRN01 record (t_oc 06:00) describes another
    orbit (√A differs by 1.1 m^½ from the 13 other PRN01 records) — 27 000 km away from
    the SP3 position. That is a data defect, reported, not something to average in."""
    t, prn = np.meshgrid(sp3.t_gps, sp3.prn, indexing="ij")
    st = satellite_position_velocity_clock(nav, prn.ravel(), t.ravel())
    pos = st.position.reshape(sp3.position.shape)
    vel = st.velocity.reshape(sp3.position.shape)
    clk = st.clock_bias.reshape(t.shape)
    igs_excluded = np.all(np.isnan(sp3.clock), axis=0)
    usable = np.isfinite(pos[..., 0]) & np.isfinite(sp3.position[..., 0]) \
        & ~igs_excluded[None, :]
    return pos, vel, clk, usable, igs_excluded


def test_orbit_against_sp3(sp3, comparison):
    """Broadcast APC vs SP3 centre of mass, 3D. Thresholds: published GPS broadcast orbit
    errors of this era are ~1-2 m 3D RMS; the APC-CoM offset (~0-1.6 m, mostly radial)
    is not removed. Observed on this day: 3D RMS 1.87 m, max 5.7 m, radial mean −0.75 m."""
    pos, _vel, _, usable, excluded = comparison
    assert sp3.prn[excluded].tolist() == [1]
    d = pos - sp3.position
    d3 = np.linalg.norm(d, axis=2)[usable]
    radial_unit = sp3.position / np.linalg.norm(sp3.position, axis=2, keepdims=True)
    radial = np.sum(d * radial_unit, axis=2)[usable]
    rms, mx = np.sqrt(np.mean(d3 ** 2)), d3.max()
    print(f"\norbit: n={d3.size} 3D RMS {rms:.3f} m, max {mx:.3f} m, radial mean "
          f"{radial.mean():.3f} m RMS {np.sqrt(np.mean(radial ** 2)):.3f} m")
    assert usable.sum() > 2800  # 30 satellites × 96 epochs minus gaps
    assert rms < 2.5
    assert mx < 8.0
    assert np.sqrt(np.mean(radial ** 2)) < 1.5


def test_clock_against_sp3(sp3, comparison):
    """IGS clocks exclude the periodic relativistic term (−2 r·v/c²) that the broadcast
    clock includes (F e √A sin E); add it to SP3. Broadcast clock accuracy of the era is
    a few ns; observed RMS 3.9 ns, 17 ns without the relativistic term."""
    _pos, vel, clk, usable, _ = comparison
    rel = -2.0 * np.sum(sp3.position * vel, axis=2) / C_LIGHT ** 2
    ok = usable & np.isfinite(sp3.clock)
    diff_ns = (clk - (sp3.clock + rel))[ok] * 1e9
    no_rel_ns = (clk - sp3.clock)[ok] * 1e9
    rms = np.sqrt(np.mean(diff_ns ** 2))
    print(f"\nclock: RMS {rms:.2f} ns, max {np.abs(diff_ns).max():.2f} ns, mean "
          f"{diff_ns.mean():.2f} ns; without relativistic term RMS "
          f"{np.sqrt(np.mean(no_rel_ns ** 2)):.2f} ns")
    assert rms < 5.0
    assert np.sqrt(np.mean(no_rel_ns ** 2)) > 2.0 * rms


def test_velocity_matches_finite_difference(nav, sp3):
    prn = np.repeat(sp3.prn[1:], 4)
    t = np.tile(sp3.t_gps[[5, 30, 61, 90]] + 123.4, sp3.prn.size - 1)
    h = 0.5
    st = satellite_position_velocity_clock(nav, prn, t)
    idx = st.eph_index
    plus = satellite_position_velocity_clock(nav, prn, t + h, idx)
    minus = satellite_position_velocity_clock(nav, prn, t - h, idx)
    fd = (plus.position - minus.position) / (2 * h)
    ok = st.valid
    err = np.linalg.norm(st.velocity[ok] - fd[ok], axis=1)
    assert ok.sum() > 100
    assert err.max() < 1e-3  # m/s; |v| ≈ 3 km/s
    drift_fd = (plus.clock_bias - minus.clock_bias) / (2 * h)
    assert np.max(np.abs(st.clock_drift[ok] - drift_fd[ok])) < 1e-14


def test_selection_rules(nav):
    prn01 = np.flatnonzero(nav.prn == 1)
    unhealthy_toe = nav.toe[prn01[nav.health[prn01] != 0][0]]
    healthy = prn01[nav.health[prn01] == 0]
    assert select_ephemeris(nav, 1, unhealthy_toe)[0] in np.r_[healthy, -1]
    assert select_ephemeris(nav, 1, unhealthy_toe, require_healthy=False)[0] >= 0
    k = np.flatnonzero(nav.prn == 5)
    toe = nav.toe[k]
    got = select_ephemeris(nav, 5, toe + 100.0)
    np.testing.assert_allclose(nav.toe[got], toe, atol=1e-3)
    assert select_ephemeris(nav, 5, toe.min() - 7201.0)[0] == -1
    assert select_ephemeris(nav, 33, toe[0])[0] == -1


def test_transmit_time_and_sagnac(nav):
    """t_tx + P/c + Δt_sv = t_rx exactly, and the Sagnac rotation is ω_e τ |r_xy|."""
    k = np.flatnonzero((nav.prn == 7) & (nav.health == 0))[3]
    t_rx = nav.toe[k] + 600.0
    p = 2.2e7
    t_tx, idx = transmit_time(nav, 7, t_rx, p)
    st = satellite_position_velocity_clock(nav, 7, t_tx, idx)
    assert t_tx + p / C_LIGHT + st.clock_bias[0] == pytest.approx(t_rx, abs=1e-12)
    rcv = np.array([-3976219.5, 3382372.6, 3652513.0])
    rot, _, tau = earth_rotation_correction(st.position, rcv)
    shift = np.linalg.norm(rot[0] - st.position[0])
    assert shift == pytest.approx(OMEGA_EARTH * tau[0] * np.hypot(*st.position[0, :2]),
                                  rel=1e-6)
    assert tau[0] == pytest.approx(np.linalg.norm(rot[0] - rcv) / C_LIGHT, rel=1e-12)
    assert 0.06 < tau[0] < 0.16  # 20 000-47 000 km, visible or not
