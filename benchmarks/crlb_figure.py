"""√CRLB of the position at the end of a 180-s simulated trajectory for every IMU grade of
001 Table 4-1, ErrINSEKF vs GMIKF (the shape of 001 Fig. 4-7 and Fig. 4-9).

Setting (gmis.crlb): Tables 4-2..4-4 (P0, process noise, 1-Hz 1-m position and 0.1° heading
aiding), truth = 20 s at rest then accelerations, turns and a banked run at constant height.
Modes: free-inertial (aiding only during the 20-s static start) and loosely coupled (aiding
throughout). A third series, "ErrINSEKF + ZUPT", gives the ErrINSEKF zero-velocity updates
(0.001 m/s) while the truth is static — the information the GMIKF receives from its zero
process noise while static (Table 4-3) — to separate that effect from the motion model.

Run:  python benchmarks/crlb_figure.py OUT.png [--json OUT.json]
Prints the table of final horizontal and up √CRLB (m) and writes the figure (150 dpi).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from gmis.crlb import crlb_table
from gmis.simulate.imu_grades import GRADE_NAMES

SERIES = (("errins", "ErrINSEKF", "tab:red", "o"),
          ("errins_zupt", "ErrINSEKF + ZUPT (static)", "tab:orange", "s"),
          ("gmikf", "GMIKF", "tab:blue", "^"))
MODES = (("free", "free-inertial after 20 s static aiding"),
         ("loose", "loosely coupled (1 Hz position 1 m, heading 0.1°)"))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("output", help="PNG file to write")
    ap.add_argument("--json", help="also write the numbers as JSON")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    table = crlb_table()
    elapsed = time.perf_counter() - t0
    print(f"sqrt(CRLB) of position at t = 180 s (m), computed in {elapsed:.1f} s")
    for mode, label in MODES:
        print(f"\n{label}")
        print(f"{'grade':8s} " + " ".join(f"{name + ' H':>14s} {name + ' U':>12s}"
                                          for name, *_ in SERIES))
        for g in GRADE_NAMES:
            r = table[g][mode]
            print(f"{g:8s} " + " ".join(f"{r[s]['horizontal_m']:14.4g} {r[s]['up_m']:12.4g}"
                                        for s, *_ in SERIES))
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 8), sharex=True)
    x = np.arange(len(GRADE_NAMES))
    for row, (mode, label) in enumerate(MODES):
        for col, comp in enumerate(("horizontal_m", "up_m")):
            ax = axes[row, col]
            for i, (s, name, color, marker) in enumerate(SERIES):
                y = [table[g][mode][s][comp] for g in GRADE_NAMES]
                ax.semilogy(x + (i - 1) * 0.12, y, marker, color=color, label=name, ms=7)
            ax.set_title(f"{'horizontal' if comp == 'horizontal_m' else 'up'} — {label}",
                         fontsize=9)
            ax.set_ylabel("√CRLB position (m)")
            ax.grid(alpha=0.3, which="both")
    for ax in axes[1]:
        ax.set_xticks(x, GRADE_NAMES, rotation=30)
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("√CRLB of position at the end of the 180-s trajectory (001 Fig. 4-7 / 4-9 "
                 "setting, Tables 4-1..4-4)", fontsize=10)
    fig.tight_layout()
    fig.savefig(args.output, dpi=150)
    plt.close(fig)
    print(f"\nfigure written to {args.output}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(table, fh, indent=2)


if __name__ == "__main__":
    main()
