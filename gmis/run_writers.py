"""Writers of a `gmis run` results folder (docs/formats.md): solution.npz/.csv,
records.npz, tc_records.npz (tightly coupled) and errors.csv (with a reference)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from gmis.gmikf import SLOT_NAMES
from gmis.results import write_csv, write_npz
from gmis.run_filter import FilterRecords
from gmis.solution_antenna import antenna_solution, write_solution_pos
from gmis.state import BA, BG, NOISE_NAMES_27, SA, SG, STATE_NAMES_27
from gmis.tc_models import group_names

RAD_TO_DEG = 180 / math.pi        # rad → deg
SCALE_FACTORS = slice(SG.start, SA.stop)


def write_solution(folder: Path, prep, rec: FilterRecords, nav, csv_rate_hz: float = 10.0):
    """solution.npz (every epoch, full state and 1σ), records.npz (innovations, outlier
    flags, VCE terms) and solution.csv decimated to at most csv_rate_hz."""
    n = prep.config.n_imu
    enu_ant, llh_ant = antenna_solution(prep, rec.t, nav["enu"], nav["euler"])
    write_npz(folder / "solution.npz", t=rec.t, llh=nav["llh"], enu=nav["enu"],
              llh_antenna=llh_ant, enu_antenna=enu_ant,
              enu_sd=nav["enu_sd"], vel_enu=nav["vel_enu"], vel_enu_sd=nav["vel_enu_sd"],
              vel_body=nav["vel_body"], vel_body_sd=nav["vel_body_sd"], euler=nav["euler"],
              euler_sd=nav["euler_sd"], x=rec.x[:, :n], sd=rec.sd[:, :n],
              state_names=np.array(STATE_NAMES_27[:n]), frame=prep.frame)
    write_npz(folder / "records.npz", t=rec.t, imu_row=rec.imu_row, innov=rec.innov,
              innov_var=rec.innov_var, rejected=rec.rejected, nobs=rec.nobs, vz=rec.vz,
              rz=rec.rz, vw=rec.vw, rw=rec.rw, slot_names=np.array(SLOT_NAMES),
              noise_names=np.array(NOISE_NAMES_27[:n - 9]))
    step = max(1, round(prep.recipe.imu.rate_hz / csv_rate_hz)) if csv_rate_hz else 1
    rows = np.nonzero(rec.imu_row >= 0)[0][::step]
    header = ["time_gps_s", "lat_deg", "lon_deg", "h_m", "e_m", "n_m", "u_m",
              "ve_m_s", "vn_m_s", "vu_m_s", "vx_m_s", "vy_m_s", "vz_m_s",
              "pitch_deg", "roll_deg", "heading_deg",
              "bgx_deg_s", "bgy_deg_s", "bgz_deg_s", "bax_m_s2", "bay_m_s2", "baz_m_s2"]
    cols = [rec.t[rows], nav["llh"][rows, :2] * RAD_TO_DEG, nav["llh"][rows, 2], nav["enu"][rows],
            nav["vel_enu"][rows], nav["vel_body"][rows], nav["euler"][rows] * RAD_TO_DEG,
            rec.x[rows, BG] * RAD_TO_DEG, rec.x[rows, BA]]
    sd_header = ["sd_e_m", "sd_n_m", "sd_u_m", "sd_ve_m_s", "sd_vn_m_s", "sd_vu_m_s",
                 "sd_pitch_deg", "sd_roll_deg", "sd_heading_deg", "sd_bgx_deg_s",
                 "sd_bgy_deg_s", "sd_bgz_deg_s", "sd_bax_m_s2", "sd_bay_m_s2", "sd_baz_m_s2"]
    sd_cols = [nav["enu_sd"][rows], nav["vel_enu_sd"][rows], nav["euler_sd"][rows] * RAD_TO_DEG,
               rec.sd[rows, BG] * RAD_TO_DEG, rec.sd[rows, BA]]
    if n == 27:
        header += ["sgx", "sgy", "sgz", "sax", "say", "saz"]
        cols.append(rec.x[rows, SCALE_FACTORS])
        sd_header += ["sd_sgx", "sd_sgy", "sd_sgz", "sd_sax", "sd_say", "sd_saz"]
        sd_cols.append(rec.sd[rows, SCALE_FACTORS])
    write_csv(folder / "solution.csv", header + sd_header, *cols, *sd_cols)
    gnss = prep.dataset.gnss
    week = prep.recipe.time.gps_week if prep.recipe.time.gps_week is not None \
        else getattr(gnss, "gps_week", None)
    if week is not None:  # solution.pos needs calendar time
        title = (f"gmis {prep.recipe.dataset.name}: primary antenna, Q from the filter's "
                 "1-sigma (gmis.solution_antenna)")
        write_solution_pos(folder / "solution.pos", rec.t[rows], week, llh_ant[rows],
                           nav["enu_sd"][rows], gnss, [title])


def dd_residual_arrays(tc_rec):
    """Standardized DD residuals of every used observation (for per-group and
    per-satellite histograms): GNSS epoch, group (0 code, 1 L1, 2 L2, 3 Doppler or
    TDCP), PRN, v/σ_v."""
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


def write_tc_records(folder: Path, tc_rec, tc_info):
    """tc_records.npz: per-GNSS-epoch records of the tightly coupled filter."""
    write_npz(folder / "tc_records.npz", t=tc_rec.t, epoch_index=tc_rec.epoch_index,
              n_sat=tc_rec.n_sat, ref_prn=tc_rec.ref_prn, fixed=tc_rec.fixed,
              ratio=tc_rec.ratio, n_fixed=tc_rec.n_fixed,
              fix_rejected=tc_rec.fix_rejected, rejected_obs=tc_rec.rejected_obs,
              vpv=tc_rec.vpv, redundancy=tc_rec.redundancy, n_obs=tc_rec.n_obs,
              fixed_integers=fixed_integer_table(tc_rec),
              **dd_residual_arrays(tc_rec),
              group_names=np.array(group_names(
                  tc_info.get("velocity_observable", "doppler"))))


def write_errors_csv(folder: Path, errs):
    """errors.csv: solution − reference per compared epoch (m, m/s, deg) and NEES."""
    write_csv(folder / "errors.csv",
              ["time_gps_s", "de_m", "dn_m", "du_m", "dve_m_s", "dvn_m_s", "dvu_m_s",
               "dpitch_deg", "droll_deg", "dheading_deg", "nees_position",
               "nees_velocity_body", "nees_attitude"],
              errs["t"], errs["pos"], errs["vel"], errs["att"] * RAD_TO_DEG,
              errs["nees"]["position"], errs["nees"]["velocity_body"],
              errs["nees"]["attitude"])


__all__ = ["dd_residual_arrays", "fixed_integer_table", "write_errors_csv",
           "write_solution", "write_tc_records"]
