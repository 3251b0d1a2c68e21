"""Plausibility checks at load time: catch the mistakes that parse fine but are physically
wrong (a wrong unit in the recipe, swapped columns, a heading file in radians, absurd
values), before a run produces a confident wrong answer.

Each check either raises :class:`gmis.errors.GmisInputError` naming the file and column
(the data cannot be what the recipe says) or returns a warning line (suspicious but
possible); the caller stores warnings in the summary and :func:`announce` prints each on
stderr once. Bounds are for any land vehicle, generous on purpose:

=====================================  =========================  ======================
quantity                               error beyond               source of the bound
=====================================  =========================  ======================
|accelerometer| (m/s²)                 MAX_ACCEL_M_S2 = 1000      ≈ 100 g; MEMS ranges
                                                                  end at ±16..±40 g
|gyro| (rad/s)                         MAX_GYRO_RAD_S = 50        ≈ 2900 deg/s; ranges
                                                                  end at ±2000 deg/s
1-s mean |gyro| (rad/s)                MAX_TURN_RATE_RAD_S = 10   a car's yaw rate stays
                                                                  below ~1 rad/s
GNSS / reference height (m)            [-500, 9000]               Dead Sea .. Everest
GNSS / reference speed (m/s)           MAX_SPEED_M_S = 150        540 km/h
GNSS position sigma (m)                (0, 1e4]; warn > 100
heading sigma (deg)                    (0, 180]
distance from [origin]/[base] (m)      MAX_ORIGIN_DISTANCE_M = 200 km
lever arms in the recipe (m)           MAX_LEVER_ARM_M = 30       a truck with trailer
=====================================  =========================  ======================

Unit checks (errors, since each is a factor of 57.3 or 9.81 off):

* gyro: the turning of the vehicle measured by the gyro (rate about the mean specific
  force direction, i.e. about the local vertical, integrated over 10 s windows) against
  the change of the heading file or of the GNSS course over the same windows, where they
  turn by ≥ 90° in total; a least-squares scale outside [0.5, 2] is an error.
* accelerometer: the median specific-force norm is gravity (9.81 m/s²) for a land
  vehicle whether it moves or not; a median norm near 1 (data in g read as m/s²) or near
  96 (m/s² read as g), or any other norm outside [0.5 g, 2 g], is an error. The
  check needs UNIT_CHECK_MIN_S = 30 s of IMU data (a few seconds of synthetic test data
  are left alone).
* heading: against the GNSS course at speed > 3 m/s: if the values read as radians match
  the course and read as degrees do not, the file is in radians (error); values outside
  [-360, 720] are an error.
"""

from __future__ import annotations

import math
import sys
from itertools import pairwise

import numpy as np

from gmis.errors import GmisInputError

GRAVITY = 9.80665
MAX_ACCEL_M_S2 = 1000.0
MAX_GYRO_RAD_S = 50.0
MAX_TURN_RATE_RAD_S = 10.0
HEIGHT_RANGE_M = (-500.0, 9000.0)
MAX_SPEED_M_S = 150.0
MAX_POSITION_SIGMA_M = 1e4
WARN_POSITION_SIGMA_M = 100.0
MAX_VELOCITY_SIGMA_M_S = 100.0
MAX_HEADING_SIGMA_DEG = 180.0
MAX_ORIGIN_DISTANCE_M = 200e3
MAX_LEVER_ARM_M = 30.0
UNIT_CHECK_MIN_S = 30.0
TURN_WINDOW_S = 10.0
MIN_TOTAL_TURN_RAD = math.radians(90.0)
COURSE_MIN_SPEED_M_S = 3.0
EARTH_RADIUS_M = 6371e3

_announced: set[str] = set()


def one_line_warnings() -> None:
    """Show Python warnings and library log records (e.g. georinex's ``logging.error``
    calls in the RINEX reader) as one ``gmis: warning:`` line each on stderr."""
    import logging
    import warnings

    logging.basicConfig(format="gmis: warning: %(message)s", level=logging.WARNING,
                        stream=sys.stderr)
    for handler in logging.getLogger().handlers:   # INFO records of libraries with their
        handler.setLevel(logging.WARNING)          # own logger levels (dask) stay out

    def show(message, category, filename, lineno, file=None, line=None):
        announce([" ".join(str(message).split())], file)

    warnings.showwarning = show


def announce(warnings, stream=None) -> None:
    """Print each warning once per process as ``gmis: warning: ...`` on stderr."""
    stream = stream or sys.stderr
    for w in warnings:
        if w not in _announced:
            _announced.add(w)
            print(f"gmis: warning: {w}", file=stream)


def _fail(path, message):
    raise GmisInputError(message, source=str(path))


def _first_bad(mask) -> int | None:
    idx = np.flatnonzero(mask)
    return int(idx[0]) if idx.size else None


def _row(line_numbers, k):
    return f" (line {int(line_numbers[k])})" if line_numbers is not None else f" (row {k + 1})"


# ----------------------------------------------------------------------------- IMU


def check_imu_ranges(path, t, gyro, accel, gyro_names, accel_names, line_numbers=None):
    """Values beyond any land-vehicle IMU (gyro rad/s, accel m/s², after unit conversion)."""
    for data, names, limit, what, unit in (
            (accel, accel_names, MAX_ACCEL_M_S2, "accelerometer", "m/s²"),
            (gyro, gyro_names, MAX_GYRO_RAD_S, "gyro", "rad/s")):
        k = row = None
        for a in range(0, len(data), CHECK_ROWS):    # blocks: IMU samples may be on disk
            block = np.asarray(data[a:a + CHECK_ROWS])
            kb = _first_bad(np.abs(block).max(axis=1) > limit)
            if kb is not None:
                k, row = a + kb, block[kb]
                break
        if k is not None:
            j = int(np.argmax(np.abs(row)))
            _fail(path, f"column {names[j]!r}: {what} value {row[j]:.6g} {unit} after unit "
                        f"conversion is beyond any land-vehicle IMU (|{what}| ≤ {limit:g} "
                        f"{unit}){_row(line_numbers, k)}; check [imu] units and columns")
    rate = _window_means(t, gyro, 1.0)
    if rate.size:
        peak = float(np.linalg.norm(rate, axis=1).max())
        if peak > MAX_TURN_RATE_RAD_S:
            _fail(path, f"columns {', '.join(map(repr, gyro_names))}: the gyro turns at "
                        f"{peak:.3g} rad/s over a whole second (a car stays below ~1 rad/s); "
                        "is [imu].gyro_unit right (deg/s data read as rad/s)?")


CHECK_ROWS = 1 << 16   # IMU rows per block of the range / unit checks


def _window_means(t, x, width_s):
    """Mean of x over consecutive windows of width_s (windows with < 2 samples dropped)."""
    if t.size < 2:
        return np.empty((0, x.shape[1]))
    edges = np.arange(t[0], t[-1] + width_s, width_s)
    idx = np.searchsorted(t, edges)
    out = [x[a:b].mean(axis=0) for a, b in pairwise(idx) if b - a >= 2]
    return np.array(out) if out else np.empty((0, x.shape[1]))


def check_accel_unit(path, t, accel, accel_names, unit: str):
    """Median specific-force norm vs gravity: raises unless within [0.5 g, 2 g] (files
    shorter than UNIT_CHECK_MIN_S are not checked). Returns None."""
    if t[-1] - t[0] < UNIT_CHECK_MIN_S:
        return
    norm = np.empty(len(accel))           # row by row, in blocks (samples may be on disk)
    for a in range(0, len(accel), CHECK_ROWS):
        norm[a:a + CHECK_ROWS] = np.linalg.norm(np.asarray(accel[a:a + CHECK_ROWS]), axis=1)
    norm = float(np.median(norm))
    ratio = norm / GRAVITY
    if 0.5 <= ratio <= 2.0:
        return
    hint = ""
    if 0.05 < ratio < 0.2:
        hint = " — data in g read as m/s²? (set [imu].accel_unit = \"g\")"
    elif 5.0 < ratio < 20.0:
        hint = " — data in m/s² read as g? (set [imu].accel_unit = \"m/s^2\")"
    message = (f"columns {', '.join(map(repr, accel_names))}: median specific force "
               f"{norm:.4g} m/s² with accel_unit = {unit!r}, but a land vehicle measures "
               f"gravity, {GRAVITY:.2f} m/s²{hint}")
    _fail(path, message)


def _vertical_rate(t, gyro, accel, width_s):
    """Per window: (t_mid, ∫ω·u dt) with u the window's mean specific-force direction
    (≈ local up for a land vehicle); angle in rad, sign of a right-handed turn about up."""
    edges = np.arange(t[0], t[-1] + width_s, width_s)
    idx = np.searchsorted(t, edges)
    mids, turns = [], []
    dt = np.diff(t, append=t[-1])
    for a, b in pairwise(idx):
        if b - a < 3:
            continue
        f = accel[a:b].mean(axis=0)
        n = np.linalg.norm(f)
        if n == 0:
            continue
        mids.append((t[a], t[b - 1]))
        turns.append(float((gyro[a:b] @ (f / n) * dt[a:b]).sum()))
    return np.array(mids).reshape(-1, 2), np.array(turns)


def check_gyro_unit(path, t, gyro, accel, gyro_names, unit, ref_t, ref_heading, ref_name):
    """Gyro turning vs the heading change of ``ref_heading`` (rad, azimuth) over the same
    10 s windows. Raises when the least-squares scale is outside [0.5, 2]."""
    if ref_t is None or ref_t.size < 3 or t.size < 3:
        return
    spans, turns = _vertical_rate(t, gyro, accel, TURN_WINDOW_S)
    if turns.size == 0:
        return
    psi = np.unwrap(ref_heading)
    a = np.interp(spans[:, 0], ref_t, psi)
    b = np.interp(spans[:, 1], ref_t, psi)
    covered = np.array([_densely_covered(ref_t, a0, b0) for a0, b0 in spans], dtype=bool)
    d_ref = -(b - a)        # azimuth is clockwise: a left (positive about up) turn lowers it
    use = covered & (np.abs(d_ref) > math.radians(10.0))
    if np.abs(d_ref[use]).sum() < MIN_TOTAL_TURN_RAD:
        return
    scale = float(np.dot(turns[use], d_ref[use]) / np.dot(d_ref[use], d_ref[use]))
    if 0.5 <= abs(scale) <= 2.0:
        return
    hint = ""
    if 20.0 < abs(scale) < 150.0:
        hint = " — deg/s data read as rad/s?"
    elif 1 / 150.0 < abs(scale) < 1 / 20.0:
        hint = " — rad/s data read as deg/s?"
    _fail(path, f"columns {', '.join(map(repr, gyro_names))}: the gyro measures {abs(scale):.3g} "
                f"times the turning of the vehicle seen by {ref_name} (gyro_unit = {unit!r})"
                f"{hint} Check [imu].gyro_unit and gyro_columns")


def _densely_covered(ref_t, start, end, max_gap_s=1.0):
    """True if ref_t samples the interval [start, end] with no gap above max_gap_s (a
    course known only at speed must not be interpolated across a slow turn)."""
    i, j = np.searchsorted(ref_t, [start, end])
    if i == 0 and ref_t[0] > start or j >= ref_t.size and ref_t[-1] < end:
        return False
    inside = ref_t[max(i - 1, 0):min(j + 1, ref_t.size)]
    points = np.concatenate([[start], inside[(inside > start) & (inside < end)], [end]])
    near_start = np.abs(inside - start).min() <= max_gap_s
    near_end = np.abs(inside - end).min() <= max_gap_s
    return bool(near_start and near_end and np.diff(points).max() <= max_gap_s)


# ----------------------------------------------------------------------------- GNSS


def check_gnss(path, gnss, origin_llh=None, origin_name="[origin]"):
    """Heights, speeds, sigmas and the distance from the recipe's origin/base."""
    warnings = []
    llh = gnss.llh
    h = llh[:, 2]
    k = _first_bad((h < HEIGHT_RANGE_M[0]) | (h > HEIGHT_RANGE_M[1]))
    if k is not None:
        _fail(path, f"column 'h_m': height {h[k]:.6g} m outside any road's range "
                    f"{HEIGHT_RANGE_M[0]:g}..{HEIGHT_RANGE_M[1]:g} m (row {k + 1})")
    if gnss.vel_enu is not None:
        speed = np.linalg.norm(gnss.vel_enu, axis=1)
        k = _first_bad(speed > MAX_SPEED_M_S)
        if k is not None:
            _fail(path, f"columns 've_m_s', 'vn_m_s', 'vu_m_s': speed {speed[k]:.6g} m/s beyond "
                        f"any land vehicle ({MAX_SPEED_M_S:g} m/s) (row {k + 1})")
    if gnss.t.size > 1:
        step = _ground_distance(llh[:-1], llh[1:])
        speed = step / np.diff(gnss.t)
        k = _first_bad(speed > MAX_SPEED_M_S)
        if k is not None:
            _fail(path, f"columns 'lat_deg', 'lon_deg': the position jumps {step[k]:.6g} m in "
                        f"{gnss.t[k + 1] - gnss.t[k]:.3g} s ({speed[k]:.3g} m/s, beyond any "
                        f"land vehicle) at row {k + 2}")
    sig = gnss.pos_sigma
    k = _first_bad(sig.max(axis=1) > MAX_POSITION_SIGMA_M)
    if k is not None:
        _fail(path, f"columns 'sigma_e_m', 'sigma_n_m', 'sigma_u_m': position sigma "
                    f"{sig[k].max():.6g} m is absurd (> {MAX_POSITION_SIGMA_M:g} m) (row {k + 1})")
    n_warn = int((sig.max(axis=1) > WARN_POSITION_SIGMA_M).sum())
    if n_warn:
        warnings.append(f"{path}: {n_warn} epochs with a position sigma above "
                        f"{WARN_POSITION_SIGMA_M:g} m")
    if gnss.vel_sigma is not None:
        k = _first_bad(gnss.vel_sigma.max(axis=1) > MAX_VELOCITY_SIGMA_M_S)
        if k is not None:
            _fail(path, f"columns 'sigma_ve_m_s', ...: velocity sigma "
                        f"{gnss.vel_sigma[k].max():.6g} m/s is absurd (row {k + 1})")
    if origin_llh is not None and gnss.t.size:
        o = np.array(origin_llh, float)[None, :]
        d = float(_ground_distance(o, llh[:1])[0])
        if d > MAX_ORIGIN_DISTANCE_M:
            swapped = np.array([[llh[0, 1], llh[0, 0], llh[0, 2]]])
            hint = (" — 'lat_deg' and 'lon_deg' swapped?"
                    if _ground_distance(o, swapped)[0] < MAX_ORIGIN_DISTANCE_M else "")
            _fail(path, f"columns 'lat_deg', 'lon_deg': the first fix is {d / 1e3:.6g} km from "
                        f"{origin_name} (more than {MAX_ORIGIN_DISTANCE_M / 1e3:g} km){hint}")
    return warnings


def _ground_distance(llh_a, llh_b):
    """Great-circle distance (m) between rows of [lat rad, lon rad, h] arrays, plus height."""
    la, lb = llh_a[:, 0], llh_b[:, 0]
    dlon = llh_b[:, 1] - llh_a[:, 1]
    c = np.sin(la) * np.sin(lb) + np.cos(la) * np.cos(lb) * np.cos(dlon)
    ang = np.arccos(np.clip(c, -1.0, 1.0))
    return np.hypot(ang * EARTH_RADIUS_M, llh_b[:, 2] - llh_a[:, 2])


def gnss_course(gnss):
    """(t, azimuth rad) of the GNSS course at speed > COURSE_MIN_SPEED_M_S, from the
    velocity columns or, without them, from position differences; None when too few."""
    if gnss is None or gnss.t.size < 3:
        return None
    if gnss.vel_enu is not None:
        ve, vn, t = gnss.vel_enu[:, 0], gnss.vel_enu[:, 1], gnss.t
    else:
        dt = np.diff(gnss.t)
        lat = gnss.llh[:, 0]
        vn = np.diff(lat) * EARTH_RADIUS_M / dt
        ve = np.diff(gnss.llh[:, 1]) * EARTH_RADIUS_M * np.cos(lat[:-1]) / dt
        t = gnss.t[:-1] + dt / 2
    fast = np.hypot(ve, vn) > COURSE_MIN_SPEED_M_S
    if fast.sum() < 3:
        return None
    return t[fast], np.arctan2(ve[fast], vn[fast])


def check_heading(path, heading, course=None):
    """Heading file range and unit (heading.heading is in rad as read from degrees)."""
    deg = np.degrees(heading.heading)
    k = _first_bad((deg < -360.0) | (deg > 720.0))
    if k is not None:
        _fail(path, f"column 'heading_deg': {deg[k]:.6g} deg outside -360..720 (row {k + 1})")
    sig = np.degrees(heading.sigma)
    k = _first_bad(sig > MAX_HEADING_SIGMA_DEG)
    if k is not None:
        _fail(path, f"column 'sigma_heading_deg': {sig[k]:.6g} deg is absurd (> 180) "
                    f"(row {k + 1})")
    if course is None:
        if deg.size >= 10 and np.abs(deg).max() <= 2 * math.pi + 1e-6 and np.ptp(deg) > 1.0:
            return [(f"{path}: column 'heading_deg': every value lies within ±2π; is the "
                     "file in radians?")]
        return []
    ct, cpsi = course
    inside = (heading.t >= ct[0]) & (heading.t <= ct[-1])
    if inside.sum() < 10:
        return []
    near = np.abs(ct[np.clip(np.searchsorted(ct, heading.t[inside]), 0, ct.size - 1)]
                  - heading.t[inside]) < 1.0
    if near.sum() < 10:
        return []
    ref = np.interp(heading.t[inside], ct, np.unwrap(cpsi))[near]
    as_deg = heading.heading[inside][near]
    as_rad = deg[inside][near]

    def median_misfit(x):
        return float(np.degrees(np.median(np.abs(np.angle(np.exp(1j * (x - ref)))))))

    m_deg, m_rad = median_misfit(as_deg), median_misfit(as_rad)
    if m_deg > 30.0 and m_rad < 15.0:
        _fail(path, f"column 'heading_deg': the values match the GNSS course when read as "
                    f"radians (median misfit {m_rad:.3g} deg) and not as degrees "
                    f"({m_deg:.3g} deg); the file must be in degrees")
    if m_deg > 30.0:
        return [(f"{path}: column 'heading_deg': median misfit {m_deg:.3g} deg against "
                 "the GNSS course at speed > 3 m/s (antenna baseline or sign convention?)")]
    return []


# ----------------------------------------------------------------------------- dataset


def check_lever_arms(recipe) -> None:
    """Every lever arm of the recipe within MAX_LEVER_ARM_M of the IMU (a land vehicle)."""
    arms = [("antennas.primary_lever_arm_m", recipe.antennas.primary_lever_arm_m),
            ("antennas.secondary_lever_arm_m", recipe.antennas.secondary_lever_arm_m)]
    if recipe.nonholonomic is not None:
        arms.append(("nonholonomic.lever_arm_m", recipe.nonholonomic.lever_arm_m))
    for key, arm in arms:
        if arm is None:
            continue
        length = float(np.linalg.norm(np.asarray(arm, float)))
        if not length <= MAX_LEVER_ARM_M:
            _fail(recipe.path, f"{key}: {length:.6g} m from the IMU; a land vehicle's lever "
                               f"arms are shorter than {MAX_LEVER_ARM_M:g} m")


def check_reference_height(path, h) -> None:
    """The reference's heights h (m) inside HEIGHT_RANGE_M, else an error naming the
    first one outside (also used by gmis.readers.read_reference_blocks)."""
    k = _first_bad((h < HEIGHT_RANGE_M[0]) | (h > HEIGHT_RANGE_M[1]))
    if k is not None:
        _fail(path, f"column 'h_m': height {h[k]:.6g} m outside "
                    f"{HEIGHT_RANGE_M[0]:g}..{HEIGHT_RANGE_M[1]:g} m")


def check_dataset(ds) -> list[str]:
    """Every check on a loaded gmis.readers.Dataset; returns the warnings, raises
    GmisInputError for data that cannot be what the recipe says."""
    recipe = ds.recipe
    check_lever_arms(recipe)
    imu_path = recipe.paths.imu
    names_g = [str(c) for c in recipe.imu.gyro_columns]
    names_a = [str(c) for c in recipe.imu.accel_columns]
    imu = ds.imu
    warnings = []
    check_imu_ranges(imu_path, imu.t, imu.gyro, imu.accel, names_g, names_a)
    check_accel_unit(imu_path, imu.t, imu.accel, names_a, recipe.imu.accel_unit)
    course = None
    if ds.gnss is not None:
        origin = recipe.origin_llh()
        name = "[origin]" if recipe.origin is not None else "[base]"
        warnings += check_gnss(recipe.paths.gnss_solution or recipe.paths.gnss_pos, ds.gnss, origin, name)
        course = gnss_course(ds.gnss)
    if ds.heading is not None:
        warnings += check_heading(recipe.paths.heading, ds.heading, course)
    if ds.reference is not None:
        check_reference_height(recipe.paths.reference, ds.reference.llh[:, 2])
    if ds.heading is not None and ds.heading.t.size >= 3:
        ref = (ds.heading.t, ds.heading.heading, f"{recipe.paths.heading} ('heading_deg')")
    elif course is not None:
        ref = (course[0], course[1], f"the GNSS course of {recipe.paths.gnss_solution or recipe.paths.gnss_pos}")
    else:
        ref = (None, None, "")
    check_gyro_unit(imu_path, imu.t, imu.gyro, imu.accel, names_g, recipe.imu.gyro_unit, *ref)
    return warnings


# ----------------------------------------------------------------------------- raw GNSS

# [rtk] options: (low, high, low inclusive, high inclusive); every angle in degrees.
RTK_OPTION_RANGES = {
    "elevation_mask_deg": (0.0, 90.0, True, False),
    "ratio_threshold": (1.0, 1e3, True, True),
    "sigma_code_m": (0.0, 100.0, False, True),
    "sigma_phase_m": (0.0, 1.0, False, True),
    "ambiguity_process_noise_cycles2": (0.0, 1e6, True, True),
    "hold_tolerance_cycles": (0.0, 0.5, False, True),
    "min_fix_satellites": (2, 64, True, True),
    "min_lock_epochs": (1, 10_000, True, True),
}
MAX_BASE_OFFSET_M = 1000.0      # [base] vs the base file header (approximate, ~m)
EPOCH_TOLERANCE_S = 0.025        # base/rover epochs closer than this are common
EPHEMERIS_REACH_S = 4 * 3600.0   # a broadcast ephemeris serves ±2 h of toe (fit 4 h)


def check_rtk_options(options: dict, source) -> None:
    """Type and range of every numeric [rtk] option (an elevation mask of 100° is not a
    mask; 89° is allowed and simply leaves no satellite, which the run reports)."""
    for key, value in options.items():
        if key not in RTK_OPTION_RANGES:
            if key == "continuous" and not isinstance(value, bool):
                _fail(source, f"rtk.continuous: expected true or false, got {value!r}")
            continue
        lo, hi, lo_in, hi_in = RTK_OPTION_RANGES[key]
        integer = isinstance(lo, int)
        ok_type = (isinstance(value, int) if integer else isinstance(value, (int, float))) \
            and not isinstance(value, bool)
        if not ok_type:
            _fail(source, f"rtk.{key}: expected {'an integer' if integer else 'a number'}, "
                          f"got {value!r}")
        v = float(value)
        inside = math.isfinite(v) and (v >= lo if lo_in else v > lo) and \
            (v <= hi if hi_in else v < hi)
        if not inside:
            _fail(source, f"rtk.{key}: {value!r} out of range {'[' if lo_in else '('}{lo:g}, "
                          f"{hi:g}{']' if hi_in else ')'}")


def _gps_date(t_gps: float) -> str:
    import datetime as _dt
    try:
        return (_dt.datetime(1980, 1, 6) + _dt.timedelta(seconds=float(t_gps))).strftime(
            "%Y-%m-%d %H:%M")
    except (OverflowError, ValueError):
        return f"{t_gps:.0f} s"


def check_rtk_inputs(base, rover, nav, base_ecef=None, source=None) -> None:
    """Base and rover have enough and common epochs, the navigation file covers the
    observations (else every epoch would fail with a misleading message), and the [base]
    position is within MAX_BASE_OFFSET_M of the base file's APPROX POSITION XYZ."""
    approx = getattr(base, "approx_position_ecef", None)
    if base_ecef is not None and approx is not None and np.linalg.norm(approx) > 6e6:
        offset = float(np.linalg.norm(np.asarray(base_ecef, float) - approx))
        if offset > MAX_BASE_OFFSET_M:
            _fail(source or base.path, f"base: the [base] position is {offset / 1e3:.6g} km "
                                       f"from the APPROX POSITION XYZ of {base.path} (more "
                                       f"than {MAX_BASE_OFFSET_M / 1e3:g} km)")
    for obs, role in ((rover, "rover"), (base, "base")):
        if obs.t_gps.size < 2:
            _fail(obs.path, f"only {obs.t_gps.size} epoch(s) in the {role} observation file; "
                            "RTK needs at least 2")
    j = np.clip(np.searchsorted(base.t_gps, rover.t_gps), 1, base.t_gps.size - 1)
    near = np.minimum(np.abs(base.t_gps[j - 1] - rover.t_gps), np.abs(base.t_gps[j] - rover.t_gps))
    if not (near <= EPOCH_TOLERANCE_S).any():
        _fail(rover.path, f"no epoch in common with the base file {base.path}: rover "
                          f"{_gps_date(rover.t_gps[0])}..{_gps_date(rover.t_gps[-1])}, base "
                          f"{_gps_date(base.t_gps[0])}..{_gps_date(base.t_gps[-1])} (GPS time)")
    if nav.toe.size == 0:
        _fail(nav.path, "no GPS ephemeris in the navigation file")
    t_eph = np.asarray(nav.toe, float)          # absolute GPS seconds (gnss.rinex.NavData)
    t0, t1 = float(rover.t_gps[0]), float(rover.t_gps[-1])
    reach = (t_eph >= t0 - EPHEMERIS_REACH_S) & (t_eph <= t1 + EPHEMERIS_REACH_S)
    if not reach.any():
        _fail(nav.path, f"the navigation file does not cover the observations: its "
                        f"ephemerides are for {_gps_date(t_eph.min())}..{_gps_date(t_eph.max())}"
                        f", the rover observes {_gps_date(t0)}..{_gps_date(t1)} (GPS time)")


def solved_epochs(sol, solved, what: str, source):
    """The solution restricted to the epochs that have one (``solved`` mask and a finite
    time and at least one satellite): an epoch without a solution is never written as
    one, as RTKLIB writes none. Raises when no epoch is solved."""
    keep = np.asarray(solved, bool) & np.isfinite(sol.t_gps) & (np.asarray(sol.n_sat) > 0)
    for name in ("ecef", "llh"):
        keep &= np.isfinite(getattr(sol, name)).all(axis=1)
    if not keep.any():
        _fail(source, f"{what}: no epoch has a solution ({sol.t_gps.size} epochs, 0 with "
                      "satellites above the elevation mask, common to base and rover and "
                      "with ephemerides); nothing written")
    h = sol.llh[keep, 2]
    bad = (h < HEIGHT_RANGE_M[0]) | (h > HEIGHT_RANGE_M[1])
    if bad.any():
        _fail(source, f"{what}: {int(bad.sum())} solved epochs have a height outside "
                      f"{HEIGHT_RANGE_M[0]:g}..{HEIGHT_RANGE_M[1]:g} m (first {h[bad][0]:.6g} "
                      "m); check the [base] position; nothing written")
    import dataclasses
    n = sol.t_gps.size
    changes = {}
    for f in dataclasses.fields(sol):
        v = getattr(sol, f.name)
        if isinstance(v, np.ndarray) and v.shape[:1] == (n,):
            changes[f.name] = v[keep]
        elif isinstance(v, list) and len(v) == n:
            changes[f.name] = [x for x, k in zip(v, keep) if k]
    return dataclasses.replace(sol, **changes)
