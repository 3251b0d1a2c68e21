"""Save or compare the raw per-epoch records of the GMIKF and the error-state filter.

    python benchmarks/compare_records.py save OUT.npz [--dataset DIR]
    python benchmarks/compare_records.py compare REF.npz [--dataset DIR] [--tol 1e-9]

Runs, on the embedded default drive (simulated once into DIR, default
./gmis-default/dataset), the 27-state GMIKF plain (vce_mode 0), with VCE records and r_x
(vce_mode 2), the 21-state GMIKF, and the error-state INS; stores every FilterRecords /
ErrInsRecords array. ``compare`` reruns them with the code on PYTHONPATH and prints the
largest absolute difference per array (NaN patterns must match); exit 1 above --tol.
A refactor that claims "behaviour unchanged" must pass ``compare`` against a ``save``
made with the code before it.
"""

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np


def _records(dataset: Path) -> dict:
    from gmis.errins import run_errins_prepared
    from gmis.pipeline import prepare_run, run_prepared
    from gmis.recipe import load_recipe
    from gmis.simulate import default_scenario_path, simulate_scenario

    recipes = sorted(dataset.glob("*.toml"))
    if not recipes:
        simulate_scenario(default_scenario_path(), dataset, seed=None)
        recipes = sorted(dataset.glob("*.toml"))
    recipe = load_recipe(recipes[0])
    out = {}
    for states in (27, 21):
        r = dataclasses.replace(recipe, filter=dataclasses.replace(recipe.filter,
                                                                   states=states))
        prep = prepare_run(r)
        modes = (0, 2) if states == 27 else (1,)
        for mode in modes:
            rec = run_prepared(prep, dataclasses.replace(prep.config, vce_mode=mode))
            for f in dataclasses.fields(rec):
                v = getattr(rec, f.name)
                if isinstance(v, np.ndarray):
                    out[f"gmikf{states}_m{mode}.{f.name}"] = v
        if states == 27:
            erec = run_errins_prepared(prep)
            for f in dataclasses.fields(erec):
                out[f"errins.{f.name}"] = getattr(erec, f.name)
    return out


def _compare(ref: dict, new: dict, tol: float) -> bool:
    ok = True
    for key in sorted(set(ref) | set(new)):
        if key not in ref or key not in new:
            print(f"{key:32s} missing in {'new' if key in ref else 'reference'}")
            ok = False
            continue
        a = np.asarray(ref[key], float)
        b = np.asarray(new[key], float)
        if a.shape != b.shape:
            print(f"{key:32s} shape {a.shape} vs {b.shape}")
            ok = False
            continue
        nan_a, nan_b = np.isnan(a), np.isnan(b)
        if not np.array_equal(nan_a, nan_b):
            print(f"{key:32s} NaN pattern differs ({int((nan_a != nan_b).sum())} entries)")
            ok = False
            continue
        diff = np.abs(a[~nan_a] - b[~nan_b])
        worst = float(diff.max()) if diff.size else 0.0
        exact = bool(np.array_equal(a[~nan_a], b[~nan_b]))
        flag = "identical" if exact else ("ok" if worst <= tol else "DIFFERS")
        print(f"{key:32s} max |diff| {worst:.3e}  {flag}")
        ok &= worst <= tol
    return ok


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("action", choices=("save", "compare"))
    ap.add_argument("npz", type=Path)
    ap.add_argument("--dataset", type=Path, default=Path("gmis-default/dataset"))
    ap.add_argument("--tol", type=float, default=1e-9)
    args = ap.parse_args()
    new = _records(args.dataset)
    if args.action == "save":
        np.savez_compressed(args.npz, **new)
        print(f"saved {len(new)} arrays to {args.npz}")
        return 0
    ref = dict(np.load(args.npz))
    ok = _compare(ref, new, args.tol)
    print("records equal within tolerance" if ok else "records DIFFER")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
