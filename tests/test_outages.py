"""GNSS-outage experiment (gmis.outages) on a short simulated drive: window rule, outputs,
drift bookkeeping, the no-reference fallback, input errors and the CLI."""

import copy
import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest

from gmis.cli import main
from gmis.errors import GmisInputError
from gmis.outages import choose_outage_windows, run_outage_experiment, window_drifts
from gmis.pipeline import prepare_run
from gmis.recipe import load_recipe
from gmis.simulate import load_scenario, scenario_path, simulate_scenario
from tests.simulated_drives import square_drive_segments


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    sc = copy.deepcopy(load_scenario(scenario_path("default")))
    sc["scenario"]["imu_rate_hz"] = 100.0
    sc["gnss"]["outage"] = []
    sc["segment"] = square_drive_segments()
    out = tmp_path_factory.mktemp("outages") / "ds"
    res = simulate_scenario(sc, out)
    return res


def test_window_rule(dataset):
    prep = prepare_run(load_recipe(dataset.recipe_path))
    wins = choose_outage_windows(prep, 8.0, 4)
    assert len(wins) == 4
    t0 = prep.dataset.imu.t[0]
    align_end = t0 + prep.recipe.filter.static_alignment_s
    g = prep.dataset.gnss
    speed = np.hypot(g.vel_enu[:, 0], g.vel_enu[:, 1])
    moving = g.t[speed > 0.5]
    starts = np.array([a for a, _ in wins])
    assert np.allclose([b - a for a, b in wins], 8.0)
    assert starts[0] >= max(align_end, moving[0]) and wins[-1][1] <= moving[-1]
    assert np.all(np.diff(starts) > 8.0)                       # no overlap
    assert np.allclose(np.diff(starts), np.diff(starts)[0])    # evenly spread
    with pytest.raises(GmisInputError, match="do not fit"):
        choose_outage_windows(prep, 20.0, 8)
    with pytest.raises(GmisInputError, match="positive integer"):
        choose_outage_windows(prep, 5.0, 0)


def test_window_drifts_bookkeeping():
    t = np.arange(0.0, 10.0, 0.1)
    ref = np.zeros((t.size, 3))
    pos = np.zeros((t.size, 3))
    pos[:, 0] = 0.3                                   # constant offset: no drift
    inside = (t >= 4.0) & (t <= 6.0)
    pos[inside, 1] = 0.5 * (t[inside] - 4.0) ** 2     # 2 m north at the window end
    pos[inside, 2] = -(t[inside] - 4.0)
    (w,) = window_drifts(t, pos, ref, [(4.0, 6.0)])
    np.testing.assert_allclose(w["max_abs"], [0.0, 2.0, 2.0, 2.0], atol=1e-9)
    assert w["t"][0] == pytest.approx(0.0)


def test_experiment_outputs_and_drifts(dataset, tmp_path):
    out = tmp_path / "res"
    s = run_outage_experiment(dataset.recipe_path, duration_s=8.0, count=4, results_dir=out)
    assert s["drift_basis"] == "reference trajectory"
    assert s["gnss_samples_removed"] > 0
    for name in ("errins", "gmikf"):
        rms = s["rms_max_drift_m"][name]
        assert 0.005 < rms["horizontal"] < 50.0, rms
        assert rms["horizontal"] >= max(rms["east"], rms["north"]) - 1e-12
    rows = [r for r in csv.reader((out / "outages.csv").read_text().splitlines()) if r and not r[0].startswith("#")]
    assert len(rows) == 1 + 4 + 1
    data = np.array([[float(x) for x in r] for r in rows[1:]])
    rms_check = np.sqrt((data[:4, 3:] ** 2).mean(axis=0))
    np.testing.assert_allclose(data[4, 3:], rms_check, rtol=1e-6)
    summ = json.loads((out / "summary.json").read_text())
    assert len(summ["windows"]) == 4 and summ["less_drift"] in ("errins", "gmikf")
    png = (out / "outage_drift.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20000


def test_without_reference_uses_full_gnss_solution(dataset, tmp_path):
    text = Path(dataset.recipe_path).read_text()
    text = re.sub(r'(?m)^reference\s*=.*$', "", text)
    recipe = tmp_path / "recipe.toml"
    recipe.write_text(text.replace('"imu.csv"', f'"{dataset.dataset_dir}/imu.csv"')
                      .replace('"gnss.csv"', f'"{dataset.dataset_dir}/gnss.csv"')
                      .replace('"heading.csv"', f'"{dataset.dataset_dir}/heading.csv"'))
    s = run_outage_experiment(recipe, duration_s=8.0, count=2)
    assert s["drift_basis"].startswith("same filter with full GNSS")
    assert s["rms_max_drift_m"]["errins"]["horizontal"] > 0.005


def test_without_reference_with_gnss_between_imu_samples(dataset, tmp_path):
    """GNSS epochs between IMU samples are epochs of their own, and the withheld ones
    are missing from the outage run: the full-GNSS run is matched to it by IMU sample
    (it was indexed epoch by epoch and raised IndexError on the real car drive)."""
    text = Path(dataset.recipe_path).read_text()
    text = re.sub(r'(?m)^reference\s*=.*$', "", text)
    lines = (Path(dataset.dataset_dir) / "gnss.csv").read_text().splitlines()
    shifted = [lines[0]] + [f"{float(x.split(',', 1)[0]) + 0.004!r},{x.split(',', 1)[1]}"
                            for x in lines[1:]]
    (tmp_path / "gnss.csv").write_text("\n".join(shifted) + "\n")
    recipe = tmp_path / "recipe.toml"
    recipe.write_text(text.replace('"imu.csv"', f'"{dataset.dataset_dir}/imu.csv"')
                      .replace('"heading.csv"', f'"{dataset.dataset_dir}/heading.csv"'))
    prep = prepare_run(load_recipe(recipe))
    assert (prep.epochs.imu < 0).sum() > 100            # aiding-only epochs
    s = run_outage_experiment(recipe, duration_s=8.0, count=2)
    assert s["drift_basis"].startswith("same filter with full GNSS")
    assert 0.005 < s["rms_max_drift_m"]["gmikf"]["horizontal"] < 5.0


def test_cli_outages(dataset, tmp_path, capsys):
    rc = main(["outages", dataset.recipe_path, "--duration", "30", "--count", "8",
               "-o", str(tmp_path / "x"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("gmis: error:") and err.count("\n") == 1
    assert not (tmp_path / "x").exists()
    rc = main(["outages", dataset.recipe_path, "--duration", "8", "--count", "2",
               "-o", str(tmp_path / "y"), "--quiet"])
    assert rc == 0 and (tmp_path / "y" / "outages.csv").is_file()
