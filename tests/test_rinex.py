"""RINEX readers: real RINEX 2.10 files, a RINEX 3.03 file written here, cache, bad input."""

import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from gnss.errors import GnssInputError as GmisInputError  # gnss raises the base type
from gnss.rinex import read_nav, read_obs
from tests.shared_data import RTKLIB_TEST as DATA

needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=f"real data folder {DATA} absent")


@pytest.fixture
def cache(tmp_path):
    return tmp_path / "cache"


@needs_data
def test_read_rinex2_base(cache):
    obs = read_obs(DATA / "07590920.05o", cache_dir=cache)
    assert obs.C1.shape == (120, 11)
    assert obs.version == pytest.approx(2.10)
    np.testing.assert_allclose(obs.approx_position_ecef,
                               [-3976219.5082, 3382372.5671, 3652512.9849])
    assert set(obs.signals["C1"]) == {"C1"} and set(obs.signals["C2"]) == {"P2"}
    assert np.all(obs.week == 1316)
    np.testing.assert_allclose(np.diff(obs.t_gps)[:12], 30.0)
    # code in m, phase in cycles: L1 phase·λ1 − C1 stays within the ambiguity, 24 Mm ranges
    c1 = obs.C1[np.isfinite(obs.C1)]
    assert 1.9e7 < c1.min() and c1.max() < 2.7e7
    assert np.isnan(obs.D1).all() and np.isnan(obs.S1).all()  # not in this file


@needs_data
def test_epoch_tags_are_exact(cache):
    """Epoch 12 of 3040 is tagged '0  5 59.9990000' in the file; georinex alone gives
    59.998 s. The reader must keep the tag to 1 µs."""
    obs = read_obs(DATA / "30400920.05o", cache_dir=cache)
    line = [ln for ln in (DATA / "30400920.05o").read_text().splitlines()
            if ln.startswith(" 05  4  2  0  5 59.9990000")]
    assert line, "test premise: epoch line present in the file"
    assert obs.sow[12] == pytest.approx(6 * 86400 + 5 * 60 + 59.999, abs=1e-6)


@needs_data
def test_cache_roundtrip_and_speed(cache):
    t0 = time.perf_counter()
    first = read_obs(DATA / "07590920.05o", cache_dir=cache)
    t_parse = time.perf_counter() - t0
    files = list(cache.glob("*.npz"))
    assert len(files) == 1
    t0 = time.perf_counter()
    second = read_obs(DATA / "07590920.05o", cache_dir=cache)
    t_cached = time.perf_counter() - t0
    print(f"\nparse {t_parse * 1e3:.1f} ms, cached {t_cached * 1e3:.1f} ms")
    for name in ("t_gps", "C1", "L1", "L2", "C2", "LLI1", "prn"):
        np.testing.assert_array_equal(getattr(first, name), getattr(second, name))
    assert t_cached < t_parse


@needs_data
def test_unwritable_cache_falls_back(tmp_path):
    blocker = tmp_path / "not_a_dir"
    blocker.write_text("x")
    with pytest.warns(UserWarning, match="cache not writable"):
        obs = read_obs(DATA / "07590920.05o", cache_dir=blocker / "sub")
    assert obs.C1.shape == (120, 11)


@needs_data
def test_tlim(cache):
    obs = read_obs(DATA / "07590920.05o", cache_dir=cache)
    part = read_obs(DATA / "07590920.05o", cache_dir=cache,
                    tlim=(obs.t_gps[10], obs.t_gps[19]))
    assert part.n_epochs == 10
    np.testing.assert_array_equal(part.L1, obs.L1[10:20])


@needs_data
def test_read_nav(cache):
    nav = read_nav(DATA / "brdc1820.10n", cache_dir=cache)
    assert nav.n_records > 400
    assert np.all(np.diff(nav.prn) >= 0)
    np.testing.assert_allclose(nav.ion_alpha, [0.4657e-08, 0.1490e-07, -0.5960e-07,
                                               -0.1192e-06])
    assert np.all(nav.week == 1590)
    assert np.all(np.abs(nav.toe - nav.toc) < 7200.0)
    assert np.all((nav.sqrt_a > 5100) & (nav.sqrt_a < 5200))


# ------------------------------------------------------------------ bad input

def _without_last_lines(text: str, n_lines: int) -> str:
    return "".join(text.splitlines(keepends=True)[:-n_lines])


def _header_only(text: str) -> str:
    return text[: text.index("END OF HEADER")] + "END OF HEADER\n"


def test_missing_file(tmp_path):
    with pytest.raises(GmisInputError, match="file not found"):
        read_obs(tmp_path / "nope.05o")
    with pytest.raises(GmisInputError, match="file not found"):
        read_nav(tmp_path / "nope.05n")


@needs_data
@pytest.mark.parametrize("source, bad_name, edit, read, match", [
    ("07590920.05o", "cut.05o", lambda text: text[: int(len(text) * 0.6)], read_obs,
     "truncated"),
    ("07590920.05o", "cut2.05o", lambda text: _without_last_lines(text, 3), read_obs,
     "truncated"),
    ("07590920.05n", "cut.05n", lambda text: _without_last_lines(text, 3), read_nav,
     "truncated"),
    ("07590920.05o", "v5.05o", lambda text: "     5.00" + text[9:], read_obs,
     "unsupported RINEX version"),
    ("07590920.05o", "glo.05o", lambda text: text[:40] + "R" + text[41:], read_obs, "no GPS"),
    ("07590920.05o", "empty.05o", _header_only, read_obs, "no epochs"),
], ids=["truncated_obs", "truncated_obs_on_line_boundary", "truncated_nav",
        "unknown_version", "no_gps_system", "header_only_has_no_epochs"])
def test_malformed_file_is_refused(tmp_path, source, bad_name, edit, read, match):
    bad = tmp_path / bad_name
    bad.write_text(edit((DATA / source).read_text()))
    with pytest.raises(GmisInputError, match=match):
        read(bad, cache_dir=tmp_path / "c")


def test_not_rinex(tmp_path):
    bad = tmp_path / "junk.05o"
    bad.write_text("hello\nworld\n")
    with pytest.raises(GmisInputError, match="END OF HEADER"):
        read_obs(bad, cache_dir=tmp_path / "c")


# ------------------------------------------------------------------ RINEX 3

def _rinex3_line(label_text: str, label: str) -> str:
    return f"{label_text:<60}{label}\n"


def _obs_field(value) -> str:
    return " " * 16 if value is None else f"{value:14.3f}  "


def _write_rinex3(path: Path) -> dict:
    """Three epochs, GPS G05 (C1C, C1W, L1C, C2W, L2W, S1C, D1C) with G07 lacking C1C
    (so C1W must be used for it), and a GLONASS satellite that must be skipped."""
    g_types = ["C1C", "L1C", "D1C", "S1C", "C1W", "C2L", "C2W", "L2W"]
    r_types = ["C1C", "L1C"]
    hdr = [
        _rinex3_line("     3.03           OBSERVATION DATA    M", "RINEX VERSION / TYPE"),
        _rinex3_line("TEST", "MARKER NAME"),
        _rinex3_line("  1000000.0000  2000000.0000  3000000.0000", "APPROX POSITION XYZ"),
        _rinex3_line(f"G{len(g_types):5d} " + " ".join(g_types), "SYS / # / OBS TYPES"),
        _rinex3_line(f"R{len(r_types):5d} " + " ".join(r_types), "SYS / # / OBS TYPES"),
        _rinex3_line("    30.000", "INTERVAL"),
        _rinex3_line("  2020     1     5     0     0    0.0000000     GPS",
                     "TIME OF FIRST OBS"),
        _rinex3_line("", "END OF HEADER"),
    ]
    rng = np.random.default_rng(7)
    truth = {"G05": {}, "G07": {}}
    body = []
    for k in range(3):
        minute, sec = divmod(30 * k, 60)
        body.append(f"> 2020 01 05 00 {minute:02d} {float(sec):10.7f}  0  3\n")
        for sat in ("G05", "G07"):
            vals = {t: float(rng.uniform(2e7, 2.5e7)) for t in g_types}
            vals["S1C"] = 45.0 + k
            vals["D1C"] = -1234.5 + k
            if sat == "G07":
                vals["C1C"] = None
                vals["C2W"] = None
            truth[sat][k] = vals
            body.append(sat + "".join(_obs_field(vals[t]) for t in g_types).rstrip() + "\n")
        body.append("R01" + "".join(_obs_field(2.1e7) for _ in r_types).rstrip() + "\n")
    path.write_text("".join(hdr + body))
    return truth


def test_rinex3_priority_and_skip(tmp_path):
    path = tmp_path / "test.rnx"
    truth = _write_rinex3(path)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        obs = read_obs(path, cache_dir=tmp_path / "c")
    assert any("R skipped" in str(w.message) for w in rec)
    assert list(obs.sats) == ["G05", "G07"]
    assert obs.signals["C1"].tolist() == ["C1C", "C1W"]
    assert obs.signals["C2"].tolist() == ["C2W", "C2L"]
    for k in range(3):
        assert obs.C1[k, 0] == pytest.approx(truth["G05"][k]["C1C"], abs=1e-3)
        assert obs.C1[k, 1] == pytest.approx(truth["G07"][k]["C1W"], abs=1e-3)
        assert obs.C2[k, 1] == pytest.approx(truth["G07"][k]["C2L"], abs=1e-3)
        assert obs.L2[k, 0] == pytest.approx(truth["G05"][k]["L2W"], abs=1e-3)
        assert obs.S1[k, 0] == pytest.approx(45.0 + k)
        assert obs.D1[k, 0] == pytest.approx(-1234.5 + k)
    np.testing.assert_allclose(obs.approx_position_ecef, [1e6, 2e6, 3e6])
    np.testing.assert_allclose(np.diff(obs.t_gps), 30.0)


# ------------------------------------------------------------------ layout, compression, notes

def _same_obs(a, b):
    np.testing.assert_array_equal(a.t_gps, b.t_gps)
    assert list(a.sats) == list(b.sats)
    for name in ("C1", "L1", "C2", "L2", "D1", "S1", "LLI1", "LLI2"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


@needs_data
def test_missing_final_newline_reads_the_same(tmp_path):
    """'head -c -1' of a valid obs/nav file (a complete file without its final newline)
    reads the same as the original."""
    for name in ("07590920.05o", "brdc1820.10n"):
        raw = (DATA / name).read_bytes()
        assert raw.endswith(b"\n")
        cut = tmp_path / name
        cut.write_bytes(raw[:-1])
        if name.endswith("o"):
            _same_obs(read_obs(cut, use_cache=False), read_obs(DATA / name, use_cache=False))
        else:
            a, b = read_nav(cut, use_cache=False), read_nav(DATA / name, use_cache=False)
            for f in ("prn", "toc", "toe", "sqrt_a", "e", "m0", "fit_interval_h", "iodc"):
                np.testing.assert_array_equal(getattr(a, f), getattr(b, f))


@needs_data
def test_cut_inside_a_number_is_an_error_with_its_line(tmp_path):
    text = (DATA / "07590920.05o").read_text()
    k = text.rindex(".", 0, len(text) - 200) - 3   # inside a number near the end
    bad = tmp_path / "cut.05o"
    bad.write_text(text[:k])
    with pytest.raises(GmisInputError, match=r"line \d+: .*(cut short|truncated)"):
        read_obs(bad, use_cache=False)
    nav = (DATA / "brdc1820.10n").read_text()
    bad = tmp_path / "cut.10n"
    bad.write_text(nav[:len(nav) - 10])
    with pytest.raises(GmisInputError, match=r"line \d+: ephemeris line cut short"):
        read_nav(bad, use_cache=False)


@needs_data
def test_epoch_at_60_seconds_is_the_next_minute(tmp_path):
    """RTKLIB's convention: '0  0 60.0000000' is 00:01:00 (the reader notes it)."""
    text = (DATA / "07590920.05o").read_text()
    assert " 05  4  2  0  1  0.0000000" in text
    bad = tmp_path / "sixty.05o"
    bad.write_text(text.replace(" 05  4  2  0  1  0.0000000", " 05  4  2  0  0 60.0000000"))
    with pytest.warns(UserWarning, match="1 epoch.* tagged 60.0 s normalised"):
        obs = read_obs(bad, use_cache=False)
    _same_obs(obs, read_obs(DATA / "07590920.05o", use_cache=False))


@needs_data
def test_compressed_copies_and_damaged_archives(tmp_path):
    import bz2
    import gzip
    import zipfile
    raw = (DATA / "07590920.05o").read_bytes()
    plain = read_obs(DATA / "07590920.05o", use_cache=False)
    (tmp_path / "a.05o.gz").write_bytes(gzip.compress(raw))
    (tmp_path / "a.05o.bz2").write_bytes(bz2.compress(raw))
    with zipfile.ZipFile(tmp_path / "a.05o.zip", "w") as z:
        z.writestr("a.05o", raw)
    for name in ("a.05o.gz", "a.05o.bz2", "a.05o.zip"):
        _same_obs(read_obs(tmp_path / name, use_cache=False), plain)
        data = (tmp_path / name).read_bytes()
        cut = tmp_path / ("cut_" + name)
        cut.write_bytes(data[: len(data) // 2])
        with pytest.raises(GmisInputError, match="cannot decompress"):
            read_obs(cut, use_cache=False)
    bogus = tmp_path / "bogus.18o.zip"
    bogus.write_text("this is not a zip")
    with pytest.raises(GmisInputError, match=r"bogus.18o.zip: not a zip file"):
        read_obs(bogus, use_cache=False)


def test_truncated_hatanaka_is_one_line_error(tmp_path):
    from tests.shared_data import RINEX_CORPUS
    src = RINEX_CORPUS / "P43300USA_R_20190012056_17M_15S_MO.crx"
    if not src.is_file():
        pytest.skip(f"corpus file {src} absent (../shared/data)")
    bad = tmp_path / "trunc.crx"
    bad.write_bytes(src.read_bytes()[:20000])
    with pytest.raises(GmisInputError, match="Hatanaka") as exc:
        read_obs(bad, use_cache=False)
    assert "\n" not in str(exc.value) and str(exc.value).startswith(str(bad))


def test_declared_and_listed_type_counts_differ(tmp_path):
    """wrong_obs2_count.10o: the header says 6 types and lists 7; the data follow the 7."""
    from tests.shared_data import RINEX_CORPUS
    src = RINEX_CORPUS / "wrong_obs2_count.10o"
    if not src.is_file():
        pytest.skip(f"corpus file {src} absent (../shared/data)")
    with pytest.warns(UserWarning, match="declares 6 GPS observation types but lists 7"):
        obs = read_obs(src, use_cache=False)
    assert obs.S1[np.isfinite(obs.S1)].size > 0   # S1 is the 6th, S2 the 7th listed type
    assert np.isfinite(obs.S2).any()


def test_glonass_rinex2_nav_is_named(tmp_path):
    bad = tmp_path / "glo.18g"
    bad.write_text(f"{'     2.11           G: GLONASS NAV DATA':<60}RINEX VERSION / TYPE\n"
                   f"{'':<60}END OF HEADER\n")
    with pytest.raises(GmisInputError, match="a GLONASS navigation file"):
        read_nav(bad, use_cache=False)


@needs_data
def test_leading_blank_line_is_skipped_and_counted(tmp_path):
    text = (DATA / "07590920.05o").read_text()
    blank_first = tmp_path / "blank1st.05o"
    blank_first.write_text("\n" + text)
    _same_obs(read_obs(blank_first, use_cache=False), read_obs(DATA / "07590920.05o",
                                                                use_cache=False))
    lines = text.splitlines(keepends=True)
    k = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln) + 1  # 1st epoch line
    lines[k] = " junk" + lines[k][5:]
    bad = tmp_path / "junk.05o"
    bad.write_text("\n" + "".join(lines))
    with pytest.raises(GmisInputError, match=f"line {k + 2}: malformed"):
        read_obs(bad, use_cache=False)
