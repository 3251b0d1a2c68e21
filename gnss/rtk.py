"""GNSS-only kinematic RTK: DD code + L1/L2 phase float filter, WL → L1 LAMBDA fixing.

Model (short baseline, 001 §5.1.2.2; the ionosphere cancels in the DD): for every
non-reference satellite k of an epoch (DD w.r.t. the reference j, 001 eq. 5.1.7)

    ∇ΔP_i  = ∇Δρ(x0) + ∇ΔT + h_k·δx + ε_P              (C1, C2; m)
    ∇ΔΦ_i  = ∇Δρ(x0) + ∇ΔT + h_k·δx + λ_i ∇ΔN_i + ε_Φ   (λ1 L1, λ2 L2; m)

∇ΔT (RtkConfig.troposphere = "hydrostatic", as RTKLIB's relative mode and gmis.tc): DD of
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

Output Q like RTKLIB: 1 = fixed, 2 = float.
"""

from __future__ import annotations

import math
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gmis.earth import ecef_to_enu_matrix, ecef_to_geodetic, geodetic_to_ecef
from gmis.errors import GmisInputError
from gnss.constants import WAVELENGTH_L1, WAVELENGTH_L2
from gnss.cycle_slips import SatelliteArc, SlipConfig, detect_cycle_slips
from gnss.double_difference import DDSession, form_double_differences
from gnss.lambda_ils import ratio_test, resolve_integers
from gnss.rinex import ObsData, read_nav, read_obs
from gnss.spp import solve_spp_session
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


def _nearest_epochs(t_ref: np.ndarray, t: np.ndarray, tol: float = 0.025) -> np.ndarray:
    """Index into t_ref of the epoch nearest to each t (−1 when farther than tol)."""
    j = np.clip(np.searchsorted(t_ref, t), 1, max(t_ref.size - 1, 1))
    j = np.where(np.abs(t_ref[j - 1] - t) <= np.abs(t_ref[j] - t), j - 1, j)
    return np.where(np.abs(t_ref[j] - t) <= tol, j, -1)


def dd_slip_flags(dd: DDSession, base: ObsData, rover: ObsData,
                  config: SlipConfig) -> tuple[np.ndarray, np.ndarray]:
    """Slip flag per DD row (n_dd,) for satellite k and per epoch (n_ep,) for the reference
    (either receiver), from LLI (DD rows) and the per-receiver arc detectors.

    A flag raised at a receiver epoch, or for a satellite, that forms no DD (no epoch of
    the other receiver within tolerance, < 2 satellites, satellite below the mask or
    without code) is carried to the satellite's next DD epoch, so its ambiguity is reset."""
    flags_b = receiver_slip_flags(base, config)
    flags_r = receiver_slip_flags(rover, config)
    ib = _nearest_epochs(base.t_gps, dd.t_gps)
    ir = _nearest_epochs(rover.t_gps, dd.t_gps)
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
                config: RtkConfig | None = None, progress=None) -> RtkSolution:
    """Kinematic RTK over a base/rover session (module doc)."""
    cfg = config or RtkConfig()
    base_ecef = np.asarray(base_ecef, float)
    spp = solve_spp_session(rover, nav)
    if not spp.ok.any():
        raise GmisInputError("no rover epoch has a single-point solution (too few satellites "
                             "with C1 and ephemerides)", source=rover.path)
    x0 = spp.position.copy()
    ok_idx = np.flatnonzero(spp.ok)
    fill = ok_idx[np.clip(np.searchsorted(ok_idx, np.arange(x0.shape[0])), 0, ok_idx.size - 1)]
    x0[~spp.ok] = spp.position[fill[~spp.ok]]
    dd = form_double_differences(base, rover, nav, base_ecef, x0,
                                 elevation_mask_deg=cfg.elevation_mask_deg)
    row_slip, ref_slip = dd_slip_flags(dd, base, rover, cfg.slip)
    ir = _nearest_epochs(rover.t_gps, dd.t_gps)
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
        raise GmisInputError(f"rtk.troposphere: {cfg.troposphere!r} is not one of "
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


# ------------------------------------------------------------------------- output


_GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ms")


def write_pos(path, sol: RtkSolution, header_lines=()) -> Path:
    """RTKLIB-like .pos text: GPST (yyyy/mm/dd hh:mm:ss.sss), lat/lon (deg), height (m,
    ellipsoidal), Q (1 fix, 2 float), ns, sdn/sde/sdu (m), ratio."""
    path = Path(path)
    lines = [f"% {h}" for h in header_lines]
    lines.append("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns"
                 "   sdn(m)   sde(m)   sdu(m)  ratio")
    for i in range(sol.t_gps.size):
        if sol.q[i] == 0:
            continue
        t = _GPS_EPOCH + np.timedelta64(round(float(sol.t_gps[i]) * 1000.0), "ms")
        s = str(t).replace("-", "/").replace("T", " ")
        lat, lon, h = sol.llh[i]
        sn, se, su = sol.sigma_enu[i][[1, 0, 2]]
        lines.append(f"{s:23s} {math.degrees(lat):14.9f} {math.degrees(lon):14.9f} "
                     f"{h:10.4f} {sol.q[i]:3d} {sol.n_sat[i]:3d} {sn:8.4f} {se:8.4f} "
                     f"{su:8.4f} {sol.ratio[i]:6.1f}")
    path.write_text("\n".join(lines) + "\n")
    return path


def run_rnx2rtkp(rover_obs, base_obs, nav, base_ecef, out_pos, timeout_s: float = 120.0):
    """RTKLIB's kinematic reference solution with the settings gmis is compared under
    (rnx2rtkp -p 2 -f 2 -m 15 -v 3.0 -sys G, base position given as ECEF XYZ) written to
    out_pos; returns the wall time (s). Needs the Debian package rtklib."""
    import subprocess
    cmd = ["rnx2rtkp", "-p", "2", "-f", "2", "-m", "15", "-v", "3.0", "-sys", "G", "-t",
           "-r", *(f"{v:.4f}" for v in base_ecef), "-o", str(out_pos),
           str(rover_obs), str(base_obs), str(nav)]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, timeout=timeout_s)
    return time.perf_counter() - t0


def read_pos(path) -> dict:
    """Read an RTKLIB .pos (GPST date time, lat/lon/h in degrees) or one written by
    write_pos: t_gps (s), llh (n,3) rad/rad/m, q, ns, ratio (NaN when absent)."""
    t, llh, q, ns, ratio = [], [], [], [], []
    for line in Path(path).read_text().splitlines():
        if not line.strip() or line.startswith("%"):
            continue
        f = line.split()
        stamp = np.datetime64(f[0].replace("/", "-") + "T" + f[1], "ms")
        t.append((stamp - _GPS_EPOCH) / np.timedelta64(1, "s"))
        llh.append((math.radians(float(f[2])), math.radians(float(f[3])), float(f[4])))
        q.append(int(f[5]))
        ns.append(int(f[6]))
        ratio.append(float(f[-1]) if len(f) in (11, 15) else np.nan)
    return {"t_gps": np.array(t), "llh": np.array(llh).reshape(-1, 3),
            "q": np.array(q, np.int64), "ns": np.array(ns, np.int64), "ratio": np.array(ratio)}


# ------------------------------------------------------------------------- recipe


def read_rtk_recipe(recipe_path: Path) -> dict:
    """Rover/base/nav paths and base ECEF from a recipe ([paths] rover_obs, base_obs, nav;
    [base] ecef_m or lat_deg/lon_deg/h_m; optional [rtk] options). Read with tomllib so a
    GNSS-only recipe without [paths].imu is accepted."""
    src = str(recipe_path)
    if not recipe_path.is_file():
        raise GmisInputError("recipe file not found", source=src)
    try:
        doc = tomllib.loads(recipe_path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise GmisInputError(f"not valid TOML: {exc}", source=src) from None
    paths = doc.get("paths", {})
    out = {}
    for key in ("rover_obs", "base_obs", "nav"):
        rel = paths.get(key)
        if not isinstance(rel, str) or not rel.strip():
            raise GmisInputError(f"paths.{key}: required for rtk (RINEX file path)", source=src)
        p = Path(rel)
        p = p if p.is_absolute() else (recipe_path.parent / p).resolve()
        if not p.is_file():
            raise GmisInputError(f"paths.{key}: file not found: {p}", source=src)
        out[key] = p
    base = doc.get("base")
    if not isinstance(base, dict):
        raise GmisInputError("base: required section [base] (ecef_m or lat_deg/lon_deg/h_m) "
                             "for rtk", source=src)
    if "ecef_m" in base:
        xyz = base["ecef_m"]
        if (not isinstance(xyz, list) or len(xyz) != 3
                or not all(isinstance(v, (int, float)) for v in xyz)):
            raise GmisInputError("base.ecef_m: expected [x, y, z] numbers (m)", source=src)
        xyz = np.array(xyz, float)
        if not 6.30e6 < np.linalg.norm(xyz) < 6.48e6:
            raise GmisInputError("base.ecef_m: not an ECEF position near the earth's surface",
                                 source=src)
    else:
        try:
            lat, lon, h = (float(base[k]) for k in ("lat_deg", "lon_deg", "h_m"))
        except (KeyError, TypeError, ValueError):
            raise GmisInputError("base: give ecef_m = [x, y, z] or numeric lat_deg, lon_deg, "
                                 "h_m", source=src) from None
        xyz = geodetic_to_ecef(math.radians(lat), math.radians(lon), h)
    out["base_ecef"] = xyz
    rtk = doc.get("rtk", {})
    known = {f for f in RtkConfig.__dataclass_fields__ if f != "slip"}
    bad = [k for k in rtk if k not in known]
    if bad:
        raise GmisInputError(f"rtk.{bad[0]}: unknown option; valid: {', '.join(sorted(known))}",
                             source=src)
    if rtk.get("troposphere", "hydrostatic") not in TROPOSPHERE_MODELS:
        raise GmisInputError(f"rtk.troposphere: {rtk['troposphere']!r} is not one of "
                             f"{', '.join(TROPOSPHERE_MODELS)}", source=src)
    from gmis.plausibility import check_rtk_options
    check_rtk_options(rtk, src)
    out["config"] = RtkConfig(**rtk)
    out["name"] = str(doc.get("dataset", {}).get("name", recipe_path.parent.name))
    return out


def run_rtk_recipe(recipe_path, results_dir, progress=None) -> dict:
    """Run RTK for a recipe and write rtk.pos, rtk.csv and summary.json into results_dir
    (atomically via gmis.results.results_directory). Returns the summary dict."""
    from gmis.results import results_directory, write_csv, write_json

    recipe_path = Path(recipe_path).expanduser().resolve()
    inp = read_rtk_recipe(recipe_path)
    t0 = time.perf_counter()
    base = read_obs(inp["base_obs"])
    rover = read_obs(inp["rover_obs"])
    nav = read_nav(inp["nav"])
    from gmis.plausibility import check_rtk_inputs, solved_epochs
    check_rtk_inputs(base, rover, nav, inp["base_ecef"], str(recipe_path))
    sol = process_rtk(base, rover, nav, inp["base_ecef"], inp["config"], progress=progress)
    wall = time.perf_counter() - t0
    fixed = sol.q == Q_FIXED
    summary = {
        "dataset": inp["name"],
        "epochs": int(sol.t_gps.size),
        "epochs_solved": int((sol.q > 0).sum()),
        "epochs_fixed": int(fixed.sum()),
        "fix_rate": sol.fix_rate,
        "median_ratio": float(np.median(sol.ratio[sol.q > 0])) if (sol.q > 0).any() else 0.0,
        "mean_fixed_ecef_m": sol.ecef[fixed].mean(axis=0).tolist() if fixed.any() else None,
        "baseline_length_m": float(np.linalg.norm(sol.ecef[fixed].mean(axis=0)
                                                  - inp["base_ecef"])) if fixed.any() else None,
        "wall_time_s": wall,
    }
    sol = solved_epochs(sol, sol.q > 0, "gmis rtk", inp["rover_obs"])
    with results_directory(results_dir) as out:
        write_pos(out / "rtk.pos", sol, [f"gmis rtk {recipe_path}",
                                         f"base ECEF {np.round(inp['base_ecef'], 4).tolist()}"])
        write_csv(out / "rtk.csv", ["t_gps_s", "x_m", "y_m", "z_m", "lat_deg", "lon_deg",
                                    "h_m", "q", "ratio", "n_sat", "sigma_e_m", "sigma_n_m",
                                    "sigma_u_m"],
                  sol.t_gps, sol.ecef, np.degrees(sol.llh[:, :2]), sol.llh[:, 2], sol.q,
                  sol.ratio, sol.n_sat, sol.sigma_enu, fmt="%.12g")
        write_json(out / "summary.json", summary)
    return summary

