"""Tightly coupled GMIKF with DD time-differenced L1 phase (TDCP) as the velocity observable
([filter].tc_velocity_observable = "tdcp") on the simulated tightly_coupled scenario: fix
rate, correct integers, accuracy with ≥ 5 satellites, heading, NEES, the TDCP group's
variance factor and VCE recovery of its σ; plus the epoch pairing rules of the filter."""


import numpy as np
import pytest

from gmis.earth import make_nav_frame
from gmis.errors import GmisInputError
from gmis.tc_epochs import TcEpoch
from gmis.tc_filter import TcConfig, TcFilter
from tests.tc_truth import assert_accuracy_and_consistency, run_tight_scenario, wrong_dd_integers


@pytest.fixture(scope="module")
def tdcp_run(tmp_path_factory):
    return run_tight_scenario(tmp_path_factory.mktemp("tdcp"), "tight_tdcp.toml",
                              'tc_velocity_observable = "tdcp"')


def test_tdcp_group_is_named_used_and_fixes_stay_correct(tdcp_run):
    sim, summary, results, _ = tdcp_run
    tc = summary["tightly_coupled"]
    assert tc["velocity_observable"] == "tdcp"
    assert set(tc["sigma0_sq"]) == {"code", "phase_l1", "phase_l2", "tdcp"}
    rec = np.load(results / "tc_records.npz")
    assert list(rec["group_names"]) == ["code", "phase_l1", "phase_l2", "tdcp"]
    # TDCP rows at nearly every epoch (not the first, not across slips)
    assert (rec["n_obs"][:, 3] > 0).mean() > 0.98
    assert tc["fix_rate"] >= 0.99
    table = rec["fixed_integers"]
    assert table.shape[0] > 1000
    wrong, _ = wrong_dd_integers(sim.dataset_dir, tc["time_offset_s"], rec["t"], table)
    assert wrong == 0


def test_tdcp_accuracy_heading_and_consistency(tdcp_run):
    _, summary, results, _ = tdcp_run
    assert_accuracy_and_consistency(summary, results)


def test_tdcp_variance_factor_near_one_with_true_phase_sigma(tdcp_run):
    """The recipe's phase σ90 is the simulated one and the TDCP σ defaults to it: the TDCP
    group's σ̂²_0 (with the ignored temporal and same-epoch L1 correlations) stays within
    10 % of 1, as do the other groups."""
    _, summary, _, _ = tdcp_run
    for group, value in summary["tightly_coupled"]["sigma0_sq"].items():
        assert 0.9 < value < 1.1, (group, value)


@pytest.mark.parametrize("start", [0.3])
def test_vce_recovers_tdcp_noise(tdcp_run, start):
    """gmis vce on the TDCP run: the DD groups start at 0.3× the simulated σ90 (TDCP: the
    L1 phase σ90) and return within ±10 % (the 3× start: benchmarks/tc_vce_recovery.py)."""
    from gmis.pipeline import prepare_run
    from gmis.recipe import load_recipe
    from vce import tune
    _, _, _, tight = tdcp_run
    recipe = load_recipe(tight)
    truth = {"code": recipe.noise.code_sigma_m, "phase_l1": recipe.noise.phase_l1_sigma_m,
             "phase_l2": recipe.noise.phase_l2_sigma_m, "tdcp": recipe.noise.tdcp_sigma_m}
    assert truth["tdcp"] == truth["phase_l1"]
    res = tune(prepare_run(recipe), max_iterations=15,
               initial_sigma={k: v * start for k, v in truth.items()})
    assert res.converged
    final = {c.name: s for c, s in zip(res.components, res.final_sigma)}
    assert "doppler" not in final
    for name, value in truth.items():
        assert 0.9 <= final[name] / value <= 1.1, (name, final[name] / value)


# ----------------------------------------------------------------------------- pairing


def _epoch(t, prn, l1, slip=None):
    n = len(prn)
    rng = np.random.default_rng(int(t * 10))
    return TcEpoch(t=t, prn=np.array(prn), sat_pos=rng.normal(0, 2e7, (n, 3)),
                   sat_vel=np.zeros((n, 3)), base_range=rng.uniform(2e7, 2.5e7, n),
                   base_rate=np.zeros(n), elevation_base=np.full(n, 0.8),
                   sd={"code": np.zeros(n), "l1": np.array(l1, float), "l2": np.zeros(n),
                       "doppler": np.zeros(n)},
                   slip=np.zeros(n, bool) if slip is None else np.array(slip))


def test_tdcp_pairs_epochs_by_prn_and_skips_slips_gaps_and_missing_phase():
    frame = make_nav_frame(0.76, -1.39, 180.0)
    cfg = TcConfig(velocity_observable="tdcp")
    filt = TcFilter(None, [3, 5, 7, 9], 21, np.zeros(3), frame, cfg, nominal_interval_s=0.5)
    prev = _epoch(10.0, [5, 3, 9, 7], [5.0, 3.0, np.nan, 7.0])
    filt.prev = prev
    # current order differs; PRN 9 had no phase before, PRN 7 slips now
    cur = _epoch(10.5, [3, 5, 7, 9], [3.5, 5.25, 7.0, 9.0], slip=[False, False, True, False])
    rows, z = filt._tdcp_rows(cur, 0, np.array([1, 2, 3]))       # reference PRN 3
    assert rows.tolist() == [1]
    assert z == pytest.approx([(5.25 - 3.5) - (5.0 - 3.0)])
    dt, prev_pos, prev_range = filt._tdcp_prev
    assert dt == pytest.approx(0.5)
    assert np.array_equal(prev_pos[1], prev.sat_pos[0]) and prev_range[1] == prev.base_range[0]
    assert np.all(np.isnan(prev_pos[2])) and np.isnan(prev_range[2])
    # a slipped reference disables every row
    cur_slip_ref = _epoch(10.5, [3, 5], [3.5, 5.25], slip=[True, False])
    assert filt._tdcp_rows(cur_slip_ref, 0, np.array([1]))[0].size == 0
    # a gap longer than 2.5 nominal intervals, or a non-positive step, disables TDCP
    for t in (11.26, 10.0, 9.5):
        assert filt._tdcp_rows(_epoch(t, [3, 5], [3.5, 5.25]), 0, np.array([1]))[0].size == 0
    assert filt._tdcp_rows(_epoch(11.24, [3, 5], [3.5, 5.25]), 0, np.array([1]))[0].size == 1


def test_tc_config_rejects_an_unknown_velocity_observable():
    with pytest.raises(GmisInputError, match="velocity_observable.*'doppler', 'tdcp'"):
        TcConfig(velocity_observable="phase-rate")
    assert TcConfig().sigma(3) == TcConfig().sigma_doppler_m_s
    assert TcConfig(velocity_observable="tdcp", sigma_phase_l1_m=0.003).sigma(3) == 0.003
    assert TcConfig(velocity_observable="tdcp", sigma_tdcp_m=0.004).sigma(3) == 0.004
