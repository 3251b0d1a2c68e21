"""`gmis batch` (gmis.batch): jobs expanded from a spec, run on a dask LocalCluster with
2 workers and serially with the same files; a failing job is one row, the others kept."""

import tomllib
from pathlib import Path

import pytest

from benchmarks.compare_outputs import compare
from gmis.batch import expand_jobs, load_spec, run_batch
from gmis.errors import GmisInputError
from tests.simulated_drives import default_scenario_cut


def _short_scenario(path: Path) -> Path:
    """The default scenario cut to ~30 s, as a TOML file."""
    sc = default_scenario_cut(30.0)
    kept = sc["segment"]
    lines = []

    def emit(prefix, table):
        scalars = {k: v for k, v in table.items() if not isinstance(v, (dict, list))
                   or (isinstance(v, list) and not (v and isinstance(v[0], dict)))}
        if prefix:
            lines.append(f"[{prefix}]")
        for k, v in scalars.items():
            lines.append(f"{k} = {_toml(v)}")
        for k, v in table.items():
            if isinstance(v, dict):
                emit(f"{prefix}.{k}" if prefix else k, v)
            elif isinstance(v, list) and v and isinstance(v[0], dict):
                for item in v:
                    lines.append(f"[[{prefix + '.' if prefix else ''}{k}]]")
                    for kk, vv in item.items():
                        lines.append(f"{kk} = {_toml(vv)}")

    emit("", sc)
    path.write_text("\n".join(lines) + "\n")
    assert tomllib.loads(path.read_text())["segment"] == kept
    return path


def _toml(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return repr(v)


@pytest.fixture(scope="module")
def spec(tmp_path_factory):
    root = tmp_path_factory.mktemp("batch")
    _short_scenario(root / "short.toml")
    (root / "spec.toml").write_text(
        '[batch]\nworkers = 2\n\n'
        '[[job]]\ncommand = "simulate"\nscenario = "short.toml"\nseeds = [11, 12, 13]\n'
        'then = "run"\n\n'
        '[[job]]\ncommand = "run"\nrecipe = "missing/recipe.toml"\n')
    return root / "spec.toml"


def test_expand_jobs(spec):
    batch, jobs = load_spec(spec)
    assert batch["workers"] == 2
    assert [j.name for j in jobs] == ["simulate-short-seed11", "simulate-short-seed12",
                                      "simulate-short-seed13", "run-missing"]
    assert jobs[0].then == "run" and jobs[0].seed == 11
    with pytest.raises(GmisInputError, match=r"job\[0\]\.command"):
        expand_jobs({"job": [{"command": "fly"}]})
    with pytest.raises(GmisInputError, match=r"job\[0\]\.recipes"):
        expand_jobs({"job": [{"command": "run"}]})


def test_cluster_equals_serial_and_keeps_the_others(spec, tmp_path):
    serial = run_batch(spec, output=tmp_path / "serial", serial=True, quiet=True)
    dist = run_batch(spec, output=tmp_path / "dask", workers=2, quiet=True)
    assert [r["name"] for r in dist] == [r["name"] for r in serial]
    assert [r["status"] for r in dist] == ["ok", "ok", "ok", "failed"]
    assert "missing" in dist[3]["error"] and "\n" not in dist[3]["error"]
    for r in dist[:3]:
        name = r["name"]
        assert compare(tmp_path / "serial" / name, tmp_path / "dask" / name, tol=0.0)
        assert r["h_rms_m"] == next(s for s in serial if s["name"] == name)["h_rms_m"]
    # different seeds give different runs
    assert dist[0]["h_rms_m"] != dist[1]["h_rms_m"]
    table = (tmp_path / "dask" / "batch.csv").read_text().splitlines()
    assert len(table) == 5 and table[0].startswith("name,command")
    # a re-run into the same folder replaces it (its marker lists batch.csv / batch.json)
    again = run_batch(spec, output=tmp_path / "serial", serial=True, quiet=True)
    assert [r["status"] for r in again] == [r["status"] for r in serial]


def test_a_users_folder_at_a_job_path_is_refused_before_any_work(spec, tmp_path):
    """A job replaces <root>/<name>: a folder of that name holding files gmis did not
    write stops the batch before anything runs, and its files stay."""
    from gmis.output_folder import MARKER, mark

    root = tmp_path / "out"
    keep = root / "simulate-short-seed12" / "notes.txt"
    keep.parent.mkdir(parents=True)
    keep.write_text("field notes")
    with pytest.raises(GmisInputError, match="not written by gmis") as unmarked_root:
        run_batch(spec, output=root, serial=True, quiet=True)
    assert "simulate-short-seed12" not in str(unmarked_root.value.source)
    mark(root, "batch")                       # the root of an earlier batch
    with pytest.raises(GmisInputError, match="not written by gmis") as user_folder:
        run_batch(spec, output=root, serial=True, quiet=True)
    assert str(user_folder.value.source).endswith("simulate-short-seed12")
    assert keep.read_text() == "field notes"
    assert sorted(p.name for p in root.iterdir()) == [MARKER, "simulate-short-seed12"]


def test_a_batch_root_that_holds_the_spec_is_refused(spec):
    with pytest.raises(GmisInputError, match="holds the input"):
        run_batch(spec, output=spec.parent, serial=True, quiet=True)


@pytest.mark.parametrize("options, message", [
    ("{ output_rate = 5.0 }", r"job\[0\]\.options\.output_rate: unknown option for run"),
    ("{ output_rate_hz = -1.0 }", r"job\[0\]\.options\.output_rate_hz: expected a number"),
    ("{ smooth = 1 }", r"job\[0\]\.options\.smooth: expected true or false"),
])
def test_job_options_are_checked_before_any_job_runs(tmp_path, options, message):
    """A misspelt or mistyped option was a TypeError inside every job (helper review
    2026-12-06); now one line naming it, before anything runs."""
    spec = tmp_path / "spec.toml"
    spec.write_text(f'[[job]]\ncommand = "run"\nrecipe = "default"\noptions = {options}\n')
    with pytest.raises(GmisInputError, match=message):
        load_spec(spec)
    vce = tmp_path / "vce.toml"
    vce.write_text('[[job]]\ncommand = "simulate"\nscenario = "default"\nthen = "vce"\n'
                   'options = { max_iterations = "three" }\n')
    with pytest.raises(GmisInputError, match=r"options\.max_iterations: expected an integer"):
        load_spec(vce)


def test_a_failed_job_says_its_folder_holds_earlier_results(tmp_path):
    """A job that fails leaves an earlier batch's folder in place (never deleted); its row
    says so instead of pointing at those results as if they were this run's."""
    from gmis.batch import Job, run_job

    folder = tmp_path / "run-x"
    folder.mkdir()
    (folder / "summary.json").write_text("{}")
    row = run_job(Job("run-x", "run", recipe=str(tmp_path / "missing.toml")), str(tmp_path))
    assert row["status"] == "failed"
    assert "still holds an earlier batch's results" in row["error"]
    assert (folder / "summary.json").read_text() == "{}"
