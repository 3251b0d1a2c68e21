"""Road-test scenario TOML: parsing and strict validation.

A scenario describes a simulated drive: where and when it starts, the motion segments, the
IMU error model, the GNSS position/velocity solution and the dual-antenna heading. Every
key is checked (unknown keys, wrong types, out-of-range values) and a problem raises
:class:`gmis.errors.GmisInputError` naming the file and the key, e.g.
``default.toml: [[segment]] #3 (turn): rate_deg_s must be > 0, got -5.0``.

The normalised scenario is a plain dict (TOML-serialisable, every default filled in), so
the dataset's ``scenario.toml`` written by the simulator reproduces the run exactly.

Layout (all angles in degrees, times in s, relative times from the scenario start)::

    [scenario]  name, description?, seed, start_gps_s = 345600.0, gps_week = 2400,
                imu_rate_hz (100..200)
    [origin]    lat_deg, lon_deg, h_m
    [initial]   heading_deg = 0, speed_m_s = 0, pitch_deg = 0, roll_deg = 0
    [vehicle]   sideslip_deg_per_m_s2 = 0 (|K| <= 5): sideslip angle β = K·a_lat of the
                deterministic segments, a_lat = heading rate × speed, so the body lateral
                velocity is s·β (gmis.simulate.trajectory); 0 = no sideslip
    [[segment]] type = "static"     duration_s
                type = "accelerate" speed_m_s (target), accel_m_s2 (> 0), ramp_s = 1
                type = "cruise"     duration_s, roll_deg? (target), ramp_s = 2
                type = "turn"       angle_deg (+ = right/clockwise), rate_deg_s (> 0),
                                    bank_deg = 0, ramp_s = 1
                type = "climb"      pitch_deg (target), duration_s, ramp_s = 2
                type = "random"     duration_s, sigma_jerk_m_s3, sigma_angacc_deg_s2
                                    (scalar or 3 per body axis), speed_m_s? (nominal,
                                    default entry speed), reversion_time_s = 5 (0 = none)
    [imu]       grade? (001 Table 4-1 preset) and per-axis overrides (scalar or [x, y, z]):
                gyro_arw_deg_sqrt_h, accel_vrw_m_s_sqrt_h (white-noise densities),
                gyro_bias_deg_h, accel_bias_mg (constant turn-on bias; default drawn
                from N(0, bias instability²) with the seed),
                gyro_scale_ppm, accel_scale_ppm (constant scale factor, default 0),
                gyro_bias_instability_deg_h, accel_bias_instability_mg,
                bias_correlation_time_s = 100 (bias random walk, per-step σ = BS·√(δt/T)),
                gyro_gm_sigma_deg_h, gyro_gm_tau_s, accel_gm_sigma_mg, accel_gm_tau_s
                (optional first-order Gauss-Markov drift; σ = 0 → off),
                gyro_quantization_deg_s, accel_quantization_mg (0 = off)
    [gnss]      rate_hz (1..10, must divide imu_rate_hz), position_sigma_m ([E, N, U]),
                velocity_sigma_m_s, lever_arm_m (body RFU), latency_s = 0 (0..1: every
                fix stamped this late), velocity_latency_s = 0 (0..1: the velocity is the
                antenna's this long before its fix's time, rounded to the IMU period — a
                receiver whose velocity lags its position), [[gnss.outage]] start_s, end_s
    [heading]   rate_hz, sigma_deg, lever_arm_m (secondary antenna), [[heading.outage]]

Random segments must come last (only random segments may follow a random segment): their
end state is stochastic, so no deterministic segment can continue from it smoothly.
"""

import copy
import os
import tomllib

from gmis.errors import GmisInputError
from gmis.simulate.imu_grades import IMU_GRADES
from gmis.simulate.validation import REQUIRED, ScenarioTable, check_rate, nonneg_vec, positive

SEGMENT_KEYS = {
    "static": {"duration_s": ("float", REQUIRED)},
    "accelerate": {"speed_m_s": ("float", REQUIRED), "accel_m_s2": ("float", REQUIRED),
                   "ramp_s": ("float", 1.0)},
    "cruise": {"duration_s": ("float", REQUIRED), "roll_deg": ("float", None),
               "ramp_s": ("float", 2.0)},
    "turn": {"angle_deg": ("float", REQUIRED), "rate_deg_s": ("float", REQUIRED),
             "bank_deg": ("float", 0.0), "ramp_s": ("float", 1.0)},
    "climb": {"pitch_deg": ("float", REQUIRED), "duration_s": ("float", REQUIRED),
              "ramp_s": ("float", 2.0)},
    "random": {"duration_s": ("float", REQUIRED), "sigma_jerk_m_s3": ("vec3", REQUIRED),
               "sigma_angacc_deg_s2": ("vec3", REQUIRED), "speed_m_s": ("float", None),
               "reversion_time_s": ("float", 5.0)},
}

IMU_AXIS_KEYS = (
    "gyro_arw_deg_sqrt_h", "accel_vrw_m_s_sqrt_h", "gyro_bias_deg_h", "accel_bias_mg",
    "gyro_scale_ppm", "accel_scale_ppm", "gyro_bias_instability_deg_h",
    "accel_bias_instability_mg", "gyro_gm_sigma_deg_h", "gyro_gm_tau_s",
    "accel_gm_sigma_mg", "accel_gm_tau_s", "gyro_quantization_deg_s", "accel_quantization_mg",
)


def _outages(sec, key, source):
    out = []
    for i, item in enumerate(sec.get(key, "list", [])):
        o = ScenarioTable(item, f"{sec.name.rstrip(']')}.{key}] #{i + 1}", source)
        start = positive(o, "start_s", o.get("start_s", "float"), allow_zero=True)
        end = o.get("end_s", "float")
        if end <= start:
            o.fail_key("end_s", f"must be > start_s ({start}), got {end}")
        o.done()
        out.append({"start_s": start, "end_s": end})
    return out


def _pop_table(raw, name, source):
    if name not in raw:
        raise GmisInputError(f"[{name}]: section is required", source)
    return raw.pop(name)


def validate_scenario(raw, source="scenario"):
    """Check a raw scenario dict (as parsed from TOML) and return the normalised dict."""
    if not isinstance(raw, dict):
        raise GmisInputError("scenario must be a table", source)
    raw = copy.deepcopy(raw)
    out = {}

    s = ScenarioTable(_pop_table(raw, "scenario", source), "[scenario]", source)
    sc = {"name": s.get("name", "str"), "description": s.get("description", "str", "")}
    seed = s.get("seed", "int")
    if seed < 0:
        s.fail_key("seed", f"must be >= 0, got {seed}")
    sc["seed"] = seed
    sc["start_gps_s"] = positive(s, "start_gps_s", s.get("start_gps_s", "float", 345600.0),
                                  allow_zero=True)
    week = s.get("gps_week", "int", 2400)
    if week < 0:
        s.fail_key("gps_week", f"must be >= 0, got {week}")
    sc["gps_week"] = week
    rate = s.get("imu_rate_hz", "float")
    if not 100.0 <= rate <= 200.0:
        s.fail_key("imu_rate_hz", f"must be within 100..200 Hz, got {rate}")
    sc["imu_rate_hz"] = rate
    s.done()
    out["scenario"] = sc

    o = ScenarioTable(_pop_table(raw, "origin", source), "[origin]", source)
    lat = o.get("lat_deg", "float")
    if abs(lat) > 89.0:
        o.fail_key("lat_deg", f"must be within ±89°, got {lat}")
    lon = o.get("lon_deg", "float")
    if abs(lon) > 180.0:
        o.fail_key("lon_deg", f"must be within ±180°, got {lon}")
    h = o.get("h_m", "float")
    if not -1000.0 <= h <= 10000.0:
        o.fail_key("h_m", f"must be within -1000..10000 m, got {h}")
    o.done()
    out["origin"] = {"lat_deg": lat, "lon_deg": lon, "h_m": h}

    i = ScenarioTable(raw.pop("initial", {}), "[initial]", source)
    init = {"heading_deg": i.get("heading_deg", "float", 0.0),
            "speed_m_s": positive(i, "speed_m_s", i.get("speed_m_s", "float", 0.0), True),
            "pitch_deg": i.get("pitch_deg", "float", 0.0),
            "roll_deg": i.get("roll_deg", "float", 0.0)}
    for key in ("pitch_deg", "roll_deg"):
        if abs(init[key]) > 45.0:
            i.fail_key(key, f"must be within ±45°, got {init[key]}")
    i.done()
    out["initial"] = init

    out["vehicle"] = _vehicle(raw.pop("vehicle", {}), source)
    out["segment"] = _segments(raw.pop("segment", None), source)
    out["imu"] = _imu(raw.pop("imu", {}), source)
    out["gnss"] = _gnss(_pop_table(raw, "gnss", source), sc, source)
    out["heading"] = _heading(_pop_table(raw, "heading", source), sc, source)
    if "raw_gnss" in raw:  # optional: raw GNSS observations (gmis.simulate.raw_gnss)
        from gmis.simulate.raw_gnss import validate_raw_gnss_section
        out["raw_gnss"] = validate_raw_gnss_section(raw.pop("raw_gnss"), sc, source)
    top = ScenarioTable(raw, "top level", source)
    top.done()
    return out


def _vehicle(table, source):
    sec = ScenarioTable(table, "[vehicle]", source)
    k = sec.get("sideslip_deg_per_m_s2", "float", 0.0)
    if abs(k) > 5.0:
        sec.fail_key("sideslip_deg_per_m_s2", f"must be within ±5 °/(m/s²), got {k}")
    sec.done()
    return {"sideslip_deg_per_m_s2": k}


def _segments(items, source):
    if items is None:
        raise GmisInputError("[[segment]]: at least one segment is required", source)
    if not isinstance(items, list) or not items:
        raise GmisInputError("[[segment]] must be a non-empty array of tables", source)
    segments = []
    seen_random = False
    for n, item in enumerate(items):
        where = f"[[segment]] #{n + 1}"
        sec = ScenarioTable(item, where, source)
        kind = sec.get("type", "str")
        if kind not in SEGMENT_KEYS:
            sec.fail_key("type", f"must be one of {', '.join(SEGMENT_KEYS)}, got {kind!r}")
        sec.name = f"{where} ({kind})"
        seg = {"type": kind, "label": sec.get("label", "str", "")}
        for key, (vkind, default) in SEGMENT_KEYS[kind].items():
            value = sec.get(key, vkind, default)
            if value is not None:
                seg[key] = value
        sec.done()
        for key in ("duration_s", "accel_m_s2", "rate_deg_s"):
            if key in seg:
                positive(sec, key, seg[key])
        if "ramp_s" in seg:
            positive(sec, "ramp_s", seg["ramp_s"])
        if "speed_m_s" in seg:
            positive(sec, "speed_m_s", seg["speed_m_s"], allow_zero=True)
            if seg["speed_m_s"] > 70.0:
                sec.fail_key("speed_m_s", f"must be <= 70 m/s for a land vehicle, got "
                         f"{seg['speed_m_s']}")
        if kind == "turn" and seg["angle_deg"] == 0.0:
            sec.fail_key("angle_deg", "must be non-zero")
        for key in ("bank_deg", "roll_deg", "pitch_deg"):
            if key in seg and abs(seg[key]) > 30.0:
                sec.fail_key(key, f"must be within ±30°, got {seg[key]}")
        if kind in ("cruise", "climb") and seg["ramp_s"] > seg["duration_s"]:
            sec.fail_key("ramp_s", f"must be <= duration_s ({seg['duration_s']}), "
                     f"got {seg['ramp_s']}")
        if kind == "random":
            nonneg_vec(sec, "sigma_jerk_m_s3", seg["sigma_jerk_m_s3"])
            nonneg_vec(sec, "sigma_angacc_deg_s2", seg["sigma_angacc_deg_s2"])
            positive(sec, "reversion_time_s", seg["reversion_time_s"], allow_zero=True)
            seen_random = True
        elif seen_random:
            sec.fail_key("type", "cannot follow a random segment (random segments must come last)")
        segments.append(seg)
    return segments


def _imu(table, source):
    sec = ScenarioTable(table, "[imu]", source)
    grade = sec.get("grade", "str", "")
    if grade and grade not in IMU_GRADES:
        sec.fail_key("grade", f"must be one of {', '.join(IMU_GRADES)}, got {grade!r}")
    preset = IMU_GRADES.get(grade, {})
    imu = {"grade": grade}
    for key in IMU_AXIS_KEYS:
        default = preset.get(key)
        if key in ("gyro_bias_deg_h", "accel_bias_mg"):
            default = None  # drawn from the bias instability when absent
        elif key.endswith("_tau_s"):
            default = 3600.0
        elif default is None:
            default = 0.0
        value = sec.get(key, "vec3", None)
        if value is None:
            value = None if default is None else [float(default)] * 3
        elif key not in ("gyro_bias_deg_h", "accel_bias_mg", "gyro_scale_ppm",
                         "accel_scale_ppm"):
            nonneg_vec(sec, key, value)
            if key.endswith("_tau_s") and min(value) <= 0.0:
                sec.fail_key(key, f"must be > 0, got {value}")
        if value is not None:
            imu[key] = value
    imu["bias_correlation_time_s"] = sec.checked("bias_correlation_time_s", "float", positive,
                                                 default=100.0)
    sec.done()
    return imu


def _gnss(table, sc, source):
    sec = ScenarioTable(table, "[gnss]", source)
    g = {"rate_hz": sec.checked("rate_hz", "float", check_rate, 1.0, 10.0, sc["imu_rate_hz"]),
         "position_sigma_m": sec.checked("position_sigma_m", "vec3", nonneg_vec),
         "velocity_sigma_m_s": sec.checked("velocity_sigma_m_s", "vec3", nonneg_vec),
         "lever_arm_m": sec.get("lever_arm_m", "vec3"),
         "latency_s": sec.checked("latency_s", "float", positive, True, default=0.0),
         "velocity_latency_s": sec.checked("velocity_latency_s", "float", positive, True,
                                           default=0.0),
         "outage": _outages(sec, "outage", source)}
    for key in ("latency_s", "velocity_latency_s"):
        if g[key] > 1.0:
            sec.fail_key(key, f"must be <= 1 s, got {g[key]}")
    sec.done()
    return g


def _heading(table, sc, source):
    sec = ScenarioTable(table, "[heading]", source)
    hd = {"rate_hz": sec.checked("rate_hz", "float", check_rate, 0.1, 20.0, sc["imu_rate_hz"]),
          "sigma_deg": sec.checked("sigma_deg", "float", positive, True),
          "lever_arm_m": sec.get("lever_arm_m", "vec3"),
          "outage": _outages(sec, "outage", source)}
    sec.done()
    return hd


def load_scenario(path):
    """Read and validate a scenario TOML file; returns the normalised scenario dict."""
    path = os.fspath(path)
    name = os.path.basename(path)
    try:
        with open(path, "rb") as fh:
            raw = tomllib.load(fh)
    except FileNotFoundError:
        raise GmisInputError("scenario file not found", path) from None
    except OSError as exc:
        raise GmisInputError(f"cannot read scenario file: {exc.strerror}", path) from None
    except tomllib.TOMLDecodeError as exc:
        raise GmisInputError(f"not valid TOML: {exc}", name) from None
    return validate_scenario(raw, name)


def default_scenario_path():
    """Path of the embedded default scenario (gmis/scenarios/default.toml)."""
    return os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                        "scenarios", "default.toml")
