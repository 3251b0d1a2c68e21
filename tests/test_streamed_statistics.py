"""Exact statistics over blocks (gmis.streamed_statistics): the percentile equals
np.percentile to the last bit and the k-th value np.partition's, for sizes, ties, zeros
and blocks of every length, with the in-memory selection limit forced low so that the
radix passes run."""

import numpy as np
import pytest

from gmis import streamed_statistics as ss


def _blocks(values, size):
    return lambda: (values[i:i + size] for i in range(0, values.size, size))


def _cases():
    rng = np.random.default_rng(7)
    yield rng.standard_normal(1)
    yield np.array([0.0, 3.0])
    yield np.zeros(1000)
    yield np.repeat(rng.random(5), 400)                  # heavy ties
    yield np.abs(rng.standard_normal(70001)) * 1e-3
    yield rng.standard_t(2, 20000)                       # heavy tails, both signs
    yield np.r_[np.full(5000, 1e-300), rng.random(3000) * 1e300, 0.0, -0.0]


@pytest.mark.parametrize("limit", [3, 1 << 16])
@pytest.mark.parametrize("case", range(7))
@pytest.mark.parametrize("size", [97, 4099, 1 << 16])
def test_percentile_and_kth_equal_numpy(monkeypatch, limit, case, size):
    monkeypatch.setattr(ss, "SELECT_LIMIT", limit)
    values = list(_cases())[case]
    e = np.abs(values)
    for q in (0.0, 50.0, 95.0, 99.9, 100.0):
        assert ss.percentile_of_nonnegative(_blocks(e, size), q, e.size) == np.percentile(e, q)
    part = np.sort(e)
    for k in {0, e.size // 3, e.size - 1}:
        assert ss.kth_smallest_pair(_blocks(e, size), k, e.size) == \
            (part[k], part[min(k + 1, e.size - 1)])


def test_rms_p95_max_of_one_block_equals_the_whole_array_formulas():
    rng = np.random.default_rng(3)
    c = rng.standard_normal(5000) * 0.3
    got = ss.rms_p95_max(_blocks(c, 1 << 16), 2.0)
    assert got["rms"] == float(np.sqrt(np.mean((c * 2.0) ** 2)))
    assert got["p95"] == float(np.percentile(np.abs(c) * 2.0, 95))
    assert got["max"] == float((np.abs(c) * 2.0).max())
    blocked = ss.rms_p95_max(_blocks(c, 333), 2.0)
    assert blocked["p95"] == got["p95"] and blocked["max"] == got["max"]
    assert blocked["rms"] == pytest.approx(got["rms"], rel=1e-14)
