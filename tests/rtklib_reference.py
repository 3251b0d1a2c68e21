"""RTKLIB's kinematic reference solution for the tests and benchmarks that compare with it
(rnx2rtkp from the Debian package rtklib). Not part of gnss: a test/benchmark helper."""

import shutil
import subprocess
import time

from gnss.pos_file import read_pos
from tests.shared_data import RTKLIB_TEST

# the shared 0759 (base) / 3040 (rover) session; base = 0759 header APPROX POSITION
BASE_ECEF_0759 = (-3976219.5082, 3382372.5671, 3652512.9849)
ROVER_3040, BASE_0759, NAV_0759 = (RTKLIB_TEST / "30400920.05o", RTKLIB_TEST / "07590920.05o",
                                   RTKLIB_TEST / "07590920.05n")


def run_rnx2rtkp(rover_obs, base_obs, nav, base_ecef, out_pos, timeout_s: float = 120.0,
                 n_frequencies: int = 2):
    """RTKLIB's kinematic reference solution with the settings gmis is compared under
    (rnx2rtkp -p 2 -f 2 -m 15 -v 3.0 -sys G, base position given as ECEF XYZ; -f 1 with
    n_frequencies=1: L1 only) written to out_pos; returns the wall time (s). Needs the
    Debian package rtklib."""
    cmd = ["rnx2rtkp", "-p", "2", "-f", str(int(n_frequencies)), "-m", "15", "-v", "3.0",
           "-sys", "G", "-t",
           "-r", *(f"{v:.4f}" for v in base_ecef), "-o", str(out_pos),
           str(rover_obs), str(base_obs), str(nav)]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, timeout=timeout_s)
    return time.perf_counter() - t0


def without_epoch_near(obs, t: float, tolerance_s: float = 0.025):
    """The ObsData without its epoch nearest to t (s), which must lie within tolerance_s:
    a session in which the other receiver's epoch at t has no partner."""
    import dataclasses

    import numpy as np
    b = int(np.argmin(np.abs(obs.t_gps - t)))
    assert abs(obs.t_gps[b] - t) < tolerance_s
    keep = np.arange(obs.t_gps.size) != b
    per_epoch = ("t_gps", "week", "sow", "C1", "L1", "D1", "S1", "C2", "L2", "D2", "S2",
                 "LLI1", "LLI2")
    return dataclasses.replace(obs, **{k: getattr(obs, k)[keep] for k in per_epoch})


def rtklib_0759_3040_pos(out_dir, n_frequencies: int = 2) -> dict:
    """RTKLIB's solution of the shared 0759/3040 session (read_pos dict) written into
    out_dir (L1+L2, or L1 only with n_frequencies=1); skips the calling test when the data
    or rnx2rtkp are absent."""
    import pytest
    if not RTKLIB_TEST.is_dir():
        pytest.skip(f"real data folder {RTKLIB_TEST} (../shared/data) absent")
    if shutil.which("rnx2rtkp") is None:
        pytest.skip("rnx2rtkp (Debian package rtklib) not installed")
    out = out_dir / "rtklib.pos"
    run_rnx2rtkp(ROVER_3040, BASE_0759, NAV_0759, BASE_ECEF_0759, out,
                 n_frequencies=n_frequencies)
    return read_pos(out)
