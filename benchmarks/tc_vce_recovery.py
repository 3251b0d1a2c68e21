"""VCE recovery of the tightly coupled DD noise from wrong starts (the full study behind
tests/test_tc.py / test_tc_tdcp.py, which keep one start each for the suite's budget).

    python3 benchmarks/tc_vce_recovery.py [--starts 3.0 0.3]

For the Doppler run and the TDCP run of tests.tc_truth.run_tight_scenario, every DD group
(σ90 of code, L1, L2 phase, Doppler or TDCP) starts at START × the simulated value; prints
per start: converged, iterations, final/true ratio per group (pass band 0.9-1.1), CPU time.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main(argv=None):
    from gmis.pipeline import prepare_run
    from gmis.recipe import load_recipe
    from tests.tc_truth import run_tight_scenario
    from vce import tune

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=float, nargs="+", default=[3.0, 0.3])
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        runs = {}
        sim, _, _, _ = run_tight_scenario(Path(tmp) / "tc")
        runs["doppler"] = (Path(sim.recipe_path).parent / "tight.toml", "doppler", 12)
        _, _, _, tight = run_tight_scenario(Path(tmp) / "tdcp", "tight_tdcp.toml",
                                            'tc_velocity_observable = "tdcp"')
        runs["tdcp"] = (tight, "tdcp", 15)
        print("| run | start | converged | iterations | final/true per group | all in "
              "0.9-1.1 | CPU s |")
        print("|---|---|---|---|---|---|---|")
        for label, (path, velocity, max_it) in runs.items():
            recipe = load_recipe(path)
            truth = {"code": recipe.noise.code_sigma_m,
                     "phase_l1": recipe.noise.phase_l1_sigma_m,
                     "phase_l2": recipe.noise.phase_l2_sigma_m}
            truth[velocity] = (recipe.noise.doppler_sigma_m_s if velocity == "doppler"
                               else recipe.noise.tdcp_sigma_m)
            for start in args.starts:
                c0 = time.process_time()
                res = tune(prepare_run(recipe), max_iterations=max_it,
                           initial_sigma={k: v * start for k, v in truth.items()})
                cpu = time.process_time() - c0
                final = {c.name: s for c, s in zip(res.components, res.final_sigma)}
                ratios = {k: final[k] / v for k, v in truth.items()}
                ok = all(0.9 <= r <= 1.1 for r in ratios.values())
                text = ", ".join(f"{k} {r:.3f}" for k, r in ratios.items())
                print(f"| {label} | {start:g} | {res.converged} | {len(res.history)} | "
                      f"{text} | {ok} | {cpu:.0f} |")


if __name__ == "__main__":
    main()
