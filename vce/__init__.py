"""Helmert variance component estimation in the GMIKF (001 §2.7.2, ch. 5).

    from vce import tune
    result = tune(load_recipe("recipe.toml"))   # TuningResult with the per-iteration history
"""

from vce.tune import TuningResult, tune

__all__ = ["TuningResult", "tune"]
