"""Manufacturer values for the comparison table (001 Table 5-4): a small TOML file

    [gyro]
    random_walk_deg_sqrt_h = 2.0        # angle random walk
    bias_instability_deg_s = 0.007      # or bias_instability_deg_h
    quantization_deg_s = 0.05           # optional
    [accel]
    random_walk_m_s_sqrt_h = 0.2        # velocity random walk
    bias_instability_mg = 0.2
    quantization_mg = 3.33              # optional

converted to the SI coefficients of calibration.allan (N in u·√s, B and Q in u).

The comparison table's "VCE on a drive" row reads the ``[noise]`` table `gmis vce` writes
(tuned_noise.toml, or a recipe): ``gyro_deg_s`` and ``accel_m_s2``, the per-sample 1σ the
GMIKF's IMU rows were tuned to (recipe body axes, at that drive's IMU rate).
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np

from gmis.errors import GmisInputError

DEG = np.pi / 180.0
G0 = 9.80665
KEYS = {
    "gyro": {"random_walk_deg_sqrt_h": ("random_walk", DEG / 60.0),
             "bias_instability_deg_s": ("bias_instability", DEG),
             "bias_instability_deg_h": ("bias_instability", DEG / 3600.0),
             "quantization_deg_s": ("quantization", DEG)},
    "accel": {"random_walk_m_s_sqrt_h": ("random_walk", 1.0 / 60.0),
              "bias_instability_mg": ("bias_instability", G0 * 1e-3),
              "bias_instability_m_s2": ("bias_instability", 1.0),
              "quantization_mg": ("quantization", G0 * 1e-3)},
}


def _read_toml(path: Path) -> dict:
    """The parsed TOML document at path; a missing or unparsable file is a GmisInputError."""
    try:
        return tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise GmisInputError("file not found", source=str(path)) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise GmisInputError(f"not valid TOML ({exc})", source=str(path)) from None


def read_datasheet(path) -> dict:
    path = Path(path)
    doc = _read_toml(path)
    out = {}
    for section, table in doc.items():
        if section not in KEYS or not isinstance(table, dict):
            raise GmisInputError(f"{section}: unknown section; use [gyro] and [accel]",
                                 source=str(path))
        out[section] = {}
        for key, value in table.items():
            if key not in KEYS[section]:
                raise GmisInputError(f"{section}.{key}: unknown key; known: "
                                     + ", ".join(KEYS[section]), source=str(path))
            if not isinstance(value, (int, float)) or not value >= 0:
                raise GmisInputError(f"{section}.{key}: must be a number >= 0",
                                     source=str(path))
            name, scale = KEYS[section][key]
            out[section][name] = float(value) * scale
    return out


def read_vce_noise(path) -> dict:
    """{"gyro": (3,) rad/s, "accel": (3,) m/s²} from the [noise] table of a gmis vce
    fragment; a missing table or key, or a value that is not 3 numbers > 0, is an error."""
    path = Path(path)
    doc = _read_toml(path)
    noise = doc.get("noise")
    if not isinstance(noise, dict):
        raise GmisInputError("noise: no [noise] table (use the tuned_noise.toml of gmis vce)",
                             source=str(path))
    out = {}
    for kind, key, scale in (("gyro", "gyro_deg_s", DEG), ("accel", "accel_m_s2", 1.0)):
        value = noise.get(key)
        if (not isinstance(value, list) or len(value) != 3
                or not all(isinstance(v, (int, float)) and v > 0 for v in value)):
            raise GmisInputError(f"noise.{key}: needs 3 numbers > 0, got {value!r}",
                                 source=str(path))
        out[kind] = np.array(value, dtype=float) * scale
    return out
