"""Road-test simulator: scenario TOML → dataset folder (docs/formats.md) + recipe + truth.

Public API:
    simulate_scenario(scenario, out_dir, seed=None, progress=None, overwrite=False)
    load_scenario(path), validate_scenario(raw, source), default_scenario_path()
    scenario_path(name)  (embedded scenarios: "default", "random_dynamics", "tactical",
    "tightly_coupled")
"""

import os

from gmis.simulate.run import SimulationResult, SimulationTruth, simulate_scenario
from gmis.simulate.scenario import default_scenario_path, load_scenario, validate_scenario


def scenario_path(name):
    """Path of an embedded scenario TOML in gmis/scenarios/ by name (without .toml)."""
    return os.path.join(os.path.dirname(default_scenario_path()), f"{name}.toml")


__all__ = [
    "SimulationResult",
    "SimulationTruth",
    "default_scenario_path",
    "load_scenario",
    "scenario_path",
    "simulate_scenario",
    "validate_scenario",
]
