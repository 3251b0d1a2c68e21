"""The gmis command line (one-line errors, exit codes, dispatch), all-or-nothing results
folders and the progress reporter. Engine modules are replaced by small fakes so these
tests check the CLI's own behaviour whatever else exists in this version."""

import io
import json
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from gmis import __version__, cli
from gmis.output_folder import MARKER
from gmis.progress import Progress
from gmis.readers import load_dataset
from gmis.recipe import load_recipe
from gmis.results import results_directory, write_csv, write_json, write_npz
from tests.conftest import T0

REPO = Path(__file__).resolve().parents[1]


def run_cli(capsys, *argv):
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(err: str, *words):
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("gmis: error: "), err
    assert "Traceback" not in err
    for word in words:
        assert word in lines[0], (word, err)


@pytest.fixture
def fake_pipeline(monkeypatch):
    """gmis.pipeline stand-in that really loads the dataset (so bad data files surface
    through the CLI) and returns a summary dict."""
    calls = []

    def run_recipe(recipe_path, results_dir, progress=None, **options):
        ds = load_dataset(load_recipe(recipe_path))
        with results_directory(results_dir) as out:
            write_json(out / "summary.json", {"imu_samples": ds.imu.t.size})
        progress(1.0)
        calls.append((Path(recipe_path), Path(results_dir)))
        return {"imu_samples": ds.imu.t.size, "position_rms_m": np.float64(0.0123),
                "per_axis": {"east_m": 0.01, "north_m": 0.02}, "big": np.zeros(100)}

    module = types.ModuleType("gmis.pipeline")
    module.run_recipe = run_recipe
    monkeypatch.setitem(sys.modules, "gmis.pipeline", module)
    return calls


# ----------------------------------------------------------------------------- help


def test_help_and_version(capsys):
    with pytest.raises(SystemExit) as info:
        cli.main(["--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    for command in ("simulate", "run", "vce", "report", "rtk"):
        assert command in out
    with pytest.raises(SystemExit):
        cli.main(["--version"])
    assert capsys.readouterr().out.strip() == f"gmis {__version__}"


@pytest.mark.parametrize("command, words", [
    ("simulate", ["scenario", "--seed", "recipe.toml"]),
    ("run", ["GMIKF", "m/s", "deg", "default"]),
    ("vce", ["variance component", "noise_override"]),
    ("report", ["N(0,1)", "report"]),
    ("rtk", ["LAMBDA", "ratio"]),
])
def test_subcommand_help(capsys, command, words):
    with pytest.raises(SystemExit) as info:
        cli.main([command, "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    for word in words:
        assert word in out, (command, word)


# ----------------------------------------------------------------------------- bad input


# Malformed inputs through `gmis run`: (recipe change or data-file change, words in the line).
def _recipe_case(section, changes):
    return lambda ds: ds.write(ds.modified(section, **changes))


def _doc_case(extra):
    return lambda ds: ds.write(dict(ds.doc, **extra))


def _imu_text_case(edit):
    def make(ds):
        lines = ds.imu.read_text().splitlines()
        edit(lines)
        ds.imu.write_text("\n".join(lines) + "\n")
        return ds.write()
    return make


def _cell(lines, row, col, value):
    cells = lines[row].split(",")
    cells[col] = value
    lines[row] = ",".join(cells)


# imu.csv line 1 is a comment, line 2 the header, lines[k] is file line k+1.
CLI_CASES = {
    "unknown key": (_recipe_case("noise", {"gyro_deg": [1, 1, 1]}),
                    ["recipe.toml", "noise.gyro_deg", "gyro_deg_s"]),
    "unknown section": (_doc_case({"filtre": {"mode": "loose"}}),
                        ["recipe.toml", "filtre", "filter"]),
    "missing file": (_recipe_case("paths", {"heading": "heading2.csv"}),
                     ["recipe.toml", "paths.heading", "heading2.csv"]),
    "wrong unit": (_recipe_case("imu", {"accel_unit": "mg"}), ["recipe.toml", "imu.accel_unit"]),
    "vector length": (_recipe_case("antennas", {"primary_lever_arm_m": [0.1, 0.2, 1.5, 0.0]}),
                      ["recipe.toml", "antennas.primary_lever_arm_m", "got 4"]),
    "bad axes": (_recipe_case("imu", {"axes": ["y", "y", "z"]}), ["recipe.toml", "imu.axes"]),
    "start >= end": (_recipe_case("time", {"start_gps_s": T0 + 2, "end_gps_s": T0 + 1}),
                     ["recipe.toml", "time.end_gps_s"]),
    "empty IMU file": (_imu_text_case(lambda lines: lines.clear()), ["imu.csv", "empty file"]),
    "missing column": (_imu_text_case(lambda lines: lines.__setitem__(
        1, lines[1].replace("accel_y", "acc_y"))), ["imu.csv", "missing column 'accel_y'"]),
    "NaN value": (_imu_text_case(lambda lines: _cell(lines, 40, 2, "NaN")),
                  ["imu.csv", "non-finite", "line 41"]),
    "time backwards": (_imu_text_case(lambda lines: _cell(lines, 50, 0, repr(T0))),
                       ["imu.csv", "time goes backwards at line 51"]),
    "duplicate time": (_imu_text_case(lambda lines: _cell(lines, 50, 0, lines[49].split(",")[0])),
                       ["imu.csv", "duplicate time at line 51"]),
    "non-numeric cell": (_imu_text_case(lambda lines: _cell(lines, 60, 5, "1.0.0")),
                         ["imu.csv", "line 61", "'1.0.0'"]),
    "rate mismatch": (_recipe_case("imu", {"rate_hz": 200.0}),
                      ["imu.csv", "measured IMU rate 100 Hz", "200 Hz"]),
}


@pytest.mark.parametrize("case", sorted(CLI_CASES))
def test_bad_input_is_one_line_and_exit_2(dataset, capsys, fake_pipeline, tmp_path, case):
    make, words = CLI_CASES[case]
    recipe = make(dataset)
    code, _out, err = run_cli(capsys, "run", str(recipe), "-o", str(tmp_path / "results"),
                             "--quiet")
    assert code == 2
    assert_one_line_error(err, *words)
    assert not (tmp_path / "results").exists()
    assert fake_pipeline == []


def test_subprocess_entry_point_prints_no_traceback(dataset, tmp_path):
    recipe = dataset.write(dataset.modified("imu", gyro_unit="degrees/s"))
    proc = subprocess.run([sys.executable, "-m", "gmis", "run", str(recipe)],
                          capture_output=True, text=True, cwd=tmp_path, timeout=120,
                          check=False)
    assert proc.returncode == 2
    assert_one_line_error(proc.stderr, str(recipe), "imu.gyro_unit", "deg/s")
    proc = subprocess.run([sys.executable, "-m", "gmis", "report", str(tmp_path / "none")],
                          capture_output=True, text=True, cwd=tmp_path, timeout=120,
                          check=False)
    assert proc.returncode == 2
    assert_one_line_error(proc.stderr, "none", "results folder not found")


def test_unreadable_user_path_is_exit_2(capsys, tmp_path):
    code, _, err = run_cli(capsys, "simulate", str(tmp_path / "nope.toml"))
    assert code == 2
    assert_one_line_error(err, "nope.toml")


# ----------------------------------------------------------------------------- dispatch


def test_run_writes_results_and_prints_summary(dataset, capsys, fake_pipeline, tmp_path):
    out_dir = tmp_path / "res"
    code, out, err = run_cli(capsys, "run", str(dataset.write()), "-o", str(out_dir), "--quiet")
    assert code == 0, err
    assert json.loads((out_dir / "summary.json").read_text()) == {"imu_samples": 300}
    assert f"results written to {out_dir}" in out
    assert "imu_samples: 300" in out
    assert "position_rms_m: 0.0123" in out
    assert "per_axis: east_m 0.01, north_m 0.02" in out
    assert "big" not in out
    assert err == ""


def test_summary_lines_put_errors_first_and_fold_small_tables():
    summary = {"dataset": "x", "duration_s": 574.0, "timing_s": {"real_time_ratio": 600.0},
               "errors_vs_reference": {"position": {"e": {"rms": 0.0771, "max": 0.5,
                                                          "unit": "m"}}},
               "samples": np.arange(10), "nested": {"deep": {"n": np.int64(3)}}}
    lines = cli.summary_lines(summary)
    assert lines[0] == "  errors_vs_reference.position.e: rms 0.0771, max 0.5 m"
    assert "  duration_s: 574" in lines and "  timing_s: real_time_ratio 600" in lines
    assert "  nested.deep: n 3" in lines
    assert not any("samples" in line for line in lines)
    many = cli.summary_lines({f"k{i}": [1.0] * 7 + [i] for i in range(3)} |
                             {f"v{i:02d}": {"a": [0] * 7, "b": i} for i in range(50)})
    assert len(many) == 41 and many[-1] == "  ... 10 more figures in the results folder"


def test_summary_heading_wraps_at_360():
    lines = cli.summary_lines({"alignment": {"heading_deg": 359.9972, "pitch_deg": 1.5},
                               "final_heading_deg": 12.3456})
    assert "  alignment: heading_deg 0.00, pitch_deg 1.5" in lines
    assert "  final_heading_deg: 12.35" in lines


def test_missing_engine_module_is_exit_3(dataset, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "gmis.pipeline", None)
    code, _out, err = run_cli(capsys, "run", str(dataset.write()))
    assert code == 3
    assert err.strip() == "gmis run: not yet available in this version"
    monkeypatch.setitem(sys.modules, "gmis.rtk_job", None)
    assert run_cli(capsys, "rtk", str(dataset.write()))[0] == 3


def test_missing_dependency_inside_a_module_is_not_hidden(tmp_path, monkeypatch):
    (tmp_path / "gmis_fake_engine.py").write_text("import gmis_no_such_dependency\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ModuleNotFoundError, match="gmis_no_such_dependency"):
        cli._import("gmis_fake_engine", "fake")
    with pytest.raises(cli._NotAvailable):
        cli._import("gmis_fake_engine_absent.job", "fake")


def test_missing_dependency_is_one_line_exit_4(dataset, capsys, monkeypatch, tmp_path):
    (tmp_path / "gmis_fake_engine.py").write_text("import gmis_no_such_dependency\n")
    monkeypatch.syspath_prepend(str(tmp_path))

    def handler(_args):
        return cli._import("gmis_fake_engine", "fake")

    monkeypatch.setattr(cli, "cmd_run", handler)
    code, out, err = run_cli(capsys, "run", str(dataset.write()))
    assert code == cli.EXIT_MISSING_DEPENDENCY == 4
    assert out == ""
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "'gmis_no_such_dependency' is not installed" in err


@pytest.mark.parametrize("command, module, function", [
    ("vce", "vce.job", "tune_recipe"), ("rtk", "gmis.rtk_job", "run_rtk_recipe")])
def test_vce_and_rtk_dispatch(dataset, capsys, monkeypatch, tmp_path, command, module,
                              function):
    seen = {}

    def engine(recipe_path, results_dir, progress=None, **options):
        seen["args"] = (Path(recipe_path), Path(results_dir), callable(progress))
        seen["options"] = options
        return {"iterations": 4, "converged": True}

    fake = {function: engine}
    if command == "rtk":
        fake["read_rtk_recipe"] = lambda path: seen.setdefault("validated", Path(path))
    monkeypatch.setitem(sys.modules, module, types.SimpleNamespace(**fake))
    recipe = dataset.write()
    code, out, err = run_cli(capsys, command, str(recipe), "-o", str(tmp_path / "o"))
    assert code == 0, err
    assert seen["args"] == (recipe, tmp_path / "o", True)
    assert "iterations: 4" in out and "converged: True" in out
    if command == "vce":
        assert seen["options"] == {"max_iterations": 30, "tol": 0.02, "min_redundancy": 0.1,
                                   "estimate_drifts": False}


def test_report_dispatch(capsys, monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "gmis.report", types.SimpleNamespace(
        make_report=lambda results_dir, **options: {"figures": 7, "folder": str(results_dir)}))
    code, out, _ = run_cli(capsys, "report", str(tmp_path))
    assert code == 0
    assert "figures: 7" in out


def test_run_default_simulates_once_then_reuses(dataset, capsys, monkeypatch, tmp_path,
                                                fake_pipeline):
    work = tmp_path / "cwd"
    work.mkdir()
    monkeypatch.chdir(work)
    simulated = []

    def simulate_scenario(scenario, out_dir, seed=None, progress=None):
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True)
        for source in (dataset.imu, dataset.gnss, dataset.heading, dataset.reference):
            (out_dir / source.name).write_bytes(source.read_bytes())
        recipe = out_dir / "recipe.toml"
        recipe.write_bytes(dataset.write().read_bytes())
        simulated.append((scenario, seed))
        return types.SimpleNamespace(dataset_dir=out_dir, recipe_path=recipe)

    monkeypatch.setitem(sys.modules, "gmis.simulate", types.SimpleNamespace(
        simulate_scenario=simulate_scenario, default_scenario_path=lambda: "default.toml"))
    for _ in range(2):
        code, _out, err = run_cli(capsys, "run", "default", "--quiet")
        assert code == 0, err
    assert simulated == [("default.toml", None)]
    assert [c[1] for c in fake_pipeline] == [Path("gmis-default/results")] * 2
    assert (work / "gmis-default" / "results" / "summary.json").is_file()


def test_simulate_dispatch(capsys, monkeypatch, tmp_path):
    scenario = tmp_path / "s.toml"
    scenario.write_text("[scenario]\nname = 'x'\n")
    seen = {}

    def simulate_scenario(path, out_dir, seed=None, progress=None):
        seen.update(path=Path(path), out=Path(out_dir), seed=seed)
        return types.SimpleNamespace(dataset_dir=Path(out_dir),
                                     recipe_path=Path(out_dir) / "recipe.toml")

    monkeypatch.setitem(sys.modules, "gmis.simulate", types.SimpleNamespace(
        simulate_scenario=simulate_scenario))
    code, out, _ = run_cli(capsys, "simulate", str(scenario), "-o", str(tmp_path / "d"),
                           "--seed", "7")
    assert code == 0
    assert seen == {"path": scenario, "out": tmp_path / "d", "seed": 7}
    assert f"dataset written to {tmp_path / 'd'}" in out


# ----------------------------------------------------------------------------- results


def test_results_directory_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "results"
    with pytest.raises(RuntimeError, match="boom"), results_directory(target) as out:
        write_csv(out / "a.csv", ["t", "x"], np.arange(3.0), np.ones(3))
        raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_results_directory_of_the_python_api_keeps_the_cli_rules(tmp_path):
    """The Python API (no CLI claim) never replaces a folder gmis did not write, nor one
    into which the user put files of their own; its own earlier output it replaces."""
    from gmis.errors import GmisInputError

    user = tmp_path / "mydata"
    user.mkdir()
    (user / "recipe.toml").write_text("[dataset]\n")
    with pytest.raises(GmisInputError, match="not written by gmis"), \
            results_directory(user) as out:
        pass
    assert sorted(p.name for p in user.iterdir()) == ["recipe.toml"]
    target = tmp_path / "out"
    with results_directory(target) as out:
        write_json(out / "summary.json", {"a": 1})
    assert json.loads((target / MARKER).read_text())["files"] == ["summary.json"]
    (target / "notes.txt").write_text("mine")
    with pytest.raises(GmisInputError, match="files gmis did not write \\(notes.txt\\)"), \
            results_directory(target) as out:
        pass
    assert (target / "notes.txt").read_text() == "mine"
    (target / "notes.txt").unlink()
    (target / "report").mkdir()                     # a gmis report inside: may be replaced
    (target / "report" / "report.html").write_text(
        '<meta name="generator" content="gmis report">')
    with results_directory(target) as out:
        write_json(out / "summary.json", {"a": 2})
    assert json.loads((target / "summary.json").read_text()) == {"a": 2}


def test_a_command_does_not_replace_another_commands_folder(tmp_path):
    from gmis import output_folder
    from gmis.errors import GmisInputError

    target = tmp_path / "res"
    output_folder.check_and_claim(target, "run")
    try:
        with results_directory(target) as out:
            write_json(out / "summary.json", {"a": 1})
    finally:
        output_folder.release(target)
    assert json.loads((target / MARKER).read_text())["command"] == "run"
    with pytest.raises(GmisInputError, match=r"results of `gmis run`"):
        output_folder.check_output_folder(target, "vce")
    assert output_folder.check_output_folder(target, "run") == target.resolve()
    report = tmp_path / "rep"                       # signed, not marked: still `report`'s
    report.mkdir()
    (report / "report.html").write_text('<meta name="generator" content="gmis report">')
    with pytest.raises(GmisInputError, match=r"results of `gmis report`"):
        output_folder.check_output_folder(report, "run")
    assert output_folder.check_output_folder(report, "report") == report.resolve()


def test_results_directory_replaces_previous_results_only_on_success(tmp_path):
    target = tmp_path / "results"
    with results_directory(target) as out:
        write_json(out / "summary.json", {"rms": np.float32(0.5), "bad": np.nan,
                                          "v": np.arange(2)})
        assert not target.exists()
    assert json.loads((target / "summary.json").read_text()) == {"rms": 0.5, "bad": None,
                                                                  "v": [0, 1]}
    with pytest.raises(KeyboardInterrupt), results_directory(target) as out:
        (out / "other.txt").write_text("partial")
        raise KeyboardInterrupt
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results"]
    # the Python API's folders carry the marker too (command "python", the files listed)
    assert sorted(p.name for p in target.iterdir()) == [MARKER, "summary.json"]
    with results_directory(target) as out:
        write_npz(out / "arrays.npz", x=np.arange(4.0))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results"]
    assert sorted(p.name for p in target.iterdir()) == [MARKER, "arrays.npz"]
    assert np.load(target / "arrays.npz")["x"].tolist() == [0.0, 1.0, 2.0, 3.0]


def test_write_csv_layout(tmp_path):
    path = write_csv(tmp_path / "x.csv", ["t", "e", "n", "u"], np.array([1.0, 2.0]),
                     np.array([[0.5, 0.25, 0.125], [1.0, 2.0, 3.0]]))
    assert path.read_text().splitlines() == ["t,e,n,u", "1,0.5,0.25,0.125", "2,1,2,3"]
    with pytest.raises(ValueError, match="header"):
        write_csv(tmp_path / "y.csv", ["t"], np.ones(2), np.ones(2))


# ----------------------------------------------------------------------------- progress


class FakeTTY(io.StringIO):
    def isatty(self):
        return True


def test_progress_draws_rate_limited_on_tty_and_is_silent_otherwise():
    now = [0.0]
    stream = FakeTTY()
    with Progress(1000, "filter", stream=stream, clock=lambda: now[0]) as p:
        for _ in range(100):
            now[0] += 0.01  # 100 updates over 1 s → about 5 redraws
            p.update(5)
        assert "50.0%" in p.line() and "500/s" in p.line() and "ETA 00:01" in p.line()
    text = stream.getvalue()
    assert 4 <= text.count("\r") <= 7
    assert text.rstrip().endswith("\033[K") and "100.0%" in text and text.endswith("\n")

    quiet = FakeTTY()
    with Progress(10, stream=quiet, quiet=True) as p:
        p.update(10)
    not_tty = io.StringIO()
    with Progress(10, stream=not_tty) as p:
        p.update(10)
    assert quiet.getvalue() == "" and not_tty.getvalue() == ""


def test_progress_as_fraction_callback():
    stream = FakeTTY()
    p = Progress(stream=stream, clock=lambda: 2.0, min_interval=0.0)
    p.start = 0.0
    p(0.25)
    assert "25.0%" in stream.getvalue() and "ETA 00:06" in stream.getvalue()
    p.close()


def test_readme_quick_start_and_ci_run_the_same_test_command():
    readme = (REPO / "README.md").read_text()
    quick = readme.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    commands = [block.strip() for block in quick.split("```bash")[1:]]
    commands = [block.split("```", 1)[0].strip() for block in commands]
    assert commands[0] == "pip install -e . && gmis run default"
    assert len(commands) == 2
    ci = (REPO / ".ci" / "run").read_text().splitlines()
    assert "set -euo pipefail" in ci
    assert ci[-1].strip() == commands[1]


def test_every_command_accepts_quiet():
    """`gmis report … --quiet` was refused (helper review 2026-12-06): every command takes
    the flag a script passes to all of them."""
    parser = cli.build_parser()
    for argv in (["report", "res"], ["run", "r.toml"], ["vce", "r.toml"], ["rtk", "r.toml"],
                 ["outages", "r.toml"], ["simulate", "s.toml"], ["calibrate", "a.csv"]):
        assert parser.parse_args([*argv, "--quiet"]).quiet is True
