import numpy as np
import pytest

from gmis.epochs import merge_streams
from gmis.errors import GmisInputError


def test_coincident_samples_share_an_epoch_and_others_get_their_own():
    imu_t = np.arange(0.0, 1.0, 0.01)
    pos_t = np.array([0.2, 0.4000004, 0.455])   # last one is between IMU epochs
    hdg_t = np.array([0.2, 0.455])
    ep = merge_streams(imu_t, pos_t=pos_t, vel_t=pos_t, heading_t=hdg_t, tolerance_s=1e-3)
    assert len(ep) == imu_t.size + 1
    assert np.all(np.diff(ep.t) > 0)
    k = np.nonzero(np.isclose(ep.t, 0.2))[0][0]
    assert ep.imu[k] == 20 and ep.pos[k] == 0 and ep.vel[k] == 0 and ep.heading[k] == 0
    k2 = np.nonzero(np.isclose(ep.t, 0.455))[0][0]
    assert ep.imu[k2] == -1 and ep.pos[k2] == 2 and ep.heading[k2] == 1
    assert ep.pos[ep.pos >= 0].tolist() == [0, 1, 2]
    assert (ep.imu >= 0).sum() == imu_t.size


def test_two_samples_on_one_imu_epoch_is_an_error():
    imu_t = np.arange(0.0, 1.0, 0.01)
    with pytest.raises(GmisInputError, match="pos"):
        merge_streams(imu_t, pos_t=np.array([0.2, 0.2002]), tolerance_s=1e-3)


def test_without_imu_every_aiding_sample_is_its_own_epoch():
    """The no-IMU tightly coupled run (gmis.tc_gnss_only) merges GNSS epochs only."""
    pos_t = np.array([0.0, 30.0, 60.0])
    ep = merge_streams(np.empty(0), pos_t=pos_t, heading_t=np.array([30.0]))
    assert ep.t.tolist() == pos_t.tolist()
    assert np.all(ep.imu == -1) and ep.pos.tolist() == [0, 1, 2]
    assert ep.heading.tolist() == [-1, 0, -1]


def _merge_by_argsort(imu_t, streams, tolerance_s):
    """The merge as it was built before the memory change (a stable argsort of all the
    times, one index array per stream): the reference merge_streams must equal."""
    from gmis.epochs import _attach

    attach, extra = {}, [np.empty(0)]
    for name, st in streams.items():
        st = np.empty(0) if st is None else np.asarray(st, dtype=float)
        attach[name] = (st, _attach(imu_t, st, tolerance_s, name))
        extra.append(st[attach[name][1] < 0])
    own = np.unique(np.concatenate(extra))
    t = np.concatenate([imu_t, own])
    order = np.argsort(t, kind="stable")
    t = t[order]
    pos_in_t = np.empty(t.size, dtype=np.int64)
    pos_in_t[order] = np.arange(t.size)
    out = {"imu": np.full(t.size, -1, dtype=np.int64)}
    out["imu"][pos_in_t[:imu_t.size]] = np.arange(imu_t.size)
    for name, (st, row) in attach.items():
        idx = np.full(t.size, -1, dtype=np.int64)
        on = row >= 0
        idx[pos_in_t[row[on]]] = np.nonzero(on)[0]
        own_rows = np.nonzero(~on)[0]
        idx[pos_in_t[imu_t.size + np.searchsorted(own, st[own_rows])]] = own_rows
        out[name] = idx
    return t, out


@pytest.mark.parametrize("seed", range(40))
def test_merge_equals_the_argsort_merge_and_shares_arrays(seed):
    """Random streams (on IMU epochs, between them, on the same times as another stream,
    before/after the IMU span, absent): the same epochs and rows as a stable argsort of
    all times; the epoch times are imu_t itself when no sample needs its own epoch, and
    equal streams share one index array."""
    rng = np.random.default_rng(seed)
    imu_t = np.cumsum(rng.uniform(0.005, 0.015, rng.integers(0, 300)))
    if seed % 7 == 0:
        imu_t = np.empty(0)
    span = imu_t[-1] + 0.5 if imu_t.size else 3.0

    def stream():
        kind = rng.integers(0, 4)
        if kind == 0:
            return None
        if kind == 1 and imu_t.size:          # on IMU epochs (within the tolerance)
            rows = np.unique(rng.integers(0, imu_t.size, rng.integers(1, 30)))
            return imu_t[rows] + rng.uniform(-4e-4, 4e-4, rows.size)
        return np.unique(rng.uniform(-0.5, span, rng.integers(1, 30)))

    pos = stream()
    streams = {"pos": pos, "vel": pos if rng.random() < 0.5 else stream(),
               "heading": stream(), "sog": pos if rng.random() < 0.5 else None}
    ep = merge_streams(imu_t, streams["pos"], streams["vel"], streams["heading"],
                       tolerance_s=1e-3, sog_t=streams["sog"])
    t, ref = _merge_by_argsort(imu_t, streams, 1e-3)
    assert np.array_equal(ep.t, t)
    for name, field in (("imu", "imu"), ("pos", "pos"), ("vel", "vel"),
                        ("heading", "heading"), ("sog", "sog")):
        got = getattr(ep, field)
        if name == "sog" and streams["sog"] is None:   # no stream: empty, not (E,) of -1
            assert got.dtype == np.int64 and got.size == 0 and (ref[name] < 0).all()
            continue
        assert got.dtype == np.int64 and np.array_equal(got, ref[name]), name
    if t.size == imu_t.size:
        assert ep.t is imu_t
    if streams["vel"] is streams["pos"]:
        assert ep.vel is ep.pos
    if streams["heading"] is None and streams["vel"] is None:
        assert ep.vel is ep.heading


@pytest.mark.parametrize("seed", range(40))
def test_compact_merge_equals_the_arrays(seed, monkeypatch):
    """merge_streams(compact=True): RowIndex entries equal the arrays of the plain merge
    (whole, by random epoch ranges, by comparison blocks of 7 epochs)."""
    import gmis.epochs as epochs_module
    from gmis.epochs import RowIndex

    monkeypatch.setattr(epochs_module, "BLOCK", 7)
    rng = np.random.default_rng(100 + seed)
    imu_t = np.cumsum(rng.uniform(0.005, 0.015, rng.integers(1, 300)))
    span = imu_t[-1] + 0.5

    def stream():
        kind = rng.integers(0, 4)
        if kind == 0:
            return None
        if kind == 1:
            rows = np.unique(rng.integers(0, imu_t.size, rng.integers(1, 30)))
            return imu_t[rows] + rng.uniform(-4e-4, 4e-4, rows.size)
        return np.unique(rng.uniform(-0.5, span, rng.integers(1, 30)))

    pos = stream()
    args = (imu_t, pos, pos if rng.random() < 0.5 else stream(), stream())
    sog = pos if rng.random() < 0.5 else None
    plain = merge_streams(*args, tolerance_s=1e-3, sog_t=sog)
    compact = merge_streams(*args, tolerance_s=1e-3, sog_t=sog, compact=True)
    assert np.array_equal(compact.t, plain.t)
    np.testing.assert_array_equal(compact.sog, plain.sog)
    n = len(plain)
    for name in ("imu", "pos", "vel", "heading"):
        a, b = getattr(plain, name), getattr(compact, name)
        assert isinstance(b, RowIndex) and len(b) == n
        np.testing.assert_array_equal(np.asarray(b), a, err_msg=name)
        np.testing.assert_array_equal(b >= 0, a >= 0)
        np.testing.assert_array_equal(b < 0, a < 0)
        for _ in range(5):
            lo, hi = np.sort(rng.integers(0, n + 3, 2))
            np.testing.assert_array_equal(b[lo:hi], a[lo:hi])
        k = int(rng.integers(0, n))
        assert b[k] == a[k] and b[-1] == a[-1]
    if plain.vel is plain.pos:
        assert compact.vel is compact.pos
