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

# the IMU sections, the reader wrapper (result or error text) and the comparison of the
# on-disk reader's tests
from tests.test_imu_spool import SECTIONS, _read, _same

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


def _whole(monkeypatch, *args, **kwargs):
    with monkeypatch.context() as m:
        m.setattr(text_window, "WINDOW_MIN_BYTES", 1 << 62)
        return _read(*args, **kwargs)


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


def _rows_of(text):
    lines = text.splitlines(keepends=True)
    return lines[0], lines[1:]


def _retimed(line, t):
    fields = line.rstrip("\n").split(",")
    fields[0] = repr(t)
    return ",".join(fields) + "\n"


def _both(tmp_path, monkeypatch, text, window, section=0, name="imu.csv"):
    path = write(tmp_path / name, text)
    whole = _whole(monkeypatch, path, SECTIONS[section], window)
    return _read(path, SECTIONS[section], window), whole


@pytest.mark.parametrize("probe", [128, 4096])
@pytest.mark.parametrize("glitch", [1, 50])
def test_tags_that_jump_ahead_inside_the_window_are_not_a_silent_cut(
        tmp_path, monkeypatch, small_probes, probe, glitch):
    """A run of tags inside the window stamped 3 s late: the end search may stop on one
    of them; the step across that cut (and the disorder after it) sends the read to the
    whole file, whose error names the line."""
    monkeypatch.setattr(text_window, "PROBE_BYTES", probe)
    header, rows = _rows_of(imu_seed(N))
    for k in range(1100, 1100 + glitch):
        rows[k] = _retimed(rows[k], T0 + k / 100.0 + 3.0)
    windowed, whole = _both(tmp_path, monkeypatch, header + "".join(rows), WINDOWS[0])
    assert isinstance(whole, str) and "time goes backwards" in whole
    assert windowed == whole


@pytest.mark.parametrize("window", [(T0 + 10.0, T0 + 13.5), (T0 + 13.5, T0 + 17.0)])
def test_a_gap_across_a_window_edge_reads_the_whole_file(tmp_path, monkeypatch,
                                                         small_probes, window):
    header, rows = _rows_of(imu_seed(N))
    rows = rows[:1200] + [_retimed(r, float(r.split(",")[0]) + 3.0) for r in rows[1200:]]
    windowed, whole = _both(tmp_path, monkeypatch, header + "".join(rows), window)
    assert not isinstance(whole, str) and any("gap of 3.010 s" in w for w in whole[3])
    _same(windowed, whole)


def test_one_sample_then_a_comment_is_one_sample(tmp_path, monkeypatch, small_probes):
    header, rows = _rows_of(imu_seed(N))
    rows = rows[:1000] + [_retimed(rows[1500], T0 + 15.0), "# logger note\n"] + \
        [_retimed(r, float(r.split(",")[0]) + 10.0) for r in rows[1000:2000]]
    windowed, whole = _both(tmp_path, monkeypatch, header + "".join(rows),
                            (T0 + 15.0, T0 + 15.0))
    _same(windowed, whole)
    assert whole[0].size == 1


def test_header_after_a_long_preamble_and_a_numeric_header_name(tmp_path, monkeypatch,
                                                                small_probes):
    header, rows = _rows_of(imu_seed(N))
    preamble = "".join(f"# preamble line {i:05d} " + "x" * 60 + "\n" for i in range(1000))
    windowed, whole = _both(tmp_path, monkeypatch, preamble + header + "".join(rows),
                            WINDOWS[0])
    _same(windowed, whole)
    numeric = "0," + header.split(",", 1)[1]          # header names "0, gyro_x, ..."
    section = ImuSection(rate_hz=100.0, time_column="0")
    path = write(tmp_path / "numeric.csv", numeric + "".join(rows))
    for window in (WINDOWS[0], (None, T0 + 0.5)):
        _same(_read(path, section, window), _whole(monkeypatch, path, section, window))


@pytest.mark.parametrize("separator", ["\x0c", "\x85", "\u2028", "\r"])
def test_line_numbers_count_every_line_break_the_parser_counts(tmp_path, monkeypatch,
                                                               small_probes, separator):
    header, rows = _rows_of(imu_seed(N))
    rows[1100] = rows[1100].replace(",", ",x", 1)
    text = header + "# a comment" + separator + "\n" + "".join(rows)
    windowed, whole = _both(tmp_path, monkeypatch, text, WINDOWS[0])
    assert isinstance(whole, str) and "non-numeric" in whole
    assert windowed == whole


def test_decoding_errors_name_the_byte_after_the_mark(tmp_path, monkeypatch, small_probes):
    header, rows = _rows_of(imu_seed(N))
    path = tmp_path / "imu.csv"
    data = ("\ufeff" + header + "".join(rows)).encode()
    cut = data.index(rows[1100].encode())
    path.write_bytes(data[:cut] + b"\xff" + data[cut:])
    windowed = _read(path, SECTIONS[0], WINDOWS[0])
    assert windowed == _whole(monkeypatch, path, SECTIONS[0], WINDOWS[0])
    assert "not a text file" in windowed


def test_an_inverted_window_reads_as_the_whole_file_does(tmp_path, monkeypatch,
                                                         small_probes):
    windowed, whole = _both(tmp_path, monkeypatch, imu_seed(N), (T0 + 20.0, T0 + 10.0))
    _same(windowed, whole)
    path = write(tmp_path / "reference.csv", _reference_csv(N))
    got = readers.read_reference(path, (T0 + 20.0, T0 + 10.0))
    assert got.t.size == N
