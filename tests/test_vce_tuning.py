"""VCE tuning job: recovery of known noise levels on simulation, the low-redundancy hold
rule, and the job's outputs."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from gmis.pipeline import prepare_run
from gmis.recipe import load_recipe
from gmis.simulate import scenario_path, simulate_scenario
from tests.simulated_drives import simulate_random_dynamics, true_sigmas
from vce import tune
from vce.job import tune_recipe


@pytest.fixture(scope="module")
def random_dynamics(tmp_path_factory):
    """Random-dynamics drive (tests.simulated_drives.simulate_random_dynamics)."""
    return simulate_random_dynamics(tmp_path_factory.mktemp("rd") / "dataset")


@pytest.mark.parametrize("start", [3.0, 0.3])
def test_recovers_every_component_from_wrong_start(random_dynamics, start):
    _, recipe, prep = random_dynamics
    truth = true_sigmas(recipe)
    res = tune(prep, max_iterations=8, min_redundancy=0.001,
               initial_sigma={k: v * start for k, v in truth.items()})
    assert res.converged and len(res.history) <= 8
    for comp, sigma in zip(res.components, res.final_sigma):
        ratio = sigma / truth[comp.name]
        assert 0.9 <= ratio <= 1.1, (comp.name, ratio)


def test_low_redundancy_components_are_reported_and_held(random_dynamics):
    _, recipe, prep = random_dynamics
    truth = true_sigmas(recipe)
    start = {k: v * 0.3 for k, v in truth.items()}
    res = tune(prep, max_iterations=3, min_redundancy=0.1, initial_sigma=start)
    held = 0
    for it in res.history:
        for j, (comp, st, est) in enumerate(zip(res.components, it.status, it.estimates)):
            if est.mean_redundancy < 0.1:
                assert st == "low redundancy"
                assert it.next_sigma[j] == it.sigma[j]
                held += 1
            else:
                assert st == "estimated"
    assert held > 0          # the process-noise components at 0.3× have r ≈ 0.002


def test_vce_job_outputs(random_dynamics, tmp_path):
    sim, _, _ = random_dynamics
    summary = tune_recipe(sim.recipe_path, tmp_path / "vce", max_iterations=2,
                          min_redundancy=0.001)
    out = tmp_path / "vce"
    for name in ("vce_history.csv", "vce_table.md", "tuned_noise.toml", "residuals_first.npz",
                 "residuals_final.npz", "windows_final.npz", "summary.json"):
        assert (out / name).is_file(), name
    with open(out / "vce_history.csv") as fh:
        hist = list(csv.DictReader(fh))
    assert len(hist) == 2 * len(summary["final"])
    assert {r["iteration"] for r in hist} == {"1", "2"}
    saved = json.loads((out / "summary.json").read_text())
    assert saved["iterations"] == 2
    # the tuned fragment loads back as a noise override
    recipe_path = Path(sim.recipe_path)
    recipe_text = recipe_path.read_text().replace(
        "[paths]\n", f'[paths]\nnoise_override = "{out / "tuned_noise.toml"}"\n', 1)
    tuned_recipe = recipe_path.parent / "tuned.toml"
    tuned_recipe.write_text(recipe_text)
    tuned = load_recipe(tuned_recipe)
    assert np.isclose(np.degrees(tuned.noise.gyro_sigma_rad_s[0]),
                      saved["final"]["gyro_x"]["sigma"])
    res = np.load(out / "residuals_final.npz")
    w = res["gyro_x__w"]
    assert w.size > 20000 and abs(np.std(w) - 1) < 0.1


@pytest.mark.parametrize("start", [3.0, 0.3])
def test_tactical_grade_drive_recovers_measurement_noise(tmp_path_factory, start):
    """Second IMU grade (HG1700-class, deterministic drive): every component with a true
    value — IMU axes and the aiding scales — is recovered within ±10 %. The jerk and
    angular-acceleration noises of a smooth deterministic trajectory have no true value."""
    sim = simulate_scenario(scenario_path("tactical"), tmp_path_factory.mktemp("tac") / "ds")
    recipe = load_recipe(sim.recipe_path)
    truth = {k: v for k, v in true_sigmas(recipe).items()
             if not k.startswith(("jerk", "angacc"))}
    res = tune(prepare_run(recipe), max_iterations=6,
               initial_sigma={k: v * start for k, v in truth.items()})
    for comp, sigma in zip(res.components, res.final_sigma):
        if comp.name in truth:
            assert 0.9 <= sigma / truth[comp.name] <= 1.1, (comp.name, sigma / truth[comp.name])
