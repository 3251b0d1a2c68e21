"""Single-frequency (L1-only) dual-antenna heading on the heading test scene
(tests/test_heading.py: 9 satellites, 2 m along-track baseline, 1 Hz, 3 mm / 0.3 m
undifferenced σ with elevation weighting, 3 m primary-position error, a steady 3°/s turn).

For each seed: fix rate, first fixed epoch, wrong integer fixes (every fixed epoch's DD
integers against the simulated truth; before and after the baseline-length check), length
rejections, partial-AR fixes, heading RMS against the truth and the mean reported σ, CPU
time (time.process_time). The dual-frequency run of the same scene (with L2) is the
reference.

Heading RMS with and without the known-length constraint (gnss.heading module doc) and,
per fixed epoch, the Cramér-Rao bounds of the heading from the fixed baseline b̂ ~ N(b, C_b)
(C_b the reported full ENU covariance = the inverse Fisher information of the epoch's
phase + code DDs once the integers are known; the scene's noise is white, so other epochs
carry no information on this epoch's baseline), evaluated at the true b, RMS over the
fixed epochs √(mean σ²):
    free       σ_ψ² = gᵀ C_b g / h⁴,          g = (b_n, −b_e, 0), h² = b_e² + b_n²
    |b| known  σ_ψ² = gᵀ C_c g / h⁴,          C_c = C_b − C_b u uᵀ C_b / (uᵀ C_b u), u = b/|b|
    attitude   σ_ψ² = 1 / (gᵀ C_b⁻¹ g)        (pitch and roll known exactly: b = R_ψ b₀,
                                                ∂b/∂ψ = g, one unknown)
The |b|-known bound is computed a second time from the scene's own noise model
(scene_covariance: Fisher information from the DD design and SD cofactors with the
simulated σ, independent of the estimator's reported C_b), with the 95 % bootstrap
interval (epochs resampled) of heading RMS / that bound: 1 inside it = at the bound. Options: default RtkConfig(frequencies=("L1",)) — lock 5 epochs, ratio 3,
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

from gmis.earth import ecef_to_enu_matrix, ecef_to_geodetic
from gnss.double_difference import dd_cofactor
from gnss.heading import body_baseline_azimuth, heading_from_dd_epochs
from gnss.rtk import Q_FIXED, RtkConfig, process_dd_epochs
from tests.test_heading import PRIMARY_L, SECONDARY_L, simulate_moving_baseline

SIGMA_PHASE_M, SIGMA_CODE_M = 0.003, 0.3   # simulate_moving_baseline's defaults


def wrong(integers, truth, rows=None) -> int:
    idx = range(len(integers)) if rows is None else rows
    return sum(1 for i in idx if integers[i] is not None
               and any(n != truth[i][k] for k, n in integers[i].items()))


def crlb(cov, b):
    """RMS over epochs of the three heading bounds of the module doc (deg)."""
    g = np.column_stack([b[:, 1], -b[:, 0], np.zeros(len(b))])
    h4 = (b[:, 0] ** 2 + b[:, 1] ** 2) ** 2
    u = b / np.linalg.norm(b, axis=1)[:, None]
    cu = np.einsum("nij,nj->ni", cov, u)
    c_c = cov - np.einsum("ni,nj->nij", cu, cu) / np.einsum("ni,ni->n", u, cu)[:, None, None]
    free = np.einsum("ni,nij,nj->n", g, cov, g) / h4
    known = np.einsum("ni,nij,nj->n", g, c_c, g) / h4
    att = 1.0 / np.einsum("ni,ni->n", g, np.linalg.solve(cov, g[:, :, None])[:, :, 0])
    return tuple(float(np.degrees(np.sqrt(v.mean()))) for v in (free, known, att)), known


def scene_covariance(epochs, lin, rows, l1_only):
    """(len(rows), 3, 3) m²: the inverse Fisher information of each epoch's ENU baseline
    from the scene's own noise model (tests.test_heading.simulate_moving_baseline: σ 3 mm
    phase, 0.3 m code per undifferenced observable × √(1 + 1/sin²β), white, integers
    known), built from the DD design and SD cofactors alone — not from the covariance the
    estimator reports."""
    n_obs = 1 if l1_only else 2
    info_per_m = n_obs * (1.0 / SIGMA_PHASE_M ** 2 + 1.0 / SIGMA_CODE_M ** 2)
    out = np.empty((len(rows), 3, 3))
    for n, i in enumerate(rows):
        ep = epochs[i]
        lat, lon, _ = ecef_to_geodetic(*lin[i])
        a = ep.design @ ecef_to_enu_matrix(lat, lon).T
        m_inv = np.linalg.inv(dd_cofactor(ep.m_sd, ep.m_sd_ref))
        out[n] = np.linalg.inv(a.T @ m_inv @ a * info_per_m)
    return out


def ratio_interval(err, var, n_boot=2000):
    """95 % bootstrap interval (epochs resampled) of RMS(err) / √mean(var)."""
    rng = np.random.default_rng(0)
    idx = rng.integers(0, err.size, (n_boot, err.size))
    r = np.sqrt((err[idx] ** 2).mean(axis=1) / var[idx].mean(axis=1))
    return np.percentile(r, [2.5, 97.5])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--epochs", type=int, default=1000)
    ap.add_argument("--seeds", type=int, nargs="+", default=[3, 4, 5])
    args = ap.parse_args()
    alpha = body_baseline_azimuth(PRIMARY_L, SECONDARY_L)
    totals = {"epochs": 0, "fixed": 0, "wrong": 0}
    for seed in args.seeds:
        for l1_only in (True, False):
            epochs, lin, th, b_true, truth = simulate_moving_baseline(
                seed=seed, n_epochs=args.epochs, l1_only=l1_only, with_integers=True)
            cfg = RtkConfig(frequencies=("L1",) if l1_only else ("L1", "L2"))
            t0 = time.process_time()
            sol = heading_from_dd_epochs(epochs, lin.copy(), lin, 2.0, alpha, cfg)
            cpu = time.process_time() - t0
            free = heading_from_dd_epochs(epochs, lin.copy(), lin, 2.0, alpha, cfg,
                                          constrain_length=False)
            raw = process_dd_epochs(epochs, lin.copy(), cfg)
            fixed = sol.q == Q_FIXED
            d = (sol.heading[fixed] - th[fixed] + np.pi) % (2 * np.pi) - np.pi
            n_wrong = wrong(raw.integers, truth)
            n_wrong_out = wrong(raw.integers, truth, np.flatnonzero(fixed))
            name = "L1   " if l1_only else "L1+L2"
            bound, _ = crlb(sol.baseline_cov_enu[fixed], b_true[fixed])
            scene_bound, known_var = crlb(scene_covariance(epochs, lin, np.flatnonzero(fixed),
                                                           l1_only), b_true[fixed])
            lo, hi = ratio_interval(d, known_var)
            d_free = (free.heading[free.q == Q_FIXED] - th[free.q == Q_FIXED] + np.pi) \
                % (2 * np.pi) - np.pi
            print(f"seed {seed} {name}: {args.epochs} epochs, fix rate {fixed.mean():.4f} "
                  f"(first fix at epoch {int(np.argmax(fixed))}), wrong integer fixes "
                  f"{n_wrong} (after the length check {n_wrong_out}), length-rejected "
                  f"{int(sol.length_rejected.sum())}, partial-AR epochs {int(raw.partial.sum())}, "
                  f"heading RMS {np.degrees(np.sqrt(np.mean(d ** 2))):.4f} deg, max "
                  f"{np.degrees(np.abs(d).max()):.3f} deg, mean sigma "
                  f"{np.degrees(sol.sigma_heading[fixed].mean()):.4f} deg, CPU {cpu:.2f} s; "
                  f"without the length constraint: fix rate {(free.q == Q_FIXED).mean():.4f}, "
                  f"RMS {np.degrees(np.sqrt(np.mean(d_free ** 2))):.4f} deg; CRLB RMS free "
                  f"{bound[0]:.4f} / |b| known {bound[1]:.4f} / attitude known "
                  f"{bound[2]:.4f} deg; from the scene's noise model |b| known "
                  f"{scene_bound[1]:.4f} deg, RMS / bound "
                  f"{np.sqrt(np.mean(d ** 2)) / np.radians(scene_bound[1]):.3f} "
                  f"(95 % bootstrap {lo:.3f}-{hi:.3f})")
            if l1_only:
                totals["epochs"] += args.epochs
                totals["fixed"] += int(fixed.sum())
                totals["wrong"] += n_wrong
    print(f"L1 total: {totals['fixed']} fixed of {totals['epochs']} epochs, "
          f"{totals['wrong']} wrong integer fixes")


if __name__ == "__main__":
    main()
