"""The smoothed `gmis run` in bounded memory (gmis.smoothed_stream; issue 15 item 2): its
results folder equals the in-memory smoothed run's file for file — record buffers,
forward blocks, backward blocks and output chunks cut anywhere — on a simulated drive
and on the real car drive."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from gmis import run_preparation, smoothed_stream
from gmis.output_folder import MARKER
from gmis.pipeline import run_recipe
from gmis.simulate import simulate_scenario
from tests.simulated_drives import default_scenario_cut

REAL_DRIVE = Path(__file__).resolve().parents[1] / "datasets" / "drive-boulder-0708" / \
    "recipe.toml"
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "drive-boulder-0708"


@pytest.fixture(scope="module")
def short_drive(tmp_path_factory):
    sim = simulate_scenario(default_scenario_cut(70.0), tmp_path_factory.mktemp("drive") / "ds")
    return sim.recipe_path


def _without_timing(summary: dict) -> dict:
    out = {k: v for k, v in summary.items() if k not in ("timing_s", "results_dir")}
    if "smoother" in out:
        out["smoother"] = {k: v for k, v in out["smoother"].items() if "cpu" not in k}
    return out


def _same_folders(a: Path, b: Path):
    names = sorted(p.name for p in a.iterdir())
    assert names == sorted(p.name for p in b.iterdir())
    # no temporary folder left behind (the output marker is the one hidden file)
    assert not any(p.name.startswith(".") and p.name != MARKER for p in b.iterdir())
    for name in names:
        if name != "summary.json":
            assert (a / name).read_bytes() == (b / name).read_bytes(), name
    sa = json.loads((a / "summary.json").read_text())
    sb = json.loads((b / "summary.json").read_text())
    assert list(sa) == list(sb)
    if "smoother" in sa:
        # a sum over chunks of output epochs instead of np.mean of the whole: last digits
        za = sa["smoother"].pop("forward_backward_position_rms_z")
        zb = sb["smoother"].pop("forward_backward_position_rms_z")
        assert zb == pytest.approx(za, rel=1e-12)
    assert _without_timing(sa) == _without_timing(sb)


def _write_rate(recipe: Path, folder: Path, rate_hz: float) -> Path:
    text = recipe.read_text()
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("imu.csv", "gnss.csv", "heading.csv", "reference.csv"):
        text = text.replace(f'"{name}"', f'"{(recipe.parent / name).as_posix()}"')
    text = text.replace("[filter]", f"[filter]\nsmoother_rate_hz = {rate_hz}", 1)
    out = folder / "recipe.toml"
    out.write_text(text)
    return out


@pytest.mark.parametrize("cuts", [(37, 7, 11), (4096, 512, 4096)])
@pytest.mark.parametrize("rate_hz", [10.0, 100.0])
def test_streamed_smoothed_run_equals_in_memory(short_drive, tmp_path, monkeypatch, cuts,
                                                rate_hz):
    chunk, block, out_chunk = cuts
    real = run_preparation.gmikf_config
    monkeypatch.setattr(run_preparation, "gmikf_config",
                        lambda *a, **k: dataclasses.replace(real(*a, **k), chunk=chunk))
    monkeypatch.setattr(smoothed_stream, "BLOCK_OUTPUT_EPOCHS", block)
    monkeypatch.setattr(smoothed_stream, "OUTPUT_CHUNK", out_chunk)
    recipe = _write_rate(Path(short_drive), tmp_path / "recipe", rate_hz) \
        if rate_hz != 10.0 else short_drive
    memory = run_recipe(recipe, tmp_path / "memory", smooth=True, bounded_memory=False)
    streamed = run_recipe(recipe, tmp_path / "streamed", smooth=True)
    _same_folders(tmp_path / "memory", tmp_path / "streamed")
    assert streamed["smoother"]["output_epochs"] == memory["smoother"]["output_epochs"]
    assert memory["smoother"]["output_epochs"] > 3 * block


def test_streamed_smoother_divergence_writes_nothing(short_drive, tmp_path, monkeypatch):
    """A backward filter that fails leaves no results folder (results_directory)."""
    def fail(*args, **kwargs):
        return np.nan, 3
    monkeypatch.setattr(smoothed_stream, "backward_block", fail)
    from gmis.run_filter import FilterDivergedError
    with pytest.raises(FilterDivergedError, match="backward filter of the smoother"):
        run_recipe(short_drive, tmp_path / "res", smooth=True)
    assert not (tmp_path / "res").exists()


@pytest.mark.skipif(not SHARED.exists(), reason="../shared/data/drive-boulder-0708 is absent "
                    "(the real car drive; see ../shared/data/README.md)")
def test_streamed_smoothed_real_drive_equals_in_memory(tmp_path):
    run_recipe(REAL_DRIVE, tmp_path / "memory", smooth=True, bounded_memory=False)
    run_recipe(REAL_DRIVE, tmp_path / "streamed", smooth=True)
    _same_folders(tmp_path / "memory", tmp_path / "streamed")


def _late_errors(path: Path):
    """(horizontal RMS (m), mean NEES of r / v^b / θ) of errors.csv 10 s after its start."""
    a = np.genfromtxt(path, delimiter=",", names=True)
    late = a["time_gps_s"] >= a["time_gps_s"][0] + 10.0
    h = np.hypot(a["de_m"], a["dn_m"])[late]
    return float(np.sqrt(np.mean(h ** 2))), [float(a[f"nees_{k}"][late].mean()) for k in
                                             ("position", "velocity_body", "attitude")]


def test_speed_course_rows_are_smoothed(tmp_path):
    """A receiver that logs speed/course instead of an ENU velocity (white fixes, no
    latency: the filter's model), drive starting at 15 m/s: the smoother takes the rows
    (the backward filter reads them at its own epochs), the smoothed solution beats the
    forward one on every seed, σ_s ≤ σ_f, the mean NEES over 3 seeds stays in the band
    the forward filter is held to (tests/test_consumer_receiver.py), and the streamed
    folder equals the in-memory one."""
    from gmis.simulate.consumer_receiver import ConsumerReceiver, write_consumer_receiver
    from tests.test_consumer_receiver import SCENARIO

    (tmp_path / "s.toml").write_text(SCENARIO)
    white = ConsumerReceiver(error_sigma_m=(0.0, 0.0, 0.0), latency_s=0.0)
    nees = []
    for seed in (4, 5, 6):
        sim = simulate_scenario(tmp_path / "s.toml", tmp_path / f"d{seed}", seed=seed)
        write_consumer_receiver(sim, white, seed + 73)
        summary = run_recipe(sim.recipe_path, tmp_path / f"o{seed}", smooth=True)
        assert summary["smoother"]["max_sigma_ratio_smoothed_over_forward"] <= 1.0
        smoothed, z = _late_errors(tmp_path / f"o{seed}" / "errors.csv")
        forward, _ = _late_errors(tmp_path / f"o{seed}" / "errors_forward.csv")
        assert smoothed < 0.75 * forward, (seed, smoothed, forward)
        nees.append(z)
        if seed == 4:
            run_recipe(sim.recipe_path, tmp_path / "memory", smooth=True, bounded_memory=False)
            _same_folders(tmp_path / "memory", tmp_path / "o4")
    mean = np.mean(nees, axis=0)
    assert np.all((mean > 1.5) & (mean < 4.5)), mean


def test_reference_shorter_than_the_drive(tmp_path):
    """Record buffers and output chunks wholly after the reference's end (a streamed
    chunk with no compared epoch once raised in np.interp): forward and smoothed runs
    equal the in-memory ones."""
    sim = simulate_scenario(default_scenario_cut(110.0), tmp_path / "ds")
    path = Path(sim.recipe_path).parent / "reference.csv"
    lines = path.read_text().splitlines()
    t0 = float(lines[1].split(",")[0])
    path.write_text("\n".join([lines[0]] + [x for x in lines[1:]
                                             if float(x.split(",")[0]) <= t0 + 35.0]) + "\n")
    for smooth in (False, True):
        run_recipe(sim.recipe_path, tmp_path / f"memory{smooth}", smooth=smooth,
                   bounded_memory=False)
        run_recipe(sim.recipe_path, tmp_path / f"streamed{smooth}", smooth=smooth)
        _same_folders(tmp_path / f"memory{smooth}", tmp_path / f"streamed{smooth}")


def test_low_output_rates_cut_backward_blocks_by_epochs(short_drive, tmp_path, monkeypatch):
    """At 0.5 Hz output a block of BLOCK_OUTPUT_EPOCHS output epochs would span 100,000
    IMU epochs of scratch records: MAX_BLOCK_EPOCHS cuts it (here to 150 epochs, one or
    two output epochs per block); the folder is the in-memory run's."""
    monkeypatch.setattr(smoothed_stream, "MAX_BLOCK_EPOCHS", 150)
    sizes = []
    real = smoothed_stream._record_buffers
    monkeypatch.setattr(smoothed_stream, "_record_buffers",
                        lambda length, *a: sizes.append(length) or real(length, *a))
    recipe = _write_rate(Path(short_drive), tmp_path / "recipe", 0.5)
    run_recipe(recipe, tmp_path / "memory", smooth=True, bounded_memory=False)
    run_recipe(recipe, tmp_path / "streamed", smooth=True)
    _same_folders(tmp_path / "memory", tmp_path / "streamed")
    assert len(sizes) > 10 and max(sizes) <= 2 * 202 + 2


def test_no_fix_epochs_means_no_gnss_aided_rows():
    from gmis.run_statistics import recently_fixed_rows
    errs = {"idx": np.arange(5), "t": np.arange(5.0)}
    keep = recently_fixed_rows(errs, np.arange(5.0), np.zeros(5, dtype=bool))
    assert not keep(0, 5).any()
    keep = recently_fixed_rows(errs, np.arange(5.0), np.array([0, 0, 1, 0, 0], dtype=bool))
    assert keep(0, 5).tolist() == [False, False, True, True, False]
