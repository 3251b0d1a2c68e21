"""Block-wise reading (gmis.text_blocks, gmis.readers.read_table, the tick IMU reader):
tiny blocks give the same values, line numbers and error lines as one block holding the
whole file, and the lines of the blocks are the lines of the text."""

import codecs

import numpy as np
import pytest

from gmis.errors import GmisInputError
from gmis.readers import LineNumbers, read_table
from gmis.readers_rtklib import read_tick_imu_csv
from gmis.text_blocks import line_blocks

WHOLE = 1 << 30    # one block for any test file


def table_text(newline="\n"):
    rows = ["# leading comment", "t,a,b"]
    rows += [f"{k * 0.01:.2f},{k * 1.5:.6f},{-k / 7:.12g}" for k in range(200)]
    rows.insert(40, "# a comment in the middle")
    rows.insert(41, "   ")
    rows.insert(90, "")
    return newline.join(rows) + newline


@pytest.mark.parametrize("newline", ["\n", "\r\n"])
@pytest.mark.parametrize("block", [1, 7, 64, 500])
def test_blocks_join_to_the_lines_of_the_text(tmp_path, newline, block):
    path = tmp_path / "t.csv"
    text = table_text(newline)
    path.write_bytes(codecs.BOM_UTF8 + text.encode())
    got, number = [], 1
    for lines, first, _ in line_blocks(path, block):
        assert first == number
        got += lines
        number += len(lines)
    assert got == text.splitlines()


@pytest.mark.parametrize("block", [1, 13, 100, 4096])
def test_small_blocks_read_the_same_table(tmp_path, block):
    path = tmp_path / "t.csv"
    path.write_text(table_text())
    whole = read_table(path, block_bytes=WHOLE)
    small = read_table(path, block_bytes=block)
    assert small.names == whole.names == ["t", "a", "b"]
    assert np.array_equal(small.data, whole.data) and small.data.shape == (200, 3)
    assert np.asarray(small.line_numbers).tolist() == np.asarray(whole.line_numbers).tolist()
    lines = path.read_text().splitlines()
    for row in (0, 37, 38, 39, 86, 87, 199):     # around the comment and blank lines
        assert lines[small.line_numbers[row] - 1].startswith(f"{row * 0.01:.2f},")


def _error(path, block):
    with pytest.raises(GmisInputError) as info:
        read_table(path, block_bytes=block)
    return str(info.value)


@pytest.mark.parametrize("block", [1, 50, 300])
def test_errors_name_the_same_line_with_small_blocks(tmp_path, block):
    path = tmp_path / "t.csv"
    lines = table_text().splitlines()
    bad = list(lines)
    bad[150] = bad[150].replace(",", ",x", 1)          # non-numeric value at line 151
    path.write_text("\n".join(bad) + "\n")
    assert _error(path, block) == _error(path, WHOLE)
    assert "line 151: non-numeric value" in _error(path, block)
    bad[180] = bad[180] + ",1"                          # and a wrong column count later:
    path.write_text("\n".join(bad) + "\n")              # the count is reported first
    assert _error(path, block) == _error(path, WHOLE)
    assert "line 181: 4 columns, expected 3" in _error(path, block)


def test_decoding_error_names_the_byte_as_read_text_does(tmp_path):
    path = tmp_path / "t.csv"
    raw = codecs.BOM_UTF8 + table_text().encode()
    path.write_bytes(raw[:1000] + b"\xff" + raw[1000:])
    with pytest.raises(UnicodeDecodeError) as exc:
        path.read_text(encoding="utf-8-sig")
    expected = f"not a text file ({exc.value.reason} at byte {exc.value.start})"
    for block in (16, 200, WHOLE):
        assert expected in _error(path, block)


def test_line_numbers_runs():
    numbers = LineNumbers()
    numbers.add_run(3, 4)
    numbers.add_run(7, 2)      # continues the run
    numbers.add_lines([12, 13, 20])
    assert len(numbers) == 9 and len(numbers._rows) == 3
    assert np.asarray(numbers).tolist() == [3, 4, 5, 6, 7, 8, 12, 13, 20]
    assert numbers[8] == 20 and numbers[-1] == 20 and numbers[5] == 8
    assert LineNumbers.of([5, 6, 9]).tolist() == [5, 6, 9]
    with pytest.raises(IndexError):
        numbers[9]


def write_tick(path, n, first_partial=None, last_partial=None, blank_every=0):
    rows = []
    if first_partial:
        rows.append(first_partial)
    for k in range(n):
        rows.append(f"0.01,0.02,1.0,{k * 0.1:.3f},-0.2,0.3,{1000 + 10 * k}")
        if blank_every and k % blank_every == 0:
            rows.append("")
    if last_partial:
        rows.append(last_partial)
    path.write_text("\n".join(rows) + "\n")
    return path


class _Tag:
    start_gps_s = 345600.0 + 604800.0 * 2000
    tick_ms = np.array([0, 1990])


@pytest.mark.parametrize("blank_every", [0, 7])
def test_tick_reader_blocks_and_partial_lines(tmp_path, monkeypatch, blank_every):
    import gmis.text_blocks as tb

    path = write_tick(tmp_path / "i.csv", 200, first_partial="3,0.1,-0.2",
                      last_partial="0.000,0.0", blank_every=blank_every)
    whole = read_tick_imu_csv(path, _Tag)
    monkeypatch.setattr(tb, "BLOCK_BYTES", 97)
    monkeypatch.setattr(tb.line_blocks, "__defaults__", (97, None))
    small = read_tick_imu_csv(path, _Tag)
    for a, b in zip(whole[:3], small[:3]):
        assert np.array_equal(a, b) and a.shape[0] == 200
    assert whole[3].tolist() == small[3].tolist()
    assert whole[4] == small[4] and len(small[4]) == 2
    assert "partial first line" in small[4][0] and "partial last line" in small[4][1]
    text = path.read_text().splitlines()
    assert text[small[3][0] - 1].startswith("0.01,0.02,1.0,0.000,")
    # a partial line in the middle is an error naming it, with any block size
    lines = path.read_text().splitlines()
    lines[100] = "0.01,0.02"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(GmisInputError, match=r"line 101: expected 7 numbers"):
        read_tick_imu_csv(path, _Tag)
