"""The default drive with a 200 Hz IMU and 1 Hz GNSS / heading (issue 13): the filter must
be consistent at the other rate. NOT YET: measured sampled attitude NEES 4.28 with the
per-step Q used unchanged (9f59828), 4.88 with Q from Δt (this branch), 4.07 with the
white-noise discretisation tried here; the band is [2.15, 3.99]. Position and velocity are
inside. The remaining attitude inconsistency is not the process-noise Δt handling (the
issue's scale-factor runaway, −48 500 ppm on gyro x at 200 Hz, is the suspect); strict
xfail so the test reports when a fix lands."""

import tomllib
from pathlib import Path

import pytest

from gmis.pipeline import run_recipe
from gmis.simulate import default_scenario_path, simulate_scenario
from tests.simulated_drives import assert_nees_time_average_in_chi2_band


@pytest.fixture(scope="module")
def run_200hz(tmp_path_factory):
    root = tmp_path_factory.mktemp("imu200")
    doc = tomllib.loads(Path(default_scenario_path()).read_text())
    doc["scenario"]["imu_rate_hz"] = 200.0
    doc["scenario"]["name"] = "default-200hz-1hz"
    doc["gnss"]["rate_hz"] = 1.0
    doc["heading"]["rate_hz"] = 1.0
    sim = simulate_scenario(doc, root / "dataset")
    summary = run_recipe(sim.recipe_path, root / "results")
    return summary, root / "results"


@pytest.mark.xfail(strict=True, reason="attitude NEES 4.88 > 3.99 at 200 Hz (see module doc)")
def test_nees_time_average_within_chi2_band_at_200hz(run_200hz):
    """NEES of r^n, v^b, θ sampled every 10 s of the aided motion, averaged, against the
    χ²(3K)/K band (the default-drive test's check, tests/test_pipeline_default_drive.py)."""
    summary, results = run_200hz
    assert summary["imu_epochs"] == 120001
    assert_nees_time_average_in_chi2_band(results / "errors.csv")
