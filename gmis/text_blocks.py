"""A text file read as blocks of whole lines, so that a reader's memory is one block
(a few MiB) however long the file is (docs/DESIGN.md "Bounded memory").

Every block ends at a ``\\n`` byte (the last one may not), so the blocks' ``splitlines``
put together are exactly the lines of the whole text: no line break (``\\r\\n``
included) and no UTF-8 sequence is ever cut. A byte-order mark is dropped at the start
only, as the ``utf-8-sig`` codec does. A decoding problem raises GmisInputError
"not a text file (<reason> at byte <n>)" with n counted in the file after the mark, as
``Path.read_text(encoding="utf-8-sig")`` reports it.
"""

from __future__ import annotations

import codecs
from bisect import bisect_right
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from gmis.errors import GmisInputError

BLOCK_BYTES = 4 << 20  # 4 MiB of text per block (~40 000 lines of an IMU file)
MMAP_THRESHOLD_BYTES = 1 << 20
_allocator_set = False


def _fixed_mmap_threshold() -> None:
    """glibc only: allocations of >= 1 MiB always from their own mapping (mallopt
    M_MMAP_THRESHOLD), so a freed block goes back to the system. By default glibc raises
    the threshold to the size of the last freed mapping, and the many equal blocks of
    the readers then come from the heap, where freed ones stay resident: 3 h drive,
    `gmis run` peak RSS 551 MiB by default, 513 MiB with the fixed threshold (the
    same as MALLOC_MMAP_THRESHOLD_=1048576 in the environment). Elsewhere a no-op."""
    global _allocator_set
    if _allocator_set:
        return
    _allocator_set = True
    try:
        import ctypes
        import ctypes.util

        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.mallopt(-3, MMAP_THRESHOLD_BYTES)      # -3 = M_MMAP_THRESHOLD
    except (OSError, AttributeError):
        pass


def _check_file(path: Path) -> None:
    if not path.exists():
        raise GmisInputError("file not found", source=str(path))
    if not path.is_file():
        raise GmisInputError("not a file", source=str(path))


def line_blocks(path, block_bytes: int = BLOCK_BYTES,
                byte_range: tuple[int, int] | None = None
                ) -> Iterator[tuple[list[str], int, str]]:
    """(lines, number of the first line (1-based), the block's text) per block of the
    file, in order.

    byte_range (b0, b1): only the bytes [b0, b1) of the file, both at line starts (or the
    file's end); the line numbers then count from b0 (1 = the line starting at b0) and
    decoding errors name the byte offset in the file."""
    path = Path(path)
    _check_file(path)
    _fixed_mmap_threshold()
    b0, b1 = (0, None) if byte_range is None else (int(byte_range[0]), int(byte_range[1]))
    with open(path, "rb") as fh:
        rest = b""
        decoded = 0          # bytes decoded so far (after the byte-order mark)
        first = b0 == 0
        if b0:
            bom = fh.read(len(codecs.BOM_UTF8)) == codecs.BOM_UTF8
            fh.seek(b0)
            decoded = b0 - (len(codecs.BOM_UTF8) if bom else 0)   # counted after the mark
        left = None if b1 is None else max(0, b1 - b0)
        line_no = 1
        while True:
            size = block_bytes if left is None else min(block_bytes, left)
            chunk = fh.read(size) if size else b""
            if left is not None:
                left -= len(chunk)
            data = rest + chunk
            if first:
                if len(data) < len(codecs.BOM_UTF8) and chunk:
                    rest = data
                    continue
                data = data.removeprefix(codecs.BOM_UTF8)
                first = False
            if chunk:
                cut = data.rfind(b"\n") + 1
                if cut == 0:          # no line end yet: read on
                    rest = data
                    continue
                block, rest = data[:cut], data[cut:]
            else:
                block, rest = data, b""
            if not block:
                return
            try:
                text = block.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise GmisInputError(f"not a text file ({exc.reason} at byte "
                                     f"{decoded + exc.start})", source=str(path)) from None
            decoded += len(block)
            lines = text.splitlines()
            yield lines, line_no, text
            line_no += len(lines)
            if not chunk:
                return


def count_lines_before(path, offset: int) -> int:
    """Number of lines in the bytes [0, offset) of the file (offset at a line start), as
    line_blocks numbers them (``str.splitlines``: \\r, \\f, \\x85, \\u2028 … count as
    line breaks too): the line starting at ``offset`` is this + 1. Read only when a
    message needs one."""
    return sum(len(lines) for lines, _, _ in line_blocks(path, byte_range=(0, offset)))


__all__ = ["BLOCK_BYTES", "count_lines_before", "line_blocks"]


class LineNumbers:
    """1-based file line number per data row, stored as runs of consecutive lines (one
    run per block of a file without comments inside the data): a few integers instead of
    8 bytes per row. ``numbers[row]`` → int; ``len(numbers)`` rows."""

    def __init__(self, lines_before=None):
        self._rows = []     # first row of each run
        self._lines = []    # its line number
        self.size = 0
        # the numbers added count from a line inside the file (a byte range of
        # line_blocks): lines_before() → lines before it, asked for on first use
        self._lines_before = lines_before
        self._base = None if lines_before is not None else 0

    def add_run(self, first_line: int, count: int) -> None:
        if count <= 0:
            return
        if self._rows and self._lines[-1] + (self.size - self._rows[-1]) == first_line:
            self.size += count     # continues the last run
            return
        self._rows.append(self.size)
        self._lines.append(int(first_line))
        self.size += count

    def add_lines(self, numbers) -> None:
        """Rows whose line numbers are the increasing sequence ``numbers``."""
        for n in numbers:
            self.add_run(int(n), 1)

    def __len__(self) -> int:
        return self.size

    def __getitem__(self, row) -> int:
        row = int(row)
        if row < 0:
            row += self.size
        if not 0 <= row < self.size:
            raise IndexError(f"row {row} of {self.size}")
        k = bisect_right(self._rows, row) - 1
        return self.base + self._lines[k] + row - self._rows[k]

    @property
    def base(self) -> int:
        """Lines of the file before the first line the added numbers count from."""
        if self._base is None:
            self._base = int(self._lines_before())
        return self._base

    def __array__(self, dtype=None, copy=None):
        """All row line numbers as an (N,) int64 array (materialised)."""
        out = np.empty(self.size, dtype=np.int64)
        ends = self._rows[1:] + [self.size]
        for r0, r1, line in zip(self._rows, ends, self._lines):
            out[r0:r1] = np.arange(line, line + r1 - r0)
        if self._rows:
            out += self.base
        return out if dtype is None else out.astype(dtype)

    def tolist(self) -> list[int]:
        return np.asarray(self).tolist()

    @classmethod
    def of(cls, numbers) -> LineNumbers:
        out = cls()
        numbers = np.asarray(numbers, dtype=np.int64)
        if numbers.size:
            breaks = np.flatnonzero(np.diff(numbers) != 1) + 1
            starts = np.r_[0, breaks]
            ends = np.r_[breaks, numbers.size]
            for s, e in zip(starts.tolist(), ends.tolist()):
                out.add_run(int(numbers[s]), e - s)
        return out
