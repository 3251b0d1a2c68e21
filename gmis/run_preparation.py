"""Preparation of a `gmis run`: recipe → dataset → ENU origin, merged epoch streams,
static alignment (001 §4.3.1), initial state x0 and the engine configs.

    prep = prepare_run(load_recipe("recipe.toml"))
    records = run_prepared(prep)
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from gmis.alignment import StaticAlignment, static_alignment
from gmis.earth import earth_rate_nav, make_nav_frame
from gmis.engine_configs import errins_config, gmikf_config, tc_config
from gmis.enu_rows import geodetic_to_enu_rows
from gmis.epochs import EpochIndex, merge_streams
from gmis.errors import GmisInputError
from gmis.frames import dcm_body_to_nav
from gmis.imu_noise_floor import imu_noise_floor
from gmis.motion import first_motion, gnss_horizontal_speed, stationary_epochs
from gmis.readers import Dataset, load_dataset
from gmis.recipe import Recipe
from gmis.run_filter import GmikfConfig, Measurements, run_gmikf
from gmis.state import ACC, ATT, BA, BG, ERR_PHI, ERR_R, ERR_V, POS, RATE, VEL


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
    outage_windows: tuple = ()  # ((start_s, end_s), ...) GNSS withheld (GPS s)
    stationary: np.ndarray | None = None   # (E,) epochs at rest (gmis.motion)
    raw_gnss: object = None   # gmis.tc.RawGnss when the preparation read it (tight mode)
    in_motion: object = None  # gmis.motion_initialisation.InMotionStart of a moving start
    # gmis.latency_estimation.TimeOffsetEstimate when [gnss].estimate_time_offset
    gnss_time_offset: object = None
    # gmis.nhc_offset_estimation.NhcOffsetEstimate when [nonholonomic].estimate_lever_arm
    nhc_offset: object = None
    # gmis.gnss_velocity_lag.VelocityLagEstimate when [gnss].estimate_velocity_time_offset
    gnss_velocity_lag: object = None

    def tc_config(self):
        """TcConfig of the tightly coupled filter (gmis.engine_configs.tc_config)."""
        return tc_config(self.recipe)

    def errins_config(self):
        """ErrInsConfig of the error-state EKF (gmis.engine_configs.errins_config), with
        the IMU σ the GMIKF uses (after the static-window floor, gmis.imu_noise_floor);
        after a moving start its initial σ of r, v, φ are those of the in-motion start."""
        config = replace(errins_config(self.recipe),
                         imu_sd=np.array(self.config.imu_sd, dtype=float))
        start = self.in_motion
        if start is None:
            return config
        p0 = np.array(config.p0_sd, float)
        p0[ERR_R] = start.pos_sd
        p0[ERR_V] = np.max(start.vel_sd)
        p0[ERR_PHI] = (start.att_sd[0], start.att_sd[1], start.att_sd[2])
        return replace(config, p0_sd=p0)


def release_prepared_inputs(prep: PreparedRun) -> None:
    """After the preparation, what a streamed run no longer needs of the dataset: the
    reference (the outputs read it into their own spool), the heading stream and the
    GNSS positions / velocities (prep.meas holds them in ENU). The GNSS times, satellite
    counts and week stay (solution.pos). ~100 bytes per GNSS epoch (docs/DESIGN.md
    "Bounded memory")."""
    gnss = prep.dataset.gnss
    if gnss is not None:
        gnss = type(gnss)(t=gnss.t, llh=np.empty((0, 3)), pos_sigma=np.empty((0, 3)),
                          ns=gnss.ns, gps_week=gnss.gps_week)
    prep.dataset = replace(prep.dataset, reference=None, heading=None, gnss=gnss)


def streams_imu(recipe: Recipe) -> bool:
    """True when a streamed run (`gmis run`'s forward loosely coupled run, `gmis vce`) of
    this recipe keeps its IMU samples on disk (gmis.readers.load_dataset imu_on_disk):
    the plain loosely coupled preparation, which reads the samples by row ranges. The
    estimated GNSS time offset and NHC lever arm (filter runs inside the preparation)
    and the tightly coupled filter keep them in memory."""
    nhc = recipe.nonholonomic
    return (recipe.filter.mode == "loose" and not recipe.gnss.estimate_time_offset
            and not (nhc is not None and nhc.estimate_lever_arm))


def _whole_imu(ds: Dataset) -> Dataset:
    """ds with its IMU samples in memory (read whole from gmis.imu_spool when on disk):
    for the preparation steps that work on whole arrays (a moving start, the course
    heading, the in-motion noise floor)."""
    imu = ds.imu
    if getattr(imu.gyro, "spool", None) is None:
        return ds
    return replace(ds, imu=replace(imu, gyro=np.asarray(imu.gyro), accel=np.asarray(imu.accel)))


def _circular_mean(angles):
    return float(np.arctan2(np.sin(angles).mean(), np.cos(angles).mean()) % (2 * np.pi))


def _aiding_measurements(ds: Dataset, frame, keep_mask, remove_heading=True,
                         velocity_offset_s: float = 0.0):
    """Measurements (IMU, GNSS position/velocity in ENU, heading) and the GNSS position,
    velocity and heading time stamps (None when absent) of the samples keep_mask keeps;
    velocity_offset_s: [gnss].velocity_time_offset_s (or its estimate)."""
    imu = ds.imu
    meas = Measurements(imu_z=imu.z)   # the reader's (N, 6) storage, not a copy
    pos_t = vel_t = hdg_t = None
    if ds.gnss is not None:
        k = keep_mask(ds.gnss.t)
        pos_t = ds.gnss.t[k]
        meas.pos_enu = geodetic_to_enu_rows(frame, np.ascontiguousarray(ds.gnss.llh[k]))
        meas.pos_sd = ds.gnss.pos_sigma[k]
        if ds.gnss.vel_enu is not None:
            # [gnss].velocity_time_offset_s: the velocity at its own (shifted) epochs, withheld
            # by its own times; the removed-sample count stays one per GNSS solution epoch
            offset = velocity_offset_s
            t_vel = ds.gnss.t + offset
            kv = keep_mask(t_vel, count=False) if offset else k
            vel_t = t_vel[kv]
            meas.vel_enu = ds.gnss.vel_enu[kv]
            meas.vel_sd = ds.gnss.vel_sigma[kv]
        if ds.gnss.speed_course is not None:
            meas.speed_course = ds.gnss.speed_course[k]
            meas.speed_course_sd = ds.gnss.speed_course_sigma[k]
    if ds.heading is not None:
        k = keep_mask(ds.heading.t) if remove_heading else np.ones(ds.heading.t.size, bool)
        hdg_t = ds.heading.t[k]
        meas.heading = ds.heading.heading[k]
        meas.heading_sd = ds.heading.sigma[k]
    return meas, pos_t, vel_t, hdg_t


def _with_velocity_for_initialisation(ds: Dataset) -> Dataset:
    """The dataset whose speed/course GNSS (no vertical velocity) carries the ENU velocity
    of gmis.speed_course.velocity_for_initialisation, for the start (stillness, in-motion
    fit, course heading) only; the filter's measurements keep speed and course."""
    g = ds.gnss
    if g is None or g.vel_enu is not None or g.speed_course is None:
        return ds
    from gmis.speed_course import velocity_for_initialisation
    vel, vel_sd = velocity_for_initialisation(g.speed_course, g.speed_course_sigma)
    return replace(ds, gnss=replace(g, vel_enu=vel, vel_sigma=vel_sd))


def _gnss_given_to_run(ds: Dataset, keep_mask, remove_heading: bool = True,
                       velocity_offset_s: float = 0.0) -> Dataset:
    """The dataset whose GNSS solution holds only the epochs the run is given: outside
    every outage window by the position's time and, with [gnss].velocity_time_offset_s,
    by the velocity's own time too; the heading stream likewise when the outages remove
    it. The start (stillness, static window, in-motion fit, course heading, initial
    heading and antenna) uses it, so that no withheld fix reaches the run (a course
    heading taken inside the first window did, before)."""
    h = ds.heading
    if remove_heading and h is not None and h.t.size:
        keep_h = keep_mask(h.t, count=False)
        if not keep_h.all():
            ds = replace(ds, heading=replace(h, t=h.t[keep_h], heading=h.heading[keep_h],
                                             sigma=h.sigma[keep_h]))
    g = ds.gnss
    if g is None or g.t.size == 0:
        return ds
    keep = keep_mask(g.t, count=False)
    offset = velocity_offset_s
    if g.vel_enu is not None and offset:
        keep &= keep_mask(g.t + offset, count=False)
    if keep.all():
        return ds
    rows = {f.name: getattr(g, f.name)[keep] for f in fields(g)
            if isinstance(getattr(g, f.name), np.ndarray)
            and getattr(g, f.name).shape[:1] == g.t.shape}
    return replace(ds, gnss=replace(g, **rows))


def _initial_heading(recipe: Recipe, ds: Dataset, t0, win, raw_init):
    if ds.heading is not None and ds.heading.t.size > 0:
        in_win = ds.heading.t <= t0 + max(win, 1.0)
        return _circular_mean(ds.heading.heading[in_win]) if in_win.any() \
            else float(ds.heading.heading[0])
    if raw_init is not None and raw_init[0] is not None:
        return raw_init[0]
    course = _course_heading(ds, t0, win)
    if course is not None:
        return course
    raise GmisInputError("the dataset has no heading stream and the GNSS velocity never "
                         "reaches 2 m/s: the initial heading needs [paths].heading or, in "
                         "tight mode, [paths].heading_obs (dual-antenna heading)",
                         source=str(recipe.path))


def _course_heading(ds: Dataset, t0, win):
    """Heading at t0 from the GNSS course once moving (gmis.course_heading), with a note
    on stderr; None without GNSS velocity or motion. Its σ is set by the caller."""
    from gmis.course_heading import heading_from_course
    from gmis.plausibility import announce

    if ds.gnss is None or ds.gnss.vel_enu is None:
        return None
    ds = _whole_imu(ds)
    sel = (ds.imu.t >= t0) & (ds.imu.t < t0 + max(win, 1.0))
    bias_z = float(ds.imu.gyro[sel, 2].mean()) if sel.sum() > 10 else 0.0
    got = heading_from_course(ds.gnss.t, ds.gnss.vel_enu, ds.imu.t, ds.imu.gyro[:, 2],
                              bias_z, t0)
    if got is None:
        return None
    heading, sigma, t1 = got
    note = (f"no heading stream: initial heading {np.degrees(heading):.1f} deg from the "
            f"GNSS course at t={t1:.2f} s carried back by the gyro, 1 sigma "
            f"{np.degrees(sigma):.0f} deg")
    announce([note])
    return CourseHeading(heading, sigma, note)


class CourseHeading(float):
    """A heading (rad) from the GNSS course, carrying its 1σ (rad)."""

    def __new__(cls, value, sigma, note):
        obj = super().__new__(cls, value)
        obj.sigma = sigma
        obj.note = note
        return obj


def _initial_antenna(recipe: Recipe, ds: Dataset, frame, t0, win, raw_init, config):
    """Antenna ENU position at the start (mean over the alignment window); a raw-GNSS
    single-point start widens the initial position σ to metres (in config.p0_sd)."""
    if ds.gnss is not None and ds.gnss.t.size > 0:
        g_enu = geodetic_to_enu_rows(frame, np.ascontiguousarray(ds.gnss.llh))
        g_win = ds.gnss.t <= t0 + max(win, 1.0)
        return g_enu[g_win].mean(axis=0) if g_win.any() else g_enu[0]
    if raw_init is not None:
        config.p0_sd[POS] = np.maximum(config.p0_sd[POS], 3.0)
        return raw_init[1]
    raise GmisInputError("the dataset has no GNSS position solution ([paths]."
                         "gnss_solution): the loosely coupled filter needs one",
                         source=str(recipe.path))


LAND_VEHICLE_SPEED_SIGMA_M_S = 50.0   # the 1σ of an unknown start velocity (180 km/h)
REST_SPEED_M_S = 0.2                  # GNSS speed below which a fix is at rest


def _late_first_fix(ds: Dataset, t0, win, config):
    """When the first GNSS fix the run is given lies after the static alignment window, its
    position is the start's (``_initial_antenna``) only if the vehicle was at rest from the
    start until that fix: the GNSS speed there below REST_SPEED_M_S and no motion seen by
    the IMU before it (an IMU cannot tell rest from a constant velocity, but a vehicle at
    rest at its first fix that had moved before would have braked). Otherwise the start
    position and velocity are unknown until the first fix: their initial 1σ (config.p0_sd)
    become LAND_VEHICLE_SPEED_SIGMA_M_S and that speed times the time to the fix, so the
    solution before the fix says so and the fix corrects it. Returns the note, or None when
    a fix lies inside the window."""
    g = ds.gnss
    if g is None or g.t.size == 0 or (g.t <= t0 + max(win, 1.0)).any():
        return None
    t_fix = float(g.t[0])
    speed = float("nan")
    if g.vel_enu is not None:
        speed = float(np.hypot(g.vel_enu[0, 0], g.vel_enu[0, 1]))
    t_move = first_motion(ds.imu.t, ds.imu.gyro, ds.imu.accel, t0)
    if speed < REST_SPEED_M_S and (t_move is None or t_move > t_fix):
        return (f"no GNSS fix in the static alignment window: the first is at t={t_fix:.2f} s "
                f"({t_fix - t0:.1f} s after the start) with the vehicle at rest until then "
                "(IMU and GNSS speed): start position = that fix")
    dt = t_fix - t0
    pos_sd = LAND_VEHICLE_SPEED_SIGMA_M_S * dt
    config.p0_sd[POS] = np.maximum(config.p0_sd[POS], pos_sd)
    config.p0_sd[VEL] = np.maximum(config.p0_sd[VEL], LAND_VEHICLE_SPEED_SIGMA_M_S)
    why = (f"moving there ({speed:.1f} m/s)" if speed >= REST_SPEED_M_S else
           "not seen at rest until then by the IMU" if np.isfinite(speed) else
           "without a GNSS velocity to show it at rest")
    return (f"no GNSS fix in the static alignment window: the first is at t={t_fix:.2f} s "
            f"({dt:.1f} s after the start), the vehicle {why}: the start position and "
            f"velocity are unknown until then (initial 1 sigma {pos_sd:.0f} m and "
            f"{LAND_VEHICLE_SPEED_SIGMA_M_S:.0f} m/s; the solution before the fix has them)")


MOTION_MARGIN_S = 1.0  # the static window ends this long before the first motion
MIN_CUT_WINDOW_S = 1.0  # a cut that would leave less than this keeps the window (warning)


def _static_window(ds: Dataset, t0, win):
    """[filter].static_alignment_s cut, when the first motion seen by the IMU or the GNSS
    speed (gmis.motion.first_motion) lies inside it, to end MOTION_MARGIN_S before that
    motion; (window s, warning or None)."""
    return _static_window_and_start(ds, t0, win)[:2]


def _static_window_and_start(ds: Dataset, t0, win):
    """_static_window and True when the data start in motion (too early to cut)."""
    gnss_t = speed = None
    if ds.gnss is not None and ds.gnss.t.size:
        enu = np.zeros((ds.gnss.t.size, 3))
        if ds.gnss.vel_enu is None:
            from gmis.earth import make_nav_frame as _frame
            enu = geodetic_to_enu_rows(_frame(*ds.gnss.llh[0]),
                                       np.ascontiguousarray(ds.gnss.llh))
        gnss_t = ds.gnss.t
        speed = gnss_horizontal_speed(gnss_t, enu, ds.gnss.vel_enu)
    t_move = first_motion(ds.imu.t, ds.imu.gyro, ds.imu.accel, t0, gnss_t, speed)
    if t_move is None or t_move >= t0 + win:
        return win, None, False
    new = t_move - MOTION_MARGIN_S - t0
    if new < MIN_CUT_WINDOW_S:
        return win, (f"static alignment window [filter].static_alignment_s = {win:g} s "
                     f"contains motion from t={t_move:.2f} s ({t_move - t0:.1f} s after the "
                     f"start): too early to cut the window to a static part, kept as given; "
                     "pitch/roll/gyro bias of the alignment may be wrong"), True
    return new, (f"static alignment window [filter].static_alignment_s = {win:g} s contains "
                 f"motion from t={t_move:.2f} s ({t_move - t0:.1f} s after the start); "
                 f"window cut to {new:.1f} s"), False


def _start_in_motion(ds: Dataset, frame, t0, config):
    """gmis.motion_initialisation.in_motion_start from the dataset, or None (no GNSS fit,
    or a slow start whose course never reaches 2 m/s)."""
    from gmis.course_heading import heading_from_course
    from gmis.motion_initialisation import in_motion_start

    gnss = ds.gnss
    if gnss is None or gnss.t.size < 4:
        return None
    ds = _whole_imu(ds)
    enu = geodetic_to_enu_rows(frame, np.ascontiguousarray(gnss.llh))
    vel = gnss.vel_enu if gnss.vel_enu is not None else \
        np.column_stack([np.gradient(enu[:, i], gnss.t) for i in range(3)])
    heading = heading_sd = None
    if ds.heading is not None:
        near = np.flatnonzero(np.abs(ds.heading.t - t0) <= 1.0)
        if near.size:
            heading = float(ds.heading.heading[near[0]])
            heading_sd = float(ds.heading.sigma[near[0]])

    def carried():
        got = heading_from_course(gnss.t, vel, ds.imu.t, ds.imu.gyro[:, 2], 0.0, t0)
        return None if got is None else got[:2]

    return in_motion_start(frame, gnss.t, enu, gnss.pos_sigma, ds.imu.t, ds.imu.gyro,
                           ds.imu.accel, t0, config.lever_arm, config.p0_sd[BG],
                           config.p0_sd[BA], gnss.vel_enu, gnss.vel_sigma, heading,
                           heading_sd, carried,
                           correlated=(config.gnss_error_sigma_m, config.gnss_error_tau_s[0])
                           if config.gnss_error_states else None)


def prepare_run(recipe: Recipe, dataset: Dataset | None = None, gnss_outages=(),
                remove_heading: bool | None = None):
    """Read the data, fix the ENU origin, merge the streams, align and build x0.

    gnss_outages: [(start_s, end_s), ...] windows (GPS s) in which GNSS position/velocity
    are removed, and the heading too unless remove_heading is False (None: the recipe's
    [outages].remove_heading); the recipe's own [outages].windows are always added."""
    ds = dataset if dataset is not None else load_dataset(recipe)
    if recipe.gnss.estimate_velocity_time_offset and recipe.filter.mode == "loose":
        return _prepare_with_velocity_lag(recipe, ds, gnss_outages, remove_heading)
    if recipe.nonholonomic is not None and recipe.nonholonomic.estimate_lever_arm:
        from gmis.nhc_offset_estimation import with_estimated_nhc_point
        nhc = recipe.nonholonomic
        first = prepare_run(replace(recipe, nonholonomic=replace(nhc, estimate_lever_arm=False)),
                            ds, gnss_outages, remove_heading)
        return with_estimated_nhc_point(first, nhc)
    if recipe.gnss.estimate_time_offset and recipe.filter.mode == "loose":
        return _prepare_with_estimated_offset(recipe, ds, gnss_outages, remove_heading)
    origin = ds.origin_llh()
    if origin is None:
        raise GmisInputError("no ENU origin: give [origin] or [base], or a GNSS solution "
                             "file whose first fix can serve", source=str(recipe.path))
    frame = make_nav_frame(*origin)
    imu = ds.imu
    config = gmikf_config(recipe)
    removed = 0

    def keep_mask(t, count=True):
        nonlocal removed
        keep = np.ones(t.size, bool)
        for a, b in gnss_outages:
            keep &= ~((t >= a) & (t <= b))
        if count:
            removed += int((~keep).sum())
        return keep

    gnss_outages = sorted([*map(tuple, gnss_outages), *recipe.outages.spans()])
    if remove_heading is None:
        remove_heading = recipe.outages.remove_heading
    v_offset = recipe.gnss.velocity_time_offset_s
    meas, pos_t, vel_t, hdg_t = _aiding_measurements(ds, frame, keep_mask, remove_heading,
                                                     v_offset)
    if gnss_outages and removed == 0 and ds.gnss is not None and ds.gnss.t.size:
        from gmis.plausibility import announce
        note = (f"GNSS outage windows {', '.join(f'{a:g}..{b:g}' for a, b in gnss_outages)} "
                f"(GPS s) withhold no GNSS epoch: the run's GNSS spans "
                f"{ds.gnss.t[0]:.1f}..{ds.gnss.t[-1]:.1f} s")
        ds = replace(ds, warnings=ds.warnings + (note,))
        announce([note])
    tol = min(1e-3, 0.25 / recipe.imu.rate_hz)
    sog_t = pos_t if len(meas.speed_course) else None   # gmis.speed_course rows
    # IMU samples on disk (a streamed run): the epoch indices compact too (RowIndex)
    epochs = merge_streams(imu.t, pos_t, vel_t, hdg_t, tolerance_s=tol, sog_t=sog_t,
                           compact=getattr(imu.gyro, "spool", None) is not None)
    ds_aiding = ds
    ds = _with_velocity_for_initialisation(_gnss_given_to_run(ds, keep_mask, remove_heading,
                                                              v_offset))

    # ---- initial state from a static start (001 §4.3.1)
    t0 = imu.t[0]
    win = recipe.filter.static_alignment_s
    raw_init = raw_gnss = None
    has_heading = ds.heading is not None and ds.heading.t.size > 0
    has_gnss = ds.gnss is not None and ds.gnss.t.size > 0
    if recipe.filter.mode == "tight" and not (has_heading and has_gnss):
        from gmis.tc import raw_gnss_initialisation, read_raw_gnss
        raw_gnss = read_raw_gnss(recipe)
        raw_init = raw_gnss_initialisation(raw_gnss, recipe, frame, imu.t, win)
    win, cut, moving_start = _static_window_and_start(ds, t0, win)
    start = None
    if moving_start and recipe.filter.mode == "loose":
        start = _start_in_motion(ds, frame, t0, config)
    if start is not None:
        from gmis.plausibility import announce
        ds = replace(ds, warnings=ds.warnings + (start.note,))
        announce([start.note])
        x0 = np.zeros(config.n_imu)
        x0[POS], x0[VEL], x0[ACC] = start.pos_enu, start.vel_body, start.acc_body
        x0[ATT], x0[RATE] = start.attitude, start.rate_body
        for block, sd in ((POS, start.pos_sd), (VEL, start.vel_sd), (ACC, start.acc_sd),
                          (ATT, start.att_sd), (RATE, start.rate_sd)):
            config.p0_sd[block] = sd
        al = StaticAlignment(float(start.attitude[0]), float(start.attitude[1]),
                             np.zeros(3), start.n_imu_samples, start.accel_std,
                             start.gyro_std)
        if recipe.filter.imu_noise_from_static:   # no static window: Δ² in motion
            ds = _in_motion_noise_floor(recipe, ds, config, imu, t0)
        prep = _prepared(recipe, replace(ds, gnss=ds_aiding.gnss), frame, epochs, meas, x0,
                         config, al, removed, pos_t, vel_t, raw_gnss, gnss_outages)
        prep.in_motion = start
        return prep
    if cut is not None:
        from gmis.plausibility import announce
        ds = replace(ds, warnings=ds.warnings + (cut,))
        announce([cut])
    heading0 = _initial_heading(recipe, ds, t0, win, raw_init)
    if isinstance(heading0, CourseHeading):
        config.p0_sd[ATT.start + 2] = max(config.p0_sd[ATT.start + 2], heading0.sigma)
        ds = replace(ds, warnings=ds.warnings + (heading0.note,))
        heading0 = float(heading0)
    try:
        al = static_alignment(imu.t, imu.gyro, imu.accel, t0, win, earth_rate_nav(frame),
                              heading0)
    except GmisInputError as exc:         # name the recipe, not only its key
        raise GmisInputError(str(exc), source=str(recipe.path)) from None
    if recipe.filter.imu_noise_from_static:
        config.imu_sd, note = imu_noise_floor(config.imu_sd, al.gyro_std, al.accel_std,
                                              al.n_samples, win,
                                              explicit=_explicit_imu_sigma(recipe))
        if note is not None:
            from gmis.plausibility import announce
            ds = replace(ds, warnings=ds.warnings + (note,))
            announce([note])
    c_bn = dcm_body_to_nav(al.pitch, al.roll, heading0)
    ant0 = _initial_antenna(recipe, ds, frame, t0, win, raw_init, config)
    late = _late_first_fix(ds, t0, win, config)
    if late is not None:
        from gmis.plausibility import announce
        ds = replace(ds, warnings=ds.warnings + (late,))
        announce([late])
    x0 = np.zeros(config.n_imu)
    x0[POS] = ant0 - c_bn @ config.lever_arm
    x0[ATT] = (al.pitch, al.roll, heading0)
    x0[BG] = al.gyro_bias
    return _prepared(recipe, replace(ds, gnss=ds_aiding.gnss), frame, epochs, meas, x0,
                     config, al, removed, pos_t, vel_t, raw_gnss, gnss_outages)


def _explicit_imu_sigma(recipe):
    """(6,) bool: the gyro / accel axes the at-rest floor keeps — all of them when the σ
    are `gmis vce` estimates ([noise].imu_sigma_source = "vce", gmis.imu_noise_floor)."""
    return (recipe.noise.imu_sigma_source == "vce",) * 6


def _in_motion_noise_floor(recipe, ds, config, imu, t0):
    """config.imu_sd floored by gmis.imu_noise_floor.imu_noise_in_motion; ds with the
    note (also printed) when an axis was raised."""
    from gmis.imu_noise_floor import IN_MOTION_WINDOW_S, imu_noise_in_motion

    imu = _whole_imu(replace(ds, imu=imu)).imu
    g_sd, a_sd, n_eff = imu_noise_in_motion(imu.t, imu.gyro, imu.accel, t0)
    config.imu_sd, note = imu_noise_floor(config.imu_sd, g_sd, a_sd, n_eff,
                                          IN_MOTION_WINDOW_S, in_motion=True,
                                          explicit=_explicit_imu_sigma(recipe))
    if note is None:
        return ds
    from gmis.plausibility import announce
    announce([note])
    return replace(ds, warnings=ds.warnings + (note,))


def _prepare_with_estimated_offset(recipe, ds, gnss_outages, remove_heading):
    """[gnss].estimate_time_offset: the offset from the data (gmis.latency_estimation,
    searched within time_offset_search_s of the recipe's offset), then the run prepared
    with the GNSS times shifted by it; the estimate is kept in gnss_time_offset and a
    note printed."""
    from gmis.latency_estimation import (
        MIN_MOVING_FIXES,
        MOVING_SPEED_M_S,
        TimeOffsetEstimate,
        estimate_time_offset,
    )
    from gmis.plausibility import announce

    no_estimate = replace(recipe, gnss=replace(recipe.gnss, estimate_time_offset=False))
    first = prepare_run(no_estimate, ds, gnss_outages, remove_heading)
    if ds.gnss is None or ds.gnss.t.size < 2:
        return first

    def not_applied(reason, runs=0):
        note = (f"GNSS time offset not estimated ({reason}): [gnss].time_offset_s = "
                f"{recipe.gnss.time_offset_s:+.4f} s kept")
        announce([note])
        first.dataset = replace(first.dataset, warnings=first.dataset.warnings + (note,))
        first.gnss_time_offset = TimeOffsetEstimate(0.0, float("inf"), np.empty(0),
                                                    np.empty(0), runs, False, reason)
        return first

    pos_t = first.epochs.t[np.asarray(first.epochs.pos) >= 0]
    vel = first.meas.vel_enu if len(first.meas.vel_enu) == pos_t.size else None
    speed = gnss_horizontal_speed(pos_t, np.asarray(first.meas.pos_enu).reshape(-1, 3), vel)
    moving = int(np.sum(speed >= MOVING_SPEED_M_S))
    if moving < MIN_MOVING_FIXES:
        return not_applied(f"{moving} GNSS fixes faster than {MOVING_SPEED_M_S:g} m/s, at "
                           f"least {MIN_MOVING_FIXES} needed: the offset shows only in motion")
    half = recipe.gnss.time_offset_search_s
    est = estimate_time_offset(first, half)
    if not np.isfinite(est.sigma_s) or abs(est.offset_s) > half:
        return not_applied(f"no minimum of the likelihood inside ±{half:g} s", est.runs)
    total = recipe.gnss.time_offset_s + est.offset_s
    note = (f"GNSS time offset estimated from the data: [gnss].time_offset_s = {total:+.4f} s "
            f"(1 sigma {est.sigma_s * 1e3:.1f} ms; shift {est.offset_s * 1e3:+.1f} ms on the "
            f"recipe's {recipe.gnss.time_offset_s:+.4f} s, {est.runs} filter runs)")
    shifted = replace(ds, gnss=replace(ds.gnss, t=ds.gnss.t + est.offset_s),
                      warnings=ds.warnings + (note,))
    announce([note])
    prep = prepare_run(replace(no_estimate, gnss=replace(recipe.gnss, time_offset_s=total,
                                                          estimate_time_offset=False)),
                       shifted, gnss_outages, remove_heading)
    prep.gnss_time_offset = est
    return prep


def _prepare_with_velocity_lag(recipe, ds, gnss_outages, remove_heading):
    """[gnss].estimate_velocity_time_offset: the velocity's lag behind the positions from
    the GNSS the run is given (outside every outage window; gmis.gnss_velocity_lag),
    then the run prepared with velocity_time_offset_s = −δ̂, or with the recipe's value
    when the estimate is not defined; the estimate is kept in gnss_velocity_lag and a
    note printed either way."""
    from gmis.gnss_velocity_lag import estimate_velocity_lag
    from gmis.plausibility import announce

    g = ds.gnss
    source = str(recipe.paths.gnss_pos or recipe.paths.gnss_solution or recipe.path)
    if g is None or g.vel_enu is None:
        raise GmisInputError("gnss.estimate_velocity_time_offset: the GNSS solution has no "
                             "ENU velocity to compare with its positions (speed/course or "
                             "position-only files: set it to false)", source=source)
    keep = np.ones(g.t.size, bool)
    for a, b in [*map(tuple, gnss_outages), *recipe.outages.spans()]:
        keep &= ~((g.t >= a) & (g.t <= b))
    given = recipe.gnss.velocity_time_offset_s
    if keep.any():
        frame = make_nav_frame(*g.llh[np.argmax(keep)])
        enu = geodetic_to_enu_rows(frame, np.ascontiguousarray(g.llh[keep]))
        est = estimate_velocity_lag(g.t[keep], enu, g.vel_enu[keep], centre_s=-given)
    else:
        est = estimate_velocity_lag(g.t[:0], np.empty((0, 3)), np.empty((0, 3)))
    if est.applied:
        offset = est.velocity_time_offset_s
        note = (f"GNSS velocity lag estimated from the solution: it lags its positions by "
                f"{est.lag_s * 1e3:.1f} ms (1 sigma {est.sigma_s * 1e3:.1f} ms, "
                f"{est.epochs} moving epochs; |v - dr/dt| RMS {est.rms_at_zero_m_s:.3f} -> "
                f"{est.rms_at_lag_m_s:.3f} m/s): [gnss].velocity_time_offset_s = "
                f"{offset:+.4f} s")
    else:
        offset = given
        note = (f"GNSS velocity lag not estimated ({est.reason}): "
                f"[gnss].velocity_time_offset_s = {offset:+.4f} s kept")
    announce([note])
    ds = replace(ds, warnings=ds.warnings + (note,))
    fixed = replace(recipe, gnss=replace(recipe.gnss, velocity_time_offset_s=offset,
                                         estimate_velocity_time_offset=False))
    prep = prepare_run(fixed, ds, gnss_outages, remove_heading)
    prep.gnss_velocity_lag = est
    return prep


def _prepared(recipe, ds, frame, epochs, meas, x0, config, al, removed, pos_t, vel_t,
              raw_gnss, gnss_outages) -> PreparedRun:
    """PreparedRun with the stationary epochs (gmis.motion) of the kept GNSS."""
    if pos_t is not None and pos_t.size:
        speed = gnss_horizontal_speed(pos_t, meas.pos_enu,
                                      meas.vel_enu if vel_t is not None else None)
        still = stationary_epochs(epochs, pos_t, speed, imu=(ds.imu.t, ds.imu.gyro))
    else:
        still = np.zeros(len(epochs), dtype=bool)
    return PreparedRun(recipe=recipe, dataset=ds, frame=frame, epochs=epochs, meas=meas,
                       x0=x0, config=config, alignment=al, gnss_removed=removed,
                       stationary=still, raw_gnss=raw_gnss,
                       outage_windows=tuple(gnss_outages))


def run_prepared(prep: PreparedRun, config: GmikfConfig | None = None, progress=None,
                 meas: Measurements | None = None, sink=None):
    """The GMIKF over a prepared run (gmis.run_filter.run_gmikf); config / meas replace
    the prepared ones (VCE iterations); sink: records chunk by chunk (run_gmikf)."""
    return run_gmikf(prep.epochs, meas or prep.meas, prep.x0, config or prep.config,
                     prep.frame, progress=progress, stationary=prep.stationary, sink=sink)


__all__ = ["PreparedRun", "prepare_run", "release_prepared_inputs", "run_prepared",
           "streams_imu"]
