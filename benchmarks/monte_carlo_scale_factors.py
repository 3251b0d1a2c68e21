"""Monte Carlo consistency of the GMIKF's bias and scale-factor states (issue 13 item 2).

For seeds s0 … s0+N−1 the scenario is simulated (every random stream re-seeded), the
recipe the simulator writes is run, and per run

  z_j = (x̂_j − x_j) / σ̂_j   at the last epoch, for the 12 states b_ω, b_a, S_ω, S_a

is recorded (x_j the simulated truth: bias at the last sample, constant scale factor).
Printed: per state mean z ± its Monte-Carlo standard error, RMS z and the fraction of
runs with |z| ≤ 3; the NEES of r^n, v^b, θ averaged over the runs at 1 Hz epochs and the
fraction of those epochs inside the two-sided 95 % band χ²(3N)/N; and the aiding
observations rejected (a consistent filter rejects ≈ α of good data).

Usage (from the repository root):
    PYTHONPATH=$PWD python3 benchmarks/monte_carlo_scale_factors.py --seeds 20
    ... --scale-ppm 6000 -7000 8000 5000 -6000 7000     (IMU440-class true scale factors)
    ... --imu-rate 200 --gnss-rate 1                     (200 Hz IMU / 1 Hz GNSS variant)
    ... --bias-drawn-from-prior   (turn-on biases drawn per seed from N(0, BS²), BS the
        bias instability, and the recipe's prior σ of b set to that BS: the truth is then
        a draw from the filter's prior, instead of a fixed bias with prior σ 3|b| — the
        static part's NEES test, docs/DESIGN.md "Process noise at rest")
"""

from __future__ import annotations

import argparse
import copy
import tempfile
import time
from dataclasses import replace

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


def one_run(scenario, seed, workdir, bias_prior=None):
    sim = simulate_scenario(scenario, f"{workdir}/seed{seed}", seed=seed)
    recipe = load_recipe(sim.recipe_path)
    if bias_prior is not None:
        recipe = replace(recipe, initial_sigma=replace(
            recipe.initial_sigma, gyro_bias_rad_s=tuple(bias_prior[0]),
            accel_bias_m_s2=tuple(bias_prior[1])))
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
    nees = np.stack([errs["nees"][k][pick] for k in ("position", "velocity_body",
                                                      "attitude")])
    rejected = int(rec.rejected[:, AIDING_SLOTS].sum())
    return z, x, truth, nees, rejected


def monte_carlo(scenario, seeds, quiet=False, bias_prior=None):
    zs, nees, rejected, est = [], [], [], []
    with tempfile.TemporaryDirectory() as work:
        for s in seeds:
            z, x, truth, ne, rej = one_run(scenario, s, work, bias_prior)
            zs.append(z)
            est.append((x, truth))
            nees.append(ne)
            rejected.append(rej)
            if not quiet:
                print(f"seed {s}: max |z| {np.abs(z).max():.2f} ({NAMES[np.argmax(np.abs(z))]}),"
                      f" aiding rejected {rej}", flush=True)
    k = min(a.shape[1] for a in nees)
    return (np.array(zs), np.stack([a[:, :k] for a in nees]), np.array(rejected), est)


def report(zs, nees, rejected):
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
    lo, hi = stats.chi2.ppf([0.025, 0.975], 3 * n) / n
    mean_nees = nees.mean(axis=0)            # (3, epochs)
    for b, name in enumerate(("position", "velocity_body", "attitude")):
        inside = np.mean((mean_nees[b] >= lo) & (mean_nees[b] <= hi))
        print(f"NEES {name:13s}: time mean {mean_nees[b].mean():.2f}, ensemble mean inside "
              f"[{lo:.2f}, {hi:.2f}] on {inside:.1%} of {mean_nees.shape[1]} 1 Hz epochs "
              f"(below {np.mean(mean_nees[b] < lo):.1%}, above {np.mean(mean_nees[b] > hi):.1%})")
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
    ap.add_argument("--bias-drawn-from-prior", action="store_true",
                    help="draw the turn-on biases from N(0, BS²) and use BS as their prior σ")
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
               np.concatenate([p["rejected"] for p in parts]))
        return
    sc = copy.deepcopy(load_scenario(scenario_path(args.scenario)))
    if args.scale_ppm:
        sc["imu"]["gyro_scale_ppm"] = list(args.scale_ppm[:3])
        sc["imu"]["accel_scale_ppm"] = list(args.scale_ppm[3:])
    if args.imu_rate:
        sc["scenario"]["imu_rate_hz"] = args.imu_rate
    if args.gnss_rate:
        sc["gnss"]["rate_hz"] = args.gnss_rate
        sc["heading"]["rate_hz"] = args.gnss_rate
    bias_prior = None
    if args.bias_drawn_from_prior:
        imu = sc["imu"]
        imu.pop("gyro_bias_deg_h", None)
        imu.pop("accel_bias_mg", None)
        bias_prior = (np.asarray(imu["gyro_bias_instability_deg_h"], float) * DEG_H,
                      np.asarray(imu["accel_bias_instability_mg"], float) * MG)
    t0 = time.process_time()
    zs, nees, rejected, _ = monte_carlo(sc, range(args.first_seed,
                                                  args.first_seed + args.seeds), args.quiet,
                                        bias_prior)
    report(zs, nees, rejected)
    if args.save:
        np.savez(args.save, z=zs, nees=nees, rejected=rejected)
    print(f"CPU {time.process_time() - t0:.0f} s")


if __name__ == "__main__":
    main()
