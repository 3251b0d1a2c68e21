"""Autocorrelation of a run's normalised GNSS position / velocity innovations and the
Gauss-Markov correlation time they imply (docs/DESIGN.md "Held-out outage windows": the
τ of datasets/drive-boulder-0708/timing-gm.toml).

    PYTHONPATH=. python3 benchmarks/gnss_innovation_acf.py RECIPE [--lags 6]

The whole run, GNSS everywhere (no outages). z = innovation / √(innovation variance) per
ENU axis at the accepted rows; ρ_k from pairs exactly k fix intervals apart (no gap).
Rule for τ: a stream of white plus first-order Gauss-Markov error has ρ_k = c φ^k for
k ≥ 1 (c: the correlated share of the innovation variance), so φ = ρ₂ / ρ₁ (not ρ₁, which
the white part dilutes) and τ = −Δ / ln φ, Δ the fix interval; printed per axis and for
the mean of the three axes' ρ₁, ρ₂ (one τ for the recipe). A consistent filter's
innovations are white: ρ_k ≈ 0 within ±2/√N."""

import argparse

import numpy as np

from gmis.recipe import load_recipe
from gmis.run_preparation import prepare_run, run_prepared

GROUPS = ((6, "position"), (9, "velocity"))   # first slot of each 3-row GNSS group


def autocorrelation(t, z, ok, lags):
    """(lags, 3) ρ_k of the columns of z over pairs k fix intervals apart; and the fix
    interval Δ (median spacing, s)."""
    dt = float(np.median(np.diff(t)))
    rho = np.full((lags, z.shape[1]), np.nan)
    for k in range(1, lags + 1):
        exact = np.abs((t[k:] - t[:-k]) - k * dt) < 0.3 * dt
        for a in range(z.shape[1]):
            m = exact & ok[:-k, a] & ok[k:, a]
            x, y = z[:-k, a][m], z[k:, a][m]
            x, y = x - x.mean(), y - y.mean()
            rho[k - 1, a] = (x * y).mean() / np.sqrt((x * x).mean() * (y * y).mean())
    return rho, dt


def gm_time(rho1, rho2, dt):
    """(φ, τ s, c) of ρ_k = c φ^k from the first two lags; τ = inf when φ ∉ (0, 1)."""
    phi = rho2 / rho1
    tau = -dt / np.log(phi) if 0.0 < phi < 1.0 else np.inf
    return phi, tau, rho1 / phi


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("recipe")
    ap.add_argument("--lags", type=int, default=6)
    args = ap.parse_args()
    rec = run_prepared(prepare_run(load_recipe(args.recipe)))
    for s0, name in GROUPS:
        rows = np.flatnonzero(rec.innov_var[:, s0] > 0)
        z = rec.innov[rows, s0:s0 + 3] / np.sqrt(rec.innov_var[rows, s0:s0 + 3])
        ok = rec.rejected[rows, s0:s0 + 3] == 0
        rho, dt = autocorrelation(rec.t[rows], z, ok, args.lags)
        print(f"{name}: {rows.size} epochs, fix interval {dt:.3f} s, ±2/√N = "
              f"{2 / np.sqrt(rows.size):.3f}")
        for k in range(args.lags):
            print(f"  lag {k + 1} ({(k + 1) * dt:.2f} s): ρ E N U "
                  + " ".join(f"{v:6.3f}" for v in rho[k]))
        for label, r1, r2 in [*zip("ENU", rho[0], rho[1]),
                              ("mean", rho[0].mean(), rho[1].mean())]:
            phi, tau, c = gm_time(r1, r2, dt)
            print(f"  {label:4s}: φ = ρ2/ρ1 = {phi:.3f} per fix → τ {tau:.3f} s, "
                  f"correlated share c {c:.2f}")


if __name__ == "__main__":
    main()
