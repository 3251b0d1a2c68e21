"""Cycle-slip detectors on a simulated GPS L1/L2 arc with injected slips.

Simulation (fixed seeds): static receiver at 45 deg latitude on a rotating spherical Earth,
satellite on a circular orbit (radius 26 560 km, period 43 082 s, inclination 55 deg), in an
inertial frame; orbit phases drawn until the elevation stays >= 10 deg over the arc
(1 h at 1 Hz, 4 h at 30 s).  Range
rho + troposphere 2.4 m / sin(el) + receiver clock (bias + 0.05 m/s drift); slant L1
ionosphere I1 = 3 m + 1 m sin(2 pi t / 2 h + phi) (drifts ~1 mm/s), I2 = (f1/f2)^2 I1.
Noise: code 0.3 m, phase 3 mm, Doppler 0.05 Hz (white).  Doppler = -dL1/dt of the noiseless
phase (RINEX sign convention), by central difference of the smooth model.

Slips are injected (L_i[k:] += dN_i) every ~60 epochs (1 Hz) / ~20 epochs (30 s) at random
offsets; a slip counts as
detected when the flag is raised at exactly that epoch; false-alarm rate = flags at the
other epochs / number of other epochs.
"""

from __future__ import annotations

import numpy as np
import pytest

from gnss.cycle_slips import (
    LAMBDA_L1,
    LAMBDA_L2,
    SatelliteArc,
    SlipConfig,
    SlipInputError,
    data_gap_detector,
    detect_cycle_slips,
    doppler_phase_detector,
    geometry_free,
    geometry_free_detector,
    melbourne_wubbena,
    melbourne_wubbena_detector,
)

GM = 3.986004418e14
R_EARTH = 6371e3
R_ORBIT = 26_560e3
OMEGA_EARTH = 7.2921151467e-5
GAMMA = (1575.42 / 1227.60) ** 2
SIGMA_CODE, SIGMA_PHASE_M, SIGMA_DOPPLER_HZ = 0.3, 0.003, 0.05


# --------------------------------------------------------------------------- simulation


class Geometry:
    def __init__(self, rng, duration):
        self.lat = np.deg2rad(45.0)
        self.mean_motion = np.sqrt(GM / R_ORBIT**3)
        self.inc = np.deg2rad(55.0)
        self.iono_phase = rng.uniform(0, 2 * np.pi)
        self.clock_bias = rng.uniform(-3e5, 3e5)
        for _ in range(10_000):  # orbit phases with the satellite above 10 deg all arc long
            self.raan = rng.uniform(0, 2 * np.pi)
            self.u0 = rng.uniform(0, 2 * np.pi)
            if self.elevation(np.linspace(0.0, duration, 60)).min() > np.deg2rad(10.0):
                return
        raise RuntimeError(f"no visible {duration} s pass found")

    def sat(self, t):
        """inertial satellite position [m]"""
        u = self.u0 + self.mean_motion * np.asarray(t, dtype=float)
        cO, sO, ci, si = np.cos(self.raan), np.sin(self.raan), np.cos(self.inc), np.sin(self.inc)
        return R_ORBIT * np.stack([np.cos(u) * cO - np.sin(u) * ci * sO,
                                   np.cos(u) * sO + np.sin(u) * ci * cO,
                                   np.sin(u) * si], axis=-1)

    def rx(self, t):
        """inertial receiver position [m] (rotates with the Earth)"""
        w = OMEGA_EARTH * np.asarray(t, dtype=float)
        return R_EARTH * np.stack([np.cos(self.lat) * np.cos(w), np.cos(self.lat) * np.sin(w),
                                   np.full_like(w, np.sin(self.lat))], axis=-1)

    def elevation(self, t):
        los = self.sat(t) - self.rx(t)
        up = self.rx(t) / R_EARTH
        return np.arcsin(np.sum(los * up, axis=-1) / np.linalg.norm(los, axis=-1))

    def nondispersive(self, t):
        """rho + troposphere + receiver clock [m]."""
        rho = np.linalg.norm(self.sat(t) - self.rx(t), axis=-1)
        return rho + 2.4 / np.sin(self.elevation(t)) + self.clock_bias + 0.05 * np.asarray(t)

    def iono_l1(self, t):
        return 3.0 + 1.0 * np.sin(2 * np.pi * np.asarray(t) / 7200.0 + self.iono_phase)

    def phase_l1_m(self, t):
        return self.nondispersive(t) - self.iono_l1(t)


def simulate_arc(seed, dt, duration):
    """Clean arc (no slips) with integer ambiguities; returns SatelliteArc."""
    rng = np.random.default_rng(seed)
    geo = Geometry(rng, duration)
    t = np.arange(0.0, duration, dt)
    g = geo.nondispersive(t)
    i1 = geo.iono_l1(t)
    n1, n2 = rng.integers(-10**6, 10**6, size=2)
    L1 = (g - i1 + SIGMA_PHASE_M * rng.normal(size=t.size)) / LAMBDA_L1 + n1
    L2 = (g - GAMMA * i1 + SIGMA_PHASE_M * rng.normal(size=t.size)) / LAMBDA_L2 + n2
    P1 = g + i1 + SIGMA_CODE * rng.normal(size=t.size)
    P2 = g + GAMMA * i1 + SIGMA_CODE * rng.normal(size=t.size)
    h = 1e-3
    doppler = -(geo.phase_l1_m(t + h) - geo.phase_l1_m(t - h)) / (2 * h) / LAMBDA_L1
    D1 = doppler + SIGMA_DOPPLER_HZ * rng.normal(size=t.size)
    return SatelliteArc(time=t, L1=L1, L2=L2, P1=P1, P2=P2, D1=D1,
                        lli1=np.zeros(t.size, int), lli2=np.zeros(t.size, int))


def inject(arc, rng, slip_choices, spacing):
    """Inject one slip (dN1, dN2), drawn from slip_choices with a random sign, every
    spacing +- spacing/4 epochs.  Returns (arc with slips, slip epoch indices)."""
    n = arc.time.size
    epochs = np.arange(spacing, n - 5, spacing)
    epochs = epochs + rng.integers(-(spacing // 4), spacing // 4 + 1, size=epochs.size)
    L1, L2 = arc.L1.copy(), arc.L2.copy()
    for k in epochs:
        d1, d2 = slip_choices[rng.integers(len(slip_choices))]
        sign = rng.choice([-1, 1])
        L1[k:] += sign * d1
        L2[k:] += sign * d2
    return SatelliteArc(arc.time, L1, L2, arc.P1, arc.P2, arc.D1, arc.lli1, arc.lli2), epochs


def campaign(detector, slip_choices, dt, duration, n_arcs, seed=0, spacing=None):
    if spacing is None:
        spacing = 60 if dt < 10 else 20  # 1 min at 1 Hz, 10 min at 30 s
    """Run detector(arc) -> flags over n_arcs simulated arcs with injected slips.
    Returns (detection rate, false-alarm rate, n_slips, n_clean_epochs)."""
    rng = np.random.default_rng(seed)
    hits = slips = false = clean = 0
    for i in range(n_arcs):
        arc, epochs = inject(simulate_arc(1000 * seed + i, dt, duration), rng, slip_choices,
                             spacing)
        flags = np.asarray(detector(arc))
        is_slip = np.zeros(flags.size, bool)
        is_slip[epochs] = True
        hits += int(flags[epochs].sum())
        slips += epochs.size
        false += int(flags[~is_slip][1:].sum())  # first epoch cannot be tested
        clean += int((~is_slip).sum()) - 1
    return hits / slips, false / clean, slips, clean


def doppler_flags(arc):
    return doppler_phase_detector(arc.time, arc.L1, arc.D1).flags


def gf_flags(arc, order=1):
    return geometry_free_detector(arc.time, arc.L1, arc.L2, poly_order=order).flags


def mw_flags(arc):
    return melbourne_wubbena_detector(arc.L1, arc.L2, arc.P1, arc.P2).flags


def combined_flags(arc):
    return detect_cycle_slips(arc, SlipConfig()).slip


def report(name, result):
    det, fa, n_slips, n_clean = result
    print(f"\n{name}: detection {det:.2%} of {n_slips} slips, false alarms {fa:.3%} of "
          f"{n_clean} epochs")
    return det, fa


# slip families, (dN1, dN2) in cycles
L1_SLIPS = [(1, 0), (2, 0), (5, 0), (10, 0), (1, 1), (2, 3), (9, 7), (10, 10)]
L2_ONLY = [(0, 1), (0, 2), (0, 5), (0, 10)]
GF_VISIBLE = [(1, 0), (0, 1), (2, 0), (0, 2), (2, 2), (5, 5), (10, 0), (0, 10), (5, 2)]  # >= 0.1 m
GF_BLIND = [(9, 7), (18, 14), (77, 60)]  # |l1 dN1 - l2 dN2| = 3.3, 6.6, 0.0 mm
MW_VISIBLE = [(9, 7), (2, 0), (0, 2), (5, 0), (10, 0), (1, -1), (3, 1)]  # |dN1 - dN2| >= 2
MW_BLIND = [(1, 1), (2, 2), (5, 5), (10, 10)]


# --------------------------------------------------------------------------- 1 Hz


def test_combinations_cancel_geometry():
    arc = simulate_arc(1, 1.0, 600)
    mw = melbourne_wubbena(arc.L1, arc.L2, arc.P1, arc.P2)
    assert np.std(mw) < 0.3  # code noise only, ~0.25 WL cycles
    gf = geometry_free(arc.L1, arc.L2)
    assert np.std(np.diff(gf)) < 0.01  # phase noise + slow ionosphere
    # Doppler really is the phase rate with the RINEX sign: flipping it breaks the test
    bad = doppler_phase_detector(arc.time, arc.L1, -arc.D1)
    assert bad.flags[1:].all()


@pytest.mark.parametrize("label, flags, slips", [
    ("Doppler 1 Hz, L1 slips 1-10 cycles", doppler_flags, L1_SLIPS),
    ("GF 1 Hz, slips with |dGF| >= 0.1 m", gf_flags, GF_VISIBLE),
    ("MW 1 Hz, |dN1-dN2| >= 2", mw_flags, MW_VISIBLE),
], ids=["doppler_l1_slips", "geometry_free_visible_slips", "melbourne_wubbena_wide_lane_slips"])
def test_detector_detects_its_slips_at_1hz(label, flags, slips):
    det, fa = report(label, campaign(flags, slips, 1.0, 3600, 10))
    assert det >= 0.99
    assert fa <= 0.005


@pytest.mark.parametrize("label, flags, slips", [
    ("Doppler 1 Hz, L2-only slips", doppler_flags, L2_ONLY),
    ("GF 1 Hz, (9,7)-type slips", gf_flags, GF_BLIND),
    ("MW 1 Hz, dN1 = dN2", mw_flags, MW_BLIND),
], ids=["doppler_l2_only_slips", "geometry_free_wavelength_matched_slips",
        "melbourne_wubbena_equal_slips"])
def test_detector_is_blind_to_its_invisible_slips_at_1hz(label, flags, slips):
    det, fa = report(label, campaign(flags, slips, 1.0, 3600, 4))
    assert det <= 0.01
    assert fa <= 0.005


def test_geometry_free_on_marginal_one_one_slip():
    """(1, 1) moves GF by 0.054 m, barely above the 0.05 m threshold: reported, and it must
    be neither reliably seen nor missed (the noise of the GF prediction is ~6 mm)."""
    det, _ = report("GF 1 Hz, (1,1) slips", campaign(gf_flags, [(1, 1)], 1.0, 3600, 4))
    assert 0.2 < det < 0.95


def test_order_zero_is_the_epoch_difference():
    arc = simulate_arc(3, 1.0, 120)
    res = geometry_free_detector(arc.time, arc.L1, arc.L2, poly_order=0, window=10)
    gf = geometry_free(arc.L1, arc.L2)
    np.testing.assert_allclose(res.statistic[1:], np.diff(gf), rtol=0, atol=1e-9)
    assert np.isnan(res.statistic[0])


def test_melbourne_wubbena_one_cycle_wide_lane_is_marginal():
    """A 1-cycle wide-lane slip sits at the 4-sigma threshold (sigma_MW = 0.25 WL cycles for
    0.3 m code noise): ~50 % exceed it and ~50 % of those are confirmed by the next epoch, so
    ~25 % are detected.  Missed slips stay in the running mean for mw_window = 100 epochs,
    so these slips are spaced 150 epochs apart to measure each one on clean statistics."""
    det, _ = report("MW 1 Hz, |dN1-dN2| = 1",
                    campaign(mw_flags, [(1, 0), (0, 1)], 1.0, 3600, 10, spacing=150))
    assert 0.1 < det < 0.5


def test_combined_detects_every_slip_kind_at_1hz():
    kinds = L1_SLIPS + L2_ONLY + GF_BLIND + MW_BLIND
    det, fa = report("combined 1 Hz, all kinds", campaign(combined_flags, kinds, 1.0, 3600, 10))
    assert det >= 0.99
    assert fa <= 0.005


# --------------------------------------------------------------------------- 30 s


def test_geometry_free_at_30s():
    for order in (0, 1):
        det, fa = report(f"GF 30 s order {order}",
                         campaign(lambda arc, o=order: gf_flags(arc, o), GF_VISIBLE, 30.0, 4 * 3600, 20))
        assert det >= 0.99
        assert fa <= 0.005


def test_melbourne_wubbena_at_30s():
    det, fa = report("MW 30 s", campaign(mw_flags, MW_VISIBLE, 30.0, 4 * 3600, 20))
    assert det >= 0.99
    assert fa <= 0.005


def test_doppler_at_30s_sees_only_large_slips():
    small, fa = report("Doppler 30 s, 1-2 cycles",
                       campaign(doppler_flags, [(1, 0), (2, 0)], 30.0, 4 * 3600, 20))
    assert small <= 0.05
    assert fa <= 0.005
    large, _ = report("Doppler 30 s, 20-50 cycles",
                      campaign(doppler_flags, [(20, 0), (50, 0)], 30.0, 4 * 3600, 20))
    assert large >= 0.99


def test_combined_at_30s():
    kinds = GF_VISIBLE + MW_VISIBLE
    det, fa = report("combined 30 s", campaign(combined_flags, kinds, 30.0, 4 * 3600, 20))
    assert det >= 0.99
    assert fa <= 0.005


# --------------------------------------------------------------------------- flags and edge cases


def test_loss_of_lock_and_gaps_flag_the_next_valid_epoch():
    arc = simulate_arc(7, 1.0, 300)
    lli1 = arc.lli1.copy()
    lli1[100] = 1  # bit 0: loss of lock
    lli1[150] = 2  # bit 1 (half-cycle ambiguity) is not a loss of lock
    L1, L2 = arc.L1.copy(), arc.L2.copy()
    L1[200:203] = np.nan  # 3 missing epochs: gap of 4 s > 2 x 1 s
    L2[200:203] = np.nan
    L1[250] = L2[250] = np.nan  # 1 missing epoch: 2 s gap is tolerated
    arc = SatelliteArc(arc.time, L1, L2, arc.P1, arc.P2, arc.D1, lli1, arc.lli2)
    rep = detect_cycle_slips(arc)
    assert rep.max_gap_s == 2.0
    assert np.flatnonzero(rep.lli).tolist() == [100]
    assert np.flatnonzero(rep.gap).tolist() == [203]
    assert np.flatnonzero(rep.slip).tolist() == [100, 203]
    assert not rep.slip[0]


def test_explicit_max_gap_and_gap_detector():
    t = np.array([0.0, 1.0, 2.0, 8.0, 9.0, 15.0])
    valid = np.array([True, True, True, True, False, True])
    assert data_gap_detector(t, valid, 5.0).tolist() == [False, False, False, True, False, True]


def test_missing_code_disables_only_mw():
    arc = simulate_arc(8, 1.0, 200)
    P2 = arc.P2.copy()
    P2[50:60] = np.nan
    L1 = arc.L1.copy()
    L1[55:] += 1  # L1 slip while MW cannot be formed
    arc = SatelliteArc(arc.time, L1, arc.L2, arc.P1, P2, arc.D1)
    rep = detect_cycle_slips(arc)
    assert np.all(np.isnan(rep.mw.statistic[50:60]))
    assert np.flatnonzero(rep.slip).tolist() == [55]
    assert rep.doppler.flags[55]
    assert np.isnan(rep.gf.statistic[55])  # GF history was reset by the Doppler detection
    assert geometry_free_detector(arc.time, L1, arc.L2).flags[55]


def test_mw_single_epoch_code_outlier_is_not_a_slip():
    arc = simulate_arc(9, 1.0, 200)
    P1 = arc.P1.copy()
    P1[120] += 5.0  # 5 m code blunder, ~4.4 WL cycles in MW, returns next epoch
    res = melbourne_wubbena_detector(arc.L1, arc.L2, P1, arc.P2)
    assert res.outliers[120]
    assert not res.flags.any()


def test_bad_input_raises_clear_errors():
    arc = simulate_arc(10, 1.0, 20)
    t = arc.time.copy()
    t[5] = t[4]
    with pytest.raises(ValueError, match="not strictly increasing"):
        detect_cycle_slips(SatelliteArc(t, arc.L1, arc.L2, arc.P1, arc.P2, arc.D1))
    with pytest.raises(SlipInputError, match=r"arc.P2 must have shape \(20,\)"):
        detect_cycle_slips(SatelliteArc(arc.time, arc.L1, arc.L2, arc.P1, arc.P2[:10], arc.D1))
    with pytest.raises(SlipInputError, match="gf_threshold_m must be a positive"):
        detect_cycle_slips(arc, SlipConfig(gf_threshold_m=-1.0))


from tests.shared_data import RTKLIB_TEST as REAL_DATA


@pytest.mark.skipif(not REAL_DATA.is_dir(), reason=f"real data folder {REAL_DATA} absent")
@pytest.mark.parametrize("station", ["07590920.05o", "30400920.05o"])
def test_real_30s_static_arcs_flag_only_loss_of_lock(station):
    """GSI 0759/3040 (Trimble 5700, 30 s, 1 h): with the default config every flag falls on
    an epoch the receiver marked with LLI bit 0; no unexplained GF/MW flags (the setting
    satellites' ionosphere moves GF by up to ~4 cm per epoch, close to the 0.05 m limit)."""
    georinex = pytest.importorskip("georinex")
    ds = georinex.load(REAL_DATA / station, useindicators=True)
    t = (ds.time.values - ds.time.values[0]).astype("timedelta64[ms]").astype(float) / 1e3
    n_arcs = 0
    for sv in ds.sv.values:
        d = ds.sel(sv=sv)
        if np.isfinite(d.L1.values).sum() < 10:
            continue
        n_arcs += 1
        rep = detect_cycle_slips(SatelliteArc(t, d.L1.values, d.L2.values, d.C1.values,
                                              d.P2.values, np.full(t.size, np.nan),
                                              d.L1lli.values, d.L2lli.values))
        unexplained = np.flatnonzero(rep.slip & ~rep.lli)
        assert unexplained.size == 0, f"{station} {sv}: flags at {unexplained.tolist()}"
    assert n_arcs >= 8
