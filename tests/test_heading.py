"""gnss.heading: moving-baseline (dual-antenna) heading on a synthetic drive with known
integer ambiguities, a wrong primary position (SPP-like, metres) and turns."""

import math

import numpy as np
import pytest

from gmis.earth import ecef_to_enu_matrix, geodetic_to_ecef
from gmis.frames import dcm_body_to_nav
from gnss.constants import C_LIGHT, WAVELENGTH_L1, WAVELENGTH_L2
from gnss.double_difference import double_difference_epoch, elevation_cofactor
from gnss.errors import GnssInputError as GmisInputError  # gnss raises the base type
from gnss.heading import baseline_to_heading, body_baseline_azimuth, heading_from_dd_epochs
from gnss.rtk import Q_FIXED, RtkConfig

SAT_RADIUS = 26_560e3
PRIMARY_L = np.array([0.3, 1.0, 1.5])
SECONDARY_L = np.array([0.3, -1.0, 1.5])     # 2 m behind the primary: α = 180°


def simulate_moving_baseline(seed=3, n_sats=9, n_epochs=60, dt=1.0, sigma_phase=0.003,
                             sigma_code=0.3, primary_error_m=3.0, l1_only=False,
                             with_integers=False, lowest_l1_bias_cycles=0.0):
    """The heading test scene. l1_only: single-frequency receivers (no C2/L2 in the DD).
    with_integers: also return the true DD integers per epoch {(prn, f): ∇ΔN} w.r.t. the
    epoch's reference (secondary − primary). lowest_l1_bias_cycles: a constant non-integer
    L1 phase bias (e.g. an unresolved half cycle) at the secondary on the lowest satellite,
    which the float ambiguity absorbs as a fraction that no integer fits."""
    rng = np.random.default_rng(seed)
    lat, lon = math.radians(43.77), math.radians(-79.50)
    origin = geodetic_to_ecef(lat, lon, 180.0)
    c_en = ecef_to_enu_matrix(lat, lon)
    az = rng.uniform(0, 2 * np.pi, n_sats)
    el = np.radians(rng.uniform(25, 85, n_sats))
    los = np.c_[np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)] @ c_en
    bu = los @ origin
    sat = origin + (-bu + np.sqrt(bu ** 2 - origin @ origin + SAT_RADIUS ** 2))[:, None] * los
    prn = np.arange(1, n_sats + 1)
    amb = {s: rng.integers(-300_000, 300_000, (2, n_sats)) for s in ("p", "s")}
    clock = {"p": 2e-4, "s": -5e-4}
    epochs, lin, truth_heading, truth_b, truth_n = [], [], [], [], []
    ref = -1
    pos = np.zeros(3)
    for i in range(n_epochs):
        heading = math.radians(20.0 + 3.0 * i)          # a steady turn
        pitch, roll = math.radians(2.0), math.radians(-1.5)
        c_bn = dcm_body_to_nav(pitch, roll, heading)
        pos = pos + c_bn @ np.array([0.0, 10.0 * dt, 0.0])
        ant = {"p": origin + c_en.T @ (pos + c_bn @ PRIMARY_L),
               "s": origin + c_en.T @ (pos + c_bn @ SECONDARY_L)}
        sites = {}
        for name, r in ant.items():
            rho = np.linalg.norm(sat - r, axis=1)
            up = r / np.linalg.norm(r)
            m = np.sqrt(elevation_cofactor(np.arcsin(((sat - r) / rho[:, None]) @ up)))
            clk = C_LIGHT * clock[name]
            sites[name] = {
                "C1": rho + clk + sigma_code * m * rng.standard_normal(n_sats),
                "C2": rho + clk + sigma_code * m * rng.standard_normal(n_sats),
                "L1": (rho + clk + sigma_phase * m * rng.standard_normal(n_sats))
                / WAVELENGTH_L1 + amb[name][0],
                "L2": (rho + clk + sigma_phase * m * rng.standard_normal(n_sats))
                / WAVELENGTH_L2 + amb[name][1],
                "LLI1": np.zeros(n_sats, np.int64), "LLI2": np.zeros(n_sats, np.int64)}
            if name == "s":
                sites[name]["L1"][np.argmin(el)] += lowest_l1_bias_cycles
            if l1_only:
                del sites[name]["C2"], sites[name]["L2"]
        primary_est = ant["p"] + rng.normal(0, primary_error_m, 3)
        ep = double_difference_epoch(1000.0 + i * dt, prn, sites["p"], sites["s"], sat, sat,
                                     primary_est, primary_est, current_ref=ref)
        ref = ep.ref_prn
        sd = amb["s"] - amb["p"]
        j = ref - 1
        truth_n.append({(int(k), f + 1): int(sd[f, k - 1] - sd[f, j])
                        for k in ep.prn for f in range(2)})
        epochs.append(ep)
        lin.append(primary_est)
        truth_heading.append(heading)
        truth_b.append(c_bn @ (SECONDARY_L - PRIMARY_L))
    out = epochs, np.array(lin), np.array(truth_heading), np.array(truth_b)
    return (*out, truth_n) if with_integers else out


def test_moving_baseline_heading_is_fixed_and_accurate():
    epochs, lin, true_heading, true_b = simulate_moving_baseline()
    alpha = body_baseline_azimuth(PRIMARY_L, SECONDARY_L)
    assert abs(alpha - math.pi) < 1e-12
    sol = heading_from_dd_epochs(epochs, lin.copy(), lin, 2.0, alpha, RtkConfig())
    fixed = sol.q == Q_FIXED
    assert fixed.mean() >= 0.95
    # baseline errors (despite a 3 m primary-position error) agree with the reported σ
    err = sol.baseline_enu[fixed] - true_b[fixed]
    sig = sol.baseline_sigma_enu[fixed]
    assert np.all(np.abs(err) < 4 * sig)
    ratio = np.sqrt((err ** 2).mean(axis=0)) / sig.mean(axis=0)
    assert np.all((0.6 < ratio) & (ratio < 1.5)), ratio
    assert np.sqrt((err[:, :2] ** 2).mean()) < 0.01              # m, horizontal RMS
    # level-vehicle conversion: the residual heading error is the pitch/roll coupling of an
    # along-track baseline (zero for pitch-only, tiny for 2° pitch / 1.5° roll)
    d = (sol.heading[fixed] - true_heading[fixed] + np.pi) % (2 * np.pi) - np.pi
    assert np.degrees(np.abs(d)).max() < 0.5
    assert np.degrees(np.sqrt(np.mean(d ** 2))) < 0.3
    # the reported σ is honest: errors of the baseline azimuth within 4σ
    true_az = np.arctan2(true_b[:, 0], true_b[:, 1])
    e_az = (sol.baseline_azimuth[fixed] - true_az[fixed] + np.pi) % (2 * np.pi) - np.pi
    assert np.all(np.abs(e_az) < 4 * sol.sigma_heading[fixed] + 1e-4)
    assert np.all(np.abs(sol.length_m[fixed] - 2.0) < 0.03)


def test_length_check_rejects_a_wrong_fix():
    epochs, lin, _, _ = simulate_moving_baseline(n_epochs=10)
    alpha = body_baseline_azimuth(PRIMARY_L, SECONDARY_L)
    # a surveyed length 10 cm off makes every (correct) fix fail the check: reported float
    sol = heading_from_dd_epochs(epochs, lin.copy(), lin, 2.10, alpha, RtkConfig())
    assert sol.length_rejected.any() and not (sol.q == Q_FIXED).any()


def test_heading_sigma_formula_matches_finite_differences():
    b = np.array([[1.2, -1.5, 0.1]])
    s = np.array([[0.004, 0.003, 0.008]])
    _, _, _, sig_az, sig_pitch = baseline_to_heading(b, s, 0.0)
    grad = []
    for k in range(3):
        e = np.zeros((1, 3))
        e[0, k] = 1e-7
        a1, p1, *_ = baseline_to_heading(b + e, s, 0.0)
        a0, p0, *_ = baseline_to_heading(b - e, s, 0.0)
        grad.append(((a1 - a0)[0] / 2e-7, (p1 - p0)[0] / 2e-7))
    grad = np.array(grad)
    assert abs(np.sqrt(np.sum((grad[:, 0] * s[0]) ** 2)) - sig_az[0]) < 1e-9
    assert abs(np.sqrt(np.sum((grad[:, 1] * s[0]) ** 2)) - sig_pitch[0]) < 1e-9


def test_coincident_antennas_are_an_input_error():
    with pytest.raises(GmisInputError, match="secondary_lever_arm_m"):
        body_baseline_azimuth([0, 0, 1], [0.05, 0.0, 1.2])


def test_heading_file_feeds_the_filter_reader(tmp_path):
    from gmis.readers import read_heading
    from gnss.heading import write_heading_csv
    epochs, lin, _, _ = simulate_moving_baseline(n_epochs=12)
    sol = heading_from_dd_epochs(epochs, lin.copy(), lin, 2.0, math.pi, RtkConfig())
    path = write_heading_csv(tmp_path / "heading.csv", sol)
    data = read_heading(path)
    fixed = sol.q == Q_FIXED
    np.testing.assert_allclose(data.heading, sol.heading[fixed], atol=1e-8)
    np.testing.assert_allclose(data.sigma, sol.sigma_heading[fixed], rtol=1e-6)


def _wrong_fixes(sol_integers, truth):
    return sum(1 for ints, tr in zip(sol_integers, truth) if ints is not None
               and any(n != tr[k] for k, n in ints.items()))


def test_single_frequency_heading_is_fixed_without_wrong_integers():
    """L1-only receivers (no C2/L2): L1 ambiguity resolution after the single-frequency
    lock count (5 epochs). Measured (200 epochs): fix rate 0.98 (first fix at epoch 4),
    heading RMS 0.211° with the length constraint (0.217° without; the L1-only phase
    noise of this scene: mean σ 0.202°; L1+L2 0.156°), azimuth error RMS / σ 1.05, 0 wrong integers (1000 epochs and more seeds:
    benchmarks/heading_single_frequency.py)."""
    from gnss.rtk import process_dd_epochs
    epochs, lin, true_heading, true_b, truth = simulate_moving_baseline(
        n_epochs=200, l1_only=True, with_integers=True)
    assert all(np.isnan(ep.observables["L2"]).all() for ep in epochs)
    alpha = body_baseline_azimuth(PRIMARY_L, SECONDARY_L)
    cfg = RtkConfig(frequencies=("L1",))
    raw = process_dd_epochs(epochs, lin.copy(), cfg)
    assert _wrong_fixes(raw.integers, truth) == 0
    assert all(k[1] == 1 for ints in raw.integers if ints for k in ints)
    sol = heading_from_dd_epochs(epochs, lin.copy(), lin, 2.0, alpha, cfg)
    fixed = sol.q == Q_FIXED
    assert fixed.mean() >= 0.95 and not sol.length_rejected.any()
    d = (sol.heading[fixed] - true_heading[fixed] + np.pi) % (2 * np.pi) - np.pi
    assert np.degrees(np.sqrt(np.mean(d ** 2))) < 0.25
    # σ from the full covariance describes the azimuth errors (RMS/σ near 1)
    true_az = np.arctan2(true_b[:, 0], true_b[:, 1])
    e_az = (sol.baseline_azimuth[fixed] - true_az[fixed] + np.pi) % (2 * np.pi) - np.pi
    z = e_az / sol.sigma_heading[fixed]
    assert 0.8 < np.sqrt(np.mean(z ** 2)) < 1.25
    # the dual-frequency processing of the same L1-only data cannot fix (no L2)
    dual = heading_from_dd_epochs(epochs[:20], lin[:20].copy(), lin[:20], 2.0, alpha,
                                  RtkConfig())
    assert not (dual.q == Q_FIXED).any()


@pytest.mark.parametrize("l1_only", [False, True])
def test_partial_ar_fixes_the_others_when_one_satellite_has_a_half_cycle(l1_only):
    """A half-cycle L1 bias on the lowest satellite: no integer vector of the full set
    passes the ratio test, so without partial AR nothing is fixed; dropping the lowest
    satellite first (the documented rule) fixes the others with their true integers.
    Partial AR is on by default for L1 only; dual-frequency enables it (partial_ar=True)."""
    from gnss.rtk import process_dd_epochs
    epochs, lin, _, _, truth = simulate_moving_baseline(
        n_epochs=40, l1_only=l1_only, with_integers=True, lowest_l1_bias_cycles=0.5)
    freqs = ("L1",) if l1_only else ("L1", "L2")
    off = process_dd_epochs(epochs, lin.copy(), RtkConfig(frequencies=freqs, partial_ar=False))
    on = process_dd_epochs(epochs, lin.copy(), RtkConfig(frequencies=freqs, partial_ar=True))
    assert (off.q == Q_FIXED).mean() < 0.1
    # fixed by a subset (later epochs may fix through the held subset integers)
    assert (on.q == Q_FIXED).mean() > 0.8 and on.partial.any()
    low = int(epochs[0].prn[np.argmin(epochs[0].elevation_rover)])
    assert all(k[0] != low for ints in on.integers if ints for k in ints)
    assert _wrong_fixes(on.integers, truth) == 0
    alpha = body_baseline_azimuth(PRIMARY_L, SECONDARY_L)
    sol = heading_from_dd_epochs(epochs, lin.copy(), lin, 2.0, alpha,
                                 RtkConfig(frequencies=freqs, partial_ar=True))
    assert (sol.q == Q_FIXED).mean() > 0.8


def test_heading_sigma_from_the_full_covariance_matches_finite_differences():
    b = np.array([[1.2, -1.5, 0.1]])
    a = np.array([[0.004, 0.0, 0.0], [0.002, 0.003, 0.0], [-0.003, 0.001, 0.008]])
    cov = (a @ a.T)[None]
    _, _, _, sig_az, sig_pitch = baseline_to_heading(b, None, 0.0, cov)
    jac = np.zeros((2, 3))
    for k in range(3):
        e = np.zeros((1, 3))
        e[0, k] = 1e-7
        a1, p1, *_ = baseline_to_heading(b + e, None, 0.0, cov)
        a0, p0, *_ = baseline_to_heading(b - e, None, 0.0, cov)
        jac[:, k] = ((a1 - a0)[0] / 2e-7, (p1 - p0)[0] / 2e-7)
    full = jac @ cov[0] @ jac.T
    assert abs(np.sqrt(full[0, 0]) - sig_az[0]) < 1e-9
    assert abs(np.sqrt(full[1, 1]) - sig_pitch[0]) < 1e-9
    # the diagonal-only σ differs for this correlated covariance
    _, _, _, sig_diag, _ = baseline_to_heading(b, np.sqrt(np.diag(cov[0]))[None], 0.0)
    assert abs(sig_diag[0] - sig_az[0]) > 0.05 * sig_az[0]


def test_heading_with_attitude_inverts_the_body_to_nav_rotation():
    """ψ from the baseline azimuth with the true pitch/roll (001 eq. 2.2.4) is exact, where
    the level-vehicle conversion is off for a cross-track baseline on a tilted vehicle."""
    from gnss.heading import heading_with_attitude
    prim, sec = np.array([0.3, 1.0, 1.5]), np.array([-0.9, 0.2, 1.7])   # oblique baseline
    alpha = body_baseline_azimuth(prim, sec)
    rng = np.random.default_rng(5)
    for _ in range(20):
        pitch, roll = np.radians(rng.uniform(-15, 15, 2))
        psi = rng.uniform(0, 2 * np.pi)
        b = dcm_body_to_nav(pitch, roll, psi) @ (sec - prim)
        az = math.atan2(b[0], b[1])
        got = heading_with_attitude(az, prim, sec, pitch, roll)
        assert abs((got - psi + np.pi) % (2 * np.pi) - np.pi) < 1e-12
    level = (az - alpha - psi + np.pi) % (2 * np.pi) - np.pi
    assert abs(level) > 1e-3              # the level-vehicle formula is not exact here


def test_length_constraint_is_the_constrained_minimum_and_its_covariance_is_first_order():
    """b̌ lies on |b| = L, satisfies the Lagrange condition C⁻¹(b̌ − b̂) ∥ b̌ and beats every
    other point of the sphere near it; C_b̌ equals J C Jᵀ with J = ∂b̌/∂b̂ by central
    differences at a b̂ on the sphere (where the first-order covariance is exact)."""
    from gnss.heading import constrain_to_length
    a = np.array([[0.004, 0.0, 0.0], [0.002, 0.003, 0.0], [-0.003, 0.001, 0.008]])
    cov = a @ a.T
    b_hat = np.array([1.21, -1.52, 0.12])
    b, _ = constrain_to_length(b_hat, cov, 2.0)
    assert abs(np.linalg.norm(b) - 2.0) < 1e-12
    grad = np.linalg.solve(cov, b - b_hat)
    assert np.linalg.norm(np.cross(grad, b)) < 1e-9 * np.linalg.norm(grad) * 2.0
    cost = (b - b_hat) @ np.linalg.solve(cov, b - b_hat)
    rng = np.random.default_rng(1)
    for _ in range(200):
        t = b + rng.normal(0, 0.01, 3)
        t *= 2.0 / np.linalg.norm(t)
        assert (t - b_hat) @ np.linalg.solve(cov, t - b_hat) >= cost - 1e-12
    on = 2.0 * b_hat / np.linalg.norm(b_hat)
    _, c_on = constrain_to_length(on, cov, 2.0)
    jac = np.zeros((3, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1e-6
        jac[:, k] = (constrain_to_length(on + e, cov, 2.0)[0]
                     - constrain_to_length(on - e, cov, 2.0)[0]) / 2e-6
    np.testing.assert_allclose(jac @ cov @ jac.T, c_on, atol=1e-12)
    assert abs(np.linalg.det(c_on)) < 1e-20            # rank 2: the length is known


def test_length_constraint_lowers_the_single_frequency_heading_error():
    """The weakest geometry of benchmarks/heading_single_frequency.py (seed 4, all
    satellites above 47°): the length-constrained heading has a smaller RMS than the free
    fixed baseline's and its σ still describes the errors; the σ-aware length check
    rejects no correct fix there."""
    from gnss.rtk import process_dd_epochs
    epochs, lin, true_heading, _, truth = simulate_moving_baseline(
        seed=4, n_epochs=300, l1_only=True, with_integers=True)
    alpha = body_baseline_azimuth(PRIMARY_L, SECONDARY_L)
    cfg = RtkConfig(frequencies=("L1",))
    raw = process_dd_epochs(epochs, lin.copy(), cfg)
    assert _wrong_fixes(raw.integers, truth) == 0
    on = heading_from_dd_epochs(epochs, lin.copy(), lin, 2.0, alpha, cfg)
    off = heading_from_dd_epochs(epochs, lin.copy(), lin, 2.0, alpha, cfg,
                                 constrain_length=False)
    fixed = on.q == Q_FIXED
    assert np.array_equal(fixed, off.q == Q_FIXED)
    assert not on.length_rejected.any() and fixed.mean() >= 0.95

    def rms(sol):
        d = (sol.heading[fixed] - true_heading[fixed] + np.pi) % (2 * np.pi) - np.pi
        return np.sqrt(np.mean(d ** 2)), d
    r_on, d_on = rms(on)
    r_off, _ = rms(off)
    assert r_on < 0.97 * r_off
    z = d_on / on.sigma_heading[fixed]
    assert 0.8 < np.sqrt(np.mean(z ** 2)) < 1.25
    np.testing.assert_allclose(np.linalg.norm(on.baseline_constrained_enu[fixed], axis=1),
                               2.0, atol=1e-9)
