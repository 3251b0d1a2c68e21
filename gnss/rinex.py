"""RINEX 2.1x / 3.x observation and GPS navigation readers, with an NPZ cache.

Observation files are parsed here, fixed-column, decoding only the GPS satellite lines (a
day of 30-s all-system data reads in ~1 s); navigation records are decoded by georinex
after a layout check here. Files may be gzip/bzip2/zip/.Z/xz compressed and/or Hatanaka;
every decoding or layout failure is one GmisInputError line naming the file (and the line).
The rules (no final newline, 60-s epochs, type-count mismatch, truncation) are in
docs/formats.md, "GNSS input files".

Time base: every time in the ``gnss`` package is a float of **seconds since the GPS epoch
1980-01-06 00:00:00 GPST** ("absolute GPS seconds"). ``ObsData.week`` / ``ObsData.sow``
give the same instants as GPS week + seconds of week for reports and for ``docs/formats.md``
(``time_gps_s`` = ``sow`` when a dataset uses seconds of week). A float64 of ~1.4e9 s keeps
~0.2 µs resolution, i.e. < 1 mm of satellite motion.

Observables (one column per satellite, NaN where absent) and the RINEX codes read for them,
in priority order. The choice is made **per satellite**: the first code in the list that has
at least one value for that satellite in the file is used for the whole file, so one arc never
mixes tracking modes; ``ObsData.signals[name][k]`` records the code chosen for satellite k.

====== ============================================ ===================
name   RINEX 3 priority                              RINEX 2 priority
====== ============================================ ===================
C1     C1C > C1W > C1P > C1X > C1L > C1S (m)         C1 > P1
L1     L1C > L1W > L1P > L1X > L1L > L1S (cycles)    L1
D1     D1C > D1W > D1P > D1X > D1L > D1S (Hz)        D1
S1     S1C > S1W > S1P > S1X > S1L > S1S (dB-Hz)     S1
C2     C2W > C2P > C2L > C2X > C2S > C2D > C2C (m)   P2 > C2
L2     L2W > L2P > L2L > L2X > L2S > L2D > L2C       L2
D2     D2W > D2P > D2L > D2X > D2S > D2D > D2C       D2
S2     S2W > S2P > S2L > S2X > S2S > S2D > S2C       S2
====== ============================================ ===================

LLI1/LLI2 are the loss-of-lock indicators of the chosen L1/L2 phase (int8, 0 when blank).
Only GPS ('G') is processed; other systems in the file are skipped and reported once in
``notes`` and by ``warnings.warn``.

Parsed files are cached as NPZ in ``$GMIS_CACHE_DIR`` (default ``~/.cache/gmis/rinex``)
keyed by the SHA-256 of the file's bytes, so an edited file is re-parsed. If the cache is
not writable the reader warns once and works without it.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import warnings
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np

from gnss.constants import SECONDS_PER_WEEK
from gnss.errors import GnssInputError as GmisInputError

CACHE_FORMAT_VERSION = "3"
_GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")

OBS_PRIORITY_RINEX3 = {
    "C1": ("C1C", "C1W", "C1P", "C1X", "C1L", "C1S"),
    "L1": ("L1C", "L1W", "L1P", "L1X", "L1L", "L1S"),
    "D1": ("D1C", "D1W", "D1P", "D1X", "D1L", "D1S"),
    "S1": ("S1C", "S1W", "S1P", "S1X", "S1L", "S1S"),
    "C2": ("C2W", "C2P", "C2L", "C2X", "C2S", "C2D", "C2C"),
    "L2": ("L2W", "L2P", "L2L", "L2X", "L2S", "L2D", "L2C"),
    "D2": ("D2W", "D2P", "D2L", "D2X", "D2S", "D2D", "D2C"),
    "S2": ("S2W", "S2P", "S2L", "S2X", "S2S", "S2D", "S2C"),
}
OBS_PRIORITY_RINEX2 = {
    "C1": ("C1", "P1"), "L1": ("L1",), "D1": ("D1",), "S1": ("S1",),
    "C2": ("P2", "C2"), "L2": ("L2",), "D2": ("D2",), "S2": ("S2",),
}
OBS_NAMES = ("C1", "L1", "D1", "S1", "C2", "L2", "D2", "S2")

NAV_FIELDS = ("prn", "toc", "toe", "week", "sqrt_a", "e", "i0", "omega0", "omega", "m0",
              "delta_n", "idot", "omega_dot", "cuc", "cus", "crc", "crs", "cic", "cis",
              "af0", "af1", "af2", "tgd", "health", "iode", "iodc", "fit_interval_h")
_GEORINEX_NAV = {"sqrt_a": "sqrtA", "e": "Eccentricity", "i0": "Io", "omega0": "Omega0",
                 "omega": "omega", "m0": "M0", "delta_n": "DeltaN", "idot": "IDOT",
                 "omega_dot": "OmegaDot", "cuc": "Cuc", "cus": "Cus", "crc": "Crc",
                 "crs": "Crs", "cic": "Cic", "cis": "Cis", "af0": "SVclockBias",
                 "af1": "SVclockDrift", "af2": "SVclockDriftRate", "tgd": "TGD",
                 "health": "health", "iode": "IODE", "iodc": "IODC"}


@dataclass
class ObsData:
    """GPS observations of one receiver. Arrays are (n_epochs, n_sats), NaN when absent.

    t_gps: absolute GPS seconds of each epoch (receiver time tags); week/sow the same as
    GPS week and seconds of week. prn: (n_sats,) GPS PRN numbers; sats: "G05"-style ids.
    C1/C2 code (m), L1/L2 phase (cycles), D1/D2 Doppler (Hz), S1/S2 SNR (dB-Hz).
    """

    path: str
    version: float
    marker: str
    approx_position_ecef: np.ndarray | None
    interval: float
    t_gps: np.ndarray
    week: np.ndarray
    sow: np.ndarray
    prn: np.ndarray
    sats: np.ndarray
    C1: np.ndarray
    L1: np.ndarray
    D1: np.ndarray
    S1: np.ndarray
    C2: np.ndarray
    L2: np.ndarray
    D2: np.ndarray
    S2: np.ndarray
    LLI1: np.ndarray
    LLI2: np.ndarray
    signals: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    @property
    def n_epochs(self) -> int:
        return self.t_gps.size

    def sat_index(self, prn: int) -> int:
        """Column of a PRN, −1 if the satellite is not in the file."""
        hit = np.flatnonzero(self.prn == prn)
        return int(hit[0]) if hit.size else -1


@dataclass
class NavData:
    """GPS broadcast ephemerides, one entry per record (arrays of length n_records).

    toc/toe are absolute GPS seconds; angles in rad (semicircles converted by georinex are
    already radians in RINEX), sqrt_a in m^½, af0 s, af1 s/s, af2 s/s², tgd s,
    fit_interval_h hours (0/blank in the file → 4 h). ion_alpha/ion_beta: Klobuchar
    coefficients from the header (None when the file has none).
    """

    path: str
    version: float
    prn: np.ndarray
    toc: np.ndarray
    toe: np.ndarray
    week: np.ndarray
    sqrt_a: np.ndarray
    e: np.ndarray
    i0: np.ndarray
    omega0: np.ndarray
    omega: np.ndarray
    m0: np.ndarray
    delta_n: np.ndarray
    idot: np.ndarray
    omega_dot: np.ndarray
    cuc: np.ndarray
    cus: np.ndarray
    crc: np.ndarray
    crs: np.ndarray
    cic: np.ndarray
    cis: np.ndarray
    af0: np.ndarray
    af1: np.ndarray
    af2: np.ndarray
    tgd: np.ndarray
    health: np.ndarray
    iode: np.ndarray
    iodc: np.ndarray
    fit_interval_h: np.ndarray
    ion_alpha: np.ndarray | None = None
    ion_beta: np.ndarray | None = None
    notes: list = field(default_factory=list)

    @property
    def n_records(self) -> int:
        return self.prn.size


def gps_seconds_from_datetime64(t: np.ndarray) -> np.ndarray:
    """datetime64 (GPS time scale) → absolute GPS seconds (float64)."""
    dt = (np.asarray(t).astype("datetime64[ns]") - _GPS_EPOCH).astype(np.int64)
    return dt.astype(np.float64) * 1e-9


def gps_seconds_from_datetime(t: datetime) -> float:
    """Naive datetime in GPS time → absolute GPS seconds."""
    return float(gps_seconds_from_datetime64(np.array([np.datetime64(t, "ns")]))[0])


def week_and_sow(t_gps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Absolute GPS seconds → (GPS week, seconds of week)."""
    t = np.asarray(t_gps, dtype=float)
    week = np.floor(t / SECONDS_PER_WEEK).astype(np.int64)
    return week, t - week * SECONDS_PER_WEEK


# ---------------------------------------------------------------- file text

_MAGIC = ((b"\x1f\x8b", "gzip"), (b"BZh", "bzip2"), (b"PK\x03\x04", "zip"), (b"PK\x05\x06", "zip"),
          (b"\x1f\x9d", "Unix compress (.Z)"), (b"\xfd7zXZ\x00", "xz"))
_SUFFIX_FORMAT = {".gz": "gzip", ".bz2": "bzip2", ".zip": "zip", ".z": "Unix compress (.Z)",
                  ".xz": "xz"}


def _decompress(raw: bytes, fmt: str) -> bytes:
    import bz2
    import gzip
    import io
    import lzma
    import zipfile
    if fmt == "gzip":
        return gzip.decompress(raw)
    if fmt == "bzip2":
        return bz2.decompress(raw)
    if fmt == "xz":
        return lzma.decompress(raw)
    if fmt == "zip":
        with zipfile.ZipFile(io.BytesIO(raw)) as z:
            names = [n for n in z.namelist() if not n.endswith("/")]
            if not names:
                raise ValueError("the zip archive holds no file")
            return z.read(names[0])
    from ncompress import decompress as unlzw
    return unlzw(raw)


def read_text(path: Path) -> str:
    """The text of a RINEX/SP3 file, decompressed (gzip, bzip2, zip, .Z, xz — recognised by
    their magic bytes, whatever the suffix) and Hatanaka-expanded (CRINEX 1/3).

    Every decoding failure (damaged or truncated archive, truncated CRINEX) is one
    GmisInputError naming the file. Leading blank lines are kept (line numbers in messages
    count them); the readers skip them as georinex does."""
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise GmisInputError(f"cannot read file ({exc.strerror or exc})", str(path)) from None
    fmt = next((name for magic, name in _MAGIC if raw.startswith(magic)), None)
    claimed = _SUFFIX_FORMAT.get(path.suffix.lower())
    if fmt is None and claimed is not None:
        raise GmisInputError(f"not a {claimed} file (its name says {path.suffix}, its first "
                             "bytes do not)", str(path))
    if fmt is not None:
        try:
            raw = _decompress(raw, fmt)
        except Exception as exc:  # noqa: BLE001 — zlib/bz2/lzma/zipfile/ncompress errors
            msg = str(exc).splitlines()[0] if str(exc) else "damaged or truncated"
            raise GmisInputError(f"cannot decompress {fmt} data ({exc.__class__.__name__}: "
                                 f"{msg})", str(path)) from None
    if raw.startswith((b"\x89HDF", b"CDF")):
        raise GmisInputError("a NetCDF/HDF5 file, not RINEX/SP3 text", str(path))
    if b"\x00" in raw[:4096]:
        raise GmisInputError("a binary file, not RINEX/SP3 text", str(path))
    text = raw.decode("ascii", errors="replace")
    start = _first_nonblank_offset(text)
    first = text[start:].split("\n", 1)[0]
    if first[20:40] == "COMPACT RINEX FORMAT" or first[60:80].startswith("CRINEX VERS"):
        text = text[start:]
        import hatanaka
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                text = hatanaka.crx2rnx(text)
        except Exception as exc:  # noqa: BLE001 — HatanakaException and decoder errors
            msg = str(exc).splitlines()[0] if str(exc) else ""
            raise GmisInputError(f"cannot expand Hatanaka (CRINEX) data "
                                 f"({exc.__class__.__name__}: {msg})", str(path)) from None
    return text


def _first_nonblank_offset(text: str) -> int:
    """Offset of the first line that is not blank (0 when there is none)."""
    pos = 0
    while True:
        nl = text.find("\n", pos)
        if nl < 0:
            return pos if text[pos:].strip() else 0
        if text[pos:nl].strip():
            return pos
        pos = nl + 1


# ---------------------------------------------------------------- header / structure

def _split_header(text: str, path: Path) -> tuple[list[str], list[str], int]:
    """(header lines from the first non-blank line, body lines, index of the first body line
    in the file)."""
    lines = text.splitlines()
    start = next((k for k, ln in enumerate(lines) if ln.strip()), 0)
    for i in range(start, len(lines)):
        if lines[i][60:].strip().startswith("END OF HEADER"):
            return lines[start:i + 1], lines[i + 1:], i + 1
    raise GmisInputError("no 'END OF HEADER' line: not a RINEX file or truncated header",
                         str(path))


def _header_version(header: list[str], path: Path) -> tuple[float, str, str]:
    first = header[0]
    if "RINEX VERSION / TYPE" not in first[60:]:
        raise GmisInputError("first line is not 'RINEX VERSION / TYPE'", str(path))
    try:
        version = float(first[:9])
    except ValueError:
        raise GmisInputError(f"unreadable RINEX version {first[:9]!r}", str(path)) from None
    if not (2.0 <= version < 4.0):
        raise GmisInputError(f"unsupported RINEX version {version} (2.x and 3.x are supported)",
                             str(path))
    return version, first[20:21].upper(), first[40:41].upper()


# epoch lines of observation records (the satellite count, I3, is checked separately: some
# writers put it left-justified in its field)
_RINEX2_EPOCH = re.compile(r"^ [ \d]\d( [ \d]\d){4}[ \d]{2}\d\.\d{7}  [016]")
_RINEX3_EPOCH = re.compile(r"^> \d{4}( [ \d]\d){4}[ \d]{2}\d\.\d{7}  [016]")


class _Layout(Exception):
    """A record that breaks the fixed-column layout: (0-based line index in the file, what)."""


def _bad_line(line_index: int, line: str) -> _Layout:
    return _Layout(line_index, f"malformed or truncated epoch record {line.rstrip()[:60]!r}")


def _obs_types(header: list[str], version: float, path: Path, notes: list[str]) -> list[str]:
    """GPS observation types in file order (RINEX 2 '# / TYPES OF OBSERV', RINEX 3 'G' of
    'SYS / # / OBS TYPES'). When the declared count differs from the list, the listed
    types are used (the data lines follow the list) and a note says so."""
    label = "# / TYPES OF OBSERV" if version < 3.0 else "SYS / # / OBS TYPES"
    declared, types, sys_now = None, [], None
    for line in header:
        if label not in line[60:]:
            continue
        if version < 3.0:
            if declared is None:
                declared = line[:6]
            types += line[6:60].split()
        else:
            if line[0].strip():
                sys_now = line[0]
                if sys_now == "G":
                    declared = line[3:6]
            if sys_now == "G":
                types += line[7:60].split()
    if declared is None:
        return []
    try:
        n = int(declared)
    except ValueError:
        raise GmisInputError(f"unreadable number of observation types {declared!r}",
                             str(path)) from None
    if n != len(types):
        notes.append(f"{path.name}: header declares {n} GPS observation types but lists "
                     f"{len(types)} ({' '.join(types)}); the {len(types)} listed are used")
    return types


def _epoch_time(y: str, mo: str, d: str, h: str, mi: str, sec: str) -> np.datetime64:
    """Exact epoch tag (ns). Seconds ≥ 60 (a receiver writing 60.0000000) roll into the next
    minute, as RTKLIB's epoch2time does."""
    whole, _, frac = sec.strip().partition(".")
    day = np.datetime64(f"{int(y):04d}-{int(mo):02d}-{int(d):02d}", "ns")
    ns = (int(h) * 3600 + int(mi) * 60 + int(whole)) * 10**9 + int((frac + "000000000")[:9])
    return day + np.timedelta64(ns, "ns")


def _obs_records(body: list[str], version: float, n_types: int, first_line: int):
    """Walk the epoch records of an observation body.

    Returns (epoch times datetime64[ns], GPS record texts, their epoch index, their sat ids,
    their first line index, n_epochs_with_60s, whether the last non-blank line belongs to an
    observation record). Only GPS satellite lines are kept; a
    record of another system is skipped without being parsed. Raises _Layout on a line
    that is not where the layout puts it (a malformed epoch line, a record cut short)."""
    times: list[np.datetime64] = []
    texts: list[str] = []
    ep_idx: list[int] = []
    sats: list[str] = []
    lines_at: list[int] = []
    n60 = 0
    obs_end = -1
    n_lines_sat = (n_types - 1) // 5 + 1 if version < 3.0 else 1
    i, nb = 0, len(body)
    while i < nb:
        ln = body[i]
        if not ln.strip():
            i += 1
            continue
        if version >= 3.0:
            if not ln.startswith(">") or not ln[32:35].strip().isdigit() \
                    or ln[31] not in "0123456":
                raise _bad_line(first_line + i, ln)
            flag, n = int(ln[31]), int(ln[32:35])
        else:
            if len(ln) < 30 or ln[28] not in "0123456" or not ln[29:32].strip().isdigit():
                raise _bad_line(first_line + i, ln)
            flag, n = int(ln[28]), int(ln[29:32])
        if flag in (2, 3, 4, 5):  # special records: n header/comment lines follow
            if i + 1 + n > nb:
                raise _Layout(first_line + nb, "")
            for k in range(i + 1, i + 1 + n):
                if "TYPES OF OBSERV" in body[k][60:] or "SYS / # / OBS TYPES" in body[k][60:]:
                    raise _Layout(first_line + k, "observation types redefined inside the "
                                  "file (not supported)")
            i += 1 + n
            continue
        regex = _RINEX3_EPOCH if version >= 3.0 else _RINEX2_EPOCH
        if not regex.match(ln):
            raise _bad_line(first_line + i, ln)
        if version >= 3.0:
            svs = None
            hdr_lines = 1
        else:  # RINEX 2: satellite list, 12 per line, continuation lines after the first
            hdr_lines = (n - 1) // 12 + 1 if n else 1
            if i + hdr_lines > nb:
                raise _Layout(first_line + nb, "")
            svs = []
            for k in range(hdr_lines):
                row = body[i + k][32:68]
                want = min(12, n - 12 * k)
                if len(row.rstrip()) < 3 * want:
                    raise _bad_line(first_line + i + k, body[i + k])
                svs += [row[3 * j:3 * j + 3] for j in range(want)]
        start = i + hdr_lines
        end = start + n * n_lines_sat
        if end > nb:
            raise _Layout(first_line + nb, "")
        obs_end = end
        if flag == 6:  # cycle-slip records repeat observations: not observations themselves
            i = end
            continue
        if version >= 3.0:
            y, mo, d, h, mi, sec = ln[2:6], ln[7:9], ln[10:12], ln[13:15], ln[16:18], ln[18:29]
        else:
            yy = int(ln[1:3])
            y = str(yy + (2000 if yy < 80 else 1900))
            mo, d, h, mi, sec = ln[4:6], ln[7:9], ln[10:12], ln[13:15], ln[15:26]
        n60 += float(sec) >= 60.0
        times.append(_epoch_time(y, mo, d, h, mi, sec))
        e = len(times) - 1
        if version >= 3.0:
            for k in range(start, end):
                row = body[k]
                if row[:1] == "G":
                    texts.append(row[3:])
                    sats.append(row[:3])
                    ep_idx.append(e)
                    lines_at.append(first_line + k)
                elif row[:1] == ">" or not row[:1].strip():
                    raise _Layout(first_line + k, "a satellite line expected (the epoch "
                                  "record has fewer lines than its epoch line announces)")
        else:
            for j, sv in enumerate(svs):
                if sv[0] in "G ":
                    k = start + j * n_lines_sat
                    rows = body[k:k + n_lines_sat]
                    if any(len(r.rstrip()) > 80 for r in rows):
                        raise _Layout(first_line + k, "observation line longer than 80 columns")
                    texts.append("".join(r.ljust(80) for r in rows))
                    sats.append(sv)
                    ep_idx.append(e)
                    lines_at.append(first_line + k)
        i = end
    last = max((k for k in range(nb) if body[k].strip()), default=-1)
    return (np.array(times, dtype="datetime64[ns]"), texts, np.array(ep_idx, dtype=np.int64),
            sats, np.array(lines_at, dtype=np.int64), n60, obs_end == last + 1)


def _obs_values(texts: list[str], n_types: int, version: float, lines_at: np.ndarray):
    """Fixed-column decode of the GPS records: (values (n_rec, n_types) NaN when blank,
    LLI (n_rec, n_types) int8). Every non-blank F14.3 field must end '.ddd' at its
    column: a field cut by a truncation (or shifted) is an error, never a number."""
    width = 16 * n_types
    too_long = [k for k, t in enumerate(texts) if len(t.rstrip()) > width]
    if too_long:
        raise _Layout(int(lines_at[too_long[0]]), "more observations than the header lists")
    buf = "".join(t.ljust(width)[:width] for t in texts).encode("ascii", errors="replace")
    chars = np.frombuffer(buf, dtype="S1").reshape(len(texts), width)
    values = np.full((len(texts), n_types), np.nan)
    lli = np.zeros((len(texts), n_types), dtype=np.int8)
    digits = (chars >= b"0") & (chars <= b"9")
    blank = chars == b" "
    for j in range(n_types):
        s = 16 * j
        fld = chars[:, s:s + 14]
        empty = blank[:, s:s + 14].all(axis=1)
        ok = (chars[:, s + 10] == b".") & digits[:, s + 11:s + 14].all(axis=1) \
            & (digits[:, s:s + 10] | blank[:, s:s + 10] | (fld[:, :10] == b"-")).all(axis=1)
        bad = ~empty & ~ok
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise _Layout(int(lines_at[k]) + (j // 5 if version < 3.0 else 0),
                          "observation field cut short or malformed")
        if (~empty).any():
            vals = np.ascontiguousarray(fld[~empty]).view("S14").ravel().astype(float)
            values[~empty, j] = vals
        c = chars[:, s + 14]
        has = (c >= b"0") & (c <= b"9")
        if has.any():
            lli[has, j] = (np.frombuffer(c[has].tobytes(), dtype=np.uint8) - 48).astype(np.int8)
    return values, lli


def _approx_position(header: list[str]) -> np.ndarray | None:
    for line in header:
        if "APPROX POSITION XYZ" in line[60:]:
            try:
                xyz = np.array([float(line[0:14]), float(line[14:28]), float(line[28:42])])
            except ValueError:
                return None
            return None if not np.any(xyz) else xyz
    return None


def _header_value(header: list[str], label: str) -> str:
    for line in header:
        if line[60:].strip().startswith(label):
            return line[:60]
    return ""


def _systems_v3(header: list[str]) -> list[str]:
    return sorted({ln[0] for ln in header
                   if "SYS / # / OBS TYPES" in ln[60:] and ln[0].strip()})


# ---------------------------------------------------------------- cache

def _cache_dir(cache_dir: str | os.PathLike | None) -> Path:
    if cache_dir is not None:
        return Path(cache_dir)
    env = os.environ.get("GMIS_CACHE_DIR")
    return Path(env) if env else Path.home() / ".cache" / "gmis" / "rinex"


def _cache_file(path: Path, digest: str, kind: str, cache_dir) -> Path:
    return _cache_dir(cache_dir) / f"{path.name}.{kind}.{digest[:24]}.v{CACHE_FORMAT_VERSION}.npz"


def _cache_load(cfile: Path) -> dict | None:
    try:
        with np.load(cfile, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (OSError, ValueError, KeyError, EOFError):
        return None


def _cache_save(cfile: Path, arrays: dict) -> None:
    try:
        cfile.parent.mkdir(parents=True, exist_ok=True)
        tmp = cfile.with_name(cfile.name + f".{os.getpid()}.tmp.npz")
        np.savez(tmp, **arrays)
        os.replace(tmp, cfile)
    except OSError as exc:
        warnings.warn(f"RINEX cache not writable ({cfile.parent}: {exc}); continuing without "
                      "cache", stacklevel=4)   # the caller of read_obs / read_nav


def _file_digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _parsed_arrays(path: Path, kind: str, parse, cache_dir, use_cache: bool) -> dict:
    """The arrays ``parse(path)`` gives, loaded from the cache file of this content (kind
    "obs" or "nav") when there is a readable one, else parsed and (use_cache) saved."""
    cfile = _cache_file(path, _file_digest(path), kind, cache_dir)
    arrays = _cache_load(cfile) if use_cache and cfile.is_file() else None
    if arrays is None:
        arrays = parse(path)
        if use_cache:
            _cache_save(cfile, arrays)
    return arrays


def checked_input_path(path) -> Path:
    """Path(path) of an existing, non-empty file, else GnssInputError (one line)."""
    p = Path(path)
    if not p.is_file():
        raise GmisInputError("file not found", str(p))
    if p.stat().st_size == 0:
        raise GmisInputError("file is empty", str(p))
    return p


def _georinex_load(path: Path, text: str, **kwargs):
    """georinex on the already decompressed text; its warnings (RuntimeWarning on a single
    record, FutureWarning from xarray) are ours to report, not to leak."""
    import io

    import georinex
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return georinex.load(io.StringIO(text), **kwargs)
    except GmisInputError:
        raise
    except Exception as exc:  # noqa: BLE001 — georinex raises many types on bad text
        msg = str(exc).splitlines()[0] if str(exc) else ""
        raise GmisInputError(f"malformed RINEX ({exc.__class__.__name__}: {msg})",
                             str(path)) from None


# ---------------------------------------------------------------- observations

def _check_final_obs_line(line: str, version: float, line_no: int, path: Path) -> None:
    """A file without its final newline may end inside a field of a satellite the reader
    skips (another system): every F14.3 field of that last line must still be complete."""
    rest = line[3:] if version >= 3.0 else line
    for q in range(0, len(rest.rstrip()), 16):
        fld = rest[q:q + 14]
        if fld.strip() and not (len(fld) == 14 and fld[10] == "." and fld[11:].isdigit()):
            raise GmisInputError(f"line {line_no}: last line ends inside an observation "
                                 "field: the file is truncated", str(path))


def _parse_obs(path: Path) -> dict:
    text = read_text(path)
    header, body, body_at = _split_header(text, path)
    version, ftype, system = _header_version(header, path)
    if ftype != "O":
        raise GmisInputError(f"not an observation file (type {ftype!r})", str(path))
    notes: list[str] = []
    if version < 3.0:
        if not any("# / TYPES OF OBSERV" in ln[60:] for ln in header):
            raise GmisInputError("no '# / TYPES OF OBSERV' in the header", str(path))
        if system not in ("G", " ", "M", ""):
            raise GmisInputError(f"no GPS observations (file system {system!r})", str(path))
        if system == "M":
            notes.append(f"{path.name}: mixed-system RINEX 2 file; only GPS satellites are "
                         "processed, others skipped")
        priority = OBS_PRIORITY_RINEX2
    else:
        systems = _systems_v3(header)
        if "G" not in systems:
            raise GmisInputError(f"no GPS observations (systems in header: {systems})",
                                 str(path))
        others = [s for s in systems if s != "G"]
        if others:
            notes.append(f"{path.name}: systems {''.join(others)} skipped (only GPS is "
                         "processed)")
        priority = OBS_PRIORITY_RINEX3
    types = _obs_types(header, version, path, notes)
    if not types:
        raise GmisInputError("no GPS observation types in the header", str(path))
    try:
        times, texts, ep_idx, sv_ids, lines_at, n60, ends_in_obs = _obs_records(
            body, version, len(types), body_at)
        if times.size == 0:
            raise GmisInputError("no epochs in the file", str(path))
        if not texts:
            raise GmisInputError("no GPS observations in the file", str(path))
        values, lli_all = _obs_values(texts, len(types), version, lines_at)
    except _Layout as exc:
        line_no, what = exc.args
        if line_no >= body_at + len(body):
            raise GmisInputError(f"line {line_no}: last epoch record is incomplete: the file "
                                 "is truncated", str(path)) from None
        raise GmisInputError(f"line {line_no + 1}: {what}", str(path)) from None
    # a last line without its line break may have been cut (a CR alone still ends a line)
    unterminated = not text.endswith(("\n", "\r"))
    if unterminated and body and body[-1] and not body[-1].strip():
        raise GmisInputError(f"line {body_at + len(body)}: file ends in a partial blank "
                             "line: the file is truncated", str(path))
    if unterminated and ends_in_obs:
        k = max(k for k in range(len(body)) if body[k].strip())
        _check_final_obs_line(body[k], version, body_at + k + 1, path)
    if n60:
        notes.append(f"{path.name}: {n60} epoch(s) tagged 60.0 s normalised to the next "
                     "minute (as RTKLIB does)")
    if np.any(np.diff(times) <= np.timedelta64(0, "ns")):
        k = int(np.flatnonzero(np.diff(times) <= np.timedelta64(0, "ns"))[0]) + 1
        raise GmisInputError(f"epoch {k + 1} ({times[k]}) is not after the previous epoch "
                             "(duplicated or unordered time tags)", str(path))
    sv_ids = np.array([("G" + sv[1:].replace(" ", "0")) for sv in sv_ids])
    sats = np.unique(sv_ids)
    col = np.searchsorted(sats, sv_ids)
    n_ep, n_sat = times.size, sats.size
    out: dict = {}
    signals: dict = {}
    grids: dict = {}
    for name in OBS_NAMES:
        arr = np.full((n_ep, n_sat), np.nan)
        chosen = np.array([""] * n_sat, dtype="<U3")
        lli = np.zeros((n_ep, n_sat), dtype=np.int8)
        for code in priority[name]:
            if code not in types:
                continue
            if code not in grids:
                j = types.index(code)
                g = np.full((n_ep, n_sat), np.nan)
                g[ep_idx, col] = values[:, j]
                gl = np.zeros((n_ep, n_sat), dtype=np.int8)
                gl[ep_idx, col] = lli_all[:, j]
                grids[code] = (g, gl)
            vals, lv = grids[code]
            take = np.isfinite(vals).any(axis=0) & (chosen == "")
            arr[:, take] = vals[:, take]
            chosen[take] = code
            if name in ("L1", "L2"):
                lli[:, take] = lv[:, take]
        out[name] = arr
        signals[name] = chosen
        if name == "L1":
            out["LLI1"] = lli
        elif name == "L2":
            out["LLI2"] = lli
    if not np.isfinite(out["C1"]).any() and not np.isfinite(out["L1"]).any():
        raise GmisInputError("no GPS L1 code or phase observations in the file", str(path))
    # epochs in which no GPS satellite has any observation are dropped
    has_any = np.zeros(n_ep, dtype=bool)
    for name in ("C1", "L1", "C2", "L2"):
        has_any |= np.isfinite(out[name]).any(axis=1)
    if not has_any.any():
        raise GmisInputError("all epochs are empty (no GPS observations)", str(path))
    if not has_any.all():
        notes.append(f"{path.name}: {int((~has_any).sum())} epochs without GPS data dropped")
    t = gps_seconds_from_datetime64(times)
    try:
        interval = float(_header_value(header, "INTERVAL")[:10])
    except ValueError:
        interval = float(np.median(np.diff(t))) if t.size > 1 else float("nan")
    arrays = {k: v[has_any] for k, v in out.items()}
    approx = _approx_position(header)
    arrays.update(
        t_gps=t[has_any], sats=sats, prn=np.array([int(s[1:]) for s in sats]),
        approx=approx if approx is not None else np.full(3, np.nan),
        meta=np.array(json.dumps({
            "version": version, "marker": _header_value(header, "MARKER NAME").strip(),
            "interval": interval,
            "signals": {k: v.tolist() for k, v in signals.items()}, "notes": notes})))
    return arrays


def _obs_from_arrays(path: Path, a: dict) -> ObsData:
    meta = json.loads(str(a["meta"]))
    week, sow = week_and_sow(a["t_gps"])
    approx = a["approx"]
    return ObsData(
        path=str(path), version=meta["version"], marker=meta["marker"],
        approx_position_ecef=None if not np.all(np.isfinite(approx)) else approx.copy(),
        interval=meta["interval"], t_gps=a["t_gps"], week=week, sow=sow, prn=a["prn"],
        sats=a["sats"], **{k: a[k] for k in OBS_NAMES}, LLI1=a["LLI1"], LLI2=a["LLI2"],
        signals={k: np.array(v, dtype="<U3") for k, v in meta["signals"].items()},
        notes=list(meta["notes"]))


def _to_gps_seconds(t) -> float:
    return gps_seconds_from_datetime(t) if isinstance(t, datetime) else float(t)


def read_obs(path, use=("G",), tlim=None, cache_dir=None, use_cache: bool = True) -> ObsData:
    """Read GPS observations from a RINEX 2.1x/3.x observation file (also .gz/.crx where
    georinex can open them).

    use: satellite systems requested; only "G" is supported (others are reported and
    skipped). tlim: optional (start, end), inclusive, as absolute GPS seconds or naive GPS
    datetimes. Raises GmisInputError for a missing, unreadable, truncated or malformed file,
    an unsupported version, or a file without GPS observations.
    """
    path = checked_input_path(path)
    if "G" not in tuple(use):
        raise GmisInputError(f"use={tuple(use)} has no 'G': only GPS is supported", str(path))
    extra = [s for s in use if s != "G"]
    arrays = _parsed_arrays(path, "obs", _parse_obs, cache_dir, use_cache)
    obs = _obs_from_arrays(path, arrays)
    if extra:
        obs.notes.append(f"{path.name}: systems {''.join(extra)} requested but only GPS is "
                         "supported; skipped")
    for note in obs.notes:
        warnings.warn(note, stacklevel=2)
    if tlim is not None:
        t0, t1 = _to_gps_seconds(tlim[0]), _to_gps_seconds(tlim[1])
        keep = (obs.t_gps >= t0 - 1e-6) & (obs.t_gps <= t1 + 1e-6)
        if not keep.any():
            raise GmisInputError(f"no epochs inside tlim {tlim}", str(path))
        obs = _slice_epochs(obs, keep)
    return obs


def _slice_epochs(obs: ObsData, keep: np.ndarray) -> ObsData:
    kw = {k: getattr(obs, k) for k in obs.__dataclass_fields__}
    for k in ("t_gps", "week", "sow", "LLI1", "LLI2") + OBS_NAMES:
        kw[k] = kw[k][keep]
    return ObsData(**kw)


# ---------------------------------------------------------------- navigation

_NAV_SYSTEMS = {"G": "GPS", "R": "GLONASS", "E": "Galileo", "J": "QZSS", "C": "BeiDou",
                "I": "NavIC/IRNSS", "S": "SBAS"}
_NAV2_TYPES = {"G": "GLONASS", "H": "SBAS (GEO)", "E": "Galileo", "L": "Galileo",
               "J": "QZSS", "C": "BeiDou"}
_NAV_NUMBER = re.compile(r"^ *[+-]?(\d+\.?\d*|\.\d+)([DEde][+-]?\d+)?$")


def _nav_record_lines(sys_char: str, version: float) -> int:
    """Lines of one RINEX 3 navigation record (epoch/clock line + broadcast orbits): 8,
    SBAS 4, GLONASS 4 (5 from RINEX 3.05, which adds BROADCAST ORBIT - 4)."""
    if sys_char == "R":
        return 5 if version >= 3.05 - 1e-9 else 4
    return 4 if sys_char == "S" else 8


def _check_nav_layout(body: list[str], version: float, first_line: int, unterminated: bool,
                      path: Path) -> None:
    """Structure of the navigation body: every record complete (its number of lines), every
    GPS data line on the 19-column field grid with complete numbers (a field cut by a
    truncation is an error with its line number, never a number) and, for the last line of
    an unterminated file, all of its fields present (orbit 7: transmission time and fit
    interval)."""
    where = [(first_line + i, ln) for i, ln in enumerate(body) if ln.strip()]
    if not where:
        raise GmisInputError("no ephemeris records in the file", str(path))
    k, n = 0, len(where)
    last_line_no = where[-1][0]
    n_fields_before: dict[int, int] = {}  # line of a GPS record -> fields in the previous one
    while k < n:
        line_no, ln = where[k]
        if version >= 3.0:
            sys_char = ln[:1]
            if sys_char not in _NAV_SYSTEMS:
                raise GmisInputError(f"line {line_no + 1}: expected the first line of a "
                                     f"navigation record, found {ln.rstrip()[:40]!r}", str(path))
            size, pre0, pre = _nav_record_lines(sys_char, version), 23, 4
        else:
            sys_char, size, pre0, pre = "G", 8, 22, 3
        if k + size > n:
            raise GmisInputError(f"line {line_no + 1}: last ephemeris record has "
                                 f"{n - k} of {size} lines: the file is truncated", str(path))
        if sys_char == "G":
            for m in range(size):
                ln_no, row = where[k + m]
                start = pre0 if m == 0 else pre
                tail = row.rstrip()[start:]
                fields = [tail[q:q + 19] for q in range(0, len(tail), 19)]
                # a final line without its newline may have lost whole fields: it must hold
                # as many as the same line of the record before (or, in a one-record file,
                # all but the optional fit interval)
                need = n_fields_before.get(m, 1 if m == size - 1 else 3 if m == 0 else 4) \
                    if (unterminated and ln_no == last_line_no) else 0
                if len(tail) % 19 or len(fields) < need or len(fields) > 4 or \
                        any(f.strip() and not _NAV_NUMBER.match(f) for f in fields):
                    raise GmisInputError(f"line {ln_no + 1}: ephemeris line cut short or off "
                                         f"the 19-column field grid: {row.rstrip()[-40:]!r}",
                                         str(path))
                n_fields_before[m] = len(fields)
        k += size


def _parse_nav(path: Path) -> dict:
    text = read_text(path)
    header, body, body_at = _split_header(text, path)
    version, ftype, system = _header_version(header, path)
    if version < 3.0:
        if ftype in _NAV2_TYPES:
            raise GmisInputError(f"a {_NAV2_TYPES[ftype]} navigation file (RINEX {version:.2f} "
                                 f"type {ftype!r}): only GPS ephemerides are read", str(path))
        if ftype != "N":
            raise GmisInputError(f"not a GPS navigation file (type {ftype!r})", str(path))
    else:
        if ftype != "N":
            raise GmisInputError(f"not a navigation file (type {ftype!r})", str(path))
        if system not in ("G", "M", " "):
            name = _NAV_SYSTEMS.get(system, f"system {system!r}")
            raise GmisInputError(f"a {name} navigation file (system {system!r}): only GPS "
                                 "ephemerides are read", str(path))
    _check_nav_layout(body, version, body_at, not text.endswith(("\n", "\r")), path)
    ds = _georinex_load(path, text[_first_nonblank_offset(text):], use={"G"})
    sats = [s for s in ds.sv.values.tolist() if str(s).startswith("G")] if "sv" in ds.dims \
        else []
    if not sats or "sqrtA" not in ds:
        raise GmisInputError("no GPS ephemeris records in the file", str(path))
    ds = ds.sel(sv=sats)
    sqrt_a = ds["sqrtA"].values
    it, isv = np.nonzero(np.isfinite(sqrt_a))
    if it.size == 0:
        raise GmisInputError("no GPS ephemeris records in the file", str(path))
    rec = {name: ds[gname].values[it, isv].astype(float)
           for name, gname in _GEORINEX_NAV.items()}
    toc = gps_seconds_from_datetime64(ds.time.values)[it]
    toe_sow = ds["Toe"].values[it, isv].astype(float)
    toe = toe_sow + SECONDS_PER_WEEK * np.round((toc - toe_sow) / SECONDS_PER_WEEK)
    fit = ds["FitIntvl"].values[it, isv].astype(float) if "FitIntvl" in ds \
        else np.full(it.size, np.nan)
    fit = np.where(np.isfinite(fit) & (fit > 0), fit, 4.0)
    rec.update(prn=np.array([int(sats[k][1:]) for k in isv]), toc=toc, toe=toe,
               week=np.floor(toe / SECONDS_PER_WEEK).astype(np.int64), fit_interval_h=fit)
    for k in ("health", "tgd", "iode", "iodc", "af2"):
        rec[k] = np.where(np.isfinite(rec[k]), rec[k], 0.0)
    order = np.lexsort((rec["toe"], rec["prn"]))
    arrays = {k: np.asarray(v)[order] for k, v in rec.items()}
    ion = ds.attrs.get("ionospheric_corr_GPS")
    ion = np.asarray(ion, dtype=float) if ion is not None else None
    arrays["ion"] = ion if ion is not None and ion.size == 8 and np.any(ion) \
        else np.full(8, np.nan)
    arrays["meta"] = np.array(json.dumps({"version": version}))
    return arrays


def read_nav(path, cache_dir=None, use_cache: bool = True) -> NavData:
    """Read GPS broadcast ephemerides (RINEX 2.1x GPS nav or 3.x GPS/mixed nav).

    Records are sorted by (prn, toe). Raises GmisInputError for a missing, truncated or
    malformed file, an unsupported version, or a file without GPS records.
    """
    path = checked_input_path(path)
    a = _parsed_arrays(path, "nav", _parse_nav, cache_dir, use_cache)
    meta = json.loads(str(a["meta"]))
    ion = a["ion"]
    has_ion = bool(np.all(np.isfinite(ion)))
    return NavData(path=str(path), version=meta["version"],
                   **{k: a[k] for k in NAV_FIELDS},
                   ion_alpha=ion[:4].copy() if has_ion else None,
                   ion_beta=ion[4:].copy() if has_ion else None)
