"""File readers: unit conversions, axis mapping, cropping, speed, and one malformed file
per check (each must raise GmisInputError naming the file, and the line where there is one)."""

import time

import numpy as np
import pytest

from gmis.errors import GmisInputError
from gmis.readers import (
    load_dataset,
    read_gnss_solution,
    read_heading,
    read_imu,
    read_reference,
)
from gmis.recipe import STANDARD_GRAVITY, ImuSection, NoiseSection, load_recipe
from tests.conftest import IMU_HEADER, IMU_RATE_HZ, T0, imu_rows, write_csv_text

D2R = np.pi / 180.0


def test_rate_file_in_si_is_read_unchanged(dataset):
    imu = read_imu(dataset.imu, ImuSection(rate_hz=IMU_RATE_HZ))
    rows = imu_rows()
    assert imu.t == pytest.approx(rows[:, 0], abs=1e-9)
    assert np.array_equal(imu.gyro, rows[:, 1:4])
    assert np.array_equal(imu.accel, rows[:, 4:7])
    assert imu.warnings == ()
    assert imu.rate_hz == pytest.approx(IMU_RATE_HZ, rel=1e-6)


@pytest.mark.parametrize("unit, factor", [("deg/s", D2R), ("deg/h", D2R / 3600.0),
                                          ("rad/s", 1.0)])
def test_gyro_units(dataset, unit, factor):
    imu = read_imu(dataset.imu, ImuSection(rate_hz=IMU_RATE_HZ, gyro_unit=unit))
    assert imu.gyro == pytest.approx(imu_rows()[:, 1:4] * factor, rel=1e-14)


def test_accel_in_g(dataset):
    imu = read_imu(dataset.imu, ImuSection(rate_hz=IMU_RATE_HZ, accel_unit="g"))
    assert imu.accel == pytest.approx(imu_rows()[:, 4:7] * 9.80665, rel=1e-14)
    assert STANDARD_GRAVITY == 9.80665


def test_increments_become_rates(tmp_path):
    rows = imu_rows(n=50)
    dt = np.diff(rows[:, 0])
    # Increments over the interval ending at each sample: Δθ = ω·Δt (deg), Δv = f·Δt (m/s).
    inc = rows.copy()
    inc[1:, 1:4] = rows[1:, 1:4] * dt[:, None]
    inc[1:, 4:7] = rows[1:, 4:7] * dt[:, None]
    inc[0, 1:] = rows[0, 1:] / IMU_RATE_HZ
    path = write_csv_text(tmp_path / "inc.csv", IMU_HEADER, inc)
    imu = read_imu(path, ImuSection(rate_hz=IMU_RATE_HZ, format="increment", gyro_unit="deg",
                                    accel_unit="m/s"))
    assert imu.gyro == pytest.approx(rows[:, 1:4] * D2R, rel=1e-9)
    assert imu.accel == pytest.approx(rows[:, 4:7], rel=1e-9)


def test_axis_mapping_forward_left_up_to_rfu(dataset):
    imu = read_imu(dataset.imu, ImuSection(rate_hz=IMU_RATE_HZ, axes=("-y", "x", "z")))
    rows = imu_rows()
    assert np.array_equal(imu.gyro[:, 0], -rows[:, 2])  # right = -left
    assert np.array_equal(imu.gyro[:, 1], rows[:, 1])  # forward = sensor x
    assert np.array_equal(imu.accel[:, 2], rows[:, 6])


def test_whitespace_file_without_header_by_column_index(tmp_path):
    rows = imu_rows(n=20)
    order = [6, 0, 3, 2, 1, 5, 4]  # scrambled column order
    path = write_csv_text(tmp_path / "imu.txt", None, rows[:, order], delimiter="   ")
    section = ImuSection(rate_hz=IMU_RATE_HZ, delimiter="whitespace", time_column=1,
                         gyro_columns=(4, 3, 2), accel_columns=(6, 5, 0))
    imu = read_imu(path, section)
    assert np.array_equal(imu.t, rows[:, 0])
    assert np.array_equal(imu.gyro, rows[:, 1:4])
    assert np.array_equal(imu.accel, rows[:, 4:7])


def test_gap_is_a_warning_not_an_error(tmp_path):
    rows = np.delete(imu_rows(), np.s_[100:110], axis=0)  # 0.11 s gap = 11 samples
    path = write_csv_text(tmp_path / "imu.csv", IMU_HEADER, rows)
    imu = read_imu(path, ImuSection(rate_hz=IMU_RATE_HZ))
    assert len(imu.warnings) == 1
    assert "gap of 0.110 s" in imu.warnings[0] and "line 101" in imu.warnings[0]
    short = np.delete(imu_rows(), np.s_[100:103], axis=0)  # 4 samples: not a gap
    path = write_csv_text(tmp_path / "imu2.csv", IMU_HEADER, short)
    assert read_imu(path, ImuSection(rate_hz=IMU_RATE_HZ)).warnings == ()


def test_gnss_heading_reference_conversions(dataset):
    gnss = read_gnss_solution(dataset.gnss)
    assert gnss.llh[0] == pytest.approx([43.7735 * D2R, -79.5019 * D2R, 180.0])
    assert gnss.pos_sigma[0] == pytest.approx([0.02, 0.02, 0.05])
    assert gnss.vel_enu is None and gnss.vel_sigma is None
    noise = NoiseSection(heading_sigma_rad=0.01)
    heading = read_heading(dataset.heading, noise)
    assert heading.heading == pytest.approx(np.full(15, np.pi / 2))
    assert heading.sigma == pytest.approx(np.full(15, 0.01))
    ref = read_reference(dataset.reference)
    assert ref.euler[0] == pytest.approx([1.0 * D2R, -2.0 * D2R, 90.0 * D2R])
    assert ref.llh[:, 2] == pytest.approx(179.0)


def test_gnss_without_sigmas_uses_recipe_noise_and_reads_velocity(tmp_path):
    t = T0 + np.arange(5.0)
    rows = np.column_stack([t, np.full(5, 10.0), np.full(5, 200.0), np.zeros(5),
                            np.ones((5, 3))])
    path = write_csv_text(tmp_path / "g.csv", ["time_gps_s", "lat_deg", "lon_deg", "h_m",
                                               "ve_m_s", "vn_m_s", "vu_m_s"], rows)
    noise = NoiseSection(gnss_position_sigma_m=(1.0, 2.0, 3.0),
                         gnss_velocity_sigma_m_s=(0.1, 0.2, 0.3))
    gnss = read_gnss_solution(path, noise)
    assert gnss.pos_sigma == pytest.approx(np.tile([1.0, 2.0, 3.0], (5, 1)))
    assert gnss.vel_sigma == pytest.approx(np.tile([0.1, 0.2, 0.3], (5, 1)))
    assert gnss.vel_enu == pytest.approx(np.ones((5, 3)))
    assert gnss.llh[0, 1] == pytest.approx(-160.0 * D2R)  # 0..360 longitude wrapped


def test_load_dataset_crops_to_time_window_and_origin(dataset):
    doc = dataset.modified("time", start_gps_s=T0 + 0.5, end_gps_s=T0 + 2.0)
    ds = load_dataset(load_recipe(dataset.write(doc)))
    assert ds.imu.t[0] == pytest.approx(T0 + 0.5) and ds.imu.t[-1] == pytest.approx(T0 + 2.0)
    assert ds.imu.t.size == ds.imu.gyro.shape[0] == 151
    assert ds.gnss.t[0] >= T0 + 0.5 and ds.gnss.t[-1] <= T0 + 2.0
    assert ds.gnss.llh.shape == (ds.gnss.t.size, 3)
    assert ds.reference.euler.shape == (ds.reference.t.size, 3)
    assert ds.origin_llh() == pytest.approx(tuple(ds.gnss.llh[0]))


def test_hour_of_100hz_imu_loads_in_seconds(tmp_path):
    n = 360_000
    rows = imu_rows(n=n)
    cols = [np.char.mod("%.6f", rows[:, j]) for j in range(7)]  # vectorised formatting
    body = "\n".join(",".join(r) for r in zip(*cols))
    (tmp_path / "imu.csv").write_text(",".join(IMU_HEADER) + "\n" + body + "\n")
    start = time.process_time()     # CPU time: wall time fails on a loaded CI machine
    imu = read_imu(tmp_path / "imu.csv", ImuSection(rate_hz=IMU_RATE_HZ, gyro_unit="deg/s"))
    elapsed = time.process_time() - start
    assert imu.t.size == n
    assert imu.gyro[-1] == pytest.approx(rows[-1, 1:4] * D2R, rel=1e-6)
    assert elapsed < 6.0, f"360 000-row IMU file took {elapsed:.2f} s CPU"


# ----------------------------------------------------------------------------- bad files


def _imu_with(tmp_path, mutate):
    """IMU CSV text (header + rows as strings) changed by ``mutate(lines)``."""
    rows = imu_rows(n=50)
    lines = [",".join(IMU_HEADER)] + [",".join(repr(float(x)) for x in r) for r in rows]
    mutate(lines)
    path = tmp_path / "imu.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


def _set_cell(row, col, value):
    def mutate(lines):
        cells = lines[row].split(",")
        cells[col] = value
        lines[row] = ",".join(cells)
    return mutate


def _set_time(row, source_row):
    def mutate(lines):
        cells = lines[row].split(",")
        cells[0] = lines[source_row].split(",")[0]
        lines[row] = ",".join(cells)
    return mutate


# lines[0] is the header (file line 1); lines[k] is file line k+1.
BAD_IMU_FILES = {
    "empty file": (lambda lines: lines.clear(), "empty file"),
    "header only": (lambda lines: lines.__delitem__(slice(1, None)), "no data lines"),
    "missing column": (lambda lines: lines.__setitem__(0, lines[0].replace("gyro_z", "gyro_w")),
                       "missing column 'gyro_z'"),
    "wrong column count": (lambda lines: lines.__setitem__(7, lines[7] + ",1.0"),
                           "line 8: 8 columns, expected 7"),
    "non-numeric cell": (_set_cell(10, 3, "abc"), "line 11: non-numeric value 'abc'"),
    "empty cell": (_set_cell(12, 2, ""), "line 13: non-numeric value empty value"),
    "NaN value": (_set_cell(20, 4, "nan"), "non-finite value nan in column 'accel_x' (line 21)"),
    "inf value": (_set_cell(21, 6, "inf"), "non-finite value inf in column 'accel_z' (line 22)"),
    "time backwards": (_set_time(30, 25), "time goes backwards at line 31"),
    "duplicate time": (_set_time(30, 29), "duplicate time at line 31"),
    "rate mismatch": (lambda lines: [lines.__setitem__(k, lines[k].replace(
        lines[k].split(",")[0], repr(T0 + (k - 1) * 0.0106), 1)) for k in range(1, len(lines))],
        "measured IMU rate 94.34 Hz differs from [imu].rate_hz = 100 Hz"),
    "single sample": (lambda lines: lines.__delitem__(slice(2, None)), "only 1 IMU sample"),
}


@pytest.mark.parametrize("case", sorted(BAD_IMU_FILES))
def test_bad_imu_file(tmp_path, case):
    mutate, words = BAD_IMU_FILES[case]
    path = _imu_with(tmp_path, mutate)
    with pytest.raises(GmisInputError) as info:
        read_imu(path, ImuSection(rate_hz=IMU_RATE_HZ))
    message = str(info.value)
    assert message.startswith(str(path) + ": "), message
    assert words in message, message
    assert "\n" not in message


def test_missing_imu_file(tmp_path):
    with pytest.raises(GmisInputError, match="absent.csv: file not found"):
        read_imu(tmp_path / "absent.csv", ImuSection(rate_hz=IMU_RATE_HZ))


def test_bad_gnss_files(dataset):
    text = dataset.gnss.read_text().splitlines()
    bad = dataset.root / "bad_gnss.csv"
    bad.write_text("\n".join([text[0].replace("sigma_u_m", "sigma_up_m")] + text[1:]))
    with pytest.raises(GmisInputError, match=r"unknown column 'sigma_up_m' \(did you mean "
                                             r"'sigma_u_m'\?\)"):
        read_gnss_solution(bad)
    cells = text[3].split(",")
    cells[1] = "95.0"
    bad.write_text("\n".join(text[:3] + [",".join(cells)] + text[4:]))
    with pytest.raises(GmisInputError, match=r"bad_gnss.csv: latitude 95.0 deg out of range "
                                             r"\[-90, 90\] \(line 4\)"):
        read_gnss_solution(bad)
    header = text[0].split(",")[:6]  # sigma_e, sigma_n without sigma_u
    bad.write_text("\n".join([",".join(header)] + [",".join(r.split(",")[:6]) for r in text[1:]]))
    with pytest.raises(GmisInputError, match="give all of"):
        read_gnss_solution(bad)


def test_heading_with_zero_sigma_is_rejected(tmp_path):
    path = write_csv_text(tmp_path / "h.csv", ["time_gps_s", "heading_deg", "sigma_heading_deg"],
                          [[T0, 10.0, 0.5], [T0 + 1, 11.0, 0.0]])
    with pytest.raises(GmisInputError, match=r"h.csv: sigma_heading_deg must be > 0, got 0.0 "
                                             r"\(line 3\)"):
        read_heading(path)


def test_gnss_on_another_time_base_is_rejected(dataset):
    text = dataset.gnss.read_text().splitlines()
    shifted = [text[0]] + [",".join([repr(float(r.split(",")[0]) - 345600.0 + 1.5e9)]
                                    + r.split(",")[1:]) for r in text[1:]]
    dataset.gnss.write_text("\n".join(shifted) + "\n")
    with pytest.raises(GmisInputError, match=r"gnss.csv: no epochs within the IMU time span .* "
                                             r"same time base"):
        load_dataset(load_recipe(dataset.write()))


def test_time_window_without_imu_data(dataset):
    doc = dataset.modified("time", start_gps_s=T0 + 100.0)
    with pytest.raises(GmisInputError, match=r"recipe.toml: time.start_gps_s: fewer than 2 IMU "
                                             r"samples"):
        load_dataset(load_recipe(dataset.write(doc)))


def test_comment_and_blank_lines_inside_the_data_keep_line_numbers(tmp_path):
    rows = imu_rows(n=30)
    lines = ["# leading comment", ",".join(IMU_HEADER)]
    lines += [",".join(repr(float(x)) for x in r) for r in rows]
    lines.insert(12, "# a comment in the middle")
    lines.insert(15, "   ")
    lines.insert(16, "")
    path = tmp_path / "imu.csv"
    path.write_text("\n".join(lines) + "\n")
    imu = read_imu(path, ImuSection(rate_hz=IMU_RATE_HZ))
    assert np.array_equal(imu.t, rows[:, 0]) and np.array_equal(imu.gyro, rows[:, 1:4])
    cells = lines[20].split(",")
    cells[2] = "x1"
    lines[20] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(GmisInputError, match=r"imu.csv: line 21: non-numeric value 'x1'"):
        read_imu(path, ImuSection(rate_hz=IMU_RATE_HZ))
