"""Compare two `gmis run` / `gmis vce` results folders file by file.

    python benchmarks/compare_outputs.py REF_FOLDER NEW_FOLDER [--tol 1e-9]

Every .npz array (same names, shapes, NaN patterns, largest absolute difference), every
.csv / .pos as numbers (text columns must match exactly), summary.json recursively
(numbers within --tol, timing_s and results_dir ignored) and every other file byte for
byte. Prints one line per file; exit 1 when a file is missing or differs above --tol.
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np

IGNORED_KEYS = {"timing_s", "wall_time_s", "results_dir", "recipe"}   # recipe: the checkout's path


def _array_diff(a, b):
    """(worst |a − b|, problem or None) of two arrays."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        return np.inf, f"shape {a.shape} vs {b.shape}"
    if a.dtype.kind in "US" or b.dtype.kind in "US":
        return (0.0, None) if np.array_equal(a, b) else (np.inf, "text differs")
    a, b = a.astype(float), b.astype(float)
    na, nb = np.isnan(a), np.isnan(b)
    if not np.array_equal(na, nb):
        return np.inf, f"NaN pattern differs ({int((na != nb).sum())} entries)"
    d = np.abs(a[~na] - b[~nb])
    return (float(d.max()) if d.size else 0.0), None


def _json_diff(a, b, path=""):
    """Largest numeric difference and the first structural problem of two JSON values."""
    if isinstance(a, dict) and isinstance(b, dict):
        worst, problem = 0.0, None
        for k in sorted(set(a) | set(b)):
            if k in IGNORED_KEYS:
                continue
            if k not in a or k not in b:
                return np.inf, f"{path}/{k} missing"
            w, p = _json_diff(a[k], b[k], f"{path}/{k}")
            worst, problem = max(worst, w), problem or p
        return worst, problem
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return np.inf, f"{path} length {len(a)} vs {len(b)}"
        worst, problem = 0.0, None
        for i, (x, y) in enumerate(zip(a, b)):
            w, p = _json_diff(x, y, f"{path}[{i}]")
            worst, problem = max(worst, w), problem or p
        return worst, problem
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and \
            not isinstance(a, bool):
        return abs(float(a) - float(b)), None
    return (0.0, None) if a == b else (np.inf, f"{path}: {a!r} vs {b!r}")


def _table(path: Path):
    lines = path.read_text().splitlines()
    return [ln.replace(",", " ").split() for ln in lines if ln and not ln.startswith("%")]


def _text_diff(a: Path, b: Path):
    ra, rb = _table(a), _table(b)
    if len(ra) != len(rb):
        return np.inf, f"{len(ra)} vs {len(rb)} rows"
    worst = 0.0
    for x, y in zip(ra, rb):
        if len(x) != len(y):
            return np.inf, "row length differs"
        for u, v in zip(x, y):
            if u == v:
                continue
            try:
                worst = max(worst, abs(float(u) - float(v)))
            except ValueError:
                return np.inf, f"{u!r} vs {v!r}"
    return worst, None


def compare(ref: Path, new: Path, tol: float) -> bool:
    ok = True
    names = sorted({p.relative_to(ref) for p in ref.rglob("*") if p.is_file()}
                   | {p.relative_to(new) for p in new.rglob("*") if p.is_file()})
    for rel in names:
        a, b = ref / rel, new / rel
        if not a.exists() or not b.exists():
            print(f"{rel}: missing in {'new' if a.exists() else 'reference'}")
            ok = False
            continue
        if a.suffix == ".npz":
            za, zb = np.load(a), np.load(b)
            if sorted(za.files) != sorted(zb.files):
                worst, problem = np.inf, f"members {sorted(za.files)} vs {sorted(zb.files)}"
            else:
                worst, problem = 0.0, None
                for k in za.files:
                    w, p = _array_diff(za[k], zb[k])
                    worst, problem = max(worst, w), problem or (p and f"{k}: {p}")
        elif a.suffix == ".json":
            worst, problem = _json_diff(json.loads(a.read_text()), json.loads(b.read_text()))
        elif a.suffix in (".csv", ".pos"):
            worst, problem = _text_diff(a, b)
        else:
            same = a.read_bytes() == b.read_bytes()
            worst, problem = (0.0, None) if same else (np.inf, "bytes differ")
        flag = "identical" if worst == 0 and problem is None else \
            ("ok" if worst <= tol and problem is None else "DIFFERS")
        print(f"{rel!s:28s} max |diff| {worst:.3e}  {flag}{'  ' + problem if problem else ''}")
        ok &= flag != "DIFFERS"
    return ok


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("ref", type=Path)
    ap.add_argument("new", type=Path)
    ap.add_argument("--tol", type=float, default=1e-9)
    args = ap.parse_args()
    ok = compare(args.ref, args.new, args.tol)
    print("folders equal within tolerance" if ok else "folders DIFFER")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
