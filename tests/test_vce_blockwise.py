"""vce.blockwise: the VCE estimates of spooled records, reduced block by block, equal the
whole-array forms of vce.estimate bit for bit (docs/DESIGN.md "Bounded memory")."""

from types import SimpleNamespace

import numpy as np
import pytest

from gmis.gmikf import N_SLOTS
from gmis.record_spool import ColumnSpool
from vce import blockwise
from vce.estimate import (
    _sliding_window_sigma0,
    _standardized_residuals,
    estimate_component,
)
from vce.spooled_records import SpooledRecords, spool_component_residuals


def _wide(rng, shape):
    return rng.standard_normal(shape) * 10.0 ** rng.uniform(-6, 6, shape)


@pytest.mark.parametrize("n", [0, 1, 7, 8, 127, 128, 129, 1000, 4099, 70_001])
@pytest.mark.parametrize("leaf", [128, 200, 1 << 16])
def test_pairwise_sum_equals_numpy(n, leaf):
    rng = np.random.default_rng(n + leaf)
    a = _wide(rng, n)
    acc = blockwise.PairwiseSum(n, leaf)
    cuts = np.sort(rng.integers(0, n + 1, 6)) if n else np.zeros(0, int)
    for lo, hi in zip([0, *cuts], [*cuts, n]):
        acc.add(lo, a[lo:hi])
    assert acc.result() == a.sum()


@pytest.mark.parametrize("rows,cols", [(1, 3), (5, 2), (3001, 3), (40_000, 3), (9, 1)])
def test_column_major_sum_equals_numpy(rows, cols):
    rng = np.random.default_rng(rows)
    a = np.asfortranarray(_wide(rng, (rows, cols)))
    acc = blockwise.ColumnMajorSum(rows, cols, leaf=256)
    for e0, e1 in blockwise.row_blocks(rows, 333):
        acc.add(e0, a[e0:e1])
    assert acc.result() == a.sum()
    # the column-major order matters: the C-order sum of the same numbers differs
    if rows > 1000:
        b = np.asfortranarray(rng.standard_normal((rows, cols)))
        assert np.ascontiguousarray(b).sum() != b.sum()


def test_row_blocks_never_leave_a_single_row():
    for n in range(40):
        for block in (2, 3, 5, 8):
            got = list(blockwise.row_blocks(n, block))
            assert [e0 for e0, _ in got] == sorted({e0 for e0, _ in got})
            assert sum(e1 - e0 for e0, e1 in got) == n
            assert all(e1 - e0 >= 2 for e0, e1 in got) or n == 1


def _records(tmp_path, rng, n, slots, axes):
    """Random records with absent rows (NaN), rejections, r_w = 0 and a spool of them."""
    vz = _wide(rng, (n, N_SLOTS))
    rz = rng.uniform(0.0, 1.0, (n, N_SLOTS))
    rz[rng.random((n, N_SLOTS)) < 0.4] = np.nan
    rvar = rng.uniform(1e-4, 1.0, (n, N_SLOTS))
    rejected = (rng.random((n, N_SLOTS)) < 0.01).astype(np.int8)
    vw, rw = _wide(rng, (n, 9)), rng.uniform(0.0, 1.0, (n, 9))
    rw[rng.random((n, 9)) < 0.1] = 0.0
    t = 345600.0 + np.cumsum(rng.uniform(0.005, 0.015, n))
    still = rng.random(n) < 0.2
    whole = SimpleNamespace(vz=vz, rz=rz, rvar=rvar, rejected=rejected, vw=vw, rw=rw, t=t,
                            still=still, helmert_trunc=rng.uniform(0, 5, N_SLOTS + 10))
    cols = {f"{k}_{i}": ((), dt) for k, dt in (("vz", float), ("rz", float),
                                               ("rvar", float), ("rejected", np.int8))
            for i in slots}
    cols.update({f"{k}_{i}": ((), float) for k in ("vw", "rw") for i in axes})
    spool = ColumnSpool(tmp_path / "spool", n, cols)
    for e0 in range(0, n, 1000):
        blocks = {f"{k}_{i}": getattr(whole, k)[e0:e0 + 1000, i] for k in
                  ("vz", "rz", "rvar", "rejected") for i in slots}
        blocks.update({f"{k}_{i}": getattr(whole, k)[e0:e0 + 1000, i] for k in ("vw", "rw")
                       for i in axes})
        spool.append(**blocks)
    spool.close()
    spooled = SpooledRecords(spool, t, still, None, None, whole.helmert_trunc)
    return whole, spooled


def test_component_estimates_equal_the_whole_arrays(tmp_path, monkeypatch):
    """Blocks of 777 epochs, summation leaves of 256 elements: every estimate, window
    and residual of 20,000 random epochs equals vce.estimate's whole-array value."""
    monkeypatch.setattr(blockwise, "BLOCK_ROWS", 777)
    monkeypatch.setattr(blockwise, "LEAF", 256)
    rng = np.random.default_rng(18)
    comps = [SimpleNamespace(name="gyro", kind="measurement", index=(0, 1, 2),
                             dynamics=False),
             SimpleNamespace(name="pos", kind="measurement", index=(6,), dynamics=False),
             SimpleNamespace(name="jerk", kind="process", index=(0, 1, 2), dynamics=True),
             SimpleNamespace(name="drift", kind="process", index=(6, 7), dynamics=False)]
    whole, spooled = _records(tmp_path, rng, 20_000, [0, 1, 2, 6], [0, 1, 2, 6, 7])
    q_var = rng.uniform(0.1, 2.0, 9)
    for c in comps:
        for alpha in (0.0, 1e-3):
            a = blockwise.estimate(spooled, c, q_var, whole.still, window_s=13.0,
                                   outlier_alpha=alpha)
            b = estimate_component(whole, c, q_var, whole.still, window_s=13.0,
                                   outlier_alpha=alpha)
            assert a == b or (np.isnan(a.f_fail_t) and np.isnan(b.f_fail_t) and
                              a.__dict__ | {"f_fail_t": 0} == b.__dict__ | {"f_fail_t": 0})
        got = blockwise.sliding_window(spooled, c, q_var, 17.0, whole.still)
        want = _sliding_window_sigma0(whole, c, q_var, 17.0, whole.still)
        for x, y in zip(got, want):
            np.testing.assert_array_equal(x, y)
    res = spool_component_residuals(spooled, comps, q_var, whole.still, None,
                                    tmp_path, "final")
    for c in comps:
        t, w = _standardized_residuals(whole, c, q_var, whole.still)
        ts, ws = res[c.name]
        np.testing.assert_array_equal(ts, t)
        np.testing.assert_array_equal(ws, w)
        path_t = res[c.name].paths[0]
        np.save(tmp_path / "ref.npy", t)
        assert path_t.read_bytes() == (tmp_path / "ref.npy").read_bytes()
