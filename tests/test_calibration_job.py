"""`gmis calibrate`: outputs of a small run, the one-line error on bad input, real data."""

import gzip
import json
from pathlib import Path

import numpy as np
import pytest

from calibration import processes as P
from gmis.cli import main

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "imu-static-adis16405"


def _write(path, n=2 ** 15, seed=0, gz=False):
    rng = np.random.default_rng(seed)
    cols = [np.arange(n) * 0.01]
    for _ in range(3):
        cols.append(P.simulate(("WN", "RW"), [0.1, 1e-7], n, rng))  # deg/s
    for _ in range(3):
        cols.append(P.simulate(("WN", "AR1"), [1e-6, 0.999, 1e-9], n, rng))  # g
    text = "time_s,gyro_x_deg_s,gyro_y_deg_s,gyro_z_deg_s,accel_x_g,accel_y_g,accel_z_g\n"
    text += "\n".join(",".join(f"{v:.9g}" for v in row) for row in np.column_stack(cols)) + "\n"
    if gz:
        path.write_bytes(gzip.compress(text.encode()))
    else:
        path.write_text(text)
    return path


def test_calibrate_two_replicates_writes_everything(tmp_path):
    files = [str(_write(tmp_path / "a.csv", seed=1)), str(_write(tmp_path / "b.csv.gz", seed=2,
                                                                 gz=True))]
    out = tmp_path / "cal"
    assert main(["calibrate", *files, "-o", str(out), "--model", "WN+AR1+RW", "--quiet"]) == 0
    doc = json.loads((out / "calibration.json").read_text())
    gx = doc["axes"]["gyro_x"]
    assert gx["selected_model"] == "WN+RW"
    wn = next(p for p in gx["awv"]["processes"] if p["process"] == "WN")
    assert wn["sigma2"] == pytest.approx(0.1 * (np.pi / 180) ** 2, rel=0.05)
    assert len(gx["replicates"]) == 2 and "between_replicate_sd" in gx
    used = gx["allan_replicates_used"]              # how many replicates each mean has
    assert set(used) == set(gx["allan"]) and all(0 <= n <= 2 for n in used.values())
    assert all((gx["allan"][k] is None) == (n == 0) for k, n in used.items())
    ax = doc["axes"]["accel_x"]
    ar1 = next(p for p in ax["awv"]["processes"] if p["process"] == "AR1")
    assert ar1["tau_s"] == pytest.approx(-0.01 / np.log(0.999), rel=0.5)
    fragment = (out / "noise_fragment.toml").read_text()
    assert "gyro_deg_s = [" in fragment and "accel_bias_drift_m_s2" in fragment
    sigma = float(fragment.split("gyro_deg_s = [")[1].split(",")[0])
    assert sigma == pytest.approx(np.sqrt(0.1), rel=0.05)
    for name in ("model_selection.csv", "comparison.csv", "figures/gyro_x_wv.png",
                 "figures/accel_z_replicates.png"):
        assert (out / name).is_file()


def test_bad_input_one_line_error_and_no_output(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,gyro_x_deg_s\n" + "\n".join(f"{i * 0.01},{i}" for i in range(40))
                   + "\n0.5,abc\n")
    out = tmp_path / "cal"
    assert main(["calibrate", str(bad), "-o", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("gmis: error: ") and "line 42" in err and "\n" not in err
    assert not out.exists()
    assert main(["calibrate", str(tmp_path / "missing.csv"), "-o", str(out), "--quiet"]) == 2
    assert main(["calibrate", str(bad), "--model", "WN+WN", "-o", str(out), "--quiet"]) == 2
    assert not out.exists()


@pytest.mark.slow
@pytest.mark.skipif(not DATA.is_dir(), reason="../shared/data/imu-static-adis16405 not present")
def test_real_adis16405_gyro_arw_near_measured(tmp_path):
    from calibration.job import calibrate

    files = sorted(str(p) for p in DATA.glob("*.csv.gz"))[:2]
    summary = calibrate(files, tmp_path / "cal", largest="WN+QN+AR1+RW", axes=["gyro_x"])
    # the data README: ADEV(1 s) ≈ 0.041 deg/s, i.e. ARW ≈ 2.4 deg/√h (datasheet 2)
    assert summary["gyro_x"]["allan_random_walk"] == pytest.approx(2.4, rel=0.15)


def test_min_scale_and_horizon_reach_the_fit_and_the_bias_state(tmp_path, capsys):
    """--min-scale drops the first wavelet scales from every fit (τ range reported);
    --horizon is the Gauss-Markov over-bound's lag range; a horizon not above the IMU
    interval is one error line."""
    f = str(_write(tmp_path / "a.csv", n=2 ** 14, seed=3))
    out = tmp_path / "cal"
    assert main(["calibrate", f, "-o", str(out), "--model", "WN+AR1", "--no-select",
                 "--min-scale", "0.08", "--horizon", "120", "--quiet"]) == 0
    doc = json.loads((out / "calibration.json").read_text())
    fit = doc["axes"]["accel_x"]["fit"]
    assert fit["tau_range_s"][0] == pytest.approx(0.08)
    assert doc["min_scale_s"] == 0.08 and doc["bias_horizon_s"] == 120.0
    assert main(["calibrate", f, "-o", str(tmp_path / "c2"), "--horizon", "0.001",
                 "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("gmis: error: --horizon: must exceed the IMU interval")


def test_a_record_that_moves_is_flagged():
    """Calibrating a drive's IMU ran to completion without a word (helper review
    2026-12-06): a record whose 10-s means of |f| or of the rate change is named."""
    from calibration.job import not_static
    from calibration.records import StaticRecord

    rng = np.random.default_rng(1)
    n, dt = 6000, 0.01
    axes = {f"gyro_{a}": rng.normal(0, 0.01, n) for a in "xyz"}
    axes |= {f"accel_{a}": rng.normal(0, 0.05, n) + (9.81 if a == "z" else 0.0) for a in "xyz"}
    units = dict.fromkeys(axes, "si")
    assert not_static(StaticRecord("still.csv", dt, axes, units)) is None
    moving = dict(axes)
    moving["accel_x"] = axes["accel_x"] + np.where(np.arange(n) > 3000, 3.0, 0.0)
    moving["gyro_z"] = axes["gyro_z"] + np.where(np.arange(n) > 4000, 0.3, 0.0)
    note = not_static(StaticRecord("drive.csv", dt, moving, units))
    assert note.startswith("drive.csv: not a static record") and "deg/s" in note
