"""The non-holonomic constraint point from the data (gmis.nhc_offset_estimation): on the
simulated default drive (the vehicle moves along its body forward axis at the IMU, so the
true constraint point is the IMU itself) the profile likelihood finds the point from a
search centred 0.8 m off; the recipe switch; the profile's parabola on a known cost."""

import dataclasses

import numpy as np
import pytest

from gmis.nhc_offset_estimation import estimate_nhc_offset
from gmis.recipe import NonholonomicSection, load_recipe
from gmis.simulate import default_scenario_path, simulate_scenario


class _Prep:
    """The fields of a PreparedRun estimate_nhc_offset reads."""

    def __init__(self, center):
        from gmis.run_filter import GmikfConfig
        self.config = GmikfConfig(n_imu=21, q_sd=np.ones(12), imu_sd=np.ones(6),
                                  lever_arm=np.zeros(3), p0_sd=np.ones(21),
                                  nhc_sd=np.full(2, 0.1),
                                  nhc_lever_arm=np.array([0.0, center, 0.0]))


def test_parabola_vertex_and_curvature_sigma_of_a_known_profile():
    runs = []

    def cost(prep, y):
        runs.append(y)
        return 400.0 * (y + 0.37) ** 2 + 3.0 * (y + 0.37) ** 4 - 10.0

    est = estimate_nhc_offset(_Prep(0.5), half_width_m=2.0, cost=cost)
    assert abs(est.forward_m + 0.37) < 2e-3
    assert abs(est.sigma_m - 1.0 / np.sqrt(400.0)) < 0.1 / np.sqrt(400.0)
    assert est.runs == len(set(np.round(runs, 9)))


def test_a_flat_profile_has_no_estimate():
    est = estimate_nhc_offset(_Prep(0.0), cost=lambda prep, y: -abs(y))   # concave
    assert not np.isfinite(est.sigma_m)


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    return simulate_scenario(default_scenario_path(), tmp_path_factory.mktemp("nhc") / "d")


def test_the_constraint_point_of_the_simulated_drive_is_found(simulated):
    from gmis.run_preparation import prepare_run

    recipe = load_recipe(simulated.recipe_path)
    recipe = dataclasses.replace(recipe, nonholonomic=NonholonomicSection(
        lever_arm_m=(0.0, 0.8, 0.0), estimate_lever_arm=True))
    prep = prepare_run(recipe)
    est = prep.nhc_offset
    assert est.applied and np.isfinite(est.sigma_m)
    assert abs(est.forward_m) < 0.1, est          # truth 0; the search started at 0.8 m
    assert prep.config.nhc_lever_arm[1] == est.forward_m
    assert any("constraint point estimated" in w for w in prep.dataset.warnings)


def test_recipe_switch(dataset):
    path = dataset.write(dataset.modified("nonholonomic", estimate_lever_arm=True,
                                          lever_arm_search_m=1.5))
    nhc = load_recipe(path).nonholonomic
    assert nhc.estimate_lever_arm and nhc.lever_arm_search_m == 1.5
    assert not load_recipe(dataset.write(dataset.modified("nonholonomic"))) \
        .nonholonomic.estimate_lever_arm
