"""Reading only a [time] window of a large IMU log (gmis.text_window, read_table's
time_window; issue 18): the rows, values, file span and errors inside the window are the
whole-file read's, and only the window's text (plus its margins) is parsed."""

import numpy as np
import pytest

from gmis import readers, text_blocks, text_window
from gmis.errors import GmisInputError
from gmis.readers import read_imu
from gmis.recipe import ImuSection
from tests.test_fuzz_readers import T0, imu_seed, write

SECTIONS = [ImuSection(rate_hz=100.0),
            ImuSection(rate_hz=100.0, format="increment", gyro_unit="deg",
                       accel_unit="m/s", axes=("y", "x", "-z")),
            ImuSection(rate_hz=100.0, time_column=0, gyro_columns=(1, 2, 3),
                       accel_columns=(4, 5, 6))]
N = 3000                       # 30 s at 100 Hz
WINDOWS = [(T0 + 10.005, T0 + 12.0), (None, T0 + 3.0), (T0 + 25.0, None),
           (T0 + 0.0, T0 + 29.99), (T0 - 5.0, T0 + 0.5), (T0 + 29.5, T0 + 40.0)]


@pytest.fixture
def small_probes(monkeypatch):
    """Probes of 128 bytes (a line or two) and no minimum file size: bisections of many
    steps on a 30-s file. Yields the list of byte ranges the bisections returned."""
    monkeypatch.setattr(text_window, "PROBE_BYTES", 128)
    monkeypatch.setattr(text_window, "WINDOW_MIN_BYTES", 0)
    found = []
    real = text_window.time_window_bytes

    def spy(*args, **kwargs):
        found.append(real(*args, **kwargs))
        return found[-1]
    monkeypatch.setattr(text_window, "time_window_bytes", spy)
    return found


def _layout(text: str, layout: str, section: int) -> str:
    if layout == "crlf":
        return text.replace("\n", "\r\n")
    if layout == "bom_comments":
        lines = text.splitlines(keepends=True)
        for i in range(len(lines) - 100, 1, -397):
            lines.insert(i, "# a comment line\n" if i % 2 else "\n")
        return "\ufeff# logged by a test\n" + "".join(lines)
    if layout == "no_header":
        return text.split("\n", 1)[1] if section == 2 else text
    return text


def _read(path, section, window, on_disk=False):
    try:
        imu = read_imu(path, section, window, on_disk=on_disk)
    except GmisInputError as exc:
        return str(exc)
    return imu.t, np.asarray(imu.gyro), np.asarray(imu.accel), imu.warnings, imu.file_span


def _whole(monkeypatch, *args, **kwargs):
    with monkeypatch.context() as m:
        m.setattr(text_window, "WINDOW_MIN_BYTES", 1 << 62)
        return _read(*args, **kwargs)


def _same(a, b):
    if isinstance(a, str) or isinstance(b, str):
        assert a == b
        return
    for x, y in zip(a, b):
        if isinstance(x, np.ndarray):
            np.testing.assert_array_equal(x, y)
        else:
            assert x == y


@pytest.mark.parametrize("layout", ["plain", "crlf", "bom_comments", "no_header"])
@pytest.mark.parametrize("section", range(len(SECTIONS)))
@pytest.mark.parametrize("window", range(len(WINDOWS)))
def test_window_read_equals_whole_read(tmp_path, monkeypatch, small_probes, layout,
                                       section, window):
    path = write(tmp_path / "imu.csv", _layout(imu_seed(N), layout, section))
    whole = _whole(monkeypatch, path, SECTIONS[section], WINDOWS[window])
    small_probes.clear()
    _same(_read(path, SECTIONS[section], WINDOWS[window]), whole)
    _same(_read(path, SECTIONS[section], WINDOWS[window], on_disk=True), whole)
    covers_file = WINDOWS[window][0] is not None and WINDOWS[window][0] < T0 + 1.1 \
        and WINDOWS[window][1] > T0 + 28.9
    assert len(small_probes) == 2
    assert (small_probes[0] is None) == covers_file
    assert (small_probes[1] is None) == covers_file


def test_only_the_window_is_parsed(tmp_path, monkeypatch, small_probes):
    """10 s of a 600-s file: the text handed to the parser is the window's 10 s plus
    the margins (1 s + 2 samples each side), not the file."""
    path = write(tmp_path / "imu.csv", imu_seed(60000))
    parsed = []
    real = text_blocks.line_blocks

    def counting(*args, **kwargs):
        for block in real(*args, **kwargs):
            parsed.append(len(block[2].encode()))
            yield block
    monkeypatch.setattr(text_blocks, "line_blocks", counting)
    imu = read_imu(path, SECTIONS[0], (T0 + 300.0, T0 + 310.0))
    assert imu.t[0] == pytest.approx(T0 + 300.0) and imu.t[-1] == pytest.approx(T0 + 310.0)
    margin = readers.WINDOW_MARGIN_S + 2 / 100.0
    needed = sum(len(line) + 1 for line in path.read_text().splitlines()[1:]
                 if T0 + 300.0 - margin <= float(line.split(",")[0]) <= T0 + 310.0 + margin)
    assert needed <= sum(parsed) <= needed + 2 * 110      # + at most a line either side
    assert sum(parsed) < 0.025 * path.stat().st_size
    assert imu.file_span == (T0, T0 + 599.99)


@pytest.mark.parametrize("fault", ["token", "columns", "backwards"])
def test_errors_inside_the_window_name_the_file_line(tmp_path, monkeypatch, small_probes,
                                                     fault):
    lines = imu_seed(N).splitlines(keepends=True)
    k = 1 + 1100                   # the sample at T0 + 11 s, inside WINDOWS[0]
    fields = lines[k].rstrip("\n").split(",")
    if fault == "token":
        fields[3] = "x1e-3"
    elif fault == "columns":
        fields.append("0.5")
    else:
        fields[0] = f"{T0 + 10.5:.2f}"
    lines[k] = ",".join(fields) + "\n"
    path = write(tmp_path / "imu.csv", "# two comment lines\n#\n" + "".join(lines))
    windowed = _read(path, SECTIONS[0], WINDOWS[0])
    assert isinstance(windowed, str) and f"line {k + 3}" in windowed
    assert windowed == _whole(monkeypatch, path, SECTIONS[0], WINDOWS[0])


def test_faults_outside_the_window_are_not_read(tmp_path, small_probes):
    """The documented limit: a window run checks only the lines it reads."""
    lines = imu_seed(N).splitlines(keepends=True)
    lines[2500] = lines[2500].replace(",", ",x", 1)
    path = write(tmp_path / "imu.csv", "".join(lines))
    with pytest.raises(GmisInputError, match="non-numeric"):
        read_imu(path, SECTIONS[0], None)
    imu = read_imu(path, SECTIONS[0], WINDOWS[0])
    assert imu.t.size == 200


def test_unordered_files_are_read_whole(tmp_path, small_probes):
    lines = imu_seed(N).splitlines(keepends=True)
    body = lines[1:]
    text = lines[0] + "".join(body[N // 2:] + body[:N // 2])     # second half first
    path = write(tmp_path / "imu.csv", text)
    section = SECTIONS[0]
    time_of = readers._time_of_line(",", 7, 0, lambda t: t)
    assert text_window.time_window_bytes(path, time_of, readers._is_content,
                                         T0 + 20.0, T0 + 22.0, 0.0) is None
    with pytest.raises(GmisInputError, match="time goes backwards"):
        read_imu(path, section, WINDOWS[0])


def test_small_files_are_read_whole(tmp_path):
    path = write(tmp_path / "imu.csv", imu_seed(N))
    time_of = readers._time_of_line(",", 7, 0, lambda t: t)
    assert path.stat().st_size < text_window.WINDOW_MIN_BYTES
    assert text_window.time_window_bytes(path, time_of, readers._is_content,
                                         T0 + 10.0, T0 + 12.0, 0.0) is None


def _reference_csv(n):
    k = np.arange(n)
    rows = np.column_stack([T0 + k / 100.0, 40.0 + 1e-7 * k, -105.0 + 1e-7 * k,
                            1600.0 + 1e-3 * k, np.sin(k), np.cos(k), 0 * k,
                            0.1 + 0 * k, 0.2 + 0 * k, (k * 0.3) % 360.0])
    return (",".join(readers.REFERENCE_COLUMNS) + "\n"
            + "".join(",".join(repr(float(v)) for v in row) + "\n" for row in rows))


@pytest.mark.parametrize("window", range(len(WINDOWS)))
def test_reference_window_equals_whole_read(tmp_path, monkeypatch, small_probes, window):
    path = write(tmp_path / "reference.csv", _reference_csv(N))
    start, end = WINDOWS[window]
    whole = readers._crop(readers.read_reference(path), start, end)
    small_probes.clear()
    windowed = readers._crop(readers.read_reference(path, (start, end)), start, end)
    got = []
    readers.read_reference_blocks(path, lambda *a: got.append([x.copy() for x in a]),
                                  start, end)
    for name in ("t", "llh", "vel_enu", "euler"):
        np.testing.assert_array_equal(getattr(windowed, name), getattr(whole, name))
    for j, name in enumerate(("t", "llh", "vel_enu", "euler")):
        np.testing.assert_array_equal(np.concatenate([g[j] for g in got]),
                                      getattr(whole, name))
    covers_file = start is not None and start <= T0 and end >= T0 + 29.99
    assert [w is None for w in small_probes] == [covers_file] * 2
