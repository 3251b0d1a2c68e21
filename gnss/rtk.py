"""GNSS-only kinematic RTK: DD code + L1/L2 phase float filter, WL → L1 LAMBDA fixing.

Model (short baseline, 001 §5.1.2.2; the ionosphere cancels in the DD): for every
non-reference satellite k of an epoch (DD w.r.t. the reference j, 001 eq. 5.1.7)

    ∇ΔP_i  = ∇Δρ(x0) + ∇ΔT + h_k·δx + ε_P              (C1, C2; m)
    ∇ΔΦ_i  = ∇Δρ(x0) + ∇ΔT + h_k·δx + λ_i ∇ΔN_i + ε_Φ   (λ1 L1, λ2 L2; m)

∇ΔT (RtkConfig.troposphere = "hydrostatic", as RTKLIB's relative mode and gmis.tc_filter): DD of
the rover − base hydrostatic Saastamoinen slant delay (gnss.troposphere, humidity 0), base
side at the known base position, rover side at the epoch's current rover estimate — the
float solution of a first pass at x0, then the epoch is solved again (the SPP height's
metre-level noise would add ~1 mm/m to ∇ΔT). Its gradient (~3e-4 m per m of height) is
left out of the design matrix. Elevations are those of the DD epoch (at x0; a few metres
of position error change them by ~1e-7 rad). With a 5 m antenna-height difference it is
a few mm in the DD and shifts the solution by several mm (0759/3040); "none" assumes it
cancels. "hydrostatic" is the default (RtkConfig and a recipe's [rtk] troposphere).

with δx the rover position correction to the linearisation point x0 (the SPP position;
the neglected curvature |δx|²/ρ is ~1e-6 m for metre-level SPP errors) and h_k the design
row of gnss.double_difference. Covariance per observable type σ90²·M (001 eq. 5.1.8-5.1.11),
σ_code = 0.3 m, σ_phase = 3 mm (RTKLIB defaults).

Filter (documented choice): the state carried between epochs is the vector of DD
ambiguities [∇ΔN_1; ∇ΔN_2] (cycles) with its covariance; the rover position has infinite
process noise (kinematic), so every epoch solves the normal equations

    (Aᵀ R⁻¹ A + Π) [δx; a] = Aᵀ R⁻¹ y + Π [0; a⁻],  Π = blockdiag(0, P_a⁻¹),

which is exactly the Kalman update with position states reset each epoch; ambiguities of
new (or slipped) satellites get no prior (Π rows zero). A reference-satellite change
j → j' re-maps carried ambiguities: ∇ΔN^{kj'} = ∇ΔN^{kj} − ∇ΔN^{j'j}, ∇ΔN^{jj'} = −∇ΔN^{j'j}
(linear map T applied to mean and covariance). Cycle slips (LLI, data gap, geometry-free
and Melbourne-Wübbena detectors of gnss.cycle_slips on each receiver's arcs) reset the
satellite's ambiguities; a slip of the reference satellite resets all.

Ambiguity resolution (Teunissen LAMBDA, gnss.lambda_ils): wide lane N_WL = N1 − N2 first
(ratio test); the float solution is conditioned on the fixed WL, then N1 is fixed by LAMBDA
(ratio test), N2 = N1 − N_WL, and the baseline is conditioned on the integers
(x̌ = x̂ − Q_xa Q_a⁻¹ (â − ǎ)). Continuous AR: integers that passed the ratio test are held
across epochs (re-mapped at reference changes, dropped on slips); when a later epoch's own
ratio fails, the held integers still fix the solution if they agree with the float
ambiguities to within ``hold_tolerance_cycles``.

Output Q like RTKLIB: 1 = fixed, 2 = float (gnss.pos_file writes and reads .pos files).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gnss.constants import WAVELENGTH_L1, WAVELENGTH_L2
from gnss.cycle_slips import SatelliteArc, SlipConfig, detect_cycle_slips
from gnss.double_difference import DDSession, form_double_differences
from gnss.epoch_matching import match_epochs
from gnss.errors import GnssInputError
from gnss.geodesy import ecef_to_enu_matrix, ecef_to_geodetic
from gnss.lambda_ils import ratio_test, resolve_integers
from gnss.rinex import ObsData
from gnss.spp import filled_positions, solve_spp_session
from gnss.troposphere import saastamoinen_delay

Q_FIXED = 1
Q_FLOAT = 2
TROPOSPHERE_MODELS = ("hydrostatic", "none")


@dataclass(frozen=True)
class RtkConfig:
    """Processing options (units: m, cycles, degrees)."""

    elevation_mask_deg: float = 15.0
    ratio_threshold: float = 3.0
    sigma_code_m: float = 0.3
    sigma_phase_m: float = 0.003
    ambiguity_process_noise_cycles2: float = 1e-8
    continuous: bool = True
    hold_tolerance_cycles: float = 0.3
    min_fix_satellites: int = 4
    troposphere: str = "hydrostatic"   # or "none" (module doc)
    slip: SlipConfig = field(default_factory=SlipConfig)


@dataclass
class RtkSolution:
    """Per epoch (n,): t_gps (s), ecef (n,3) m, llh (n,3) rad/rad/m, q (1 fixed / 2 float /
    0 none), ratio, n_sat (satellites used incl. reference), sigma_enu (n,3) m (float or
    fixed solution σ), ambiguities_fixed (n,) number of fixed DD ambiguities, ref_prn (n,)
    reference satellite, integers: per epoch {(prn, freq): DD integer} or None (float)."""

    t_gps: np.ndarray
    ecef: np.ndarray
    llh: np.ndarray
    q: np.ndarray
    ratio: np.ndarray
    n_sat: np.ndarray
    sigma_enu: np.ndarray
    ambiguities_fixed: np.ndarray
    ref_prn: np.ndarray
    integers: list

    @property
    def fix_rate(self) -> float:
        valid = self.q > 0
        return float(np.mean(self.q[valid] == Q_FIXED)) if valid.any() else 0.0


# ------------------------------------------------------------------------- slips


def receiver_slip_flags(obs: ObsData, config: SlipConfig) -> np.ndarray:
    """(n_ep, n_sat) bool: LLI / gap / GF / MW slip of each satellite arc of one receiver."""
    flags = np.zeros(obs.L1.shape, dtype=bool)
    for s in range(obs.prn.size):
        valid = np.isfinite(obs.L1[:, s]) | np.isfinite(obs.L2[:, s])
        if valid.sum() < 2:
            continue
        arc = SatelliteArc(time=obs.t_gps, L1=obs.L1[:, s], L2=obs.L2[:, s], P1=obs.C1[:, s],
                           P2=obs.C2[:, s], D1=obs.D1[:, s], lli1=obs.LLI1[:, s],
                           lli2=obs.LLI2[:, s])
        flags[:, s] = detect_cycle_slips(arc, config).slip
    return flags


def dd_slip_flags(dd: DDSession, base: ObsData, rover: ObsData,
                  config: SlipConfig) -> tuple[np.ndarray, np.ndarray]:
    """Slip flag per DD row (n_dd,) for satellite k and per epoch (n_ep,) for the reference
    (either receiver), from LLI (DD rows) and the per-receiver arc detectors.

    A flag raised at a receiver epoch, or for a satellite, that forms no DD (no epoch of
    the other receiver within tolerance, < 2 satellites, satellite below the mask or
    without code) is carried to the satellite's next DD epoch, so its ambiguity is reset."""
    flags_b = receiver_slip_flags(base, config)
    flags_r = receiver_slip_flags(rover, config)
    ib = match_epochs(base.t_gps, dd.t_gps)
    ir = match_epochs(rover.t_gps, dd.t_gps)
    prns = np.union1d(base.prn, rover.prn)
    col = {int(p): i for i, p in enumerate(prns)}
    # receiver flags in the common satellite column order: (n_ep, n_prn)
    per_prn = []
    for obs, flags in ((base, flags_b), (rover, flags_r)):
        f = np.zeros((flags.shape[0], prns.size), bool)
        f[:, np.searchsorted(prns, obs.prn)] = flags
        per_prn.append(f)
    pending = np.zeros(prns.size, bool)
    last = [-1, -1]                                      # last receiver epoch accumulated
    row = dd.lli_l1 | dd.lli_l2
    ref = np.zeros(dd.n_epochs, bool)
    for e in range(dd.n_epochs):
        for r, idx in enumerate((ib, ir)):
            if idx[e] > last[r]:
                pending |= per_prn[r][last[r] + 1:idx[e] + 1].any(axis=0)
                last[r] = idx[e]
        a, b = dd.start[e], dd.start[e + 1]
        if a == b:
            continue
        cols = [col[int(p)] for p in dd.prn[a:b]]
        row[a:b] |= pending[cols]
        ref[e] = pending[col[int(dd.ref_prn[e])]]
        pending[cols] = False
        pending[col[int(dd.ref_prn[e])]] = False
    return row, ref


# ------------------------------------------------------------------------- ambiguity state


class AmbiguityState:
    """Carried DD ambiguities keyed (prn, freq) w.r.t. reference ``ref``: mean (cycles),
    covariance (cycles²) in ``keys`` order."""

    def __init__(self):
        self.ref = -1
        self.keys: list[tuple[int, int]] = []
        self.mean = np.zeros(0)
        self.cov = np.zeros((0, 0))

    def reset(self):
        self.__init__()

    def remap_reference(self, new_ref: int) -> None:
        """∇ΔN^{kj'} = ∇ΔN^{kj} − ∇ΔN^{j'j}; the old reference j becomes −∇ΔN^{j'j}.
        Frequencies without the new reference among the carried states are dropped."""
        if new_ref == self.ref or not self.keys:
            self.ref = new_ref
            return
        old = self.ref
        n = len(self.keys)
        rows, new_keys = [], []
        for f in (1, 2):
            pivot = [i for i, kf in enumerate(self.keys) if kf == (new_ref, f)]
            if not pivot:
                continue
            p = pivot[0]
            for i, (prn, ff) in enumerate(self.keys):
                if ff != f or i == p:
                    continue
                t = np.zeros(n)
                t[i], t[p] = 1.0, -1.0
                rows.append(t)
                new_keys.append((prn, f))
            t = np.zeros(n)
            t[p] = -1.0
            rows.append(t)
            new_keys.append((old, f))
        T = np.array(rows).reshape(len(rows), n)
        self.mean = T @ self.mean
        self.cov = T @ self.cov @ T.T
        self.keys = new_keys
        self.ref = new_ref

    def drop(self, keep) -> None:
        idx = [i for i, k in enumerate(self.keys) if k in keep]
        self.keys = [self.keys[i] for i in idx]
        self.mean = self.mean[idx]
        self.cov = self.cov[np.ix_(idx, idx)]


def remap_integers(held: dict, old_ref: int, new_ref: int) -> dict:
    """Held integer DD ambiguities {(prn, f): n} re-mapped to a new reference (as
    AmbiguityState.remap_reference); frequencies lacking the new reference are dropped."""
    if old_ref == new_ref or not held:
        return dict(held)
    out = {}
    for f in (1, 2):
        if (new_ref, f) not in held:
            continue
        piv = held[(new_ref, f)]
        for (prn, ff), n in held.items():
            if ff == f and prn != new_ref:
                out[(prn, f)] = n - piv
        out[(old_ref, f)] = -piv
    return out


# ------------------------------------------------------------------------- one epoch


def _condition(x, Q, C, value):
    """Condition N(x, Q) on the exact linear constraint C x = value."""
    S = C @ Q @ C.T
    K = np.linalg.solve(S, C @ Q).T
    return x - K @ (C @ x - value), Q - K @ C @ Q


@dataclass
class EpochFloat:
    prn: np.ndarray
    keys: list
    x: np.ndarray
    Q: np.ndarray
    H: np.ndarray
    y: np.ndarray
    R: np.ndarray


def float_epoch(ep, state: AmbiguityState, cfg: RtkConfig,
                troposphere=None) -> EpochFloat | None:
    """Float update of one DD epoch (module doc): unknowns [δx(3), a1, a2] (m, cycles).
    troposphere: None, or a function δx → (m,) ∇ΔT (m) per DD row at the rover position
    x0 + δx; it is evaluated at δx = 0 and then at the first float δx, and the epoch is
    solved again with the latter (y only; not in the design matrix)."""
    obs = ep.observables
    m = ep.prn.size
    M = ep.cofactor
    have1 = np.isfinite(obs["L1"])
    have2 = np.isfinite(obs["L2"])
    keys = [(int(p), 1) for p in ep.prn[have1]] + [(int(p), 2) for p in ep.prn[have2]]
    na = len(keys)
    col = {k: 3 + i for i, k in enumerate(keys)}
    blocks = []
    rows = []                                            # DD row (satellite) of each y
    for name, lam, freq in (("C1", 0.0, 1), ("C2", 0.0, 2), ("L1", WAVELENGTH_L1, 1),
                            ("L2", WAVELENGTH_L2, 2)):
        v = obs[name]
        ok = np.isfinite(v)
        if not ok.any():
            continue
        sig = cfg.sigma_phase_m if lam else cfg.sigma_code_m
        A = np.zeros((ok.sum(), 3 + na))
        A[:, :3] = ep.design[ok]
        yv = (lam * v[ok] if lam else v[ok]) - ep.computed_range[ok]
        if lam:
            for r, p in enumerate(ep.prn[ok]):
                A[r, col[(int(p), freq)]] = lam
        blocks.append((A, yv, sig ** 2 * M[np.ix_(ok, ok)]))
        rows.append(np.flatnonzero(ok))
    if not blocks:
        return None
    A = np.vstack([b[0] for b in blocks])
    y = np.concatenate([b[1] for b in blocks])
    R = np.zeros((y.size, y.size))
    o = 0
    for b in blocks:
        k = b[1].size
        R[o:o + k, o:o + k] = b[2]
        o += k
    W = np.linalg.inv(R)
    N = A.T @ W @ A
    b = A.T @ W @ y
    prior = [i for i, k in enumerate(state.keys) if k in col]
    if prior:
        idx = np.array([col[state.keys[i]] for i in prior])
        P = state.cov[np.ix_(prior, prior)] + cfg.ambiguity_process_noise_cycles2 * np.eye(len(prior))
        Pinv = np.linalg.inv(P)
        N[np.ix_(idx, idx)] += Pinv
        b[idx] += Pinv @ state.mean[prior]
    if np.linalg.matrix_rank(N) < N.shape[0] or m < 3:
        return None
    Q = np.linalg.inv(N)
    x = Q @ b
    if troposphere is not None:
        rows = np.concatenate(rows)
        b_trop = A.T @ W
        x_sol = x
        for dx in (np.zeros(3), None):
            trop = troposphere(x_sol[:3] if dx is None else dx)[rows]
            x_sol = Q @ (b - b_trop @ trop)
        x = x_sol
        y = y - trop
    Q = 0.5 * (Q + Q.T)
    return EpochFloat(ep.prn, keys, x, Q, A, y, R)


def resolve_epoch(fl: EpochFloat, held: dict, cfg: RtkConfig):
    """WL then L1 LAMBDA (module doc). Returns (x_fixed or None, Q_x fixed, ratio,
    integers {(prn, f): n} or None, n_fixed_ambiguities)."""
    col = {k: 3 + i for i, k in enumerate(fl.keys)}
    both = [int(p) for p in fl.prn if (int(p), 1) in col and (int(p), 2) in col]
    n_all = fl.x.size
    if len(both) + 1 < cfg.min_fix_satellites:
        return None, None, 0.0, None, 0
    i1 = np.array([col[(p, 1)] for p in both])
    i2 = np.array([col[(p, 2)] for p in both])
    C_wl = np.zeros((len(both), n_all))
    C_wl[np.arange(len(both)), i1] = 1.0
    C_wl[np.arange(len(both)), i2] = -1.0
    x, Q = fl.x, fl.Q
    ratio = 0.0
    wl = resolve_integers(C_wl @ x, C_wl @ Q @ C_wl.T)
    ints = None
    if ratio_test(wl, cfg.ratio_threshold):
        xw, Qw = _condition(x, Q, C_wl, wl.fixed.astype(float))
        l1 = resolve_integers(xw[i1], Qw[np.ix_(i1, i1)])
        ratio = min(l1.ratio, wl.ratio)
        if ratio_test(l1, cfg.ratio_threshold):
            ints = {}
            for p, n1, w in zip(both, l1.fixed, wl.fixed):
                ints[(p, 1)] = int(n1)
                ints[(p, 2)] = int(n1 - w)
    else:
        ratio = wl.ratio
    if ints is None and cfg.continuous and held:
        usable = [p for p in both if (p, 1) in held and (p, 2) in held]
        if len(usable) + 1 >= cfg.min_fix_satellites:
            cand = {}
            for p in usable:
                cand[(p, 1)], cand[(p, 2)] = held[(p, 1)], held[(p, 2)]
            dev = [abs(x[col[k]] - n) for k, n in cand.items()]
            dev_wl = [abs(x[col[(p, 1)]] - x[col[(p, 2)]] - (cand[(p, 1)] - cand[(p, 2)]))
                      for p in usable]
            if max(dev) < cfg.hold_tolerance_cycles and max(dev_wl) < cfg.hold_tolerance_cycles:
                ints = cand
    if ints is None:
        return None, None, ratio, None, 0
    keys = list(ints)
    C = np.zeros((len(keys), n_all))
    C[np.arange(len(keys)), [col[k] for k in keys]] = 1.0
    xf, Qf = _condition(x, Q, C, np.array([ints[k] for k in keys], float))
    return xf, Qf, ratio, ints, len(keys)


# ------------------------------------------------------------------------- session


def process_rtk(base: ObsData, rover: ObsData, nav, base_ecef,
                config: RtkConfig | None = None, progress=None,
                rover_spp=None) -> RtkSolution:
    """Kinematic RTK over a base/rover session (module doc). rover_spp: the rover's
    gnss.spp.SppSession when already solved (else solved here), the linearisation point."""
    cfg = config or RtkConfig()
    base_ecef = np.asarray(base_ecef, float)
    spp = rover_spp if rover_spp is not None else solve_spp_session(rover, nav)
    if not spp.ok.any():
        raise GnssInputError("no rover epoch has a single-point solution (too few satellites "
                             "with C1 and ephemerides)", source=rover.path)
    x0 = filled_positions(spp)
    dd = form_double_differences(base, rover, nav, base_ecef, x0,
                                 elevation_mask_deg=cfg.elevation_mask_deg)
    row_slip, ref_slip = dd_slip_flags(dd, base, rover, cfg.slip)
    ir = match_epochs(rover.t_gps, dd.t_gps)
    epochs = [dd.epoch(i) for i in range(dd.n_epochs)]
    rows = [row_slip[dd.start[i]:dd.start[i + 1]] for i in range(dd.n_epochs)]
    x_lin = np.array([x0[j] if j >= 0 else x0[0] for j in ir])
    return process_dd_epochs(epochs, x_lin, cfg, rows, ref_slip, progress, base_ecef)


def dd_hydrostatic_delay(ep, base_llh, rover_ecef) -> np.ndarray:
    """∇ΔT (m,) m: DD (k − reference) of the rover − base hydrostatic Saastamoinen slant
    delay (humidity 0) at the epoch's base/rover elevations; base_llh (lat, lon, h) rad/m,
    rover_ecef (3,) m (module doc)."""
    lat, _, h = ecef_to_geodetic(*rover_ecef)
    el_r = np.append(ep.elevation_rover, ep.ref_elevation_rover)
    el_b = np.append(ep.elevation_base, ep.ref_elevation_base)
    sd = saastamoinen_delay(lat, h, el_r, humidity=0.0) - \
        saastamoinen_delay(base_llh[0], base_llh[2], el_b, humidity=0.0)
    return sd[:-1] - sd[-1]


def process_dd_epochs(epochs, x_lin, config: RtkConfig | None = None, row_slip=None,
                      ref_slip=None, progress=None, base_ecef=None) -> RtkSolution:
    """The RTK epoch loop over DD epochs (list of DDEpoch or None) linearised at x_lin
    (n,3) ECEF m: float update, ambiguity re-mapping, slip resets, WL/L1 fixing (module
    doc). row_slip: per epoch (m,) bool slip of satellite k (LLI flags of the DD are always
    used); ref_slip (n,) bool slip of the reference satellite. base_ecef: (3,) m fixed base
    for the hydrostatic troposphere model (config.troposphere); None (e.g. the moving
    base of gnss.heading) models no troposphere."""
    cfg = config or RtkConfig()
    if cfg.troposphere not in TROPOSPHERE_MODELS:
        raise GnssInputError(f"rtk.troposphere: {cfg.troposphere!r} is not one of "
                             f"{', '.join(TROPOSPHERE_MODELS)}")
    base_llh = None
    if cfg.troposphere == "hydrostatic" and base_ecef is not None:
        base_llh = ecef_to_geodetic(*np.asarray(base_ecef, float))
    n = len(epochs)
    t = np.array([ep.t_gps if ep is not None else np.nan for ep in epochs])
    out = RtkSolution(t_gps=t, ecef=np.full((n, 3), np.nan),
                      llh=np.full((n, 3), np.nan), q=np.zeros(n, np.int64),
                      ratio=np.zeros(n), n_sat=np.zeros(n, np.int64),
                      sigma_enu=np.full((n, 3), np.nan), ambiguities_fixed=np.zeros(n, np.int64),
                      ref_prn=np.full(n, -1, np.int64), integers=[None] * n)
    state = AmbiguityState()
    held: dict = {}
    for i, ep in enumerate(epochs):
        if progress is not None and n:
            progress(i / n)
        if ep is None:
            continue
        slip_rows = ep.lli_l1 | ep.lli_l2
        if row_slip is not None:
            slip_rows = slip_rows | np.asarray(row_slip[i], bool)
        if ref_slip is not None and ref_slip[i]:
            state.reset()
            held = {}
        held = remap_integers(held, state.ref, ep.ref_prn) if state.ref >= 0 else {}
        state.remap_reference(ep.ref_prn)
        slipped = {int(p) for p in ep.prn[slip_rows]}
        present = {(int(p), f) for p in ep.prn for f in (1, 2)} - \
                  {(p, f) for p in slipped for f in (1, 2)}
        state.drop(present)
        held = {k: v for k, v in held.items() if k in present}
        trop = None
        if base_llh is not None:
            def trop(dx, ep=ep, x0=x_lin[i]):
                return dd_hydrostatic_delay(ep, base_llh, x0 + dx)
        fl = float_epoch(ep, state, cfg, trop)
        if fl is None:
            continue
        state.ref = ep.ref_prn
        state.keys = list(fl.keys)
        state.mean = fl.x[3:].copy()
        state.cov = fl.Q[3:, 3:].copy()
        xf, Qf, ratio, ints, nfix = resolve_epoch(fl, held, cfg)
        if ints is not None:
            held = ints
            dx, Qx, q = xf[:3], Qf[:3, :3], Q_FIXED
        else:
            dx, Qx, q = fl.x[:3], fl.Q[:3, :3], Q_FLOAT
        pos = x_lin[i] + dx
        lat, lon, h = ecef_to_geodetic(*pos)
        Ce = ecef_to_enu_matrix(lat, lon)
        out.ecef[i] = pos
        out.llh[i] = (lat, lon, h)
        out.q[i] = q
        out.ratio[i] = ratio
        out.n_sat[i] = ep.prn.size + 1
        out.sigma_enu[i] = np.sqrt(np.diag(Ce @ Qx @ Ce.T))
        out.ambiguities_fixed[i] = nfix
        out.ref_prn[i] = ep.ref_prn
        out.integers[i] = dict(ints) if ints is not None else None
    if progress is not None:
        progress(1.0)
    return out
