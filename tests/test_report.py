"""gmis report: every figure/table of a run + VCE report is written, statistics use the
full residual sets, report.html links only to files it ships, bad folders give one
GmisInputError (CLI: exit status 2, one line)."""

from __future__ import annotations

import csv
import json
import shutil
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import urlparse

import numpy as np
import pytest
from scipy import stats

from gmis.cli import main as cli_main
from gmis.errors import GmisInputError
from gmis.pipeline import run_recipe
from gmis.report import make_report
from gmis.report.plotting import decimate_for_drawing, minmax_indices
from gmis.results import write_npz
from tests.conftest import DatasetFiles
from vce.job import tune_recipe

RUN_FIGURES = {"trajectory", "speed", "solution_sigma", "imu_biases", "imu_scale_factors",
               "errors_vs_reference", "innovation_histograms", "innovations_gyro",
               "innovations_accel", "innovations_gnss_position", "innovations_heading"}
VCE_FIGURES = {"residual_histograms_measurement", "residual_histograms_process", "vce_sigma",
               "vce_sigma0", "vce_redundancy", "vce_windows"}
RUN_TABLES = {"error_statistics", "innovation_statistics", "blunders"}
VCE_TABLES = {"vce_table", "vce_blunders", "residual_statistics"}


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """A real `gmis run` and `gmis vce` folder from the pipeline on the 3-s test dataset
    (IMU, GNSS position, heading, reference) below one parent folder."""
    root = tmp_path_factory.mktemp("report")
    ds = DatasetFiles(root)
    recipe = ds.write(ds.modified("filter", static_alignment_s=1.0))
    run_recipe(recipe, root / "results" / "run")
    tune_recipe(recipe, root / "results" / "vce", max_iterations=2)
    return root / "results"


class Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.targets = []

    def handle_starttag(self, tag, attrs):
        for key, value in attrs:
            if key in ("src", "href") and value is not None and not value.startswith("#"):
                self.targets.append(value)


def html_targets(page: Path) -> list:
    parser = Links()
    parser.feed(page.read_text(encoding="utf-8"))
    return parser.targets


def read_rows(path: Path) -> list:
    with open(path, encoding="utf-8", newline="") as fh:
        return list(csv.DictReader(fh))


def stems(folder: Path, ext: str) -> set:
    return {p.stem for p in folder.glob(f"*.{ext}")}


@pytest.fixture(scope="module")
def report(results, tmp_path_factory):
    """`gmis report <run> --vce <vce> -o <out> --svg` through the CLI."""
    out = tmp_path_factory.mktemp("rep") / "report"
    code = cli_main(["report", str(results / "run"), "--vce", str(results / "vce"),
                     "-o", str(out), "--svg"])
    assert code == 0
    return out


def test_run_plus_vce_report_has_every_figure_and_table(results, report):
    assert stems(report / "figures", "png") == RUN_FIGURES | VCE_FIGURES
    assert stems(report / "figures", "svg") == RUN_FIGURES | VCE_FIGURES
    assert stems(report / "tables", "csv") == RUN_TABLES | VCE_TABLES
    for png in (report / "figures").glob("*.png"):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    # the VCE table has one row per (iteration, component) of vce_history.csv
    hist = read_rows(results / "vce" / "vce_history.csv")
    table = read_rows(report / "tables" / "vce_table.csv")
    assert [(r["iteration"], r["component"]) for r in table] == \
        [(r["iteration"], r["component"]) for r in hist]
    # blunder counts are those of records.npz
    rec = np.load(results / "run" / "records.npz")
    rows = read_rows(report / "tables" / "blunders.csv")
    assert [r["slot"] for r in rows] == list(rec["slot_names"])
    assert [int(r["rejected"]) for r in rows] == list((rec["rejected"] != 0).sum(axis=0))
    assert [int(r["measurements"]) for r in rows] == list(np.isfinite(rec["innov"]).sum(axis=0))
    # error statistics are those of summary.json
    summary = json.loads((results / "run" / "summary.json").read_text())
    errs = {(r["epochs"], r["quantity"], r["axis"]): r
            for r in read_rows(report / "tables" / "error_statistics.csv")}
    ref = summary["errors_vs_reference"]["attitude"]["heading"]
    assert float(errs[("all epochs", "attitude", "heading")]["RMS"]) == \
        pytest.approx(ref["rms"], rel=1e-9)


def test_html_references_only_shipped_files(report):
    page = report / "report.html"
    targets = html_targets(page)
    assert targets
    root = report.resolve()
    for target in targets:
        url = urlparse(target)
        assert not url.scheme and not url.netloc, target
        path = (report / url.path).resolve()
        assert path.is_file() and root in path.parents, target
    shipped = {p.relative_to(report).as_posix() for p in report.rglob("*") if p.is_file()}
    assert shipped - {"report.html"} == set(targets)
    text = page.read_text(encoding="utf-8")
    assert "<script" not in text and "http://" not in text and "https://" not in text
    for unit in ("(m)", "(m/s)", "(deg)", "(deg/s)"):
        assert unit in text


def test_innovation_ks_on_all_accepted_epochs(results, report):
    rows = {r["slot"]: r for r in read_rows(report / "tables" / "innovation_statistics.csv")}
    rec = np.load(results / "run" / "records.npz")
    checked = 0
    for i, name in enumerate(rec["slot_names"]):
        d, var = rec["innov"][:, i], rec["innov_var"][:, i]
        ok = np.isfinite(d) & (var > 0) & (rec["rejected"][:, i] == 0)
        if ok.sum() == 0:
            continue
        z = d[ok] / np.sqrt(var[ok])
        assert int(rows[str(name)]["n"]) == z.size
        assert float(rows[str(name)]["KS D"]) == pytest.approx(
            stats.kstest(z, "norm").statistic, rel=1e-8)
        checked += 1
    assert checked >= 7          # IMU (6) + position/heading slots
    had_data = {str(n) for i, n in enumerate(rec["slot_names"])
                if np.isfinite(rec["innov"][:, i]).any()}
    assert set(rows) == had_data   # no empty panels for sensors the run did not have


def test_run_only_and_vce_only_folders(results, tmp_path):
    run_summary = make_report(results / "run", out_dir=tmp_path / "r")
    assert run_summary["vce_dir"] is None and run_summary["residual_ks"] == {}
    assert stems(tmp_path / "r" / "figures", "png") == RUN_FIGURES
    assert stems(tmp_path / "r" / "tables", "csv") == RUN_TABLES
    # VCE folder alone, through the CLI, default report folder <results>/report
    copy = tmp_path / "vcecopy"
    shutil.copytree(results / "vce", copy)
    assert cli_main(["report", str(copy)]) == 0
    assert stems(copy / "report" / "figures", "png") == VCE_FIGURES
    assert stems(copy / "report" / "tables", "csv") == VCE_TABLES


def test_ks_statistic_uses_every_residual(results, tmp_path):
    """Residuals in which every 10th sample is large: a decimated subset (stride 10, or
    any fixed share) gives a very different KS statistic from the full set."""
    vce = tmp_path / "vce"
    shutil.copytree(results / "vce", vce)
    first = dict(np.load(vce / "residuals_first.npz"))
    rng = np.random.default_rng(7)
    final, expected = {}, {}
    n = 50_000
    for key in first:
        name, _, suffix = key.rpartition("__")
        if suffix != "w":
            continue
        w = rng.standard_normal(n)
        w[::10] *= 6.0
        final[f"{name}__t"] = 345600.0 + 0.01 * np.arange(n)
        final[f"{name}__w"] = w
        expected[name] = w
    write_npz(vce / "residuals_final.npz", **final)
    summary = make_report(vce, out_dir=tmp_path / "rep")
    rows = {(r["component"], r["iteration"]): r
            for r in read_rows(tmp_path / "rep" / "tables" / "residual_statistics.csv")}
    assert set(summary["residual_ks"]) == set(expected)
    for name, w in expected.items():
        full = stats.kstest(w, "norm").statistic
        assert summary["residual_ks"][name]["final"] == pytest.approx(full, rel=1e-12)
        assert abs(stats.kstest(w[::10], "norm").statistic - full) > 0.1
        row = rows[(name, "final")]
        assert int(row["n"]) == n and float(row["KS D"]) == pytest.approx(full, rel=1e-8)
        assert float(row["std"]) == pytest.approx(np.std(w), rel=1e-8)
        fw = first[f"{name}__w"]
        assert summary["residual_ks"][name]["first"] == pytest.approx(
            stats.kstest(fw[np.isfinite(fw)], "norm").statistic, rel=1e-12)


def test_decimation_keeps_extremes_and_breaks_gaps():
    y = np.sin(np.linspace(0, 50, 200_000))
    y[123_457] = 9.0
    y[7] = -9.0
    idx = minmax_indices(y, 2000)
    assert idx.size <= 2000 and 123_457 in idx and 7 in idx
    t = np.arange(1000.0)
    t[500:] += 100.0                         # a 100-s gap
    td, yd = decimate_for_drawing(t, np.ones(1000), 100)
    gap = np.nonzero(np.isnan(yd))[0]
    assert gap.size == 1 and td[gap[0] - 1] < 500 and td[gap[0] + 1] >= 600


def test_bad_folders_give_one_input_error(results, tmp_path, capsys):
    with pytest.raises(GmisInputError, match="not found"):
        make_report(tmp_path / "absent")
    (tmp_path / "empty").mkdir()
    with pytest.raises(GmisInputError, match="no `gmis run` files"):
        make_report(tmp_path / "empty")
    broken = tmp_path / "broken"
    shutil.copytree(results / "run", broken)
    (broken / "solution.npz").write_text("not an npz")
    with pytest.raises(GmisInputError, match="solution.npz"):
        make_report(broken)
    rec = dict(np.load(results / "run" / "records.npz"))
    del rec["innov_var"]
    write_npz(broken / "records.npz", **rec)
    shutil.copy(results / "run" / "solution.npz", broken / "solution.npz")
    with pytest.raises(GmisInputError, match="innov_var"):
        make_report(broken)
    (broken / "records.npz").unlink()
    with pytest.raises(GmisInputError, match="records.npz missing"):
        make_report(broken)
    vce = tmp_path / "vce"
    shutil.copytree(results / "vce", vce)
    text = (vce / "vce_history.csv").read_text().splitlines()
    text[1] = text[1].replace(text[1].split(",")[3], "abc", 1)
    (vce / "vce_history.csv").write_text("\n".join(text) + "\n")
    with pytest.raises(GmisInputError, match="sigma"):
        make_report(vce)
    with pytest.raises(GmisInputError, match="not a `gmis vce`"):
        make_report(results / "run", vce_dir=results / "run")
    with pytest.raises(GmisInputError, match="unknown figure format"):
        make_report(results, formats=("png", "jpeg"))
    # the CLI prints one line and exits with status 2; nothing half-written is left
    assert cli_main(["report", str(tmp_path / "empty")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gmis: error:")
    assert not (tmp_path / "empty" / "report").exists()
