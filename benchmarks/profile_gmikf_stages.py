"""Where the µs of one GMIKF epoch go: the kernel's stages timed cumulatively.

    python benchmarks/profile_gmikf_stages.py [--keep DIR] [--minutes 10] [--rounds 7]

The bench_gmikf drive (simulated into --keep, or a temporary folder) is run to its middle;
from that state x, P a numba loop over the next 20,000 epochs restarts every epoch from the
same x, P and runs the stages of gmis.gmikf.gmikf_chunk_ws up to a level: 0 copy of x, P
only; 1 + predict (Φ P Φᵀ + Λ Q Λᵀ, f(x)); 2 + the rows of every sensor present and the
cleared records; 3 + innovations (H P, D); 4 + the outlier tests; 5 + the Kalman update;
6 + the scale-factor consider step; 7 + the state records. Printed per level: the minimum
and median over --rounds of the CPU µs per epoch, and the increment over the level below
(its stage's cost; minima are the figure to read on a loaded machine). The epochs keep their
sensor pattern (IMU every epoch, GNSS at its rate); Δt is the IMU interval. The loop
compiles once per tree (about a minute; cached beside this file).
"""

import argparse
import statistics
import sys
import time
from pathlib import Path

from numba import njit

sys.path.append(str(Path(__file__).resolve().parents[1]))
from gmis import gmikf as G

LEVELS = ("copy x, P", "predict", "rows + clear", "innovations", "outlier tests",
          "kalman_update", "drop_imu_scale_gain", "record_state")


@njit(cache=True)
def run_upto(level, e0, e1, dt, x0, p0, inp, cfg, ws, rec, x, p):
    """Epochs [e0, e1) from x0, P0 each, stages up to ``level`` (module doc)."""
    acc = 0.0
    for e in range(e0, e1):
        x[:] = x0
        p[:, :] = p0
        if level >= 1:
            G.predict(x, p, dt, cfg.n_imu, cfg.q_psd, 1.0, False, ws, cfg.drift_inv_tau)
        if level >= 2:
            G.assemble_epoch_rows(e, x, inp, cfg, ws)
            G.clear_epoch_records(e, cfg.q_psd.shape[0], ws, rec)
        m = G.innovations(e, p, ws, rec) if level >= 3 else 0
        if level >= 4 and m > 0:
            for g in range(0 if cfg.test_imu else 1, G.GROUP_START.shape[0]):
                G.group_outlier_test(e, G.GROUP_START[g], G.GROUP_SIZE[g], m,
                                     cfg.chi2_crit, cfg.z_crit, ws, rec)
            G.refute_stop(e, m, ws, rec)
            m = G.drop_rejected(e, m, ws, rec)
        ok = level >= 5 and m > 0 and G.kalman_update(x, p, m, ws)
        if ok and level >= 6 and cfg.consider_scale_imu and cfg.n_imu >= G.N_STATES_27:
            G.drop_imu_scale_gain(x, p, m, ws)
        if level >= 7:
            G.record_state(e, x, p, rec)
        acc += x[0] + p[5, 5]
    return acc


def main():
    from benchmarks.bench_gmikf import long_scenario
    from benchmarks.reference_kernel import bench_folder
    from gmis import run_filter
    from gmis.pipeline import prepare_run
    from gmis.recipe import load_recipe
    from gmis.simulate import simulate_scenario
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--keep", type=Path,
                    help="folder of the simulated drive (reused when present)")
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()
    folder = bench_folder(args.keep, "gmis-stages-")
    if not (folder / "recipe.toml").exists():
        simulate_scenario(long_scenario(args.minutes), folder, overwrite=True)
    prep = prepare_run(load_recipe(folder / "recipe.toml"))
    runner = run_filter.GmikfRunner(prep.epochs, prep.meas, prep.x0, prep.config,
                                    prep.frame, prep.stationary)
    half = runner.e_total // 2
    runner.advance(half)
    x0, p0 = runner.x.copy(), runner.p.copy()
    x, p = x0.copy(), p0.copy()
    inp, cfg = runner.inputs, runner.kernel_settings()
    ws, rec = runner.workspace, runner.records
    e0, e1 = half, min(half + 20000, runner.e_total)
    dt = float(prep.epochs.t[half + 1] - prep.epochs.t[half])
    for lv in range(len(LEVELS)):           # compile / warm up, touch the record rows
        run_upto(lv, e0, e1, dt, x0, p0, inp, cfg, ws, rec, x, p)
    us = {lv: [] for lv in range(len(LEVELS))}
    for _ in range(args.rounds):
        for lv in range(len(LEVELS)):
            c0 = time.process_time()
            run_upto(lv, e0, e1, dt, x0, p0, inp, cfg, ws, rec, x, p)
            us[lv].append((time.process_time() - c0) / (e1 - e0) * 1e6)
    print(f"{e1 - e0} epochs from the middle of the drive ({prep.x0.shape[0]} states), "
          f"CPU µs per epoch, {args.rounds} rounds:")
    prev_min = prev_med = 0.0
    for lv, name in enumerate(LEVELS):
        lo, med = min(us[lv]), statistics.median(us[lv])
        print(f"{lv} {name:20s} cumulative min {lo:6.2f} median {med:6.2f} | stage min "
              f"{lo - prev_min:+6.2f} median {med - prev_med:+6.2f}")
        prev_min, prev_med = lo, med


if __name__ == "__main__":
    main()
