"""The VCE estimates of a spooled run computed block by block (docs/DESIGN.md "Bounded
memory"): the same numbers, bit for bit, as vce.estimate's whole-array forms, with memory
independent of the run's length.

vce.estimate builds, per component, (E, k) arrays of vᵀPv terms and redundancies over the
whole run (E epochs, k slots or axes: ~200 bytes per epoch for a 3-axis IMU component) and
reduces them. Here the spooled columns (vce.spooled_records) are read in blocks of
BLOCK_ROWS epochs and every reduction is carried across blocks so that it returns the
bits of the whole-array one:

- ``a.sum()`` of a float64 array is numpy's pairwise summation over the array in memory
  order (F order: the (E, k) arrays are column-major, as SpooledRecords hands them out).
  :class:`PairwiseSum` rebuilds that summation tree for the known length E·k: every
  subtree of at most LEAF elements is one ``np.add.reduce`` of a contiguous buffer (numpy
  runs the same recursion inside it), the levels above are added in the tree's order at
  the end. It holds one partly filled leaf per column, plus the leaves that straddle two
  columns (filled at the end of one column and the start of the next).
- ``np.cumsum`` is sequential: carried from block to block.
- ``np.bincount(k, w)`` adds the weights in order into their bins: ``np.add.at`` on the
  carried totals does the same additions.
- per-row reductions (``vpv[rows].sum(axis=1)``) and elementwise terms use the same
  expressions on blocks of the same memory layout; a block never has a single row (a
  one-row block would be contiguous in both orders and numpy could reduce it otherwise).
- boolean selections (the standardized residuals) run in row order: blocks concatenated.

The estimate needs Σr before the vᵀPv terms (they are divided by the truncation factor
κ_i(Σr)): two passes over the spooled columns.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import stats

from vce.estimate import (
    ComponentEstimate,
    _standardized_of,
    _terms_of,
    component_truncation_factor,
    estimate_component,
    sliding_window_sigma0,
)

BLOCK_ROWS = 1 << 16      # epochs per block read back from the spool
LEAF = 1 << 16            # elements of the largest summation subtree buffered whole


def row_blocks(n: int, block: int | None = None):
    """[e0, e1) blocks covering range(n), none of a single row (unless n == 1)."""
    block = max(2, int(block or BLOCK_ROWS))
    e0 = 0
    while e0 < n:
        e1 = min(n, e0 + block)
        if n - e1 == 1:               # do not leave a one-row block behind
            e1 = n
        yield e0, e1
        e0 = e1


def _pairwise_leaves(n: int, leaf: int):
    """The subtrees of numpy's pairwise summation of n elements (numpy's
    pairwise_sum: a node of more than 128 elements splits at n2 = n/2 rounded down to a
    multiple of 8) that hold at most `leaf` elements: [(start, size)] in order."""
    out = []
    stack = [(0, n)]
    while stack:
        lo, size = stack.pop()
        if size <= leaf:
            out.append((lo, size))
            continue
        n2 = size // 2
        n2 -= n2 % 8
        stack.append((lo + n2, size - n2))
        stack.append((lo, n2))
    return out


class PairwiseSum:
    """``np.add.reduce`` of a float64 array of n elements that arrives in pieces
    (``add(pos, values)``: values are the elements pos, pos+1, ... of the array), with the
    bits of the whole-array sum (module docstring). leaf ≥ 128."""

    def __init__(self, n: int, leaf: int | None = None):
        leaf = int(leaf or LEAF)
        if leaf < 128:
            raise ValueError("leaf must be >= 128 (numpy's unrolled block)")
        self.n, self.leaf = int(n), leaf
        leaves = _pairwise_leaves(self.n, leaf) if self.n else []
        self.starts = np.array([a for a, _ in leaves], dtype=np.int64)
        self.sizes = np.array([s for _, s in leaves], dtype=np.int64)
        self.values = np.zeros(len(leaves))
        self.buffers = {}             # leaf index → (buffer, elements filled)

    def add(self, pos: int, values) -> None:
        values = np.asarray(values, dtype=np.float64).ravel()
        pos, m, done = int(pos), values.size, 0
        if pos < 0 or pos + m > self.n:
            raise ValueError(f"PairwiseSum.add: [{pos}, {pos + m}) outside [0, {self.n})")
        while done < m:
            i = int(np.searchsorted(self.starts, pos + done, side="right")) - 1
            start, size = int(self.starts[i]), int(self.sizes[i])
            off = pos + done - start
            take = min(size - off, m - done)
            if off == 0 and take == size:      # a whole leaf in one piece
                self.values[i] = np.add.reduce(values[done:done + take])
            else:
                buf, filled = self.buffers.get(i, (None, 0))
                if buf is None:
                    buf = np.empty(size)
                buf[off:off + take] = values[done:done + take]
                filled += take
                if filled == size:
                    self.values[i] = np.add.reduce(buf)
                    self.buffers.pop(i, None)
                else:
                    self.buffers[i] = (buf, filled)
            done += take

    def result(self) -> float:
        """The sum (every element must have been added)."""
        if self.buffers:
            raise ValueError("PairwiseSum.result: some elements were never added")
        if self.n == 0:
            return 0.0
        index = {int(a): k for k, a in enumerate(self.starts)}
        values = self.values

        def node(lo, size):
            if size <= self.leaf:
                return values[index[lo]]
            n2 = size // 2
            n2 -= n2 % 8
            return node(lo, n2) + node(lo + n2, size - n2)

        return float(node(0, self.n))


class ColumnMajorSum:
    """``a.sum()`` of a column-major (E, k) float64 array fed as row blocks (b, k)."""

    def __init__(self, n_rows: int, n_cols: int, leaf: int | None = None):
        self.rows = int(n_rows)
        self.total = PairwiseSum(self.rows * int(n_cols), leaf)

    def add(self, e0: int, block) -> None:
        for j in range(block.shape[1]):
            self.total.add(j * self.rows + e0, block[:, j])

    def result(self) -> float:
        return self.total.result()


class RegionalFScan:
    """vce.estimate.regional_f_scan fed with blocks of rows (vpv per row, r per row, t
    per row; rows in time order); first/last: the times of the first and last row, n
    their count (the first pass)."""

    def __init__(self, t_first: float, t_last: float, n: int, window_s: float,
                 f_alpha: float):
        self.n, self.f_alpha = int(n), f_alpha
        self.edges = np.arange(t_first + window_s, t_last + window_s, window_s) \
            if n >= 4 else np.zeros(0)
        m = self.edges.size
        self.k = np.zeros(m, dtype=np.int64)        # rows with t <= edge
        self.cv, self.cr, self.t_end = np.zeros(m), np.zeros(m), np.full(m, np.nan)
        self.carry = None                           # (Σ vpv, Σ r) so far (cumsum)

    def add(self, t_rows, vpv_rows, r_rows) -> None:
        if vpv_rows.size == 0 or self.edges.size == 0:
            return
        if self.carry is None:
            cv, cr = np.cumsum(vpv_rows), np.cumsum(r_rows)
        else:
            cv = np.cumsum(np.r_[self.carry[0], vpv_rows])[1:]
            cr = np.cumsum(np.r_[self.carry[1], r_rows])[1:]
        self.carry = (cv[-1], cr[-1])
        cnt = np.searchsorted(t_rows, self.edges, side="right")
        self.k += cnt
        hit = cnt > 0
        self.cv[hit], self.cr[hit] = cv[cnt[hit] - 1], cr[cnt[hit] - 1]
        self.t_end[hit] = t_rows[cnt[hit] - 1]

    def result(self):
        """(F, F_crit, pass, t_fail) as regional_f_scan."""
        if self.n < 4:
            return np.nan, np.nan, True, np.nan
        worst, t_fail = (np.nan, np.nan, True), np.nan
        ratio_worst = -np.inf
        k_prev, cv_prev, cr_prev = 0, 0.0, 0.0
        f_alpha = self.f_alpha
        for e in range(self.edges.size):
            k = int(self.k[e])
            s = k - k_prev
            c_prev = (cv_prev, cr_prev)
            k_prev, cv_prev, cr_prev = k, self.cv[e], self.cr[e]
            if s <= 0 or k - s < 1:
                continue
            r1, r2 = c_prev[1], self.cr[e] - c_prev[1]
            if not (r1 > 1 and r2 > 1):
                continue
            s1, s2 = c_prev[0] / r1, (self.cv[e] - c_prev[0]) / r2
            if not (s1 > 0 and s2 > 0):
                continue
            if s1 >= s2:
                f, crit = s1 / s2, stats.f.ppf(1 - f_alpha, r1, r2)
            else:
                f, crit = s2 / s1, stats.f.ppf(1 - f_alpha, r2, r1)
            if f > crit and np.isnan(t_fail):
                t_fail = float(self.t_end[e])
            if f / crit > ratio_worst:
                ratio_worst = f / crit
                worst = (float(f), float(crit), bool(f <= crit))
        return worst[0], worst[1], bool(np.isnan(t_fail)), t_fail


def _term_blocks(rec, comp, q_var, stationary):
    """(e0, vpv, r, used, blunders) of vce.estimate._terms per row block of rec."""
    for e0, e1 in row_blocks(rec.n_epochs):
        still = None if stationary is None else stationary[e0:e1]
        yield (e0, *_terms_of(rec.block(comp, e0, e1), comp, q_var, still))


def estimate_component_blocks(rec, comp, q_var, stationary=None, f_alpha=0.05,
                              window_s=60.0, outlier_alpha=0.0):
    """vce.estimate.estimate_component of SpooledRecords, block by block."""
    k, n_e = len(comp.index), rec.n_epochs
    sum_r = ColumnMajorSum(n_e, k)
    n = blunders = rows = 0
    t_first = t_last = np.nan
    for e0, _, r, used, bl in _term_blocks(rec, comp, q_var, stationary):
        sum_r.add(e0, r)
        n += int(used.sum())
        blunders += bl
        on = np.flatnonzero(used.any(axis=1))
        if on.size:
            rows += on.size
            if np.isnan(t_first):
                t_first = rec.t[e0 + on[0]]
            t_last = rec.t[e0 + on[-1]]
    s_r = sum_r.result()
    factor = component_truncation_factor(rec, comp, s_r, outlier_alpha)
    sum_vpv = ColumnMajorSum(n_e, k)
    scan = RegionalFScan(t_first, t_last, rows, window_s, f_alpha)
    for e0, vpv, r, used, _ in _term_blocks(rec, comp, q_var, stationary):
        vpv = vpv / factor
        sum_vpv.add(e0, vpv)
        on = np.flatnonzero(used.any(axis=1))
        scan.add(rec.t[e0:e0 + vpv.shape[0]][on], vpv[on].sum(axis=1), r[on].sum(axis=1))
    s_vpv = sum_vpv.result()
    sigma0_sq = s_vpv / s_r if s_r > 0 else np.nan
    f_stat, f_crit, f_pass, t_fail = scan.result()
    return ComponentEstimate(s_vpv, s_r, n, blunders, sigma0_sq, s_r / n if n else 0.0,
                             f_stat, f_crit, f_pass, t_fail)


def sliding_window_blocks(rec, comp, q_var, window_s=60.0, stationary=None):
    """vce.estimate._sliding_window_sigma0 of SpooledRecords, block by block."""
    t = rec.t
    edges = np.arange(t[0], t[-1] + window_s, window_s)
    s_vpv = np.zeros(max(edges.size - 1, 0))
    s_r = np.zeros_like(s_vpv)
    for e0, vpv, r, _, _ in _term_blocks(rec, comp, q_var, stationary):
        k = np.clip(np.searchsorted(edges, t[e0:e0 + vpv.shape[0]], side="right") - 1, 0,
                    edges.size - 2)
        np.add.at(s_vpv, k, vpv.sum(axis=1))     # bincount's additions, in order
        np.add.at(s_r, k, r.sum(axis=1))
    with np.errstate(invalid="ignore", divide="ignore"):
        sig = np.where(s_r > 0, s_vpv / s_r, np.nan)
    return edges[:-1] + window_s / 2, sig, s_r


def estimate(rec, comp, q_var, stationary=None, f_alpha=0.05, window_s=60.0,
             outlier_alpha=0.0):
    """vce.estimate.estimate_component of any records: spooled ones (SpooledRecords,
    which read by blocks) block by block, records in memory whole."""
    if hasattr(rec, "block"):
        return estimate_component_blocks(rec, comp, q_var, stationary, f_alpha, window_s,
                                         outlier_alpha)
    return estimate_component(rec, comp, q_var, stationary, f_alpha, window_s,
                              outlier_alpha)


def sliding_window(rec, comp, q_var, window_s=60.0, stationary=None):
    """vce.estimate.sliding_window_sigma0 of any records (as :func:`estimate`)."""
    if comp.kind != "dd" and hasattr(rec, "block"):
        return sliding_window_blocks(rec, comp, q_var, window_s, stationary)
    return sliding_window_sigma0(rec, comp, q_var, window_s, stationary)


def _npy_from_raw(raw: Path, path: Path, count: int) -> None:
    """path.npy: the float64 rows of raw (no header) under the header np.save writes."""
    from gmis.record_spool import COPY_BLOCK_BYTES, _header

    with open(path, "wb") as out, open(raw, "rb") as src:
        np.lib.format.write_array_header_1_0(out, _header((count,), np.float64))
        while chunk := src.read(COPY_BLOCK_BYTES):
            out.write(chunk)
    raw.unlink()


def standardized_residual_files(rec, comp, q_var, stationary, t_path: Path,
                                w_path: Path) -> None:
    """vce.estimate._standardized_residuals of SpooledRecords written block by block to
    t_path, w_path (.npy, the bytes np.save writes for the whole arrays)."""
    raw_t, raw_w = t_path.with_suffix(".raw"), w_path.with_suffix(".raw")
    count = 0
    with open(raw_t, "wb") as ft, open(raw_w, "wb") as fw:
        for e0, e1 in row_blocks(rec.n_epochs):
            still = None if stationary is None else stationary[e0:e1]
            t, w = _standardized_of(rec.block(comp, e0, e1), rec.t[e0:e1], comp, q_var,
                                   still)
            ft.write(np.ascontiguousarray(t, dtype=np.float64).data)
            fw.write(np.ascontiguousarray(w, dtype=np.float64).data)
            count += t.size
    _npy_from_raw(raw_t, t_path, count)
    _npy_from_raw(raw_w, w_path, count)


__all__ = ["ColumnMajorSum", "PairwiseSum", "RegionalFScan", "estimate",
           "estimate_component_blocks", "row_blocks", "sliding_window",
           "sliding_window_blocks", "standardized_residual_files"]
