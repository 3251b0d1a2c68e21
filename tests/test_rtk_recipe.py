"""GNSS-only recipes (`gmis rtk`) go through gmis.recipe.load_recipe: [rtk] keys are
validated (unknown key, wrong type → one line, exit 2, no results folder) and become the
RtkConfig of gmis.engine_configs."""

from __future__ import annotations

import pytest

from gmis import cli
from gmis.engine_configs import rtk_config, tc_gnss_only_config
from gmis.errors import GmisInputError
from gmis.recipe import load_recipe
from gnss.rtk import RtkConfig

BASE = "[base]\necef_m = [-3976219.5082, 3382372.5671, 3652512.9849]\n"


def _recipe(tmp_path, rtk: str = "", base: str = BASE,
            dataset: str = '[dataset]\nname = "gnss-only"\n'):
    for name in ("rover.obs", "base.obs", "nav.n"):
        (tmp_path / name).write_text("")
    path = tmp_path / "recipe.toml"
    path.write_text(dataset + '[paths]\nrover_obs = "rover.obs"\n'
                    'base_obs = "base.obs"\nnav = "nav.n"\n' + base + rtk)
    return path


def _cli_error(capsys, tmp_path, recipe):
    code = cli.main(["rtk", str(recipe), "-o", str(tmp_path / "out"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and err.startswith("gmis: error: ")
    assert not (tmp_path / "out").exists()
    return err


def test_gnss_only_recipe_needs_no_imu_and_keeps_rtk_defaults(tmp_path):
    recipe = load_recipe(_recipe(tmp_path), gnss_only=True)
    assert recipe.imu is None and recipe.paths.imu is None
    assert rtk_config(recipe) == RtkConfig()
    assert recipe.dataset.name == "gnss-only"
    with pytest.raises(GmisInputError, match=r"paths\.imu: required key missing"):
        load_recipe(_recipe(tmp_path))      # a `gmis run` recipe still needs the IMU
    unnamed = load_recipe(_recipe(tmp_path, dataset=""), gnss_only=True)
    assert unnamed.dataset.name == tmp_path.name   # as gnss.rtk's reader did
    with pytest.raises(GmisInputError, match=r"dataset: required section \[dataset\]"):
        load_recipe(_recipe(tmp_path, dataset=""))


def test_rtk_keys_become_the_rtk_config(tmp_path):
    path = _recipe(tmp_path, '[rtk]\nelevation_mask_deg = 10\nratio_threshold = 2.5\n'
                             'continuous = false\nmin_fix_satellites = 5\n'
                             'troposphere = "none"\n')
    cfg = rtk_config(load_recipe(path, gnss_only=True))
    assert cfg == RtkConfig(elevation_mask_deg=10.0, ratio_threshold=2.5, continuous=False,
                            min_fix_satellites=5, troposphere="none")
    tc = tc_gnss_only_config(cfg)
    assert (tc.elevation_mask_deg, tc.ratio_threshold) == (10.0, 2.5)


def test_unknown_rtk_key_is_one_line_exit_2(capsys, tmp_path):
    err = _cli_error(capsys, tmp_path, _recipe(tmp_path, "[rtk]\nratio = 3.0\n"))
    assert "rtk.ratio: unknown key in [rtk]" in err and "ratio_threshold" in err


@pytest.mark.parametrize("line, words", [
    ('ratio_threshold = "3"', "rtk.ratio_threshold: expected a number, got a string"),
    ("continuous = 1", "rtk.continuous: expected true or false, got an integer"),
    ("min_fix_satellites = 4.5", "rtk.min_fix_satellites: expected an integer"),
    ('troposphere = "wet"', "rtk.troposphere: invalid value 'wet'"),
    ("elevation_mask_deg = 95", "rtk.elevation_mask_deg: must be <= 90"),
    ('frequencies = ["L2"]', 'rtk.frequencies: expected ["L1", "L2"] or ["L1"]'),
    ('frequencies = "L1"', 'rtk.frequencies: expected ["L1", "L2"] or ["L1"]'),
    ('frequencies = ["L1", "L1"]', 'rtk.frequencies: expected ["L1", "L2"] or ["L1"]'),
    ('frequencies = ["L1", "L5"]', 'rtk.frequencies: expected ["L1", "L2"] or ["L1"]'),
    ("partial_ar = 1", "rtk.partial_ar: expected true or false, got an integer"),
    ("min_lock_epochs = 0", "rtk.min_lock_epochs: must be >= 1"),
    ("min_lock_epochs = 2.5", "rtk.min_lock_epochs: expected an integer"),
    ("min_success_rate = 1.0", "rtk.min_success_rate: must be <= 0.999999"),
    ("min_success_rate = -0.1", "rtk.min_success_rate: must be >= 0"),
])
def test_wrong_rtk_value_is_one_line_exit_2(capsys, tmp_path, line, words):
    err = _cli_error(capsys, tmp_path, _recipe(tmp_path, f"[rtk]\n{line}\n"))
    assert words in err, err


def test_missing_base_is_one_line_exit_2(capsys, tmp_path):
    err = _cli_error(capsys, tmp_path, _recipe(tmp_path, base=""))
    assert "base: required section [base]" in err


def test_frequencies_and_partial_ar_keys_become_the_rtk_config(tmp_path):
    path = _recipe(tmp_path, '[rtk]\nfrequencies = ["L1"]\npartial_ar = false\n'
                             'min_lock_epochs = 8\n')
    cfg = rtk_config(load_recipe(path, gnss_only=True))
    assert cfg == RtkConfig(frequencies=("L1",), partial_ar=False, min_lock_epochs=8)
    assert not cfg.dual_frequency and cfg.lock_epochs == 8
    both = rtk_config(load_recipe(_recipe(tmp_path, '[rtk]\nfrequencies = ["L2", "L1"]\n'),
                                  gnss_only=True))
    assert both.frequencies == ("L1", "L2") and both.lock_epochs == 1
    assert RtkConfig(frequencies=("L1",)).lock_epochs == 5      # single-frequency default
    assert tc_gnss_only_config(cfg).use == (True, True, False, True)   # no L2 phase group
    assert tc_gnss_only_config(both).use == (True, True, True, True)


def test_rtk_config_rejects_an_unknown_frequency_set():
    from gnss.errors import GnssInputError
    with pytest.raises(GnssInputError, match=r"rtk.frequencies: \['L2'\] is not one of"):
        RtkConfig(frequencies=("L2",))


def test_min_success_rate_reaches_rtk_and_both_tight_filters(tmp_path):
    """[rtk].min_success_rate (the bootstrapping gate, default off) configures gmis rtk,
    gmis rtk --tight and a run recipe's tightly coupled filter; out of range in Python is
    refused too."""
    from gmis.engine_configs import tc_config
    from gmis.tc_filter import TcConfig
    cfg = rtk_config(load_recipe(_recipe(tmp_path, "[rtk]\nmin_success_rate = 0.999\n"),
                                 gnss_only=True))
    assert cfg.min_success_rate == 0.999
    assert tc_gnss_only_config(cfg).min_success_rate == 0.999
    assert RtkConfig().min_success_rate == 0.0 and TcConfig().min_success_rate == 0.0
    run = load_recipe(_recipe(tmp_path, "[rtk]\nmin_success_rate = 0.99\n"), gnss_only=True)
    assert tc_config(run).min_success_rate == 0.99
    from gnss.errors import GnssInputError
    with pytest.raises(GnssInputError, match="rtk.min_success_rate"):
        RtkConfig(min_success_rate=1.5)
    from gmis.errors import GmisInputError
    with pytest.raises(GmisInputError, match="TcConfig.min_success_rate"):
        TcConfig(min_success_rate=-0.1)
