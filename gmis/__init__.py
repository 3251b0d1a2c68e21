"""gmis: generic multisensor integration (GMIKF) post-processing engine.

Main entry points (imported on first use, so ``import gmis`` and ``gmis --help`` stay
fast)::

    from gmis import load_recipe, run_recipe, prepare_run, run_prepared
    summary = run_recipe("recipe.toml", "results/")          # `gmis run`
    summary = run_rtk_recipe("recipe.toml", "rtk/")           # `gmis rtk`
    result = simulate_scenario("scenario.toml", "dataset/")   # `gmis simulate`
    summary = make_report("results/")                         # `gmis report`

VCE tuning (`gmis vce`) is the package ``vce`` (vce.tune, vce.tune_recipe).
"""

from gmis.lazy_exports import lazy_getattr

__version__ = "0.1.0"

_EXPORTS = {
    "GmisInputError": "gmis.errors",
    "Recipe": "gmis.recipe",
    "load_recipe": "gmis.recipe",
    "errins_config": "gmis.engine_configs",
    "gmikf_config": "gmis.engine_configs",
    "rtk_config": "gmis.engine_configs",
    "tc_config": "gmis.engine_configs",
    "PreparedRun": "gmis.run_preparation",
    "prepare_run": "gmis.run_preparation",
    "run_prepared": "gmis.run_preparation",
    "run_recipe": "gmis.pipeline",
    "run_rtk_recipe": "gmis.rtk_job",
    "simulate_scenario": "gmis.simulate",
    "make_report": "gmis.report",
}


__getattr__ = lazy_getattr(__name__, _EXPORTS)


def __dir__():
    return sorted(set(globals()) | set(_EXPORTS))


__all__ = ["GmisInputError", "PreparedRun", "Recipe", "__version__", "errins_config",
           "gmikf_config", "load_recipe", "make_report", "prepare_run", "rtk_config",
           "run_prepared", "run_recipe", "run_rtk_recipe", "simulate_scenario", "tc_config"]
assert set(__all__) == set(_EXPORTS) | {"__version__"}
