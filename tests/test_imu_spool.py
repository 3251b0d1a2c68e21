"""IMU samples on disk (gmis.imu_spool; docs/DESIGN.md "Bounded memory"): the streamed
reader gives the in-memory reader's values and errors, the lazy columns index like
arrays, and the filter fed chunk by chunk from the spool gives the same records as with
the samples in memory — chunk edges on aiding epochs, aiding epochs of their own between
IMU samples, a [time] window."""

import copy
import dataclasses

import numpy as np
import pytest
from hypothesis import given

from gmis.epochs import RowIndex
from gmis.errors import GmisInputError
from gmis.imu_spool import ImuSpool, spool_array
from gmis.readers import load_dataset, read_imu
from gmis.recipe import ImuSection, load_recipe
from gmis.run_preparation import prepare_run, run_prepared
from gmis.simulate import load_scenario, scenario_path, simulate_scenario
from tests.simulated_drives import square_drive_segments
from tests.test_fuzz_readers import edits, fuzz_settings, imu_seed, mutate, write


def _read(path, section, window=None, on_disk=False):
    try:
        imu = read_imu(path, section, window, on_disk=on_disk)
    except GmisInputError as exc:
        return str(exc)
    return imu.t, np.asarray(imu.gyro), np.asarray(imu.accel), imu.warnings, imu.file_span


def _same(a, b):
    if isinstance(a, str) or isinstance(b, str):
        assert a == b
        return
    for x, y in zip(a, b):
        if isinstance(x, np.ndarray):
            np.testing.assert_array_equal(x, y)
        else:
            assert x == y


SECTIONS = [ImuSection(rate_hz=100.0),
            ImuSection(rate_hz=100.0, format="increment", gyro_unit="deg",
                       accel_unit="m/s", axes=("y", "x", "-z")),
            ImuSection(rate_hz=100.0, time_column=0, gyro_columns=(1, 2, 3),
                       accel_columns=(4, 5, 6))]


@pytest.mark.parametrize("section", range(len(SECTIONS)))
@pytest.mark.parametrize("window", [None, (345600.105, 345600.4), (None, 345600.2)])
def test_on_disk_reader_equals_in_memory(tmp_path, monkeypatch, section, window):
    """Blocks of 7 conversion rows and 200 bytes of text: many blocks in 60 lines."""
    from gmis import readers, text_blocks

    monkeypatch.setattr(readers, "ROTATE_ROWS", 7)
    monkeypatch.setattr(text_blocks, "BLOCK_BYTES", 200)
    path = write(tmp_path / "imu.csv", imu_seed(60))
    _same(_read(path, SECTIONS[section], window, True), _read(path, SECTIONS[section], window))


BAD_LINES = {
    "nan time": (5, "345600.04", "nan"),
    "nan accel": (40, "9.8", "inf"),
    "nan gyro and accel": (30, "0.1,", "nan,"),
    "non-numeric": (12, "0.2", "abc"),
    "backwards": (20, "345600.19", "345600.1"),
    "duplicate": (20, "345600.19", "345600.18"),
    "columns": (33, "0.2,", ""),
}


@pytest.mark.parametrize("case", sorted(BAD_LINES))
def test_on_disk_reader_errors_equal_in_memory(tmp_path, monkeypatch, case):
    from gmis import text_blocks

    monkeypatch.setattr(text_blocks, "BLOCK_BYTES", 300)
    line, old, new = BAD_LINES[case]
    lines = imu_seed(60).splitlines(keepends=True)
    assert old in lines[line], (case, lines[line])
    lines[line] = lines[line].replace(old, new, 1)
    path = write(tmp_path / "imu.csv", "".join(lines))
    got = _read(path, SECTIONS[0], on_disk=True)
    assert isinstance(got, str) and str(path) in got
    assert got == _read(path, SECTIONS[0])


@pytest.mark.parametrize("what", ["time_column", "gyro_columns", "accel_columns"])
def test_on_disk_reader_column_errors_equal_in_memory(tmp_path, what):
    path = write(tmp_path / "imu.csv", imu_seed(60).replace("accel_z", "acc_z")
                 .replace("gyro_y", "gyr_y").replace("time_gps_s", "tim"))
    named = {"time_column": "tim", "gyro_columns": ("gyro_x", "gyr_y", "gyro_z"),
             "accel_columns": ("accel_x", "accel_y", "acc_z")}
    named.pop(what)           # the others named as in the file
    section = dataclasses.replace(ImuSection(rate_hz=100.0), **named)
    got = _read(path, section, on_disk=True)
    assert isinstance(got, str) and "missing column" in got
    assert got == _read(path, section)


@fuzz_settings(40)
@given(edit_list=edits)
def test_mutated_imu_on_disk_equals_in_memory(tmp_path_factory, edit_list):
    path = write(tmp_path_factory.mktemp("m") / "imu.csv", mutate(imu_seed(), edit_list))
    _same(_read(path, SECTIONS[0], on_disk=True), _read(path, SECTIONS[0]))


def test_spooled_columns_index_like_arrays():
    rng = np.random.default_rng(7)
    z = rng.normal(size=(100_003, 6))
    spool = spool_array(z)
    assert isinstance(spool, ImuSpool) and spool.shape == z.shape
    for first in (0, 3):
        cols, want = spool.columns(first), z[:, first:first + 3]
        assert cols.shape == want.shape and len(cols) == len(want)
        mask = rng.random(z.shape[0]) < 0.001
        mask[:50] = False
        keys = [slice(None), slice(5, 17), slice(99_990, None), slice(-5, None),
                slice(70_000, 70_000 + 40_000), mask, (mask, 2), (slice(3, 9), 1),
                np.array([4, 99_000, 17]), 12, (12, 0), -1]
        for key in keys:
            got, exp = cols[key], want[key]
            np.testing.assert_array_equal(got, exp)
            assert np.shape(got) == np.shape(exp)
        np.testing.assert_array_equal(np.asarray(cols), want)
        for a, b in ((0, 3), (99_999, 100_010), (50, 50), (40_000, 90_000)):
            np.testing.assert_array_equal(spool.rows(a, b), z[a:min(b, z.shape[0])])
    path = spool.path
    spool.remove()
    assert not path.exists()


@pytest.fixture(scope="module")
def short_drive(tmp_path_factory):
    """The square drive (20 s static, then driving with turns) with the default IMU."""
    sc = copy.deepcopy(load_scenario(scenario_path("default")))
    sc["gnss"]["outage"] = []
    sc["segment"] = square_drive_segments()
    return simulate_scenario(sc, tmp_path_factory.mktemp("drive") / "ds").recipe_path


def _chunks(prep, chunk):
    """Every record buffer handed to the sink, copied, and the returned records."""
    prep = dataclasses.replace(prep, config=dataclasses.replace(prep.config, chunk=chunk))
    got = []
    last = run_prepared(prep, sink=lambda e0, rec: got.append(
        (e0, {k: np.array(getattr(rec, k)) for k in ("x", "sd", "innov", "rejected", "vz",
                                                       "nobs", "rvar", "still")})))
    return got, last


@pytest.mark.parametrize("shift", [0.0, 0.0037])
def test_filter_from_the_spool_equals_in_memory(short_drive, shift):
    """Chunks whose edges fall on GNSS epochs (and one epoch either side), with the GNSS
    on the IMU epochs and (shift) as epochs of their own between IMU samples; the
    recipe's IMU scale-factor rows read the ±25 neighbouring samples across the edges."""
    recipe = load_recipe(short_drive)
    recipe = dataclasses.replace(recipe, gnss=dataclasses.replace(recipe.gnss,
                                                                  time_offset_s=shift))
    mem = prepare_run(recipe, load_dataset(recipe, with_reference=False))
    disk = prepare_run(recipe, load_dataset(recipe, with_reference=False, imu_on_disk=True))
    assert isinstance(disk.meas.imu_z, ImuSpool)
    assert isinstance(disk.epochs.imu, RowIndex) and isinstance(disk.epochs.pos, RowIndex)
    assert disk.config.consider_scale_imu
    pos_epochs = np.flatnonzero(mem.epochs.pos >= 0)
    own = np.flatnonzero(mem.epochs.imu < 0)
    assert (own.size > 0) == (shift > 0)
    moving = np.flatnonzero(~mem.stationary[pos_epochs])
    assert moving.size > 10
    e_p = int(pos_epochs[moving[moving.size // 2]])     # a GNSS epoch while driving
    for chunk in (e_p - 1, e_p, e_p + 1, 37):
        a, last_a = _chunks(mem, chunk)
        b, last_b = _chunks(disk, chunk)
        assert [e0 for e0, _ in a] == [e0 for e0, _ in b]
        for (_, ra), (_, rb) in zip(a, b):
            for k in ra:
                np.testing.assert_array_equal(ra[k], rb[k], err_msg=f"{k}, chunk {chunk}")
        np.testing.assert_array_equal(last_a.helmert_totals, last_b.helmert_totals)
    whole = run_prepared(mem)
    x = np.concatenate([r["x"] for _, r in b])
    np.testing.assert_array_equal(x, whole.x)


def test_window_on_disk_equals_in_memory(short_drive):
    """A [time] window that starts and ends between IMU samples."""
    recipe = load_recipe(short_drive)
    t0 = recipe.time.start_gps_s or 345600.0
    recipe = dataclasses.replace(recipe, time=dataclasses.replace(
        recipe.time, start_gps_s=t0 + 0.1234, end_gps_s=t0 + 55.4321))
    mem = load_dataset(recipe, with_reference=False)
    disk = load_dataset(recipe, with_reference=False, imu_on_disk=True)
    np.testing.assert_array_equal(mem.imu.t, disk.imu.t)
    np.testing.assert_array_equal(mem.imu.z, np.asarray(disk.imu.z))
    assert mem.imu.t[0] >= t0 + 0.1234 and mem.imu.t[-1] <= t0 + 55.4321
    a, _ = _chunks(prepare_run(recipe, mem), 777)
    b, _ = _chunks(prepare_run(recipe, disk), 777)
    for (_, ra), (_, rb) in zip(a, b):
        np.testing.assert_array_equal(ra["x"], rb["x"])


def test_every_step_imu_epoch_equals_the_whole_array_form(monkeypatch):
    from gmis import run_writers
    from gmis.epochs import merge_streams

    monkeypatch.setattr(run_writers, "EPOCH_BLOCK", 13)
    rng = np.random.default_rng(3)
    imu_t = np.cumsum(rng.uniform(0.005, 0.015, 500))
    own = np.unique(rng.uniform(0, imu_t[-1], 40))
    for compact in (False, True):
        ep = merge_streams(imu_t, own, compact=compact)
        whole = np.nonzero(np.asarray(ep.imu) >= 0)[0]
        for step in (1, 3, 10, 1000):
            np.testing.assert_array_equal(run_writers.every_step_imu_epoch(ep.imu, step),
                                          whole[::step])
