"""gnss.pos_file.write_pos formats the whole table at once: the same bytes as the
per-row f-string formatting it replaced (kept here as the reference)."""

import math
from types import SimpleNamespace

import numpy as np

from gnss.pos_file import _GPS_EPOCH, write_pos


def per_row_reference(sol) -> list[str]:
    lines = []
    for i in range(sol.t_gps.size):
        if sol.q[i] == 0:
            continue
        t = _GPS_EPOCH + np.timedelta64(round(float(sol.t_gps[i]) * 1000.0), "ms")
        s = str(t).replace("-", "/").replace("T", " ")
        lat, lon, h = sol.llh[i]
        sn, se, su = sol.sigma_enu[i][[1, 0, 2]]
        ratio = float(sol.ratio[i]) if math.isfinite(float(sol.ratio[i])) else 0.0
        lines.append(f"{s:23s} {math.degrees(lat):14.9f} {math.degrees(lon):14.9f} "
                     f"{h:10.4f} {sol.q[i]:3d} {sol.n_sat[i]:3d} {sn:8.4f} {se:8.4f} "
                     f"{su:8.4f} {ratio:6.1f}")
    return lines


def test_write_pos_equals_per_row_formatting(tmp_path):
    rng = np.random.default_rng(5)
    for n in (0, 1, 7, 1500):
        # half-millisecond times: round() and np.rint must agree on ties (half to even)
        t = 2100 * 604800 + np.cumsum(rng.uniform(0, 1, n)) + rng.choice([0, 5e-4, 1.5e-3], n)
        sol = SimpleNamespace(
            t_gps=t, llh=np.column_stack([rng.uniform(-1.5, 1.5, n), rng.uniform(-3.1, 3.1, n),
                                          rng.uniform(-100, 9000, n)]),
            q=rng.integers(0, 3, n), n_sat=rng.integers(0, 30, n),
            sigma_enu=rng.uniform(0, 50, (n, 3)),
            ratio=np.where(rng.uniform(size=n) < 0.2, np.nan, rng.uniform(0, 999, n)))
        text = write_pos(tmp_path / "s.pos", sol, ["title"]).read_text()
        lines = text.splitlines()
        assert lines[0] == "% title" and lines[1].startswith("%  GPST")
        assert lines[2:] == per_row_reference(sol)
        assert text.endswith("\n")
