"""Reading the results folders of `gmis run` and `gmis vce` for the report.

Which folders a report covers (:func:`locate_results`):

* ``results_dir`` holds ``solution.npz`` + ``records.npz`` → a `gmis run` folder;
* ``results_dir`` holds ``vce_history.csv`` → a `gmis vce` folder;
* both sets of files in one folder → both parts;
* neither → its immediate sub-folders are classified the same way (e.g. ``run/`` and
  ``vce/`` below one parent); at most one run and one vce folder may be found there;
* ``vce_dir`` given explicitly (CLI ``--vce``) adds/overrides the VCE part.

Every file a producer always writes must be present and readable; otherwise one
:class:`~gmis.errors.GmisInputError` names the file (and key) and the problem.
Units are those of the files: SI and radians in the .npz files, degrees in the CSV files.
"""

from __future__ import annotations

import csv
import json
import math
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gmis.errors import GmisInputError

RUN_FILES = ("solution.npz", "records.npz", "summary.json")
VCE_FILES = ("vce_history.csv", "residuals_first.npz", "residuals_final.npz",
             "windows_final.npz", "summary.json")
SOLUTION_KEYS = ("t", "enu", "enu_sd", "vel_enu", "vel_enu_sd", "euler", "euler_sd", "x",
                 "sd", "state_names")
RECORD_KEYS = ("t", "innov", "innov_var", "rejected", "slot_names")
ERROR_COLUMNS = ("time_gps_s", "de_m", "dn_m", "du_m", "dve_m_s", "dvn_m_s", "dvu_m_s",
                 "dpitch_deg", "droll_deg", "dheading_deg")
HISTORY_NUMERIC = ("iteration", "sigma", "mean_redundancy", "sum_redundancy", "sigma0_sq",
                   "sigma0_sq_simplified", "observations", "blunders", "next_sigma",
                   "f_statistic", "f_critical")
HISTORY_COLUMNS = HISTORY_NUMERIC + ("component", "unit", "status", "f_test")


@dataclass
class RunData:
    """A `gmis run` folder: per-epoch solution (SI/rad), records and summary."""
    folder: Path
    solution: dict
    records: dict
    summary: dict
    errors: dict | None = None     # errors.csv columns (m, m/s, deg), None without reference
    tc: dict | None = None         # tc_records.npz of a tightly coupled run
    forward: dict | None = None    # solution_forward.npz of a smoothed run (gmis.smoothed_run)
    errors_forward: dict | None = None   # errors_forward.csv of a smoothed run


@dataclass
class VceData:
    """A `gmis vce` folder: iteration history, standardized residuals, windows, summary."""
    folder: Path
    history: list                  # rows of vce_history.csv (numbers as float)
    components: list               # component names in file order
    residuals_first: dict          # component → (t, w) full rate
    residuals_final: dict
    windows_final: dict            # component → (t, sigma0_sq, r)
    summary: dict = field(default_factory=dict)


def _require_folder(path: Path) -> Path:
    path = Path(path).expanduser()
    if not path.exists():
        raise GmisInputError("results folder not found (run `gmis run` or `gmis vce` first)",
                             source=str(path))
    if not path.is_dir():
        raise GmisInputError("not a folder; give the results folder of `gmis run` or "
                             "`gmis vce`", source=str(path))
    return path


def _kind(folder: Path) -> set:
    kinds = set()
    if (folder / "solution.npz").is_file() or (folder / "records.npz").is_file():
        kinds.add("run")
    if (folder / "vce_history.csv").is_file():
        kinds.add("vce")
    return kinds


def locate_results(results_dir, vce_dir=None) -> tuple[Path | None, Path | None]:
    """(run folder or None, vce folder or None) for a report; rules in the module doc."""
    root = _require_folder(results_dir)
    kinds = _kind(root)
    run = root if "run" in kinds else None
    vce = root if "vce" in kinds else None
    if not kinds:
        found = {"run": [], "vce": []}
        for sub in sorted(p for p in root.iterdir() if p.is_dir()
                          and not p.name.startswith(".")):
            for k in _kind(sub):
                found[k].append(sub)
        for k, subs in found.items():
            if len(subs) > 1:
                names = ", ".join(s.name for s in subs)
                raise GmisInputError(f"several `gmis {k}` folders inside ({names}); give one "
                                     "of them (and --vce for the VCE folder)",
                                     source=str(root))
        run = found["run"][0] if found["run"] else None
        vce = found["vce"][0] if found["vce"] else None
    if vce_dir is not None:
        vce = _require_folder(vce_dir)
        if "vce" not in _kind(vce):
            raise GmisInputError("vce_history.csv not found: not a `gmis vce` results folder",
                                 source=str(vce))
    if run is None and vce is None:
        raise GmisInputError("no `gmis run` files (solution.npz, records.npz) and no `gmis vce` "
                             "files (vce_history.csv) here or in a sub-folder", source=str(root))
    return run, vce


def _missing(folder: Path, names) -> None:
    absent = [n for n in names if not (folder / n).is_file()]
    if absent:
        raise GmisInputError(f"incomplete results folder: {', '.join(absent)} missing",
                             source=str(folder))


def _load_npz(path: Path, keys=()) -> dict:
    """All arrays of an .npz (loaded), checking that ``keys`` are present."""
    try:
        with np.load(path, allow_pickle=False) as data:
            absent = [k for k in keys if k not in data.files]
            if absent:
                raise GmisInputError(f"key(s) {', '.join(absent)} missing", source=str(path))
            return {k: data[k] for k in data.files}
    except GmisInputError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise GmisInputError(f"cannot read as .npz ({exc})", source=str(path)) from None


def _load_json(path: Path) -> dict:
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise GmisInputError(f"cannot read as JSON ({exc})", source=str(path)) from None
    if not isinstance(obj, dict):
        raise GmisInputError("expected a JSON object", source=str(path))
    return obj


def _check_rows(path: Path, arrays: dict, keys, rows: int) -> None:
    for k in keys:
        if arrays[k].shape[:1] != (rows,):
            raise GmisInputError(f"key {k}: {arrays[k].shape[0] if arrays[k].ndim else 0} "
                                 f"rows, expected {rows} (as 't')", source=str(path))


def load_errors_csv(path: Path) -> dict:
    """errors.csv → {column: (K,) array}."""
    try:
        with open(path, encoding="utf-8") as fh:
            header = fh.readline().strip().split(",")
        table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise GmisInputError(f"cannot read as CSV ({exc})", source=str(path)) from None
    absent = [c for c in ERROR_COLUMNS if c not in header]
    if absent:
        raise GmisInputError(f"column(s) {', '.join(absent)} missing", source=str(path))
    if table.shape[1] != len(header):
        raise GmisInputError(f"{len(header)} header names for {table.shape[1]} columns",
                             source=str(path))
    return {name: table[:, i] for i, name in enumerate(header)}


def load_run(folder) -> RunData:
    """Read a `gmis run` folder (solution.npz, records.npz, summary.json, errors.csv)."""
    folder = _require_folder(folder)
    _missing(folder, RUN_FILES)
    sol = _load_npz(folder / "solution.npz", SOLUTION_KEYS)
    rec = _load_npz(folder / "records.npz", RECORD_KEYS)
    n = sol["t"].shape[0]
    if n < 2:
        raise GmisInputError("fewer than 2 epochs", source=str(folder / "solution.npz"))
    _check_rows(folder / "solution.npz", sol, SOLUTION_KEYS[1:-1], n)
    forward = errors_forward = None
    if (folder / "solution_forward.npz").is_file():   # smoothed run: records are forward's
        forward = _load_npz(folder / "solution_forward.npz", SOLUTION_KEYS)
        _check_rows(folder / "solution_forward.npz", forward, SOLUTION_KEYS[1:-1],
                    forward["t"].shape[0])
        if (folder / "errors_forward.csv").is_file():
            errors_forward = load_errors_csv(folder / "errors_forward.csv")
    _check_rows(folder / "records.npz", rec, RECORD_KEYS[:-1],
                n if forward is None else forward["t"].shape[0])
    slots = rec["slot_names"].shape[0]
    for k in ("innov", "innov_var", "rejected"):
        if rec[k].ndim != 2 or rec[k].shape[1] != slots:
            raise GmisInputError(f"key {k}: shape {rec[k].shape}, expected ({n}, {slots})",
                                 source=str(folder / "records.npz"))
    if sol["x"].shape[1] < 21:
        raise GmisInputError(f"key x: {sol['x'].shape[1]} states, expected 21 or 27",
                             source=str(folder / "solution.npz"))
    errors = None
    if (folder / "errors.csv").is_file():
        errors = load_errors_csv(folder / "errors.csv")
    tc = None
    if (folder / "tc_records.npz").is_file():
        tc = _load_npz(folder / "tc_records.npz",
                       ("t", "n_sat", "fixed", "ratio", "dd_residual_std",
                        "dd_residual_group", "dd_residual_prn"))
    return RunData(folder, sol, rec, _load_json(folder / "summary.json"), errors, tc,
                   forward, errors_forward)


def _number(text: str, path: Path, line: int, column: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise GmisInputError(f"line {line}, column {column}: {text!r} is not a number",
                             source=str(path)) from None


def load_history(path: Path) -> list:
    """vce_history.csv → list of dict rows (numeric columns as float)."""
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            reader = csv.DictReader(fh)
            header = reader.fieldnames or []
            absent = [c for c in HISTORY_COLUMNS if c not in header]
            if absent:
                raise GmisInputError(f"column(s) {', '.join(absent)} missing", source=str(path))
            rows = []
            for i, raw in enumerate(reader, start=2):
                row = dict(raw)
                for c in HISTORY_NUMERIC:
                    row[c] = _number(raw[c] or "", path, i, c)
                rows.append(row)
    except (OSError, UnicodeDecodeError) as exc:
        raise GmisInputError(f"cannot read ({exc})", source=str(path)) from None
    if not rows:
        raise GmisInputError("no iterations recorded", source=str(path))
    return rows


def _pairs(path: Path, arrays: dict, suffixes) -> dict:
    """{component: tuple of arrays} from keys '<component>__<suffix>'."""
    names = []
    for key in arrays:
        name, sep, suffix = key.rpartition("__")
        if not sep or suffix not in suffixes:
            raise GmisInputError(f"key {key!r}: expected '<component>__{suffixes[0]}' "
                                 f"style keys ({', '.join(suffixes)})", source=str(path))
        if name not in names:
            names.append(name)
    out = {}
    for name in names:
        parts = []
        for s in suffixes:
            key = f"{name}__{s}"
            if key not in arrays:
                raise GmisInputError(f"key {key} missing", source=str(path))
            parts.append(np.asarray(arrays[key], dtype=float).ravel())
        if len({p.size for p in parts}) != 1:
            raise GmisInputError(f"component {name}: arrays of different lengths",
                                 source=str(path))
        out[name] = tuple(parts)
    return out


def load_vce(folder) -> VceData:
    """Read a `gmis vce` folder."""
    folder = _require_folder(folder)
    _missing(folder, VCE_FILES)
    history = load_history(folder / "vce_history.csv")
    components = list(dict.fromkeys(r["component"] for r in history))
    res = {}
    for label in ("first", "final"):
        path = folder / f"residuals_{label}.npz"
        res[label] = _pairs(path, _load_npz(path), ("t", "w"))
    path = folder / "windows_final.npz"
    windows = _pairs(path, _load_npz(path), ("t", "sigma0_sq", "r"))
    summary = _load_json(folder / "summary.json")
    for key in ("tol", "min_redundancy"):
        v = summary.get(key)
        if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v)):
            raise GmisInputError(f"key {key}: expected a number, got {v!r}",
                                 source=str(folder / "summary.json"))
    return VceData(folder, history, components, res["first"], res["final"], windows, summary)
