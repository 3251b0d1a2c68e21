"""Tightly coupled runs of a recipe: the glue between a prepared recipe and the filter.

The filter is gmis.tc_filter (TcFilter, run_tightly_coupled), its GNSS epochs come from
gmis.tc_epochs (prepare_tc_epochs). This module reads the run's raw GNSS inputs once
(RawGnss: rover/base/heading RINEX, nav, the rover's single-point solution and the
dual-antenna heading solution), derives the initial heading/position from them when the
dataset has no GNSS-solution or heading file, and builds the iteration-invariant
TightInputs a run (or every VCE iteration) uses. Design: docs/DESIGN.md "Tightly coupled".
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from gmis.earth import ecef_to_enu
from gmis.engine_configs import rtk_config
from gmis.errors import GmisInputError
from gmis.motion import gnss_horizontal_speed, stationary_epochs
from gmis.tc_epochs import prepare_tc_epochs
from gmis.tc_filter import TcConfig, run_tightly_coupled
from gnss.constants import SECONDS_PER_WEEK
from gnss.heading import HeadingSolution, dual_antenna_heading
from gnss.rinex import NavData, ObsData, read_nav, read_obs
from gnss.spp import SppSession, solve_spp_session


@dataclass
class RawGnss:
    """A run's raw GNSS inputs, read and solved once: rover/base (and heading-antenna)
    observations, the broadcast nav, the rover's single-point solution (the approximate
    position of prepare_tc_epochs, the initial position and the primary antenna of the
    heading solution) and the dual-antenna heading solution (None without heading_obs or
    a secondary lever arm)."""
    rover: ObsData
    base: ObsData
    nav: NavData
    heading_obs: ObsData | None
    rover_spp: SppSession
    heading: HeadingSolution | None


def read_raw_gnss(recipe) -> RawGnss:
    """Read the recipe's rover, base (and heading) observations and the nav file, solve the
    rover's single-point positions and the dual-antenna heading (RawGnss)."""
    paths = recipe.paths
    missing = [k for k in ("rover_obs", "base_obs", "nav") if getattr(paths, k) is None]
    if missing or recipe.base is None:
        what = ", ".join(f"[paths].{k}" for k in missing) + (", [base]" if recipe.base is None
                                                              else "")
        raise GmisInputError(f"filter.mode = \"tight\" needs {what.strip(', ')}",
                             source=str(recipe.path))
    rover = read_obs(paths.rover_obs)
    base = read_obs(paths.base_obs)
    nav = read_nav(paths.nav)
    heading_obs = read_obs(paths.heading_obs) if paths.heading_obs is not None else None
    rover_spp = solve_spp_session(rover, nav)
    heading = None
    if heading_obs is not None and recipe.antennas.secondary_lever_arm_m is not None:
        heading = dual_antenna_heading(rover, heading_obs, nav,
                                       recipe.antennas.primary_lever_arm_m,
                                       recipe.antennas.secondary_lever_arm_m,
                                       config=rtk_config(recipe),   # [rtk]: e.g. ["L1"]
                                       primary_spp=rover_spp)
    return RawGnss(rover, base, nav, heading_obs, rover_spp, heading)


def gnss_time_offset(recipe, imu_t, rover) -> float:
    """Seconds to subtract from RINEX absolute GPS time to reach the dataset's time base:
    0 when the IMU file already uses absolute GPS seconds, else week·604800 ([time].gps_week
    or the rover file's first week)."""
    if imu_t[0] > 2 * SECONDS_PER_WEEK:
        return 0.0
    week = recipe.time.gps_week if recipe.time.gps_week is not None else int(rover.week[0])
    return week * SECONDS_PER_WEEK


def raw_gnss_initialisation(raw: RawGnss, recipe, frame, imu_t, window_s):
    """Initial heading (rad, circular mean of fixed dual-antenna epochs in the window, or
    None) and primary-antenna ENU position (m, mean single-point solution in the window)
    for a tightly coupled recipe without GNSS-solution / heading files."""
    offset = gnss_time_offset(recipe, imu_t, raw.rover)
    t_end = imu_t[0] + max(window_s, 1.0)
    heading0 = None
    hs = raw.heading
    if hs is not None:
        sel = (hs.q == 1) & (hs.t_gps - offset <= t_end) & np.isfinite(hs.heading)
        if not sel.any():
            sel = (hs.q == 1) & np.isfinite(hs.heading)
        if sel.any():
            heading0 = float(np.arctan2(np.sin(hs.heading[sel]).mean(),
                                        np.cos(hs.heading[sel]).mean()) % (2 * np.pi))
    spp = raw.rover_spp
    sel = spp.ok & (spp.t_gps - offset <= t_end)
    if not sel.any():
        sel = spp.ok
    if not sel.any():
        raise GmisInputError("no rover epoch has a single-point solution for the initial "
                             "position", source=raw.rover.path)
    ant0 = ecef_to_enu(frame, spp.position[sel].mean(axis=0))
    return heading0, ant0


@dataclass
class TightInputs:
    """Iteration-invariant inputs of a tightly coupled run (for VCE iterations)."""
    epochs: list
    heading_t: np.ndarray
    heading: np.ndarray
    heading_sd: np.ndarray
    stationary_fn: object
    config: TcConfig
    info: dict
    # (3,) m body: L_secondary − L_primary when the heading stream is gnss.heading's
    # level-vehicle conversion (the GMIKF's attitude-aware heading row), else None
    heading_baseline: np.ndarray | None = None


def prepare_tight(prep, raw: RawGnss | None = None) -> TightInputs:
    """Form the DD epoch inputs and the heading stream of a prepared recipe from its raw
    GNSS inputs (raw, else prep.raw_gnss when the preparation read them, else read here):
    dual-antenna RINEX (gnss.heading, fixed epochs) when [paths].heading_obs is given, else
    the heading file. TcConfig from the recipe's [noise] (σ90 of code, phase, Doppler, TDCP)
    and [filter].tc_velocity_observable; the rover − base hydrostatic troposphere is removed
    from the single differences unless [filter].tc_troposphere = "none"."""
    recipe = prep.recipe
    raw = raw or getattr(prep, "raw_gnss", None) or read_raw_gnss(recipe)
    imu = prep.dataset.imu
    offset = gnss_time_offset(recipe, imu.t, raw.rover)
    epochs_tc = prepare_tc_epochs(
        raw.rover, raw.base, raw.nav, recipe.base.ecef_m, offset, (imu.t[0], imu.t[-1]),
        hydrostatic_troposphere=recipe.filter.tc_troposphere == "hydrostatic",
        rover_spp=raw.rover_spp)
    cfg = prep.tc_config()
    info = {"gnss_epochs": len(epochs_tc), "time_offset_s": offset,
            "velocity_observable": cfg.velocity_observable,
            "troposphere": recipe.filter.tc_troposphere}
    h_t, h, h_sd, source = _heading_stream(raw, prep.dataset, offset)
    info.update(source)
    in_span = (h_t >= imu.t[0]) & (h_t <= imu.t[-1])
    baseline = None
    if raw.heading is not None:
        baseline = np.asarray(recipe.antennas.secondary_lever_arm_m, float) - \
            np.asarray(recipe.antennas.primary_lever_arm_m, float)
    return TightInputs(epochs_tc, h_t[in_span], h[in_span], h_sd[in_span],
                       _stationary_fn(prep), cfg, info, baseline)


def _heading_stream(raw: RawGnss, dataset, offset):
    """(t, heading rad, σ rad, info) of the heading measurements: the fixed epochs of the
    dual-antenna solution, else the dataset's heading file, else none."""
    hs = raw.heading
    if hs is not None:
        ok = (hs.q == 1) & np.isfinite(hs.heading)
        return (np.round(hs.t_gps[ok] - offset, 6), hs.heading[ok], hs.sigma_heading[ok],
                {"heading_source": "dual-antenna RINEX (gnss.heading)",
                 "heading_fix_rate": hs.fix_rate})
    if dataset.heading is not None:
        return (dataset.heading.t, dataset.heading.heading, dataset.heading.sigma,
                {"heading_source": "heading file"})
    empty = np.zeros(0)
    return empty, empty, empty, {"heading_source": "none"}


def _stationary_fn(prep):
    """epochs → (E,) bool at rest from the GNSS-solution speed (gmis.motion), or None."""
    def still(epochs):
        if prep.meas.pos_enu.size == 0:
            return None
        t_pos = prep.epochs.t[prep.epochs.pos >= 0]
        speed = gnss_horizontal_speed(t_pos, prep.meas.pos_enu,
                                      prep.meas.vel_enu if prep.meas.vel_enu.size else None)
        return stationary_epochs(epochs, t_pos, speed,
                                 imu=(prep.dataset.imu.t, prep.dataset.imu.gyro))
    return still


def run_tight(prep, progress=None, inputs: TightInputs | None = None, gmikf_config=None,
              tc_config: TcConfig | None = None, heading_scale: float = 1.0):
    """Tightly coupled run of a prepared recipe. Returns (FilterRecords, TcRecords, info)."""
    inp = inputs or prepare_tight(prep)
    imu = prep.dataset.imu
    config = gmikf_config or prep.config
    if inp.heading_baseline is not None:     # ψ_b − α of gnss.heading: attitude-aware row
        config = dataclasses.replace(config, heading_baseline=inp.heading_baseline)
    rec, tc_rec, prns = run_tightly_coupled(
        imu.t, np.hstack([imu.gyro, imu.accel]), inp.heading_t, inp.heading,
        inp.heading_sd * heading_scale, inp.epochs, prep.x0, config,
        tc_config or inp.config, prep.frame, stationary_fn=inp.stationary_fn,
        progress=progress)
    info = dict(inp.info)
    info["prns"] = [int(p) for p in prns]
    return rec, tc_rec, info


__all__ = [
    "RawGnss",
    "TcConfig",
    "TightInputs",
    "gnss_time_offset",
    "prepare_tight",
    "raw_gnss_initialisation",
    "read_raw_gnss",
    "run_tight",
]
