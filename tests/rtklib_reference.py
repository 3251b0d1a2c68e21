"""RTKLIB's kinematic reference solution for the tests and benchmarks that compare with it
(rnx2rtkp from the Debian package rtklib). Not part of gnss: a test/benchmark helper."""

import subprocess
import time


def run_rnx2rtkp(rover_obs, base_obs, nav, base_ecef, out_pos, timeout_s: float = 120.0):
    """RTKLIB's kinematic reference solution with the settings gmis is compared under
    (rnx2rtkp -p 2 -f 2 -m 15 -v 3.0 -sys G, base position given as ECEF XYZ) written to
    out_pos; returns the wall time (s). Needs the Debian package rtklib."""
    cmd = ["rnx2rtkp", "-p", "2", "-f", "2", "-m", "15", "-v", "3.0", "-sys", "G", "-t",
           "-r", *(f"{v:.4f}" for v in base_ecef), "-o", str(out_pos),
           str(rover_obs), str(base_obs), str(nav)]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, timeout=timeout_s)
    return time.perf_counter() - t0
