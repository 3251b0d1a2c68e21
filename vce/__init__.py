"""Helmert variance component estimation in the GMIKF (001 §2.7.2, ch. 5).

    from vce import tune, tune_recipe
    result = tune(load_recipe("recipe.toml"))   # TuningResult with the per-iteration history
    summary = tune_recipe("recipe.toml", "vce/")   # `gmis vce`: the results folder
"""

from vce.components import VarianceComponent, dd_components, gmikf_components
from vce.job import tune_recipe
from vce.tune import TuningResult, tune

__all__ = ["TuningResult", "VarianceComponent", "dd_components", "gmikf_components", "tune",
           "tune_recipe"]
