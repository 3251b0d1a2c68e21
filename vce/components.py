"""Variance components of the GMIKF and how they map onto the filter's records.

The grouping follows the measurement models (001 §5.2.1): one component per IMU axis
(3 gyro, 3 accel), one per aiding observable type (GNSS position, GNSS velocity, heading),
one per process-noise axis (3 jerk, 3 angular acceleration) and, switched off by default
(redundancy ~1e-6, 001 Table 5-1), the bias and scale-factor drifts. A component is a set
of measurement slots (gmis.gmikf.SLOT_NAMES) or process-noise indices; its variance is
σ² times a fixed cofactor (the per-epoch file sigmas for GNSS/heading: the component is
then a scale on those sigmas). Names, units and slots of the components that stand for a
recipe noise value come from gmis.noise_registry.
"""

from dataclasses import dataclass

from gmis.gmikf import SLOT_NAMES
from gmis.noise_registry import NOISE, NoiseValue, dd_values, values_of, velocity_observables
from gmis.state import NOISE_NAMES_27, n_noise_for


@dataclass(frozen=True)
class VarianceComponent:
    name: str
    kind: str                 # "measurement" | "process" | "dd" (tightly coupled group)
    index: tuple              # slots (measurement) or noise indices (process)
    unit: str                 # unit of sigma as reported (the recipe's unit)
    to_si: float              # reported unit → SI
    is_scale: bool = False    # True: sigma is a dimensionless scale on per-epoch sigmas
    dynamics: bool = False    # process components paused while stationary


AIDING_SCALE_UNIT = "x file σ"


def _per_axis(value: NoiseValue, kind: str, slot_names, dynamics=False):
    """One component per axis of a registry value (gmis.noise_registry): its slot (or
    process-noise index) in the filter, unit and factor to SI from the registry."""
    return [VarianceComponent(name, kind, (slot_names.index(slot),), value.unit, value.to_si,
                              dynamics=dynamics)
            for name, slot in zip(value.vce, value.slots)]


def _aiding(name: str):
    value = NOISE[name]
    return VarianceComponent(value.vce[0], "measurement",
                             tuple(SLOT_NAMES.index(s) for s in value.slots),
                             AIDING_SCALE_UNIT, 1.0, is_scale=True)


GNSS_ERROR_COMPONENTS = ("gnss_position_error_e", "gnss_position_error_n",
                         "gnss_position_error_u")


def gnss_error_components(n_imu: int):
    """σ_b of the fix-error Gauss-Markov states (gmis.gnss_error_states), one component per
    ENU axis: process components whose noise index is after the IMU's process noise (the
    kernel's VCE axes nw .. nw + 2, state n_imu + i). Their variance σ_b² (1 − e^{−2Δt/τ})
    is linear in σ_b² for the recipe's τ; reported σ is σ_b in m."""
    nw = n_noise_for(n_imu)
    return [VarianceComponent(name, "process", (nw + i,), "m", 1.0)
            for i, name in enumerate(GNSS_ERROR_COMPONENTS)]


def gmikf_components(n_imu: int, has_position=True, has_velocity=True, has_heading=True,
                     include_drifts=False, has_nonholonomic=False, has_zero_motion=False,
                     has_speed_course=False, has_gnss_error_states=False):
    """The components of a loosely coupled GMIKF run, in a fixed order (speed and course,
    gmis.speed_course: one scale each on the per-epoch σ; the fix-error σ_b per axis when
    the run has those states, gnss_error_components)."""
    comps = []
    for value in values_of("imu"):
        comps += _per_axis(value, "measurement", SLOT_NAMES)
    for present, name in ((has_position, "gnss_position_sigma_m"),
                          (has_velocity, "gnss_velocity_sigma_m_s"),
                          (has_heading, "heading_sigma_rad"),
                          (has_speed_course, "gnss_speed_sigma_m_s"),
                          (has_speed_course, "gnss_course_sigma_rad")):
        if present:
            comps.append(_aiding(name))
    if has_nonholonomic:
        comps.append(VarianceComponent("nhc_lateral", "measurement",
                                       (SLOT_NAMES.index("nhc_lateral"),), "m/s", 1.0))
        comps.append(VarianceComponent("nhc_vertical", "measurement",
                                       (SLOT_NAMES.index("nhc_vertical"),), "m/s", 1.0))
    if has_zero_motion:      # ZUPT / ZARU: one component each, the three axes together
        for name, unit in (("zupt", "m/s"), ("zaru", "rad/s")):
            comps.append(VarianceComponent(name, "measurement", tuple(
                SLOT_NAMES.index(f"{name}_{a}") for a in "xyz"), unit, 1.0))
    process = NOISE_NAMES_27[:n_noise_for(n_imu)]
    for value in values_of("process"):
        dynamics = not value.allow_zero      # jerk and angular acceleration
        if dynamics or (include_drifts and value.slots[0] in process):
            comps += _per_axis(value, "process", NOISE_NAMES_27, dynamics=dynamics)
    if has_gnss_error_states and has_position:
        comps += gnss_error_components(n_imu)
    assert all(s < len(SLOT_NAMES) for c in comps if c.kind == "measurement" for s in c.index)
    return comps


def dd_components(velocity_observable: str = "doppler"):
    """The tightly coupled observable groups (001 §5.2.1 θ_z: C/A, L1, L2, and the
    velocity observable: Doppler or time-differenced L1 phase "tdcp"): σ90 of the
    undifferenced observable, the DD covariance σ90²·M (eq. 5.1.8-5.1.11; 2σ²·M for TDCP)
    being its cofactor. index = the group's column in gmis.tc.TcRecords (the velocity
    observable is column 3 either way)."""
    if velocity_observable not in velocity_observables():
        raise ValueError(f"velocity observable must be one of {velocity_observables()}, "
                         f"got {velocity_observable!r}")
    return [VarianceComponent(v.vce[0], "dd", (v.group,), v.unit, 1.0)
            for v in dd_values(velocity_observable)]
