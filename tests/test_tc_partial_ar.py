"""Partial ambiguity resolution in the tightly coupled filter (gmis.tc_filter, TcConfig.
partial_ar), GNSS-only (`gmis rtk --tight` path) on simulated RINEX (tests/tc_gnss_scene):
5-7 satellites with a 5-satellite blockage stretch, and an unresolvable half-cycle L1 bias
on the lowest satellite at the rover, so the full ambiguity set fails the ratio test
whenever that satellite is in view."""

from __future__ import annotations

import numpy as np
import pytest

from gmis.simulate.raw_gnss import RawGnssConfig, SkyBlockage
from gmis.tc_filter import TcConfig
from gmis.tc_gnss_only import run_tight_without_imu
from tests.tc_gnss_scene import BASE, T0, satellites_by_elevation, simulate_session, wrong_integers

N_EP = 180


def test_partial_ar_raises_the_tc_fix_rate_without_wrong_integers(tmp_path):
    """Measured: partial AR off 71 of 180 epochs fixed (11 of the 60 after the blockage,
    when the biased satellite is back), on 177 of 180 (60 of 60; 99 partial fixes; 120
    with 49 partial by variance ordering alone, without the leave-one-out stage), 0 wrong
    integers apart from the biased L1 itself either way, fixed 3-D error ≤ 4.2 cm."""
    cfg = RawGnssConfig(blockages=[SkyBlockage(T0 + 60, T0 + 120, highest_n=5)])
    sim, obs, nav = simulate_session(tmp_path, N_EP, cfg, lowest_l1_bias_cycles=0.5)
    biased = int(satellites_by_elevation(N_EP)[-1])
    runs = {pa: run_tight_without_imu(obs["rover"], obs["base"], nav, BASE,
                                      TcConfig(partial_ar=pa), hydrostatic_troposphere=False)
            for pa in (False, True)}
    off, on = runs[False], runs[True]
    after = on.t_gps >= T0 + 120
    assert off.fixed[after].mean() < 0.3
    assert on.fixed[after].mean() > 0.95 and on.tc_records.partial.sum() >= 30
    assert on.fixed.sum() >= off.fixed.sum() + 40
    for sol in (off, on):
        wrong, checked = wrong_integers(sim, sol, skip={(biased, 1)})
        assert wrong == 0 and checked > 500
        err = np.linalg.norm(sol.ecef - sim.receivers["rover"].antenna_ecef, axis=1)
        assert err[sol.fixed].max() < 0.05
    # a partial fix leaves the biased L1 ambiguity float (its L2 may be fixed)
    rec = on.tc_records
    for g, ints in zip(np.flatnonzero(on.fixed), rec.integers):
        if rec.partial[g]:
            assert (biased, 1) not in ints


def test_wide_lane_cascade_returns_the_true_integers_and_refuses_unclear_floats():
    """gmis.tc_filter.wide_lane_cascade on DD floats near known integers (a correlated
    covariance: the L1/L2 floats of a satellite move together, wide lane tighter): the true
    N1 and N2 = N1 − N_WL come back in pairs order; a wide lane at a half cycle, or an L1
    at a half cycle once the wide lanes are fixed, is refused (None)."""
    from gmis.tc_filter import wide_lane_cascade
    rng = np.random.default_rng(2)
    k = 5
    n1 = rng.integers(-50, 50, k)
    n2 = n1 - rng.integers(-5, 5, k)
    pairs = [(0, s) for s in range(k)] + [(1, s) for s in range(k)]
    together = np.vstack([np.eye(k), np.eye(k)])
    q = 0.04 * together @ together.T + 0.0025 * np.eye(2 * k)    # cycles²
    truth = np.concatenate([n1, n2]).astype(float)
    a = truth + rng.normal(0, 0.01, 2 * k)
    idx, ints, ratio = wide_lane_cascade(pairs, a, q, 3.0, 4)
    got = dict(zip(idx.tolist(), ints.tolist()))
    assert [got[i] for i in range(k)] == n1.tolist()
    assert [got[k + i] for i in range(k)] == n2.tolist()
    assert ratio >= 3.0
    wl_half = a.copy()
    wl_half[0] += 0.5                                  # N1 − N2 of satellite 0 at .5
    assert wide_lane_cascade(pairs, wl_half, q, 3.0, 4) is None
    l1_half = a.copy()
    l1_half[[0, k]] += 0.5                             # wide lane intact, L1 and L2 at .5
    assert wide_lane_cascade(pairs, l1_half, q, 3.0, 4) is None
    assert wide_lane_cascade(pairs[:1] + pairs[k:k + 1], a[[0, k]], q[np.ix_([0, k], [0, k])],
                             3.0, 4) is None           # 2 ambiguities < min_fix_ambiguities


def test_wide_lane_cascade_adds_fixes_without_wrong_integers(tmp_path):
    """The half-cycle scene without partial AR: the cascade (WL first, then L1) fixes
    epochs the joint search does not. Measured: 71 → 82 of 180 epochs fixed (11 → 22 of the
    60 after the blockage), 0 wrong of 722 checked integers (the biased L1 not checked)."""
    cfg = RawGnssConfig(blockages=[SkyBlockage(T0 + 60, T0 + 120, highest_n=5)])
    sim, obs, nav = simulate_session(tmp_path, N_EP, cfg, lowest_l1_bias_cycles=0.5)
    biased = int(satellites_by_elevation(N_EP)[-1])
    runs = {c: run_tight_without_imu(obs["rover"], obs["base"], nav, BASE,
                                     TcConfig(partial_ar=False, wide_lane_cascade=c),
                                     hydrostatic_troposphere=False) for c in (False, True)}
    assert runs[True].fixed.sum() >= runs[False].fixed.sum() + 5
    assert runs[True].tc_records.cascade.any() and not runs[False].tc_records.cascade.any()
    wrong, checked = wrong_integers(sim, runs[True], skip={(biased, 1)})
    assert wrong == 0 and checked > 600


def test_leave_one_satellite_out_names_the_one_satellite_that_spoils_the_set():
    """gmis.tc_filter.leave_one_satellite_out on DD floats of 6 satellites × L1/L2 near
    known integers: with a half-cycle L1 float on one satellite the full set fails the ratio
    test, and only that satellite's omission lets the rest pass — it is named and left out,
    the rest come back as the true integers. Two half-cycle satellites: no single omission
    explains the failure → None."""
    from gmis.tc_filter import leave_one_satellite_out
    from gnss.lambda_ils import ratio_test, resolve_integers
    rng = np.random.default_rng(4)
    k = 6
    pairs = [(f, s) for f in (0, 1) for s in range(k)]
    truth = rng.integers(-40, 40, 2 * k).astype(float)
    together = np.vstack([np.eye(k), np.eye(k)])
    q = 0.02 * together @ together.T + 0.004 * np.eye(2 * k)    # cycles²
    a = truth + rng.normal(0, 0.02, 2 * k)
    a[2] += 0.5                                        # satellite 2, L1
    assert not ratio_test(resolve_integers(a, q), 3.0)
    sat, subset, res = leave_one_satellite_out(pairs, a, q, 3.0, 4)
    assert sat == 2
    assert sorted(pairs[i] for i in subset) == sorted(p for p in pairs if p[1] != 2)
    assert np.array_equal(res.fixed, truth[subset]) and res.ratio >= 3.0
    two = a.copy()
    two[4] += 0.5                                      # satellite 4 too
    assert leave_one_satellite_out(pairs, two, q, 3.0, 4) is None


def test_satellite_phase_test_finds_a_half_cycle_on_fixed_phases():
    """gmis.tc_filter.satellite_phase_test on simulated DD phase residuals (6 satellites,
    L1 + L2, DD covariance σ²(I + 1), a position error the fit absorbs): correct integers
    pass in ≥ 99.3 % of 600 draws (family level 1e-4, Bonferroni); one L1 row 0.5 λ1 off is
    named in ≥ 99 % of 100 draws."""
    from gmis.tc_filter import satellite_phase_test
    from gnss.constants import WAVELENGTH_L1
    rng = np.random.default_rng(7)
    n_dd = 5
    los = rng.normal(size=(n_dd + 1, 3))
    los[:, 2] = np.abs(los[:, 2]) + 0.3
    los /= np.linalg.norm(los, axis=1)[:, None]
    dd = -(los[1:] - los[0])
    a_pos = np.vstack([dd, dd])
    sat_k = np.concatenate([np.arange(1, n_dd + 1)] * 2)
    sigma = 0.004
    block = sigma ** 2 * (np.eye(n_dd) + 1.0)
    r_mat = np.kron(np.eye(2), block)
    chol = np.linalg.cholesky(r_mat)
    cache = {}
    false_alarms = 0
    for _ in range(600):
        res = a_pos @ rng.normal(0, 0.05, 3) + chol @ rng.normal(size=2 * n_dd)
        false_alarms += satellite_phase_test(res, a_pos, r_mat, sat_k, 1e-4, cache) is not None
    assert false_alarms <= 4, false_alarms
    named = 0
    for _ in range(100):
        res = a_pos @ rng.normal(0, 0.05, 3) + chol @ rng.normal(size=2 * n_dd)
        res[2] += 0.5 * WAVELENGTH_L1                  # satellite 3's L1
        named += satellite_phase_test(res, a_pos, r_mat, sat_k, 1e-4, cache) == 3
    assert named >= 99, named


def test_satellite_statistic_is_the_fall_of_the_fit_without_the_satellite():
    """satellite_phase_test's one-fit statistic u_kᵀ M_kk⁻¹ u_k equals Ω − Ω₋ₖ of two explicit
    weighted least-squares fits (all rows, and without satellite k's rows), on random
    L1 + L2 DD geometries with correlated DD covariance: the satellite it names is the one
    the refits name."""
    from gmis import tc_filter
    rng = np.random.default_rng(3)

    def omega(rows, res, a_pos, r_mat):
        w = np.linalg.inv(r_mat[np.ix_(rows, rows)])
        a, r = a_pos[rows], res[rows]
        v = r - a @ np.linalg.solve(a.T @ w @ a, a.T @ w @ r)
        return float(v @ w @ v)

    for _ in range(50):
        n_dd = int(rng.integers(5, 9))
        a_pos = np.vstack([rng.normal(size=(n_dd, 3))] * 2)
        sat_k = np.concatenate([np.arange(n_dd)] * 2)
        r_mat = np.kron(np.diag([1.0, 1.6]), 1e-6 * (np.eye(n_dd) + 1.0))
        res = rng.normal(size=2 * n_dd) * 1e-3
        res[int(rng.integers(2 * n_dd))] += 0.05
        every = np.arange(res.size)
        fall = {k: omega(every, res, a_pos, r_mat) - omega(every[sat_k != k], res, a_pos,
                                                             r_mat) for k in range(n_dd)}
        crit = tc_filter.chi2_quantile(1.0 - 1e-4 / n_dd, 2)
        worst = max(fall, key=fall.get)
        expected = worst if fall[worst] > crit else None
        assert tc_filter.satellite_phase_test(res, a_pos, r_mat, sat_k, 1e-4) == expected


@pytest.fixture(scope="module")
def scene_e(tmp_path_factory):
    """(sim, obs, nav, biased prn) of tests.tc_gnss_scene.five_satellite_stretch, simulated
    once for the tests that use it."""
    from tests.tc_gnss_scene import five_satellite_stretch
    return five_satellite_stretch(tmp_path_factory.mktemp("scene_e"))


def test_leave_one_out_fixes_a_five_satellite_stretch_with_a_biased_satellite(scene_e):
    """Scene E of benchmarks/tc_slips_partial_ar.py: a half-cycle L1 bias on the 5th-highest
    of 7 satellites, in view during a 5-satellite stretch. Measured (benchmark): variance
    ordering alone 0 of 60 stretch epochs fixed (0 of 180); with the stage 60 of 60 (177 of
    180), 0 wrong of 1205 checked integers, the biased L1 in no fix, fixed 3-D error
    ≤ 4.6 cm (95 % 3.6 cm)."""
    sim, obs, nav, biased = scene_e
    on = run_tight_without_imu(obs["rover"], obs["base"], nav, BASE, TcConfig(),
                               hydrostatic_troposphere=False)
    stretch = (on.t_gps >= T0 + 60) & (on.t_gps < T0 + 120)
    assert on.fixed[stretch].mean() > 0.95 and on.fixed.mean() > 0.9
    wrong, checked = wrong_integers(sim, on, skip={(biased, 1)})
    assert wrong == 0 and checked > 1000
    assert not any((biased, 1) in ints for ints in on.tc_records.integers)
    err = np.linalg.norm(on.ecef - sim.receivers["rover"].antenna_ecef, axis=1)
    assert err[on.fixed].max() < 0.05


def test_satellites_identifiable_counts_the_dof_left_without_each_new_satellite():
    """gmis.tc_filter.satellites_identifiable: L1 only (one row per satellite), 4 DD rows
    (5 satellites) cannot name a culprit, 5 rows can; L1+L2 (two rows each) 3 satellites'
    6 rows can, 2 satellites' 4 rows cannot; with all but one satellite held (trusted) the
    4 rows of 5 L1-only satellites can, with no redundancy at all nothing can."""
    from gmis.tc_filter import satellites_identifiable
    assert not satellites_identifiable([1, 2, 3, 4])
    assert satellites_identifiable([1, 2, 3, 4, 5])
    assert satellites_identifiable([1, 1, 2, 2, 3, 3])
    assert not satellites_identifiable([1, 1, 2, 2])
    assert satellites_identifiable([1, 2, 3, 4], untrusted={4})
    assert not satellites_identifiable([1, 2, 3, 4], untrusted={3, 4})
    assert not satellites_identifiable([1, 2, 3], untrusted={3})
    # mixed: an L1+L2 satellite among L1-only ones leaves 6 − 2 − 3 = 1 dof
    assert satellites_identifiable([1, 1, 2, 3, 4, 5])
    assert not satellites_identifiable([1, 1, 2, 3, 4])


def test_single_frequency_five_satellite_stretch_fixes_no_biased_satellite(scene_e):
    """Scene E with L1 only: in the 5-satellite stretch 4 DD L1 phases for 3 position
    unknowns cannot say which satellite carries the half cycle. Measured (benchmarks/
    tc_slips_partial_ar.py, part E): before the identifiability requirement the full set
    was fixed there (ratio 3.1) and held, the biased L1 in 58 fixes, 16.5 cm off (95 %);
    with it the candidate fixes are refused (8 epochs) and none holds the biased L1."""
    sim, obs, nav, biased = scene_e
    sol = run_tight_without_imu(obs["rover"], obs["base"], nav, BASE,
                                TcConfig(use=(True, True, False, True)),
                                hydrostatic_troposphere=False)
    rec = sol.tc_records
    assert rec.unidentifiable.sum() > 0
    assert not any((biased, 1) in ints for ints in rec.integers)
    err = np.linalg.norm(sol.ecef - sim.receivers["rover"].antenna_ecef, axis=1)
    assert not sol.fixed.any() or err[sol.fixed].max() < 0.05


def test_success_rate_gate_refuses_the_wrong_single_frequency_set_of_scene_e(scene_e):
    """Scene E, L1 only at 001's VCE-final σ (code 0.15 m, phase 3 mm, Table 6-3): without
    the gate the biased 7-satellite set is fixed wrongly at a bootstrapping success rate of
    0.968 (ratio ≥ 3, every residual test passed: the wrong set plus a ~50 cm shift fits the
    6 DD phases) and held; with TcConfig.min_success_rate = 0.999 the candidates (P_s
    0.96-0.996 measured) are refused and no wrong integer is fixed."""
    sim, obs, nav, biased = scene_e
    vce = {"use": (True, True, False, True), "sigma_code_m": 0.15, "sigma_phase_l1_m": 0.003}
    runs = {ps: run_tight_without_imu(obs["rover"], obs["base"], nav, BASE,
                                      TcConfig(min_success_rate=ps, **vce),
                                      hydrostatic_troposphere=False)
            for ps in (0.0, 0.999)}
    wrong_off, _ = wrong_integers(sim, runs[0.0], skip={(biased, 1)})
    assert wrong_off > 100                      # the failure the gate is there for
    gated = runs[0.999]
    wrong, _ = wrong_integers(sim, gated, skip={(biased, 1)})
    rec = gated.tc_records
    assert wrong == 0 and rec.low_success_rate.sum() > 0
    assert not any((biased, 1) in ints for ints in rec.integers)
    refused = rec.success_rate[rec.low_success_rate]
    assert np.all(refused < 0.999) and np.all(refused > 0.0)
