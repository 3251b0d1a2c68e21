"""Regression tests for the cases of issue 16: output folders that must not be written,
IMU gaps, plausibility checks at load time, RTK inputs without a solution.

The CLI tests replace the engine by a small fake (as tests/test_cli.py does) that really
loads the dataset, so they check where and when the CLI refuses, not the filter."""

from __future__ import annotations

import errno
import json
import math
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from gmis import cli, output_folder, plausibility
from gmis.errors import GmisInputError
from gmis.readers import MAX_GAP_S, load_dataset
from gmis.recipe import load_recipe
from gmis.results import results_directory, write_csv, write_json
from tests.shared_data import DRIVE_BOULDER, RTKLIB_TEST, require
from tests.test_cli import run_cli

REPO = Path(__file__).resolve().parents[1]


def one_line_error(err: str, *words):
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gmis: error: "), err
    assert "Traceback" not in err and ".partial-" not in err, err
    for w in words:
        assert w in lines[0], (w, err)


@pytest.fixture
def engine(monkeypatch):
    """gmis.pipeline stand-in: loads the dataset and writes summary.json atomically."""
    calls = []

    def run_recipe(recipe_path, results_dir, progress=None, **options):
        ds = load_dataset(load_recipe(recipe_path))
        with results_directory(results_dir) as out:
            write_json(out / "summary.json", {"imu_samples": ds.imu.t.size})
        calls.append(Path(results_dir))
        return {"imu_samples": ds.imu.t.size}

    module = types.ModuleType("gmis.pipeline")
    module.run_recipe = run_recipe
    monkeypatch.setitem(sys.modules, "gmis.pipeline", module)
    return calls


def files_of(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


# ----------------------------------------------------------------------------- output folders


def test_output_is_never_the_current_directory(dataset, tmp_path, capsys, monkeypatch, engine):
    recipe = dataset.write()
    work = tmp_path / "s"
    (work / "chapter").mkdir(parents=True)
    (work / "thesis.tex").write_text("mine")
    (work / "chapter" / "intro.tex").write_text("mine too")
    monkeypatch.chdir(work)
    for out in (".", "..", str(work), ""):
        code, _, err = run_cli(capsys, "run", str(recipe), "-o", out, "--quiet")
        assert code == 2
        one_line_error(err, "current directory")
    assert files_of(work) == {"thesis.tex": b"mine", "chapter/intro.tex": b"mine too"}
    assert engine == []


def test_output_is_never_an_input_folder(dataset, tmp_path, capsys, engine):
    recipe = dataset.write()
    before = files_of(tmp_path)
    for out in (tmp_path, tmp_path.parent):
        code, _, err = run_cli(capsys, "run", str(recipe), "-o", str(out), "--quiet")
        assert code == 2
        one_line_error(err, "holds the input")
    assert files_of(tmp_path) == before
    assert engine == []


def test_data_folder_named_in_the_recipe_is_protected(dataset, tmp_path, capsys, engine):
    data = tmp_path / "data"
    data.mkdir()
    (data / "imu.csv").write_bytes(dataset.imu.read_bytes())
    recipe = dataset.write(dataset.modified("paths", imu="data/imu.csv"))
    code, _, err = run_cli(capsys, "run", str(recipe), "-o", str(data), "--quiet")
    assert code == 2
    one_line_error(err, "holds the input", "imu.csv")
    assert (data / "imu.csv").is_file()


def test_existing_folder_without_marker_is_refused_even_if_it_looks_like_results(
        dataset, tmp_path, capsys, engine):
    recipe = dataset.write()
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text("{}")
    code, _, err = run_cli(capsys, "run", str(recipe), "-o", str(out), "--quiet")
    assert code == 2
    one_line_error(err, "not written by gmis", output_folder.MARKER)
    assert files_of(out) == {"summary.json": b"{}"}


def test_new_empty_and_marked_folders_are_written_and_marked(dataset, tmp_path, capsys, engine):
    recipe = dataset.write()
    new, empty = tmp_path / "r" / "new", tmp_path / "empty"
    empty.mkdir()
    for out in (new, empty, new):      # the third run replaces gmis's own earlier output
        code, _, err = run_cli(capsys, "run", str(recipe), "-o", str(out), "--quiet")
        assert code == 0, err
        assert output_folder.is_gmis_folder(out)
        assert json.loads((out / output_folder.MARKER).read_text())["command"] == "run"
    assert len(engine) == 3
    assert sorted(p.name for p in new.iterdir()) == [output_folder.MARKER, "summary.json"]


def test_signed_main_files_mark_report_and_rtk_folders(tmp_path):
    html = '<html><head><meta charset="utf-8">\n<meta name="generator" content="gmis report">'
    for name, text in (("report.html", html),
                       ("rtk.pos", "% gmis rtk /x/recipe.toml\n"),
                       ("tc.pos", "% gmis rtk --tight /x/recipe.toml\n")):
        folder = tmp_path / name.replace(".", "_")
        folder.mkdir()
        (folder / name).write_text(text)
        assert output_folder.is_gmis_folder(folder)
        output_folder.check_output_folder(folder, "rtk" if name.endswith("pos") else "report")
        (folder / name).write_text("% my own notes\n")
        assert not output_folder.is_gmis_folder(folder)


@pytest.mark.parametrize("target, words", [
    ("afile", ["exists and is not a folder"]),
    ("afile/below", ["lies below the file"]),
    ("/proc/gmis-test-x", ["cannot be created here"]),
])
def test_unusable_output_paths_fail_before_work(dataset, tmp_path, capsys, engine, target,
                                                words):
    recipe = dataset.write()
    (tmp_path / "afile").write_text("keep")
    target = target if target.startswith("/") else str(tmp_path / target)
    code, _, err = run_cli(capsys, "run", str(recipe), "-o", target, "--quiet")
    assert code == 2
    one_line_error(err, *words)
    assert engine == []
    assert (tmp_path / "afile").read_text() == "keep"


def test_report_never_writes_into_the_folder_it_reports(tmp_path, capsys, monkeypatch):
    run = tmp_path / "run"
    run.mkdir()
    (run / "solution.csv").write_text("t\n1\n")
    (run / output_folder.MARKER).write_text("{}")
    monkeypatch.setitem(sys.modules, "gmis.report", types.SimpleNamespace(
        make_report=lambda *a, **k: pytest.fail("report must not start")))
    code, _, err = run_cli(capsys, "report", str(run), "-o", str(run))
    assert code == 2
    one_line_error(err, "holds the input")
    monkeypatch.chdir(run)
    code, _, err = run_cli(capsys, "report", str(run), "-o", ".")
    assert code == 2
    assert (run / "solution.csv").read_text() == "t\n1\n"


def test_simulate_overwrite_replaces_only_a_gmis_folder(tmp_path, capsys, monkeypatch):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("mine")
    monkeypatch.setitem(sys.modules, "gmis.simulate", types.SimpleNamespace(
        simulate_scenario=lambda *a, **k: pytest.fail("simulate must not start"),
        scenario_path=lambda name: str(REPO / "gmis" / "scenarios" / f"{name}.toml")))
    code, _, err = run_cli(capsys, "simulate", "default", "-o", str(mine), "--overwrite")
    assert code == 2
    one_line_error(err, "not written by gmis")
    assert (mine / "thesis.tex").read_text() == "mine"


def test_rtk_default_is_refused_before_anything_is_written(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, _, err = run_cli(capsys, "rtk", "default", "--quiet")
    assert code == 2
    one_line_error(err, "no RINEX")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(SystemExit):
        cli.main(["rtk", "--help"])
    assert "'default'" not in capsys.readouterr().out


def test_full_disk_is_one_line_and_nothing_is_left(tmp_path):
    target = tmp_path / "out"
    with pytest.raises(GmisInputError, match="No space left.*temporary files in .*TMPDIR"), \
            results_directory(target) as out:
        (out / "a.csv").write_text("partial")
        raise OSError(errno.ENOSPC, "No space left on device")
    assert list(tmp_path.iterdir()) == []


def test_a_full_disk_without_a_file_name_says_where_to_look(monkeypatch, capsys):
    """An ENOSPC raised by a write to an open spool file has no file name: the line says
    which disks (the results' and TMPDIR's) may be full (helper review 2026-12-06)."""
    def full(args):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(cli, "cmd_run", full)
    parser_main = cli.main
    assert parser_main(["run", "default", "-o", "x"]) in (2,)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left on device (the disk of the results folder" in err[0]
    assert "TMPDIR" in err[0]


def test_results_directory_refuses_to_replace_the_current_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine.txt").write_text("mine")
    with pytest.raises(GmisInputError, match="current directory"), results_directory("."):
        pass
    assert (tmp_path / "mine.txt").read_text() == "mine"


def test_non_finite_output_is_an_error_naming_the_column(tmp_path):
    with pytest.raises(GmisInputError, match=r"column 'e_m' at row 2"):
        write_csv(tmp_path / "x.csv", ["t", "e_m"], np.array([1.0, 2.0]),
                  np.array([0.5, np.nan]))
    assert not (tmp_path / "x.csv").exists()
    write_csv(tmp_path / "y.csv", ["t", "ratio"], np.array([1.0]), np.array([np.nan]),
              allow_nonfinite=["ratio"])


# ----------------------------------------------------------------------------- IMU gaps


def _imu_without(dataset, first_line: int, last_line: int):
    lines = dataset.imu.read_text().splitlines(keepends=True)
    del lines[first_line - 1:last_line]
    dataset.imu.write_text("".join(lines))


def test_imu_gap_longer_than_the_limit_is_an_error(dataset):
    _imu_without(dataset, 103, 250)              # 148 samples missing: 1.49 s
    with pytest.raises(GmisInputError, match=f"IMU gap of 1.490 s .* limit of {MAX_GAP_S:g} s"):
        load_dataset(load_recipe(dataset.write()))


def test_imu_gap_outside_the_time_window_does_not_matter(dataset):
    from tests.conftest import T0
    _imu_without(dataset, 203, 290)
    ds = load_dataset(load_recipe(dataset.write(dataset.modified("time", end_gps_s=T0 + 1.9))))
    assert ds.imu.t[-1] <= T0 + 1.9


def test_imu_gap_across_the_window_end_is_an_error(dataset):
    """A +3600 s jump inside the window leaves the rest of the window without IMU data."""
    from tests.conftest import T0
    lines = dataset.imu.read_text().splitlines(keepends=True)
    for i in range(152, len(lines)):               # file line 153 on: t + 3600 s
        cells = lines[i].split(",")
        cells[0] = repr(float(cells[0]) + 3600.0)
        lines[i] = ",".join(cells)
    dataset.imu.write_text("".join(lines))
    with pytest.raises(GmisInputError, match="runs past .time..end_gps_s"):
        load_dataset(load_recipe(dataset.write(dataset.modified("time", end_gps_s=T0 + 2.9))))


def test_short_imu_gap_is_flagged_in_summary_and_on_stderr(dataset, capsys):
    _imu_without(dataset, 103, 152)              # 50 samples missing: 0.51 s
    ds = load_dataset(load_recipe(dataset.write()))
    assert any("gap of 0.510 s" in w for w in ds.warnings)
    assert "gmis: warning: " in capsys.readouterr().err


# ----------------------------------------------------------------------------- plausibility


def _drive(n_s=200.0, rate=100.0, turn_deg_s=9.0):
    """Level car: 10 s straight, then turns at turn_deg_s (left) and straight, repeated;
    gyro rad/s about body up, accel = gravity; heading azimuth in rad."""
    t = 345600.0 + np.arange(0.0, n_s, 1.0 / rate)
    phase = ((t - t[0]) // 10.0) % 2 == 1
    omega = np.where(phase, math.radians(turn_deg_s), 0.0)
    gyro = np.column_stack([np.zeros_like(t), np.zeros_like(t), omega])
    accel = np.tile([0.0, 0.0, 9.80665], (t.size, 1))
    heading = -np.cumsum(omega) / rate              # azimuth clockwise: a left turn lowers it
    return t, gyro, accel, heading


def test_gyro_unit_is_checked_against_the_heading_change():
    t, gyro, accel, heading = _drive()
    names = ["gx", "gy", "gz"]
    plausibility.check_gyro_unit("imu.csv", t, gyro, accel, names, "rad/s", t[::20],
                                 heading[::20], "heading.csv")
    with pytest.raises(GmisInputError, match="rad/s data read as deg/s"):
        plausibility.check_gyro_unit("imu.csv", t, gyro * math.pi / 180, accel, names,
                                     "deg/s", t[::20], heading[::20], "heading.csv")
    with pytest.raises(GmisInputError, match="deg/s data read as rad/s"):
        plausibility.check_gyro_unit("imu.csv", t, gyro * 180 / math.pi, accel, names,
                                     "rad/s", t[::20], heading[::20], "heading.csv")


def test_gyro_unit_check_needs_turning():
    t, gyro, accel, heading = _drive(turn_deg_s=0.0)
    plausibility.check_gyro_unit("imu.csv", t, gyro * 100, accel, ["a", "b", "c"], "rad/s",
                                 t[::20], heading[::20], "heading.csv")


def test_accelerometer_unit_by_the_gravity_norm():
    t, _, accel, _ = _drive()
    plausibility.check_accel_unit("imu.csv", t, accel, ["ax", "ay", "az"], "m/s^2")
    with pytest.raises(GmisInputError, match="data in g read as m/s²"):
        plausibility.check_accel_unit("imu.csv", t, accel / 9.80665, ["ax"], "m/s^2")
    with pytest.raises(GmisInputError, match="data in m/s² read as g"):
        plausibility.check_accel_unit("imu.csv", t, accel * 9.80665, ["ax"], "g")


def test_absurd_imu_values_name_file_column_and_row():
    t, gyro, accel, _ = _drive(n_s=5.0)
    accel[123, 1] = 1e300
    with pytest.raises(GmisInputError, match=r"imu.csv: column 'ay'.*1e\+300.*row 124"):
        plausibility.check_imu_ranges("imu.csv", t, gyro, accel, ["gx", "gy", "gz"],
                                      ["ax", "ay", "az"])


def test_lever_arm_of_a_thousand_km_is_refused(dataset):
    recipe = dataset.write(dataset.modified("antennas", primary_lever_arm_m=[0.3, 1.0, 1e6]))
    with pytest.raises(GmisInputError, match="antennas.primary_lever_arm_m: 1e.06 m"):
        load_dataset(load_recipe(recipe))


def _gnss(lat_deg=43.7735, lon_deg=-79.5019, h=180.0, n=50, speed=10.0):
    t = 345600.0 + np.arange(n) * 0.2
    north = speed * (t - t[0])
    lat = np.radians(lat_deg) + north / 6371e3
    llh = np.column_stack([lat, np.full(n, np.radians(lon_deg)), np.full(n, h)])
    return types.SimpleNamespace(t=t, llh=llh, pos_sigma=np.full((n, 3), 0.02),
                                 vel_enu=np.tile([0.0, speed, 0.0], (n, 1)),
                                 vel_sigma=np.full((n, 3), 0.05))


ORIGIN = (math.radians(43.7735), math.radians(-79.5019), 180.0)


def test_gnss_checks_pass_on_a_plausible_drive():
    assert plausibility.check_gnss("gnss.csv", _gnss(), ORIGIN) == []


@pytest.mark.parametrize("change, words", [
    (lambda g: g.llh.__setitem__((slice(None), [0, 1]), g.llh[:, [1, 0]]), ["swapped"]),
    (lambda g: g.llh.__setitem__((7, 2), 1e12), ["'h_m'", "1e+12", "row 8"]),
    (lambda g: g.vel_enu.__setitem__((3, 1), 1e4), ["speed", "row 4"]),
    (lambda g: g.pos_sigma.__setitem__((5, 0), 1e9), ["position sigma", "absurd"]),
])
def test_gnss_checks_catch(change, words):
    g = _gnss()
    change(g)
    with pytest.raises(GmisInputError) as info:
        plausibility.check_gnss("gnss.csv", g, ORIGIN)
    for w in words:
        assert w in str(info.value), (w, str(info.value))


def test_heading_in_radians_is_recognised_against_the_gnss_course():
    g = _gnss()
    course = plausibility.gnss_course(g)
    as_deg = types.SimpleNamespace(t=g.t, heading=np.zeros(g.t.size),
                                   sigma=np.full(g.t.size, 0.01))
    assert plausibility.check_heading("heading.csv", as_deg, course) == []
    g.vel_enu[:] = [10.0 * math.sin(1.2), 10.0 * math.cos(1.2), 0.0]   # course 68.75°
    course = plausibility.gnss_course(g)
    in_rad = types.SimpleNamespace(t=g.t, heading=np.full(g.t.size, math.radians(1.2)),
                                   sigma=np.full(g.t.size, 0.01))
    with pytest.raises(GmisInputError, match="read as radians"):
        plausibility.check_heading("heading.csv", in_rad, course)


def _read_drive_imu():
    """The real drive's raw IMU ([g], [deg/s], ms) → t s, gyro rad/s, accel m/s²."""
    rows = []
    for line in require(DRIVE_BOULDER / "imu_1934.csv").read_text().splitlines():
        cells = line.split(",")
        if len(cells) == 7:
            try:
                rows.append([float(c) for c in cells])
            except ValueError:
                continue
    a = np.array(rows)
    return (a[:, 6] - a[0, 6]) / 1000.0, np.radians(a[:, 3:6]), a[:, :3] * 9.80665


def _read_drive_course(t_imu_start_gps):
    """GNSS course of the drive's RTKLIB .pos (vn/ve columns) in the IMU's time base."""
    t, ve, vn = [], [], []
    epoch = np.datetime64("1980-01-06T00:00:00", "ms")
    for line in require(DRIVE_BOULDER / "gnss_1934_sf.pos").read_text().splitlines():
        if line.startswith("%") or not line.strip():
            continue
        f = line.split()
        stamp = np.datetime64(f[0].replace("/", "-") + "T" + f[1], "ms")
        t.append((stamp - epoch) / np.timedelta64(1, "s") - t_imu_start_gps)
        vn.append(float(f[15]))
        ve.append(float(f[16]))
    g = types.SimpleNamespace(t=np.array(t), vel_enu=np.column_stack([ve, vn, np.zeros(len(t))]),
                              llh=np.zeros((len(t), 3)))
    return plausibility.gnss_course(g)


def test_no_check_misfires_on_the_real_drive_raw_imu():
    """imu_1934.csv: [g] and [deg/s], engine vibration ~2.6 deg/s std at idle; the turning
    measured by the gyro must match the GNSS course (scale 1), and the wrong units fail."""
    import struct
    t, gyro, accel = _read_drive_imu()
    assert np.degrees(gyro[:1000].std(axis=0)).max() > 2.0      # the vibration is there
    names_g, names_a = ["gyroX", "gyroY", "gyroZ"], ["accX", "accY", "accZ"]
    plausibility.check_imu_ranges("imu_1934.csv", t, gyro, accel, names_g, names_a)
    plausibility.check_accel_unit("imu_1934.csv", t, accel, names_a, "g")
    tag = require(DRIVE_BOULDER / "imu_1934.csv.tag").read_bytes()
    seconds, = struct.unpack_from("<I", tag, 64)
    frac, = struct.unpack_from("<d", tag, 68)
    start_gps = seconds + frac - 315964800.0 - 0.125           # README: −0.125 s delay
    course = _read_drive_course(start_gps)
    plausibility.check_gyro_unit("imu_1934.csv", t, gyro, accel, names_g, "deg/s", *course,
                                 "gnss_1934_sf.pos")
    with pytest.raises(GmisInputError, match="rad/s data read as deg/s"):
        plausibility.check_gyro_unit("imu_1934.csv", t, gyro / 57.29578, accel, names_g,
                                     "rad/s", *course, "gnss_1934_sf.pos")
    with pytest.raises(GmisInputError, match="beyond any land-vehicle IMU|turns at"):
        plausibility.check_imu_ranges("imu_1934.csv", t, gyro * 57.29578, accel, names_g,
                                      names_a)
    with pytest.raises(GmisInputError, match="data in g read as m/s²"):
        plausibility.check_accel_unit("imu_1934.csv", t, accel / 9.80665, names_a, "m/s^2")


@pytest.mark.slow
def test_checks_do_not_misfire_on_the_embedded_scenarios(tmp_path):
    """Every embedded scenario simulated (short) and loaded: no error, no warning."""
    pytest.importorskip("gmis.simulate")
    from gmis.simulate import simulate_scenario
    from gmis.simulate.scenario import load_scenario  # noqa: F401  (validates below)
    scen_dir = REPO / "gmis" / "scenarios"
    for scen in sorted(scen_dir.glob("*.toml")):
        out = tmp_path / scen.stem
        res = simulate_scenario(scen, out)
        ds = load_dataset(load_recipe(res.recipe_path))
        assert ds.warnings == (), (scen.name, ds.warnings)


# ----------------------------------------------------------------------------- RTK


@pytest.mark.parametrize("options, ok", [
    ({"elevation_mask_deg": 89}, True), ({"elevation_mask_deg": 0}, True),
    ({"elevation_mask_deg": 100}, False), ({"elevation_mask_deg": 90}, False),
    ({"elevation_mask_deg": -5}, False), ({"elevation_mask_deg": "high"}, False),
    ({"elevation_mask_deg": float("nan")}, False), ({"ratio_threshold": 0}, False),
    ({"sigma_code_m": -1}, False), ({"min_fix_satellites": 2.5}, False),
    ({"hold_tolerance_cycles": 0.7}, False), ({"continuous": 1}, False),
])
def test_rtk_option_ranges(options, ok):
    if ok:
        plausibility.check_rtk_options(options, "recipe.toml")
    else:
        with pytest.raises(GmisInputError, match=f"recipe.toml: rtk.{next(iter(options))}"):
            plausibility.check_rtk_options(options, "recipe.toml")


def _obs(path):
    from gnss.rinex import read_obs
    return read_obs(require(path), use_cache=False)


def test_rtk_inputs_nav_not_covering_the_observations_is_named():
    from gnss.rinex import read_nav
    rover, base = _obs(RTKLIB_TEST / "30400920.05o"), _obs(RTKLIB_TEST / "07590920.05o")
    plausibility.check_rtk_inputs(base, rover, read_nav(RTKLIB_TEST / "07590920.05n"))
    nav2010 = read_nav(require(RTKLIB_TEST / "brdc1820.10n"))
    with pytest.raises(GmisInputError, match=r"brdc1820.10n: the navigation file does not "
                                             r"cover the observations.*2010-07-01.*2005-04-02"):
        plausibility.check_rtk_inputs(base, rover, nav2010)


def test_rtk_inputs_without_common_epochs_or_with_one_epoch():
    import dataclasses

    from gnss.rinex import read_nav
    rover, base = _obs(RTKLIB_TEST / "30400920.05o"), _obs(RTKLIB_TEST / "07590920.05o")
    nav = read_nav(RTKLIB_TEST / "07590920.05n")

    def epochs(obs, sl):
        n = obs.t_gps.size
        return dataclasses.replace(obs, **{f.name: getattr(obs, f.name)[sl]
                                           for f in dataclasses.fields(obs)
                                           if isinstance(getattr(obs, f.name), np.ndarray)
                                           and getattr(obs, f.name).shape[:1] == (n,)})
    with pytest.raises(GmisInputError, match="no epoch in common with the base file"):
        plausibility.check_rtk_inputs(epochs(base, slice(60, None)), epochs(rover, slice(0, 60)),
                                      nav)
    with pytest.raises(GmisInputError, match="only 1 epoch"):
        plausibility.check_rtk_inputs(base, epochs(rover, slice(0, 1)), nav)


def test_base_position_far_from_the_base_file_header_is_refused():
    from gnss.rinex import read_nav
    rover, base = _obs(RTKLIB_TEST / "30400920.05o"), _obs(RTKLIB_TEST / "07590920.05o")
    nav = read_nav(RTKLIB_TEST / "07590920.05n")
    plausibility.check_rtk_inputs(base, rover, nav, base.approx_position_ecef, "recipe.toml")
    with pytest.raises(GmisInputError, match=r"recipe.toml: base: .* 300 km from the APPROX"):
        plausibility.check_rtk_inputs(base, rover, nav,
                                      base.approx_position_ecef + [300e3, 0, 0], "recipe.toml")


def test_epochs_without_solution_are_never_written_as_solutions():
    from gnss.rtk import RtkSolution
    n = 4
    sol = RtkSolution(t_gps=np.array([1.0, np.nan, 3.0, 4.0]),
                      ecef=np.tile([1e6, 2e6, 3e6], (n, 1)), llh=np.ones((n, 3)),
                      q=np.array([1, 0, 2, 2]), ratio=np.zeros(n),
                      n_sat=np.array([6, 0, 5, 0]), sigma_enu=np.ones((n, 3)),
                      ambiguities_fixed=np.zeros(n, int), ref_prn=np.zeros(n, int),
                      integers=[None] * n)
    kept = plausibility.solved_epochs(sol, sol.q > 0, "gmis rtk", "rover.obs")
    assert kept.t_gps.tolist() == [1.0, 3.0] and kept.n_sat.tolist() == [6, 5]
    assert len(kept.integers) == 2
    with pytest.raises(GmisInputError, match="no epoch has a solution"):
        plausibility.solved_epochs(sol, np.zeros(n, bool), "gmis rtk", "rover.obs")


def test_elevation_mask_89_is_no_solution_and_nothing_written(tmp_path):
    from gmis.rtk_job import run_rtk_recipe
    for name in ("30400920.05o", "07590920.05o", "07590920.05n"):
        require(RTKLIB_TEST / name)
    recipe = tmp_path / "recipe.toml"
    recipe.write_text(f"""[paths]
rover_obs = "{RTKLIB_TEST / '30400920.05o'}"
base_obs = "{RTKLIB_TEST / '07590920.05o'}"
nav = "{RTKLIB_TEST / '07590920.05n'}"
[base]
ecef_m = [-3976219.5082, 3382372.5671, 3652512.9849]
[rtk]
elevation_mask_deg = 89
""")
    with pytest.raises(GmisInputError, match="no epoch has a solution"):
        run_rtk_recipe(recipe, tmp_path / "out")
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- shared data


def test_no_fixed_machine_path_for_the_shared_data():
    machine_root = "/" + "work" + "/"   # spelled in parts: this file must not hold it either
    for rel in ("tests/shared_data.py", "datasets/rtklib-0759-3040/recipe.toml",
                "datasets/drive-boulder-0708/recipe.toml"):
        assert machine_root not in (REPO / rel).read_text(), rel
