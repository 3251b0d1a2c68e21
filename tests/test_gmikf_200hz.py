"""The default drive with a 200 Hz IMU and 1 Hz GNSS / heading (issue 13): the filter must
be consistent at the other rate. NOT YET at this seed: sampled attitude NEES 4.28 with the
per-step Q used unchanged (9f59828), 4.88 with Q from Δt, 5.18 with the scale-factor
regressor from the neighbouring samples, 4.44 with the simulator's bias drift written per
100 Hz step as the filter reads it (this branch); the band is [2.15, 3.99]. Position and
velocity are inside. At this seed a roll error of −0.15…−0.37° persists through the drive
against σ 0.08-0.16°. Over 20 seeds (benchmarks/monte_carlo_scale_factors.py --imu-rate
200 --gnss-rate 1 --bias-drawn-from-prior) the ensemble-mean attitude NEES while moving is
3.13 (in band on 95.6 % of the moving epochs), and this statistic — 27 samples 10 s apart
that are not independent for the tilt — is outside the band on 20 % of 20 seeds of this
scenario (35 % on the 100 Hz default drive): docs/DESIGN.md "Scale factors in the IMU rows", 200 Hz
paragraph. Strict xfail so the test reports when it passes."""

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


@pytest.mark.xfail(strict=True, reason="attitude NEES 4.44 > 3.99 at 200 Hz (see module doc)")
def test_nees_time_average_within_chi2_band_at_200hz(run_200hz):
    """NEES of r^n, v^b, θ sampled every 10 s of the aided motion, averaged, against the
    χ²(3K)/K band (the default-drive test's check, tests/test_pipeline_default_drive.py)."""
    summary, results = run_200hz
    assert summary["imu_epochs"] == 120001
    assert_nees_time_average_in_chi2_band(results / "errors.csv")
