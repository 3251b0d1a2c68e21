"""`gmis run`: recipe → dataset → GMIKF → results folder (solution, records, summary).

Python API::

    prep = prepare_run(load_recipe("recipe.toml"))
    records = run_prepared(prep)
    summary = run_recipe("recipe.toml", "results/")

Results folder (written all-or-nothing, see gmis.results):
  solution.csv   time, lat/lon/h, ENU, ENU and body velocity, attitude, biases, scale
                 factors and their 1σ, decimated to at most ``csv_rate_hz`` (default 10 Hz)
  solution.npz   the same quantities at every epoch plus the full state and 1σ
  records.npz    per-epoch innovations, innovation variances, outlier flags (and VCE
                 residuals/redundancies when computed)
  errors.csv     errors against the reference trajectory (when the recipe has one)
  summary.json   configuration, counts, timings and error statistics
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numba import njit

from gmis.alignment import static_alignment
from gmis.earth import ecef_to_enu, ecef_to_geodetic, enu_to_ecef, geodetic_to_ecef, make_nav_frame
from gmis.epochs import EpochIndex, merge_streams
from gmis.errors import GmisInputError
from gmis.frames import dcm_body_to_nav, dcm_body_to_nav_array
from gmis.gmikf import SLOT_NAMES
from gmis.motion import gnss_horizontal_speed, stationary_epochs
from gmis.readers import Dataset, load_dataset
from gmis.recipe import Recipe, load_recipe
from gmis.results import results_directory, write_csv, write_json, write_npz
from gmis.run_filter import FilterRecords, GmikfConfig, Measurements, run_gmikf
from gmis.state import NOISE_NAMES_27, STATE_NAMES_27
from gmis.tc_models import group_names


@njit(cache=True)
def geodetic_to_enu_rows(frame, llh):
    """(K,3) [rad, rad, m] → (K,3) ENU m in the frame."""
    out = np.empty((llh.shape[0], 3))
    for k in range(llh.shape[0]):
        out[k] = ecef_to_enu(frame, geodetic_to_ecef(llh[k, 0], llh[k, 1], llh[k, 2]))
    return out


@njit(cache=True)
def enu_to_geodetic_rows(frame, enu):
    out = np.empty((enu.shape[0], 3))
    for k in range(enu.shape[0]):
        e = enu_to_ecef(frame, enu[k])
        lat, lon, h = ecef_to_geodetic(e[0], e[1], e[2])
        out[k, 0] = lat
        out[k, 1] = lon
        out[k, 2] = h
    return out


def config_from_recipe(recipe: Recipe) -> GmikfConfig:
    """GMIKF configuration (per-step process noise, IMU noise, P0) from the recipe."""
    nz = recipe.noise
    n_imu = recipe.filter.states
    q = [*nz.jerk_sigma_m_s3, *nz.angular_acceleration_sigma_rad_s2,
         *nz.gyro_bias_drift_sigma_rad_s, *nz.accel_bias_drift_sigma_m_s2]
    if n_imu == 27:
        q += [*nz.gyro_scale_drift_sigma, *nz.accel_scale_drift_sigma]
    s = recipe.initial_sigma
    p0 = [*s.position_m, *s.velocity_m_s, *s.acceleration_m_s2, *s.attitude_rad,
          *s.angular_rate_rad_s, *s.gyro_bias_rad_s, *s.accel_bias_m_s2]
    if n_imu == 27:
        p0 += [*s.gyro_scale, *s.accel_scale]
    nhc = recipe.nonholonomic
    nhc_args = {} if nhc is None else {
        "nhc_sd": np.array([nhc.sigma_lateral_m_s, nhc.sigma_vertical_m_s]),
        "nhc_interval_s": 1.0 / nhc.rate_hz, "nhc_lever_arm": np.array(nhc.lever_arm_m)}
    return GmikfConfig(n_imu=n_imu, q_sd=np.array(q), imu_sd=np.array(
        [*nz.gyro_sigma_rad_s, *nz.accel_sigma_m_s2]),
        lever_arm=np.array(recipe.antennas.primary_lever_arm_m), p0_sd=np.array(p0),
        outlier_alpha=recipe.filter.outlier_alpha, consider_scale_imu=True, **nhc_args)


@dataclass
class PreparedRun:
    recipe: Recipe
    dataset: Dataset
    frame: np.ndarray
    epochs: EpochIndex
    meas: Measurements
    x0: np.ndarray
    config: GmikfConfig
    alignment: object
    gnss_removed: int = 0
    stationary: np.ndarray | None = None   # (E,) epochs at rest (gmis.motion)


def _circular_mean(angles):
    return float(np.arctan2(np.sin(angles).mean(), np.cos(angles).mean()) % (2 * np.pi))


def prepare_run(recipe: Recipe, dataset: Dataset | None = None, gnss_outages=()):
    """Read the data, fix the ENU origin, merge the streams, align and build x0.

    gnss_outages: [(start_s, end_s), ...] windows in which GNSS position/velocity AND
    heading are removed (outage experiments)."""
    ds = dataset if dataset is not None else load_dataset(recipe)
    origin = ds.origin_llh()
    if origin is None:
        raise GmisInputError("no ENU origin: give [origin] or [base], or a GNSS solution "
                             "file whose first fix can serve", source=str(recipe.path))
    frame = make_nav_frame(*origin)
    imu = ds.imu
    config = config_from_recipe(recipe)
    removed = 0

    def keep_mask(t):
        nonlocal removed
        keep = np.ones(t.size, bool)
        for a, b in gnss_outages:
            keep &= ~((t >= a) & (t <= b))
        removed += int((~keep).sum())
        return keep

    meas = Measurements(imu_z=np.hstack([imu.gyro, imu.accel]))
    pos_t = vel_t = hdg_t = None
    if ds.gnss is not None:
        k = keep_mask(ds.gnss.t)
        pos_t = ds.gnss.t[k]
        meas.pos_enu = geodetic_to_enu_rows(frame, np.ascontiguousarray(ds.gnss.llh[k]))
        meas.pos_sd = ds.gnss.pos_sigma[k]
        if ds.gnss.vel_enu is not None:
            vel_t = pos_t
            meas.vel_enu = ds.gnss.vel_enu[k]
            meas.vel_sd = ds.gnss.vel_sigma[k]
    if ds.heading is not None:
        k = keep_mask(ds.heading.t)
        hdg_t = ds.heading.t[k]
        meas.heading = ds.heading.heading[k]
        meas.heading_sd = ds.heading.sigma[k]
    tol = min(1e-3, 0.25 / recipe.imu.rate_hz)
    epochs = merge_streams(imu.t, pos_t, vel_t, hdg_t, tolerance_s=tol)

    # ---- initial state from a static start (001 §4.3.1)
    t0 = imu.t[0]
    win = recipe.filter.static_alignment_s
    tight = recipe.filter.mode == "tight"
    raw_init = None
    has_heading = ds.heading is not None and ds.heading.t.size > 0
    has_gnss = ds.gnss is not None and ds.gnss.t.size > 0
    if tight and not (has_heading and has_gnss):
        from gmis.tc import raw_gnss_initialisation
        raw_init = raw_gnss_initialisation(recipe, frame, imu.t, win)
    if has_heading:
        in_win = ds.heading.t <= t0 + max(win, 1.0)
        heading0 = _circular_mean(ds.heading.heading[in_win]) if in_win.any() \
            else float(ds.heading.heading[0])
    elif raw_init is not None and raw_init[0] is not None:
        heading0 = raw_init[0]
    else:
        raise GmisInputError("the dataset has no heading stream: the initial heading needs "
                             "[paths].heading or, in tight mode, [paths].heading_obs "
                             "(dual-antenna heading); initialising from the GNSS course is "
                             "not implemented", source=str(recipe.path))
    al = static_alignment(imu.t, imu.gyro, imu.accel, t0, win, frame[15:18], heading0)
    c_bn = dcm_body_to_nav(al.pitch, al.roll, heading0)
    if has_gnss:
        g_enu = geodetic_to_enu_rows(frame, np.ascontiguousarray(ds.gnss.llh))
        g_win = ds.gnss.t <= t0 + max(win, 1.0)
        ant0 = g_enu[g_win].mean(axis=0) if g_win.any() else g_enu[0]
    elif raw_init is not None:
        ant0 = raw_init[1]
        # a single-point start: metres, not centimetres
        config.p0_sd[0:3] = np.maximum(config.p0_sd[0:3], 3.0)
    else:
        raise GmisInputError("the dataset has no GNSS position solution ([paths]."
                             "gnss_solution): the loosely coupled filter needs one",
                             source=str(recipe.path))
    x0 = np.zeros(config.n_imu)
    x0[0:3] = ant0 - c_bn @ config.lever_arm
    x0[9:12] = (al.pitch, al.roll, heading0)
    x0[15:18] = al.gyro_bias
    if pos_t is not None and pos_t.size:
        speed = gnss_horizontal_speed(pos_t, meas.pos_enu,
                                      meas.vel_enu if vel_t is not None else None)
        still = stationary_epochs(epochs, pos_t, speed)
    else:
        still = np.zeros(len(epochs), dtype=bool)
    return PreparedRun(recipe=recipe, dataset=ds, frame=frame, epochs=epochs, meas=meas,
                       x0=x0, config=config, alignment=al, gnss_removed=removed,
                       stationary=still)


def run_prepared(prep: PreparedRun, config: GmikfConfig | None = None, progress=None,
                 meas: Measurements | None = None):
    return run_gmikf(prep.epochs, meas or prep.meas, prep.x0, config or prep.config,
                     prep.frame, progress=progress, stationary=prep.stationary)


# ----------------------------------------------------------------------------- outputs


def _t_matrix_array(pitch, roll):
    """T of 001 eq. 4.1.29 (attitude error φ in ENU = T δθ), vectorised → (N, 3, 3)."""
    sp, cp, sr, cr = np.sin(pitch), np.cos(pitch), np.sin(roll), np.cos(roll)
    t = np.zeros((pitch.size, 3, 3))
    t[:, 0, 0] = cr
    t[:, 0, 2] = cp * sr
    t[:, 1, 1] = 1.0
    t[:, 1, 2] = -sp
    t[:, 2, 0] = sr
    t[:, 2, 2] = -cp * cr
    return t


def _skew_array(v):
    s = np.zeros((v.shape[0], 3, 3))
    s[:, 0, 1], s[:, 0, 2] = -v[:, 2], v[:, 1]
    s[:, 1, 0], s[:, 1, 2] = v[:, 2], -v[:, 0]
    s[:, 2, 0], s[:, 2, 1] = -v[:, 1], v[:, 0]
    return s


def navigation_solution(prep: PreparedRun, rec: FilterRecords):
    """Per-epoch navigation quantities with 1σ (dict of arrays, SI/rad). ENU velocity
    covariance by eq. 4.1.31: C cov(v^b) Cᵀ + [v^n×] T cov(θ) Tᵀ [v^n×]ᵀ."""
    x, sd = rec.x, rec.sd
    enu = x[:, 0:3]
    llh = enu_to_geodetic_rows(prep.frame, np.ascontiguousarray(enu))
    c = dcm_body_to_nav_array(x[:, 9:12])
    v_n = np.einsum("kij,kj->ki", c, x[:, 3:6])
    tm = _skew_array(v_n) @ _t_matrix_array(x[:, 9], x[:, 10])
    cov = (c @ rec.cov_blocks[:, 1] @ np.transpose(c, (0, 2, 1))
           + tm @ rec.cov_blocks[:, 2] @ np.transpose(tm, (0, 2, 1)))
    v_n_sd = np.sqrt(np.maximum(np.diagonal(cov, axis1=1, axis2=2), 0.0))
    return dict(t=rec.t, llh=llh, enu=enu, enu_sd=sd[:, 0:3], vel_enu=v_n, vel_enu_sd=v_n_sd,
                vel_body=x[:, 3:6], vel_body_sd=sd[:, 3:6], euler=x[:, 9:12],
                euler_sd=sd[:, 9:12], x=x, sd=sd)


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def reference_errors(prep: PreparedRun, rec: FilterRecords, nav):
    """Errors of the solution against the reference at the IMU epochs inside its span:
    ENU position (m), ENU velocity (m/s), attitude (rad), and NEES of r^n, v^b, θ."""
    ref = prep.dataset.reference
    if ref is None:
        return None
    t = rec.t
    inside = (t >= ref.t[0]) & (t <= ref.t[-1]) & (rec.imu_row >= 0)
    idx = np.nonzero(inside)[0]
    ref_enu = geodetic_to_enu_rows(prep.frame, np.ascontiguousarray(ref.llh))
    interp = lambda a: np.column_stack([np.interp(t[idx], ref.t, a[:, i])
                                        for i in range(a.shape[1])])
    r_true = interp(ref_enu)
    v_true = interp(ref.vel_enu)
    unwrapped = np.unwrap(ref.euler, axis=0)
    th_true = interp(unwrapped)
    d_pos = nav["enu"][idx] - r_true
    d_vel = nav["vel_enu"][idx] - v_true
    d_att = _wrap(nav["euler"][idx] - th_true)
    # NEES on the filter's own state blocks
    vb_true = np.einsum("kji,kj->ki", dcm_body_to_nav_array(th_true), v_true)
    d_vb = rec.x[idx, 3:6] - vb_true
    nees = {}
    for name, err, b in (("position", d_pos, 0), ("velocity_body", d_vb, 1),
                         ("attitude", d_att, 2)):
        cov = rec.cov_blocks[idx, b]
        nees[name] = np.einsum("ki,ki->k", err, np.linalg.solve(cov, err[..., None])[..., 0])
    return dict(t=t[idx], idx=idx, pos=d_pos, vel=d_vel, att=d_att, nees=nees)


def error_statistics(err: np.ndarray, names, scale=1.0, unit=""):
    stats = {}
    for i, name in enumerate(names):
        e = np.abs(err[:, i]) * scale
        stats[name] = {"rms": float(np.sqrt(np.mean((err[:, i] * scale) ** 2))),
                       "p95": float(np.percentile(e, 95)), "max": float(e.max()),
                       "unit": unit}
    return stats


def seconds_since_last_fix(t, has_fix):
    """Per epoch: time (s) since the latest epoch with GNSS position information
    (inf before the first)."""
    last = np.maximum.accumulate(np.where(has_fix, t, -np.inf))
    return t - last


def summarize_errors(errs, skip_s: float = 0.0, keep=None):
    """RMS / 95 % / max per axis after skipping the first skip_s seconds (and only where
    ``keep`` is True, when given)."""
    keep = (errs["t"] >= errs["t"][0] + skip_s) & (True if keep is None else keep)
    if not np.any(keep):
        return {"epochs_compared": 0,
                "note": f"no reference epochs after the first {skip_s:g} s (static alignment)"}
    out = {
        "position": error_statistics(errs["pos"][keep], ["e", "n", "u"], 1.0, "m"),
        "velocity": error_statistics(errs["vel"][keep], ["e", "n", "u"], 1.0, "m/s"),
        "attitude": error_statistics(errs["att"][keep], ["pitch", "roll", "heading"],
                                     180 / math.pi, "deg"),
        "nees_mean": {k: float(v[keep].mean()) for k, v in errs["nees"].items()},
        "epochs_compared": int(keep.sum()),
    }
    return out


def write_solution(folder: Path, prep: PreparedRun, rec: FilterRecords, nav,
                   csv_rate_hz: float = 10.0):
    n = prep.config.n_imu
    deg = 180 / math.pi
    write_npz(folder / "solution.npz", t=rec.t, llh=nav["llh"], enu=nav["enu"],
              enu_sd=nav["enu_sd"], vel_enu=nav["vel_enu"], vel_enu_sd=nav["vel_enu_sd"],
              vel_body=nav["vel_body"], vel_body_sd=nav["vel_body_sd"], euler=nav["euler"],
              euler_sd=nav["euler_sd"], x=rec.x[:, :n], sd=rec.sd[:, :n],
              state_names=np.array(STATE_NAMES_27[:n]), frame=prep.frame)
    write_npz(folder / "records.npz", t=rec.t, imu_row=rec.imu_row, innov=rec.innov,
              innov_var=rec.innov_var, rejected=rec.rejected, nobs=rec.nobs, vz=rec.vz,
              rz=rec.rz, vw=rec.vw, rw=rec.rw, slot_names=np.array(SLOT_NAMES),
              noise_names=np.array(NOISE_NAMES_27[:n - 9]))
    # decimated CSV
    step = max(1, int(round(prep.recipe.imu.rate_hz / csv_rate_hz))) if csv_rate_hz else 1
    rows = np.nonzero(rec.imu_row >= 0)[0][::step]
    header = ["time_gps_s", "lat_deg", "lon_deg", "h_m", "e_m", "n_m", "u_m",
              "ve_m_s", "vn_m_s", "vu_m_s", "vx_m_s", "vy_m_s", "vz_m_s",
              "pitch_deg", "roll_deg", "heading_deg",
              "bgx_deg_s", "bgy_deg_s", "bgz_deg_s", "bax_m_s2", "bay_m_s2", "baz_m_s2"]
    cols = [rec.t[rows], nav["llh"][rows, :2] * deg, nav["llh"][rows, 2], nav["enu"][rows],
            nav["vel_enu"][rows], nav["vel_body"][rows], nav["euler"][rows] * deg,
            rec.x[rows, 15:18] * deg, rec.x[rows, 18:21]]
    sd_header = ["sd_e_m", "sd_n_m", "sd_u_m", "sd_ve_m_s", "sd_vn_m_s", "sd_vu_m_s",
                 "sd_pitch_deg", "sd_roll_deg", "sd_heading_deg", "sd_bgx_deg_s",
                 "sd_bgy_deg_s", "sd_bgz_deg_s", "sd_bax_m_s2", "sd_bay_m_s2", "sd_baz_m_s2"]
    sd_cols = [nav["enu_sd"][rows], nav["vel_enu_sd"][rows], nav["euler_sd"][rows] * deg,
               rec.sd[rows, 15:18] * deg, rec.sd[rows, 18:21]]
    if n == 27:
        header += ["sgx", "sgy", "sgz", "sax", "say", "saz"]
        cols.append(rec.x[rows, 21:27])
        sd_header += ["sd_sgx", "sd_sgy", "sd_sgz", "sd_sax", "sd_say", "sd_saz"]
        sd_cols.append(rec.sd[rows, 21:27])
    write_csv(folder / "solution.csv", header + sd_header, *cols, *sd_cols)


def rejected_counts(rec: FilterRecords):
    return {name: int(rec.rejected[:, i].sum()) for i, name in enumerate(SLOT_NAMES)}


def dd_residual_arrays(tc_rec):
    """Standardized DD residuals of every used observation (for per-group and
    per-satellite histograms): GNSS epoch, group (0 code, 1 L1, 2 L2, 3 Doppler or
    TDCP), PRN,
    v/σ_v."""
    if not tc_rec.residuals:
        z = np.zeros(0)
        return {"dd_residual_epoch": z.astype(np.int64), "dd_residual_group": z.astype(np.int64),
                "dd_residual_prn": z.astype(np.int64), "dd_residual_std": z}
    g = np.concatenate([np.full(k.size, e) for e, k, _, _ in tc_rec.residuals])
    return {"dd_residual_epoch": g.astype(np.int64),
            "dd_residual_group": np.concatenate([k for _, k, _, _ in tc_rec.residuals]),
            "dd_residual_prn": np.concatenate([p for _, _, p, _ in tc_rec.residuals]),
            "dd_residual_std": np.concatenate([w for _, _, _, w in tc_rec.residuals])}


def fixed_integer_table(tc_rec):
    """(K, 5) rows [GNSS epoch, reference PRN, PRN, frequency, DD integer] of every
    validated fix (cycles)."""
    rows = []
    for g, ints in zip(np.flatnonzero(tc_rec.fixed), tc_rec.integers):
        rows += [(g, tc_rec.ref_prn[g], prn, f, v) for (prn, f), v in sorted(ints.items())]
    return np.array(rows, dtype=np.int64).reshape(-1, 5)


def tc_summary(tc_rec, info):
    """Key figures of a tightly coupled run (fix rate, satellites, outliers, σ̂²_0 per
    observable group = Σ vᵀR⁻¹v / Σ r over the run)."""
    names = group_names(info.get("velocity_observable", "doppler"))
    solved = tc_rec.n_sat >= 2
    out = dict(info)
    out.update({
        "fix_rate": float(tc_rec.fixed[solved].mean()) if solved.any() else 0.0,
        "fixes_rejected_by_chi2": int(tc_rec.fix_rejected.sum()),
        "satellites_median": float(np.median(tc_rec.n_sat[solved])) if solved.any() else 0,
        "satellites_min": int(tc_rec.n_sat[solved].min()) if solved.any() else 0,
        "rejected_observations": {n: int(v) for n, v in zip(names, tc_rec.rejected_obs.sum(0))},
        "sigma0_sq": {n: (float(q / r) if r > 0 else None) for n, q, r in
                      zip(names, tc_rec.vpv.sum(0), tc_rec.redundancy.sum(0))},
        "mean_redundancy": {n: (float(r / k) if k else None) for n, r, k in
                            zip(names, tc_rec.redundancy.sum(0), tc_rec.n_obs.sum(0))},
    })
    return out


def run_recipe(recipe_path, results_dir, progress=None, gnss_outages=(),
               csv_rate_hz: float = 10.0) -> dict:
    """Run the GMIKF on a recipe and write the results folder; returns the summary."""
    t_start = time.perf_counter()
    recipe = load_recipe(recipe_path)
    prep = prepare_run(recipe, gnss_outages=gnss_outages)
    t_read = time.perf_counter()
    tc_rec = None
    if recipe.filter.mode == "tight":
        from gmis.tc import run_tight
        rec, tc_rec, tc_info = run_tight(prep, progress=progress)
        gnss_fix = np.zeros(rec.t.size, bool)
        gnss_fix[tc_rec.epoch_index[tc_rec.n_sat >= 5]] = True
    else:
        rec = run_prepared(prep, progress=progress)
        gnss_fix = prep.epochs.pos >= 0
    t_filter = time.perf_counter()
    nav = navigation_solution(prep, rec)
    errs = reference_errors(prep, rec, nav)
    n_imu = int((rec.imu_row >= 0).sum())
    duration = float(prep.dataset.imu.t[-1] - prep.dataset.imu.t[0])
    summary = {
        "recipe": str(recipe.path),
        "dataset": recipe.dataset.name,
        "mode": recipe.filter.mode,
        "states": recipe.filter.states,
        "origin_lat_lon_h": [math.degrees(prep.frame[0]), math.degrees(prep.frame[1]),
                             float(prep.frame[2])],
        "epochs": len(prep.epochs),
        "imu_epochs": n_imu,
        "duration_s": duration,
        "alignment": {"pitch_deg": math.degrees(prep.alignment.pitch),
                      "roll_deg": math.degrees(prep.alignment.roll),
                      "heading_deg": math.degrees(prep.x0[11]) % 360.0,
                      "gyro_bias_deg_s": np.degrees(prep.alignment.gyro_bias).tolist(),
                      "samples": prep.alignment.n_samples},
        "rejected_observations": rejected_counts(rec),
        "stationary_epochs": int(prep.stationary.sum()),
        "gnss_samples_removed_by_outages": prep.gnss_removed,
        "timing_s": {"read_and_prepare": t_read - t_start, "filter": t_filter - t_read,
                     "imu_epochs_per_s": n_imu / max(t_filter - t_read, 1e-9),
                     "real_time_ratio": duration / max(t_filter - t_read, 1e-9)},
        "warnings": list(prep.dataset.warnings),
    }
    if errs is not None and errs["t"].size:
        skip = recipe.filter.static_alignment_s
        summary["errors_vs_reference"] = summarize_errors(errs, skip_s=skip)
        aided = seconds_since_last_fix(rec.t, gnss_fix)[errs["idx"]] <= 1.0
        summary["errors_vs_reference_gnss_aided"] = summarize_errors(errs, skip, aided)
        summary["errors_vs_reference_gnss_aided"]["definition"] = (
            "epochs at most 1 s after a GNSS position update (outages excluded)" if tc_rec is None
            else "epochs at most 1 s after a DD update with ≥ 5 satellites")
    if tc_rec is not None:
        summary["tightly_coupled"] = tc_summary(tc_rec, tc_info)
    with results_directory(results_dir) as folder:
        write_solution(folder, prep, rec, nav, csv_rate_hz)
        if tc_rec is not None:
            write_npz(folder / "tc_records.npz", t=tc_rec.t, epoch_index=tc_rec.epoch_index,
                      n_sat=tc_rec.n_sat, ref_prn=tc_rec.ref_prn, fixed=tc_rec.fixed,
                      ratio=tc_rec.ratio, n_fixed=tc_rec.n_fixed,
                      fix_rejected=tc_rec.fix_rejected, rejected_obs=tc_rec.rejected_obs,
                      vpv=tc_rec.vpv, redundancy=tc_rec.redundancy, n_obs=tc_rec.n_obs,
                      fixed_integers=fixed_integer_table(tc_rec),
                      **dd_residual_arrays(tc_rec),
                      group_names=np.array(group_names(
                          tc_info.get("velocity_observable", "doppler"))))
        if errs is not None and errs["t"].size:
            deg = 180 / math.pi
            write_csv(folder / "errors.csv",
                      ["time_gps_s", "de_m", "dn_m", "du_m", "dve_m_s", "dvn_m_s", "dvu_m_s",
                       "dpitch_deg", "droll_deg", "dheading_deg", "nees_position",
                       "nees_velocity_body", "nees_attitude"],
                      errs["t"], errs["pos"], errs["vel"], errs["att"] * deg,
                      errs["nees"]["position"], errs["nees"]["velocity_body"],
                      errs["nees"]["attitude"])
        summary["timing_s"]["total"] = time.perf_counter() - t_start
        write_json(folder / "summary.json", summary)
    summary["results_dir"] = str(Path(results_dir).resolve())
    return summary


__all__ = [
    "PreparedRun",
    "config_from_recipe",
    "navigation_solution",
    "prepare_run",
    "reference_errors",
    "replace",
    "run_prepared",
    "run_recipe",
    "summarize_errors",
]
