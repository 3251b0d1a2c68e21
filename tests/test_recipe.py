"""Recipe loading: defaults, unit conversion, path resolution, noise fragments, and one
malformed recipe per validation rule (each must raise GmisInputError naming file and key)."""

import math

import numpy as np
import pytest

from gmis.errors import GmisInputError
from gmis.recipe import (
    DEG,
    NoiseSection,
    format_noise_fragment,
    load_recipe,
)
from tests.conftest import toml_text


def test_valid_recipe_defaults_are_table_6_2(dataset):
    recipe = load_recipe(dataset.write())
    assert recipe.dataset.name == "unit-test"
    assert recipe.paths.imu == dataset.imu.resolve()
    assert recipe.paths.rover_obs is None
    n = recipe.noise
    assert n.jerk_sigma_m_s3 == (72.0, 72.0, 72.0)
    assert n.angular_acceleration_sigma_rad_s2 == pytest.approx([300 * math.pi / 180] * 3)
    assert n.gyro_sigma_rad_s == pytest.approx([0.75 * math.pi / 180] * 3)
    assert n.accel_sigma_m_s2 == (0.16, 0.16, 0.16)
    assert n.heading_sigma_rad == pytest.approx(0.5 * math.pi / 180)
    assert (n.code_sigma_m, n.phase_l1_sigma_m, n.doppler_sigma_m_s) == (0.5, 0.02, 0.1)
    assert recipe.filter.mode == "loose" and recipe.filter.states == 27
    assert recipe.antennas.primary_lever_arm_m == (0.1, 0.2, 1.5)
    assert recipe.origin_llh() is None


def test_degrees_become_radians_and_origin(dataset):
    doc = dataset.modified("noise", gyro_deg_s=[1.0, 2.0, 3.0], heading_deg=2.0)
    doc["initial_sigma"] = {"attitude_deg": [0.5, 0.5, 4.0]}
    doc["origin"] = {"lat_deg": 43.5, "lon_deg": -79.25, "h_m": 150.0}
    recipe = load_recipe(dataset.write(doc))
    assert recipe.noise.gyro_sigma_rad_s == pytest.approx(np.deg2rad([1.0, 2.0, 3.0]))
    assert recipe.noise.heading_sigma_rad == pytest.approx(np.deg2rad(2.0))
    assert recipe.initial_sigma.attitude_rad == pytest.approx(np.deg2rad([0.5, 0.5, 4.0]))
    assert recipe.origin_llh() == pytest.approx((np.deg2rad(43.5), np.deg2rad(-79.25), 150.0))


def test_base_ecef_and_geodetic_agree_and_become_origin(dataset):
    doc = dataset.modified("base", lat_deg=43.77, lon_deg=-79.5, h_m=170.0)
    geodetic = load_recipe(dataset.write(doc)).base
    doc = dataset.modified("base", ecef_m=list(geodetic.ecef_m))
    recipe = load_recipe(dataset.write(doc))
    assert recipe.base.llh.lat_rad == pytest.approx(43.77 * DEG, abs=1e-11)
    assert recipe.base.llh.lon_rad == pytest.approx(-79.5 * DEG, abs=1e-11)
    assert recipe.base.llh.h_m == pytest.approx(170.0, abs=1e-5)
    assert recipe.origin_llh() == pytest.approx(recipe.base.llh.as_tuple())


def test_paths_are_relative_to_the_recipe_file(dataset):
    sub = dataset.root / "recipes" / "deep"
    sub.mkdir(parents=True)
    doc = dataset.modified("paths", imu="../../imu.csv", gnss_solution="../../gnss.csv",
                           heading=None, reference=None)
    recipe = load_recipe(dataset.write(doc, name="recipes/deep/r.toml"))
    assert recipe.paths.imu == dataset.imu.resolve()
    assert recipe.paths.gnss_solution == dataset.gnss.resolve()


def test_axes_matrix_maps_forward_left_up_sensor_to_rfu(dataset):
    recipe = load_recipe(dataset.write(dataset.modified("imu", axes=["-y", "x", "z"])))
    sensor = np.array([1.0, 2.0, 3.0])  # forward, left, up
    assert recipe.imu.axes_matrix @ sensor == pytest.approx([-2.0, 1.0, 3.0])


def test_noise_fragment_round_trip_through_noise_override(dataset):
    tuned = NoiseSection().__class__(
        jerk_sigma_m_s3=(10.5, 11.25, 3.0), gyro_sigma_rad_s=(0.001, 0.002, 0.003),
        heading_sigma_rad=0.0123, gyro_bias_drift_sigma_rad_s=(0.0, 1e-6, 0.0),
        code_sigma_m=0.37, imu_sigma_source="vce")
    (dataset.root / "tuned_noise.toml").write_text(format_noise_fragment(tuned, "tuned by VCE"))
    doc = dataset.modified("paths", noise_override="tuned_noise.toml")
    doc["noise"] = {"jerk_m_s3": [1.0, 1.0, 1.0], "phase_l1_m": 0.05}
    recipe = load_recipe(dataset.write(doc))
    assert recipe.noise.imu_sigma_source == "vce"
    for name in NoiseSection.__dataclass_fields__:
        if name == "imu_sigma_source":
            continue
        assert np.allclose(getattr(recipe.noise, name), getattr(tuned, name), rtol=1e-13,
                           atol=0), name

    # the fragment pasted into a recipe reads back the same
    text = dataset.write().read_text() + "\n" + format_noise_fragment(tuned)
    (dataset.root / "pasted.toml").write_text(text)
    pasted = load_recipe(dataset.root / "pasted.toml")
    assert np.allclose(pasted.noise.gyro_sigma_rad_s, tuned.gyro_sigma_rad_s, rtol=1e-13)


def test_with_noise_replaces_only_given_fields(dataset):
    recipe = load_recipe(dataset.write())
    tuned = recipe.with_noise(accel_sigma_m_s2=np.array([0.3, 0.4, 0.5]), code_sigma_m=0.9)
    assert tuned.noise.accel_sigma_m_s2 == (0.3, 0.4, 0.5)
    assert tuned.noise.code_sigma_m == 0.9
    assert tuned.noise.gyro_sigma_rad_s == recipe.noise.gyro_sigma_rad_s
    assert recipe.noise.code_sigma_m == 0.5  # original untouched
    with pytest.raises(TypeError, match="accel_sigma_m_s2"):
        recipe.with_noise(accel_sigma_m_s3=(1, 1, 1))
    with pytest.raises(ValueError):
        recipe.with_noise(accel_sigma_m_s2=(1, 1))


# One malformed recipe per rule: (section, changes, dotted key expected in the message,
# words expected in the message).
MALFORMED = {
    "unknown key": ("imu", {"rate_hzz": 100.0}, "imu.rate_hzz", "did you mean 'rate_hz'"),
    "missing file": ("paths", {"gnss_solution": "nope.csv"}, "paths.gnss_solution",
                     "file not found"),
    "wrong unit": ("imu", {"gyro_unit": "deg/sec"}, "imu.gyro_unit", "deg/s"),
    "increment unit with rate format": ("imu", {"gyro_unit": "deg"}, "imu.gyro_unit",
                                        'set [imu].format = "increment"'),
    "imu sigma source": ("noise", {"imu_sigma_source": "VCE"}, "noise.imu_sigma_source",
                         "allowed: 'given', 'vce'"),
    "vector length": ("noise", {"gyro_deg_s": [0.75, 0.75]}, "noise.gyro_deg_s",
                      "3 numbers, got 2"),
    "scalar for vector": ("antennas", {"primary_lever_arm_m": 1.5},
                          "antennas.primary_lever_arm_m", "list of 3"),
    "axes repeated": ("imu", {"axes": ["x", "x", "z"]}, "imu.axes", "signed permutation"),
    "axes unknown name": ("imu", {"axes": ["x", "y", "w"]}, "imu.axes", "invalid axis"),
    "axes left-handed": ("imu", {"axes": ["-x", "y", "z"]}, "imu.axes", "left-handed"),
    "start after end": ("time", {"start_gps_s": 345610.0, "end_gps_s": 345600.0},
                        "time.end_gps_s", "must be after"),
    "start equals end": ("time", {"start_gps_s": 345600.0, "end_gps_s": 345600.0},
                         "time.end_gps_s", "must be after"),
    "non-positive rate": ("imu", {"rate_hz": 0.0}, "imu.rate_hz", "> 0"),
    "missing rate": ("imu", {"rate_hz": None}, "imu.rate_hz", "required"),
    "string for number": ("imu", {"rate_hz": "100"}, "imu.rate_hz", "expected a number"),
    "negative sigma": ("noise", {"accel_m_s2": [0.1, -0.1, 0.1]}, "noise.accel_m_s2", "> 0"),
    "zero heading sigma": ("noise", {"heading_deg": 0.0}, "noise.heading_deg", "> 0"),
    "negative drift": ("noise", {"gyro_bias_drift_deg_s": [0, -1e-4, 0]},
                       "noise.gyro_bias_drift_deg_s", ">= 0"),
    "bad mode": ("filter", {"mode": "tightly"}, "filter.mode", "did you mean 'tight'"),
    "tight without RINEX": ("filter", {"mode": "tight"}, "filter.mode", "rover_obs"),
    "bad states": ("filter", {"states": 24}, "filter.states", "[21, 27]"),
    "bad velocity observable": ("filter", {"tc_velocity_observable": "tdpc"},
                                "filter.tc_velocity_observable", "did you mean 'tdcp'"),
    "velocity observable not a string": ("filter", {"tc_velocity_observable": 3},
                                         "filter.tc_velocity_observable", "expected a string"),
    "zero tdcp sigma": ("noise", {"tdcp_m": 0.0}, "noise.tdcp_m", "> 0"),
    "float states": ("filter", {"states": 27.0}, "filter.states", "integer"),
    "latitude out of range": ("origin", {"lat_deg": 91.0, "lon_deg": 0.0, "h_m": 0.0},
                              "origin.lat_deg", "<= 90"),
    "origin incomplete": ("origin", {"lat_deg": 43.0, "lon_deg": -79.0}, "origin.h_m",
                          "required"),
    "base both forms": ("base", {"lat_deg": 43.0, "lon_deg": -79.0, "h_m": 1.0,
                                 "ecef_m": [1.0, 2.0, 3.0]}, "base.lat_deg", "either"),
    "base ecef not on earth": ("base", {"ecef_m": [1.0, 2.0, 3.0]}, "base.ecef_m",
                               "not an ECEF position"),
    "missing dataset name": ("dataset", {"name": None}, "dataset.name", "required"),
    "missing lever arm with GNSS": ("antennas", {"primary_lever_arm_m": None},
                                    "antennas.primary_lever_arm_m", "required"),
    "bad delimiter": ("imu", {"delimiter": ";"}, "imu.delimiter", "allowed"),
    "negative column index": ("imu", {"time_column": -1}, "imu.time_column", ">= 0"),
    "bad troposphere": ("filter", {"tc_troposphere": "saastamoinen"}, "filter.tc_troposphere",
                        "allowed: 'hydrostatic', 'none'"),
    "nhc unknown key": ("nonholonomic", {"sigma_lateral": 0.1},
                        "nonholonomic.sigma_lateral", "did you mean 'sigma_lateral_m_s'"),
    "nhc zero sigma": ("nonholonomic", {"sigma_vertical_m_s": 0.0},
                       "nonholonomic.sigma_vertical_m_s", "> 0"),
    "nhc zero rate": ("nonholonomic", {"rate_hz": 0.0}, "nonholonomic.rate_hz", "> 0"),
    "nhc lever arm length": ("nonholonomic", {"lever_arm_m": [0.0, -1.2]},
                             "nonholonomic.lever_arm_m", "3 numbers, got 2"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_recipe_names_file_and_key(dataset, case):
    section, changes, key, words = MALFORMED[case]
    path = dataset.write(dataset.modified(section, **changes))
    with pytest.raises(GmisInputError) as info:
        load_recipe(path)
    message = str(info.value)
    assert message.startswith(str(path.resolve()) + ": "), message
    assert key in message, message
    assert words in message, message
    assert "\n" not in message


def test_unknown_section_suggests_nearest(dataset):
    doc = dict(dataset.doc, noize={"gyro_deg_s": [1.0, 1.0, 1.0]})
    with pytest.raises(GmisInputError, match=r"noize: unknown section \[noize\] \(did you "
                                             r"mean 'noise'\?\)"):
        load_recipe(dataset.write(doc))


def test_missing_recipe_file_and_bad_toml(dataset):
    with pytest.raises(GmisInputError, match="recipe file not found"):
        load_recipe(dataset.root / "absent.toml")
    bad = dataset.root / "bad.toml"
    bad.write_text(toml_text(dataset.doc) + "\n[imu\nrate = 1\n")
    with pytest.raises(GmisInputError, match=r"bad.toml: not valid TOML"):
        load_recipe(bad)


def test_noise_override_errors_name_the_override_file(dataset):
    (dataset.root / "tuned.toml").write_text("[noise]\ngyro_deg_s = [1.0, 1.0]\n")
    path = dataset.write(dataset.modified("paths", noise_override="tuned.toml"))
    with pytest.raises(GmisInputError, match=r"tuned.toml: noise.gyro_deg_s: expected a list "
                                             r"of 3 numbers, got 2"):
        load_recipe(path)
    (dataset.root / "tuned.toml").write_text("[imu]\nrate_hz = 1.0\n")
    with pytest.raises(GmisInputError, match=r"tuned.toml: imu: a noise override file holds "
                                             r"only a \[noise\] table"):
        load_recipe(path)


def test_nonholonomic_section_enables_the_constraint_in_the_filter_config(dataset):
    from gmis.engine_configs import gmikf_config as config_from_recipe
    plain = load_recipe(dataset.write(dataset.modified("filter")))
    assert plain.nonholonomic is None
    assert not config_from_recipe(plain).nhc_enabled
    path = dataset.write(dataset.modified("nonholonomic", sigma_lateral_m_s=0.2, rate_hz=5.0,
                                          lever_arm_m=[0.0, -1.5, -0.4]))
    cfg = config_from_recipe(load_recipe(path))
    assert cfg.nhc_enabled
    assert np.allclose(cfg.nhc_sd, [0.2, 0.1]) and cfg.nhc_interval_s == pytest.approx(0.2)
    assert np.allclose(cfg.nhc_lever_arm, [0.0, -1.5, -0.4])


def test_velocity_observable_and_tdcp_sigma(dataset):
    recipe = load_recipe(dataset.write())
    assert recipe.filter.tc_velocity_observable == "doppler"
    assert recipe.noise.tdcp_sigma_m == recipe.noise.phase_l1_sigma_m
    doc = dataset.modified("noise", phase_l1_m=0.003)
    assert load_recipe(dataset.write(doc)).noise.tdcp_sigma_m == 0.003   # follows L1
    doc = dataset.modified("filter", tc_velocity_observable="tdcp")
    doc["noise"] = dict(doc.get("noise", {}), tdcp_m=0.004)
    recipe = load_recipe(dataset.write(doc))
    assert recipe.filter.tc_velocity_observable == "tdcp"
    assert recipe.noise.tdcp_sigma_m == 0.004
    assert "tdcp_m = 0.004" in format_noise_fragment(recipe.noise)


def test_filter_config_rejects_half_enabled_nonholonomic_constraint():
    from gmis.run_filter import GmikfConfig
    base = {"n_imu": 21, "q_sd": np.ones(12), "imu_sd": np.ones(6),
            "lever_arm": np.zeros(3), "p0_sd": np.ones(21)}
    with pytest.raises(ValueError, match="both > 0"):
        GmikfConfig(**base, nhc_sd=[0.1, 0.0])
    with pytest.raises(ValueError, match="nhc_interval_s"):
        GmikfConfig(**base, nhc_sd=[0.1, 0.1], nhc_interval_s=0.0)
    assert not GmikfConfig(**base).nhc_enabled
