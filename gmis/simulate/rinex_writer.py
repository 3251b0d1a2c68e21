"""RINEX 3.03 writers for simulated GPS data: observation files and GPS navigation files.

Observation records (RINEX 3.03 §5.7): one epoch line ``> yyyy mm dd hh mm ss.sssssss  f nn``
then one line per satellite ``Gnn`` + per observation type F14.3 value, LLI digit (blank
when 0; bit 0 = loss of lock, written on phase observations only) and the signal-strength
digit ssi = clip(⌊S/6⌋, 1, 9) (RINEX 3.03 Table 7). A missing observable is 16 blanks.
Values are rounded to 3 decimals (phase 0.001 cycle ≈ 0.2 mm, code 1 mm, Doppler 1 mHz).

Navigation records (RINEX 3.03 §A8, GPS): ``Gnn yyyy mm dd hh mm ss`` + af0 af1 af2, then
7 broadcast orbit lines of 4 D19.12 fields (written with 'E').

Both read back through gnss.rinex.read_obs / read_nav.
"""

from __future__ import annotations

import os
import shutil
from datetime import UTC, datetime

import numpy as np

from gnss.constants import SECONDS_PER_WEEK
from gnss.rinex import NavData

OBS_TYPES_RINEX3 = {"C1": "C1C", "L1": "L1C", "D1": "D1C", "S1": "S1C",
                    "C2": "C2W", "L2": "L2W", "D2": "D2W", "S2": "S2W"}
_GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")


def _hline(content: str, label: str) -> str:
    return f"{content:<60.60s}{label}"


def _calendar(t_gps: float):
    """Absolute GPS seconds → (year, month, day, hour, minute, seconds float)."""
    whole = np.floor(t_gps)
    frac = t_gps - whole
    dt = (_GPS_EPOCH + np.timedelta64(int(whole), "s")).astype("datetime64[us]").astype(datetime)
    return dt.year, dt.month, dt.day, dt.hour, dt.minute, dt.second + frac


def _ssi(snr: float) -> str:
    return str(int(min(max(np.floor(snr / 6.0), 1), 9)))


def _header_start(file_type: str, program: str, comment: str) -> list:
    """The first header lines of a RINEX 3.03 GPS file: VERSION / TYPE, PGM / RUN BY / DATE
    (now, UTC) and one COMMENT."""
    now = datetime.now(UTC).strftime("%Y%m%d %H%M%S UTC")
    return [
        _hline(f"{3.03:9.2f}{'':11s}{file_type:20s}{'G: GPS':20s}", "RINEX VERSION / TYPE"),
        _hline(f"{program:20.20s}{'gmis':20s}{now:20s}", "PGM / RUN BY / DATE"),
        _hline(comment, "COMMENT"),
    ]


def write_obs_rinex3(path, t_gps, prn, obs: dict, lli1=None, lli2=None,
                     approx_position_ecef=None, marker: str = "SIM",
                     interval: float | None = None, program: str = "gmis.simulate") -> None:
    """Write a GPS-only RINEX 3.03 observation file.

    t_gps (n_ep,) absolute GPS s; prn (n_sat,); obs name → (n_ep, n_sat) for the names of
    OBS_TYPES_RINEX3 (C m, L cycles, D Hz, S dB-Hz; NaN = not observed); lli1/lli2
    (n_ep, n_sat) int loss-of-lock indicators of L1/L2. Epochs without any observation are
    skipped."""
    t = np.asarray(t_gps, float)
    prn = np.asarray(prn, dtype=np.int64)
    names = [n for n in OBS_TYPES_RINEX3 if n in obs]
    n_ep, n_sat = t.size, prn.size
    lli = {"L1": np.zeros((n_ep, n_sat), int) if lli1 is None else np.asarray(lli1, int),
           "L2": np.zeros((n_ep, n_sat), int) if lli2 is None else np.asarray(lli2, int)}
    snr = obs.get("S1")
    if interval is None:
        interval = float(np.median(np.diff(t))) if n_ep > 1 else 0.0
    xyz = np.zeros(3) if approx_position_ecef is None else np.asarray(approx_position_ecef)
    y, mo, d, h, mi, s = _calendar(t[0])
    head = _header_start("OBSERVATION DATA", program,
                         "simulated observations (gmis.simulate.raw_gnss)") + [
        _hline(marker, "MARKER NAME"),
        _hline("NON_GEODETIC", "MARKER TYPE"),
        _hline(f"{'gmis':20s}{'gmis':40s}", "OBSERVER / AGENCY"),
        _hline(f"{'0':20s}{'SIMULATED':20s}{'0':20s}", "REC # / TYPE / VERS"),
        _hline(f"{'0':20s}{'SIMULATED':20s}", "ANT # / TYPE"),
        _hline(f"{xyz[0]:14.4f}{xyz[1]:14.4f}{xyz[2]:14.4f}", "APPROX POSITION XYZ"),
        _hline(f"{0.0:14.4f}{0.0:14.4f}{0.0:14.4f}", "ANTENNA: DELTA H/E/N"),
        _hline(f"G  {len(names):3d}" + "".join(f" {OBS_TYPES_RINEX3[n]}" for n in names),
               "SYS / # / OBS TYPES"),
        _hline(f"{interval:10.3f}", "INTERVAL"),
        _hline(f"{y:6d}{mo:6d}{d:6d}{h:6d}{mi:6d}{s:13.7f}{'':5s}GPS", "TIME OF FIRST OBS"),
        _hline("", "END OF HEADER"),
    ]
    lines = head
    have = np.zeros((n_ep, n_sat), dtype=bool)
    for n in names:
        have |= np.isfinite(obs[n])
    for k in range(n_ep):
        cols = np.flatnonzero(have[k])
        if cols.size == 0:
            continue
        y, mo, d, h, mi, s = _calendar(t[k])
        lines.append(f"> {y:4d} {mo:02d} {d:02d} {h:02d} {mi:02d}{s:11.7f}  0{cols.size:3d}")
        for j in cols:
            ssi = _ssi(snr[k, j]) if snr is not None and np.isfinite(snr[k, j]) else " "
            parts = [f"G{prn[j]:02d}"]
            for n in names:
                v = obs[n][k, j]
                if not np.isfinite(v):
                    parts.append(" " * 16)
                    continue
                flag = lli[n][k, j] if n in lli else 0
                parts.append(f"{v:14.3f}{flag if flag else ' '}{ssi}")
            lines.append("".join(parts).rstrip())
    with open(path, "w", newline="\n") as fh:
        fh.write("\n".join(lines) + "\n")


def _e19(x: float) -> str:
    return f"{x:19.12E}"


def write_nav_rinex3(path, nav: NavData, program: str = "gmis.simulate") -> None:
    """Write the GPS records of nav as a RINEX 3.03 navigation file (D19.12 fields)."""
    lines = _header_start("N: GNSS NAV DATA", program,
                          "synthetic broadcast ephemerides (gmis.simulate.raw_gnss)") + [
        _hline("", "END OF HEADER"),
    ]
    for i in range(nav.n_records):
        y, mo, d, h, mi, s = _calendar(float(nav.toc[i]))
        toe_sow = float(nav.toe[i] - nav.week[i] * SECONDS_PER_WEEK)
        lines.append(f"G{int(nav.prn[i]):02d} {y:04d} {mo:02d} {d:02d} {h:02d} {mi:02d} "
                     f"{round(s):02d}" + _e19(nav.af0[i]) + _e19(nav.af1[i])
                     + _e19(nav.af2[i]))
        orbit = [
            (nav.iode[i], nav.crs[i], nav.delta_n[i], nav.m0[i]),
            (nav.cuc[i], nav.e[i], nav.cus[i], nav.sqrt_a[i]),
            (toe_sow, nav.cic[i], nav.omega0[i], nav.cis[i]),
            (nav.i0[i], nav.crc[i], nav.omega[i], nav.omega_dot[i]),
            (nav.idot[i], 0.0, float(nav.week[i]), 0.0),
            (2.0, nav.health[i], nav.tgd[i], nav.iodc[i]),
            (toe_sow, nav.fit_interval_h[i]),
        ]
        for row in orbit:
            lines.append("    " + "".join(_e19(float(v)) for v in row))
    with open(path, "w", newline="\n") as fh:
        fh.write("\n".join(lines) + "\n")


def copy_nav_file(src, dst) -> None:
    """Copy a real broadcast navigation file into a dataset folder unchanged."""
    shutil.copyfile(os.fspath(src), os.fspath(dst))
