"""RINEX 2.1x / 3.x observation and GPS navigation readers (georinex), with an NPZ cache.

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

CACHE_FORMAT_VERSION = "2"
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


# ---------------------------------------------------------------- header / structure

_COMPRESSED_SUFFIXES = (".gz", ".z", ".zip", ".bz2", ".crx", ".xz")


def _read_text(path: Path) -> str:
    if not any(str(path).lower().endswith(sfx) for sfx in _COMPRESSED_SUFFIXES) \
            and path.name[-1:].lower() != "d":  # Hatanaka RINEX 2: *.yyd
        try:
            return path.read_text(errors="replace")
        except OSError as exc:
            raise GmisInputError(f"cannot read file ({exc})", str(path)) from None
    try:
        from georinex.rio import opener
        with opener(path) as f:
            return f.read()
    except (OSError, UnicodeDecodeError, EOFError, ValueError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else ""
        raise GmisInputError(f"cannot read file ({exc.__class__.__name__}: {msg})",
                             str(path)) from None
    except ImportError as exc:  # Hatanaka files need the optional 'hatanaka' package
        raise GmisInputError(f"cannot decompress file ({exc})", str(path)) from None


def _split_header(text: str, path: Path) -> tuple[list[str], list[str]]:
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line[60:].strip().startswith("END OF HEADER"):
            return lines[:i + 1], lines[i + 1:]
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


_RINEX2_EPOCH = re.compile(r"^ [ \d]\d( [ \d]\d){4}[ \d]{2}\d\.\d{7}  [0-6][ \d]{2}\d")


def _epoch_tags_from_text(body: list[str], version: float) -> np.ndarray:
    """Exact epoch time tags (absolute GPS s) of observation epochs (flags 0/1) parsed from
    the text. georinex truncates the fractional second through a float (59.999 s comes out
    as 59.998 s), a 1-ms error that moves satellites by up to ~0.8 m in range."""
    tags = []
    for ln in body:
        if version >= 3.0:
            if not ln.startswith(">") or ln[31:32] not in ("0", "1"):
                continue
            y, mo, d, h, mi, sec = ln[2:6], ln[7:9], ln[10:12], ln[13:15], ln[16:18], ln[18:29]
        else:
            if not _RINEX2_EPOCH.match(ln) or ln[28] not in ("0", "1"):
                continue
            yy = int(ln[1:3])
            y = str(yy + (2000 if yy < 80 else 1900))
            mo, d, h, mi, sec = ln[4:6], ln[7:9], ln[10:12], ln[13:15], ln[15:26]
        whole, _, frac = sec.strip().partition(".")
        day = np.datetime64(f"{int(y):04d}-{int(mo):02d}-{int(d):02d}", "ns")
        ns = (int(h) * 3600 + int(mi) * 60 + int(whole)) * 10**9 + int((frac + "000000000")[:9])
        tags.append(day + np.timedelta64(ns, "ns"))
    return gps_seconds_from_datetime64(np.array(tags, dtype="datetime64[ns]")) if tags \
        else np.zeros(0)


def _check_obs_complete(body: list[str], version: float, n_types_v2: int, text: str,
                        path: Path) -> None:
    """Structural check of the last epoch record: raises on a truncated file."""
    if text and not text.endswith("\n"):
        raise GmisInputError("file ends in the middle of a line (truncated)", str(path))
    if version >= 3.0:
        starts = [i for i, ln in enumerate(body) if ln.startswith(">")]
        if not starts:
            raise GmisInputError("no epochs in the file", str(path))
        last = starts[-1]
        try:
            n = int(body[last][32:35])
        except ValueError:
            raise GmisInputError(f"malformed epoch line {body[last]!r}", str(path)) from None
        expected = n
    else:
        starts = [i for i, ln in enumerate(body) if _RINEX2_EPOCH.match(ln)]
        if not starts:
            raise GmisInputError("no epochs in the file", str(path))
        last = starts[-1]
        flag, n = int(body[last][28]), int(body[last][29:32])
        if flag <= 1 or flag == 6:
            expected = (n - 1) // 12 + n * ((n_types_v2 - 1) // 5 + 1)
        else:
            expected = n
    have = len(body) - last - 1
    if have < expected:
        raise GmisInputError(f"last epoch record is incomplete ({have} of {expected} lines): "
                             "the file is truncated", str(path))


def _check_nav_complete(body: list[str], version: float, text: str, path: Path) -> None:
    if text and not text.endswith("\n"):
        raise GmisInputError("file ends in the middle of a line (truncated)", str(path))
    lines = [ln for ln in body if ln.strip()]
    if not lines:
        raise GmisInputError("no ephemeris records in the file", str(path))
    if version < 3.0:
        if len(lines) % 8:
            raise GmisInputError(f"{len(lines)} data lines is not a multiple of 8 "
                                 "(GPS records): the file is truncated or malformed",
                                 str(path))
        return
    starts = [i for i, ln in enumerate(lines) if ln[:1].isalpha()]
    if not starts:
        raise GmisInputError("no ephemeris records in the file", str(path))
    expected = 3 if lines[starts[-1]][0] in "RS" else 7
    if len(lines) - starts[-1] - 1 < expected:
        raise GmisInputError("last ephemeris record is incomplete: the file is truncated",
                             str(path))


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


def _obs_types_v2(header: list[str]) -> list[str]:
    types: list[str] = []
    for line in header:
        if "# / TYPES OF OBSERV" in line[60:]:
            types += line[6:60].split()
    return types


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
                      "cache", stacklevel=3)


def _file_digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _check_path(path) -> Path:
    p = Path(path)
    if not p.is_file():
        raise GmisInputError("file not found", str(p))
    if p.stat().st_size == 0:
        raise GmisInputError("file is empty", str(p))
    return p


def _georinex_load(path: Path, **kwargs):
    import georinex
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)
            return georinex.load(path, **kwargs)
    except GmisInputError:
        raise
    except Exception as exc:  # noqa: BLE001 — georinex raises many types on bad text
        msg = str(exc).splitlines()[0] if str(exc) else ""
        raise GmisInputError(f"malformed RINEX ({exc.__class__.__name__}: {msg})",
                             str(path)) from None


# ---------------------------------------------------------------- observations

def _parse_obs(path: Path) -> dict:
    text = _read_text(path)
    header, body = _split_header(text, path)
    version, ftype, system = _header_version(header, path)
    if ftype != "O":
        raise GmisInputError(f"not an observation file (type {ftype!r})", str(path))
    notes: list[str] = []
    if version < 3.0:
        types = _obs_types_v2(header)
        if not types:
            raise GmisInputError("no '# / TYPES OF OBSERV' in the header", str(path))
        if system not in ("G", " ", "M", ""):
            raise GmisInputError(f"no GPS observations (file system {system!r})", str(path))
        if system == "M":
            notes.append(f"{path.name}: mixed-system RINEX 2 file; only GPS satellites are "
                         "processed, others skipped")
        priority = OBS_PRIORITY_RINEX2
    else:
        types = []
        systems = _systems_v3(header)
        if "G" not in systems:
            raise GmisInputError(f"no GPS observations (systems in header: {systems})",
                                 str(path))
        others = [s for s in systems if s != "G"]
        if others:
            notes.append(f"{path.name}: systems {''.join(others)} skipped (only GPS is "
                         "processed)")
        priority = OBS_PRIORITY_RINEX3
    _check_obs_complete(body, version, len(types), text, path)

    ds = _georinex_load(path, use={"G"}, useindicators=True)
    if ds.sizes.get("time", 0) == 0:
        raise GmisInputError("no epochs in the file", str(path))
    sats = np.array([s for s in ds.sv.values.tolist() if str(s).startswith("G")])
    if sats.size == 0:
        raise GmisInputError("no GPS observations in the file", str(path))
    ds = ds.sel(sv=sats)
    n_ep, n_sat = ds.sizes["time"], sats.size
    out: dict = {}
    signals: dict = {}
    for name in OBS_NAMES:
        arr = np.full((n_ep, n_sat), np.nan)
        chosen = np.array([""] * n_sat, dtype="<U3")
        lli = np.zeros((n_ep, n_sat), dtype=np.int8)
        for code in priority[name]:
            if code not in ds:
                continue
            vals = ds[code].values.astype(float)
            take = np.isfinite(vals).any(axis=0) & (chosen == "")
            arr[:, take] = vals[:, take]
            chosen[take] = code
            if name in ("L1", "L2") and code + "lli" in ds:
                lv = ds[code + "lli"].values
                lli[:, take] = np.where(np.isfinite(lv[:, take]), lv[:, take], 0).astype(np.int8)
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
    t = gps_seconds_from_datetime64(ds.time.values)
    exact = _epoch_tags_from_text(body, version)
    if exact.size:
        k = np.clip(np.searchsorted(exact, t), 1, exact.size - 1) if exact.size > 1 \
            else np.zeros(t.size, dtype=np.int64)
        near = np.where(np.abs(exact[k - 1] - t) < np.abs(exact[k] - t), k - 1, k) \
            if exact.size > 1 else k
        close = np.abs(exact[near] - t) < 2e-3
        t = np.where(close, exact[near], t)
    interval = ds.attrs.get("interval", np.nan)
    arrays = {k: v[has_any] for k, v in out.items()}
    arrays.update(
        t_gps=t[has_any], sats=sats, prn=np.array([int(s[1:]) for s in sats]),
        approx=_approx_position(header) if _approx_position(header) is not None
        else np.full(3, np.nan),
        meta=np.array(json.dumps({
            "version": version, "marker": _header_value(header, "MARKER NAME").strip(),
            "interval": float(interval) if interval is not None else float("nan"),
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
    path = _check_path(path)
    if "G" not in tuple(use):
        raise GmisInputError(f"use={tuple(use)} has no 'G': only GPS is supported", str(path))
    extra = [s for s in use if s != "G"]
    digest = _file_digest(path)
    cfile = _cache_file(path, digest, "obs", cache_dir)
    arrays = _cache_load(cfile) if use_cache and cfile.is_file() else None
    if arrays is None:
        arrays = _parse_obs(path)
        if use_cache:
            _cache_save(cfile, arrays)
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

def _parse_nav(path: Path) -> dict:
    text = _read_text(path)
    header, body = _split_header(text, path)
    version, ftype, system = _header_version(header, path)
    if ftype not in ("N", "G") and not (version >= 3.0 and ftype == "N"):
        raise GmisInputError(f"not a GPS navigation file (type {ftype!r})", str(path))
    if ftype == "G" or (version >= 3.0 and system not in ("G", "M", " ")):
        raise GmisInputError(f"not a GPS navigation file (system {system or ftype!r})",
                             str(path))
    _check_nav_complete(body, version, text, path)
    ds = _georinex_load(path, use={"G"})
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
    path = _check_path(path)
    digest = _file_digest(path)
    cfile = _cache_file(path, digest, "nav", cache_dir)
    a = _cache_load(cfile) if use_cache and cfile.is_file() else None
    if a is None:
        a = _parse_nav(path)
        if use_cache:
            _cache_save(cfile, a)
    meta = json.loads(str(a["meta"]))
    ion = a["ion"]
    has_ion = bool(np.all(np.isfinite(ion)))
    return NavData(path=str(path), version=meta["version"],
                   **{k: a[k] for k in NAV_FIELDS},
                   ion_alpha=ion[:4].copy() if has_ion else None,
                   ion_beta=ion[4:].copy() if has_ion else None)
