"""[gnss].estimate_velocity_time_offset (gmis.gnss_velocity_lag): the lag of a GNSS
solution's velocity behind its own positions, from the solution alone — tracks generated
here (not by the estimator's model: curvy drives integrated at 1 kHz, white and
time-correlated velocity noise, a receiver that averages over its interval), a simulated
drive through prepare_run / run_recipe, the error paths, and the real drive."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gmis.errors import GmisInputError
from gmis.gnss_velocity_lag import (
    MIN_EPOCHS,
    central_difference_velocity,
    estimate_velocity_lag,
)
from tests.shared_data import DRIVE_BOULDER, require

FINE_HZ = 1000.0


def _drive(duration_s=300.0, seed=0, slow=False):
    """A car-like horizontal track at 1 kHz: (t, r (N, 3), v (N, 3)), speed 4-14 m/s
    (0.3-0.7 m/s when slow) and heading changes of tens of degrees every ~10-40 s."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / FINE_HZ)
    ph = rng.uniform(0, 2 * np.pi, 4)
    speed = 9 + 3 * np.sin(2 * np.pi * t / 37 + ph[0]) + 2 * np.sin(2 * np.pi * t / 11 + ph[1])
    if slow:
        speed = 0.5 + 0.2 * np.sin(2 * np.pi * t / 37 + ph[0])
    heading = 0.9 * np.sin(2 * np.pi * t / 41 + ph[2]) + 0.5 * np.sin(2 * np.pi * t / 13 + ph[3])
    v = np.column_stack([speed * np.sin(heading), speed * np.cos(heading), np.zeros(t.size)])
    r = np.zeros_like(v)
    r[1:] = np.cumsum(0.5 * (v[1:] + v[:-1]) / FINE_HZ, axis=0)
    return t, r, v


def _receiver(track, lag_s, rate_hz=4.0, pos_sd=0.01, vel_sd=0.02, seed=1, vel_rho=0.0,
              interval_mean=False):
    """Fixes of the track at rate_hz: positions with white noise, velocities of the
    antenna lag_s earlier (or the mean over the last interval) with white or AR(1) noise."""
    t, r, v = track
    rng = np.random.default_rng(seed)
    step = round(FINE_HZ / rate_hz)
    k = np.arange(step, t.size, step)
    pos = r[k] + rng.normal(0, pos_sd, (k.size, 3))
    if interval_mean:
        vel = (r[k] - r[k - step]) * rate_hz
    else:
        vel = v[np.clip(k - round(lag_s * FINE_HZ), 0, t.size - 1)]
    noise = rng.normal(0, vel_sd, (k.size, 3))
    for i in range(1, k.size):                 # AR(1): correlated velocity errors
        noise[i] = vel_rho * noise[i - 1] + np.sqrt(1 - vel_rho ** 2) * noise[i]
    return t[k], pos, vel + noise


def test_central_difference_of_a_parabola_is_exact_and_gaps_are_flagged():
    t = np.array([0.0, 0.25, 0.5, 0.75, 3.0, 3.25, 3.5])
    pos = np.column_stack([2 * t ** 2, -t, np.zeros(t.size)])
    tau, rdot, valid = central_difference_velocity(t, pos)
    ok = valid
    np.testing.assert_allclose(rdot[ok, 0], 4 * tau[ok], atol=1e-12)   # d(2t²)/dt at τ
    np.testing.assert_allclose(rdot[:, 1], -1.0, atol=1e-12)
    assert valid.tolist() == [True, True, False, False, True]


@pytest.mark.parametrize("lag_s", [0.0, 0.125, -0.06, 0.3])
def test_lag_is_recovered(lag_s):
    est = estimate_velocity_lag(*_receiver(_drive(), lag_s))
    assert est.applied, est.reason
    assert abs(est.lag_s - lag_s) < 0.004, est
    assert est.sigma_s < 0.004
    assert est.velocity_time_offset_s == -est.lag_s
    if lag_s:
        assert est.rms_at_lag_m_s < est.rms_at_zero_m_s


def test_a_receiver_averaging_over_its_interval_lags_by_half_of_it():
    est = estimate_velocity_lag(*_receiver(_drive(), 0.0, rate_hz=4.0, interval_mean=True))
    assert est.applied and abs(est.lag_s - 0.125) < 0.003, est


def test_jackknife_sigma_is_honest_over_seeds_with_correlated_velocity_errors():
    """20 drives × receivers, velocity noise AR(1) with ρ = 0.9 at 4 Hz (2.4 s
    correlation): mean of z² = ((δ̂ − δ)/σ)² near 1 (χ²₁ mean; a σ 3× too small or
    too large gives ~9 or ~0.1)."""
    z2 = []
    for seed in range(20):
        est = estimate_velocity_lag(*_receiver(_drive(200.0, seed=seed), 0.1, vel_sd=0.05,
                                               seed=100 + seed, vel_rho=0.9))
        assert est.applied
        z2.append(((est.lag_s - 0.1) / est.sigma_s) ** 2)
    assert 0.3 < np.mean(z2) < 3.0, np.round(z2, 2)


def test_a_gap_in_the_track_is_not_bridged():
    t, pos, vel = _receiver(_drive(), 0.125)
    gap = (t > 120) & (t < 140)
    whole = estimate_velocity_lag(t, pos, vel)
    est = estimate_velocity_lag(t[~gap], pos[~gap], vel[~gap])
    assert est.applied and abs(est.lag_s - 0.125) < 0.004
    # the epochs next to the gap, whose central difference or bracket spans it, are out
    assert est.epochs < whole.epochs - gap.sum()


def test_slow_or_too_short_tracks_keep_the_recipe_value():
    est = estimate_velocity_lag(*_receiver(_drive(slow=True), 0.125))
    assert not est.applied and "moving" in est.reason and est.epochs < MIN_EPOCHS
    t, pos, vel = _receiver(_drive(8.0), 0.125)
    assert not estimate_velocity_lag(t, pos, vel).applied
    assert not estimate_velocity_lag(t[:2], pos[:2], vel[:2]).applied


def test_a_lag_outside_the_search_is_not_reported_as_its_edge():
    est = estimate_velocity_lag(*_receiver(_drive(), 0.8))
    assert not est.applied and "no minimum" in est.reason
    centred = estimate_velocity_lag(*_receiver(_drive(), 0.8), centre_s=0.7)
    assert centred.applied and abs(centred.lag_s - 0.8) < 0.004


SEGMENTS = [                      # static, then accelerations and turns both ways
    {"type": "static", "duration_s": 20.0},
    {"type": "accelerate", "speed_m_s": 12.0, "accel_m_s2": 2.0},
    {"type": "turn", "angle_deg": 90.0, "rate_deg_s": 15.0},
    {"type": "accelerate", "speed_m_s": 4.0, "accel_m_s2": 2.0},
    {"type": "turn", "angle_deg": -120.0, "rate_deg_s": 20.0},
    {"type": "accelerate", "speed_m_s": 14.0, "accel_m_s2": 2.5},
    {"type": "turn", "angle_deg": 60.0, "rate_deg_s": 12.0},
    {"type": "cruise", "duration_s": 5.0},
]


def lag_scenario(velocity_latency_s: float = 0.12) -> str:
    """The manoeuvring drive (START = its first sample), fixes of 1 / 1 / 2 cm and 2 / 2 /
    4 cm/s, the velocity velocity_latency_s behind its fix."""
    from tests.simulated_drives import scenario_toml
    gnss = {"position_sigma_m": [0.01, 0.01, 0.02], "velocity_sigma_m_s": [0.02, 0.02, 0.04]}
    if velocity_latency_s:
        gnss["velocity_latency_s"] = velocity_latency_s
    return scenario_toml("velocity-lag", SEGMENTS, seed=3, gnss=gnss, start_gps_s=345600.0)


@pytest.fixture(scope="module")
def lagged_drive(tmp_path_factory):
    from gmis.simulate import simulate_scenario
    root = tmp_path_factory.mktemp("velocity_lag")
    (root / "scenario.toml").write_text(lag_scenario())
    sim = simulate_scenario(root / "scenario.toml", root / "dataset")
    return Path(sim.recipe_path)


def _with_keys(recipe_path, text, tmp_path):
    """The simulated recipe with a [gnss] table added, written beside the original."""
    out = recipe_path.parent / f"{tmp_path.name}.toml"
    out.write_text(recipe_path.read_text() + "\n[gnss]\n" + text)
    return out


def test_prepare_run_applies_the_estimate_and_the_summary_reports_it(lagged_drive, tmp_path):
    from gmis.pipeline import run_recipe
    from gmis.recipe import load_recipe
    from gmis.run_preparation import prepare_run

    recipe = load_recipe(_with_keys(lagged_drive, "estimate_velocity_time_offset = true\n",
                                    tmp_path))
    prep = prepare_run(recipe)
    est = prep.gnss_velocity_lag
    assert est.applied and abs(est.lag_s - 0.12) < 0.01, est
    assert prep.recipe.gnss.velocity_time_offset_s == -est.lag_s
    assert not prep.recipe.gnss.estimate_velocity_time_offset
    assert any("GNSS velocity lag estimated" in w for w in prep.dataset.warnings)

    # the run with the estimate: its GNSS velocity innovations are those of velocities
    # at their own epochs, so the velocity error against the truth falls
    with_lag = run_recipe(recipe.path, tmp_path / "est")
    plain = run_recipe(lagged_drive, tmp_path / "plain")
    rep = with_lag["gnss_velocity_time_offset"]
    assert rep["applied"] and rep["velocity_time_offset_s"] == pytest.approx(-est.lag_s)

    def v_rms(s):
        v = s["errors_vs_reference"]["velocity"]
        return np.sqrt(sum(v[a]["rms"] ** 2 for a in "en"))
    assert v_rms(with_lag) < 0.8 * v_rms(plain), (v_rms(with_lag), v_rms(plain))


def test_outage_windows_are_not_used_by_the_estimate(lagged_drive, tmp_path):
    from gmis.recipe import load_recipe
    from gmis.run_preparation import prepare_run

    recipe = load_recipe(_with_keys(lagged_drive, "estimate_velocity_time_offset = true\n",
                                    tmp_path))
    whole = prepare_run(recipe).gnss_velocity_lag
    t0 = 345600.0 + 25.0
    cut = prepare_run(recipe, gnss_outages=[(t0, t0 + 10.0)]).gnss_velocity_lag
    assert cut.epochs < whole.epochs - 40          # 10 s at 5 Hz of moving fixes left out


def test_a_solution_without_velocity_is_refused(lagged_drive, tmp_path):
    from gmis.readers import load_dataset
    from gmis.recipe import load_recipe
    from gmis.run_preparation import prepare_run

    recipe = load_recipe(_with_keys(lagged_drive, "estimate_velocity_time_offset = true\n",
                                    tmp_path))
    ds = load_dataset(recipe)
    ds = replace(ds, gnss=replace(ds.gnss, vel_enu=None, vel_sigma=None))
    with pytest.raises(GmisInputError, match="estimate_velocity_time_offset.*no ENU velocity"):
        prepare_run(recipe, ds)


def test_the_key_is_parsed_and_refused_in_tight_mode(tmp_path):
    from tests.test_consumer_recipe_keys import _load

    assert _load(tmp_path, "[gnss]\nestimate_velocity_time_offset = true\n").gnss \
        .estimate_velocity_time_offset
    assert not _load(tmp_path, "").gnss.estimate_velocity_time_offset
    with pytest.raises(GmisInputError, match="estimate_velocity_time_offset: expected true"):
        _load(tmp_path, "[gnss]\nestimate_velocity_time_offset = 1\n")
    from gmis.recipe import load_recipe
    from tests.test_consumer_recipe_keys import BASE
    for name in ("rover.obs", "base.obs", "nav.n"):
        (tmp_path / name).write_text("")
    text = BASE.replace('gnss_solution = "g.csv"\n', 'gnss_solution = "g.csv"\n'
                        'rover_obs = "rover.obs"\nbase_obs = "base.obs"\nnav = "nav.n"\n')
    (tmp_path / "t.toml").write_text(
        text + '[filter]\nmode = "tight"\n[gnss]\nestimate_velocity_time_offset = true\n'
        '[base]\necef_m = [-3961904.0, 3348993.0, 3698211.0]\n')
    with pytest.raises(GmisInputError, match="estimate_velocity_time_offset: applies to the "
                                             "loosely coupled"):
        load_recipe(tmp_path / "t.toml")


def test_the_real_drive_velocity_lags_its_positions_by_128_ms():
    """drive-boulder-0708: the u-blox velocity against its own RTK positions (the
    recipe's GNSS file alone) — 0.128 s, about half the 4 Hz interval."""
    require(DRIVE_BOULDER)
    from gmis.earth import make_nav_frame
    from gmis.enu_rows import geodetic_to_enu_rows
    from gmis.readers import load_dataset
    from gmis.recipe import load_recipe

    root = Path(__file__).resolve().parents[1]
    ds = load_dataset(load_recipe(root / "datasets" / "drive-boulder-0708" / "recipe.toml"),
                      with_reference=False)
    g = ds.gnss
    enu = geodetic_to_enu_rows(make_nav_frame(*g.llh[0]), np.ascontiguousarray(g.llh))
    est = estimate_velocity_lag(g.t, enu, g.vel_enu)
    assert est.applied and abs(est.lag_s - 0.128) < 0.003 and est.sigma_s < 0.003, est
    assert est.rms_at_lag_m_s < 0.4 * est.rms_at_zero_m_s
