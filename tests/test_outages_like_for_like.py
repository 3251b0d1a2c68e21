"""Outage study like for like (issue 13 item 5): the default drive's defaults place their
windows around its own GNSS gap, pure dead reckoning is reported beside both filters, and
the heading switch does what it says."""

import copy
import csv

import numpy as np
import pytest

from gmis.outages import (
    NATIVE_GAP_MARGIN_S,
    choose_outage_windows,
    dead_reckoning_positions,
    run_outage_experiment,
)
from gmis.pipeline import prepare_run
from gmis.recipe import load_recipe
from gmis.simulate import load_scenario, scenario_path, simulate_scenario
from tests.simulated_drives import square_drive_segments


@pytest.fixture(scope="module")
def default_dataset(tmp_path_factory):
    return simulate_scenario(scenario_path("default"), tmp_path_factory.mktemp("d") / "ds")


def test_default_windows_avoid_the_native_gap(default_dataset):
    """`gmis outages default` defaults (8 × 20 s): 8 windows, none within 2 s of the
    scenario's own 430-445 s GNSS outage (before: 'outage slot 5 has no 20 s stretch')."""
    prep = prepare_run(load_recipe(default_dataset.recipe_path))
    wins = choose_outage_windows(prep, 20.0, 8)
    t0 = prep.dataset.imu.t[0]
    assert len(wins) == 8
    gap = (t0 + 430.0 - NATIVE_GAP_MARGIN_S, t0 + 445.0 + NATIVE_GAP_MARGIN_S)
    for a, b in wins:
        assert b - a == pytest.approx(20.0)
        assert b < gap[0] or a > gap[1], (a - t0, b - t0)
    starts = np.array([a for a, _ in wins])
    assert np.all(np.diff(starts) > 20.0)


@pytest.fixture(scope="module")
def small_dataset(tmp_path_factory):
    sc = copy.deepcopy(load_scenario(scenario_path("default")))
    sc["gnss"]["outage"] = []
    sc["segment"] = square_drive_segments()
    return simulate_scenario(sc, tmp_path_factory.mktemp("s") / "ds")


def test_dead_reckoning_column_and_heading_switch(small_dataset, tmp_path):
    out = tmp_path / "res"
    s = run_outage_experiment(small_dataset.recipe_path, duration_s=8.0, count=3,
                              results_dir=out)
    rms = s["rms_max_drift_m"]
    assert s["heading_in_outages"] == "removed" and s["dead_reckoning_biases"] == "raw"
    # raw-IMU dead reckoning keeps the 8 mg vertical accelerometer bias (+200 ppm of g):
    # ½·(0.0785 + 0.0020) m/s²·(8 s)² = 2.6 m up in every window (the aided filters have
    # calibrated it: < 0.5 m); horizontally 8 s are too short to tell them apart
    assert 1.8 < rms["dr"]["up"] < 3.4, rms
    assert rms["dr"]["up"] > 5.0 * max(rms["errins"]["up"], rms["gmikf"]["up"]), rms
    assert s["ratio_dr_over_gmikf"]["horizontal"] == pytest.approx(
        rms["dr"]["horizontal"] / rms["gmikf"]["horizontal"])
    with open(out / "outages.csv") as fh:
        rows = [r for r in csv.reader(fh) if r and not r[0].startswith("#")]
    assert rows[0][-4:] == ["dr_east_m", "dr_north_m", "dr_up_m", "dr_horizontal_m"]
    kept = run_outage_experiment(small_dataset.recipe_path, duration_s=8.0, count=3,
                                 keep_heading=True, dr_biases="filter")
    assert kept["heading_in_outages"] == "kept"
    # same windows; only the GNSS samples are removed now (before: GNSS + heading, both 5 Hz)
    assert 2 * kept["gnss_samples_removed"] == s["gnss_samples_removed"]


def test_calibrated_dead_reckoning_equals_free_inertial_errins(small_dataset):
    """With heading removed, no update reaches the error-state EKF in a window, so dead
    reckoning with that EKF's biases reproduces its free-inertial positions (same
    mechanization, same start) — the bookkeeping of the DR column is right."""
    from gmis.errins import run_errins_prepared
    recipe = load_recipe(small_dataset.recipe_path)
    full = prepare_run(recipe)
    wins = choose_outage_windows(full, 8.0, 2)
    prep = prepare_run(recipe, dataset=full.dataset, gnss_outages=wins)
    rec = run_errins_prepared(prep)
    t = rec.t
    keep = rec.imu_row >= 0
    dr = dead_reckoning_positions(prep, rec, t, keep, wins, rec.nav[:, 0:3], "filter")
    for a, b in wins:
        sel = keep & (t >= a) & (t <= b)
        np.testing.assert_allclose(dr[sel], rec.nav[sel, 0:3], atol=1e-6)
