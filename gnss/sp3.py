"""Minimal SP3-c/d precise-orbit reader: GPS satellite positions and clocks.

SP3 positions are of the satellite centre of mass in the ITRF realisation of the file
(km in the file, m here); clocks µs in the file, s here; 999999.999999 clocks and 0.0
positions mean "no value" and become NaN. Times are converted to absolute GPS seconds
(see gnss.rinex); only files in GPS time ('%c ... GPS') are accepted.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gnss.errors import GnssInputError as GmisInputError
from gnss.rinex import gps_seconds_from_datetime64


@dataclass
class Sp3Data:
    """t_gps (n_ep,), prn (n_sat,), position (n_ep, n_sat, 3) m, clock (n_ep, n_sat) s."""

    path: str
    t_gps: np.ndarray
    prn: np.ndarray
    position: np.ndarray
    clock: np.ndarray


def read_sp3(path) -> Sp3Data:
    """Read GPS ('G' or blank system) position/clock records of an SP3-c/d file."""
    p = Path(path)
    if not p.is_file():
        raise GmisInputError("file not found", str(p))
    lines = p.read_text(errors="replace").splitlines()
    if not lines or not lines[0].startswith("#") or lines[0][1:2] not in ("a", "b", "c", "d"):
        raise GmisInputError("not an SP3 file (first line must start with '#a'..'#d')", str(p))
    for ln in lines:
        if ln.startswith("%c"):
            ts = ln[9:12].strip()
            if ts and ts not in ("GPS", "ccc"):
                raise GmisInputError(f"time system {ts!r} not supported (GPS only)", str(p))
            break
    epochs: list[np.datetime64] = []
    records: list[tuple[int, int, float, float, float, float]] = []
    for ln in lines:
        if ln.startswith("* "):
            f = ln[2:].split()
            try:
                sec = float(f[5])
                iso = f"{int(f[0]):04d}-{int(f[1]):02d}-{int(f[2]):02d}T{int(f[3]):02d}:" \
                      f"{int(f[4]):02d}:00"
            except (ValueError, IndexError):
                raise GmisInputError(f"malformed epoch line {ln!r}", str(p)) from None
            epochs.append(np.datetime64(iso, "ns") + np.timedelta64(round(sec * 1e9), "ns"))
        elif ln.startswith("P") and epochs and ln[1:2] in ("G", " "):
            try:
                prn = int(ln[2:4])
                x, y, z = float(ln[4:18]), float(ln[18:32]), float(ln[32:46])
                clk = float(ln[46:60]) if ln[46:60].strip() else 999999.999999
            except ValueError:
                raise GmisInputError(f"malformed position line {ln!r}", str(p)) from None
            records.append((len(epochs) - 1, prn, x, y, z, clk))
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
