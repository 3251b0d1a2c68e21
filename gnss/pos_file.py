"""RTKLIB-like .pos solution files: write a solution, read RTKLIB's or ours.

One line per solved epoch: GPST (yyyy/mm/dd hh:mm:ss.sss), latitude and longitude (deg),
ellipsoidal height (m), Q (1 fixed, 2 float), ns (satellites), sdn/sde/sdu (1σ, m),
ratio; header lines start with '%'.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from gnss.constants import GPS_EPOCH_ISO, SECONDS_PER_WEEK

_GPS_EPOCH = np.datetime64(GPS_EPOCH_ISO, "ms")


def write_pos(path, sol, header_lines=()) -> Path:
    """Write the epochs with q > 0 of a solution with t_gps (n,) s, llh (n, 3) rad/rad/m,
    q, n_sat, sigma_enu (n, 3) m and ratio (n,) (e.g. gnss.rtk.RtkSolution). A non-finite
    ratio (no ratio test at that epoch, e.g. a held fix) is written as 0.0, as RTKLIB
    does, so read_pos reads the file back."""
    return write_pos_blocks(path, [sol], header_lines)


def write_pos_blocks(path, sols, header_lines=()) -> Path:
    """write_pos of the rows of several solutions (an iterable, e.g. blocks read back
    from disk one at a time), one after the other: the file write_pos writes for their
    concatenation."""
    path = Path(path)
    lines = [f"% {h}" for h in header_lines]
    lines.append("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns"
                 "   sdn(m)   sde(m)   sdu(m)  ratio")
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")
        for sol in sols:
            q = np.asarray(sol.q)
            keep = np.flatnonzero(q != 0)
            fh.writelines(_pos_rows(sol, q, keep[k:k + POS_BLOCK_ROWS])
                          for k in range(0, keep.size, POS_BLOCK_ROWS))
    return path


POS_BLOCK_ROWS = 20_000   # rows formatted at once by write_pos (memory: one block)


def _pos_rows(sol, q, rows) -> str:
    """The lines of solution rows ``rows`` (each ending in a newline), formatted by one
    %-format of the block instead of a Python loop with a datetime64 per row: the same
    characters — round() and np.rint both round half to even,
    datetime_as_string(unit="ms") is str() of a datetime64[ms], x * (180 / π) is
    math.degrees."""
    ms = np.rint(np.asarray(sol.t_gps, dtype=float)[rows] * 1000.0).astype(np.int64)
    stamps = np.datetime_as_string(_GPS_EPOCH + ms.astype("timedelta64[ms]"), unit="ms")
    llh = np.asarray(sol.llh, dtype=float)[rows]
    sd = np.asarray(sol.sigma_enu, dtype=float)[rows]
    ratio = np.asarray(sol.ratio, dtype=float)[rows]
    ratio = np.where(np.isfinite(ratio), ratio, 0.0)
    columns = [[str(s).replace("-", "/").replace("T", " ") for s in stamps],
               (llh[:, 0] * (180.0 / math.pi)).tolist(),
               (llh[:, 1] * (180.0 / math.pi)).tolist(), llh[:, 2].tolist(),
               q[rows].tolist(), np.asarray(sol.n_sat)[rows].tolist(),
               sd[:, 1].tolist(), sd[:, 0].tolist(), sd[:, 2].tolist(), ratio.tolist()]
    row = "%-23s %14.9f %14.9f %10.4f %3d %3d %8.4f %8.4f %8.4f %6.1f\n"
    return (row * rows.size) % tuple(v for values in zip(*columns) for v in values)


_LLH_COLUMNS = ("latitude(deg)", "longitude(deg)", "height(m)")
_ECEF_COLUMNS = ("x-ecef(m)", "y-ecef(m)", "z-ecef(m)")
# RTKLIB's column order when a file has no header line (lat/lon/h, sigmas, age, ratio); our
# own write_pos writes 11 fields: ... sdu ratio
_DEFAULT_COLUMNS = ("latitude(deg)", "longitude(deg)", "height(m)", "Q", "ns", "sdn(m)",
                    "sde(m)", "sdu(m)", "sdne(m)", "sdeu(m)", "sdun(m)", "age(s)", "ratio")
_WRITE_POS_COLUMNS = ("latitude(deg)", "longitude(deg)", "height(m)", "Q", "ns", "sdn(m)",
                      "sde(m)", "sdu(m)", "ratio")


def _header_columns(line: str):
    """Column names after the time of an RTKLIB header line ('%  GPST  latitude(deg) ...'),
    or None when the line is not one. Only GPST time is accepted."""
    tokens = line.lstrip("%").split()
    if len(tokens) < 4 or tokens[0] not in ("GPST", "UTC", "JST"):
        return None
    return tokens[0], tuple(tokens[1:])


def _epoch_seconds(f0: str, f1: str) -> float:
    """GPS seconds since 1980-01-06 of 'yyyy/mm/dd hh:mm:ss.sss' or 'week tow'."""
    if "/" in f0:
        stamp = np.datetime64(f0.replace("/", "-") + "T" + f1, "ms")
        return float((stamp - _GPS_EPOCH) / np.timedelta64(1, "ms")) / 1000.0
    week, tow = int(f0), float(f1)
    if week < 0 or not 0.0 <= tow < SECONDS_PER_WEEK:
        raise ValueError(f"GPS week {f0} / time of week {f1} out of range")
    return week * SECONDS_PER_WEEK + tow


def read_pos(path) -> dict:
    """Read an RTKLIB .pos solution (rnx2rtkp, rtkpost, str2str/u-blox converters) or one
    written by write_pos. Time: GPST, calendar (yyyy/mm/dd hh:mm:ss.sss) or GPS week and
    time of week; position: latitude/longitude (deg) and ellipsoidal height (m), or ECEF
    x/y/z (m). Columns are taken from the last '%  GPST ...' header line (RTKLIB's default
    order when there is none).

    Returns t_gps (n,) s since 1980-01-06, llh (n, 3) rad/rad/m, q (n,) int, ns (n,) int,
    ratio (n,) (NaN when absent) and ``columns``: every other column by its RTKLIB name
    (e.g. 'sdn(m)', 'sdne(m)', 'vn(m/s)', 'sdvn'), each (n,) float.
    Raises GnssInputError naming the file and line for anything it cannot read."""
    from gnss.errors import GnssInputError
    from gnss.geodesy import ecef_to_geodetic_rows

    src = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise GnssInputError(f"not a text file ({exc.reason} at byte {exc.start})",
                             src) from None
    names = None
    rows = []
    for line_no, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        if line.startswith("%"):
            header = _header_columns(line)
            if header is not None:
                if header[0] != "GPST":
                    raise GnssInputError(f"line {line_no}: time system {header[0]}: only "
                                         "GPST solutions are read", src)
                names = header[1]
            continue
        f = line.split()
        if names is None:
            names = _WRITE_POS_COLUMNS if len(f) == 11 else _DEFAULT_COLUMNS
        if len(f) != len(names) + 2:
            raise GnssInputError(f"line {line_no}: {len(f)} fields, expected "
                                 f"{len(names) + 2} (time and {', '.join(names)})", src)
        try:
            t = _epoch_seconds(f[0], f[1])
            values = [float(v) for v in f[2:]]
        except ValueError as exc:
            raise GnssInputError(f"line {line_no}: not a solution record ({exc})", src) from None
        if not all(math.isfinite(v) for v in values) or not math.isfinite(t):
            raise GnssInputError(f"line {line_no}: non-finite value", src)
        if rows and t <= rows[-1][0]:
            raise GnssInputError(f"line {line_no}: time does not increase", src)
        rows.append((t, values))
    if not rows:
        raise GnssInputError("no solution records in the file", src)
    table = np.array([v for _, v in rows]).reshape(len(rows), len(names))
    col = {name: table[:, i] for i, name in enumerate(names)}
    if all(c in col for c in _LLH_COLUMNS):
        lat, lon, h = (col.pop(c) for c in _LLH_COLUMNS)
        if np.any(np.abs(lat) > 90.0) or np.any(np.abs(lon) > 360.0):
            raise GnssInputError("latitude/longitude out of range", src)
        llh = np.column_stack([np.radians(lat), np.radians(lon), h])
    elif all(c in col for c in _ECEF_COLUMNS):
        llh = ecef_to_geodetic_rows(np.column_stack([col.pop(c) for c in _ECEF_COLUMNS]))
    else:
        raise GnssInputError("header names neither latitude(deg)/longitude(deg)/height(m) "
                             "nor x-ecef(m)/y-ecef(m)/z-ecef(m) columns", src)
    for req in ("Q", "ns"):
        if req not in col:
            raise GnssInputError(f"no '{req}' column in the header", src)
    q, ns = col.pop("Q"), col.pop("ns")
    if np.any(q != np.round(q)) or np.any(ns != np.round(ns)) or np.any(q < 0):
        raise GnssInputError("Q and ns must be whole numbers", src)
    ratio = col.pop("ratio", np.full(len(rows), np.nan))
    return {"t_gps": np.array([t for t, _ in rows]), "llh": llh,
            "q": q.astype(np.int64), "ns": ns.astype(np.int64), "ratio": ratio,
            "columns": col}
