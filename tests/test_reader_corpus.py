"""Every reader over every file of the georinex test corpus (../shared/data/rinex-corpus-georinex):
each file parses or gives the one-line input error listed in EXPECTED (so a change in
behaviour shows); GPS values read agree with an independent parse of the text
(tests/rinex_text_oracle.py); copies truncated at every section give the one-line error or
exactly the complete records before the cut — never a traceback, never a wrong value."""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from gnss.errors import GnssInputError as GmisInputError  # gnss raises the base type
from gnss.rinex import OBS_NAMES, OBS_PRIORITY_RINEX2, OBS_PRIORITY_RINEX3, read_nav, read_obs
from gnss.sp3 import read_sp3
from tests import rinex_text_oracle as oracle
from tests.shared_data import RINEX_CORPUS as CORPUS

pytestmark = pytest.mark.skipif(not CORPUS.is_dir(),
                                reason=f"RINEX corpus folder {CORPUS} absent (../shared/data)")

OK = "ok"
NOT_O = "not an observation file"
NOT_N = "not a GPS navigation file (type 'O')"
NOT_SP3 = "not an SP3 file"
NO_HDR = "no 'END OF HEADER' line"
NETCDF = "a NetCDF/HDF5 file, not RINEX/SP3 text"

# file -> expected outcome of (read_obs, read_nav, read_sp3): "ok" or a substring of the
# one-line error. Reviewed by hand; see docs/formats.md for the decisions behind them.
EXPECTED = {
    "14601736.18n": (NOT_O, OK, NOT_SP3),
    "14601736.18o": (OK, NOT_N, NOT_SP3),
    "ABMF00GLP_R_20181330000_01D_30S_MO.zip": (OK, "not a navigation file (type 'O')", NOT_SP3),
    "BRDC00IGS_R_20201360000_01D_MN.rnx": (NOT_O, "no GPS ephemeris records", NOT_SP3),
    "BRDM00DLR_R_20130010000_01D_MN.rnx": (NOT_O, OK, NOT_SP3),
    "CEBR00ESP_R_20182000000_01D_30S_MO.crx.gz": (OK, "not a navigation file (type 'O')",
                                                  NOT_SP3),
    "CEDA00USA_R_20182100000_01D_MN.rnx.gz": (NOT_O, "no GPS ephemeris records", NOT_SP3),
    "CEDA00USA_R_20182100000_23H_15S_MO.rnx.gz": ("systems in header: ['E', 'R']",
                                                  "not a navigation file (type 'O')", NOT_SP3),
    "ELKO00USA_R_20182100000_01D_MN.rnx.gz": (NOT_O, OK, NOT_SP3),
    "P43300USA_R_20190012056_17M_15S_MO.crx": (OK, "not a navigation file (type 'O')",
                                               NOT_SP3),
    "P43300USA_R_20190012056_17M_15S_MO.crx.bz2": (OK, "not a navigation file (type 'O')",
                                                   NOT_SP3),
    "VILL00ESP_R_20181700000_01D_MN.rnx.gz": (NOT_O, OK, NOT_SP3),
    "ab422100.18n": (NOT_O, OK, NOT_SP3),
    "ab430140.18o.zip": (OK, NOT_N, NOT_SP3),
    "ac660270.18o.Z": (OK, NOT_N, NOT_SP3),
    "badtime.10o": ("line 5: malformed or truncated epoch record", NOT_N, NOT_SP3),
    "blank.10n": (NOT_O, "no ephemeris records in the file", NOT_SP3),
    "blank.10o": ("no epochs in the file", NOT_N, NOT_SP3),
    "blank.sp3": ("file is empty", "file is empty", "file is empty"),
    "blank1st.10n": (NOT_O, "no ephemeris records in the file", NOT_SP3),
    "blank1st.10o": ("no epochs in the file", NOT_N, NOT_SP3),
    "blank3.10n": (NOT_O, "a SBAS navigation file (system 'S')", NOT_SP3),
    "blank3.10o": ("no epochs in the file", "not a navigation file (type 'O')", NOT_SP3),
    "blank3_1st.10n": (NOT_O, "a SBAS navigation file (system 'S')", NOT_SP3),
    "blank3_1st.10o": ("no epochs in the file", "not a navigation file (type 'O')", NOT_SP3),
    "brdc0320.16l.txt": (NOT_O, "a Galileo navigation file (system 'E')", NOT_SP3),
    "brdc2420.18n.gz": (NOT_O, OK, NOT_SP3),
    "brdc2800.15n": (NOT_O, OK, NOT_SP3),
    "ceda2100.18e": ("not an observation file (type 'E')",
                     "a Galileo navigation file (RINEX 2.12 type 'E')", NOT_SP3),
    "default_time_system2.10o": ("no GPS observations (file system 'R')", NOT_N, NOT_SP3),
    "default_time_system3.10o": (OK, "not a navigation file (type 'O')", NOT_SP3),
    "demo.10n": (NOT_O, OK, NOT_SP3),
    "demo.10o": (OK, NOT_N, NOT_SP3),
    "demo3.10o": (OK, "not a navigation file (type 'O')", NOT_SP3),
    "demo_nav3.10n": (NOT_O, "a SBAS navigation file (system 'S')", NOT_SP3),
    "demo_nav3.10n.nc": (NETCDF, NETCDF, NETCDF),
    "demo_nav3.17n": (NOT_O, OK, NOT_SP3),
    "demo_nav3.17n.nc": (NETCDF, NETCDF, NETCDF),
    "example1.sp3a": (NO_HDR, NO_HDR, OK),
    "example1.sp3a.gz": (NO_HDR, NO_HDR, OK),
    "example2.sp3a": (NO_HDR, NO_HDR, ("no EOF line and the last epoch has 2 position records "
                                       "where 5 are expected")),
    "galileo3.15n": (NOT_O, "a Galileo navigation file (system 'E')", NOT_SP3),
    "galileo3.15n.nc": (NETCDF, NETCDF, NETCDF),
    "header.sp3": (NO_HDR, NO_HDR, "no GPS position records"),
    "igs19362.sp3c": (NO_HDR, NO_HDR, OK),
    "junk_time_obs3.10o": ("line 10: malformed or truncated epoch record '> 23 29'",
                           "not a navigation file (type 'O')", NOT_SP3),
    "minimal.sp3c": (NO_HDR, NO_HDR, OK),
    "minimal.sp3d": (NO_HDR, NO_HDR, OK),
    "minimal2.10n": (NOT_O, OK, NOT_SP3),
    "minimal2.10o": (OK, NOT_N, NOT_SP3),
    "minimal3.10n": (NOT_O, "a SBAS navigation file (system 'S')", NOT_SP3),
    "minimal3.10o": (OK, "not a navigation file (type 'O')", NOT_SP3),
    "p1462100.18g": ("not an observation file (type 'G')",
                     "a GLONASS navigation file (RINEX 2.11 type 'G')", NOT_SP3),
    "qzss_nav3.14n": (NOT_O, "a QZSS navigation file (system 'J')", NOT_SP3),
    "qzss_nav3.14n.nc": (NETCDF, NETCDF, NETCDF),
    "r2G.nc": (NETCDF, NETCDF, NETCDF),
    "r2GR.nc": (NETCDF, NETCDF, NETCDF),
    "r2_C1_indicators.nc": (NETCDF, NETCDF, NETCDF),
    "r2all.nc": (NETCDF, NETCDF, NETCDF),
    "r2all_indicators.nc": (NETCDF, NETCDF, NETCDF),
    "r3G.nc": (NETCDF, NETCDF, NETCDF),
    "r3GR.nc": (NETCDF, NETCDF, NETCDF),
    "r3all.nc": (NETCDF, NETCDF, NETCDF),
    "r3all_indicators.nc": (NETCDF, NETCDF, NETCDF),
    "rinex2onesat.10o": (OK, NOT_N, NOT_SP3),
    "spare_filled_nav3.rnx": (NOT_O, OK, NOT_SP3),
    "spirentGSS9000.zip": (NOT_O, OK, NOT_SP3),
    "truncated.sp3": (NO_HDR, NO_HDR, ("no EOF line and the last epoch has 0 position records "
                                       "where 32 are expected")),
    "wrong_obs2_count.10o": (OK, NOT_N, NOT_SP3),
    "york0440.15d": (OK, NOT_N, NOT_SP3),
    "york0440.zip": (OK, NOT_N, NOT_SP3),
}

READERS = (("obs", lambda p: read_obs(p, use_cache=False)),
           ("nav", lambda p: read_nav(p, use_cache=False)),
           ("sp3", read_sp3))


def _outcome(fn, path: Path):
    """(result or None, "ok" or the error text without the file name)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # the readers' notes
            return fn(path), OK
    except GmisInputError as exc:
        text = str(exc)
        assert "\n" not in text, f"multi-line error: {text!r}"
        assert text.startswith(f"{path}: "), f"error does not name the file: {text!r}"
        return None, text[len(str(path)) + 2:]


def test_table_covers_the_corpus():
    files = sorted(p.name for p in CORPUS.iterdir() if p.name not in ("LICENSE", "README.md"))
    assert len(files) == 71
    assert sorted(EXPECTED) == files


_RESULTS: dict = {}


def _read_all(name: str):
    if name not in _RESULTS:
        _RESULTS[name] = {kind: _outcome(fn, CORPUS / name) for kind, fn in READERS}
    return _RESULTS[name]


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_outcome_table(name):
    """Each reader on each file: no traceback (any other exception fails the test), the
    listed outcome, and, for what parsed, the values of the independent parse."""
    got = _read_all(name)
    for (kind, _), want in zip(READERS, EXPECTED[name]):
        _, outcome = got[kind]
        if want == OK:
            assert outcome == OK, f"{kind}: {outcome}"
        else:
            assert want in outcome, f"{kind}: expected {want!r}, got {outcome!r}"
    obs, nav, sp3 = (got[k][0] for k in ("obs", "nav", "sp3"))
    if obs is not None or nav is not None or sp3 is not None:
        text = oracle.file_text(CORPUS / name)
        if obs is not None:
            _check_obs_against_text(obs, text)
        if nav is not None:
            _check_nav_against_text(nav, text)
        if sp3 is not None:
            _check_sp3_against_text(sp3, text)


# ------------------------------------------------------------------ independent parse

def _expected_obs(text: str, epochs=None, decode_every: int = 1):
    """Observation arrays as the documented rules build them from the text: per satellite
    the first code of the priority list with a value anywhere in the file; epochs without
    any GPS C1/L1/C2/L2 value dropped."""
    version, _, eps = oracle.obs_epochs(text, decode_every)
    if epochs is not None:
        eps = epochs
    prio = OBS_PRIORITY_RINEX3 if version >= 3 else OBS_PRIORITY_RINEX2
    present = {(s, c) for e in eps for s, cs in e.present.items() for c in cs}
    sats = sorted({s for e in eps for s in e.present})
    chosen = {(name, s): next((c for c in prio[name] if (s, c) in present), "")
              for name in OBS_NAMES for s in sats}
    keep = [e for e in eps if any(chosen[n, s] in cs for s, cs in e.present.items()
                                  for n in ("C1", "L1", "C2", "L2"))]
    return sats, chosen, keep


def _check_obs_against_text(obs, text, epochs=None):
    """Every value at every decoded epoch (all epochs of files up to 400 epochs, an evenly
    spaced sample of ~400 otherwise) equals the text; epochs, satellites and the signal
    chosen per satellite as the text gives them."""
    n_all = len(oracle.obs_epochs(text, decode_every=10**9)[2]) if epochs is None else 1
    sats, chosen, keep = _expected_obs(text, epochs, max(1, n_all // 400))
    assert list(obs.sats) == sats
    t_text = np.array([e.t_ns for e in keep], dtype=np.int64)
    assert obs.t_gps.size == t_text.size
    np.testing.assert_allclose(obs.t_gps, t_text * 1e-9, rtol=0, atol=1e-6)
    rows = np.array([k for k, e in enumerate(keep) if e.decoded], dtype=int)
    dec = [keep[k] for k in rows]
    n_checked = 0
    for name in OBS_NAMES:
        assert obs.signals[name].tolist() == [chosen[name, s] for s in sats], name
        arr = getattr(obs, name)
        for j, s in enumerate(sats):
            code = chosen[name, s]
            col = np.array([e.sats[s][code][0] if code and s in e.sats and
                            e.sats[s][code][0] is not None else np.nan for e in dec])
            np.testing.assert_array_equal(arr[rows, j], col, err_msg=f"{name} {s} {code}")
            n_checked += int(np.isfinite(col).sum())
            if name in ("L1", "L2"):
                lli = np.array([e.sats[s][code][1] if code and s in e.sats else 0
                                for e in dec])
                np.testing.assert_array_equal(getattr(obs, "LLI" + name[1])[rows, j], lli,
                                              err_msg=f"LLI {s} {code}")
    assert n_checked > 0


_SECONDS_PER_WEEK = 604800.0


def _check_nav_against_text(nav, text, records=None):
    _, recs = oracle.nav_gps_records(text)
    if records is not None:
        recs = records
    by_key = {}
    for r in recs:
        by_key.setdefault((r.prn, r.toc_ns), r)
    assert nav.n_records == len(by_key)
    for k in range(nav.n_records):
        r = by_key[int(nav.prn[k]), round(float(nav.toc[k]) * 1e9 / 1000) * 1000]
        v = dict(zip(oracle.NAV_ORDER, r.values))
        for name in ("af0", "af1", "af2", "iode", "crs", "delta_n", "m0", "cuc", "e", "cus",
                     "sqrt_a", "cic", "omega0", "cis", "i0", "crc", "omega", "omega_dot",
                     "idot", "health", "tgd", "iodc"):
            want = v[name] if v[name] is not None else 0.0
            assert getattr(nav, name)[k] == want, (name, k, getattr(nav, name)[k], want)
        assert nav.toe[k] % _SECONDS_PER_WEEK == pytest.approx(v["toe_sow"], abs=1e-6)
        fit = v["fit_interval_h"]
        assert nav.fit_interval_h[k] == (fit if fit is not None and fit > 0 else 4.0)
    assert nav.n_records > 0


def _check_sp3_against_text(sp3, text, epochs=None):
    eps = oracle.sp3_gps_epochs(text) if epochs is None else epochs
    prns = sorted({p for e in eps for p in e.pos})
    assert sp3.prn.tolist() == prns
    np.testing.assert_allclose(sp3.t_gps, [e.t_ns * 1e-9 for e in eps], rtol=0, atol=1e-6)
    for i, e in enumerate(eps):
        for j, p in enumerate(prns):
            x, y, z, c = e.pos.get(p, (0.0, 0.0, 0.0, 999999.999999))
            want = np.array([x, y, z]) * 1e3 if (x, y, z) != (0.0, 0.0, 0.0) \
                else np.full(3, np.nan)
            np.testing.assert_array_equal(sp3.position[i, j], want)
            want_c = c * 1e-6 if abs(c) < 999999.0 else np.nan
            np.testing.assert_array_equal(sp3.clock[i, j], want_c)


# ------------------------------------------------------------------ truncation sweep

def _cut_points(text: str, records_end: list[int]) -> dict[str, int]:
    """Byte offsets to cut at: inside the header, just after it, inside / after the first
    epoch line, at a line boundary inside a record, inside a number, at the end of a
    record (with and without its newline) and one byte before the end."""
    hdr_end = text.index("END OF HEADER") + len("END OF HEADER") if "END OF HEADER" in text \
        else text.index("\n", text.index("\n*") + 1)
    hdr_end = text.index("\n", hdr_end) + 1
    first_ln_end = text.index("\n", hdr_end)
    mid_rec_ln = text.index("\n", first_ln_end + 1) + 1
    # a number: the first digit-dot-digit run after the first epoch line
    k = first_ln_end + 1
    while not (text[k].isdigit() and "." in text[k:k + 12]):
        k += 1
    mid_number = k + text[k:k + 12].index(".") + 2
    cuts = {"header": hdr_end // 2, "after header": hdr_end,
            "inside first epoch line": (hdr_end + first_ln_end) // 2,
            "after first epoch line": first_ln_end + 1,
            "record line boundary": mid_rec_ln, "inside a number": mid_number,
            "end of 2nd record, no newline": records_end[1],
            "end of 2nd record + newline": records_end[1] + 1,
            "inside a number of the last record": records_end[-1] - 3,
            "one byte short": len(text.rstrip("\n")) - 1,
            "final newline removed": len(text.rstrip("\n"))}
    if text.count("\n") <= 150:  # small files: also every line end (±newline) and mid-line
        pos = 0
        for n, line in enumerate(text.split("\n")[:-1]):
            cuts[f"line {n + 1} middle"] = pos + len(line) // 2
            cuts[f"line {n + 1} end"] = pos + len(line)
            cuts[f"line {n + 1} end + newline"] = pos + len(line) + 1
            pos += len(line) + 1
    return {k: v for k, v in cuts.items() if 0 < v <= len(text)}


SWEEP = {  # file -> reader kind
    "14601736.18o": "obs", "demo.10o": "obs", "demo3.10o": "obs", "minimal2.10o": "obs",
    "demo.10n": "nav", "demo_nav3.17n": "nav", "minimal2.10n": "nav",
    "igs19362.sp3c": "sp3", "minimal.sp3c": "sp3",
}
_SWEEP_COUNTS = {"cuts": 0, "error": 0, "exact": 0}  # printed with -s: the closing figures


@pytest.mark.parametrize("name", sorted(SWEEP))
def test_truncation_sweep(name, tmp_path):
    kind = SWEEP[name]
    text = (CORPUS / name).read_text()
    if kind == "obs":
        records = oracle.obs_epochs(text)[2]
    elif kind == "nav":
        records = oracle.nav_gps_records(text)[1]
    else:
        records = oracle.sp3_gps_epochs(text)
    ends = [r.end for r in records]
    assert len(ends) >= 1
    if len(ends) < 2:
        ends = [ends[0], ends[0]]
    reader = dict(READERS)[kind]
    for label, cut in _cut_points(text, ends).items():
        path = tmp_path / f"{label.replace(' ', '_').replace(',', '')}.{name}"
        path.write_text(text[:cut])
        result, outcome = _outcome(reader, path)
        complete = [r for r in records if r.end <= cut]
        _SWEEP_COUNTS["cuts"] += 1
        if result is None:
            _SWEEP_COUNTS["error"] += 1
            assert label not in ("final newline removed",), f"{label}: {outcome}"
            continue
        _SWEEP_COUNTS["exact"] += 1
        assert complete, f"{label}: accepted a file with no complete record"
        if kind == "obs":
            _check_obs_against_text(result, text, complete)
        elif kind == "nav":
            _check_nav_against_text(result, text, complete)
        else:
            _check_sp3_against_text(result, text, complete)
    print(f"\n{name}: {_SWEEP_COUNTS}")


def test_truncated_compressed_files(tmp_path):
    """Cuts of compressed copies (Hatanaka, gzip, bzip2, zip, .Z): the one-line error, or a
    read equal to the start of the complete file's."""
    n_err = n_ok = 0
    for name in ("P43300USA_R_20190012056_17M_15S_MO.crx", "york0440.15d",
                 "P43300USA_R_20190012056_17M_15S_MO.crx.bz2", "ab430140.18o.zip",
                 "ac660270.18o.Z", "brdc2420.18n.gz", "example1.sp3a.gz"):
        raw = (CORPUS / name).read_bytes()
        kind = "sp3" if ".sp3" in name else "nav" if "n." in name else "obs"
        full, _ = _outcome(dict(READERS)[kind], CORPUS / name)
        for frac in (0.1, 0.5, 0.9):
            path = tmp_path / f"cut{int(frac * 100)}_{name}"
            path.write_bytes(raw[:int(len(raw) * frac)])
            result, outcome = _outcome(dict(READERS)[kind], path)
            if result is None:
                n_err += 1
                continue
            n_ok += 1
            if kind == "obs":
                n = result.n_epochs
                np.testing.assert_array_equal(result.t_gps, full.t_gps[:n])
                for j, s in enumerate(result.sats):
                    jf = list(full.sats).index(s)
                    for nm in OBS_NAMES:
                        if result.signals[nm][j] == full.signals[nm][jf]:
                            np.testing.assert_array_equal(getattr(result, nm)[:, j],
                                                          getattr(full, nm)[:n, jf])
            else:
                raise AssertionError(f"{path.name}: a cut {kind} archive was accepted")
    bogus = tmp_path / "bogus.18o.zip"
    bogus.write_text("this is not a zip")
    _, outcome = _outcome(dict(READERS)["obs"], bogus)
    assert "not a zip file" in outcome
    print(f"\ncompressed cuts: {n_err} one-line errors, {n_ok} exact prefixes")
    assert n_err + n_ok == 21


def test_minimal_obs_reads_with_warnings_as_errors():
    """No warning of a library leaks: under '-W error' the single-epoch minimal2.10o reads.
    Only the reader's own note (the file's GLONASS satellites are skipped) is let through,
    by its exact text."""
    code = ("import warnings; warnings.filterwarnings('ignore', message='minimal2.10o: "
            "mixed-system RINEX 2 file; only GPS'); from gnss.rinex import read_obs; "
            f"o = read_obs({str(CORPUS / 'minimal2.10o')!r}, use_cache=False); "
            "print(o.n_epochs, o.sats.size)")
    run = subprocess.run([sys.executable, "-W", "error", "-c", code], capture_output=True,
                         text=True, cwd=Path(__file__).resolve().parents[1], check=False)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["1", "5"]
