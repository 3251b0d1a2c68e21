"""Truth checks shared by the tightly coupled tests: fixed DD integers against the
simulator's ambiguities (raw_truth.npz)."""

from pathlib import Path

import numpy as np


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
