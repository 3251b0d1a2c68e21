"""`gmis outages --window ... --smooth` (gmis.outage_study): the two-filter smoother scored
against the withheld GNSS beside the forward GMIKF and the error-state EKF (issue 15's
per-window table forward / smoothed, from the command line)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gmis.cli import main
from tests.test_gnss_velocity_lag import lag_scenario

START = 345600.0


@pytest.fixture(scope="module")
def moving_drive(tmp_path_factory):
    from gmis.simulate import simulate_scenario
    root = tmp_path_factory.mktemp("outage_smoothed")
    (root / "scenario.toml").write_text(lag_scenario(velocity_latency_s=0.0))
    return Path(simulate_scenario(root / "scenario.toml", root / "dataset").recipe_path)


def test_smoothed_scores_beside_the_forward_ones(moving_drive, tmp_path):
    from gmis.outage_study import run_window_study

    windows = [(START + 30.0, START + 40.0), (START + 50.0, START + 58.0)]
    plain = run_window_study(moving_drive, windows)
    both = run_window_study(moving_drive, windows, results_dir=tmp_path / "o", smooth=True)
    # the forward figures do not change with --smooth (its forward pass is the plain run)
    assert both["all_withheld_epochs"]["gmikf"] == plain["all_withheld_epochs"]["gmikf"]
    assert "gmikf_smoothed" not in plain["all_withheld_epochs"]
    fwd = both["all_withheld_epochs"]["gmikf"]
    sm = both["all_withheld_epochs"]["gmikf_smoothed"]
    assert sm["n"] == fwd["n"] >= 80
    assert sm["horizontal_max_m"] < 0.2 * fwd["horizontal_max_m"], (sm, fwd)
    assert sm["horizontal_rms_m"] < 0.2 * fwd["horizontal_rms_m"]
    for w in both["windows"]:
        assert w["gmikf_smoothed"]["horizontal_rms_m"] < w["gmikf"]["horizontal_rms_m"]
    header = (tmp_path / "o" / "outage_windows.csv").read_text().splitlines()[0].split(",")
    assert "gmikf_smoothed_horizontal_max_m" in header and header.index(
        "gmikf_smoothed_horizontal_max_m") > header.index("errins_vertical_max_m")
    rows = np.genfromtxt(tmp_path / "o" / "outage_windows.csv", delimiter=",", names=True,
                         comments="#")
    assert rows["gmikf_smoothed_horizontal_rms_m"][-1] == pytest.approx(
        sm["horizontal_rms_m"], rel=1e-9)
    assert (tmp_path / "o" / "outage_errors.png").stat().st_size > 20_000
    saved = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert saved["all_withheld_epochs"]["gmikf_smoothed"]["n"] == sm["n"]


def test_smooth_without_windows_is_one_line(moving_drive, tmp_path, capsys):
    out = tmp_path / "never"
    rc = main(["outages", str(moving_drive), "--smooth", "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("gmis: error: --smooth:")
    assert not out.exists()
