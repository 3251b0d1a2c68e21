"""Shared fixtures: a small, fully valid dataset (IMU, GNSS, heading, reference, recipe)
written into tmp_path from code, which tests then break one thing at a time."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

IMU_RATE_HZ = 100.0
IMU_SAMPLES = 300
T0 = 345600.0
IMU_HEADER = ["time_gps_s", "gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]


def toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    raise TypeError(type(value))


def toml_text(doc: dict) -> str:
    """Minimal TOML writer for {section: {key: value}} documents (test fixtures only)."""
    lines = []
    for section, table in doc.items():
        lines.append(f"[{section}]")
        lines += [f"{key} = {toml_value(value)}" for key, value in table.items()]
        lines.append("")
    return "\n".join(lines)


def imu_rows(n=IMU_SAMPLES, rate=IMU_RATE_HZ, t0=T0) -> np.ndarray:
    """Deterministic IMU table: gyro = [0.1, 0.2, 0.3] + 1e-3·k,
    accel = [0.01, 0.02, 1] + 1e-4·k."""
    k = np.arange(n, dtype=float)
    return np.column_stack([
        t0 + k / rate,
        0.1 + 1e-3 * k, 0.2 + 1e-3 * k, 0.3 + 1e-3 * k,
        0.01 + 1e-4 * k, 0.02 + 1e-4 * k, 1.0 + 1e-4 * k,
    ])


def write_csv_text(path: Path, header, rows, delimiter=",", comments=()) -> Path:
    lines = [f"# {c}" for c in comments]
    if header is not None:
        lines.append(delimiter.join(header))
    lines += [delimiter.join(repr(float(x)) for x in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


class DatasetFiles:
    """A valid dataset folder; ``doc`` is the recipe as a dict to modify before ``write``."""

    def __init__(self, root: Path):
        self.root = root
        self.imu = write_csv_text(root / "imu.csv", IMU_HEADER, imu_rows(),
                                  comments=["synthetic IMU for tests"])
        t_gnss = T0 + np.arange(0.0, 3.0, 0.2)
        lat = 43.7735 + 1e-6 * np.arange(t_gnss.size)
        lon = np.full(t_gnss.size, -79.5019)
        gnss = np.column_stack([t_gnss, lat, lon, np.full(t_gnss.size, 180.0),
                                np.full((t_gnss.size, 3), [0.02, 0.02, 0.05])])
        self.gnss = write_csv_text(root / "gnss.csv", ["time_gps_s", "lat_deg", "lon_deg", "h_m",
                                                       "sigma_e_m", "sigma_n_m", "sigma_u_m"],
                                   gnss)
        self.heading = write_csv_text(root / "heading.csv", ["time_gps_s", "heading_deg"],
                                      np.column_stack([t_gnss, np.full(t_gnss.size, 90.0)]))
        ref = np.column_stack([t_gnss, lat, lon, np.full(t_gnss.size, 179.0),
                               np.zeros((t_gnss.size, 3)), np.full(t_gnss.size, 1.0),
                               np.full(t_gnss.size, -2.0), np.full(t_gnss.size, 90.0)])
        self.reference = write_csv_text(
            root / "reference.csv",
            ["time_gps_s", "lat_deg", "lon_deg", "h_m", "ve_m_s", "vn_m_s", "vu_m_s",
             "pitch_deg", "roll_deg", "heading_deg"], ref)
        self.doc = {
            "dataset": {"name": "unit-test"},
            "paths": {"imu": "imu.csv", "gnss_solution": "gnss.csv", "heading": "heading.csv",
                      "reference": "reference.csv"},
            "imu": {"rate_hz": IMU_RATE_HZ},
            "antennas": {"primary_lever_arm_m": [0.1, 0.2, 1.5]},
        }

    def write(self, doc: dict | None = None, name: str = "recipe.toml") -> Path:
        path = self.root / name
        path.write_text(toml_text(self.doc if doc is None else doc))
        return path

    def modified(self, section: str, **changes) -> dict:
        """A copy of ``doc`` with keys of one section changed (value None deletes a key)."""
        doc = copy.deepcopy(self.doc)
        table = doc.setdefault(section, {})
        for key, value in changes.items():
            if value is None:
                table.pop(key, None)
            else:
                table[key] = value
        return doc


@pytest.fixture
def dataset(tmp_path) -> DatasetFiles:
    return DatasetFiles(tmp_path)
