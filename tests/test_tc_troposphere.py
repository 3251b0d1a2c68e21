"""Tightly coupled troposphere model ([filter].tc_troposphere) on a simulated drive whose
base sits 40 m below the road and whose troposphere is simulated at each receiver
(raw_gnss.differential_atmosphere = 1, Saastamoinen with 70 % humidity; ionosphere off so
the test isolates the troposphere). The filter models only the hydrostatic part, at its
own antenna position: the up bias must vanish; assuming the delay cancels leaves ~−28 mm."""

import tomllib
from pathlib import Path

import numpy as np
import pytest

from gmis.pipeline import run_recipe
from gmis.simulate import scenario_path, simulate_scenario


@pytest.fixture(scope="module")
def height_offset_dataset(tmp_path_factory):
    doc = tomllib.loads(Path(scenario_path("tightly_coupled")).read_text())
    doc["raw_gnss"].update(differential_atmosphere=1.0, ionosphere_zenith_m=0.0,
                           base_offset_enu_m=[-50.0, 20.0, -40.0])
    root = tmp_path_factory.mktemp("trop")
    sim = simulate_scenario(doc, root / "dataset")
    return Path(sim.recipe_path)


def _up_error_mm(recipe, results):
    run_recipe(recipe, results)
    err = np.genfromtxt(results / "errors.csv", delimiter=",", names=True)
    t = err["time_gps_s"] - err["time_gps_s"][0]
    keep = (t > 305.0) & ~((t >= 495.0) & (t <= 525.0))    # driving, sky blockage excluded
    du = err["du_m"][keep] * 1000.0
    return float(du.mean()), float(np.sqrt(np.mean(du ** 2)))


def test_hydrostatic_model_removes_the_height_difference_bias(height_offset_dataset, tmp_path):
    recipe = height_offset_dataset
    text = recipe.read_text().replace('mode = "loose"', 'mode = "tight"')
    assert "tc_troposphere" not in text        # default: modelled
    modelled = recipe.parent / "tight.toml"
    modelled.write_text(text)
    cancels = recipe.parent / "tight_none.toml"
    cancels.write_text(text.replace('mode = "tight"', 'mode = "tight"\ntc_troposphere = "none"'))
    bias_model, rms_model = _up_error_mm(modelled, tmp_path / "model")
    bias_none, rms_none = _up_error_mm(cancels, tmp_path / "none")
    print(f"up error mean/RMS mm: modelled {bias_model:.2f}/{rms_model:.2f}, "
          f"assumed to cancel {bias_none:.2f}/{rms_none:.2f}")
    assert abs(bias_model) < 3.0
    assert rms_model < 20.0
    assert bias_none < -15.0                    # the effect is there to be removed
