"""Writing results: all-or-nothing output folders and numpy-aware CSV/NPZ/JSON helpers.

:func:`results_directory` builds the output in a hidden sibling folder and renames it into
place only when the body succeeded, so a crash or Ctrl-C never leaves a half-written
results folder that looks complete.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import shutil
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np


@contextlib.contextmanager
def results_directory(path) -> Iterator[Path]:
    """Yield a fresh temporary folder ``.<name>.partial-<pid>`` next to ``path``; on success
    it replaces ``path`` (an existing folder there is swapped out and deleted), on any
    exception it is removed and ``path`` is left untouched."""
    final = Path(path).expanduser().resolve()
    final.parent.mkdir(parents=True, exist_ok=True)
    partial = final.parent / f".{final.name}.partial-{os.getpid()}"
    if partial.exists():
        shutil.rmtree(partial)
    partial.mkdir()
    try:
        yield partial
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    old = None
    if final.exists():
        if not final.is_dir():
            shutil.rmtree(partial, ignore_errors=True)
            raise FileExistsError(f"{final} exists and is not a folder")
        old = final.parent / f".{final.name}.old-{os.getpid()}"
        if old.exists():
            shutil.rmtree(old)
        os.replace(final, old)
    try:
        os.replace(partial, final)
    except BaseException:
        if old is not None:
            os.replace(old, final)
        shutil.rmtree(partial, ignore_errors=True)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def write_csv(path, header: Sequence[str], *columns, fmt: str = "%.10g") -> Path:
    """Write columns (each (N,) or (N,k)) side by side under a one-line header."""
    arrays = [np.asarray(c, dtype=float) for c in columns]
    arrays = [a[:, None] if a.ndim == 1 else a for a in arrays]
    rows = {a.shape[0] for a in arrays}
    if len(rows) > 1:
        raise ValueError(f"write_csv {path}: columns have different lengths {sorted(rows)}")
    table = np.hstack(arrays) if arrays else np.empty((0, 0))
    if table.shape[1] != len(header):
        raise ValueError(f"write_csv {path}: {len(header)} header names for "
                         f"{table.shape[1]} columns")
    path = Path(path)
    np.savetxt(path, table, delimiter=",", header=",".join(header), comments="", fmt=fmt)
    return path


def write_npz(path, compress: bool = False, **arrays) -> Path:
    """.npz of named arrays; uncompressed by default (zlib costs ~0.1 s per MB, several
    seconds for an hour of 100 Hz records)."""
    path = Path(path)
    save = np.savez_compressed if compress else np.savez
    save(path, **{k: np.asarray(v) for k, v in arrays.items()})
    return path


def to_jsonable(obj):
    """numpy arrays/scalars → lists/numbers, Path → str, dataclasses → dicts,
    non-finite floats → None (strict JSON has no NaN)."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return to_jsonable(obj.item())
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Path):
        return str(obj)
    if obj is None or isinstance(obj, (str, int, bool)):
        return obj
    raise TypeError(f"cannot write {type(obj).__name__} to JSON")


def write_json(path, obj, indent: int = 2) -> Path:
    path = Path(path)
    path.write_text(json.dumps(to_jsonable(obj), indent=indent, allow_nan=False) + "\n",
                    encoding="utf-8")
    return path
