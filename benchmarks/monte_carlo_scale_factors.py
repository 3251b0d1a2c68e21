"""Monte Carlo consistency of the GMIKF's bias and scale-factor states (issue 13 item 2).

For seeds s0 … s0+N−1 the scenario is simulated (every random stream re-seeded), the
recipe the simulator writes is run, and per run

  z_j = (x̂_j − x_j) / σ̂_j   at the last epoch, for the 12 states b_ω, b_a, S_ω, S_a

is recorded (x_j the simulated truth: bias at the last sample, constant scale factor).
Printed: per state mean z ± its Monte-Carlo standard error, RMS z and the fraction of
runs with |z| ≤ 3; the NEES of r^n, v^b, θ averaged over the runs at 1 Hz epochs and the
fraction of those epochs inside the two-sided 95 % band χ²(3N)/N — over all epochs, the
moving and aided ones (MonteCarlo.moving_aided) and the rest; and the aiding observations
rejected (a consistent filter rejects ≈ α of good data). The ensemble NEES tests
(tests/test_pipeline_default_drive.py, tests/test_gmikf_200hz.py) are this script on a
short drive with few seeds (tests/simulated_drives.py, nees_test_drive).

Usage (from the repository root):
    PYTHONPATH=$PWD python3 benchmarks/monte_carlo_scale_factors.py --seeds 20
    ... --scale-ppm 6000 -7000 8000 5000 -6000 7000     (IMU440-class true scale factors)
    ... --imu-rate 200 --gnss-rate 1                     (200 Hz IMU / 1 Hz GNSS variant)
    ... --bias-drawn-from-prior   (turn-on biases drawn per seed from N(0, BS²), BS the
        bias instability, and the recipe's prior σ of b set to that BS: the truth is then
        a draw from the filter's prior, instead of a fixed bias with prior σ 3|b| — the
        static part's NEES test, docs/DESIGN.md "Process noise at rest")
    ... --bias-drawn-from-prior accel   (the accelerometer biases only; the gyro biases as
        the scenario writes them — see scenario_variant on the alignment's gyro bias)
    ... --static-s 60 --bias-drawn-from-prior accel   (the ensemble NEES tests' drive: the
        alignment cut to 60 s, all the motion; the outage, 430-445 s from the start, then
        falls after the end)
    ... --cut-s 450                      (the segments up to the 430 s outage)
    ... --imu-noise-scale 0.5            (the filter's gyro/accel σ halved: the NEES fails)
"""

from __future__ import annotations

import argparse
import copy
import tempfile
import time
from dataclasses import replace
from typing import NamedTuple

import numpy as np
from scipy import stats

from gmis.pipeline import navigation_solution, prepare_run, reference_errors, run_prepared
from gmis.recipe import load_recipe
from gmis.simulate import load_scenario, scenario_path, simulate_scenario
from gmis.simulate.sensors import DEG_H, MG
from gmis.state import STATE_NAMES_27

STATES = slice(15, 27)
NAMES = STATE_NAMES_27[15:27]
AIDING_SLOTS = slice(6, 13)
NEES_BLOCKS = ("position", "velocity_body", "attitude")
MOVING_SPEED_M_S = 0.5    # an epoch is moving when the true horizontal speed is above this
OUTAGE_RECOVERY_S = 5.0   # epochs this long after a GNSS outage's end count as not aided


class MonteCarlo(NamedTuple):
    """Per run j (seeds in order) and 1 Hz epoch k (the first IMU epoch of each second):
    z (runs, states) at the last epoch; nees (runs, 3 blocks, epochs); rejected aiding
    observations (runs,); est [(x̂, truth)] per run; t (epochs,) s since the start;
    moving_aided (epochs,) bool — the true horizontal speed > MOVING_SPEED_M_S and the
    epoch outside every GNSS outage of the scenario, from its start to OUTAGE_RECOVERY_S
    after its end."""
    z: np.ndarray
    nees: np.ndarray
    rejected: np.ndarray
    est: list
    t: np.ndarray
    moving_aided: np.ndarray


def scenario_variant(scenario, imu_rate=None, gnss_rate=None, scale_ppm=None,
                     bias_drawn_from_prior=False, cut_s=None, static_s=None):
    """(scenario copy, bias_prior): a scenario (name or dict) with the IMU rate (Hz), the
    GNSS and heading rate (Hz) and the true scale factors (gyro x,y,z, accel x,y,z ppm)
    replaced where given; cut_s keeps the segments up to the first that brings the drive
    to cut_s s (segments without a duration_s count 10 s), then static_s replaces the
    duration of a first static segment (the alignment). bias_drawn_from_prior: False,
    "gyro", "accel" or True (both): the scenario's turn-on biases of those sensors are
    removed, so the simulator draws them per seed from N(0, BS²) (BS the bias
    instability), and bias_prior = (gyro rad/s, accel m/s²) holds BS as the prior σ
    one_run gives the filter for them (None for a sensor not drawn: the recipe's prior
    σ = 3 |b₀|, gmis/simulate/run.py); bias_prior is None when nothing is drawn.
    Caveat for the gyro: the filter starts b_ω at the alignment window's mean rate
    (gmis/alignment.py) and then processes the same samples again, so with a prior σ of
    BS (10 °/h) against the ARW/√T (35 °/h for T = 60 s at 4.5 °/√h) of that mean, b_ω
    starts 3.5 σ off and the data are counted twice; with 3 |b₀| ≥ 270 °/h the prior is
    diffuse and the window's data decide, as they should."""
    sc = copy.deepcopy(load_scenario(scenario_path(scenario)) if isinstance(scenario, str)
                       else scenario)
    if cut_s is not None:
        kept, total = [], 0.0
        for seg in sc["segment"]:
            kept.append(seg)
            total += float(seg.get("duration_s", 10.0))
            if total >= cut_s:
                break
        sc["segment"] = kept
    if static_s is not None and sc["segment"][0]["type"] == "static":
        sc["segment"][0]["duration_s"] = float(static_s)
    if scale_ppm is not None:
        sc["imu"]["gyro_scale_ppm"] = [float(v) for v in scale_ppm[:3]]
        sc["imu"]["accel_scale_ppm"] = [float(v) for v in scale_ppm[3:]]
    if imu_rate:
        sc["scenario"]["imu_rate_hz"] = float(imu_rate)
    if gnss_rate:
        sc["gnss"]["rate_hz"] = float(gnss_rate)
        sc["heading"]["rate_hz"] = float(gnss_rate)
    if not bias_drawn_from_prior:
        return sc, None
    imu, prior = sc["imu"], [None, None]
    if bias_drawn_from_prior in (True, "gyro"):
        imu.pop("gyro_bias_deg_h", None)
        prior[0] = np.asarray(imu["gyro_bias_instability_deg_h"], float) * DEG_H
    if bias_drawn_from_prior in (True, "accel"):
        imu.pop("accel_bias_mg", None)
        prior[1] = np.asarray(imu["accel_bias_instability_mg"], float) * MG
    return sc, tuple(prior)


def one_run(scenario, seed, workdir, bias_prior=None, imu_noise_scale=1.0):
    """One seed: simulate, run the recipe the simulator writes (prior σ of b replaced by
    bias_prior when given; the filter's gyro/accel σ multiplied by imu_noise_scale — 1
    is the true noise, anything else a deliberately mis-tuned filter, run without the
    floor the pipeline otherwise puts on the IMU σ from the static window's noise).
    Returns (z, x̂, truth, nees (3, epochs), rejected, t, moving_aided) at 1 Hz epochs."""
    sim = simulate_scenario(scenario, f"{workdir}/seed{seed}", seed=seed)
    recipe = load_recipe(sim.recipe_path)
    for j, key in enumerate(("gyro_bias_rad_s", "accel_bias_m_s2")):
        if bias_prior is not None and bias_prior[j] is not None:
            recipe = replace(recipe, initial_sigma=replace(
                recipe.initial_sigma, **{key: tuple(float(v) for v in bias_prior[j])}))
    if imu_noise_scale != 1.0:   # and no floor from the data ([filter] imu_noise_from_static)
        nz = recipe.noise
        recipe = replace(recipe, noise=replace(
            nz, gyro_sigma_rad_s=tuple(imu_noise_scale * np.asarray(nz.gyro_sigma_rad_s)),
            accel_sigma_m_s2=tuple(imu_noise_scale * np.asarray(nz.accel_sigma_m_s2))),
            filter=replace(recipe.filter, imu_noise_from_static=False))
    prep = prepare_run(recipe)
    rec = run_prepared(prep)
    tr = sim.truth
    truth = np.r_[tr.gyro_bias[-1], tr.accel_bias[-1], tr.gyro_scale, tr.accel_scale]
    n = rec.x.shape[1]
    x, sd = rec.x[-1, 15:n], rec.sd[-1, 15:n]
    z = (x - truth[: n - 15]) / sd
    errs = reference_errors(prep, rec, navigation_solution(prep, rec))
    t = errs["t"] - errs["t"][0]
    pick = np.flatnonzero(np.r_[True, np.floor(t[1:]) != np.floor(t[:-1])])   # 1 Hz
    nees = np.stack([errs["nees"][k][pick] for k in NEES_BLOCKS])
    ref = prep.dataset.reference
    speed = np.interp(errs["t"][pick], ref.t, np.hypot(ref.vel_enu[:, 0], ref.vel_enu[:, 1]))
    aided = np.ones(pick.size, dtype=bool)
    for out in scenario["gnss"].get("outage", []):
        aided &= ~((t[pick] >= out["start_s"]) & (t[pick] < out["end_s"] + OUTAGE_RECOVERY_S))
    rejected = int(rec.rejected[:, AIDING_SLOTS].sum())
    return z, x, truth, nees, rejected, t[pick], (speed > MOVING_SPEED_M_S) & aided


def monte_carlo(scenario, seeds, quiet=False, bias_prior=None, imu_noise_scale=1.0):
    """one_run for every seed → MonteCarlo (epochs cut to the shortest run)."""
    zs, nees, rejected, est, masks = [], [], [], [], []
    t = None
    with tempfile.TemporaryDirectory() as work:
        for s in seeds:
            z, x, truth, ne, rej, t_s, mask = one_run(scenario, s, work, bias_prior,
                                                      imu_noise_scale)
            zs.append(z)
            est.append((x, truth))
            nees.append(ne)
            rejected.append(rej)
            masks.append(mask)
            t = t_s if t is None or t_s.size < t.size else t
            if not quiet:
                print(f"seed {s}: max |z| {np.abs(z).max():.2f} ({NAMES[np.argmax(np.abs(z))]}),"
                      f" aiding rejected {rej}", flush=True)
    k = t.size
    return MonteCarlo(np.array(zs), np.stack([a[:, :k] for a in nees]), np.array(rejected),
                      est, t, np.all([m[:k] for m in masks], axis=0))


def ensemble_nees_in_band(nees, epochs=None):
    """Ensemble-mean NEES of r^n, v^b, θ against the two-sided 95 % band χ²(3N)/N (N runs:
    the mean of N independent χ²(3) NEES of a consistent filter is χ²(3N)/N at every
    epoch). nees (N, 3, epochs); epochs: bool mask or index of the epochs to use (all).
    Returns (lo, hi, {block: (fraction of the epochs inside, below, above, time mean)})."""
    n = nees.shape[0]
    lo, hi = stats.chi2.ppf([0.025, 0.975], 3 * n) / n
    mean = nees.mean(axis=0)
    if epochs is not None:
        mean = mean[:, epochs]
    out = {name: (float(np.mean((m >= lo) & (m <= hi))), float(np.mean(m < lo)),
                  float(np.mean(m > hi)), float(m.mean()))
           for name, m in zip(NEES_BLOCKS, mean)}
    return float(lo), float(hi), out


def report(zs, nees, rejected, moving_aided=None):
    n = zs.shape[0]
    print(f"\n{n} runs: z = (estimate − truth)/σ at the last epoch")
    print(f"{'state':6s} {'mean z':>8s} {'± s.e.':>7s} {'rms z':>7s} {'|z|≤3':>7s}")
    ok = []
    for j, name in enumerate(NAMES[: zs.shape[1]]):
        z = zs[:, j]
        frac = float(np.mean(np.abs(z) <= 3.0))
        ok.append(frac)
        print(f"{name:6s} {z.mean():8.2f} {z.std(ddof=1) / np.sqrt(n):7.2f} "
              f"{np.sqrt(np.mean(z ** 2)):7.2f} {frac:7.0%}")
    print(f"mean z² over the states: {np.mean(zs ** 2):.2f};  fraction of (run, state) with "
          f"|z| ≤ 3: {np.mean(np.abs(zs) <= 3):.1%};  worst state: {min(ok):.0%}")
    subsets = [("all", None)]
    if moving_aided is not None:
        subsets += [("moving, aided", moving_aided), ("rest/outage", ~moving_aided)]
    for label, mask in subsets:
        lo, hi, blocks = ensemble_nees_in_band(nees, mask)
        count = nees.shape[2] if mask is None else int(np.sum(mask))
        print(f"ensemble-mean NEES, {label} ({count} 1 Hz epochs), band [{lo:.2f}, {hi:.2f}]:")
        for name, (inside, below, above, mean) in blocks.items():
            print(f"  {name:13s}: time mean {mean:.2f}, inside on {inside:.1%} (below "
                  f"{below:.1%}, above {above:.1%})")
    print(f"aiding observations rejected per run: mean {rejected.mean():.1f}, max "
          f"{rejected.max()}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default="default")
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--scale-ppm", type=float, nargs=6, metavar="PPM",
                    help="true gyro x,y,z and accel x,y,z scale factors (ppm)")
    ap.add_argument("--imu-rate", type=float)
    ap.add_argument("--gnss-rate", type=float)
    ap.add_argument("--bias-drawn-from-prior", nargs="?", const=True,
                    choices=(True, "gyro", "accel"), default=False,
                    help="draw the turn-on biases (of both sensors, or of the one named) "
                         "from N(0, BS²) and use BS as their prior σ")
    ap.add_argument("--cut-s", type=float, help="keep the segments up to this drive time (s)")
    ap.add_argument("--static-s", type=float, help="first (alignment) static segment (s)")
    ap.add_argument("--imu-noise-scale", type=float, default=1.0,
                    help="multiply the filter's gyro/accel σ (a mis-tuned filter; 1 = true)")
    ap.add_argument("--quiet", action="store_true")
    ap.add_argument("--save", metavar="NPZ", help="also save z, NEES, rejections (for --combine)")
    ap.add_argument("--combine", nargs="+", metavar="NPZ",
                    help="report the union of saved runs instead of running")
    args = ap.parse_args(argv)
    if args.combine:
        parts = [np.load(f) for f in args.combine]
        k = min(p["nees"].shape[2] for p in parts)
        report(np.concatenate([p["z"] for p in parts]),
               np.concatenate([p["nees"][:, :, :k] for p in parts]),
               np.concatenate([p["rejected"] for p in parts]),
               np.all([p["moving_aided"][:k] for p in parts], axis=0))
        return
    sc, bias_prior = scenario_variant(args.scenario, args.imu_rate, args.gnss_rate,
                                      args.scale_ppm, args.bias_drawn_from_prior, args.cut_s,
                                      args.static_s)
    t0 = time.process_time()
    mc = monte_carlo(sc, range(args.first_seed, args.first_seed + args.seeds), args.quiet,
                     bias_prior, args.imu_noise_scale)
    report(mc.z, mc.nees, mc.rejected, mc.moving_aided)
    if args.save:
        np.savez(args.save, z=mc.z, nees=mc.nees, rejected=mc.rejected, t=mc.t,
                 moving_aided=mc.moving_aided)
    print(f"CPU {time.process_time() - t0:.0f} s")


if __name__ == "__main__":
    main()
