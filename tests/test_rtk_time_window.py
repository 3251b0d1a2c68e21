"""`gmis rtk` and `gmis rtk --tight` process only the rover epochs of the recipe's [time]
window (helper review 2026-12-06: both ignored it), and a window outside the data is one
line naming it and the file's span."""

from __future__ import annotations

from pathlib import Path

import pytest

from gmis.errors import GmisInputError
from tests.shared_data import RTKLIB_TEST, require

ROOT = Path(__file__).resolve().parents[1]
RECIPE = ROOT / "datasets" / "rtklib-0759-3040" / "recipe.toml"


def _windowed(tmp_path, start, end):
    text = RECIPE.read_text().replace("../../../shared/data", str(RTKLIB_TEST.parent))
    path = tmp_path / "r.toml"
    path.write_text(text + f"\n[time]\nstart_gps_s = {start}\nend_gps_s = {end}\n")
    return path


def test_rtk_jobs_keep_to_the_time_window(tmp_path):
    require(RTKLIB_TEST)
    from gmis.rtk_job import run_rtk_recipe
    from gmis.tc_gnss_only import run_tight_gnss_recipe

    recipe = _windowed(tmp_path, 519000.0, 520000.0)       # 30-s epochs from 518400
    rtk = run_rtk_recipe(recipe, tmp_path / "rtk")
    assert rtk["epochs"] == 33                              # 519030 ... 519990
    tc = run_tight_gnss_recipe(recipe, tmp_path / "tc")
    assert tc["epochs"] == 33
    with pytest.raises(GmisInputError, match=r"no rover epoch inside the \[time\] window "
                                             r"100.0..200.0 s of GPS week 1316"):
        run_rtk_recipe(_windowed(tmp_path, 100.0, 200.0), tmp_path / "never")
    assert not (tmp_path / "never").exists()
