"""The tightly coupled GMIKF WITHOUT IMU (gmis.tc_gnss_only) on the real RTKLIB test session
0759 (base) / 3040 (rover, static, processed kinematically): fix rate, agreement with
RTKLIB's fixed solution, with gnss.rtk, static constancy, `gmis rtk --tight` output, and
bad input.

Thresholds from what benchmarks/tc_vs_rtklib.py measured (numbers also in docs/DESIGN.md
"Tightly coupled"): TC − RTKLIB over the 115 epochs fixed by both: median 3D 0.5 mm, 95% 1.3 mm with
the differential hydrostatic troposphere that RTKLIB's relative mode applies; without it a
mean offset of [1.7, −4.1, −4.9] mm ENU remains (median 3D 5.4 mm), and the TC then
agrees with gnss.rtk (same assumption) to a median of 0.4 mm. The limits below are about
twice the measured values: the three solutions use the same observations and models, so
sub-millimetre agreement is what a correct DD model and correct integers give; one wrong
integer on L1 moves the position by centimetres.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from gmis.cli import main
from gmis.earth import ecef_to_enu, geodetic_to_ecef
from gmis.tc_gnss_only import (
    compare_fixed_epochs,
    run_tight_gnss_recipe,
    run_tight_without_imu,
)
from gnss.errors import GnssInputError as GmisInputError  # gnss raises the base type
from gnss.rinex import read_nav, read_obs
from gnss.rtk import Q_FIXED, RtkConfig, process_rtk
from tests.rtklib_reference import rtklib_0759_3040_pos, without_epoch_near
from tests.shared_data import RTKLIB_TEST as DATA

BASE_ECEF = np.array([-3976219.5082, 3382372.5671, 3652512.9849])  # 0759 APPROX POSITION
ROVER, BASE, NAV = (DATA / "30400920.05o", DATA / "07590920.05o", DATA / "07590920.05n")

needs_data = pytest.mark.skipif(not DATA.is_dir(),
                                reason=f"real data folder {DATA} (../shared/data) absent")
needs_rtklib = pytest.mark.skipif(shutil.which("rnx2rtkp") is None,
                                  reason="rnx2rtkp (Debian package rtklib) not installed")


def write_recipe(folder, rover=ROVER, base=BASE, nav=NAV):
    path = folder / "recipe.toml"
    path.write_text(f'[paths]\nrover_obs = "{rover}"\nbase_obs = "{base}"\nnav = "{nav}"\n'
                    f"[base]\necef_m = {BASE_ECEF.tolist()}\n")
    return path


@pytest.fixture(scope="module")
def cli_run(tmp_path_factory):
    """`gmis rtk --tight` on the session: (summary dict, tc.csv table, output folder)."""
    if not DATA.is_dir():
        pytest.skip(f"real data folder {DATA} (../shared/data) absent")
    tmp = tmp_path_factory.mktemp("tc_real")
    out = tmp / "out"
    assert main(["rtk", "--tight", str(write_recipe(tmp)), "-o", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    table = np.genfromtxt(out / "tc.csv", delimiter=",", names=True)
    return summary, table, out


@pytest.fixture(scope="module")
def rtklib(tmp_path_factory):
    """RTKLIB's kinematic solution (same settings as benchmarks/rtk_vs_rtklib.py)."""
    return rtklib_0759_3040_pos(tmp_path_factory.mktemp("rtklib"))


def enu_columns(table):
    return np.column_stack([table["e_m"], table["n_m"], table["u_m"]])


def rtklib_enu(pos, frame):
    """RTKLIB llh (rad, rad, m) → ENU (m) in the TC frame (origin at the base)."""
    return np.array([ecef_to_enu(frame, geodetic_to_ecef(*p)) for p in pos["llh"]])


@needs_data
def test_no_imu_tc_fixes_the_session_and_says_the_imu_is_absent(cli_run):
    summary, table, out = cli_run
    assert {p.name for p in out.iterdir()} == {"tc.pos", "tc.csv", "summary.json"}
    assert "absent" in summary["imu"] and summary["doppler"] == "absent in the files"
    assert table.size == summary["epochs"] == 120
    # RTKLIB fixes 115 of 120 epochs here (it outputs nothing for the last five)
    assert summary["fix_rate"] >= 0.95
    assert np.all(table["n_sat"] >= 5)
    # static rover: fixed positions scatter by mm (measured std 2.8, 7.5, 14.0 mm)
    fixed = table["fixed"] == 1
    std = enu_columns(table)[fixed].std(axis=0)
    assert np.all(std[:2] < 0.010) and std[2] < 0.020
    # the 3.3 km baseline (measured 3335.390 m)
    assert abs(summary["baseline_length_m"] - 3335.39) < 0.05


@needs_data
@needs_rtklib
def test_no_imu_tc_agrees_with_rtklib_fixed_solution(cli_run, rtklib):
    from gmis.earth import ecef_to_geodetic, make_nav_frame
    _, table, _ = cli_run
    frame = make_nav_frame(*ecef_to_geodetic(*BASE_ECEF))
    c = compare_fixed_epochs(table["t_gps_s"], enu_columns(table), table["fixed"] == 1,
                             rtklib["t_gps"], rtklib_enu(rtklib, frame),
                             rtklib["q"] == Q_FIXED)
    assert c["n_common"] >= 110
    assert c["median_3d"] < 0.001        # measured 0.5 mm
    assert c["p95_3d"] < 0.003           # measured 1.3 mm
    assert np.all(np.abs(c["mean_enu"]) < 0.001)


@needs_data
@needs_rtklib
def test_without_troposphere_model_the_offset_to_rtklib_is_the_tropo_and_gnss_rtk_agrees(
        rtklib):
    """Troposphere assumed to cancel (the DD model's default): the remaining offset to
    RTKLIB is the differential hydrostatic delay (heights 70.2 m / 75.8 m), and the TC then
    matches gnss.rtk, which makes the same assumption."""
    rover, base, nav = read_obs(ROVER), read_obs(BASE), read_nav(NAV)
    sol = run_tight_without_imu(rover, base, nav, BASE_ECEF, hydrostatic_troposphere=False)
    c = compare_fixed_epochs(sol.t_gps, sol.enu, sol.fixed, rtklib["t_gps"],
                             rtklib_enu(rtklib, sol.frame), rtklib["q"] == Q_FIXED)
    assert np.linalg.norm(c["mean_enu"]) > 0.004      # measured [1.7, −4.1, −4.9] mm
    assert c["median_3d"] < 0.010
    rtk = process_rtk(base, rover, nav, BASE_ECEF, RtkConfig(troposphere="none"))
    rtk_enu = np.array([ecef_to_enu(sol.frame, x) for x in rtk.ecef])
    c2 = compare_fixed_epochs(sol.t_gps, sol.enu, sol.fixed, rtk.t_gps, rtk_enu,
                              rtk.q == Q_FIXED)
    assert c2["n_common"] >= 114
    assert c2["median_3d"] < 0.001      # measured 0.4 mm
    assert c2["p95_3d"] < 0.003         # measured 1.2 mm


@needs_data
def test_missing_rinex_file_is_named(tmp_path):
    missing = tmp_path / "nope.05o"
    recipe = write_recipe(tmp_path, rover=missing)
    with pytest.raises(GmisInputError, match="paths.rover_obs.*nope.05o"):
        run_tight_gnss_recipe(recipe, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    with pytest.raises(GmisInputError, match="nope.05o"):
        read_obs(missing)


@needs_data
def test_cli_reports_missing_rinex_without_traceback(tmp_path, capsys):
    recipe = write_recipe(tmp_path, base=tmp_path / "gone.05o")
    assert main(["rtk", "--tight", str(recipe), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "paths.base_obs" in err and "gone.05o" in err and "Traceback" not in err


@needs_data
def test_slip_at_a_skipped_epoch_is_carried_to_the_next_dd_epoch():
    """A cycle slip flagged at a rover epoch that has no base epoch (so no TcEpoch) must
    reach the next TcEpoch: otherwise the ambiguity is not reset and a TDCP spanning the
    skipped epoch (2 intervals ≤ the 2.5-interval limit) carries the slip."""
    import dataclasses

    from gmis.tc_epochs import prepare_tc_epochs
    rover, base, nav = read_obs(ROVER), read_obs(BASE), read_nav(NAV)
    i = 60
    base = without_epoch_near(base, rover.t_gps[i])
    s = int(np.flatnonzero(np.isfinite(rover.L1[i]) & np.isfinite(rover.L1[i + 1])
                           & np.isfinite(rover.L2[i]))[0])
    prn = int(rover.prn[s])
    L1 = rover.L1.copy()
    L1[i:, s] += 7.0                                     # 7-cycle L1 slip before epoch i
    rover = dataclasses.replace(rover, L1=L1)
    from gnss.cycle_slips import SlipConfig
    from gnss.rtk import receiver_slip_flags
    flags = receiver_slip_flags(rover, SlipConfig())
    assert flags[i, s] and not flags[i + 1, s]          # detected at the skipped epoch only
    offset = int(rover.week[0]) * 604800.0
    epochs = prepare_tc_epochs(rover, base, nav, BASE_ECEF, offset)
    t_next = rover.t_gps[i + 1] - offset
    assert not any(abs(ep.t - (rover.t_gps[i] - offset)) < 1e-3 for ep in epochs)
    nxt = next(ep for ep in epochs if abs(ep.t - t_next) < 1e-3)
    assert prn in nxt.prn.tolist()
    assert nxt.slip[nxt.prn.tolist().index(prn)]
