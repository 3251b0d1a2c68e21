"""RTKLIB inputs (gmis.readers_rtklib): .tag time tags, the tick-counter IMU CSV mapped to
GPST through them, .pos as the loosely coupled GNSS input, and their recipe keys."""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gmis.errors import GmisInputError
from gmis.readers import load_dataset, read_imu_tagged
from gmis.readers_rtklib import (
    UNIX_TO_GPS_EPOCH_S,
    read_gnss_pos,
    read_tick_imu_csv,
    read_time_tag,
)
from gmis.recipe import ImuSection, load_recipe

START_UNIX = 1752003261  # 2025-07-08 19:34:21 GPST, Unix-style count
START_FRAC = 0.854


def write_tag(path: Path, ticks, start=START_UNIX, frac=START_FRAC, magic=b"TIMETAG RTKLIB demo5"):
    head = magic.ljust(60, b"\0") + struct.pack("<IId", 12345, start, frac)
    body = b"".join(struct.pack("<II", t, 100 * i) for i, t in enumerate(ticks))
    path.write_bytes(head + body)
    return path


def write_tick_csv(path: Path, ms, first_partial="", last_partial=""):
    rows = [f"0.000,0.000,1.000,0.100,-0.200,0.300,{m}" for m in ms]
    text = (first_partial + "\n" if first_partial else "") + "\n".join(rows) + "\n"
    path.write_text(text + (last_partial if last_partial else ""))
    return path


def test_tag_header_and_pairs(tmp_path):
    tag = read_time_tag(write_tag(tmp_path / "a.tag", [131, 146, 548731]))
    assert tag.start_gps_s == pytest.approx(START_UNIX - UNIX_TO_GPS_EPOCH_S + START_FRAC)
    assert tag.tick_ms.tolist() == [131, 146, 548731]
    assert tag.file_pos.tolist() == [0, 100, 200]
    assert tag.tick_f == 12345
    # 2025-07-08 19:34:21.854 GPST is 243261.854 s into GPS week 2374
    assert tag.gps_week == 2374
    assert tag.start_gps_s - 2374 * 604800 == pytest.approx(243261.854)


@pytest.mark.parametrize("mutation, message", [
    (lambda b: b[:50], "not an RTKLIB time-tag file"),
    (lambda b: b"XIMETAG" + b[7:], "not an RTKLIB time-tag file"),
    (lambda b: b[:76], r"no \(tick, file position\) records"),
])
def test_tag_errors(tmp_path, mutation, message):
    raw = write_tag(tmp_path / "a.tag", [1, 2, 3]).read_bytes()
    (tmp_path / "b.tag").write_bytes(mutation(raw))
    with pytest.raises(GmisInputError, match=message):
        read_time_tag(tmp_path / "b.tag")


def test_tag_ticks_going_back_is_an_error(tmp_path):
    with pytest.raises(GmisInputError, match="record 3: tick 5 ms goes back"):
        read_time_tag(write_tag(tmp_path / "a.tag", [1, 10, 5]))


def test_tick_mapping_is_the_authors_linear_one(tmp_path):
    ms = np.array([1000, 1010, 1020, 1500, 2000])
    tag = read_time_tag(write_tag(tmp_path / "a.tag", [0, 500, 1100]))
    t, gyro, accel, lines, notes = read_tick_imu_csv(write_tick_csv(tmp_path / "i.csv", ms),
                                                     tag, time_offset_s=-0.125)
    sow0 = tag.start_gps_s - tag.gps_week * 604800
    # first sample at the start, last at start + last tick / 1000, linear between
    expected = sow0 + (ms - ms[0]) / (ms[-1] - ms[0]) * 1.1 - 0.125
    np.testing.assert_allclose(t, expected, atol=1e-9)
    np.testing.assert_allclose(gyro[0], [0.1, -0.2, 0.3])
    np.testing.assert_allclose(accel[0], [0.0, 0.0, 1.0])
    assert lines.tolist() == [1, 2, 3, 4, 5] and notes == []


def test_partial_first_and_last_lines_are_notes(tmp_path, capsys):
    ms = np.arange(1000, 1200, 10)
    csv = write_tick_csv(tmp_path / "i.csv", ms, first_partial="3,0.1,-0.2,0.3,99",
                         last_partial="0.000,0.0")
    tag = write_tag(tmp_path / "a.tag", [0, 190])
    imu = read_imu_tagged(csv, tag, ImuSection(rate_hz=100.0, time_base="tag",
                                                gyro_unit="deg/s", accel_unit="g"))
    assert imu.t.size == ms.size
    assert any("line 1: partial first line skipped" in w for w in imu.warnings)
    assert any(f"line {ms.size + 2}: partial last line skipped" in w for w in imu.warnings)
    assert "gmis: note:" in capsys.readouterr().err
    np.testing.assert_allclose(imu.accel[0], [0.0, 0.0, 9.80665])  # g → m/s², RFU
    np.testing.assert_allclose(imu.gyro[0], np.radians([0.1, -0.2, 0.3]))


def test_partial_line_in_the_middle_is_an_error(tmp_path):
    csv = write_tick_csv(tmp_path / "i.csv", [1000, 1010, 1020])
    lines = csv.read_text().splitlines()
    lines[1] = lines[1][:10]
    csv.write_text("\n".join(lines) + "\n")
    tag = read_time_tag(write_tag(tmp_path / "a.tag", [0, 20]))
    with pytest.raises(GmisInputError, match=r"i.csv: line 2: expected 7 numbers"):
        read_tick_imu_csv(csv, tag)


def test_ticks_not_increasing_is_an_error(tmp_path):
    tag = read_time_tag(write_tag(tmp_path / "a.tag", [0, 20]))
    with pytest.raises(GmisInputError, match="line 3: tick 1005 ms does not increase"):
        read_tick_imu_csv(write_tick_csv(tmp_path / "i.csv", [1000, 1010, 1005, 1020]), tag)


# ----------------------------------------------------------------------------- .pos

POS_HEADER = ("%  GPST            latitude(deg) longitude(deg) height(m) Q  ns  sdn(m) sde(m) "
              "sdu(m) sdne(m) sdeu(m) sdun(m) age(s) ratio vn(m/s) ve(m/s) vu(m/s) sdvn sdve "
              "sdvu sdvne sdveu sdvun")


def write_pos_file(path, qs):
    lines = [POS_HEADER]
    for i, q in enumerate(qs):
        lines.append(f"2025/07/08 19:34:{18 + i * 0.25:06.3f} 40.0966268 -105.1474483 1601.47 "
                     f"{q} 21 0.010 0.020 0.030 0.001 0.000 0.000 0.0 0.0 "
                     f"0.5 1.5 -0.1 0.05 0.06 0.07 0 0 0")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_pos_enu_order_velocity_and_q_policy(tmp_path):
    path = write_pos_file(tmp_path / "s.pos", [1, 2, 5, 1])
    sol = read_gnss_pos(path)
    assert sol.q.tolist() == [1, 2, 1]  # Q=5 excluded by default
    np.testing.assert_allclose(sol.t[0], 243258.0)  # seconds of week
    np.testing.assert_allclose(sol.pos_sigma[0], [0.020, 0.010, 0.030])  # E, N, U
    np.testing.assert_allclose(sol.pos_sigma[1], 3.0 * np.array([0.020, 0.010, 0.030]))
    np.testing.assert_allclose(sol.vel_enu[0], [1.5, 0.5, -0.1])
    np.testing.assert_allclose(sol.vel_sigma[0], [0.06, 0.05, 0.07])
    np.testing.assert_allclose(np.degrees(sol.llh[0, :2]), [40.0966268, -105.1474483])
    only_fix = read_gnss_pos(path, q_sigma_factor=[1.0, 0.0, 0.0, 0.0, 2.0])
    assert only_fix.q.tolist() == [1, 5, 1]
    np.testing.assert_allclose(only_fix.pos_sigma[1], 2 * np.array([0.020, 0.010, 0.030]))


def test_pos_without_used_epochs_is_an_error(tmp_path):
    with pytest.raises(GmisInputError, match="no epoch with a used quality"):
        read_gnss_pos(write_pos_file(tmp_path / "s.pos", [5, 5]))


def test_pos_bad_line_is_a_gmis_input_error(tmp_path):
    path = write_pos_file(tmp_path / "s.pos", [1, 1])
    path.write_text(path.read_text() + "2025/07/08 19:40:00.000 40.1 x\n")
    with pytest.raises(GmisInputError, match=r"s.pos: line 4:"):
        read_gnss_pos(path)


# ----------------------------------------------------------------------------- recipe keys

RECIPE = """[dataset]
name = "t"
[paths]
imu = "i.csv"
imu_tag = "a.tag"
gnss_pos = "s.pos"
[imu]
rate_hz = 100.0
time_base = "tag"
time_offset_s = -0.125
gyro_unit = "deg/s"
accel_unit = "g"
body_frame = "FRD"
mounting_rpy_deg = [180.0, 0.0, 180.0]
[antennas]
frame = "FRD"
primary_lever_arm_m = [0.1, -0.05, -0.2]
[gnss_pos]
q_sigma_factor = [1.0, 0.0]
"""


def _recipe_folder(tmp_path, text=RECIPE):
    ms = np.arange(0, 1000, 10)
    write_tick_csv(tmp_path / "i.csv", ms)
    write_tag(tmp_path / "a.tag", [0, 990])
    write_pos_file(tmp_path / "s.pos", [1, 2, 1])
    (tmp_path / "r.toml").write_text(text)
    return tmp_path / "r.toml"


def test_recipe_reads_tag_imu_and_pos(tmp_path):
    recipe = load_recipe(_recipe_folder(tmp_path))
    assert recipe.antennas.primary_lever_arm_m == pytest.approx((-0.05, 0.1, 0.2))  # RFU
    assert recipe.gnss_pos.q_sigma_factor == (1.0, 0.0)
    # tag start 243261.854 − 0.125; the .pos epochs at 243258.0.. are before it: the
    # dataset loader refuses streams outside the IMU span
    with pytest.raises(GmisInputError, match="no epochs within the IMU time span"):
        load_dataset(recipe)


@pytest.mark.parametrize("edit, key", [
    (lambda s: s.replace('time_base = "tag"', 'time_base = "ticks"'), "imu.time_base"),
    (lambda s: s.replace('imu_tag = "a.tag"\n', ""), "imu.time_base"),
    (lambda s: s.replace('body_frame = "FRD"', 'body_frame = "NED"'), "imu.body_frame"),
    (lambda s: s.replace("[180.0, 0.0, 180.0]", "[180.0, 0.0, 720.0]"),
     "imu.mounting_rpy_deg"),
    (lambda s: s.replace('frame = "FRD"\nprimary', 'frame = "XYZ"\nprimary'), "antennas.frame"),
    (lambda s: s.replace("[1.0, 0.0]", "[1.0, -1.0]"), "gnss_pos.q_sigma_factor"),
    (lambda s: s.replace('gnss_pos = "s.pos"', 'gnss_pos = "s.pos"\ngnss_solution = "s.pos"'),
     "paths.gnss_pos"),
])
def test_recipe_key_errors(tmp_path, edit, key):
    path = _recipe_folder(tmp_path, edit(RECIPE))
    with pytest.raises(GmisInputError, match=key.replace(".", r"\.")):
        load_recipe(path)


def test_cli_one_line_error_exit_2(tmp_path):
    path = _recipe_folder(tmp_path, RECIPE.replace("[1.0, 0.0]", "[1.0, -1.0]"))
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run([sys.executable, "-m", "gmis", "run", str(path), "-o",
                           str(tmp_path / "out")], check=False,
                          capture_output=True, text=True, cwd=root,
                          env={"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"})
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gmis: error: ")
    assert "gnss_pos.q_sigma_factor" in lines[0]
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- time bases

@pytest.mark.parametrize("time_base, offset", [
    ("gps", 0.0), ("gps_1980", 2374 * 604800.0), ("unix_utc", UNIX_TO_GPS_EPOCH_S - 18.0
                                                   + 2374 * 604800.0)])
def test_column_mapped_csv_time_bases(tmp_path, time_base, offset):
    from gmis.readers import read_imu
    sow = 243261.0 + np.arange(50) / 100.0
    rows = "\n".join(f"{g},{float(t + offset)!r},0.1,0.2,0.3,0,0,1" for g, t in enumerate(sow))
    (tmp_path / "i.txt").write_text(rows + "\n")
    imu = read_imu(tmp_path / "i.txt", ImuSection(rate_hz=100.0, time_column=1,
                                                  gyro_columns=(2, 3, 4),
                                                  accel_columns=(5, 6, 7),
                                                  accel_unit="g", time_base=time_base,
                                                  time_offset_s=0.5))
    np.testing.assert_allclose(imu.t, sow + 0.5, atol=1e-6)
    np.testing.assert_allclose(imu.accel[0], [0, 0, 9.80665])


def _noisy_tick_csv(path, n, rng, first=None, last=None):
    """n samples at rest with noise (g, deg/s), ticks 10 ms apart; optional raw first /
    last lines in place of the first / last sample."""
    rows = []
    for k in range(n):
        a = rng.normal([0.0, 0.0, 1.0], 0.003)
        g = rng.normal([0.1, -0.2, 0.3], 0.05)
        rows.append(",".join(f"{v:.4f}" for v in (*a, *g)) + f",{1000 + 10 * k}")
    if first is not None:
        rows[0] = first + ",1000"
    if last is not None:
        rows[-1] = last + f",{1000 + 10 * (n - 1)}"
    path.write_text("\n".join(rows) + "\n")
    return path


def test_an_end_line_cut_inside_its_first_field_is_skipped(tmp_path):
    """"19,0.027,..." of "-0.019,0.027,...": seven numbers, a wild value (helper review
    2026-12-06: at the drive's start it made the run a moving start, attitude flipped);
    skipped with a note at either end, never in the middle, never a normal end line."""
    rng = np.random.default_rng(2)
    tag = read_time_tag(write_tag(tmp_path / "a.tag", [0, 4990]))
    csv = _noisy_tick_csv(tmp_path / "i.csv", 500, rng, first="19,0.0027,1.0013,0.1,-0.2,0.3",
                          last="0.001,0.002,1.001,71,-0.2,0.3")
    t, _gyro, accel, lines, notes = read_tick_imu_csv(csv, tag)
    assert t.size == 498 and lines[0] == 2 and lines[len(lines) - 1] == 499
    assert any("line 1: first line's values lie far" in n for n in notes)
    assert any("line 500: last line's values lie far" in n for n in notes)
    t_cut = t
    clean = _noisy_tick_csv(tmp_path / "c.csv", 500, np.random.default_rng(2))
    t, _, _, lines, notes = read_tick_imu_csv(clean, tag)
    assert t.size == 500 and notes == []
    # the tick → time map still runs from the log's first to its last tick
    np.testing.assert_array_equal(t_cut, t[1:-1])
    middle = clean.read_text().splitlines()
    middle[250] = "19,0.0027,1.0013,0.1,-0.2,0.3," + middle[250].split(",")[-1]
    (tmp_path / "m.csv").write_text("\n".join(middle) + "\n")
    t, _, accel, _, notes = read_tick_imu_csv(tmp_path / "m.csv", tag)
    assert t.size == 500 and notes == [] and accel[250, 0] == 19.0


def test_a_last_line_cut_inside_its_tick_is_skipped(tmp_path):
    """"...,0.3,8104" of "...,0.3,810412": seven numbers whose tick goes back — at the end
    of the file a cut, not an error; the same line in the middle stays an error."""
    tag = read_time_tag(write_tag(tmp_path / "a.tag", [0, 30]))
    csv = write_tick_csv(tmp_path / "i.csv", [1000, 1010, 1020, 1030])
    text = csv.read_text().splitlines()
    text[-1] = text[-1][:-2]                           # "...,1030" -> "...,10"
    csv.write_text("\n".join(text) + "\n")
    t, _, _, lines, notes = read_tick_imu_csv(csv, tag)
    assert t.size == 3 and lines.tolist() == [1, 2, 3]
    assert any("line 4: last line's tick 10 ms does not follow 1020 ms" in n for n in notes)
    text[1], text[-1] = text[1][:-2], text[-1] + "30"
    csv.write_text("\n".join(text) + "\n")
    with pytest.raises(GmisInputError, match="line 2: tick 10 ms does not increase"):
        read_tick_imu_csv(csv, tag)
