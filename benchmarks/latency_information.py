"""Issue 20, latency item: where the GNSS time-offset information of the simulated
consumer drive (benchmarks/consumer_receiver_drive.py, same scenario and receiver) comes
from, and what would lower its σ.

Per seed: the data of consumer_receiver_drive.simulate, the run prepared as there (Gauss-
Markov fix-error states on, [nonholonomic] on unless --no-nhc), then the profile-
likelihood estimate of gmis.latency_estimation (search ±0.3 s around 0, as `gmis run`)
for the data and model as they are, and for variants that remove one kind of row or
change one noise figure of the model. σ_o = 1/√α is the curvature of −2 log L, i.e. the
information the rows carry about the offset under the model; the error is ô + 0.1 s.

    PYTHONPATH=. python3 benchmarks/latency_information.py [n_seeds] [first_seed] [--no-nhc]

Variants (the data are the same in every one; rows are removed by giving them no
weight: speed σ 10³ m/s, course σ NaN = absent, position σ ×30 with σ_b ×30):
  as run            the data and the recipe as in consumer_receiver_drive.py
  no speed rows     speed removed (course and positions kept)
  no course rows    course removed
  positions only    speed and course removed
  no position info  positions and their Gauss-Markov σ ×30 (velocity rows carry it all)
  IMU σ / 3         the filter's gyro and accelerometer white-noise σ divided by 3 (what a
                    3× quieter IMU would give; NOT the simulated IMU, whose σ the recipe
                    has: this variant's σ_o is optimistic for these data)
  gyro σ / 3, accel σ / 3   the same for one triad only (which one limits σ_o)
  IMU σ / 100       the same, ~a noiseless IMU: the bound set by the receiver's own speed,
                    course and fix noise
Prints σ_o and the error per seed and variant and, per variant, the RMS of σ_o and of
the error over the seeds.
"""

from __future__ import annotations

import argparse
import copy
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from consumer_receiver_drive import GM_KEYS, MODEL, simulate

NO_WEIGHT_SPEED_M_S = 1.0e3
POSITION_FACTOR = 30.0


def _no_speed(p):
    p.meas.speed_course_sd[:, 0] = NO_WEIGHT_SPEED_M_S


def _no_course(p):
    p.meas.speed_course_sd[:, 1] = np.nan


def _positions_only(p):
    _no_speed(p)
    _no_course(p)


def _no_positions(p):
    p.meas.pos_sd = p.meas.pos_sd * POSITION_FACTOR
    p.config = replace(p.config, gnss_error_sigma_m=p.config.gnss_error_sigma_m
                       * POSITION_FACTOR)


def _imu_over(factor, axes=slice(0, 6)):
    def change(p):
        sd = p.config.imu_sd.copy()
        sd[axes] /= factor
        p.config = replace(p.config, imu_sd=sd)
    return change


VARIANTS = {"as run": None, "no speed rows": _no_speed, "no course rows": _no_course,
            "positions only": _positions_only, "no position info": _no_positions,
            "IMU σ / 3": _imu_over(3.0), "gyro σ / 3": _imu_over(3.0, slice(0, 3)),
            "accel σ / 3": _imu_over(3.0, slice(3, 6)), "IMU σ / 100": _imu_over(100.0)}


def prepared(seed: int, folder: Path, nhc: bool):
    """The PreparedRun of consumer_receiver_drive's data for seed, at offset 0."""
    from gmis.recipe import GnssSection, NonholonomicSection, load_recipe
    from gmis.run_preparation import prepare_run

    recipe_path, _sim, _truth = simulate(seed, folder)
    recipe = load_recipe(recipe_path)
    if nhc:
        recipe = replace(recipe, nonholonomic=NonholonomicSection())
    gnss = replace(GnssSection(), **{k: (tuple(v) if isinstance(v, list) else v)
                                     for k, v in GM_KEYS.items()})
    return prepare_run(replace(recipe, gnss=gnss))


def main(argv=None):
    from gmis.latency_estimation import estimate_time_offset

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("n_seeds", nargs="?", type=int, default=4)
    ap.add_argument("first_seed", nargs="?", type=int, default=1)
    ap.add_argument("--no-nhc", action="store_true")
    args = ap.parse_args(argv)
    sigma = {k: [] for k in VARIANTS}
    error = {k: [] for k in VARIANTS}
    print("| seed | " + " | ".join(f"{k}: σ_o / error ms" for k in VARIANTS) + " |")
    print("|---" * (len(VARIANTS) + 1) + "|")
    for seed in range(args.first_seed, args.first_seed + args.n_seeds):
        with tempfile.TemporaryDirectory() as tmp:
            prep = prepared(seed, Path(tmp), not args.no_nhc)
        cells = []
        for name, change in VARIANTS.items():
            p = prep
            if change is not None:
                p = copy.deepcopy(prep)
                change(p)
            est = estimate_time_offset(p, 0.3)
            sigma[name].append(est.sigma_s * 1e3)
            error[name].append((est.offset_s + MODEL.latency_s) * 1e3)
            cells.append(f"{sigma[name][-1]:.2f} / {error[name][-1]:+.2f}")
        print(f"| {seed} | " + " | ".join(cells) + " |", flush=True)
    print("| RMS | " + " | ".join(
        f"{np.sqrt(np.mean(np.square(sigma[k]))):.2f} / {np.sqrt(np.mean(np.square(error[k]))):.2f}"
        for k in VARIANTS) + " |")


if __name__ == "__main__":
    main()
