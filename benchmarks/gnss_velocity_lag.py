"""Does a GNSS solution's velocity lag its own position? From the solution file alone:
the horizontal velocity v(t) against the position's central difference
ṙ(t_k) = (r_{k+1} − r_{k−1}) / (t_{k+1} − t_{k−1}) shifted by δ, over the epochs moving
faster than 1 m/s; RMS and lag-1 autocorrelation of v(t) − ṙ(t − δ) per δ, and the δ of
least RMS (a parabola through the three grid points around the minimum). With an RTK
track (cm positions) ṙ is good to a few cm/s at 4 Hz, so a velocity stamped late by δ
shows as a mismatch ≈ a·δ correlated like the acceleration. Such a lag makes the
velocity innovations time-correlated (docs/DESIGN.md "VCE as implemented"); the recipe
key [gnss].velocity_time_offset_s = −δ moves the velocity to its own epochs.

    python3 benchmarks/gnss_velocity_lag.py [RECIPE]   (default: the Boulder drive)
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

RECIPE = ROOT / "datasets" / "drive-boulder-0708" / "recipe.toml"


def lag1(x):
    x = x - x.mean()
    return float((x[:-1] * x[1:]).sum() / (x * x).sum())


def mismatch(t, pos, vel, delay_s, moving):
    """v(t) − ṙ(t − δ) (E, N) at the moving interior epochs."""
    rdot = (pos[2:] - pos[:-2]) / (t[2:] - t[:-2])[:, None]
    tc = t[1:-1]
    shifted = np.column_stack([np.interp(tc - delay_s, tc, rdot[:, i]) for i in range(2)])
    keep = moving[1:-1] & (tc - delay_s >= tc[0]) & (tc - delay_s <= tc[-1])
    return (vel[1:-1, :2] - shifted)[keep]


def main(argv=None):
    from gmis.earth import make_nav_frame
    from gmis.enu_rows import geodetic_to_enu_rows
    from gmis.readers import load_dataset
    from gmis.recipe import load_recipe

    argv = sys.argv[1:] if argv is None else argv
    ds = load_dataset(load_recipe(Path(argv[0]) if argv else RECIPE))
    g = ds.gnss
    if g is None or g.vel_enu is None:
        print("the recipe's GNSS solution has no ENU velocity")
        return 2
    frame = make_nav_frame(*g.llh[0])
    pos = geodetic_to_enu_rows(frame, np.ascontiguousarray(g.llh))
    moving = np.hypot(g.vel_enu[:, 0], g.vel_enu[:, 1]) > 1.0
    grid = np.round(np.arange(-0.5, 0.5001, 0.01), 10)
    rms = np.array([np.sqrt(np.mean(mismatch(g.t, pos, g.vel_enu, d, moving) ** 2))
                    for d in grid])
    i = int(np.clip(np.argmin(rms), 1, grid.size - 2))
    c = np.polyfit(grid[i - 1:i + 2], rms[i - 1:i + 2], 2)
    best = float(-c[1] / (2 * c[0])) if c[0] > 0 else float(grid[i])
    print("| δ (s) | RMS E, N (m/s) | lag-1 autocorrelation E, N |")
    print("|---|---|---|")
    for d in sorted({0.0, round(best, 3), -0.15, 0.15}):
        e = mismatch(g.t, pos, g.vel_enu, d, moving)
        print(f"| {d:+.3f} | {np.sqrt(np.mean(e[:, 0] ** 2)):.3f}, "
              f"{np.sqrt(np.mean(e[:, 1] ** 2)):.3f} | {lag1(e[:, 0]):.2f}, {lag1(e[:, 1]):.2f} |")
    print(f"velocity lags the position by δ = {best:+.3f} s "
          f"(→ [gnss].velocity_time_offset_s = {-best:+.3f}); {int(moving.sum())} moving epochs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
