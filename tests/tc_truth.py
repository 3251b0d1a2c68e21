"""Truth checks shared by the tightly coupled tests: fixed DD integers against the
simulator's ambiguities (raw_truth.npz); the simulated tightly coupled dataset."""

from pathlib import Path

import numpy as np


def simulate_tight_dataset(root, name: str = "tight.toml", filter_lines: str = ""):
    """Simulate the embedded tightly_coupled scenario into root/dataset and write its recipe
    with [filter] mode = "tight" (plus filter_lines) as root/dataset/name. Returns
    (SimulationResult, tight recipe path)."""
    from gmis.simulate import scenario_path, simulate_scenario
    sim = simulate_scenario(scenario_path("tightly_coupled"), Path(root) / "dataset")
    recipe = Path(sim.recipe_path)
    tight = recipe.parent / name
    text = recipe.read_text().replace('mode = "loose"', 'mode = "tight"')
    assert "[filter]" in text
    tight.write_text(text.replace("[filter]", "[filter]\n" + filter_lines) if filter_lines
                     else text)
    return sim, tight


def run_tight_scenario(root, name: str = "tight.toml", filter_lines: str = ""):
    """simulate_tight_dataset, then the tightly coupled run into root/results. Returns
    (SimulationResult, summary, results folder, tight recipe path)."""
    from gmis.pipeline import run_recipe
    sim, tight = simulate_tight_dataset(root, name, filter_lines)
    return sim, run_recipe(tight, Path(root) / "results"), Path(root) / "results", tight


def wrong_dd_integers(dataset_dir, time_offset_s, t_records, fixed):
    """(wrong, checked): DD integers that differ from the simulated truth. fixed: rows
    (g, reference PRN, PRN, frequency 1|2, integer) with g the row of t_records (s, the
    dataset's time base); time_offset_s as in the run summary."""
    with np.load(Path(dataset_dir) / "raw_truth.npz", allow_pickle=True) as raw:
        t_raw = raw["t_gps"] - time_offset_s
        prn = list(raw["prn"])
        sd_amb = {f: raw[f"rover_ambiguity_l{f}"] - raw[f"base_ambiguity_l{f}"] for f in (1, 2)}
    wrong = checked = 0
    for g, ref, p, f, value in fixed:
        e = int(np.argmin(np.abs(t_raw - t_records[g])))
        truth = sd_amb[f][e, prn.index(p)] - sd_amb[f][e, prn.index(ref)]
        wrong += round(truth) != value
        checked += 1
    return wrong, checked


def assert_accuracy_and_consistency(summary, results, position_rms_m=0.02,
                                    heading_rms_deg=0.2):
    """≥ 5-satellite position RMS and heading RMS below the issue's targets, and the mean
    NEES of position, body velocity and attitude (sampled every 10 s of the drive, the
    500-520 s sky blockage excluded) inside the 95 % χ²(3K)/K band."""
    from scipy import stats
    aided = summary["errors_vs_reference_gnss_aided"]
    for axis in "enu":
        assert aided["position"][axis]["rms"] < position_rms_m, aided["position"]
    assert aided["attitude"]["heading"]["rms"] < heading_rms_deg
    err = np.genfromtxt(Path(results) / "errors.csv", delimiter=",", names=True)
    t = err["time_gps_s"] - err["time_gps_s"][0]
    rows = [np.argmin(np.abs(t - s)) for s in np.arange(305.0, 600.0, 10.0)]
    rows = [r for r in rows if not 495 <= t[r] <= 525]
    k = len(rows)
    lo, hi = stats.chi2.ppf([0.025, 0.975], 3 * k) / k
    for name in ("nees_position", "nees_velocity_body", "nees_attitude"):
        assert lo <= err[name][rows].mean() <= hi, name
