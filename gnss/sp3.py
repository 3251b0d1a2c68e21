"""Minimal SP3-a/c/d precise-orbit reader: GPS satellite positions and clocks.

SP3 positions are of the satellite centre of mass in the ITRF realisation of the file
(km in the file, m here); clocks µs in the file, s here; 999999.999999 clocks and 0.0
positions mean "no value" and become NaN. Times are converted to absolute GPS seconds
(see gnss.rinex); only files in GPS time ('%c ... GPS') are accepted. Compressed files
(gzip, bzip2, zip, .Z, xz) are read through ``gnss.rinex.read_text``.

Layout checks (every violation is one GmisInputError naming the file and line): the epoch
line ``*  yyyy mm dd hh mm ss.ssssssss`` and the P record's x, y, z (and clock, when
present) F14.6 fields at their columns — a field cut short by a truncation is an error,
never a number. A file without the closing ``EOF`` line may have been cut: it is accepted
only when its last epoch is complete (as many P records as the satellites in the header,
or as the fullest earlier epoch when the header lists more satellites than any epoch has).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from gnss.errors import GnssInputError as GmisInputError
from gnss.rinex import checked_input_path, gps_seconds_from_datetime64, read_text

_EPOCH = re.compile(r"^\*  ?\d{4} [ \d]\d [ \d]\d [ \d]\d [ \d]\d [ \d]\d\.\d{8}")
_F14_6 = re.compile(r"^ *-?\d+\.\d{6}$")


@dataclass
class Sp3Data:
    """t_gps (n_ep,), prn (n_sat,), position (n_ep, n_sat, 3) m, clock (n_ep, n_sat) s."""

    path: str
    t_gps: np.ndarray
    prn: np.ndarray
    position: np.ndarray
    clock: np.ndarray


def _header_sat_count(lines: list[str]) -> int:
    for ln in lines:
        if ln.startswith("+ "):
            try:
                return int(ln[3:6])
            except ValueError:
                return 0
        if ln.startswith("*"):
            break
    return 0


def _epoch_time(ln: str) -> np.datetime64:
    f = ln[2:].split()
    sec = f[5]
    whole, _, frac = sec.partition(".")
    day = np.datetime64(f"{int(f[0]):04d}-{int(f[1]):02d}-{int(f[2]):02d}", "ns")
    ns = (int(f[3]) * 3600 + int(f[4]) * 60 + int(whole)) * 10**9 + int((frac + "0" * 9)[:9])
    return day + np.timedelta64(ns, "ns")


def read_sp3(path) -> Sp3Data:
    """Read GPS ('G' or blank system) position/clock records of an SP3-a/c/d file."""
    p = checked_input_path(path)
    lines = read_text(p).splitlines()
    first = next((ln for ln in lines if ln.strip()), "")  # blank lines before it are skipped
    if not first.startswith("#") or first[1:2] not in ("a", "b", "c", "d"):
        raise GmisInputError("not an SP3 file (first line must start with '#a'..'#d')", str(p))
    for ln in lines:
        if ln.startswith("%c"):
            ts = ln[9:12].strip()
            if ts and ts not in ("GPS", "ccc"):
                raise GmisInputError(f"time system {ts!r} not supported (GPS only)", str(p))
            break
    epochs: list[np.datetime64] = []
    per_epoch: list[int] = []
    records: list[tuple[int, int, float, float, float, float]] = []
    has_eof = False
    for i, ln in enumerate(lines):
        if ln.startswith("*"):
            if not _EPOCH.match(ln):
                raise GmisInputError(f"line {i + 1}: epoch line cut short or malformed "
                                     f"{ln.rstrip()!r}", str(p))
            epochs.append(_epoch_time(ln))
            per_epoch.append(0)
        elif ln.startswith("P") and epochs:
            x, y, z, c = ln[4:18], ln[18:32], ln[32:46], ln[46:60]
            if not (_F14_6.match(x) and _F14_6.match(y) and _F14_6.match(z)) or \
                    (c.strip() and not (len(c) == 14 and _F14_6.match(c))):
                raise GmisInputError(f"line {i + 1}: position record cut short or off its "
                                     f"columns {ln.rstrip()!r}", str(p))
            per_epoch[-1] += 1
            if ln[1:2] not in ("G", " "):
                continue
            try:
                prn = int(ln[2:4])
            except ValueError:
                raise GmisInputError(f"line {i + 1}: unreadable satellite number "
                                     f"{ln[1:4]!r}", str(p)) from None
            records.append((len(epochs) - 1, prn, float(x), float(y), float(z),
                            float(c) if c.strip() else 999999.999999))
        elif ln.startswith("EOF"):
            has_eof = True
            break
    if not has_eof and epochs:
        n_hdr = _header_sat_count(lines)
        full = n_hdr if len(epochs) == 1 else min(n_hdr, max(per_epoch[:-1]))
        if per_epoch[-1] < full:
            raise GmisInputError(f"no EOF line and the last epoch has {per_epoch[-1]} "
                                 f"position records where {full} are expected: the file "
                                 "looks truncated", str(p))
    if not records:
        raise GmisInputError("no GPS position records", str(p))
    rec = np.array(records)
    prns = np.unique(rec[:, 1].astype(int))
    n_ep = len(epochs)
    pos = np.full((n_ep, prns.size, 3), np.nan)
    clk = np.full((n_ep, prns.size), np.nan)
    ie = rec[:, 0].astype(int)
    js = np.searchsorted(prns, rec[:, 1].astype(int))
    good_pos = np.any(rec[:, 2:5] != 0.0, axis=1)
    pos[ie[good_pos], js[good_pos]] = rec[good_pos, 2:5] * 1e3
    good_clk = np.abs(rec[:, 5]) < 999999.0
    clk[ie[good_clk], js[good_clk]] = rec[good_clk, 5] * 1e-6
    return Sp3Data(path=str(p), t_gps=gps_seconds_from_datetime64(np.array(epochs)),
                   prn=prns, position=pos, clock=clk)
