"""RMS, mean, maximum and percentiles of a long column read block by block (docs/DESIGN.md
"Bounded memory", issue 18): the summary of a many-hour run holds one block of its error
columns, never a whole column and its sorted copy.

``blocks`` is a callable that returns a fresh iterator over the column's values in
consecutive blocks (1-D float64 arrays, already restricted to the rows that count); the
same blocks must come back on every call (a column spooled to disk is read again).

* sums (RMS, mean) add each block's ``np.sum`` (numpy's pairwise sum inside the block) to
  a running total: a whole array and its spooled column, cut into the same blocks, give
  the same figure to the last bit;
* percentiles are exact, as ``np.percentile(values, q)`` (method "linear") gives them:
  the order statistics v_(k) and v_(k+1) around the virtual index (n − 1)·q/100 are found
  by radix selection on the IEEE-754 bit patterns (for values ≥ 0 the patterns order as
  the values do), 16 bits per pass over the blocks — at most four passes, fewer once the
  candidates fit in SELECT_LIMIT values, which are then sorted — and combined by numpy's
  own interpolation formula.
"""

from __future__ import annotations

import math

import numpy as np

SELECT_LIMIT = 1 << 16      # candidates sorted in memory once no more than this many


def block_sum(blocks, transform=None) -> tuple[float, int]:
    """(Σ over the blocks of np.sum(transform(block)), number of values)."""
    total, count = 0.0, 0
    for b in blocks():
        total += float(np.sum(b if transform is None else transform(b)))
        count += b.size
    return total, count


def _keys(block: np.ndarray) -> np.ndarray:
    """uint64 keys ordered as the values (≥ 0, +0.0 for −0.0) are."""
    return np.ascontiguousarray(block, dtype=np.float64).view(np.uint64)


def _float_of_key(key) -> float:
    return float(np.array([key], dtype=np.uint64).view(np.float64)[0])


def kth_smallest_pair(blocks, k: int, count: int) -> tuple[float, float]:
    """(v_(k), v_(k+1)), the k-th and (k+1)-th smallest (0-based; v_(k+1) = v_(k) when
    k is the last) of the count non-negative finite values given in blocks: radix
    selection on the bit patterns (module docstring)."""
    prefix, mask, shift = np.uint64(0), np.uint64(0), 64
    below, candidates = 0, count
    while candidates > SELECT_LIMIT and shift > 0:
        shift -= 16
        counts = np.zeros(1 << 16, dtype=np.int64)
        for b in blocks():
            key = _keys(b)
            if mask:
                key = key[(key & mask) == prefix]
            counts += np.bincount((key >> np.uint64(shift)).astype(np.int64) & 0xFFFF,
                                  minlength=1 << 16)
        cum = np.cumsum(counts)
        digit = int(np.searchsorted(cum, k - below, side="right"))
        below += int(cum[digit - 1]) if digit else 0
        candidates = int(counts[digit])
        prefix |= np.uint64(digit) << np.uint64(shift)
        mask |= np.uint64(0xFFFF) << np.uint64(shift)
    i = k - below
    if shift == 0:                            # every candidate has this bit pattern
        v_k = _float_of_key(prefix)
        if i + 1 < candidates or k + 1 >= count:
            return v_k, v_k
    else:
        values = np.sort(np.concatenate(
            [b[(_keys(b) & mask) == prefix] if mask else b for b in blocks()]))
        if i + 1 < values.size or k + 1 >= count:
            return float(values[i]), float(values[min(i + 1, values.size - 1)])
        v_k = float(values[i])
    top = prefix | ~mask                      # the next value lies above the candidates
    nxt = min((float(b[_keys(b) > top].min()) for b in blocks()
               if np.any(_keys(b) > top)), default=v_k)
    return v_k, nxt


def percentile_of_nonnegative(blocks, q: float, count: int) -> float:
    """np.percentile(values, q) of the count non-negative finite values in blocks."""
    virtual = (count - 1) * (q / 100.0)
    if virtual >= count - 1:                  # numpy: both neighbours are the last value
        return kth_smallest_pair(blocks, count - 1, count)[0]
    k = math.floor(virtual)
    gamma = virtual - k
    a, b = kth_smallest_pair(blocks, k, count)
    diff = b - a                              # numpy.lib._function_base_impl._lerp
    return b - diff * (1.0 - gamma) if gamma >= 0.5 else a + diff * gamma


def rms_p95_max(blocks, scale: float = 1.0) -> dict:
    """{"rms", "p95", "max"} of |value|·scale over the blocks (exact, bounded memory)."""
    def scaled_abs():
        for b in blocks():
            e = np.abs(b)
            e *= scale
            yield e

    def scaled_sq(b):
        sq = b * scale
        sq **= 2
        return sq

    total, count = block_sum(blocks, scaled_sq)
    peak = max((float(e.max()) for e in scaled_abs() if e.size), default=float("nan"))
    return {"rms": math.sqrt(total / count), "p95":
            percentile_of_nonnegative(scaled_abs, 95.0, count), "max": peak}


__all__ = ["SELECT_LIMIT", "block_sum", "kth_smallest_pair",
           "percentile_of_nonnegative", "rms_p95_max"]
