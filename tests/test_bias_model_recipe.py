"""[noise].<sensor>_bias_model = "gauss_markov": recipe parsing, validation (one clear
error per rule), the engine configurations it gives (GMIKF drift_inv_tau and driving
noise, error-state INS τ) and the noise fragment round trip."""

import math

import numpy as np
import pytest

from gmis.engine_configs import errins_config, gmikf_config
from gmis.errors import GmisInputError
from gmis.recipe import DEG, format_noise_fragment, load_recipe

GM = {"gyro_bias_model": "gauss_markov", "gyro_bias_tau_s": [100.0, 200.0, 400.0],
      "gyro_bias_sigma_deg_s": [0.01, 0.02, 0.03]}


def test_gauss_markov_gyro_bias_reaches_both_filters(dataset):
    recipe = load_recipe(dataset.write(dataset.modified("noise", **GM)))
    nz = recipe.noise
    assert nz.gyro_bias_model == "gauss_markov" and nz.accel_bias_model == "random_walk"
    assert nz.gyro_bias_tau_s == (100.0, 200.0, 400.0)
    assert nz.gyro_bias_sigma_rad_s == pytest.approx(np.array([0.01, 0.02, 0.03]) * DEG)
    cfg = gmikf_config(recipe)
    tau = np.array([100.0, 200.0, 400.0])
    sigma = np.array([0.01, 0.02, 0.03]) * DEG
    n_drift = recipe.filter.states - 15
    assert cfg.drift_inv_tau.shape == (n_drift,)
    assert cfg.drift_inv_tau[:3] == pytest.approx(1 / tau)
    assert np.all(cfg.drift_inv_tau[3:] == 0.0)
    # the drift's spectral density is 2σ²/τ: the GM of stationary variance σ²
    assert cfg.q_psd()[6:9] == pytest.approx(2 * sigma ** 2 / tau, rel=1e-12)
    ecfg = errins_config(recipe)
    assert ecfg.bias_tau_s[:3] == pytest.approx(tau)
    assert np.all(np.isinf(ecfg.bias_tau_s[3:]))
    q_bg = ecfg.spectral_densities()[2]
    assert q_bg == pytest.approx(2 * sigma ** 2 / tau, rel=1e-12)


def test_random_walk_default_is_unchanged(dataset):
    recipe = load_recipe(dataset.write())
    cfg = gmikf_config(recipe)
    assert np.all(cfg.drift_inv_tau == 0.0)
    assert np.all(np.isinf(errins_config(recipe).bias_tau_s))


@pytest.mark.parametrize("noise, key", [
    ({"gyro_bias_model": "gauss_markov", "gyro_bias_tau_s": [1.0, 1.0, 1.0]},
     "noise.gyro_bias_sigma_deg_s"),
    ({"accel_bias_model": "gauss_markov", "accel_bias_sigma_m_s2": [0.1, 0.1, 0.1]},
     "noise.accel_bias_tau_s"),
    ({"gyro_bias_tau_s": [1.0, 1.0, 1.0]}, "noise.gyro_bias_tau_s"),
    ({**GM, "gyro_bias_drift_deg_s": [0.0, 1e-4, 0.0]}, "noise.gyro_bias_drift_deg_s"),
    ({**GM, "gyro_bias_tau_s": [100.0, 0.0, 1.0]}, "noise.gyro_bias_tau_s"),
    ({"gyro_bias_model": "gauss-markov"}, "noise.gyro_bias_model"),
])
def test_bad_bias_model_settings_name_the_key(dataset, noise, key):
    path = dataset.write(dataset.modified("noise", **noise))
    with pytest.raises(GmisInputError) as err:
        load_recipe(path)
    assert str(err.value).split(": ")[1] == key, str(err.value)
    assert str(path) in str(err.value)


def test_fragment_round_trip_keeps_the_gauss_markov_model(dataset):
    noise = load_recipe(dataset.write(dataset.modified("noise", **GM))).noise
    text = format_noise_fragment(noise)
    assert 'gyro_bias_model = "gauss_markov"' in text and "accel_bias_tau_s" not in text
    (dataset.root / "frag.toml").write_text(text)
    again = load_recipe(dataset.write(dataset.modified("paths", noise_override="frag.toml")))
    assert again.noise == noise
    default = format_noise_fragment(load_recipe(dataset.write()).noise)
    assert 'gyro_bias_model = "random_walk"' in default and "bias_tau_s" not in default
    assert math.isfinite(noise.gyro_bias_sigma_rad_s[0])


def test_simulator_writes_the_true_gauss_markov_model(tmp_path):
    """A scenario whose gyros have a Gauss-Markov drift and no random walk: the dataset's
    recipe carries gyro_bias_model = "gauss_markov" with the true τ and σ and loads; the
    accelerometers (random walk) keep their drift sigma."""
    import tomllib

    from gmis.simulate import default_scenario_path, simulate_scenario

    with open(default_scenario_path(), "rb") as fh:
        sc = tomllib.load(fh)
    sc["segment"] = [{"type": "static", "duration_s": 5.0},
                     {"type": "accelerate", "speed_m_s": 5.0, "accel_m_s2": 1.0}]
    sc["gnss"].pop("outage", None)
    sc["imu"] = {"gyro_arw_deg_sqrt_h": 2.0, "gyro_bias_instability_deg_h": 0.0,
                 "gyro_gm_sigma_deg_h": [36.0, 18.0, 9.0], "gyro_gm_tau_s": [50.0, 100.0, 200.0],
                 "accel_vrw_m_s_sqrt_h": 0.2, "accel_bias_instability_mg": 0.5}
    sim = simulate_scenario(sc, tmp_path / "d")
    recipe = load_recipe(sim.recipe_path)
    nz = recipe.noise
    assert nz.gyro_bias_model == "gauss_markov" and nz.accel_bias_model == "random_walk"
    assert nz.gyro_bias_tau_s == (50.0, 100.0, 200.0)
    assert np.asarray(nz.gyro_bias_sigma_rad_s) == pytest.approx(
        np.array([36.0, 18.0, 9.0]) * DEG / 3600.0)
    assert all(v > 0 for v in nz.accel_bias_drift_sigma_m_s2)
    assert gmikf_config(recipe).drift_inv_tau[:3] == pytest.approx(1 / np.array([50.0, 100.0,
                                                                                 200.0]))


def test_the_run_summary_names_the_noise_override(dataset, tmp_path):
    """A run with [paths].noise_override says so in summary.json (helper review
    2026-12-06: nothing in the results showed that tuned noise was used)."""
    from gmis.pipeline import run_recipe

    text = format_noise_fragment(load_recipe(dataset.write()).noise)
    (dataset.root / "frag.toml").write_text(text)
    recipe = dataset.write(dataset.modified("paths", noise_override="frag.toml"))
    s = run_recipe(recipe, tmp_path / "with")
    assert s["noise_override"] == str((dataset.root / "frag.toml").resolve())
    assert "noise_override" not in run_recipe(dataset.write(), tmp_path / "without")
