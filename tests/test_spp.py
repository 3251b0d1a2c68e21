"""SPP: simulated pseudoranges from real broadcast orbits (exactness, outlier rejection) and
the real 0759/3040 files (accuracy against the header positions, baseline length)."""


import numpy as np
import pytest

from gnss.constants import C_LIGHT
from gnss.ephemeris import satellite_states_at_reception
from gnss.rinex import read_nav, read_obs
from gnss.spp import elevation_azimuth, klobuchar_delay, solve_spp_epoch, solve_spp_session
from gnss.troposphere import saastamoinen_delay
from tests.shared_data import RTKLIB_TEST as DATA

pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"real data folder {DATA} absent")

TRUTH = np.array([-3976219.5082, 3382372.5671, 3652512.9849])


@pytest.fixture(scope="module")
def nav(tmp_path_factory):
    return read_nav(DATA / "07590920.05n", cache_dir=tmp_path_factory.mktemp("c"))


def _simulate(nav, t_rx, clock_m, with_atmosphere=True):
    """Pseudoranges of all healthy satellites above 15° for a receiver at TRUTH."""
    prn = np.unique(nav.prn)
    p0 = np.full(prn.size, 2.2e7)
    for _ in range(3):  # converge the transmission time for the simulated range
        st, _, _ = satellite_states_at_reception(nav, prn, t_rx, p0, TRUTH)
        rho = np.linalg.norm(st.position - TRUTH, axis=1)
        p0 = rho + clock_m - C_LIGHT * (st.clock_bias - st.tgd)
    el, az, (lat, lon, h) = elevation_azimuth(TRUTH, st.position)
    if with_atmosphere:
        p0 = p0 + saastamoinen_delay(lat, h, el) + klobuchar_delay(
            nav.ion_alpha, nav.ion_beta, lat, lon, az, el, t_rx)
    keep = st.valid & (el > np.deg2rad(15.0))
    return prn[keep], p0[keep]


def test_spp_exact_on_simulated_ranges(nav):
    t_rx = nav.toe[0] + 1800.0
    prn, p = _simulate(nav, t_rx, clock_m=12345.6)
    sol = solve_spp_epoch(nav, prn, p, t_rx)
    assert sol.ok and sol.used.sum() == prn.size
    assert np.linalg.norm(sol.position - TRUTH) < 1e-3
    assert sol.clock_m == pytest.approx(12345.6, abs=1e-3)
    assert np.all(np.abs(sol.residuals[sol.used]) < 1e-3)
    assert 1.0 < sol.dop[1] < 10.0 and sol.dop[0] > sol.dop[1] > sol.dop[2]


def test_spp_noise_and_outlier(nav):
    rng = np.random.default_rng(2)
    t_rx = nav.toe[0] + 2400.0
    prn, p = _simulate(nav, t_rx, clock_m=-500.0)
    assert prn.size >= 6
    p = p + 0.3 * rng.standard_normal(p.size)
    p_bad = p.copy()
    p_bad[2] += 80.0
    sol = solve_spp_epoch(nav, prn, p_bad, t_rx)
    assert sol.ok and not sol.used[2] and sol.used.sum() == prn.size - 1
    assert np.linalg.norm(sol.position - TRUTH) < 5.0
    no_reject = solve_spp_epoch(nav, prn, p_bad, t_rx, outlier_k=np.inf)
    assert no_reject.used[2]
    assert np.linalg.norm(no_reject.position - TRUTH) > np.linalg.norm(sol.position - TRUTH)


def test_atmosphere_models_magnitude():
    lat, h = np.deg2rad(35.0), 70.0
    zenith = saastamoinen_delay(lat, h, np.pi / 2)
    assert 2.2 < zenith < 2.6  # ≈ 2.3 m hydrostatic + wet at sea level
    assert saastamoinen_delay(lat, h, np.deg2rad(15.0)) == pytest.approx(
        zenith / np.sin(np.deg2rad(15.0)), rel=1e-12)
    alpha = [1.118e-08, 1.490e-08, -5.960e-08, -5.960e-08]
    beta = [8.806e+04, 1.638e+04, -1.966e+05, -1.311e+05]
    night = klobuchar_delay(alpha, beta, lat, np.deg2rad(139.6), 0.0, np.pi / 2,
                            518400.0 + 15 * 3600.0)  # 00:00 local ≈ 15:00 UT
    day = klobuchar_delay(alpha, beta, lat, np.deg2rad(139.6), 0.0, np.pi / 2,
                          518400.0 + 5 * 3600.0)  # 14:00 local
    assert night == pytest.approx(5e-9 * C_LIGHT * (1.0 + 16.0 * 0.03 ** 3), rel=1e-9)
    assert day > night


@pytest.fixture(scope="module")
def sessions(nav, tmp_path_factory):
    cache = tmp_path_factory.mktemp("c2")
    out = {}
    for site in ("0759", "3040"):
        obs = read_obs(DATA / f"{site}0920.05o", cache_dir=cache)
        site_nav = read_nav(DATA / f"{site}0920.05n", cache_dir=cache)
        out[site] = (obs, solve_spp_session(obs, site_nav))
    return out


def test_spp_real_sessions(sessions):
    for site, (obs, sess) in sessions.items():
        err = np.linalg.norm(sess.position - obs.approx_position_ecef, axis=1)
        good_geometry = sess.dop[:, 1] <= 6.0
        mean_err = np.linalg.norm(sess.position.mean(axis=0) - obs.approx_position_ecef)
        print(f"\n{site}: {sess.ok.sum()}/{sess.ok.size} epochs, 3D error median "
              f"{np.median(err):.2f} m, 95% {np.percentile(err, 95):.2f} m, max {err.max():.2f}"
              f" m (PDOP max {sess.dop[:, 1].max():.1f}), max with PDOP≤6 "
              f"{err[good_geometry].max():.2f} m, mean position error {mean_err:.2f} m, "
              f"used sats {np.bincount(sess.n_used).nonzero()[0].tolist()}")
        assert sess.ok.all()
        assert np.median(err) < 3.0
        assert err[good_geometry].max() < 10.0
        assert mean_err < 2.0


def test_spp_baseline_length(sessions):
    (b_obs, b), (r_obs, r) = sessions["0759"], sessions["3040"]
    spp = np.linalg.norm(r.position.mean(axis=0) - b.position.mean(axis=0))
    header = np.linalg.norm(r_obs.approx_position_ecef - b_obs.approx_position_ecef)
    print(f"\nbaseline: SPP means {spp:.3f} m, header {header:.3f} m, diff {spp - header:.3f} m")
    assert abs(spp - header) < 3.0


def test_compiled_atmosphere_models_equal_vectorised():
    """The scalar numba models of the SPP kernel (saastamoinen_delay_scalar,
    klobuchar_delay_scalar) equal the vectorised numpy functions to 1e-12 relative (the
    last bits may differ: numba's LLVM compiles for the host CPU, which may contract
    a*b+c into FMA or use other libm paths than numpy), including outside the troposphere
    model's range (h < −100 m, h > 10 km, elevation ≤ 0), where both must give exactly 0."""
    from gnss.spp import klobuchar_delay_scalar
    from gnss.troposphere import saastamoinen_delay_scalar
    rng = np.random.default_rng(7)
    lat = rng.uniform(-1.5, 1.5, 4000)
    lon = rng.uniform(-np.pi, np.pi, 4000)
    h = rng.uniform(-300.0, 1.2e4, 4000)
    el = rng.uniform(-0.2, np.pi / 2, 4000)
    az = rng.uniform(0.0, 2 * np.pi, 4000)
    t = 796435200.0 + rng.uniform(0.0, 2 * 86400.0, 4000)
    for hum in (0.0, 0.7):
        vec = saastamoinen_delay(lat, h, el, humidity=hum)
        sca = np.array([saastamoinen_delay_scalar(*a, hum) for a in zip(lat, h, el)])
        np.testing.assert_allclose(sca, vec, rtol=1e-12, atol=0.0)
        assert np.array_equal(vec == 0.0, sca == 0.0)
        assert np.any(vec == 0.0) and np.any(vec > 2.0)        # both branches exercised
    alpha = np.array([1.118e-08, 1.490e-08, -5.960e-08, -5.960e-08])
    beta = np.array([8.806e+04, 1.638e+04, -1.966e+05, -1.311e+05])
    vec = np.array([klobuchar_delay(alpha, beta, *a) for a in zip(lat, lon, az, el, t)])
    sca = np.array([klobuchar_delay_scalar(alpha, beta, *a) for a in zip(lat, lon, az, el, t)])
    np.testing.assert_allclose(sca, vec, rtol=1e-12, atol=0.0)


SPP_SAME_M = 1e-6
"""Agreement (m) of two SPP solutions that differ only in the last bits of their
arithmetic (host-CPU code generation): 1 µm, ~1e-13 of an ECEF coordinate."""


def _assert_same_solution(a, b):
    assert a.ok == b.ok and a.n_iter == b.n_iter
    assert np.array_equal(a.used, b.used), "used"
    for name in ("position", "residuals"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0.0,
                                   atol=SPP_SAME_M, equal_nan=True, err_msg=name)
    for name in ("dop", "elevation", "azimuth"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=1e-9,
                                   atol=1e-12, equal_nan=True, err_msg=name)
    assert a.clock_m == pytest.approx(b.clock_m, rel=0.0, abs=SPP_SAME_M)
    assert a.sigma0 == pytest.approx(b.sigma0, rel=1e-6, nan_ok=True)   # residuals to 1 µm


def test_compiled_spp_equals_numpy_reference(nav):
    """solve_spp_epoch (compiled kernel) against the former numpy implementation
    (tests/reference_spp.py), to 1 µm (the compiled code may differ from numpy in the
    last bits on another CPU; the discrete outcomes — used satellites, iterations, ok —
    must be identical): simulated epochs with noise, an outlier and a
    start at the earth's centre, and every epoch of the real 3040 session (each started
    from the reference's previous solution); solve_spp_session (states of all epochs in
    one call) against the reference chained epoch by epoch."""
    from tests.reference_spp import solve_spp_epoch_numpy
    rng = np.random.default_rng(3)
    for dt in (600.0, 1800.0, 2400.0):
        t_rx = nav.toe[0] + dt
        prn, p = _simulate(nav, t_rx, clock_m=-500.0 + dt)
        p = p + 0.3 * rng.standard_normal(p.size)
        p[1] += 60.0
        for kw in ({}, {"outlier_k": np.inf}, {"use_ionosphere": False, "elevation_mask_deg": 5.0}):
            _assert_same_solution(solve_spp_epoch(nav, prn, p, t_rx, **kw),
                                  solve_spp_epoch_numpy(nav, prn, p, t_rx, **kw))
    obs = read_obs(DATA / "30400920.05o")
    nav_r = read_nav(DATA / "30400920.05n")
    sess = solve_spp_session(obs, nav_r)
    x0 = np.r_[obs.approx_position_ecef, 0.0]
    for k in range(obs.t_gps.size):
        ref = solve_spp_epoch_numpy(nav_r, obs.prn, obs.C1[k], obs.t_gps[k], x0=x0)
        _assert_same_solution(solve_spp_epoch(nav_r, obs.prn, obs.C1[k], obs.t_gps[k], x0=x0),
                              ref)
        assert sess.ok[k] == ref.ok
        if ref.ok:
            np.testing.assert_allclose(sess.position[k], ref.position, rtol=0.0,
                                       atol=SPP_SAME_M)
            np.testing.assert_allclose(sess.dop[k], ref.dop, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(sess.residuals[k], ref.residuals, rtol=0.0,
                                       atol=SPP_SAME_M, equal_nan=True)
            x0 = np.r_[ref.position, ref.clock_m]
