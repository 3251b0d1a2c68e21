"""gmis.readers.read_reference_blocks (the streamed `gmis run`'s reference, docs/DESIGN.md
"Bounded memory") against read_reference + load_dataset's crop + check_dataset's height
check: the same rows bit for bit and the same first error, with blocks of a few lines."""

import numpy as np
import pytest

from gmis.errors import GmisInputError
from gmis.plausibility import check_reference_height
from gmis.readers import REFERENCE_COLUMNS, _crop, read_reference, read_reference_blocks


def _write(path, rows, header=REFERENCE_COLUMNS):
    lines = [",".join(header)] + [",".join(repr(float(v)) for v in r) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def _rows(n=400, seed=0):
    rng = np.random.default_rng(seed)
    t = 1000.0 + np.arange(n) * 0.01
    return np.column_stack([t, 40 + rng.normal(0, 1e-4, n), -105 + rng.normal(0, 1e-4, n),
                            1600 + rng.normal(0, 1, n), rng.normal(0, 5, (n, 3)),
                            rng.uniform(-179, 179, (n, 3))])


def _whole(path, start, end):
    ref = _crop(read_reference(path), start, end)
    check_reference_height(path, ref.llh[:, 2])
    return ref


def _streamed(path, start, end):
    got = {"t": [], "llh": [], "vel": [], "euler": []}

    def consume(t, llh, vel, euler):
        for k, v in (("t", t), ("llh", llh), ("vel", vel), ("euler", euler)):
            got[k].append(v.copy())

    n = read_reference_blocks(path, consume, start, end, block_bytes=2000)
    got = {k: np.concatenate(v) for k, v in got.items()}
    assert n == got["t"].size
    return got.pop("t"), got


@pytest.mark.parametrize("window", [(None, None), (1001.234, None), (None, 1002.5),
                                    (1000.5, 1003.0)])
def test_same_rows_as_the_whole_reader(tmp_path, window):
    path = _write(tmp_path / "ref.csv", _rows())
    ref = _whole(path, *window)
    t, got = _streamed(path, *window)
    assert t.size == ref.t.size and 0 < t.size
    np.testing.assert_array_equal(t, ref.t)
    np.testing.assert_array_equal(got["llh"], ref.llh)
    np.testing.assert_array_equal(got["vel"], ref.vel_enu)
    np.testing.assert_array_equal(got["euler"], ref.euler)


def _broken(kind, rows):
    rows = rows.copy()
    if kind == "nonfinite":
        rows[300, 5] = np.nan
        rows[350, 1] = np.inf        # an earlier column later in the file: reported first
    elif kind == "backwards":
        rows[250, 0] = rows[249, 0] - 0.5
        rows[390, 1] = 95.0          # latitude later: the time is reported
    elif kind == "duplicate":
        rows[5, 0] = rows[4, 0]
    elif kind == "lat":
        rows[330, 1] = -91.0
        rows[20, 2] = 400.0          # a longitude earlier: the latitude is reported
    elif kind == "lon":
        rows[299, 2] = -190.0
    elif kind == "height":
        rows[310, 3] = 12000.0
    return rows


@pytest.mark.parametrize("kind", ["nonfinite", "backwards", "duplicate", "lat", "lon",
                                  "height", "header"])
def test_same_first_error_as_the_whole_reader(tmp_path, kind):
    rows = _rows()
    header = REFERENCE_COLUMNS
    if kind == "header":
        header = [*REFERENCE_COLUMNS[:-1], "heading_dg"]
    path = _write(tmp_path / "ref.csv", _broken(kind, rows), header)
    with pytest.raises(GmisInputError) as whole:
        _whole(path, None, None)
    with pytest.raises(GmisInputError) as streamed:
        _streamed(path, None, None)
    assert str(streamed.value) == str(whole.value)


def test_track_from_file_equals_the_track_of_the_whole_reader(tmp_path, monkeypatch):
    """ReferenceTrack.from_file (times spooled too, read by forward cursors) gives the
    windows, rows and times of ReferenceTrack over read_reference's arrays."""
    import itertools
    from types import SimpleNamespace

    import gmis.navigation_solution as ns
    from gmis.earth import make_nav_frame

    monkeypatch.setattr(ns, "TIME_BLOCK_ROWS", 7)
    monkeypatch.setattr(ns, "REFERENCE_BLOCK_BYTES", 2000)
    path = _write(tmp_path / "ref.csv", _rows(3000, seed=4))
    start = 1001.005
    recipe = SimpleNamespace(paths=SimpleNamespace(reference=path),
                             time=SimpleNamespace(start_gps_s=start, end_gps_s=None))
    frame = make_nav_frame(np.radians(40.0), np.radians(-105.0), 1600.0)
    ref = _crop(read_reference(path), start, None)
    whole = ns.ReferenceTrack(SimpleNamespace(dataset=SimpleNamespace(reference=ref),
                                              frame=frame))
    streamed = ns.ReferenceTrack.from_file(recipe, frame, tmp_path / "spool")
    assert streamed.t is None
    assert (streamed.n, streamed.t_first, streamed.t_last) == \
        (whole.n, whole.t_first, whole.t_last)
    rng = np.random.default_rng(5)
    edges = [ref.t[0] - 0.3, *np.sort(rng.uniform(ref.t[0], ref.t[-1], 25)), ref.t[-1] + 1]
    for lo, hi in itertools.pairwise(edges):
        a, b = whole.window(lo, hi), streamed.window(lo, hi)
        assert a[:2] == b[:2]
        for x, y in zip(a[2:], b[2:]):
            assert np.array_equal(x, y)
        assert np.array_equal(whole.times(a[0], a[1]), streamed.times(b[0], b[1]))
