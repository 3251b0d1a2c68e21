"""Variance components of the GMIKF and how they map onto the filter's records.

The grouping follows the measurement models (001 §5.2.1): one component per IMU axis
(3 gyro, 3 accel), one per aiding observable type (GNSS position, GNSS velocity, heading),
one per process-noise axis (3 jerk, 3 angular acceleration) and, switched off by default
(redundancy ~1e-6, 001 Table 5-1), the bias and scale-factor drifts. A component is a set
of measurement slots (gmis.gmikf.SLOT_NAMES) or process-noise indices; its variance is
σ² times a fixed cofactor (the per-epoch file sigmas for GNSS/heading: the component is
then a scale on those sigmas).
"""

from dataclasses import dataclass

from gmis.gmikf import SLOT_NAMES
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


DEG = 3.141592653589793 / 180.0


def gmikf_components(n_imu: int, has_position=True, has_velocity=True, has_heading=True,
                     include_drifts=False, has_nonholonomic=False):
    """The components of a loosely coupled GMIKF run, in a fixed order."""
    comps = []
    for i, axis in enumerate("xyz"):
        comps.append(VarianceComponent(f"gyro_{axis}", "measurement", (i,), "deg/s", DEG))
    for i, axis in enumerate("xyz"):
        comps.append(VarianceComponent(f"accel_{axis}", "measurement", (3 + i,), "m/s^2", 1.0))
    if has_position:
        comps.append(VarianceComponent("gnss_position", "measurement", (6, 7, 8), "x file σ",
                                       1.0, is_scale=True))
    if has_velocity:
        comps.append(VarianceComponent("gnss_velocity", "measurement", (9, 10, 11),
                                       "x file σ", 1.0, is_scale=True))
    if has_heading:
        comps.append(VarianceComponent("heading", "measurement", (12,), "x file σ", 1.0,
                                       is_scale=True))
    if has_nonholonomic:
        comps.append(VarianceComponent("nhc_lateral", "measurement", (13,), "m/s", 1.0))
        comps.append(VarianceComponent("nhc_vertical", "measurement", (14,), "m/s", 1.0))
    for i, axis in enumerate("xyz"):
        comps.append(VarianceComponent(f"jerk_{axis}", "process", (i,), "m/s^3", 1.0,
                                       dynamics=True))
    for i, axis in enumerate("xyz"):
        comps.append(VarianceComponent(f"angacc_{axis}", "process", (3 + i,), "deg/s^2", DEG,
                                       dynamics=True))
    if include_drifts:
        units = {"bg": ("deg/s", DEG), "ba": ("m/s^2", 1.0), "sg": ("-", 1.0), "sa": ("-", 1.0)}
        for k in range(6, n_noise_for(n_imu)):
            name = NOISE_NAMES_27[k]
            unit, f = units[name[:2]]
            comps.append(VarianceComponent(name, "process", (k,), unit, f))
    assert all(s < len(SLOT_NAMES) for c in comps if c.kind == "measurement" for s in c.index)
    return comps


DD_GROUPS = (("code", "m"), ("phase_l1", "m"), ("phase_l2", "m"), ("doppler", "m/s"))
VELOCITY_GROUPS = {"doppler": ("doppler", "m/s"), "tdcp": ("tdcp", "m")}


def dd_components(velocity_observable: str = "doppler"):
    """The tightly coupled observable groups (001 §5.2.1 θ_z: C/A, L1, L2, and the
    velocity observable: Doppler or time-differenced L1 phase "tdcp"): σ90 of the
    undifferenced observable, the DD covariance σ90²·M (eq. 5.1.8-5.1.11; 2σ²·M for TDCP)
    being its cofactor. index = the group's column in gmis.tc.TcRecords (the velocity
    observable is column 3 either way)."""
    if velocity_observable not in VELOCITY_GROUPS:
        raise ValueError(f"velocity observable must be one of {tuple(VELOCITY_GROUPS)}, "
                         f"got {velocity_observable!r}")
    groups = DD_GROUPS[:3] + (VELOCITY_GROUPS[velocity_observable],)
    return [VarianceComponent(name, "dd", (g,), unit, 1.0)
            for g, (name, unit) in enumerate(groups)]
