"""Identified model → GMIKF noise inputs: rate scaling, RW/GM drift, the [noise] fragment."""

import tomllib

import numpy as np
import pytest

from calibration import filter_inputs as F
from calibration import processes as P
from calibration.gmwm import fit_gmwm
from calibration.wavelet_variance import wavelet_variance


def _fit(model, theta, dt=0.01, seed=0):
    x = P.simulate(model, theta, 2 ** 18, np.random.default_rng(seed))
    return fit_gmwm(wavelet_variance(x, dt), model)


def test_white_sigma_scales_with_the_imu_rate_and_rw_drift_per_step():
    fit = _fit(("WN", "RW"), [1e-4, 1e-10])
    at_100 = F.filter_noise(fit, 0.01)
    at_200 = F.filter_noise(fit, 0.005)
    wn, rw = fit.theta
    assert at_100["measurement_sigma"] == pytest.approx(np.sqrt(wn))
    assert at_200["measurement_sigma"] == pytest.approx(np.sqrt(2 * wn))  # N fixed, δt halved
    assert at_200["bias_drift_sigma_per_step"] == pytest.approx(np.sqrt(rw / 2))
    assert at_100["bias_drift_source"] == "RW"


def test_fragment_drift_is_per_recipe_step_whatever_the_imu_rate():
    """The recipe's drift keys are 1σ per step of 1/100 s (GmikfConfig.q_rate_hz) at any
    IMU rate: a 200 Hz (or 50 Hz) calibration must write the same value as a 100 Hz one,
    i.e. the same drift variance per second γ²/Δt in the filter."""
    fit = _fit(("WN", "RW"), [1e-4, 1e-10])
    rw = fit.theta[1]
    per_second = []
    for imu_dt in (0.02, 0.01, 0.005):
        noise = F.filter_noise(fit, imu_dt)
        fragment = tomllib.loads(F.noise_fragment({f"gyro_{a}": noise for a in "xyz"}, "t"))
        drift = np.radians(fragment["noise"]["gyro_bias_drift_deg_s"][0])
        per_second.append(drift ** 2 * 100.0)
    assert per_second == pytest.approx([rw / 0.01] * 3, rel=1e-12)


def test_gauss_markov_parameters_and_rw_overbound_without_rw():
    fit = _fit(("WN", "AR1"), [1e-4, 0.999, 1e-8])
    noise = F.filter_noise(fit, 0.01)
    phi, s2 = fit.theta[1], fit.theta[2]
    gm = noise["gauss_markov"][0]
    assert gm["tau_s"] == pytest.approx(-0.01 / np.log(phi))
    assert gm["stationary_sigma"] == pytest.approx(np.sqrt(s2 / (1 - phi ** 2)))
    assert gm["phi_at_imu_rate"] == pytest.approx(phi)
    assert noise["bias_drift_source"].startswith("AR1 over-bound")
    # the over-bounding RW matches the AR1's WV at τ = 4 (000 eq. 4.8)
    g2 = F.rw_overbound_of_ar1(phi, s2)
    assert P.rw_wv(g2, 4.0) == pytest.approx(P.ar1_wv(phi, s2, np.array([4.0]))[0])


def test_fragment_is_a_noise_table_in_recipe_units():
    fit = _fit(("WN", "RW"), [(0.3 * np.pi / 180) ** 2, 1e-12])
    noise = {f"{k}_{a}": F.filter_noise(fit, 0.01) for k in ("gyro", "accel") for a in "xyz"}
    doc = tomllib.loads(F.noise_fragment(noise, "test"))
    assert set(doc) == {"noise"}
    assert set(doc["noise"]) == {"gyro_deg_s", "gyro_bias_drift_deg_s", "accel_m_s2",
                                 "accel_bias_drift_m_s2"}
    assert doc["noise"]["gyro_deg_s"][0] == pytest.approx(0.3, rel=0.02)


def test_fragment_with_ar1_loads_as_a_gauss_markov_recipe(dataset):
    """WN+AR1 per axis: the fragment selects the Gauss-Markov bias (slowest AR1: τ and
    stationary σ), load_recipe accepts it through [paths].noise_override and the GMIKF gets
    1/τ and the density 2σ²/τ."""
    from gmis.engine_configs import gmikf_config
    from gmis.recipe import load_recipe

    fit = _fit(("WN", "AR1"), [(0.3 * np.pi / 180) ** 2, 0.999, 1e-10])
    noise = {f"{k}_{a}": F.filter_noise(fit, 0.01) for k in ("gyro", "accel") for a in "xyz"}
    text = F.noise_fragment(noise, "test")
    doc = tomllib.loads(text)["noise"]
    gm = noise["gyro_x"]["bias_state"]
    assert doc["gyro_bias_model"] == "gauss_markov" and doc["accel_bias_model"] == "gauss_markov"
    assert doc["gyro_bias_tau_s"][0] == pytest.approx(-0.01 / np.log(fit.theta[1]))
    assert doc["gyro_bias_sigma_deg_s"][1] == pytest.approx(gm["stationary_sigma"] * 180 / np.pi)
    assert "gyro_bias_drift_deg_s" not in doc
    (dataset.root / "cal.toml").write_text(text)
    recipe = load_recipe(dataset.write(dataset.modified("paths", noise_override="cal.toml")))
    cfg = gmikf_config(recipe)
    assert cfg.drift_inv_tau[:6] == pytest.approx(1 / gm["tau_s"])
    assert cfg.q_psd()[6] == pytest.approx(2 * gm["stationary_sigma"] ** 2 / gm["tau_s"])


def test_rw_with_ar1_keeps_the_rw_alternative_and_says_what_is_left_out():
    fit = _fit(("WN", "AR1", "RW"), [1e-4, 0.999, 1e-8, 1e-12])
    noise = {f"gyro_{a}": F.filter_noise(fit, 0.01) for a in "xyz"}
    text = F.noise_fragment(noise, "test")
    assert "not represented by the Gauss-Markov bias state: RW" in text
    assert "# random-walk alternative: gyro_bias_model = \"random_walk\"" in text


def test_comparison_table_vce_row_from_a_gmis_vce_fragment(tmp_path):
    """The 001 §5.3.5 table's VCE row holds the σ of a `gmis vce` fragment (format_noise_
    fragment's [noise] table, deg/s and m/s²); without one it says n/a; a fragment without
    the IMU keys is one clear error."""
    from calibration.datasheet import read_vce_noise
    from gmis.errors import GmisInputError
    from gmis.recipe import NoiseSection, format_noise_fragment

    tuned = NoiseSection(gyro_sigma_rad_s=tuple(np.radians([0.5, 0.6, 0.7])),
                         accel_sigma_m_s2=(0.11, 0.12, 0.13))
    path = tmp_path / "tuned_noise.toml"
    path.write_text(format_noise_fragment(tuned, "tuned by VCE"))
    vce = read_vce_noise(path)
    allan = {"random_walk": 1e-3, "bias_instability": 1e-5, "quantization": None}
    results = {f"{k}_{a}": {"allan": allan, "filter": {"measurement_sigma": 0.01}}
               for k in ("gyro", "accel") for a in "xyz"}
    rows = {(r[0], r[1]): r[3:] for r in F.comparison_rows(results, 0.01, None, vce)}
    assert rows[("gyro", "VCE on a drive")] == pytest.approx([0.5, 0.6, 0.7])
    assert rows[("accel", "VCE on a drive")] == pytest.approx([0.11, 0.12, 0.13])
    plain = {(r[0], r[1]): r[3:] for r in F.comparison_rows(results, 0.01, None)}
    assert plain[("gyro", "VCE on a drive")] == ["n/a"] * 3
    bad = tmp_path / "bad.toml"
    bad.write_text("[noise]\ngyro_deg_s = [0.5, 0.6]\n")
    with pytest.raises(GmisInputError, match="noise.gyro_deg_s: needs 3 numbers"):
        read_vce_noise(bad)


def test_gauss_markov_overbound_covers_ar1_plus_rw_on_the_horizon():
    """AR1 + RW (004 §IV Simulation II values at 100 Hz): the Gauss-Markov state's
    structure function 2σ²(1 − e^{−h/τ}) is ≥ the model's D(h) at 5000 lags in
    [δt, horizon] (not only the optimiser's grid), its variance σ² covers the bias'
    s² + γ²·horizon, one of the two bounds is tight (not an arbitrary inflation), and it
    falls below D past the horizon (the RW)."""
    dt, ar1, gamma2 = 0.01, [(0.9985, 1.2e-10)], 7e-13
    st = F.gauss_markov_overbound(ar1, gamma2, dt, dt, horizon_s=600.0)
    lags = np.geomspace(dt, 600.0, 5000)
    d = F.bias_structure_function(ar1, gamma2, lags / dt)
    d_gm = 2 * st["stationary_sigma"] ** 2 * -np.expm1(-lags / st["tau_s"])
    assert np.all(d_gm >= d * (1 - 1e-9))
    marginal = ar1[0][1] / (1 - ar1[0][0] ** 2) + gamma2 * 600.0 / dt
    assert st["stationary_sigma"] ** 2 >= marginal * (1 - 1e-9)
    assert np.min(d_gm / d) < 1.02 or st["stationary_sigma"] ** 2 < 1.02 * marginal
    assert 1.0 <= st["overbound_mean"] <= st["overbound_max"] <= 3.0
    far = np.array([6000.0])
    assert 2 * st["stationary_sigma"] ** 2 * -np.expm1(-far / st["tau_s"]) < \
        F.bias_structure_function(ar1, gamma2, far / dt)


def test_single_ar1_is_the_state_exactly_and_ar1_rw_is_over_bounded():
    fit = _fit(("WN", "AR1"), [1e-4, 0.999, 1e-8])
    st = F.filter_noise(fit, 0.01)["bias_state"]
    assert st["tau_s"] == pytest.approx(-0.01 / np.log(fit.theta[1]))
    assert st["over_bounded"] == []
    fit = _fit(("WN", "AR1", "RW"), [1e-4, 0.999, 1e-8, 1e-12])
    noise = F.filter_noise(fit, 0.01, horizon_s=300.0)
    st = noise["bias_state"]
    assert st["over_bounded"] == ["AR1", "RW"] and st["horizon_s"] == 300.0
    phi, xi2, g2 = fit.theta[1], fit.theta[2], fit.theta[3]
    # the σ covers the AR1's stationary σ and the RW's growth over the horizon
    assert st["stationary_sigma"] ** 2 >= xi2 / (1 - phi ** 2)
    # random-walk alternative: RW plus the AR1's over-bound (000 eq. 4.8), per step
    assert noise["bias_drift_sigma_per_step"] == pytest.approx(
        np.sqrt(g2 + F.rw_overbound_of_ar1(phi, xi2)))
    assert noise["bias_drift_source"] == "RW + AR1 over-bound (000 eq. 4.8)"


def test_sub_second_ar1_is_white_measurement_noise_not_the_bias_state():
    """ADIS16405 accel x shape (100 Hz): AR1s of 6 ms and 0.28 s beside a 78 s AR1 and a
    RW. The fast AR1s enter the measurement σ with their f = 0 spectral density
    ξ²/(1−φ)² (same velocity random walk over spans ≫ τ); the bias state over-bounds only
    the 78 s AR1 + RW (before, the 0.28 s AR1 pulled τ_b to seconds); with the threshold at
    the IMU interval the 0.28 s AR1 is back in the bias part and τ_b is short."""
    dt = 0.01
    model = ("WN", "AR1", "AR1", "AR1", "RW")
    theta = np.array([1e-4, 0.18, 1.4e-3, 0.9647, 3.07e-6, 0.999872, 1e-8, 1.8e-9])
    noise = F.filter_noise_of(model, theta, dt, dt, horizon_s=600.0)
    assert [round(w["tau_s"], 3) for w in noise["white_ar1"]] == [0.006, 0.278]
    white = 1e-4 + 1.4e-3 / (1 - 0.18) ** 2 + 3.07e-6 / (1 - 0.9647) ** 2
    assert noise["measurement_sigma"] == pytest.approx(np.sqrt(white))
    assert [round(g["tau_s"]) for g in noise["gauss_markov"]] == [78]
    assert noise["bias_state"]["over_bounded"] == ["AR1", "RW"]
    assert noise["bias_state"]["tau_s"] > 60.0
    old = F.filter_noise_of(model, theta, dt, dt, horizon_s=600.0, white_below_s=dt)
    assert len(old["gauss_markov"]) == 2 and old["bias_state"]["tau_s"] < 10.0


def test_measurement_sigma_is_capped_at_what_the_data_show():
    """A fitted per-sample σ far above the samples' Allan variance at 1 s and their spread
    in 1-s blocks is capped at that bound (ADIS16405 gyro z: 0.909 deg/s fitted, 0.43 in
    the data; helper review 2026-12-06); one within 10 % of it is kept."""
    from calibration.allan import allan_variance
    from calibration.filter_inputs import cap_to_sample_spread

    rng = np.random.default_rng(4)
    dt = 0.01
    x = [rng.normal(0.0, 0.4, 200_000) for _ in range(2)]        # white, σ 0.4 per sample
    avs = [allan_variance(xi, dt) for xi in x]
    kept = cap_to_sample_spread({"measurement_sigma": 0.41}, x, avs, dt, dt)
    assert kept["measurement_sigma"] == 0.41 and "measurement_sigma_fitted" not in kept
    # the larger of two estimates of 0.4, each good to ~2 % here (edf ~2000 at 1 s)
    assert kept["measurement_sigma_data_bound"] == pytest.approx(0.4, rel=0.05)
    capped = cap_to_sample_spread({"measurement_sigma": 0.9}, x, avs, dt, dt)
    assert capped["measurement_sigma"] == pytest.approx(0.4, rel=0.05)
    assert capped["measurement_sigma_fitted"] == 0.9
    # a filter at 50 Hz: the white part rescaled by dt/δt, the bound too
    slow = cap_to_sample_spread({"measurement_sigma": 0.9}, x, avs, dt, 0.02)
    assert slow["measurement_sigma"] == pytest.approx(0.4 / np.sqrt(2), rel=0.05)
