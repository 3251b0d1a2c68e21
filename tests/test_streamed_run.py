"""Bounded-memory `gmis run` (docs/DESIGN.md "Bounded memory"): the filter records handed
chunk by chunk to the writers give the same files as the in-memory records, and the
column spool reads back what was written."""

import dataclasses
import itertools

import numpy as np
import pytest

from benchmarks.compare_outputs import compare
from gmis.navigation_solution import navigation_solution, reference_errors
from gmis.pipeline import prepare_run, run_recipe
from gmis.recipe import load_recipe
from gmis.record_spool import ColumnSpool, LazyColumns, write_npz_members
from gmis.run_filter import FilterDivergedError, run_gmikf
from gmis.run_preparation import run_prepared
from gmis.run_writers import StreamedOutputs, write_errors_csv, write_solution
from gmis.simulate import simulate_scenario
from tests.simulated_drives import default_scenario_cut


@pytest.fixture(scope="module")
def short_drive(tmp_path_factory):
    """The default scenario cut to its first ~70 s (static alignment, then driving)."""
    sc = default_scenario_cut(70.0)
    sim = simulate_scenario(sc, tmp_path_factory.mktemp("drive") / "ds")
    return sim.recipe_path


def _in_memory_folder(prep, folder):
    """The results files written from whole in-memory records (the pre-streaming path)."""
    rec = run_prepared(prep)
    nav = navigation_solution(prep, rec)
    folder.mkdir()
    csv_epochs = write_solution(folder, prep, rec, nav, 10.0)
    write_errors_csv(folder, reference_errors(prep, rec, nav), csv_epochs)
    return rec


@pytest.mark.parametrize("chunk", [37, 1000])
def test_streamed_files_equal_in_memory(short_drive, tmp_path, chunk):
    prep = prepare_run(load_recipe(short_drive))
    prep = dataclasses.replace(prep, config=dataclasses.replace(prep.config, chunk=chunk))
    assert len(prep.epochs) > 3 * chunk
    rec = _in_memory_folder(prep, tmp_path / "memory")
    out_dir = tmp_path / "streamed"
    out_dir.mkdir()
    out = StreamedOutputs(out_dir, prep)
    last = run_prepared(prep, sink=out.add)
    errs = out.close()
    whole = reference_errors(prep, rec, navigation_solution(prep, rec))
    np.testing.assert_array_equal(errs["idx"], whole["idx"])
    np.testing.assert_array_equal(errs["nees"]["attitude"], whole["nees"]["attitude"])
    out.remove_spools()
    assert sorted(p.name for p in out_dir.iterdir()) == sorted(
        p.name for p in (tmp_path / "memory").iterdir())
    assert compare(tmp_path / "memory", out_dir, tol=0.0)
    # the accumulated records are those of the whole run; the errors read back
    np.testing.assert_array_equal(last.helmert_totals, rec.helmert_totals)
    assert last.x.shape[0] == chunk
    assert list(out.totals.rejected_counts().values()) == rec.rejected.sum(0).tolist()


def test_run_recipe_streams(short_drive, tmp_path, monkeypatch):
    """run_recipe takes the streamed path for a forward loosely coupled run, and the
    summary figures equal those computed from the whole records."""
    from gmis import run_preparation

    calls = []
    real = run_preparation.run_prepared

    def spy(*args, **kwargs):
        calls.append(kwargs.get("sink"))
        return real(*args, **kwargs)

    monkeypatch.setattr("gmis.pipeline.run_prepared", spy)
    summary = run_recipe(short_drive, tmp_path / "res")
    assert calls and calls[0] is not None
    assert not any(p.name.startswith(".") and p.is_dir() for p in (tmp_path / "res").iterdir())
    prep = prepare_run(load_recipe(short_drive))
    rec = real(prep)
    from gmis.run_statistics import rejected_counts, summarize_errors
    assert summary["rejected_observations"] == rejected_counts(rec)
    errs = reference_errors(prep, rec, navigation_solution(prep, rec))
    skip = prep.recipe.filter.static_alignment_s
    assert summary["errors_vs_reference"] == summarize_errors(errs, skip_s=skip)


def test_divergence_in_a_later_chunk_names_the_run_epoch(short_drive):
    prep = prepare_run(load_recipe(short_drive))
    imu = prep.meas.imu_z.copy()
    imu[250, 0] = np.inf
    meas = dataclasses.replace(prep.meas, imu_z=imu)
    cfg = dataclasses.replace(prep.config, chunk=100)
    with pytest.raises(FilterDivergedError, match=r"at epoch 2[0-9]{2} ") as whole:
        run_gmikf(prep.epochs, meas, prep.x0, cfg, prep.frame)
    with pytest.raises(FilterDivergedError) as streamed:
        run_gmikf(prep.epochs, meas, prep.x0, cfg, prep.frame, sink=lambda e0, rec: None)
    assert str(streamed.value) == str(whole.value)


def test_column_spool_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    x = rng.normal(size=(103, 4))
    k = rng.integers(-5, 5, size=103).astype(np.int8)
    spool = ColumnSpool(tmp_path / "s", 103, {"x": ((4,), np.float64), "k": ((), np.int8)})
    for e0 in range(0, 103, 10):
        spool.append(x=x[e0:e0 + 10], k=k[e0:e0 + 10])
    spool.close()
    np.testing.assert_array_equal(np.load(spool.path("x")), x)
    np.testing.assert_array_equal(spool.read("x", 17, 40), x[17:40])
    np.testing.assert_array_equal(spool.read("k", 95), k[95:])
    lazy = LazyColumns(spool, {"x": "x"}, extra=5)
    assert dict(lazy)["extra"] == 5 and np.array_equal(lazy["x"], x)
    write_npz_members(tmp_path / "a.npz", {"x": spool.path("x"), "names": np.array(["a"])})
    with np.load(tmp_path / "a.npz") as z:
        np.testing.assert_array_equal(z["x"], x)
        assert z["names"].tolist() == ["a"]


def test_column_spool_refuses_short_or_long(tmp_path):
    spool = ColumnSpool(tmp_path / "s", 5, {"x": ((), np.float64)})
    with pytest.raises(ValueError, match="overflow"):
        spool.append(x=np.zeros(6))
    spool = ColumnSpool(tmp_path / "t", 5, {"x": ((), np.float64)})
    spool.append(x=np.zeros(3))
    with pytest.raises(ValueError, match="3 of 5"):
        spool.close()


@pytest.mark.parametrize("fmt", ["%.10g", "%.12g", "%.9f"])
def test_format_rows_equals_savetxt(fmt):
    import io

    from gmis.results import format_rows
    rng = np.random.default_rng(3)
    t = rng.normal(size=(200, 5)) * 10.0 ** rng.integers(-12, 12, size=(200, 5))
    t[3, 2], t[5, 1], t[7, 0], t[8] = np.nan, -np.inf, -0.0, 0.0
    buf = io.StringIO()
    np.savetxt(buf, t, delimiter=",", fmt=fmt)
    assert format_rows(t, fmt) == buf.getvalue()
    assert format_rows(t[:0], fmt) == ""


def test_vce_spooled_records_equal_in_memory(short_drive, monkeypatch):
    """vce.tune with its records on disk (vce.spooled_records) gives bit-identical
    iterations and residuals to the records held whole."""
    import importlib

    tune_module = importlib.import_module("vce.tune")
    recipe = load_recipe(short_drive)
    spooled = tune_module.tune(recipe, max_iterations=3)
    monkeypatch.setattr(tune_module, "spooled_run",
                        lambda run, comps, n, folder: run(sink=None))
    whole = tune_module.tune(recipe, max_iterations=3)
    assert len(spooled.history) == len(whole.history)
    for a, b in zip(spooled.history, whole.history):
        np.testing.assert_array_equal(a.sigma0_sq, b.sigma0_sq)
        assert [e.sum_vpv for e in a.estimates] == [e.sum_vpv for e in b.estimates]
    for name, (t, w) in whole.residuals_final.items():
        ts, ws = spooled.residuals_final[name]
        np.testing.assert_array_equal(ts, t)
        np.testing.assert_array_equal(ws, w)


def test_reference_track_windows_equal_the_whole(tmp_path):
    """ReferenceTrack (a streamed run's chunks), in memory and spooled to column files:
    ENU rows, velocity rows and the unwrapped attitude continued across windows equal
    reference_track's whole-array values bit for bit, with angles crossing ±π (and
    landing exactly on π), windows of random sizes."""
    from types import SimpleNamespace

    from gmis.earth import make_nav_frame
    from gmis.navigation_solution import ReferenceTrack, reference_track

    rng = np.random.default_rng(18)
    for trial in range(12):
        n = int(rng.integers(2, 2500))
        euler = np.cumsum(rng.normal(0.0, 1.5, (n, 3)), axis=0)
        euler = (euler + np.pi) % (2 * np.pi) - np.pi
        euler[rng.integers(0, n, 5)] = np.pi
        t = np.arange(n) * 0.01
        llh = np.column_stack([0.76 + 1e-7 * np.arange(n), np.full(n, -1.38),
                               180.0 + 0.01 * np.arange(n)])
        ref = SimpleNamespace(t=t, llh=llh, euler=euler, vel_enu=rng.normal(size=(n, 3)))
        prep = SimpleNamespace(dataset=SimpleNamespace(reference=ref),
                               frame=make_nav_frame(0.76, -1.38, 180.0))
        enu_all, unwrapped_all = reference_track(prep)
        assert np.abs(np.diff(unwrapped_all, axis=0)).max() < np.pi + 1e-9
        edges = [0.0, *np.sort(rng.uniform(0, t[-1], int(rng.integers(1, 10)))), t[-1]]
        for spool in (None, tmp_path / f"spool-{trial}"):
            track = ReferenceTrack(prep, spool)
            for lo, hi in itertools.pairwise(edges):
                j0, j1, enu, vel, unwrapped = track.window(lo, hi)
                assert j0 <= max(np.searchsorted(t, lo, "right") - 1, 0)
                assert j1 >= min(np.searchsorted(t, hi, "right") + 1, n)
                assert np.array_equal(unwrapped, unwrapped_all[j0:j1])
                assert np.array_equal(enu, enu_all[j0:j1])
                assert np.array_equal(vel, ref.vel_enu[j0:j1])
            with pytest.raises(ValueError, match="go back"):
                track.window(0.0, t[-1])


def test_recently_fixed_rows_equal_the_whole_array_form():
    """summarize_errors' GNSS-aided rows, block by block from the fix epochs, are
    seconds_since_last_fix(t, fix)[idx] <= 1 s of the whole arrays."""
    from gmis.run_statistics import recently_fixed_rows, seconds_since_last_fix

    rng = np.random.default_rng(2)
    t = np.cumsum(rng.uniform(0.005, 0.015, 50_000))
    fix = rng.random(t.size) < 0.01
    fix[:3000] = False                      # inf before the first fix
    idx = np.flatnonzero(rng.random(t.size) < 0.3)
    whole = seconds_since_last_fix(t, fix)[idx] <= 1.0
    keep = recently_fixed_rows({"idx": idx}, t, fix, 1.0)
    for block in (1, 777, 1 << 16):
        got = np.concatenate([keep(j, min(j + block, idx.size))
                              for j in range(0, idx.size, block)])
        np.testing.assert_array_equal(got, whole)


def test_error_statistics_and_spooled_rows_equal_the_whole_array_forms(tmp_path):
    """error_statistics (one block here) gives the figures of the whole-array formulas
    bit for bit, and LazyColumns.rows reads back the spooled rows."""
    from gmis.run_statistics import error_statistics

    rng = np.random.default_rng(5)
    err = rng.normal(size=(10_007, 3)) * 10.0 ** rng.uniform(-4, 1, (10_007, 3))
    for scale in (1.0, 57.29577951308232):
        got = error_statistics(err, ["a", "b", "c"], scale, "u")
        for i, name in enumerate("abc"):
            c = err[:, i]
            e = np.abs(c) * scale
            assert got[name] == {"rms": float(np.sqrt(np.mean((c * scale) ** 2))),
                                 "p95": float(np.percentile(e, 95)),
                                 "max": float(e.max()), "unit": "u"}
    spool = ColumnSpool(tmp_path / "s", err.shape[0], {"pos": ((3,), np.float64)})
    for e0 in range(0, err.shape[0], 999):
        spool.append(pos=err[e0:e0 + 999])
    spool.close()
    lazy = LazyColumns(spool, {"pos": "pos"})
    assert lazy.n_rows == err.shape[0]
    for j0 in range(0, err.shape[0], 101):
        np.testing.assert_array_equal(lazy.rows("pos", j0, j0 + 101), err[j0:j0 + 101])


def test_solution_pos_from_blocks_equals_the_whole_rows(tmp_path):
    """solution.pos written from blocks of rows (read back from disk at close) is the
    file of the whole rows, byte for byte (n_sat from the nearest GNSS epoch, Q grades)."""
    from types import SimpleNamespace

    from gmis.solution_antenna import write_solution_pos, write_solution_pos_blocks

    rng = np.random.default_rng(11)
    n = 5003
    t = 345600.0 + np.arange(n) * 0.1
    llh = np.column_stack([0.76 + rng.normal(0, 1e-6, n), -1.38 + rng.normal(0, 1e-6, n),
                           180.0 + rng.normal(0, 1.0, n)])
    sd = np.abs(rng.normal(0, 0.3, (n, 3)))
    gnss = SimpleNamespace(t=t[::2] + 0.01, ns=rng.integers(4, 12, t[::2].size))
    whole = write_solution_pos(tmp_path / "whole.pos", t, 2400, llh, sd, gnss, ["x"])
    cuts = [0, 1, 777, 778, 4000, n]
    blocks = [(t[a:b], llh[a:b], sd[a:b]) for a, b in itertools.pairwise(cuts)]
    parts = write_solution_pos_blocks(tmp_path / "parts.pos", blocks, 2400, gnss, ["x"])
    assert parts.read_bytes() == whole.read_bytes()
    assert whole.read_text().count("\n") > n // 2


@pytest.mark.parametrize("a", [np.arange(300_000, dtype=np.float64) * 0.5,
                               np.arange(600_000, dtype=np.int64).reshape(-1, 3),
                               np.ones((200_000, 9), dtype=np.int8),
                               np.array(["x", "yy"] * 80_000)])
def test_npz_members_written_in_blocks_are_np_savez_bytes(tmp_path, a):
    """write_npz_members writes large arrays in 1 MiB views: the same bytes as np.savez."""
    write_npz_members(tmp_path / "a.npz", {"t": a})
    np.savez(tmp_path / "b.npz", t=a)
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
