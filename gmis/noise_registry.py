"""The noise registry: every noise value of the recipe, once.

Each :class:`NoiseValue` is one value with ONE name (the gmis.recipe.NoiseSection field,
SI unit in the name), its unit in recipes and reports and the factor to SI, its default
(001 Table 6-2: per-step 1σ at the IMU rate; the table's "m/s³" for the accelerometers
means m/s², see docs/DESIGN.md), its ``[noise]`` TOML key, the engine slot it drives and
the variance component(s) it becomes in VCE (vce.components). Everything that maps a
noise value between TOML, recipe, engine config and VCE reads this table:

  gmis.recipe        [noise] keys, validation, defaults, format_noise_fragment
  gmis.engine_configs  TcConfig fields (``engine == "dd"``)
  vce.components     component names, units, slots (measurement / process / dd)
  vce.tune           tuned sigmas → NoiseSection fields; DD sigmas → TcConfig fields

engine (what ``slots`` holds):
  "imu"      GmikfConfig.imu_sd; slots: the GMIKF measurement slot per axis
             (gmis.gmikf.SLOT_NAMES)
  "process"  GmikfConfig.q_sd; slots: the process-noise component per axis
             (gmis.state.NOISE_NAMES_27)
  "aiding"   default σ of a GNSS/heading file without per-epoch sigmas (gmis.readers);
             slots: the GMIKF measurement slots. Its VCE component is a scale on the
             per-epoch file sigmas.
  "dd"       tightly coupled DD group (gmis.tc.TcConfig); slots: (TcConfig field,);
             ``group`` is the observable group's column in gmis.tc.TcRecords
  "file_scale"  factor on every per-epoch σ of a GNSS/heading stream (the file's, or the
             [noise] "aiding" value when the file has none), applied when the data are read
             (gmis.readers.load_dataset); `gmis vce` writes its aiding scales here
             (times the recipe's), so a tuned fragment carries them; no VCE component
  "bias_model"  first-order Gauss-Markov bias parameters (correlation time τ, stationary
             1σ) read when the sensor's ``[noise].<sensor>_bias_model`` (BIAS_MODELS) is
             "gauss_markov"; they replace that sensor's random-walk bias drift in the
             GMIKF and the error-state INS (gmis.engine_configs); no VCE component
"""

from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import dataclass

DEG = math.pi / 180.0
AXES = ("x", "y", "z")


@dataclass(frozen=True)
class NoiseValue:
    name: str                   # NoiseSection field (SI)
    toml_key: str               # [noise] key, value in `unit`
    unit: str                   # recipe / report unit
    to_si: float                # unit → SI
    default: float | tuple      # SI
    engine: str                 # "imu" | "process" | "aiding" | "dd"
    slots: tuple                # module doc
    vce: tuple                  # VCE component name(s): one per axis, or one
    allow_zero: bool = False    # drift noises may be 0 (switched off)
    group: int | None = None    # dd: observable group (0 code, 1 L1, 2 L2, 3 velocity)

    @property
    def is_vector(self) -> bool:
        return isinstance(self.default, tuple)


def _per_axis(prefix: str) -> tuple:
    return tuple(f"{prefix}_{a}" for a in AXES)


NOISE_VALUES = (
    NoiseValue("jerk_sigma_m_s3", "jerk_m_s3", "m/s^3", 1.0, (72.0, 72.0, 72.0),
               "process", _per_axis("jerk"), _per_axis("jerk")),
    NoiseValue("angular_acceleration_sigma_rad_s2", "angular_acceleration_deg_s2", "deg/s^2",
               DEG, (300.0 * DEG,) * 3, "process", _per_axis("angacc"), _per_axis("angacc")),
    NoiseValue("gyro_sigma_rad_s", "gyro_deg_s", "deg/s", DEG, (0.75 * DEG,) * 3,
               "imu", _per_axis("gyro"), _per_axis("gyro")),
    NoiseValue("accel_sigma_m_s2", "accel_m_s2", "m/s^2", 1.0, (0.16, 0.16, 0.16),
               "imu", _per_axis("accel"), _per_axis("accel")),
    NoiseValue("gyro_bias_drift_sigma_rad_s", "gyro_bias_drift_deg_s", "deg/s", DEG,
               (0.0, 0.0, 0.0), "process", _per_axis("bg_drift"), _per_axis("bg_drift"),
               allow_zero=True),
    NoiseValue("accel_bias_drift_sigma_m_s2", "accel_bias_drift_m_s2", "m/s^2", 1.0,
               (0.0, 0.0, 0.0), "process", _per_axis("ba_drift"), _per_axis("ba_drift"),
               allow_zero=True),
    NoiseValue("gyro_scale_drift_sigma", "gyro_scale_drift", "-", 1.0, (0.0, 0.0, 0.0),
               "process", _per_axis("sg_drift"), _per_axis("sg_drift"), allow_zero=True),
    NoiseValue("accel_scale_drift_sigma", "accel_scale_drift", "-", 1.0, (0.0, 0.0, 0.0),
               "process", _per_axis("sa_drift"), _per_axis("sa_drift"), allow_zero=True),
    NoiseValue("gyro_bias_tau_s", "gyro_bias_tau_s", "s", 1.0, (0.0, 0.0, 0.0), "bias_model",
               _per_axis("bg"), ()),
    NoiseValue("gyro_bias_sigma_rad_s", "gyro_bias_sigma_deg_s", "deg/s", DEG, (0.0, 0.0, 0.0),
               "bias_model", _per_axis("bg"), ()),
    NoiseValue("accel_bias_tau_s", "accel_bias_tau_s", "s", 1.0, (0.0, 0.0, 0.0), "bias_model",
               _per_axis("ba"), ()),
    NoiseValue("accel_bias_sigma_m_s2", "accel_bias_sigma_m_s2", "m/s^2", 1.0, (0.0, 0.0, 0.0),
               "bias_model", _per_axis("ba"), ()),
    NoiseValue("heading_sigma_rad", "heading_deg", "deg", DEG, 0.5 * DEG,
               "aiding", ("heading",), ("heading",)),
    NoiseValue("gnss_position_sigma_m", "gnss_position_m", "m", 1.0, (0.02, 0.02, 0.04),
               "aiding", ("pos_e", "pos_n", "pos_u"), ("gnss_position",)),
    NoiseValue("gnss_velocity_sigma_m_s", "gnss_velocity_m_s", "m/s", 1.0, (0.05, 0.05, 0.1),
               "aiding", ("vel_e", "vel_n", "vel_u"), ("gnss_velocity",)),
    NoiseValue("gnss_position_sigma_scale", "gnss_position_scale", "-", 1.0, 1.0,
               "file_scale", ("gnss_position",), ()),
    NoiseValue("gnss_velocity_sigma_scale", "gnss_velocity_scale", "-", 1.0, 1.0,
               "file_scale", ("gnss_velocity",), ()),
    NoiseValue("heading_sigma_scale", "heading_scale", "-", 1.0, 1.0,
               "file_scale", ("heading",), ()),
    # speed over ground / course of a receiver without vertical velocity (gmis.speed_course)
    NoiseValue("gnss_speed_sigma_m_s", "gnss_speed_m_s", "m/s", 1.0, 0.05, "aiding",
               ("speed",), ("gnss_speed",)),
    NoiseValue("gnss_course_sigma_rad", "gnss_course_deg", "deg", DEG, 0.5 * DEG, "aiding",
               ("course",), ("gnss_course",)),
    NoiseValue("code_sigma_m", "code_m", "m", 1.0, 0.5, "dd", ("sigma_code_m",), ("code",),
               group=0),
    NoiseValue("phase_l1_sigma_m", "phase_l1_m", "m", 1.0, 0.02, "dd", ("sigma_phase_l1_m",),
               ("phase_l1",), group=1),
    NoiseValue("phase_l2_sigma_m", "phase_l2_m", "m", 1.0, 0.02, "dd", ("sigma_phase_l2_m",),
               ("phase_l2",), group=2),
    NoiseValue("doppler_sigma_m_s", "doppler_m_s", "m/s", 1.0, 0.1, "dd",
               ("sigma_doppler_m_s",), ("doppler",), group=3),
    # L1 phase σ90 in a TDCP; a recipe without [noise].tdcp_m gets its phase_l1_m
    NoiseValue("tdcp_sigma_m", "tdcp_m", "m", 1.0, 0.02, "dd", ("sigma_tdcp_m",), ("tdcp",),
               group=3),
)

# [noise].<sensor>_bias_model selects the bias states' model; with "gauss_markov" the
# sensor's Gauss-Markov values are required and its random-walk drift must be 0
BIAS_MODELS = ("random_walk", "gauss_markov")
# (model_field: the gmis.recipe.NoiseSection property derived from the τ values)
BiasModelKeys = namedtuple("BiasModelKeys", "model_key model_field tau sigma drift")
BIAS_MODEL_KEYS = (
    BiasModelKeys("gyro_bias_model", "gyro_bias_model", "gyro_bias_tau_s",
                  "gyro_bias_sigma_rad_s", "gyro_bias_drift_sigma_rad_s"),
    BiasModelKeys("accel_bias_model", "accel_bias_model", "accel_bias_tau_s",
                  "accel_bias_sigma_m_s2", "accel_bias_drift_sigma_m_s2"),
)

NOISE = {v.name: v for v in NOISE_VALUES}
BY_TOML_KEY = {v.toml_key: v for v in NOISE_VALUES}
# VCE component name → (NoiseValue, axis index or None for a one-component value)
BY_COMPONENT = {c: (v, (i if v.is_vector and len(v.vce) == 3 else None))
                for v in NOISE_VALUES for i, c in enumerate(v.vce)}


def noise_default(name: str):
    """SI default of a NoiseSection field."""
    return NOISE[name].default


def values_of(engine: str) -> tuple:
    """The NoiseValues driving one engine slot kind, in registry order."""
    return tuple(v for v in NOISE_VALUES if v.engine == engine)


def tc_sigma_fields() -> dict:
    """NoiseSection field → TcConfig field of the DD groups."""
    return {v.name: v.slots[0] for v in values_of("dd")}


def dd_values(velocity_observable: str) -> tuple:
    """The four DD groups of a tightly coupled run in column order: code, L1, L2 and the
    velocity observable ("doppler" or "tdcp")."""
    groups = [v for v in values_of("dd") if v.group < 3]
    velocity = [v for v in values_of("dd") if v.group == 3 and v.vce[0] == velocity_observable]
    return tuple(groups + velocity)


def velocity_observables() -> tuple:
    return tuple(v.vce[0] for v in values_of("dd") if v.group == 3)


def noise_overrides_from_components(noise, components, sigmas) -> tuple[dict, dict]:
    """Tuned VCE sigmas → (NoiseSection field values in SI for Recipe.with_noise, aiding
    scales {component: factor on the per-epoch file sigmas}). Components the registry
    does not know (the non-holonomic constraint) are left out; a vector value takes the
    recipe's ``noise`` for the axes that were not components."""
    fields, scales = {}, {}
    for comp, sigma in zip(components, sigmas):
        if comp.name not in BY_COMPONENT:
            continue
        value, axis = BY_COMPONENT[comp.name]
        if value.engine == "aiding":
            scales[comp.name] = float(sigma)
        elif axis is None:
            fields[value.name] = float(sigma)
        else:
            vec = fields.setdefault(value.name, list(getattr(noise, value.name)))
            vec[axis] = float(sigma)
    return fields, scales


def apply_aiding_scales(noise, scales: dict):
    """The NoiseSection with each stream's file_scale multiplied by its VCE aiding scale
    ({VCE component: factor on the σ the run used}): the scale then applies to whatever
    per-epoch σ the stream has, the file's or the [noise] value."""
    import dataclasses

    changes = {}
    carried = set()
    for value in values_of("file_scale"):
        s = scales.get(value.slots[0], 1.0)
        changes[value.name] = getattr(noise, value.name) * s
        carried.add(value.slots[0])
    for value in values_of("aiding"):   # no file_scale key (speed, course): the [noise] σ
        if value.vce and value.vce[0] not in carried and value.vce[0] in scales:
            s = scales[value.vce[0]]
            current = getattr(noise, value.name)
            changes[value.name] = (tuple(x * s for x in current) if value.is_vector
                                   else current * s)
    return dataclasses.replace(noise, **changes)


__all__ = ["BIAS_MODELS", "BIAS_MODEL_KEYS", "BY_COMPONENT", "BY_TOML_KEY", "DEG", "NOISE", "NOISE_VALUES", "NoiseValue",
           "apply_aiding_scales", "dd_values", "noise_default",
           "noise_overrides_from_components", "tc_sigma_fields", "values_of",
           "velocity_observables"]
