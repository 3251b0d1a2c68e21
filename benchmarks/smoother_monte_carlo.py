"""Monte Carlo of the two-filter smoother on simulated drives with truth (issue 15):
smoothed and forward NEES of r^n, v^b, θ against the χ² band, smoothed σ ≤ forward σ at
every output epoch, and the horizontal drift in the scenario's GNSS outages.

    PYTHONPATH=. python3 benchmarks/smoother_monte_carlo.py --seeds 20 [--scenario default]

NEES samples: every 10 s from 305 s to the end (outages included), the χ²(3K)/K band
over all K samples of all seeds (samples 10 s apart are treated as independent, as in
tests/test_pipeline_default_drive.py)."""

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import stats

from gmis.pipeline import run_recipe
from gmis.simulate import load_scenario, scenario_path, simulate_scenario

NEES = ("nees_position", "nees_velocity_body", "nees_attitude")


def one_seed(scenario, seed, root: Path):
    sim = simulate_scenario(scenario_path(scenario), root / f"ds{seed}", seed=seed)
    summary = run_recipe(sim.recipe_path, root / f"res{seed}", smooth=True)
    res = root / f"res{seed}"
    sol_s, sol_f = np.load(res / "solution.npz"), np.load(res / "solution_forward.npz")
    t0 = sol_f["t"][0]
    rows = np.searchsorted(sol_f["t"], sol_s["t"])
    sigma_ok = bool(np.all(sol_s["sd"] <= sol_f["sd"][rows] * (1 + 1e-9)))
    out = {"seed": seed, "sigma_ok": sigma_ok, "nees": {}, "outages": []}
    outages = [(o["start_s"], o["end_s"]) for o in
               load_scenario(scenario_path(scenario))["gnss"].get("outage", [])]
    for kind, name in (("smoothed", "errors.csv"), ("forward", "errors_forward.csv")):
        err = np.genfromtxt(res / name, delimiter=",", names=True)
        t = err["time_gps_s"] - t0
        samples = [int(np.argmin(np.abs(t - s))) for s in np.arange(305.0, t[-1], 10.0)]
        out["nees"][kind] = {k: err[k][samples].tolist() for k in NEES}
        h = np.hypot(err["de_m"], err["dn_m"])
        for j, (a, b) in enumerate(outages):
            inside = (t >= a) & (t <= b)
            if kind == "smoothed":
                out["outages"].append({"window": [a, b]})
            out["outages"][j][f"{kind}_max_m"] = float(h[inside].max())
    out["cpu_s_smoother"] = summary["smoother"]["cpu_s_forward_backward"]
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--scenario", default="default")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    rows = []
    c0 = time.process_time()
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            rows.append(one_seed(args.scenario, seed, Path(tmp)))
            r = rows[-1]
            drift = " ".join(f"{o['forward_max_m']:.3f}->{o['smoothed_max_m']:.3f} m "
                             f"({o['forward_max_m'] / o['smoothed_max_m']:.1f}x)"
                             for o in r["outages"])
            print(f"seed {seed:2d} sigma_s<=sigma_f {r['sigma_ok']} outage {drift}",
                  flush=True)
    print(f"scenario {args.scenario}, {args.seeds} seeds, CPU {time.process_time() - c0:.0f} s")
    for kind in ("smoothed", "forward"):
        for k in NEES:
            vals = np.concatenate([r["nees"][kind][k] for r in rows])
            n = vals.size
            lo, hi = stats.chi2.ppf([0.025, 0.975], 3 * n) / n
            print(f"{kind:8s} {k:20s} mean {vals.mean():.3f} over {n} samples, 95 % band "
                  f"[{lo:.3f}, {hi:.3f}] {'inside' if lo <= vals.mean() <= hi else 'OUTSIDE'}")
    print("sigma_s <= sigma_f at every output epoch in all seeds:",
          all(r["sigma_ok"] for r in rows))
    if rows[0]["outages"]:
        ratio = np.array([[o["forward_max_m"] / o["smoothed_max_m"] for o in r["outages"]]
                          for r in rows])
        fw = np.array([[o["forward_max_m"] for o in r["outages"]] for r in rows])
        sm = np.array([[o["smoothed_max_m"] for o in r["outages"]] for r in rows])
        print(f"outage max horizontal drift: forward median {np.median(fw):.3f} m, smoothed "
              f"median {np.median(sm):.3f} m; ratio min {ratio.min():.2f} median "
              f"{np.median(ratio):.2f}; seeds with ratio >= 5: {(ratio >= 5).sum()}/{ratio.size}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows))


if __name__ == "__main__":
    main()
