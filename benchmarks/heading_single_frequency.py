"""Single-frequency (L1-only) dual-antenna heading on the heading test scene
(tests/test_heading.py: 9 satellites, 2 m along-track baseline, 1 Hz, 3 mm / 0.3 m
undifferenced σ with elevation weighting, 3 m primary-position error, a steady 3°/s turn).

For each seed: fix rate, first fixed epoch, wrong integer fixes (every fixed epoch's DD
integers against the simulated truth; before and after the baseline-length check), length
rejections, partial-AR fixes, heading RMS against the truth and the mean reported σ, CPU
time (time.process_time). The dual-frequency run of the same scene (with L2) is the
reference. Options: default RtkConfig(frequencies=("L1",)) — lock 5 epochs, ratio 3,
χ² test, fix-and-hold, partial AR by elevation.

Run:  python benchmarks/heading_single_frequency.py [--epochs 1000] [--seeds 3 4 5]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gnss.heading import body_baseline_azimuth, heading_from_dd_epochs
from gnss.rtk import Q_FIXED, RtkConfig, process_dd_epochs
from tests.test_heading import PRIMARY_L, SECONDARY_L, simulate_moving_baseline


def wrong(integers, truth, rows=None) -> int:
    idx = range(len(integers)) if rows is None else rows
    return sum(1 for i in idx if integers[i] is not None
               and any(n != truth[i][k] for k, n in integers[i].items()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--epochs", type=int, default=1000)
    ap.add_argument("--seeds", type=int, nargs="+", default=[3, 4, 5])
    args = ap.parse_args()
    alpha = body_baseline_azimuth(PRIMARY_L, SECONDARY_L)
    totals = {"epochs": 0, "fixed": 0, "wrong": 0}
    for seed in args.seeds:
        for l1_only in (True, False):
            epochs, lin, th, _, truth = simulate_moving_baseline(
                seed=seed, n_epochs=args.epochs, l1_only=l1_only, with_integers=True)
            cfg = RtkConfig(frequencies=("L1",) if l1_only else ("L1", "L2"))
            t0 = time.process_time()
            sol = heading_from_dd_epochs(epochs, lin.copy(), lin, 2.0, alpha, cfg)
            cpu = time.process_time() - t0
            raw = process_dd_epochs(epochs, lin.copy(), cfg)
            fixed = sol.q == Q_FIXED
            d = (sol.heading[fixed] - th[fixed] + np.pi) % (2 * np.pi) - np.pi
            n_wrong = wrong(raw.integers, truth)
            n_wrong_out = wrong(raw.integers, truth, np.flatnonzero(fixed))
            name = "L1   " if l1_only else "L1+L2"
            print(f"seed {seed} {name}: {args.epochs} epochs, fix rate {fixed.mean():.4f} "
                  f"(first fix at epoch {int(np.argmax(fixed))}), wrong integer fixes "
                  f"{n_wrong} (after the length check {n_wrong_out}), length-rejected "
                  f"{int(sol.length_rejected.sum())}, partial-AR epochs {int(raw.partial.sum())}, "
                  f"heading RMS {np.degrees(np.sqrt(np.mean(d ** 2))):.4f} deg, max "
                  f"{np.degrees(np.abs(d).max()):.3f} deg, mean sigma "
                  f"{np.degrees(sol.sigma_heading[fixed].mean()):.4f} deg, CPU {cpu:.2f} s")
            if l1_only:
                totals["epochs"] += args.epochs
                totals["fixed"] += int(fixed.sum())
                totals["wrong"] += n_wrong
    print(f"L1 total: {totals['fixed']} fixed of {totals['epochs']} epochs, "
          f"{totals['wrong']} wrong integer fixes")


if __name__ == "__main__":
    main()
