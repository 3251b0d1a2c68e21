"""SP3 reader: record layout (a field cut short is an error with its line number), EOF /
truncated last epoch, blank first line, compressed files. Files are written here."""

import bz2
import gzip

import numpy as np
import pytest

from gnss.errors import GnssInputError as GmisInputError  # gnss raises the base type
from gnss.sp3 import read_sp3

HEADER = """#cP2017  2 14  0  0  0.00000000       2 ORBIT IGS14 HLM  IGS
## 1936 172800.00000000   900.00000000 57798 0.0000000000000
+    2   G03G04  0  0  0  0  0  0  0  0  0  0  0  0  0  0  0
%c G  cc GPS ccc cccc cccc cccc cccc ccccc ccccc ccccc ccccc
"""
EPOCH1 = """*  2017  2 14  0  0  0.00000000
PG03   1110.563354 -15664.982011 -21430.999250   -107.415449  7  7  6 107
PG04  -9093.224082 -16780.479633 -18497.217852 999999.999999
"""
EPOCH2 = """*  2017  2 14  0 15  0.00000000
PG03   1200.000000 -15600.000000 -21400.000000   -107.400000  7  7  6 107
PG04  -9000.000000 -16700.000000 -18400.000000     12.500000
"""


def _write(tmp_path, text, name="t.sp3"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_complete_file(tmp_path):
    sp3 = read_sp3(_write(tmp_path, HEADER + EPOCH1 + EPOCH2 + "EOF\n"))
    assert sp3.prn.tolist() == [3, 4]
    np.testing.assert_allclose(sp3.position[0, 1], [-9093224.082, -16780479.633,
                                                    -18497217.852], rtol=0, atol=1e-6)
    assert np.isnan(sp3.clock[0, 1]) and sp3.clock[1, 1] == pytest.approx(12.5e-6)
    np.testing.assert_allclose(np.diff(sp3.t_gps), 900.0)


def test_number_cut_mid_way_is_an_error_with_its_line(tmp_path):
    """The issue's case: a file cut after 'PG04  -9093.224082 -16780.479633 -18' gave
    z = -18 km. It must be an error naming line 7."""
    text = HEADER + EPOCH1
    cut = text.index("-18497") + 3
    with pytest.raises(GmisInputError, match=r"line 7: position record cut short"):
        read_sp3(_write(tmp_path, text[:cut]))


@pytest.mark.parametrize("where", ["-16780.47", "PG0", "  0.0000", "-107.4154"])
def test_any_cut_inside_a_line_is_an_error(tmp_path, where):
    text = HEADER + EPOCH1 + EPOCH2 + "EOF\n"
    cut = text.rindex(where) + len(where)
    with pytest.raises(GmisInputError, match=r"line \d+: "):
        read_sp3(_write(tmp_path, text[:cut]))


def test_cut_between_records_without_eof(tmp_path):
    """No EOF line: an incomplete last epoch is an error; a complete one is accepted with
    exactly the epochs before the cut."""
    with pytest.raises(GmisInputError, match="1 position records where 2 are expected"):
        read_sp3(_write(tmp_path, HEADER + EPOCH1 + EPOCH2.rsplit("PG04", 1)[0]))
    with pytest.raises(GmisInputError, match="0 position records where 2 are expected"):
        read_sp3(_write(tmp_path, HEADER + EPOCH1 + EPOCH2.splitlines()[0]))
    sp3 = read_sp3(_write(tmp_path, HEADER + EPOCH1))
    assert sp3.t_gps.size == 1 and np.isfinite(sp3.position).all()


def test_missing_final_newline_and_blank_first_line(tmp_path):
    full = read_sp3(_write(tmp_path, HEADER + EPOCH1 + EPOCH2 + "EOF\n", "a.sp3"))
    for text in (HEADER + EPOCH1 + EPOCH2 + "EOF", "\n" + HEADER + EPOCH1 + EPOCH2 + "EOF\n",
                 (HEADER + EPOCH1 + EPOCH2).rstrip("\n")):
        got = read_sp3(_write(tmp_path, text, "b.sp3"))
        np.testing.assert_array_equal(got.position, full.position)
        np.testing.assert_array_equal(got.clock, full.clock)


def test_compressed(tmp_path):
    text = (HEADER + EPOCH1 + EPOCH2 + "EOF\n").encode()
    plain = read_sp3(_write(tmp_path, text.decode()))
    for name, data in (("t.sp3.gz", gzip.compress(text)), ("t.sp3.bz2", bz2.compress(text)),
                       ("t.sp3.Z", __import__("ncompress").compress(text))):
        path = tmp_path / name
        path.write_bytes(data)
        got = read_sp3(path)
        np.testing.assert_array_equal(got.position, plain.position)
        path.write_bytes(data[: len(data) // 2])
        with pytest.raises(GmisInputError, match="cannot decompress|truncated|cut short"):
            read_sp3(path)
