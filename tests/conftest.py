"""Shared fixtures: a small, fully valid dataset (IMU, GNSS, heading, reference, recipe)
written into tmp_path from code, which tests then break one thing at a time."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

# Order of the test files under pytest-xdist (`-n auto --dist loadfile`; see
# pytest_collection_modifyitems): the cold compile of the GMIKF kernel (~95 s CPU) is paid by
# the first test that runs it on each worker. So one worker starts with KERNEL_FIRST, which
# compiles it into numba's on-disk cache, while the other runs the files below, which never
# call that kernel (checked with a probe plugin over the whole list: 532 tests, no
# gmikf_chunk / errins_chunk signature), and later loads the kernel from the cache instead
# of compiling it a second time. A file wrongly listed only costs time, never a result.
KERNEL_FIRST = "test_lockout_recovery"
WITHOUT_GMIKF_KERNEL = (
    "test_bias_model_recipe", "test_calibration_allan", "test_calibration_despike",
    "test_calibration_filter_inputs", "test_calibration_gmwm",
    "test_calibration_multisignal", "test_calibration_processes",
    "test_calibration_robust", "test_calibration_scale_selection",
    "test_calibration_wv_covariance", "test_consumer_recipe_keys", "test_cycle_slips",
    "test_double_difference", "test_ephemeris", "test_frames", "test_fuzz_readers",
    "test_gnss_sigma_and_time", "test_gnss_standalone", "test_heading", "test_imu_clock",
    "test_imu_noise_floor", "test_lambda", "test_measurement_models", "test_mounting",
    "test_pos_sigma_honest", "test_raw_gnss", "test_reader_corpus", "test_readers",
    "test_readers_blocks", "test_readers_rtklib", "test_rinex", "test_rtk",
    "test_rtk_recipe", "test_simulator", "test_simulator_noise", "test_solution_antenna",
    "test_sp3", "test_speed_course", "test_spp", "test_stream_sigma_scale",
)

# The rest starts with the files that took longest in CI (30-140 s each), so that no long
# file is left running alone on one worker at the end (longest-first scheduling).
LONGEST_FIRST = ("test_tc", "test_tc_tdcp", "test_tc_troposphere", "test_smoother",
                 "test_calibration_job", "test_batch", "test_report", "test_bad_inputs",
                 "test_nhc_offset_estimation", "test_streamed_run")

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


def pytest_configure(config):
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False     # keep the order below (pytest-xdist)


def pytest_collection_modifyitems(session, config, items):
    """KERNEL_FIRST, then the files without the GMIKF kernel, then the rest, LONGEST_FIRST
    leading (the comments above); otherwise files by decreasing number of tests, as
    pytest-xdist's own reordering would."""
    by_file: dict[str, list] = {}
    for item in items:
        by_file.setdefault(item.path.stem, []).append(item)

    def rank(stem):
        group = 0 if stem == KERNEL_FIRST else 1 if stem in WITHOUT_GMIKF_KERNEL else 2
        longest = LONGEST_FIRST.index(stem) if stem in LONGEST_FIRST else len(LONGEST_FIRST)
        return group, longest, -len(by_file[stem])
    items[:] = [item for stem in sorted(by_file, key=rank) for item in by_file[stem]]
