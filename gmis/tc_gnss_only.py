"""The tightly coupled GMIKF WITHOUT an IMU: base/rover RINEX only (e.g. the RTKLIB test
session 0759/3040, which has no IMU).

This is the same filter as gmis.tc_filter (TcFilter on a GmikfRunner state) with the IMU
measurement update absent: between GNSS epochs the state is propagated by the GMIKF's
kinematic model alone (001 eq. 4.1.14-4.1.38: position, body velocity, acceleration, jerk
noise; attitude, angular rate, angular-acceleration noise) and at each epoch it is updated
by the double-differenced code / L1 / L2 (and Doppler when the files have it) rows with
in-filter ambiguity resolution (SD ambiguity states, LAMBDA + ratio test, χ² wrong-fix
protection, fix-and-hold; 001 §4.1.3.2 ii, eq. 5.1.7-5.1.11). It validates the DD models,
the ambiguity bookkeeping and the fixing on real data; it does NOT exercise the IMU
model, the attitude (unobservable here: with a zero lever arm no DD row depends on it) or
the sensor biases.

Choices (docs/DESIGN.md "Tightly coupled", no-IMU run):
- ENU frame origin at the base (gmis.earth.make_nav_frame), lever arm zero: the state
  position is the antenna.
- x0: position = the rover's single-point solution at the first epoch
  (gnss.spp.solve_spp_session), everything else zero; P0 1σ: position 10 m, velocity
  10 m/s, acceleration 2 m/s², pitch/roll 0.5 rad, heading π rad, angular rate 0.5 rad/s,
  biases/scale factors 0 (no IMU observes them).
- Process noise: the recipe defaults' per-step jerk / angular-acceleration 1σ at 100 Hz
  (gmis.recipe.NoiseSection, 001 Table 6-2) rescaled to the GNSS epoch spacing at constant
  power spectral density, σ(Δt) = σ(Δt₀)·√(Δt₀/Δt) (a per-step white input held over Δt
  has PSD σ²Δt). At 30 s this still lets the position move by kilometres between epochs:
  kinematic processing, as in RTKLIB's kinematic mode.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gmis.earth import ecef_to_enu, ecef_to_geodetic, enu_to_ecef, make_nav_frame
from gmis.engine_configs import tc_gnss_only_config
from gmis.errors import GmisInputError
from gmis.recipe import NoiseSection
from gmis.run_filter import GmikfConfig
from gmis.run_statistics import fix_refusals
from gmis.state import ACC, ATT, POS, RATE, VEL, W_ANGACC, W_JERK
from gmis.tc_epochs import prepare_tc_epochs
from gmis.tc_filter import TcConfig, run_tightly_coupled
from gnss.constants import SECONDS_PER_WEEK
from gnss.epoch_matching import match_epochs
from gnss.geodesy import ecef_to_geodetic_rows
from gnss.pos_file import write_pos
from gnss.rtk import Q_FIXED, Q_FLOAT, RtkSolution
from gnss.spp import solve_spp_session

IMU_RATE_OF_DEFAULT_NOISE_HZ = 100.0


@dataclass
class TcGnssOnlySolution:
    """Per GNSS epoch (G,): t_gps absolute GPS s; enu (G,3) m in the base-origin frame;
    ecef (G,3) m; llh (G,3) rad/rad/m; sigma_enu (G,3) 1σ m; fixed (G,) bool (a validated
    fix constrains this epoch); ratio; n_sat (satellites used incl. the reference);
    n_fixed (DD ambiguities fixed); fix_rejected (ratio passed, χ² protection rejected)."""
    t_gps: np.ndarray
    enu: np.ndarray
    ecef: np.ndarray
    llh: np.ndarray
    sigma_enu: np.ndarray
    fixed: np.ndarray
    ratio: np.ndarray
    n_sat: np.ndarray
    n_fixed: np.ndarray
    fix_rejected: np.ndarray
    frame: np.ndarray
    tc_records: object
    filter_records: object
    prns: np.ndarray

    @property
    def fix_rate(self) -> float:
        return float(self.fixed.mean()) if self.fixed.size else 0.0


def kinematic_gmikf_config(epoch_spacing_s: float, n_imu: int = 21) -> GmikfConfig:
    """GmikfConfig for a run without IMU rows: per-step kinematic process noise rescaled
    from the default 100 Hz values to epoch_spacing_s at constant PSD (module doc); drift
    noises zero; IMU σ unused; lever arm zero; P0 as in the module doc."""
    if not epoch_spacing_s > 0:
        raise GmisInputError(f"GNSS epoch spacing must be positive, got {epoch_spacing_s}")
    nz = NoiseSection()
    scale = math.sqrt(1.0 / (IMU_RATE_OF_DEFAULT_NOISE_HZ * epoch_spacing_s))
    q = np.zeros(n_imu - 9)
    q[W_JERK] = np.asarray(nz.jerk_sigma_m_s3) * scale
    q[W_ANGACC] = np.asarray(nz.angular_acceleration_sigma_rad_s2) * scale
    p0 = np.zeros(n_imu)
    p0[POS] = 10.0
    p0[VEL] = 10.0
    p0[ACC] = 2.0
    p0[ATT] = (0.5, 0.5, math.pi)
    p0[RATE] = 0.5
    return GmikfConfig(n_imu=n_imu, q_sd=q, imu_sd=np.ones(6), lever_arm=np.zeros(3),
                       p0_sd=p0)


def run_tight_without_imu(rover, base, nav, base_ecef, tc_config: TcConfig | None = None,
                          gmikf_config: GmikfConfig | None = None,
                          hydrostatic_troposphere: bool = True,
                          progress=None) -> TcGnssOnlySolution:
    """Tightly coupled GMIKF on rover/base observations (gnss.rinex.ObsData) and a
    broadcast nav, no IMU (module doc). base_ecef (3,) m. tc_config defaults to
    TcConfig() (elevation mask 15°, ratio 3.0, as RTKLIB's defaults here). Missing
    Doppler (RINEX 2 without D1) just leaves the Doppler group empty.
    hydrostatic_troposphere: correct the SD observations for the modelled rover − base
    hydrostatic delay (gmis.tc.prepare_tc_epochs), as RTKLIB's relative mode does."""
    base_ecef = np.asarray(base_ecef, float)
    if base_ecef.shape != (3,) or not 6.30e6 < np.linalg.norm(base_ecef) < 6.48e6:
        raise GmisInputError("base position: expected an ECEF [x, y, z] near the earth's "
                             "surface (m)")
    week0 = int(rover.week[0])
    offset = week0 * SECONDS_PER_WEEK
    spp = solve_spp_session(rover, nav)
    epochs = prepare_tc_epochs(rover, base, nav, base_ecef, offset,
                               hydrostatic_troposphere=hydrostatic_troposphere, rover_spp=spp)
    if len(epochs) < 2:
        raise GmisInputError(f"only {len(epochs)} epoch(s) with common rover/base satellites "
                             "and ephemerides", source=rover.path)
    g_t = np.array([ep.t for ep in epochs])
    frame = make_nav_frame(*ecef_to_geodetic(*base_ecef))
    cfg = gmikf_config or kinematic_gmikf_config(float(np.median(np.diff(g_t))))
    if np.any(cfg.lever_arm != 0.0):
        raise GmisInputError("the no-IMU tightly coupled run has no attitude information: "
                             "the lever arm must be zero")
    i0 = np.flatnonzero(spp.ok & (spp.t_gps - offset >= g_t[0] - 1e-6))
    if i0.size == 0:
        raise GmisInputError("no rover epoch has a single-point solution for the initial "
                             "position", source=rover.path)
    x0 = np.zeros(cfg.n_imu)
    x0[POS] = ecef_to_enu(frame, spp.position[i0[0]])
    rec, tc_rec, prns = run_tightly_coupled(
        np.empty(0), np.zeros((0, 6)), np.empty(0), np.empty(0), np.empty(0), epochs, x0,
        cfg, tc_config or TcConfig(), frame, progress=progress)
    rows = tc_rec.epoch_index
    enu = rec.x[rows, POS].copy()
    ecef = np.array([enu_to_ecef(frame, r) for r in enu])
    llh = ecef_to_geodetic_rows(ecef)
    return TcGnssOnlySolution(
        t_gps=g_t + offset, enu=enu, ecef=ecef, llh=llh, sigma_enu=rec.sd[rows, POS].copy(),
        fixed=tc_rec.fixed.copy(), ratio=tc_rec.ratio.copy(), n_sat=tc_rec.n_sat.copy(),
        n_fixed=tc_rec.n_fixed.copy(), fix_rejected=tc_rec.fix_rejected.copy(), frame=frame,
        tc_records=tc_rec, filter_records=rec, prns=np.asarray(prns))


def solution_as_rtk(sol: TcGnssOnlySolution):
    """The solution as a gnss.rtk.RtkSolution (Q 1 fixed / 2 float) for write_pos."""
    n = sol.t_gps.size
    return RtkSolution(t_gps=sol.t_gps, ecef=sol.ecef, llh=sol.llh,
                       q=np.where(sol.fixed, Q_FIXED, Q_FLOAT).astype(np.int64),
                       ratio=sol.ratio, n_sat=sol.n_sat, sigma_enu=sol.sigma_enu,
                       ambiguities_fixed=sol.n_fixed, ref_prn=sol.tc_records.ref_prn,
                       integers=[None] * n)


def run_tight_gnss_recipe(recipe_path, results_dir, progress=None,
                          hydrostatic_troposphere: bool = True) -> dict:
    """`gmis rtk --tight`: the no-IMU tightly coupled run of a GNSS-only recipe ([paths]
    rover_obs/base_obs/nav and [base], read by gmis.rtk_job.read_rtk_recipe; its [rtk]
    elevation_mask_deg and ratio_threshold are used). Writes tc.pos (RTKLIB-like), tc.csv
    and summary.json into results_dir atomically (gmis.results.results_directory).
    Returns the summary dict."""
    from gmis.results import results_directory, write_csv, write_json
    from gmis.rtk_job import read_rtk_recipe, rover_in_time_window
    from gnss.rinex import read_nav, read_obs

    recipe_path = Path(recipe_path).expanduser().resolve()
    inp = read_rtk_recipe(recipe_path)
    tc_cfg = tc_gnss_only_config(inp["config"])
    t0 = time.perf_counter()
    base = read_obs(inp["base_obs"])
    rover = rover_in_time_window(read_obs(inp["rover_obs"]), inp["time"], str(recipe_path))
    nav = read_nav(inp["nav"])
    from gmis.plausibility import check_rtk_inputs, solved_epochs
    check_rtk_inputs(base, rover, nav, inp["base_ecef"], str(recipe_path))
    from gnss.rtk import observed_frequencies  # ["L1"]: as an L1-only receiver records
    base, rover = (observed_frequencies(o, inp["config"]) for o in (base, rover))
    doppler = bool(np.isfinite(rover.D1).any() and np.isfinite(base.D1).any())
    sol = run_tight_without_imu(rover, base, nav, inp["base_ecef"], tc_cfg,
                                hydrostatic_troposphere=hydrostatic_troposphere,
                                progress=progress)
    wall = time.perf_counter() - t0
    f = sol.fixed
    summary = {
        "dataset": inp["name"],
        "mode": "tightly coupled GMIKF, IMU ABSENT: kinematic model + DD code/phase updates",
        "imu": "absent (no IMU measurement update; attitude unobserved)",
        "doppler": "used" if doppler else "absent in the files",
        "hydrostatic_troposphere": hydrostatic_troposphere,
        "elevation_mask_deg": tc_cfg.elevation_mask_deg,
        "ratio_threshold": tc_cfg.ratio_threshold,
        "epochs": int(sol.t_gps.size),
        "epochs_fixed": int(f.sum()),
        "fix_rate": sol.fix_rate,
        "fixes_rejected_by_chi2": int(sol.fix_rejected.sum()),
        "fixes_refused": fix_refusals(sol.tc_records),
        "epochs_partial_fixed": int((sol.tc_records.partial & sol.fixed).sum()),
        "in_filter_slip_resets": int(sol.tc_records.slip_resets.sum()),
        "in_filter_slip_repairs": int(sol.tc_records.slip_repairs.sum()),
        "in_filter_reference_changes": int(sol.tc_records.reference_slips.sum()),
        "epochs_fixed_by_wide_lane_cascade": int((sol.tc_records.cascade & sol.fixed).sum()),
        "mean_fixed_enu_m": sol.enu[f].mean(axis=0).tolist() if f.any() else None,
        "std_fixed_enu_mm": (1e3 * sol.enu[f].std(axis=0)).tolist() if f.any() else None,
        "mean_fixed_ecef_m": sol.ecef[f].mean(axis=0).tolist() if f.any() else None,
        "baseline_length_m": float(np.linalg.norm(sol.enu[f].mean(axis=0))) if f.any()
        else None,
        "wall_time_s": wall,
    }
    sol = solved_epochs(sol, np.isfinite(sol.sigma_enu).all(axis=1), "gmis rtk --tight",
                        inp["rover_obs"])
    with results_directory(results_dir) as out:
        write_pos(out / "tc.pos", solution_as_rtk(sol),
                  [f"gmis rtk --tight {recipe_path}",
                   "tightly coupled GMIKF WITHOUT IMU (kinematic model + DD updates)",
                   f"base ECEF {np.round(inp['base_ecef'], 4).tolist()}"])
        write_csv(out / "tc.csv", ["t_gps_s", "e_m", "n_m", "u_m", "x_m", "y_m", "z_m",
                                   "lat_deg", "lon_deg", "h_m", "fixed", "ratio", "n_sat",
                                   "n_fixed", "sigma_e_m", "sigma_n_m", "sigma_u_m"],
                  sol.t_gps, sol.enu, sol.ecef, np.degrees(sol.llh[:, :2]), sol.llh[:, 2],
                  sol.fixed, sol.ratio, sol.n_sat, sol.n_fixed, sol.sigma_enu, fmt="%.12g",
                  allow_nonfinite=("ratio",))  # NaN: no fix attempted at the epoch
        write_json(out / "summary.json", summary)
    return summary


def compare_fixed_epochs(t, enu, fixed, t_ref, enu_ref, fixed_ref,
                         time_tolerance_s: float = 0.5) -> dict:
    """Differences enu − enu_ref (m, same ENU frame) over the epochs fixed in both
    solutions (times in s, matched to the nearest reference epoch within the tolerance):
    n_common, d (k, 3), the median and 95th percentile of |Δ| in 3D, horizontally and
    vertically (m), and the mean Δ ENU (m)."""
    t, t_ref = np.asarray(t, float), np.asarray(t_ref, float)
    if t_ref.size == 0:
        raise GmisInputError("the reference solution has no epochs")
    j = match_epochs(t_ref, t, time_tolerance_s)
    both = (j >= 0) & np.asarray(fixed, bool) & np.asarray(fixed_ref, bool)[j]
    d = np.asarray(enu)[both] - np.asarray(enu_ref)[j[both]]
    out = {"n_common": int(both.sum()), "d": d}
    if d.shape[0] == 0:
        return out
    for name, v in (("3d", np.linalg.norm(d, axis=1)), ("h", np.hypot(d[:, 0], d[:, 1])),
                    ("v", np.abs(d[:, 2]))):
        out[f"median_{name}"] = float(np.median(v))
        out[f"p95_{name}"] = float(np.percentile(v, 95))
    out["mean_enu"] = d.mean(axis=0)
    return out
