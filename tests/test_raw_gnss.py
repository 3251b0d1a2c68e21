"""Raw GNSS simulation: RINEX read-back, DD residual statistics, ambiguities, slips,
blockages, determinism (gmis.simulate.raw_gnss, gmis.simulate.rinex_writer)."""

import os

import numpy as np
import pytest

from gmis.earth import geodetic_to_ecef
from gmis.simulate.raw_gnss import (
    CycleSlip,
    RawGnssConfig,
    ReceiverTrack,
    SkyBlockage,
    dd_ambiguity,
    simulate_raw_gnss,
    synthetic_gps_nav,
)
from gmis.simulate.rinex_writer import write_nav_rinex3, write_obs_rinex3
from gnss.constants import WAVELENGTH_L1, WAVELENGTH_L2
from gnss.double_difference import form_double_differences
from gnss.rinex import NAV_FIELDS, read_nav, read_obs
from tests.shared_data import RTKLIB_TEST

BRDC = str(RTKLIB_TEST / "brdc1820.10n")
T0 = 1590 * 604800.0 + 345600.0 + 3600.0  # 2010-07-01 01:00 GPST (inside brdc1820.10n)
N_EP = 600
BASE = np.array(geodetic_to_ecef(np.deg2rad(43.77), np.deg2rad(-79.50), 170.0))
VEL = np.array([6.0, -4.0, 0.5])


def _tracks(n=N_EP):
    t = T0 + np.arange(n, dtype=float)
    rover = BASE + np.array([400.0, -250.0, 120.0]) + np.outer(t - T0, VEL)
    return t, [ReceiverTrack("base", BASE, None, vehicle=False),
               ReceiverTrack("rover", rover, np.broadcast_to(VEL, (n, 3)))]


@pytest.fixture(scope="module")
def nav():
    return synthetic_gps_nav(T0)


@pytest.fixture(scope="module")
def simulated(nav, tmp_path_factory):
    d = tmp_path_factory.mktemp("raw")
    t, rcv = _tracks()
    probe = simulate_raw_gnss(t[:1], rcv[:1], nav, seed=1).receivers["base"]
    slip_prn = int(probe.prn[np.nanargmax(probe.elevation[0])])
    cfg = RawGnssConfig(
        slips=[CycleSlip(T0 + 150.0, slip_prn, 1, 7), CycleSlip(T0 + 300.0, slip_prn, 2, -3)],
        blockages=[SkyBlockage(T0 + 400.0, T0 + 420.0, highest_n=3)])
    sim = simulate_raw_gnss(t, rcv, nav, cfg, seed=11)
    write_nav_rinex3(d / "syn.nav", nav)
    for name, r in sim.receivers.items():
        write_obs_rinex3(d / f"{name}.obs", r.t_gps, r.prn, r.obs, r.lli1, r.lli2,
                         r.antenna_ecef[0], name.upper())
    return sim, cfg, d, slip_prn


def test_nav_round_trip_exact(simulated, nav):
    _, _, d, _ = simulated
    back = read_nav(d / "syn.nav", use_cache=False)
    for k in NAV_FIELDS:
        np.testing.assert_array_equal(getattr(back, k), getattr(nav, k), err_msg=k)
    assert np.unique(nav.prn).size == 24


def test_obs_read_back(simulated):
    sim, _, d, _ = simulated
    for name, r in sim.receivers.items():
        ob = read_obs(d / f"{name}.obs", use_cache=False)
        assert ob.version == 3.03
        np.testing.assert_allclose(ob.approx_position_ecef, r.antenna_ecef[0], atol=1e-4)
        np.testing.assert_allclose(ob.t_gps, r.t_gps, rtol=0, atol=1e-6)
        cols = np.array([int(np.flatnonzero(r.prn == p)[0]) for p in ob.prn])
        for key in ("C1", "L1", "D1", "S1", "C2", "L2", "D2", "S2"):
            want = r.obs[key][:, cols]
            got = getattr(ob, key)
            np.testing.assert_array_equal(np.isnan(got), np.isnan(want), err_msg=key)
            ok = np.isfinite(want)
            assert np.max(np.abs(got[ok] - want[ok])) <= 5e-4 + 1e-6, key
        np.testing.assert_array_equal(ob.LLI1, r.lli1[:, cols])
        np.testing.assert_array_equal(ob.LLI2, r.lli2[:, cols])


def _dd(simulated, nav_data):
    sim, _, d, _ = simulated
    ob = read_obs(d / "base.obs", use_cache=False)
    orv = read_obs(d / "rover.obs", use_cache=False)
    rover_true = sim.receivers["rover"].antenna_ecef
    return form_double_differences(ob, orv, nav_data, BASE, rover_true,
                                   elevation_mask_deg=10.0)


def test_dd_code_and_phase_residuals(simulated):
    sim, cfg, d, _ = simulated
    nav_back = read_nav(d / "syn.nav", use_cache=False)
    dd = _dd(simulated, nav_back)
    m_kk = dd.m_sd + dd.m_sd_ref[dd.epoch_index]
    for key in ("C1", "C2"):
        z = (dd.observables[key] - dd.computed_range) / (cfg.sigma90_code_m * np.sqrt(m_kk))
        z = z[np.isfinite(z)]
        print(f"DD {key}: n={z.size} normalised mean {z.mean():+.3f} std {z.std():.3f}")
        assert z.size > 2000
        assert abs(z.mean()) < 4.0 / np.sqrt(z.size) * 2.0
        assert 0.95 < z.std() < 1.05
    ep_of_row = np.searchsorted(sim.t_gps, dd.t_gps[dd.epoch_index] - 1e-3)
    for key, lam, f in (("L1", WAVELENGTH_L1, 1), ("L2", WAVELENGTH_L2, 2)):
        n_true = np.array([dd_ambiguity(sim, "base", "rover", f, e, p, dd.ref_prn[i])
                           for e, p, i in zip(ep_of_row, dd.prn, dd.epoch_index)])
        frac = dd.observables[key] - dd.computed_range / lam
        assert np.all(np.abs(n_true - np.round(n_true)) == 0)
        np.testing.assert_array_equal(np.round(frac), n_true)
        z = (frac - n_true) * lam / (cfg.sigma90_phase_m * np.sqrt(m_kk))
        print(f"DD {key}: normalised mean {z.mean():+.3f} std {z.std():.3f}, "
              f"max |frac - N| {np.max(np.abs(frac - n_true)):.4f} cycles")
        assert abs(z.mean()) < 0.1
        assert 0.95 < z.std() < 1.05


def test_slips_and_arcs_flagged(simulated):
    sim, _cfg, _, prn = simulated
    r = sim.receivers["rover"]
    j = int(np.flatnonzero(r.prn == prn)[0])
    k1 = int(np.searchsorted(sim.t_gps, T0 + 150.0))
    k2 = int(np.searchsorted(sim.t_gps, T0 + 300.0))
    assert r.lli1[k1, j] & 1 and not r.lli2[k1, j] & 1
    assert r.lli2[k2, j] & 1 and not r.lli1[k2, j] & 1
    assert r.ambiguity_l1[k1, j] - r.ambiguity_l1[k1 - 1, j] == 7
    assert r.ambiguity_l2[k2, j] - r.ambiguity_l2[k2 - 1, j] == -3
    assert sorted(map(tuple, sim.slip_log[:, 1:].tolist())) == [(k1, prn, 1, 7),
                                                               (k2, prn, 2, -3)]
    # every LLI not at a configured slip is at the start of a new arc
    tracked = np.isfinite(r.obs["L1"])
    starts = tracked.copy()
    starts[1:] &= ~tracked[:-1]
    starts[0] = False
    flagged = (r.lli1 & 1).astype(bool)
    flagged[k1, j] = False
    np.testing.assert_array_equal(flagged, starts)
    base = sim.receivers["base"]
    assert not np.any(base.lli1[1:][np.isfinite(base.obs["L1"][:-1])[:, :] &
                                    np.isfinite(base.obs["L1"][1:])])


def test_blockage_leaves_configured_count(simulated):
    sim, _, _, _ = simulated
    r, b = sim.receivers["rover"], sim.receivers["base"]
    n_r = np.isfinite(r.obs["C1"]).sum(axis=1)
    n_b = np.isfinite(b.obs["C1"]).sum(axis=1)
    inside = (sim.t_gps >= T0 + 400.0) & (sim.t_gps < T0 + 420.0)
    print(f"satellites: rover {n_r[~inside].min()}-{n_r[~inside].max()} outside, "
          f"{np.unique(n_r[inside])} inside the blockage; base {n_b.min()}-{n_b.max()}")
    assert np.all(n_r[inside] == 3)
    assert n_r[~inside].min() >= 5 and n_b[inside].min() >= 5
    # the kept ones are the highest
    k = np.flatnonzero(inside)[0]
    el = np.where(np.isfinite(r.elevation[k]), r.elevation[k], -9)
    assert set(np.flatnonzero(np.isfinite(r.obs["C1"][k]))) == set(np.argsort(-el)[:3])
    # after the blockage the lost satellites come back with a new arc (LLI)
    after = np.flatnonzero(sim.t_gps >= T0 + 420.0)[0]
    back = np.isfinite(r.obs["L1"][after]) & ~np.isfinite(r.obs["L1"][after - 1])
    assert back.any() and np.all(r.lli1[after, back] & 1)


def test_azimuth_sector_blockage(nav):
    t, rcv = _tracks()
    cfg = RawGnssConfig(blockages=[SkyBlockage(T0 + 10, T0 + 30, azimuth_sectors_deg=[
        (270.0, 90.0)])])
    sim = simulate_raw_gnss(t[:60], [rcv[0], ReceiverTrack("rover", rcv[1].ecef[:60],
                                                           rcv[1].vel[:60])], nav, cfg, seed=2)
    r = sim.receivers["rover"]
    inside = np.flatnonzero((sim.t_gps >= T0 + 10) & (sim.t_gps < T0 + 30))
    az = np.rad2deg(r.azimuth[inside])
    seen = np.isfinite(r.obs["C1"][inside])
    assert np.all((az[seen] >= 270.0) | (az[seen] <= 90.0))
    above = np.rad2deg(np.nan_to_num(r.elevation[inside], nan=-90)) >= 10.0
    south = above & (az > 90.0) & (az < 270.0)
    assert south.any() and not np.any(seen & south)


def test_determinism(nav):
    t, rcv = _tracks(30)
    a = simulate_raw_gnss(t, rcv, nav, seed=5)
    b = simulate_raw_gnss(t, rcv, nav, seed=5)
    c = simulate_raw_gnss(t, rcv, nav, seed=6)
    for key in ("C1", "L1", "D1"):
        np.testing.assert_array_equal(a.receivers["rover"].obs[key],
                                      b.receivers["rover"].obs[key])
        ok = np.isfinite(a.receivers["rover"].obs[key])
        assert np.all(a.receivers["rover"].obs[key][ok] != c.receivers["rover"].obs[key][ok])


def test_doppler_matches_range_rate(nav):
    t, rcv = _tracks()
    cfg = RawGnssConfig(sigma90_doppler_m_s=0.02)
    sim = simulate_raw_gnss(t[:200], [rcv[0], ReceiverTrack("rover", rcv[1].ecef[:200],
                                                            rcv[1].vel[:200])], nav, cfg, seed=4)
    r = sim.receivers["rover"]
    # finite difference of the noise-free range agrees with the simulated range rate
    rho = r.range_m
    fd = (-rho[4:] + 8.0 * rho[3:-1] - 8.0 * rho[1:-3] + rho[:-4]) / 12.0  # O(h⁴), h = 1 s
    ok = np.isfinite(fd) & np.isfinite(r.range_rate_m_s[2:-2])
    err = np.max(np.abs(fd[ok] - r.range_rate_m_s[2:-2][ok]))
    print(f"range rate vs 5-point difference of range: max {err:.2e} m/s")
    assert err < 1e-3  # float resolution of absolute GPS time (~0.1 µs → ~0.1 mm)
    # Doppler (RINEX sign) = -(range rate + clock rates + noise)/λ
    from gnss.constants import C_LIGHT
    nav_clk = -r.obs["D1"] * WAVELENGTH_L1 - r.range_rate_m_s - r.noise["D1"]
    rx = C_LIGHT * r.clock_drift_s_s[:, None]
    sat_part = nav_clk - rx
    ok = np.isfinite(sat_part)
    assert np.all(np.abs(sat_part[ok]) < C_LIGHT * 2e-11)


@pytest.mark.skipif(not os.path.isfile(BRDC), reason=f"real broadcast nav file {BRDC} absent")
def test_real_nav_file_dd_code(tmp_path):
    nav_real = read_nav(BRDC, use_cache=False)
    t, rcv = _tracks()
    t, rcv = t[:120], [rcv[0], ReceiverTrack("rover", rcv[1].ecef[:120], rcv[1].vel[:120])]
    sim = simulate_raw_gnss(t, rcv, nav_real, RawGnssConfig(), seed=9)
    for name, r in sim.receivers.items():
        write_obs_rinex3(tmp_path / f"{name}.obs", r.t_gps, r.prn, r.obs, r.lli1, r.lli2,
                         r.antenna_ecef[0], name)
    ob = read_obs(tmp_path / "base.obs", use_cache=False)
    orv = read_obs(tmp_path / "rover.obs", use_cache=False)
    dd = form_double_differences(ob, orv, nav_real, BASE, rcv[1].ecef, elevation_mask_deg=10)
    m_kk = dd.m_sd + dd.m_sd_ref[dd.epoch_index]
    z = (dd.observables["C1"] - dd.computed_range) / (0.3 * np.sqrt(m_kk))
    n_sat = np.isfinite(sim.receivers["rover"].obs["C1"]).sum(axis=1)
    print(f"brdc1820.10n: {n_sat.min()}-{n_sat.max()} satellites, DD C1 n={z.size} "
          f"std {z.std():.3f}")
    assert n_sat.min() >= 6
    assert 0.9 < z.std() < 1.1 and abs(z.mean()) < 0.15


def _scenario(raw_gnss=None):
    scn = {
        "scenario": {"name": "raw", "seed": 3, "imu_rate_hz": 100.0},
        "origin": {"lat_deg": 43.7735, "lon_deg": -79.5019, "h_m": 180.0},
        "segment": [{"type": "static", "duration_s": 20.0},
                    {"type": "accelerate", "speed_m_s": 10.0, "accel_m_s2": 2.0},
                    {"type": "turn", "angle_deg": 90.0, "rate_deg_s": 15.0},
                    {"type": "cruise", "duration_s": 20.0}],
        "gnss": {"rate_hz": 1.0, "position_sigma_m": 0.02, "velocity_sigma_m_s": 0.05,
                 "lever_arm_m": [0.0, 0.5, 1.5]},
        "heading": {"rate_hz": 1.0, "sigma_deg": 0.2, "lever_arm_m": [0.0, -1.5, 1.5]},
    }
    if raw_gnss is not None:
        scn["raw_gnss"] = raw_gnss
    return scn


def test_scenario_writes_raw_dataset_and_recipe_loads(tmp_path):
    from gmis.errors import GmisInputError
    from gmis.recipe import load_recipe
    from gmis.simulate import simulate_scenario
    from gmis.simulate.scenario import validate_scenario

    plain = validate_scenario(_scenario(), "s")
    assert "raw_gnss" not in plain
    with pytest.raises(GmisInputError, match="raw_gnss.*frequency"):
        validate_scenario(_scenario({"slip": [{"time_s": 1.0, "prn": 3, "frequency": 5,
                                               "cycles": 1}]}), "s")
    res = simulate_scenario(_scenario({"rate_hz": 2.0, "base_offset_enu_m": [300.0, 0, 0],
                                       "blockage": [{"start_s": 30.0, "end_s": 40.0,
                                                     "highest_n": 2}]}),
                            tmp_path / "ds")
    d = res.dataset_dir
    for f in ("rover.obs", "base.obs", "heading.obs", "synthetic.nav", "raw_truth.npz"):
        assert os.path.isfile(os.path.join(d, f)), f
    rec = load_recipe(res.recipe_path)
    assert rec.paths.rover_obs.name == "rover.obs" and rec.base is not None
    rover = read_obs(os.path.join(d, "rover.obs"), use_cache=False)
    assert rover.interval == 0.5
    n = np.isfinite(rover.C1).sum(axis=1)
    sow = rover.sow - 345600.0
    assert np.all(n[(sow >= 30.0) & (sow < 40.0)] == 2) and n[sow < 30.0].min() >= 5
    truth = np.load(os.path.join(d, "raw_truth.npz"))
    # rover antenna truth = IMU truth + C_b^n·lever arm (checked at the first epoch)
    from gmis.earth import enu_to_ecef, make_nav_frame
    from gmis.frames import dcm_body_to_nav
    fr = make_nav_frame(np.deg2rad(43.7735), np.deg2rad(-79.5019), 180.0)
    e = res.truth.euler[0]
    ant = res.truth.r_enu[0] + dcm_body_to_nav(e[0], e[1], e[2]) @ np.array([0.0, 0.5, 1.5])
    np.testing.assert_allclose(truth["rover_antenna_ecef"][0], enu_to_ecef(fr, ant), atol=1e-6)
