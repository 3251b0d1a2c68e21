"""IMU samples on disk (docs/DESIGN.md "Bounded memory"): the converted (N, 6) rows
[gyro rad/s, accel m/s², body RFU] of a run in one raw float64 file, read by row range.

A streamed `gmis run` / `gmis vce` reads the IMU file block by block into such a file
(gmis.readers.read_imu(..., on_disk=True)) and holds only the time tags (8 bytes per
sample): the filter reads the rows of each chunk of epochs (gmis.run_filter.GmikfRunner),
the preparation reads the rows it looks at (the static window, the first-motion scan, the
plausibility checks' windows). :class:`SpooledColumns` stands in for ``ImuData.gyro`` /
``.accel``: indexing by a slice, a boolean mask, an integer array or an int (with a column
as second key) reads only the rows concerned, through a one-block cache; anything else
(``np.asarray``) reads the whole columns — correct, but not bounded.

The file is a temporary one, removed when the spool is garbage-collected or at exit.
"""

from __future__ import annotations

import shutil
import tempfile
import weakref
from pathlib import Path

import numpy as np

CACHE_ROWS = 1 << 15      # rows read at once for small slices (one block cached)


class ImuSpool:
    """(N, 6) float64 rows in a raw file; :meth:`append` in order, then :meth:`rows`."""

    def __init__(self, folder=None):
        self._dir = Path(tempfile.mkdtemp(prefix="gmis-imu-", dir=folder))
        self.path = self._dir / "imu.bin"
        self._fh = open(self.path, "wb")  # noqa: SIM115 - closed in finish()
        self.n = 0
        self._cache = (0, np.empty((0, 6)))
        self._finalizer = weakref.finalize(self, shutil.rmtree, str(self._dir), True)

    def append(self, block) -> None:
        a = np.ascontiguousarray(block, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != 6:
            raise ValueError(f"ImuSpool.append: shape {a.shape}, expected (k, 6)")
        self._fh.write(a.data)
        self.n += a.shape[0]

    def finish(self) -> ImuSpool:
        if self._fh is not None:
            self._fh.close()
            self._fh = None
        return self

    def remove(self) -> None:
        self.finish()
        self._finalizer()

    @property
    def shape(self):
        return (self.n, 6)

    def __len__(self):
        return self.n

    def rows(self, a: int, b: int) -> np.ndarray:
        """Rows [a, b) (clipped to [0, N)): a fresh C-contiguous (b − a, 6) array."""
        b = min(max(int(b), 0), self.n)
        a = min(max(int(a), 0), b)
        c0, cached = self._cache
        if c0 <= a and b <= c0 + cached.shape[0]:
            return cached[a - c0:b - c0].copy()
        if b - a < CACHE_ROWS:            # small reads: one block around them, kept
            lo = a
            hi = min(self.n, max(b, lo + CACHE_ROWS))
            block = self._read(lo, hi)
            self._cache = (lo, block)
            return block[a - lo:b - lo].copy()
        return self._read(a, b)

    def _read(self, a: int, b: int) -> np.ndarray:
        with open(self.path, "rb") as fh:
            fh.seek(a * 48)
            out = np.fromfile(fh, dtype=np.float64, count=(b - a) * 6)
        return out.reshape(b - a, 6)

    def __array__(self, dtype=None, copy=None):
        whole = self._read(0, self.n)
        return whole if dtype is None else whole.astype(dtype, copy=False)

    def columns(self, first: int) -> SpooledColumns:
        return SpooledColumns(self, first)


class SpooledColumns:
    """``ImuData.gyro`` (first = 0) or ``.accel`` (first = 3) of an ImuSpool: (N, 3)."""

    ndim = 2
    dtype = np.dtype(np.float64)

    def __init__(self, spool: ImuSpool, first: int):
        self.spool, self.first = spool, int(first)

    @property
    def shape(self):
        return (self.spool.n, 3)

    @property
    def size(self):
        return self.spool.n * 3

    def __len__(self):
        return self.spool.n

    def _rows(self, a, b):
        return self.spool.rows(a, b)[:, self.first:self.first + 3]

    def __getitem__(self, key):
        rows, cols = key if isinstance(key, tuple) else (key, slice(None))
        n = self.spool.n
        if isinstance(rows, slice):
            start, stop, step = rows.indices(n)
            if step == 1:
                out = self._rows(start, max(start, stop))
            else:
                out = np.asarray(self)[rows]
        elif isinstance(rows, (int, np.integer)):
            k = int(rows) + (n if rows < 0 else 0)
            if not 0 <= k < n:
                raise IndexError(f"row {rows} out of range for {n} IMU samples")
            out = self._rows(k, k + 1)[0]
            return out[cols].copy() if not np.isscalar(out[cols]) else out[cols]
        else:
            sel = np.asarray(rows)
            if sel.dtype == bool:
                if sel.shape != (n,):
                    raise IndexError(f"boolean index of shape {sel.shape}, expected ({n},)")
                nz = np.flatnonzero(sel)
                if nz.size == 0:
                    out = np.empty((0, 3))
                else:
                    lo, hi = int(nz[0]), int(nz[-1]) + 1
                    out = self._rows(lo, hi)[sel[lo:hi]]
            else:
                sel = np.where(sel < 0, sel + n, sel).astype(np.int64)
                if sel.size == 0:
                    out = np.empty((0, 3))
                else:
                    lo, hi = int(sel.min()), int(sel.max()) + 1
                    out = self._rows(lo, hi)[sel - lo]
        return np.ascontiguousarray(out[:, cols])

    def __array__(self, dtype=None, copy=None):
        whole = np.ascontiguousarray(np.asarray(self.spool)[:, self.first:self.first + 3])
        return whole if dtype is None else whole.astype(dtype, copy=False)


def spool_array(z) -> ImuSpool:
    """An ImuSpool holding the (N, 6) array z (written in blocks)."""
    spool = ImuSpool()
    for a in range(0, z.shape[0], 1 << 16):
        spool.append(z[a:a + (1 << 16)])
    return spool.finish()


__all__ = ["ImuSpool", "SpooledColumns", "spool_array"]
