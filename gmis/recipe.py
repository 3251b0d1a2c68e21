"""Dataset recipe: the TOML file that says where a dataset's files are and how to read them.

The format is specified in docs/formats.md; this module is its single implementation.
Validation is strict: every problem raises :class:`gmis.errors.GmisInputError` naming the
recipe file and the dotted key (``noise.gyro_deg_s``). Inside the returned :class:`Recipe`
every quantity is SI / radians and every field name carries its unit
(``gyro_sigma_rad_s``); degrees only live in the TOML file.

Every [noise] value (TOML key, unit, default, engine slot, VCE component) is declared once
in gmis.noise_registry; the recipe translates into engine configs in gmis.engine_configs.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gmis.errors import GmisInputError
from gmis.filter_defaults import IMU_OUTLIER_TEST, OUTLIER_ALPHA, REOPEN_AFTER_EPOCHS
from gmis.noise_registry import BIAS_MODEL_KEYS, BIAS_MODELS, BY_TOML_KEY, DEG, NOISE, NOISE_VALUES
from gmis.outage_windows import OutagesSection, parse_outages_table
from gmis.toml_table import TomlTable, suggest, type_name

STANDARD_GRAVITY = 9.80665  # m/s² per g (used for accel_unit = "g")

Vec3 = tuple[float, float, float]

# Unit name → factor to SI. Aliases are accepted; the first name of each family is canonical.
GYRO_RATE_UNITS = {"rad/s": 1.0, "deg/s": DEG, "deg/h": DEG / 3600.0, "deg/hr": DEG / 3600.0}
ACCEL_RATE_UNITS = {"m/s^2": 1.0, "m/s2": 1.0, "m/s²": 1.0, "g": STANDARD_GRAVITY}
GYRO_INCREMENT_UNITS = {"rad": 1.0, "deg": DEG}
ACCEL_INCREMENT_UNITS = {"m/s": 1.0}
AXIS_NAMES = ("x", "y", "z")


# ----------------------------------------------------------------------------- sections


@dataclass(frozen=True)
class DatasetSection:
    name: str
    description: str = ""


@dataclass(frozen=True)
class PathsSection:
    """Absolute paths (resolved relative to the recipe file); None when not given."""

    imu: Path | None  # None only in a GNSS-only recipe
    gnss_solution: Path | None = None
    gnss_pos: Path | None = None  # RTKLIB .pos instead of gnss_solution (gmis.readers_rtklib)
    imu_tag: Path | None = None  # RTKLIB .tag of the IMU log ([imu].time_base = "tag")
    heading: Path | None = None
    reference: Path | None = None
    rover_obs: Path | None = None
    base_obs: Path | None = None
    heading_obs: Path | None = None
    nav: Path | None = None
    noise_override: Path | None = None


@dataclass(frozen=True)
class TimeSection:
    gps_week: int | None = None
    start_gps_s: float | None = None
    end_gps_s: float | None = None


@dataclass(frozen=True)
class GeodeticPoint:
    lat_rad: float
    lon_rad: float
    h_m: float

    def as_tuple(self) -> tuple[float, float, float]:
        return (self.lat_rad, self.lon_rad, self.h_m)


@dataclass(frozen=True)
class BaseSection:
    """Base station: both geodetic and ECEF forms are filled whichever one the file gave."""

    llh: GeodeticPoint
    ecef_m: Vec3


@dataclass(frozen=True)
class ImuSection:
    rate_hz: float
    format: str = "rate"  # "rate" | "increment"
    gyro_unit: str = "rad/s"
    accel_unit: str = "m/s^2"
    delimiter: str = ","  # "," | "whitespace"
    time_column: str | int = "time_gps_s"
    gyro_columns: tuple[str | int, str | int, str | int] = ("gyro_x", "gyro_y", "gyro_z")
    accel_columns: tuple[str | int, str | int, str | int] = ("accel_x", "accel_y", "accel_z")
    axes: tuple[str, str, str] = ("x", "y", "z")
    time_base: str = "gps"  # "gps" | "gps_1980" | "unix_utc" | "tag" (docs/formats.md)
    time_offset_s: float = 0.0  # added to every IMU time after the time-base conversion
    uniform_clock: bool = True  # jittery tags → times of the fitted sample clock (gmis.imu_clock)
    body_frame: str = "RFU"  # frame of mounting_rpy_deg / misalignment_rpy_deg: RFU | FRD
    mounting_rpy_deg: Vec3 = (0.0, 0.0, 0.0)
    misalignment_rpy_deg: Vec3 = (0.0, 0.0, 0.0)

    @property
    def sensor_to_body(self) -> np.ndarray:
        """C with body_RFU = C @ sensor: axes, then mounting, then misalignment
        (gmis.mounting.mounting_matrix)."""
        from gmis.mounting import mounting_matrix
        return mounting_matrix(self.axes_matrix, self.mounting_rpy_deg,
                               self.misalignment_rpy_deg, self.body_frame)

    @property
    def gyro_to_si(self) -> float:
        """Factor from the file's gyro unit to rad/s (rate) or rad (increment)."""
        units = GYRO_RATE_UNITS if self.format == "rate" else GYRO_INCREMENT_UNITS
        return units[self.gyro_unit]

    @property
    def accel_to_si(self) -> float:
        """Factor from the file's accel unit to m/s² (rate) or m/s (increment)."""
        units = ACCEL_RATE_UNITS if self.format == "rate" else ACCEL_INCREMENT_UNITS
        return units[self.accel_unit]

    @property
    def axes_matrix(self) -> np.ndarray:
        """M (3×3 signed permutation, det +1) with body_RFU = M @ sensor."""
        return axes_matrix(self.axes)


@dataclass(frozen=True)
class GnssSection:
    """[gnss]: time base of the GNSS solution CSV and the receiver's latency."""

    time_base: str = "gps"  # of [paths].gnss_solution: "gps" | "gps_1980" | "unix_utc"
    time_offset_s: float = 0.0  # added to every GNSS time after the time-base conversion
    #                             (a fix stamped 0.1 s late: -0.1); also to a .pos file
    # estimate the time offset from the data (gmis.latency_estimation): profile search
    # within time_offset_s ± time_offset_search_s, the estimate replaces time_offset_s
    estimate_time_offset: bool = False
    time_offset_search_s: float = 0.3
    # added to the velocity's times only (on top of time_offset_s): a receiver whose
    # velocity lags its position (u-blox: 0.15 s on the Boulder drive) — s, late = negative
    velocity_time_offset_s: float = 0.0
    # estimate that offset from the solution itself (gmis.gnss_velocity_lag: velocity
    # against the positions' central difference, searched within velocity_time_offset_s
    # ± 0.5 s); the estimate replaces velocity_time_offset_s
    estimate_velocity_time_offset: bool = False
    # speed/course (gmis.speed_course): the course of epochs slower than this is not used
    course_min_speed_m_s: float = 1.0
    # time-correlated fix errors (gmis.gnss_error_states): first-order Gauss-Markov states
    # with this correlation time (s, 0 = white fixes) and stationary 1σ (m, E N U); the
    # per-epoch σ of the file / [noise] is then the white part
    error_correlation_time_s: float = 0.0
    error_sigma_m: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class AntennaSection:
    """Lever arms IMU centre → antenna in body RFU (converted from [antennas].frame)."""

    primary_lever_arm_m: Vec3 = (0.0, 0.0, 0.0)
    secondary_lever_arm_m: Vec3 | None = None


@dataclass(frozen=True)
class GnssPosSection:
    """[gnss_pos]: quality policy of an RTKLIB .pos input. q_sigma_factor[Q-1] multiplies
    the σ of an epoch of quality Q (1 fix, 2 float, 3 sbas, 4 dgps, 5 single, 6 ppp);
    0 excludes the epoch."""

    q_sigma_factor: tuple[float, ...] = (1.0, 3.0, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class FilterSection:
    mode: str = "loose"  # "loose" | "tight"
    states: int = 27  # 21 | 27
    static_alignment_s: float = 60.0
    outlier_alpha: float = OUTLIER_ALPHA
    tc_velocity_observable: str = "doppler"  # "doppler" | "tdcp" (tight mode, 4th DD group)
    tc_troposphere: str = "hydrostatic"  # "hydrostatic" | "none": rover − base SD correction
    reopen_after_epochs: int = REOPEN_AFTER_EPOCHS  # lock-out recovery (0 = never)
    imu_noise_from_static: bool = True  # IMU σ ≥ the noise measured in the static window
    imu_outlier_test: bool = IMU_OUTLIER_TEST  # the IMU rows take part in the outlier tests
    smoother: str = "none"  # "none" | "two_filter" (gmis.smoother; loose mode only)
    smoother_rate_hz: float = 10.0  # smoothed output epochs per second (gmis.smoother)


@dataclass(frozen=True)
class NonholonomicSection:
    """Land-vehicle non-holonomic constraint (000 eq. 5.41-5.43): the velocity of the
    constraint point (IMU + lever_arm_m, body RFU) has zero lateral (body x) and vertical
    (body z) components, applied as a pseudo-measurement every 1/rate_hz s. Units: m/s,
    Hz, m. The sigmas stand for the real violation (sideslip, suspension) and for its time
    correlation: the update rate and sigma together set how hard the constraint is."""

    sigma_lateral_m_s: float = 0.1
    sigma_vertical_m_s: float = 0.1
    rate_hz: float = 2.0
    lever_arm_m: Vec3 = (0.0, 0.0, 0.0)
    # estimate lever_arm_m[1] (the point's forward offset) from the data within
    # lever_arm_m[1] ± lever_arm_search_m (gmis.nhc_offset_estimation)
    estimate_lever_arm: bool = False
    lever_arm_search_m: float = 2.0


@dataclass(frozen=True)
class ZuptSection:
    """Zero-velocity / zero-angular-rate updates at stops (000 eq. 5.44-5.46; gmis.motion
    stop detection). σ of v^b (m/s) and ω (deg/s in the TOML, rad/s here), applied every
    1/rate_hz s while stopped; thresholds of gmis.motion.StopDetector (window s, |f| spread
    m/s², mean rate deg/s in the TOML, GNSS speed m/s). Thresholds not given (None) follow
    the IMU noise of [noise] (gmis.engine_configs.gmikf_config)."""

    sigma_velocity_m_s: float = 0.01
    sigma_rate_rad_s: float = math.radians(0.01)
    rate_hz: float = 10.0
    window_s: float = 1.0
    accel_std_threshold_m_s2: float | None = None
    gyro_threshold_rad_s: float | None = None
    gnss_speed_threshold_m_s: float = 0.2


@dataclass(frozen=True)
class NoiseSection:
    """1σ noises, SI/rad. Process noises are per-step values at the IMU rate (001 §6.2.3).
    Units, TOML keys and defaults: gmis.noise_registry (one entry per field)."""

    jerk_sigma_m_s3: Vec3 = NOISE["jerk_sigma_m_s3"].default
    angular_acceleration_sigma_rad_s2: Vec3 = NOISE["angular_acceleration_sigma_rad_s2"].default
    gyro_sigma_rad_s: Vec3 = NOISE["gyro_sigma_rad_s"].default
    accel_sigma_m_s2: Vec3 = NOISE["accel_sigma_m_s2"].default
    gyro_bias_drift_sigma_rad_s: Vec3 = NOISE["gyro_bias_drift_sigma_rad_s"].default
    accel_bias_drift_sigma_m_s2: Vec3 = NOISE["accel_bias_drift_sigma_m_s2"].default
    gyro_scale_drift_sigma: Vec3 = NOISE["gyro_scale_drift_sigma"].default
    accel_scale_drift_sigma: Vec3 = NOISE["accel_scale_drift_sigma"].default
    heading_sigma_rad: float = NOISE["heading_sigma_rad"].default
    gnss_position_sigma_m: Vec3 = NOISE["gnss_position_sigma_m"].default
    gnss_velocity_sigma_m_s: Vec3 = NOISE["gnss_velocity_sigma_m_s"].default
    # factors on every per-epoch σ of the stream (file or the value above; gmis.readers)
    gnss_position_sigma_scale: float = NOISE["gnss_position_sigma_scale"].default
    gnss_velocity_sigma_scale: float = NOISE["gnss_velocity_sigma_scale"].default
    heading_sigma_scale: float = NOISE["heading_sigma_scale"].default
    gnss_speed_sigma_m_s: float = NOISE["gnss_speed_sigma_m_s"].default
    gnss_course_sigma_rad: float = NOISE["gnss_course_sigma_rad"].default
    code_sigma_m: float = NOISE["code_sigma_m"].default
    phase_l1_sigma_m: float = NOISE["phase_l1_sigma_m"].default
    phase_l2_sigma_m: float = NOISE["phase_l2_sigma_m"].default
    doppler_sigma_m_s: float = NOISE["doppler_sigma_m_s"].default
    tdcp_sigma_m: float = NOISE["tdcp_sigma_m"].default  # a recipe without [noise].tdcp_m
    #                                                      gets its phase_l1_m (load_recipe)
    # Gauss-Markov bias states (τ s, stationary 1σ); zeros: the sensor's bias is a random
    # walk (its drift sigma). [noise].<sensor>_bias_model selects; see the properties below
    gyro_bias_tau_s: Vec3 = NOISE["gyro_bias_tau_s"].default
    gyro_bias_sigma_rad_s: Vec3 = NOISE["gyro_bias_sigma_rad_s"].default
    accel_bias_tau_s: Vec3 = NOISE["accel_bias_tau_s"].default
    accel_bias_sigma_m_s2: Vec3 = NOISE["accel_bias_sigma_m_s2"].default
    # where gyro_deg_s / accel_m_s2 come from: "given" (a datasheet value or a guess: the
    # at-rest floor of gmis.imu_noise_floor applies) or "vce" (estimated from the drive's
    # own residuals by `gmis vce`, which writes it: kept as estimated)
    imu_sigma_source: str = "given"

    @property
    def gyro_bias_model(self) -> str:
        """"gauss_markov" when the gyro Gauss-Markov τ are set, else "random_walk"."""
        return "gauss_markov" if all(t > 0 for t in self.gyro_bias_tau_s) else "random_walk"

    @property
    def accel_bias_model(self) -> str:
        return "gauss_markov" if all(t > 0 for t in self.accel_bias_tau_s) else "random_walk"

    def is_explicit(self, name: str, given=frozenset()) -> bool:
        """True when field ``name`` is in ``given`` (the fields the recipe set,
        Recipe.noise_given) or differs from the registry default: a value a user chose,
        not the RTK-grade default (gmis.readers)."""
        return name in given or getattr(self, name) != NOISE[name].default


@dataclass(frozen=True)
class RtkSection:
    """[rtk]: options of the GNSS-only RTK (gnss.rtk.RtkConfig; `gmis rtk --tight` uses the
    elevation mask and ratio threshold). Units: degrees, m, cycles. None = not given in the
    recipe: the engine's default applies (gmis.engine_configs.rtk_config)."""

    elevation_mask_deg: float | None = None
    ratio_threshold: float | None = None
    sigma_code_m: float | None = None
    sigma_phase_m: float | None = None
    ambiguity_process_noise_cycles2: float | None = None
    continuous: bool | None = None
    hold_tolerance_cycles: float | None = None
    min_fix_satellites: int | None = None
    troposphere: str | None = None   # "hydrostatic" | "none"
    frequencies: tuple | None = None  # ("L1", "L2") | ("L1",)
    partial_ar: bool | None = None
    min_lock_epochs: int | None = None
    min_success_rate: float | None = None  # bootstrapping P_s gate, 0 = off (gnss.rtk)

    def given(self) -> dict:
        """The keys the recipe gave, {RtkConfig field: value}."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if getattr(self, f.name) is not None}


@dataclass(frozen=True)
class InitialSigmaSection:
    position_m: Vec3 = (0.05, 0.05, 0.1)
    velocity_m_s: Vec3 = (0.1, 0.1, 0.1)
    acceleration_m_s2: Vec3 = (0.1, 0.1, 0.1)
    attitude_rad: Vec3 = (1.0 * DEG, 1.0 * DEG, 2.0 * DEG)
    angular_rate_rad_s: Vec3 = (0.1 * DEG,) * 3
    gyro_bias_rad_s: Vec3 = (0.5 * DEG,) * 3
    accel_bias_m_s2: Vec3 = (0.05, 0.05, 0.05)
    gyro_scale: Vec3 = (0.01, 0.01, 0.01)
    accel_scale: Vec3 = (0.01, 0.01, 0.01)


@dataclass(frozen=True)
class Recipe:
    path: Path  # the recipe file, absolute
    dataset: DatasetSection
    paths: PathsSection
    imu: ImuSection | None  # None only in a GNSS-only recipe (load_recipe(gnss_only=True))
    time: TimeSection = field(default_factory=TimeSection)
    origin: GeodeticPoint | None = None
    antennas: AntennaSection = field(default_factory=AntennaSection)
    base: BaseSection | None = None
    filter: FilterSection = field(default_factory=FilterSection)
    noise: NoiseSection = field(default_factory=NoiseSection)
    initial_sigma: InitialSigmaSection = field(default_factory=InitialSigmaSection)
    nonholonomic: NonholonomicSection | None = None  # None: constraint off
    zupt: ZuptSection | None = None  # None: no ZUPT/ZARU
    rtk: RtkSection = field(default_factory=RtkSection)
    gnss_pos: GnssPosSection = field(default_factory=GnssPosSection)
    gnss: GnssSection = field(default_factory=GnssSection)
    outages: OutagesSection = field(default_factory=OutagesSection)
    noise_given: frozenset = frozenset()  # NoiseSection fields the recipe's [noise] set

    @property
    def directory(self) -> Path:
        return self.path.parent

    def origin_llh(self) -> tuple[float, float, float] | None:
        """ENU origin (lat rad, lon rad, h m): [origin] if given, else the base station,
        else None (then the first GNSS fix applies, see gmis.readers.Dataset)."""
        if self.origin is not None:
            return self.origin.as_tuple()
        if self.base is not None:
            return self.base.llh.as_tuple()
        return None

    def with_noise(self, **overrides: Any) -> Recipe:
        """A copy with some :class:`NoiseSection` fields replaced (SI names and units);
        3-vectors accept any length-3 sequence."""
        names = {f.name: f for f in dataclasses.fields(NoiseSection)}
        clean = {}
        for key, value in overrides.items():
            if key not in names:
                raise TypeError(f"with_noise: unknown noise field {key!r}{suggest(key, names)}")
            if key == "imu_sigma_source":
                if value not in IMU_SIGMA_SOURCES:
                    raise ValueError(f"with_noise: imu_sigma_source must be one of "
                                     f"{IMU_SIGMA_SOURCES}, got {value!r}")
                clean[key] = value
            elif isinstance(getattr(self.noise, key), tuple):
                vec = tuple(float(x) for x in np.asarray(value, dtype=float).ravel())
                if len(vec) != 3:
                    raise ValueError(f"with_noise: {key} needs 3 values, got {len(vec)}")
                if not all(math.isfinite(x) and x >= 0.0 for x in vec):
                    raise ValueError(f"with_noise: {key} must be finite and >= 0, got {vec}")
                clean[key] = vec
            else:
                x = float(value)
                if not (math.isfinite(x) and x > 0.0):
                    raise ValueError(f"with_noise: {key} must be finite and > 0, got {x}")
                clean[key] = x
        return dataclasses.replace(self, noise=dataclasses.replace(self.noise, **clean))


# ----------------------------------------------------------------------------- helpers


def axes_matrix(axes) -> np.ndarray:
    """Signed permutation M with body_RFU = M @ sensor for an ``[imu].axes`` list."""
    m = np.zeros((3, 3))
    for i, name in enumerate(axes):
        sign = -1.0 if name.startswith("-") else 1.0
        m[i, AXIS_NAMES.index(name.lstrip("+-"))] = sign
    return m


# ----------------------------------------------------------------------------- sections

_SECTIONS = ("dataset", "paths", "time", "origin", "imu", "antennas", "base", "filter",
             "noise", "initial_sigma", "nonholonomic", "rtk", "gnss_pos", "outages", "zupt",
             "gnss")
_GNSS_ONLY_PATHS = ("rover_obs", "base_obs", "nav")  # what `gmis rtk` needs

_PATH_KEYS = [f.name for f in dataclasses.fields(PathsSection)]

# [initial_sigma] key → (InitialSigmaSection field, factor to SI)
_INITIAL_KEYS = {
    "position_m": ("position_m", 1.0),
    "velocity_m_s": ("velocity_m_s", 1.0),
    "acceleration_m_s2": ("acceleration_m_s2", 1.0),
    "attitude_deg": ("attitude_rad", DEG),
    "angular_rate_deg_s": ("angular_rate_rad_s", DEG),
    "gyro_bias_deg_s": ("gyro_bias_rad_s", DEG),
    "accel_bias_m_s2": ("accel_bias_m_s2", 1.0),
    "gyro_scale": ("gyro_scale", 1.0),
    "accel_scale": ("accel_scale", 1.0),
}


def read_toml(path: Path) -> dict:
    if not path.is_file():
        raise GmisInputError("recipe file not found" if not path.exists()
                             else "recipe path is not a file", source=str(path))
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise GmisInputError(f"not valid TOML: {exc}", source=str(path)) from None
    except UnicodeDecodeError:
        raise GmisInputError("not valid TOML: file is not UTF-8 text", source=str(path)) from None


def _parse_paths(doc, source, base_dir: Path, gnss_only: bool) -> PathsSection:
    sec = TomlTable(doc.get("paths", {}), "paths", source, dict.fromkeys(_PATH_KEYS))
    required = _GNSS_ONLY_PATHS if gnss_only else ("imu",)
    resolved = {}
    for key in _PATH_KEYS:
        rel = sec.string(key, required=key in required)
        if rel is None:
            continue
        if not rel.strip():
            sec.fail(f"paths.{key}", "empty path")
        p = (base_dir / rel).resolve() if not Path(rel).is_absolute() else Path(rel)
        if not p.exists():
            sec.fail(f"paths.{key}", f"file not found: {p}")
        if not p.is_file():
            sec.fail(f"paths.{key}", f"not a file: {p}")
        resolved[key] = p
    if "gnss_pos" in resolved and "gnss_solution" in resolved:
        sec.fail("paths.gnss_pos", "give either gnss_solution (CSV) or gnss_pos (RTKLIB "
                 ".pos), not both")
    return PathsSection(**{"imu": None, **resolved})


def _parse_time(doc, source) -> TimeSection:
    sec = TomlTable(doc.get("time", {}), "time", source,
                   dict.fromkeys(["gps_week", "start_gps_s", "end_gps_s"]))
    t = TimeSection(
        gps_week=sec.integer("gps_week", minimum=0),
        start_gps_s=sec.number("start_gps_s"),
        end_gps_s=sec.number("end_gps_s"),
    )
    if t.start_gps_s is not None and t.end_gps_s is not None and t.start_gps_s >= t.end_gps_s:
        sec.fail("time.end_gps_s",
                 f"end ({t.end_gps_s:.3f}) must be after start_gps_s ({t.start_gps_s:.3f})")
    return t


def _parse_geodetic(sec: TomlTable) -> GeodeticPoint:
    lat = sec.number("lat_deg", required=True, minimum=-90.0, maximum=90.0)
    lon = sec.number("lon_deg", required=True, minimum=-180.0, maximum=360.0)
    h = sec.number("h_m", required=True, minimum=-1000.0, maximum=100000.0)
    if lon > 180.0:
        lon -= 360.0
    return GeodeticPoint(lat * DEG, lon * DEG, h)


def _parse_origin(doc, source) -> GeodeticPoint | None:
    if "origin" not in doc:
        return None
    sec = TomlTable(doc["origin"], "origin", source, dict.fromkeys(["lat_deg", "lon_deg", "h_m"]))
    return _parse_geodetic(sec)


def _parse_base(doc, source) -> BaseSection | None:
    if "base" not in doc:
        return None
    from gmis.earth import ecef_to_geodetic, geodetic_to_ecef

    sec = TomlTable(doc["base"], "base", source,
                   dict.fromkeys(["lat_deg", "lon_deg", "h_m", "ecef_m"]))
    geodetic_keys = [k for k in ("lat_deg", "lon_deg", "h_m") if sec.has(k)]
    if sec.has("ecef_m"):
        if geodetic_keys:
            sec.fail(f"base.{geodetic_keys[0]}", "give either ecef_m or lat_deg/lon_deg/h_m, "
                     "not both")
        xyz = sec.vector("ecef_m")
        radius = math.sqrt(sum(c * c for c in xyz))
        if not 6.30e6 < radius < 6.48e6:
            sec.fail("base.ecef_m", f"point is {radius / 1e3:.1f} km from the earth's centre; "
                     "not an ECEF position near the surface (m)")
        lat, lon, h = ecef_to_geodetic(*xyz)
        return BaseSection(GeodeticPoint(float(lat), float(lon), float(h)), xyz)
    if not geodetic_keys:
        sec.fail("base", "give ecef_m = [x, y, z] or lat_deg, lon_deg, h_m")
    llh = _parse_geodetic(sec)
    xyz = tuple(float(c) for c in geodetic_to_ecef(*llh.as_tuple()))
    return BaseSection(llh, xyz)


def _parse_axes(sec: TomlTable) -> tuple[str, str, str]:
    value = sec.value("axes")
    if value is None:
        return ("x", "y", "z")
    if not isinstance(value, list) or len(value) != 3:
        sec.fail("imu.axes", "expected a list of 3 axis names like [\"x\", \"y\", \"z\"]")
    names = []
    for item in value:
        if not isinstance(item, str) or item.strip().lstrip("+-") not in AXIS_NAMES \
                or len(item.strip()) - len(item.strip().lstrip("+-")) > 1:
            sec.fail("imu.axes", f"invalid axis {item!r}; each entry is x, y or z with an "
                     "optional sign, e.g. [\"-y\", \"x\", \"z\"]")
        names.append(item.strip().lstrip("+"))
    bare = [n.lstrip("-") for n in names]
    if sorted(bare) != list(AXIS_NAMES):
        sec.fail("imu.axes", f"{value} is not a signed permutation of x, y, z "
                 "(each sensor axis must appear exactly once)")
    if np.linalg.det(axes_matrix(names)) < 0:
        sec.fail("imu.axes", f"{value} maps a right-handed sensor to a left-handed frame "
                 "(mirror image); flip the sign of one axis")
    return tuple(names)


def _parse_column_spec(sec: TomlTable, key, default, length=None):
    value = sec.value(key)
    if value is None:
        return default
    items = value if length is not None else [value]
    if length is not None and (not isinstance(value, list) or len(value) != length):
        sec.fail(f"imu.{key}", f"expected a list of {length} column names or 0-based indices")
    out = []
    for item in items:
        if isinstance(item, bool) or not isinstance(item, (str, int)):
            sec.fail(f"imu.{key}", f"column must be a name or a 0-based index, got {item!r}")
        if isinstance(item, int) and item < 0:
            sec.fail(f"imu.{key}", f"column index must be >= 0, got {item}")
        out.append(item)
    return tuple(out) if length is not None else out[0]


def _angles(sec: TomlTable, key: str) -> Vec3:
    """Roll/pitch/yaw (deg), each within ±360."""
    v = sec.vector(key, default=(0.0, 0.0, 0.0), minimum=-360.0)
    if max(v) > 360.0:
        sec.fail(f"imu.{key}", f"angle {max(v)} deg out of range [-360, 360]")
    return v


def _parse_imu(doc, source, gnss_only: bool) -> ImuSection | None:
    keys = [f.name for f in dataclasses.fields(ImuSection)]
    if "imu" not in doc and gnss_only:
        return None
    if "imu" not in doc:
        raise GmisInputError("imu: required section [imu] missing (at least rate_hz)",
                             source=source)
    sec = TomlTable(doc["imu"], "imu", source, dict.fromkeys(keys))
    fmt = sec.string("format", choices=("rate", "increment"), default="rate")
    other = "increment" if fmt == "rate" else "rate"
    other_units = {"rate": (GYRO_RATE_UNITS, ACCEL_RATE_UNITS),
                   "increment": (GYRO_INCREMENT_UNITS, ACCEL_INCREMENT_UNITS)}[other]
    for key, units in zip(("gyro_unit", "accel_unit"), other_units):
        value = sec.table.get(key)
        if isinstance(value, str) and value in units:
            sec.fail(f"imu.{key}", f"{value!r} is a unit for format = \"{other}\" but "
                     f"format = \"{fmt}\"; set [imu].format = \"{other}\" or use one of: "
                     + ", ".join((GYRO_RATE_UNITS if fmt == "rate" else GYRO_INCREMENT_UNITS)
                                 if key == "gyro_unit" else
                                 (ACCEL_RATE_UNITS if fmt == "rate" else ACCEL_INCREMENT_UNITS)))
    if fmt == "rate":
        gyro_unit = sec.string("gyro_unit", choices=tuple(GYRO_RATE_UNITS), default="rad/s")
        accel_unit = sec.string("accel_unit", choices=tuple(ACCEL_RATE_UNITS), default="m/s^2")
    else:
        gyro_unit = sec.string("gyro_unit", choices=tuple(GYRO_INCREMENT_UNITS), default="rad")
        accel_unit = sec.string("accel_unit", choices=tuple(ACCEL_INCREMENT_UNITS),
                                default="m/s")
    imu = ImuSection(
        rate_hz=sec.number("rate_hz", required=True, positive=True),
        format=fmt,
        gyro_unit=gyro_unit,
        accel_unit=accel_unit,
        delimiter=sec.string("delimiter", choices=(",", "whitespace"), default=","),
        time_column=_parse_column_spec(sec, "time_column", "time_gps_s"),
        gyro_columns=_parse_column_spec(sec, "gyro_columns", ImuSection.gyro_columns, 3),
        accel_columns=_parse_column_spec(sec, "accel_columns", ImuSection.accel_columns, 3),
        axes=_parse_axes(sec),
        time_base=sec.string("time_base", choices=("gps", "gps_1980", "unix_utc", "tag"),
                             default="gps"),
        time_offset_s=sec.number("time_offset_s", default=0.0, minimum=-60.0, maximum=60.0),
        uniform_clock=sec.boolean("uniform_clock", default=True),
        body_frame=sec.string("body_frame", choices=("RFU", "FRD"), default="RFU"),
        mounting_rpy_deg=_angles(sec, "mounting_rpy_deg"),
        misalignment_rpy_deg=_angles(sec, "misalignment_rpy_deg"),
    )
    if imu.time_base == "tag":
        return imu
    columns = [imu.time_column, *imu.gyro_columns, *imu.accel_columns]
    if len(set(columns)) != len(columns):
        sec.fail("imu", f"time/gyro/accel columns must be distinct, got {columns}")
    return imu


def _parse_antennas(doc, source, paths: PathsSection, gnss_only: bool) -> AntennaSection:
    sec = TomlTable(doc.get("antennas", {}), "antennas", source,
                   dict.fromkeys(["primary_lever_arm_m", "secondary_lever_arm_m", "frame"]))
    needs_primary = not gnss_only and any(
        p is not None for p in (paths.gnss_solution, paths.gnss_pos, paths.rover_obs))
    frame = sec.string("frame", choices=("RFU", "FRD"), default="RFU")
    from gmis.mounting import frame_to_rfu
    t = frame_to_rfu(frame)

    def rfu(v):
        return None if v is None else tuple(float(x) for x in t @ np.asarray(v, float))

    return AntennaSection(
        primary_lever_arm_m=rfu(sec.vector("primary_lever_arm_m", required=needs_primary,
                                           default=(0.0, 0.0, 0.0))),
        secondary_lever_arm_m=rfu(sec.vector("secondary_lever_arm_m",
                                             required=not gnss_only
                                             and paths.heading_obs is not None)),
    )


def _parse_gnss_pos(doc, source) -> GnssPosSection:
    sec = TomlTable(doc.get("gnss_pos", {}), "gnss_pos", source,
                   dict.fromkeys(["q_sigma_factor"]))
    value = sec.value("q_sigma_factor")
    if value is None:
        return GnssPosSection()
    if not isinstance(value, list) or not 1 <= len(value) <= 6 or any(
            isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
            or v < 0 for v in value):
        sec.fail("gnss_pos.q_sigma_factor", "expected a list of 1 to 6 numbers >= 0 (σ "
                 "factor for Q = 1, 2, ...; 0 excludes that quality)")
    return GnssPosSection(tuple(float(v) for v in value))


def _parse_gnss(doc, source, paths: PathsSection) -> GnssSection:
    sec = TomlTable(doc.get("gnss", {}), "gnss", source,
                   dict.fromkeys(f.name for f in dataclasses.fields(GnssSection)))
    gnss = GnssSection(
        time_base=sec.string("time_base", choices=("gps", "gps_1980", "unix_utc"),
                             default="gps"),
        time_offset_s=sec.number("time_offset_s", default=0.0, minimum=-60.0, maximum=60.0),
        estimate_time_offset=sec.boolean("estimate_time_offset", default=False),
        time_offset_search_s=sec.number("time_offset_search_s", default=0.3, positive=True,
                                        maximum=5.0),
        course_min_speed_m_s=sec.number("course_min_speed_m_s", default=1.0, minimum=0.0),
        velocity_time_offset_s=sec.number("velocity_time_offset_s", default=0.0,
                                          minimum=-5.0, maximum=5.0),
        estimate_velocity_time_offset=sec.boolean("estimate_velocity_time_offset",
                                                  default=False),
        error_correlation_time_s=sec.number("error_correlation_time_s", default=0.0,
                                            minimum=0.0),
        error_sigma_m=tuple(sec.vector("error_sigma_m", default=(0.0, 0.0, 0.0),
                                       minimum=0.0)))
    if (gnss.error_correlation_time_s > 0) != (min(gnss.error_sigma_m) > 0):
        sec.fail("gnss.error_sigma_m" if gnss.error_correlation_time_s > 0 else
                 "gnss.error_correlation_time_s",
                 "error_correlation_time_s > 0 and error_sigma_m > 0 (E N U, m) go together "
                 "(time-correlated fix errors, docs/formats.md)")
    if gnss.time_base != "gps" and paths.gnss_solution is None:
        sec.fail("gnss.time_base", "applies to [paths].gnss_solution (a .pos file carries "
                 "its own time format)")
    return gnss


def _parse_outages(doc, source) -> OutagesSection:
    sec = TomlTable(doc.get("outages", {}), "outages", source)
    return parse_outages_table(sec.table, lambda key, msg: sec.fail(f"outages.{key}", msg))


def _parse_filter(doc, source, paths: PathsSection) -> FilterSection:
    keys = [f.name for f in dataclasses.fields(FilterSection)]
    sec = TomlTable(doc.get("filter", {}), "filter", source, dict.fromkeys(keys))
    filt = FilterSection(
        mode=sec.string("mode", choices=("loose", "tight"), default="loose"),
        states=sec.integer("states", choices=(21, 27), default=27),
        static_alignment_s=sec.number("static_alignment_s", default=60.0, positive=True),
        outlier_alpha=sec.number("outlier_alpha", default=OUTLIER_ALPHA, minimum=0.0,
                                 maximum=0.5),
        tc_velocity_observable=sec.string("tc_velocity_observable",
                                          choices=("doppler", "tdcp"), default="doppler"),
        tc_troposphere=sec.string("tc_troposphere", choices=("hydrostatic", "none"),
                                  default="hydrostatic"),
        reopen_after_epochs=sec.integer("reopen_after_epochs", default=REOPEN_AFTER_EPOCHS,
                                        minimum=0),
        imu_noise_from_static=sec.boolean("imu_noise_from_static", default=True),
        imu_outlier_test=sec.boolean("imu_outlier_test", default=IMU_OUTLIER_TEST),
        smoother=sec.string("smoother", choices=("none", "two_filter"), default="none"),
        smoother_rate_hz=sec.number("smoother_rate_hz", default=10.0, positive=True),
    )
    if filt.smoother != "none" and filt.mode == "tight":
        sec.fail("filter.smoother", "the smoother does not handle the ambiguity states of "
                 "mode \"tight\"; use mode \"loose\" or smoother \"none\"")
    if filt.mode == "tight":
        for key in ("rover_obs", "base_obs", "nav"):
            if getattr(paths, key) is None:
                sec.fail("filter.mode", f"mode \"tight\" needs [paths].{key}")
    return filt


def _parse_nonholonomic(doc, source) -> NonholonomicSection | None:
    if "nonholonomic" not in doc:
        return None
    keys = [f.name for f in dataclasses.fields(NonholonomicSection)]
    sec = TomlTable(doc["nonholonomic"], "nonholonomic", source, dict.fromkeys(keys))
    d = NonholonomicSection()
    return NonholonomicSection(
        sigma_lateral_m_s=sec.number("sigma_lateral_m_s", default=d.sigma_lateral_m_s,
                                     positive=True),
        sigma_vertical_m_s=sec.number("sigma_vertical_m_s", default=d.sigma_vertical_m_s,
                                      positive=True),
        rate_hz=sec.number("rate_hz", default=d.rate_hz, positive=True),
        lever_arm_m=sec.vector("lever_arm_m", default=d.lever_arm_m),
        estimate_lever_arm=sec.boolean("estimate_lever_arm", default=False),
        lever_arm_search_m=sec.number("lever_arm_search_m", default=d.lever_arm_search_m,
                                      positive=True),
    )


def _parse_zupt(doc, source) -> ZuptSection | None:
    if "zupt" not in doc:
        return None
    keys = ("sigma_velocity_m_s", "sigma_rate_deg_s", "rate_hz", "window_s",
            "accel_std_threshold_m_s2", "gyro_threshold_deg_s", "gnss_speed_threshold_m_s")
    sec = TomlTable(doc["zupt"], "zupt", source, dict.fromkeys(keys))
    d = ZuptSection()
    deg = math.pi / 180.0
    return ZuptSection(
        sigma_velocity_m_s=sec.number("sigma_velocity_m_s", default=d.sigma_velocity_m_s,
                                      positive=True),
        sigma_rate_rad_s=sec.number("sigma_rate_deg_s", default=d.sigma_rate_rad_s / deg,
                                    positive=True) * deg,
        rate_hz=sec.number("rate_hz", default=d.rate_hz, positive=True),
        window_s=sec.number("window_s", default=d.window_s, positive=True),
        accel_std_threshold_m_s2=sec.number("accel_std_threshold_m_s2", positive=True),
        gyro_threshold_rad_s=None if not sec.has("gyro_threshold_deg_s") else
        sec.number("gyro_threshold_deg_s", positive=True) * deg,
        gnss_speed_threshold_m_s=sec.number("gnss_speed_threshold_m_s",
                                            default=d.gnss_speed_threshold_m_s, positive=True),
    )


IMU_SIGMA_SOURCES = ("given", "vce")


def _noise_values(table, name: str, source: str) -> dict[str, Any]:
    """[noise] table → {NoiseSection field: SI value} for the keys present."""
    sec = TomlTable(table, name, source,
                    {**BY_TOML_KEY, **{k.model_key: k for k in BIAS_MODEL_KEYS},
                     "imu_sigma_source": None})
    out = {k.model_key: sec.string(k.model_key, choices=BIAS_MODELS)
           for k in BIAS_MODEL_KEYS if sec.has(k.model_key)}
    if sec.has("imu_sigma_source"):
        out["imu_sigma_source"] = sec.string("imu_sigma_source", choices=IMU_SIGMA_SOURCES)
    for value in NOISE_VALUES:
        if not sec.has(value.toml_key):
            continue
        if value.is_vector:
            out[value.name] = sec.vector(value.toml_key,
                                         minimum=0.0 if value.allow_zero else None,
                                         positive=not value.allow_zero, scale=value.to_si)
        else:
            out[value.name] = sec.number(value.toml_key, positive=True) * value.to_si
    return out


def _parse_rtk(doc, source) -> RtkSection:
    keys = [f.name for f in dataclasses.fields(RtkSection)]
    sec = TomlTable(doc.get("rtk", {}), "rtk", source, dict.fromkeys(keys))
    return RtkSection(
        elevation_mask_deg=sec.number("elevation_mask_deg", minimum=0.0, maximum=90.0),
        ratio_threshold=sec.number("ratio_threshold", minimum=1.0),
        sigma_code_m=sec.number("sigma_code_m", positive=True),
        sigma_phase_m=sec.number("sigma_phase_m", positive=True),
        ambiguity_process_noise_cycles2=sec.number("ambiguity_process_noise_cycles2",
                                                   minimum=0.0),
        continuous=sec.boolean("continuous"),
        hold_tolerance_cycles=sec.number("hold_tolerance_cycles", positive=True,
                                         maximum=0.5),
        min_fix_satellites=sec.integer("min_fix_satellites", minimum=2),
        troposphere=sec.string("troposphere", choices=("hydrostatic", "none")),
        frequencies=_rtk_frequencies(sec),
        partial_ar=sec.boolean("partial_ar"),
        min_lock_epochs=sec.integer("min_lock_epochs", minimum=1),
        min_success_rate=sec.number("min_success_rate", minimum=0.0, maximum=0.999999),
    )


def _rtk_frequencies(sec) -> tuple | None:
    """[rtk].frequencies: ["L1", "L2"] (dual, either order) or ["L1"] (single-frequency)."""
    value = sec.value("frequencies")
    if value is None:
        return None
    if not (isinstance(value, list) and all(isinstance(v, str) for v in value)
            and len(set(value)) == len(value) and set(value) in ({"L1", "L2"}, {"L1"})):
        sec.fail_key("frequencies", f'expected ["L1", "L2"] or ["L1"], got {value!r}')
    return ("L1", "L2") if "L2" in value else ("L1",)


def _parse_noise(doc, source, paths: PathsSection) -> NoiseSection:
    values = _noise_values(doc.get("noise", {}), "noise", source)
    if paths.noise_override is not None:
        override_source = str(paths.noise_override)
        override = read_toml(paths.noise_override)
        for key in override:
            if key != "noise":
                raise GmisInputError(f"{key}: a noise override file holds only a [noise] "
                                     "table", source=override_source)
        values.update(_noise_values(override.get("noise", {}), "noise", override_source))
    values.setdefault("tdcp_sigma_m", values.get("phase_l1_sigma_m",
                                                 NoiseSection.phase_l1_sigma_m))
    _check_bias_models(values, source)
    return NoiseSection(**{k: v for k, v in values.items()
                           if k not in {b.model_key for b in BIAS_MODEL_KEYS}})


def _check_bias_models(values: dict, source: str):
    """gauss_markov needs the sensor's τ and stationary σ and no random-walk drift;
    random_walk takes no Gauss-Markov values (docs/formats.md [noise])."""
    for k in BIAS_MODEL_KEYS:
        model = values.get(k.model_key, "random_walk")
        gm_keys = [NOISE[f].toml_key for f in (k.tau, k.sigma)]
        if model == "gauss_markov":
            for f, key in zip((k.tau, k.sigma), gm_keys):
                if f not in values:
                    raise GmisInputError(f"noise.{key}: required with {k.model_key} = "
                                         "\"gauss_markov\" (3 values > 0)", source=source)
            if any(v != 0.0 for v in values.get(k.drift, ())):
                raise GmisInputError(
                    f"noise.{NOISE[k.drift].toml_key}: a random-walk bias drift is not used "
                    f"with {k.model_key} = \"gauss_markov\" (set it to 0 or remove it)",
                    source=source)
        else:
            for f, key in zip((k.tau, k.sigma), gm_keys):
                if f in values:
                    raise GmisInputError(f"noise.{key}: only used with {k.model_key} = "
                                         "\"gauss_markov\" (the bias model is random_walk)",
                                         source=source)


def _noise_given(doc, source, paths: PathsSection) -> frozenset:
    """The NoiseSection fields the recipe's [noise] (or its noise override) sets."""
    given = set(_noise_values(doc.get("noise", {}), "noise", source))
    if paths.noise_override is not None:
        override = read_toml(paths.noise_override).get("noise", {})
        given |= set(_noise_values(override, "noise", str(paths.noise_override)))
    return frozenset(given)


def _parse_initial_sigma(doc, source) -> InitialSigmaSection:
    sec = TomlTable(doc.get("initial_sigma", {}), "initial_sigma", source, _INITIAL_KEYS)
    values = {}
    for key, (field_name, scale) in _INITIAL_KEYS.items():
        if sec.has(key):
            values[field_name] = sec.vector(key, positive=True, scale=scale)
    return InitialSigmaSection(**values)


def load_recipe(path, gnss_only: bool = False) -> Recipe:
    """Read and validate a dataset recipe (docs/formats.md); paths are resolved relative
    to the recipe file and must exist. Raises GmisInputError naming file and key.

    gnss_only: a recipe for `gmis rtk` — [paths] rover_obs, base_obs, nav and [base] are
    required, [imu] / [paths].imu / lever arms are optional (recipe.imu is None without
    [imu]) and [dataset].name defaults to the recipe's folder name; every section given is
    validated as usual."""
    path = Path(path).expanduser().resolve()
    source = str(path)
    doc = read_toml(path)
    for key, value in doc.items():
        if key not in _SECTIONS:
            raise GmisInputError(f"{key}: unknown section [{key}]{suggest(key, _SECTIONS)}; "
                                 "valid sections: " + ", ".join(_SECTIONS), source=source)
        if not isinstance(value, dict):
            raise GmisInputError(f"{key}: expected a table [{key}], got {type_name(value)}",
                                 source=source)
    if "dataset" not in doc and not gnss_only:
        raise GmisInputError("dataset: required section [dataset] missing (needs name)",
                             source=source)
    ds = TomlTable(doc.get("dataset", {}), "dataset", source,
                   dict.fromkeys(["name", "description"]))
    dataset = DatasetSection(  # a GNSS-only recipe is named after its folder by default
        name=ds.string("name", required=not gnss_only, default=path.parent.name),
        description=ds.string("description", default=""))
    if "paths" not in doc:
        needs = ", ".join(_GNSS_ONLY_PATHS) if gnss_only else "imu"
        raise GmisInputError(f"paths: required section [paths] missing (needs {needs})",
                             source=source)
    paths = _parse_paths(doc, source, path.parent, gnss_only)
    if gnss_only and "base" not in doc:
        raise GmisInputError("base: required section [base] (ecef_m or lat_deg/lon_deg/h_m) "
                             "for rtk", source=source)
    recipe = Recipe(
        path=path,
        dataset=dataset,
        paths=paths,
        imu=_parse_imu(doc, source, gnss_only),
        time=_parse_time(doc, source),
        origin=_parse_origin(doc, source),
        antennas=_parse_antennas(doc, source, paths, gnss_only),
        base=_parse_base(doc, source),
        filter=_parse_filter(doc, source, paths),
        noise=_parse_noise(doc, source, paths),
        initial_sigma=_parse_initial_sigma(doc, source),
        nonholonomic=_parse_nonholonomic(doc, source),
        zupt=_parse_zupt(doc, source),
        rtk=_parse_rtk(doc, source),
        gnss_pos=_parse_gnss_pos(doc, source),
        gnss=_parse_gnss(doc, source, paths),
        outages=_parse_outages(doc, source),
        noise_given=_noise_given(doc, source, paths),
    )
    if recipe.imu is not None and (recipe.imu.time_base == "tag") != (paths.imu_tag
                                                                    is not None):
        raise GmisInputError("imu.time_base: time_base = \"tag\" and [paths].imu_tag go "
                             "together (the tick counter is mapped to GPST by the .tag "
                             "file)", source=source)
    g = recipe.gnss
    if recipe.filter.mode == "tight" and (g.error_correlation_time_s > 0
                                          or g.estimate_time_offset
                                          or g.estimate_velocity_time_offset):
        key = "error_correlation_time_s" if g.error_correlation_time_s > 0 \
            else "estimate_time_offset" if g.estimate_time_offset \
            else "estimate_velocity_time_offset"
        raise GmisInputError(f"gnss.{key}: applies to the loosely coupled GNSS solution "
                             "([filter].mode = \"loose\")", source=source)
    if recipe.filter.smoother != "none" and g.error_correlation_time_s > 0:
        raise GmisInputError("gnss.error_correlation_time_s: the two-filter smoother does "
                             "not handle the fix-error states yet; [filter].smoother = "
                             "\"none\"", source=source)
    return recipe


def format_noise_fragment(noise: NoiseSection, comment: str | None = None) -> str:
    """A TOML ``[noise]`` table (recipe units: degrees) holding every value of ``noise``;
    load_recipe reads it back through ``[paths].noise_override`` or pasted into a recipe."""
    lines = []
    if comment:
        lines += [f"# {line}" for line in comment.splitlines()]
    lines.append("[noise]")
    gm_values = set()
    lines.append(f'imu_sigma_source = "{noise.imu_sigma_source}"')
    for k in BIAS_MODEL_KEYS:
        lines.append(f'{k.model_key} = "{getattr(noise, k.model_field)}"')
        if getattr(noise, k.model_field) == "gauss_markov":
            gm_values |= {k.tau, k.sigma}
    for value in NOISE_VALUES:
        if value.engine == "bias_model" and value.name not in gm_values:
            continue
        si = getattr(noise, value.name)
        if value.is_vector:
            text = "[" + ", ".join(repr(float(v) / value.to_si) for v in si) + "]"
        else:
            text = repr(float(si) / value.to_si)
        lines.append(f"{value.toml_key} = {text}")
    return "\n".join(lines) + "\n"
