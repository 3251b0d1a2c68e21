"""Per-epoch records on disk: one ``.npy`` file per column, filled chunk by chunk.

A run knows its epoch count E before the loop starts, so every column file is created
with its final shape (E, ...) in the ``.npy`` header and the chunks are appended in epoch
order: memory holds one chunk, the file is a plain ``.npy`` (numpy only, no new
dependency) that ``np.load`` reads whole and :meth:`ColumnSpool.read` reads by epoch
range (a seek and one read, no memory map: mapped pages would count in the resident
set). The ``.npz`` outputs of a run (solution.npz, records.npz) are zip archives of such
``.npy`` members, written uncompressed as ``np.savez`` does, so :func:`write_npz_members`
assembles them from the column files by streaming copy (docs/DESIGN.md "Bounded memory").
"""

from __future__ import annotations

import shutil
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

COPY_BLOCK_BYTES = 1 << 20


def _header(shape, dtype) -> dict:
    return {"descr": np.lib.format.dtype_to_descr(np.dtype(dtype)),
            "fortran_order": False, "shape": tuple(int(s) for s in shape)}


def _append_rows(columns, files, blocks) -> int:
    """Write one block of rows to every column file (each (k, *tail), the same k);
    returns k."""
    if set(blocks) != set(columns):
        raise ValueError(f"append: columns {sorted(blocks)} != {sorted(columns)}")
    k = None
    for name, block in blocks.items():
        tail, dt = columns[name]
        a = np.ascontiguousarray(block, dtype=dt)
        if a.shape[1:] != tail or (k is not None and a.shape[0] != k):
            raise ValueError(f"append {name}: shape {a.shape}, expected (k, *{tail})")
        k = a.shape[0]
        files[name].write(a.data)
    return k or 0


def _read_rows(path, offset, tail, dt, rows, e0, e1) -> np.ndarray:
    """Rows [e0, e1) (clipped to [0, rows)) of a column file whose data start at byte
    offset: one seek and one read, a fresh array."""
    e1 = rows if e1 is None else min(int(e1), rows)
    e0 = max(0, min(int(e0), e1))
    per_row = int(np.prod(tail, dtype=np.int64)) if tail else 1
    with open(path, "rb") as fh:
        fh.seek(offset + e0 * per_row * dt.itemsize)
        a = np.fromfile(fh, dtype=dt, count=(e1 - e0) * per_row)
    return a.reshape((e1 - e0, *tail))


class ColumnSpool:
    """Column files ``<folder>/<name>.npy`` of shape (n_epochs, *tail) each, appended to
    in epoch order by :meth:`append` (all columns of a chunk at once)."""

    def __init__(self, folder, n_epochs: int, columns: dict):
        """columns: {name: (tail shape tuple, dtype)}."""
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.n_epochs = int(n_epochs)
        self.columns = {k: (tuple(tail), np.dtype(dt)) for k, (tail, dt) in columns.items()}
        self.rows = 0
        self._files = {}
        self._offset = {}
        for name, (tail, dt) in self.columns.items():
            fh = open(self.path(name), "wb")  # noqa: SIM115 - closed in close()
            np.lib.format.write_array_header_1_0(fh, _header((self.n_epochs, *tail), dt))
            self._offset[name] = fh.tell()
            self._files[name] = fh

    def path(self, name: str) -> Path:
        return self.folder / f"{name}.npy"

    def append(self, **blocks):
        """Append one chunk: every column, each (k, *tail), the same k."""
        k = _append_rows(self.columns, self._files, blocks)
        if self.rows + k > self.n_epochs:
            raise ValueError(f"spool overflow: {self.rows + k} > {self.n_epochs} epochs")
        self.rows += k

    def close(self):
        """Close the files; every column must hold all n_epochs rows."""
        for fh in self._files.values():
            fh.close()
        self._files = {}
        if self.rows != self.n_epochs:
            raise ValueError(f"spool closed after {self.rows} of {self.n_epochs} epochs")

    def read(self, name: str, e0: int = 0, e1: int | None = None) -> np.ndarray:
        """Rows [e0, e1) of a column (a fresh array; only those rows are read)."""
        return _read_rows(self.path(name), self._offset[name], *self.columns[name],
                          self.rows, e0, e1)

    def nbytes(self) -> int:
        return sum(self.path(n).stat().st_size for n in self.columns)


class GrowingColumns:
    """Column files ``<folder>/<name>.bin`` of raw rows (no header), appended in order
    while the row count is not known yet (a reference trajectory read block by block,
    gmis.readers.read_reference_blocks); :meth:`read` reads a row range as
    ColumnSpool.read does. Internal to a run: removed with its folder."""

    def __init__(self, folder, columns: dict):
        """columns: {name: (tail shape tuple, dtype)}."""
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.columns = {k: (tuple(tail), np.dtype(dt)) for k, (tail, dt) in columns.items()}
        self.rows = 0
        self._files = {name: open(self.path(name), "wb")  # noqa: SIM115 - closed in close()
                       for name in self.columns}

    def path(self, name: str) -> Path:
        return self.folder / f"{name}.bin"

    def append(self, **blocks):
        """Append rows: every column, each (k, *tail), the same k."""
        self.rows += _append_rows(self.columns, self._files, blocks)

    def close(self):
        for fh in self._files.values():
            fh.close()
        self._files = {}

    def read(self, name: str, e0: int = 0, e1: int | None = None) -> np.ndarray:
        """Rows [e0, e1) of a column (a fresh array; only those rows are read)."""
        return _read_rows(self.path(name), 0, *self.columns[name], self.rows, e0, e1)


class LazyColumns(Mapping):
    """A read-only mapping {key: spooled column} that reads the column from disk on every
    access and keeps nothing: the summary statistics take one column at a time.
    columns: {key: column name in the spool}; extra: further entries kept as given."""

    def __init__(self, spool: ColumnSpool, columns: dict, **extra):
        self.spool = spool
        self.columns = dict(columns)
        self.extra = extra

    def __getitem__(self, key):
        if key in self.columns:
            return self.spool.read(self.columns[key])
        return self.extra[key]

    @property
    def n_rows(self) -> int:
        return self.spool.rows

    def rows(self, key, j0: int, j1: int) -> np.ndarray:
        """Rows [j0, j1) of the spooled column key (only those are read)."""
        return self.spool.read(self.columns[key], j0, j1)

    def __iter__(self):
        return iter([*self.columns, *self.extra])

    def __len__(self):
        return len(self.columns) + len(self.extra)


def write_npz_members(path, members: dict) -> Path:
    """An .npz (uncompressed zip, as np.savez) whose members are either arrays or paths of
    existing .npy files (copied in blocks, never loaded whole)."""
    path = Path(path)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
        for name, value in members.items():
            # every member as np.savez writes it (zf.open: the 1980 time stamp, so the file
            # does not depend on when it was written); a column file copied in 1 MiB
            # blocks, not ZipFile.write's 8 KiB ones (~0.1 s CPU less per 64 MB)
            with zf.open(f"{name}.npy", "w", force_zip64=True) as fh:
                if isinstance(value, Path):
                    with open(value, "rb") as src:
                        shutil.copyfileobj(src, fh, COPY_BLOCK_BYTES)
                else:
                    _write_array_in_blocks(fh, np.asanyarray(value))
    return path


def _write_array_in_blocks(fh, a: np.ndarray):
    """np.lib.format.write_array's bytes (a version 1.0 header, then the data in C order)
    with the data of a C-contiguous array written as COPY_BLOCK_BYTES views: write_array
    copies 16 MiB at a time (an (E,) float64 column of 2 M epochs in one piece, beside the
    column itself). Other arrays go to write_array."""
    header = np.lib.format.header_data_from_array_1_0(a)
    if a.dtype.hasobject or not a.flags.c_contiguous or a.nbytes < COPY_BLOCK_BYTES:
        np.lib.format.write_array(fh, a, allow_pickle=False)
        return
    np.lib.format.write_array_header_1_0(fh, header)
    raw = a.reshape(-1).view(np.uint8)
    for i in range(0, raw.size, COPY_BLOCK_BYTES):
        fh.write(raw[i:i + COPY_BLOCK_BYTES].data)


__all__ = ["ColumnSpool", "GrowingColumns", "LazyColumns", "write_npz_members"]
