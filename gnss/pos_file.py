"""RTKLIB-like .pos solution files: write a solution, read RTKLIB's or ours.

One line per solved epoch: GPST (yyyy/mm/dd hh:mm:ss.sss), latitude and longitude (deg),
ellipsoidal height (m), Q (1 fixed, 2 float), ns (satellites), sdn/sde/sdu (1σ, m),
ratio; header lines start with '%'.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from gnss.constants import GPS_EPOCH_ISO

_GPS_EPOCH = np.datetime64(GPS_EPOCH_ISO, "ms")


def write_pos(path, sol, header_lines=()) -> Path:
    """Write the epochs with q > 0 of a solution with t_gps (n,) s, llh (n, 3) rad/rad/m,
    q, n_sat, sigma_enu (n, 3) m and ratio (n,) (e.g. gnss.rtk.RtkSolution)."""
    path = Path(path)
    lines = [f"% {h}" for h in header_lines]
    lines.append("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns"
                 "   sdn(m)   sde(m)   sdu(m)  ratio")
    for i in range(sol.t_gps.size):
        if sol.q[i] == 0:
            continue
        t = _GPS_EPOCH + np.timedelta64(round(float(sol.t_gps[i]) * 1000.0), "ms")
        s = str(t).replace("-", "/").replace("T", " ")
        lat, lon, h = sol.llh[i]
        sn, se, su = sol.sigma_enu[i][[1, 0, 2]]
        lines.append(f"{s:23s} {math.degrees(lat):14.9f} {math.degrees(lon):14.9f} "
                     f"{h:10.4f} {sol.q[i]:3d} {sol.n_sat[i]:3d} {sn:8.4f} {se:8.4f} "
                     f"{su:8.4f} {sol.ratio[i]:6.1f}")
    path.write_text("\n".join(lines) + "\n")
    return path


def read_pos(path) -> dict:
    """Read an RTKLIB .pos (GPST date time, lat/lon/h in degrees) or one written by
    write_pos: t_gps (s), llh (n,3) rad/rad/m, q, ns, ratio (NaN when absent)."""
    t, llh, q, ns, ratio = [], [], [], [], []
    for line in Path(path).read_text().splitlines():
        if not line.strip() or line.startswith("%"):
            continue
        f = line.split()
        stamp = np.datetime64(f[0].replace("/", "-") + "T" + f[1], "ms")
        t.append((stamp - _GPS_EPOCH) / np.timedelta64(1, "s"))
        llh.append((math.radians(float(f[2])), math.radians(float(f[3])), float(f[4])))
        q.append(int(f[5]))
        ns.append(int(f[6]))
        ratio.append(float(f[-1]) if len(f) in (11, 15) else np.nan)
    return {"t_gps": np.array(t), "llh": np.array(llh).reshape(-1, 3),
            "q": np.array(q, np.int64), "ns": np.array(ns, np.int64), "ratio": np.array(ratio)}
