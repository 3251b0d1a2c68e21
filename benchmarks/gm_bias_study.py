"""Gauss-Markov bias states, acceptance study (issue 17): filter consistency and outage
drift on a simulated drive whose IMU errors are a calibrated composite model.

The IMU errors of the default drive (gmis.simulate's default scenario, scale factors off,
its own GNSS outage removed) are replaced by the model `gmis calibrate` identified for a
real sensor (calibration.json, e.g. of the ADIS16405 replicates in
../shared/data/imu-static-adis16405/): per axis the white noise at the IMU rate
(`filter.measurement_sigma`), the slowest AR1 as a first-order Gauss-Markov bias and,
with `--with-rw`, the model's random walk where it has one. Then, per seed:

* the GMIKF with the calibrated recipe (the simulator's recipe with the IMU keys of the
  [noise] fragment calibration.filter_inputs writes for that simulated model: a single
  AR1 exactly, AR1 + RW as its Gauss-Markov over-bound on lags ≤ `--horizon`; or with
  `--rw-alternative` the fragment's random-walk drift) and with the default Table 6-2 noise (gyro
  0.75 deg/s, accel 0.16 m/s², no bias drift): NEES of r^n, v^b, θ (3 dof) and of b_ω,
  b_a (3 dof) at CHECK_TIMES_S, averaged over the N seeds per time (Bar-Shalom Monte
  Carlo NEES) against the two-sided band χ²(3N)/N at a family-wise 95 % level
  (Bonferroni over the times); the bias errors are correlated over τ, so only the
  across-seed average is a proper test; when the filter counts a truth AR1 as white
  measurement noise (τ < white_below_s) the rows "<bias>_slow" compare the bias states with
  the simulated bias without that AR1 (same seed, its σ set to 0);
* the outage experiment (gmis.outages.run_outage_experiment: GNSS and heading removed in
  `--windows` windows of `--outage` s over the moving part) for both recipes: RMS of the
  per-window maximum horizontal drift of the GMIKF and of the error-state INS.

    PYTHONPATH=$PWD python3 benchmarks/gm_bias_study.py CAL/calibration.json \
        [--seeds 8] [--outage-seeds 4] [--with-rw] [--horizon 600] [--rw-alternative]
        [--white-below 1.0] [--json OUT.json]
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np
from scipy import stats

from calibration import filter_inputs as F
from calibration import processes as P
from gmis.outages import run_outage_experiment
from gmis.recipe import load_recipe
from gmis.run_preparation import prepare_run, run_prepared
from gmis.simulate import default_scenario_path, simulate_scenario
from gmis.simulate.writer import dump_toml

DEG = math.pi / 180.0
DEG_H = DEG / 3600.0
IMU_DT = 0.01
CHECK_TIMES_S = np.array([330.0, 400.0, 470.0, 540.0, 590.0])


def _axis_model(entry: dict) -> tuple[tuple, np.ndarray]:
    """(model, θ) of one axis' AWV fit in calibration.json."""
    fit = entry["awv"] if "awv" in entry else entry["fit"]
    model, theta = [], []
    for proc in fit["processes"]:
        model.append(proc["process"])
        theta += [proc[name] for name in P.PARAMETER_NAMES[proc["process"]]]
    return tuple(model), np.array(theta)


def simulated_axes(cal: dict, with_rw: bool, horizon_s: float,
                   white_below_s: float = F.WHITE_BELOW_S) -> dict:
    """Per axis the simulated truth — white noise of the WN, QN and every AR1 faster than
    the IMU interval (their per-sample variance at the IMU rate), the slowest AR1 with
    τ ≥ the IMU interval as a Gauss-Markov drift and, with_rw, the RW (``truth``) — and
    the filter inputs calibration.filter_inputs gives for that truth model (AR1s shorter
    than its white_below_s count as white measurement noise; a RW with a slower AR1 is
    over-bounded by one Gauss-Markov state on lags ≤ horizon_s; a RW alone is the
    random-walk bias)."""
    dt = cal["sample_interval_s"]
    out = {}
    for axis, entry in cal["axes"].items():
        model, theta = _axis_model(entry)
        blocks = list(zip(model, P.split_theta(model, theta)))
        slow = [b for p, b in blocks if p == "AR1" and P.tau_seconds(b[0], dt) >= IMU_DT]
        if not slow:
            raise SystemExit(f"{axis}: needs an AR1 with τ ≥ IMU interval")
        slow = max(slow, key=lambda b: b[0])
        white = F.filter_noise_of(model, theta, dt, IMU_DT, horizon_s, white_below_s=IMU_DT)
        wn = white["measurement_sigma"] ** 2 * IMU_DT / dt  # white part per sample at dt
        truth_model, truth_theta = ["WN", "AR1"], [wn, slow[0], slow[1]]
        rw = [b for p, b in blocks if p == "RW"]
        if with_rw and rw:
            truth_model.append("RW")
            truth_theta.append(rw[0][0])
        out[axis] = F.filter_noise_of(tuple(truth_model), np.array(truth_theta), dt, IMU_DT,
                                      horizon_s, white_below_s)
        out[axis]["truth"] = {
            "white_sigma": white["measurement_sigma"],
            "gm_tau_s": P.tau_seconds(slow[0], dt),
            "gm_sigma": float(np.sqrt(slow[1] / (1.0 - slow[0] ** 2))),
            "rw_sigma_per_step": (float(np.sqrt(rw[0][0] * IMU_DT / dt))
                                  if with_rw and rw else 0.0)}
    return out


def calibrated_imu_section(noise: dict) -> dict:
    """The scenario's [imu] table of the simulated truth: WN density, GM σ (°/h, mg) and
    τ of the slowest AR1, the RW as bias instability with T = 100 s (0 without)."""
    out = {"bias_correlation_time_s": 100.0}
    for kind, wn_key, wn_scale, gm_key, gm_scale, bs_key in (
            ("gyro", "gyro_arw_deg_sqrt_h", 60.0 / DEG, "gyro_gm_sigma_deg_h", 1 / DEG_H,
             "gyro_bias_instability_deg_h"),
            ("accel", "accel_vrw_m_s_sqrt_h", 60.0, "accel_gm_sigma_mg", 1 / 9.80665e-3,
             "accel_bias_instability_mg")):
        f = [noise[f"{kind}_{a}"]["truth"] for a in "xyz"]
        out[wn_key] = [x["white_sigma"] * math.sqrt(IMU_DT) * wn_scale for x in f]
        out[gm_key] = [x["gm_sigma"] * gm_scale for x in f]
        out[f"{kind}_gm_tau_s"] = [x["gm_tau_s"] for x in f]
        # per-step σ_rw = BS √(δt/T)  →  BS = σ_rw / √(δt/T)
        out[bs_key] = [x["rw_sigma_per_step"] / math.sqrt(IMU_DT / 100.0) * gm_scale for x in f]
        out[f"{kind}_bias_{'deg_h' if kind == 'gyro' else 'mg'}"] = [0.0, 0.0, 0.0]
    return out


def scenario_dict(imu: dict) -> dict:
    sc = tomllib.loads(Path(default_scenario_path()).read_text())
    sc["imu"] = imu
    sc["gnss"].pop("outage", None)
    return sc


IMU_KEYS = ("gyro_deg_s", "accel_m_s2", "gyro_bias_drift_deg_s", "accel_bias_drift_m_s2",
            "gyro_bias_model", "gyro_bias_tau_s", "gyro_bias_sigma_deg_s", "accel_bias_model",
            "accel_bias_tau_s", "accel_bias_sigma_m_s2")


def recipes(dataset_dir: Path, fragment: dict) -> tuple[Path, Path]:
    """(calibrated, default Table 6-2) recipe files: the simulator's recipe with the IMU
    keys of the calibration fragment, and with none. The Gauss-Markov bias priors are the
    stationary σ (the simulator's 3σ would make the early bias NEES small)."""
    path = dataset_dir / "recipe.toml"
    doc = tomllib.loads(path.read_text())
    noise = {k: v for k, v in doc["noise"].items() if k not in IMU_KEYS}
    noise.update({k: v for k, v in fragment.items() if k in IMU_KEYS})
    doc["noise"] = noise
    if noise.get("gyro_bias_model") == "gauss_markov":
        doc["initial_sigma"]["gyro_bias_deg_s"] = list(noise["gyro_bias_sigma_deg_s"])
    if noise.get("accel_bias_model") == "gauss_markov":
        doc["initial_sigma"]["accel_bias_m_s2"] = list(noise["accel_bias_sigma_m_s2"])
    cal = dataset_dir / "recipe_calibrated.toml"
    cal.write_text(dump_toml(doc))
    default = copy.deepcopy(doc)
    default["noise"] = {k: v for k, v in noise.items()
                        if k in ("heading_deg", "gnss_position_m", "gnss_velocity_m_s")}
    dflt = dataset_dir / "recipe_default.toml"
    dflt.write_text(dump_toml(default))
    return cal, dflt


def slow_imu_section(imu: dict, noise: dict) -> dict | None:
    """The [imu] table with the Gauss-Markov σ set to 0 on every axis whose truth AR1 the
    filter counts as white measurement noise (τ < white_below_s); None if there is none.
    The simulator draws the same random numbers whatever the σ, so the same seed gives the
    same RW and the bias without that AR1: the bias state's estimand."""
    out, fast = copy.deepcopy(imu), False
    for kind, key in (("gyro", "gyro_gm_sigma_deg_h"), ("accel", "accel_gm_sigma_mg")):
        for i, a in enumerate("xyz"):
            x = noise[f"{kind}_{a}"]
            if x["truth"]["gm_tau_s"] < x["white_below_s"]:
                out[key][i], fast = 0.0, True
    return out if fast else None


def nees_samples(recipe_path: Path, truth, bias_reference=None) -> dict:
    """NEES at CHECK_TIMES_S; ``bias_reference``: a second truth (slow_imu_section) whose
    biases, without the AR1 the filter treats as noise, give the rows "<bias>_slow"."""
    prep = prepare_run(load_recipe(recipe_path))
    rec = run_prepared(prep)
    t = rec.t - truth["time_gps_s"][0]
    rows = [int(np.argmin(np.abs(t - s))) for s in CHECK_TIMES_S]
    rows = [r if rec.imu_row[r] >= 0 else r - 1 for r in rows]
    k = rec.imu_row[rows]
    out = {}
    blocks = {"position": (slice(0, 3), truth["r_enu"][k], 0),
              "velocity_body": (slice(3, 6), truth["v_b"][k], 1),
              "attitude": (slice(9, 12), truth["euler"][k], 2)}
    for name, (sl, true, b) in blocks.items():
        e = rec.x[rows, sl] - true
        if name == "attitude":
            e[:, 2] = (e[:, 2] + np.pi) % (2 * np.pi) - np.pi
        c = rec.cov_blocks[rows, b]
        out[name] = np.einsum("ki,ki->k", e, np.linalg.solve(c, e[..., None])[..., 0])
    for name, sl, true in (("gyro_bias", slice(15, 18), truth["gyro_bias"][k]),
                           ("accel_bias", slice(18, 21), truth["accel_bias"][k])):
        e = rec.x[rows, sl] - true     # bias states: diagonal P (the records keep √diag)
        out[name] = ((e / rec.sd[rows, sl]) ** 2).sum(axis=1)
        if bias_reference is not None:
            e = rec.x[rows, sl] - bias_reference[name][k]
            out[f"{name}_slow"] = ((e / rec.sd[rows, sl]) ** 2).sum(axis=1)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("calibration", type=Path, help="calibration.json of gmis calibrate")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--outage-seeds", type=int, default=4)
    ap.add_argument("--outage", type=float, default=20.0, help="outage length, s")
    ap.add_argument("--windows", type=int, default=6)
    ap.add_argument("--with-rw", action="store_true")
    ap.add_argument("--horizon", type=float, default=600.0,
                    help="lags (s) of the Gauss-Markov over-bound (default: the drive, 600)")
    ap.add_argument("--rw-alternative", action="store_true",
                    help="the fragment's random-walk alternative instead of the GM state")
    ap.add_argument("--white-below", type=float, default=F.WHITE_BELOW_S,
                    help="AR1s with a shorter τ (s) are white measurement noise for the filter "
                         "(default %(default)s; 0.01 = the IMU interval, as before)")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    cal = json.loads(args.calibration.read_text())
    noise = simulated_axes(cal, args.with_rw, args.horizon, args.white_below)
    text = F.noise_fragment(noise, "gm_bias_study: the simulated truth")
    if args.rw_alternative:
        text = text.replace("# random-walk alternative: ", "").replace(
            '_bias_model = "random_walk", ', '_bias_model = "random_walk"\n')
        text = "\n".join(line for line in text.splitlines()
                          if "gauss_markov" not in line and "_bias_tau_s" not in line
                          and "_bias_sigma_" not in line)
    fragment = tomllib.loads(text)["noise"]
    print("calibrated [noise]:", json.dumps({k: v for k, v in fragment.items()
                                             if k in IMU_KEYS}))
    print("bias states:", json.dumps({a: x["bias_state"] for a, x in noise.items()}))
    imu = calibrated_imu_section(noise)
    imu_slow = slow_imu_section(imu, noise)
    print("simulated [imu]:", json.dumps(imu))
    nees = {"calibrated": {}, "default": {}}
    drift = {"calibrated": [], "default": []}
    cpu0 = time.process_time()
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            sim = simulate_scenario(scenario_dict(imu), Path(tmp) / f"d{seed}", seed=seed + 1)
            ddir = Path(sim.dataset_dir)
            truth = np.load(ddir / "truth.npz")
            reference = None
            if imu_slow is not None:
                sim2 = simulate_scenario(scenario_dict(imu_slow), Path(tmp) / f"s{seed}",
                                         seed=seed + 1)
                reference = np.load(Path(sim2.dataset_dir) / "truth.npz")
                assert np.array_equal(reference["r_enu"], truth["r_enu"])
                for name, key in (("gyro_bias", "gyro_gm_sigma_deg_h"),
                                  ("accel_bias", "accel_gm_sigma_mg")):
                    same = [i for i in range(3) if imu_slow[key][i] == imu[key][i]]
                    assert np.array_equal(reference[name][:, same], truth[name][:, same])
            paths = dict(zip(("calibrated", "default"), recipes(ddir, fragment)))
            for label, path in paths.items():
                for name, v in nees_samples(path, truth, reference).items():
                    nees[label].setdefault(name, []).append(v)
                if seed < args.outage_seeds:
                    s = run_outage_experiment(path, args.outage, args.windows)
                    drift[label].append({f: s["rms_max_drift_m"][f]["horizontal"]
                                         for f in ("gmikf", "errins")})
            print(f"seed {seed + 1} done, CPU {time.process_time() - cpu0:.0f} s", flush=True)
    report = {"imu": imu, "with_rw": args.with_rw, "seeds": args.seeds, "nees": {},
              "horizon_s": args.horizon, "rw_alternative": args.rw_alternative,
              "white_below_s": args.white_below,
              "bias_states": {a: x["bias_state"] for a, x in noise.items()},
              "outage_s": args.outage, "windows": args.windows,
              "outage_rms_horizontal_m": {}}
    n = args.seeds
    alpha = 0.05 / CHECK_TIMES_S.size
    lo, hi = (float(v) for v in stats.chi2.ppf([alpha / 2, 1 - alpha / 2], 3 * n) / n)
    for label, by_name in nees.items():
        for name, vals in by_name.items():
            per_time = np.mean(vals, axis=0)      # (seeds, times) → mean over seeds
            report["nees"].setdefault(label, {})[name] = {
                "per_time": per_time.tolist(), "times_s": CHECK_TIMES_S.tolist(),
                "band": [lo, hi], "inside": int(((per_time >= lo) & (per_time <= hi)).sum())}
    for label, rows in drift.items():
        if rows:
            report["outage_rms_horizontal_m"][label] = {
                f: {"per_seed": [r[f] for r in rows],
                    "rms": float(np.sqrt(np.mean([r[f] ** 2 for r in rows])))}
                for f in ("gmikf", "errins")}
    print(f"\nMonte Carlo NEES over {n} seeds at t = {CHECK_TIMES_S.tolist()} s; band "
          f"[{lo:.2f}, {hi:.2f}] (family-wise 95 %), * = outside")
    for label, by_name in report["nees"].items():
        for name, d in by_name.items():
            print(f"  {label:10s} {name:13s} " + " ".join(
                f"{v:6.2f}{'*' if not lo <= v <= hi else ' '}" for v in d["per_time"])
                + f"   inside {d['inside']}/{CHECK_TIMES_S.size}")
    for label, d in report["outage_rms_horizontal_m"].items():
        print(f"outage {args.outage:g} s × {args.windows}, RMS max horizontal drift, {label}: "
              + ", ".join(f"{f} {v['rms']:.2f} m" for f, v in d.items()))
    print(f"CPU {time.process_time() - cpu0:.0f} s")
    if args.json:
        args.json.write_text(json.dumps(report, indent=1))
    return report


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
