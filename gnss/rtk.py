"""GNSS-only kinematic RTK: DD code + L1/L2 phase float filter, WL → L1 LAMBDA fixing
(or L1-only single-frequency fixing), partial ambiguity resolution.

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

Single frequency (RtkConfig.frequencies = ("L1",)): only C1 and L1 enter the float filter
(process_rtk also drops C2/L2/D2 and LLI2 from the RINEX, observed_frequencies, so the slip
detectors work as for an L1-only receiver: LLI, data gaps, Doppler-predicted phase; the
geometry-free and Melbourne-Wübbena tests need L2). LAMBDA fixes the L1 DD ambiguities
directly. The L1 float ambiguities converge slowly (code σ 0.3 m vs λ1 0.19 m), so the
policy is stricter than dual-frequency's (each a field, defaults chosen by the frequencies):
  * lock: a DD ambiguity takes part in AR only after its satellite and the reference have
    been tracked without reset for min_lock_epochs epochs (default 5; dual 1);
  * validation: ratio test and the χ² test s_best = (â − ǎ)ᵀ Q_â⁻¹ (â − ǎ) ≤ χ²_n(1 − α),
    α = fix_chi2_alpha (1e-3), and the integer-bootstrapping success rate of the set from
    its float covariance (gnss.lambda_ils.bootstrap_success_rate; WL × L1|WL in the
    cascade) ≥ min_success_rate when that is > 0 (default 0, off: at 0.999 the real
    0759/3040 L1 session's first fix moves from epoch 4 to 12, 116 → 108 fixed epochs,
    below RTKLIB's 114, the refused early fixes being right — P_s 0.75-0.998 there;
    docs/DESIGN.md "GNSS side");
  * fix-and-hold (default on; dual off): after a fix the carried ambiguity state is updated
    with the pseudo-observations ∇ΔN = ǎ of variance hold_variance_cycles2 (1e-3 cycles², as
    RTKLIB's holdamb), so the next epoch's float agrees with the held integers.
Partial AR (partial_ar; default on for L1, off for L1+L2 so the dual-frequency results are
unchanged): when the full set fails and the held integers do not validate, the satellite
with the lowest rover elevation is dropped (all its ambiguities) one at a time while at
least min_fix_satellites satellites (reference included) remain; the first subset that
passes the ratio and χ² tests is fixed and the remaining floats are conditioned on it.

Output Q like RTKLIB: 1 = fixed, 2 = float (gnss.pos_file writes and reads .pos files).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.stats import chi2

from gnss.constants import WAVELENGTH_L1, WAVELENGTH_L2
from gnss.cycle_slips import SatelliteArc, SlipConfig, detect_cycle_slips
from gnss.double_difference import DDSession, form_double_differences
from gnss.epoch_matching import match_epochs
from gnss.errors import GnssInputError
from gnss.geodesy import ecef_to_enu_matrix, ecef_to_geodetic
from gnss.lambda_ils import bootstrap_success_rate, ratio_test, resolve_integers
from gnss.rinex import ObsData
from gnss.spp import filled_positions, solve_spp_session
from gnss.troposphere import saastamoinen_delay_scalar

Q_FIXED = 1
Q_FLOAT = 2
TROPOSPHERE_MODELS = ("hydrostatic", "none")
FREQUENCY_SETS = (("L1", "L2"), ("L1",))


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
    frequencies: tuple = ("L1", "L2")  # or ("L1",): single-frequency (module doc)
    partial_ar: bool | None = None     # subset AR (module doc); None: on L1 / off dual
    min_lock_epochs: int | None = None  # epochs tracked before AR; None: 1 dual / 5 L1
    fix_and_hold: bool | None = None   # fixed integers fed back; None: off dual / on L1
    hold_variance_cycles2: float = 1e-3  # fix-and-hold pseudo-observation variance
    fix_chi2_alpha: float = 1e-3       # single-frequency / partial fix χ² test level
    min_success_rate: float = 0.0      # single-frequency / partial: bootstrapping P_s ≥ this
    slip: SlipConfig = field(default_factory=SlipConfig)

    def __post_init__(self):
        if tuple(self.frequencies) not in FREQUENCY_SETS:
            raise GnssInputError(f"rtk.frequencies: {list(self.frequencies)!r} is not one of "
                                 + ", ".join(str(list(f)) for f in FREQUENCY_SETS))
        object.__setattr__(self, "frequencies", tuple(self.frequencies))
        if not 0.0 < self.fix_chi2_alpha < 1.0:
            raise GnssInputError(f"rtk.fix_chi2_alpha: {self.fix_chi2_alpha!r} out of range "
                                 "(0, 1)")
        if not 0.0 <= self.min_success_rate < 1.0:
            raise GnssInputError(f"rtk.min_success_rate: {self.min_success_rate!r} out of "
                                 "range [0, 1)")

    @property
    def dual_frequency(self) -> bool:
        return "L2" in self.frequencies

    @property
    def partial_fixing(self) -> bool:
        """Partial AR (module doc): partial_ar, or by default single-frequency only."""
        return (not self.dual_frequency) if self.partial_ar is None else self.partial_ar

    @property
    def holds_fixes(self) -> bool:
        """Fix-and-hold (module doc): fix_and_hold, or by default single-frequency only."""
        return (not self.dual_frequency) if self.fix_and_hold is None else self.fix_and_hold

    @property
    def lock_epochs(self) -> int:
        """Epochs a DD ambiguity must have been tracked (this one included) before it takes
        part in AR: min_lock_epochs, or by default 1 dual- / 5 single-frequency."""
        if self.min_lock_epochs is not None:
            return int(self.min_lock_epochs)
        return 1 if self.dual_frequency else 5


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
    partial: np.ndarray | None = None    # (n,) bool: fixed by partial AR (a subset)
    cov_enu: np.ndarray | None = None    # (n, 3, 3) m²: full ENU covariance of the solution

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

    def hold(self, integers: dict, variance: float) -> None:
        """Fix-and-hold: Kalman update of the carried ambiguities with the pseudo-
        observations ∇ΔN_k = ň_k (variance cycles²) of the fixed integers {(prn, f): n}."""
        idx = [i for i, k in enumerate(self.keys) if k in integers]
        if not idx:
            return
        H = np.zeros((len(idx), len(self.keys)))
        H[np.arange(len(idx)), idx] = 1.0
        z = np.array([integers[self.keys[i]] for i in idx], float)
        S = H @ self.cov @ H.T + variance * np.eye(len(idx))
        K = np.linalg.solve(S, H @ self.cov).T
        self.mean = self.mean + K @ (z - H @ self.mean)
        cov = self.cov - K @ H @ self.cov
        self.cov = 0.5 * (cov + cov.T)

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
    elevation: np.ndarray | None = None   # (m,) rover elevation of ep.prn (rad)


def float_epoch(ep, state: AmbiguityState, cfg: RtkConfig,
                troposphere=None) -> EpochFloat | None:
    """Float update of one DD epoch (module doc): unknowns [δx(3), a1, a2] (m, cycles).
    troposphere: None, or a function δx → (m,) ∇ΔT (m) per DD row at the rover position
    x0 + δx; it is evaluated at δx = 0 and then at the first float δx, and the epoch is
    solved again with the latter (y only; not in the design matrix)."""
    obs = ep.observables
    m = ep.prn.size
    M = ep.cofactor
    dual = cfg.dual_frequency
    have1 = np.isfinite(obs["L1"])
    have2 = np.isfinite(obs["L2"]) if dual else np.zeros(m, bool)
    keys = [(int(p), 1) for p in ep.prn[have1]] + [(int(p), 2) for p in ep.prn[have2]]
    na = len(keys)
    col = {k: 3 + i for i, k in enumerate(keys)}
    blocks = []
    rows = []                                            # DD row (satellite) of each y
    for name, lam, freq in (("C1", 0.0, 1), ("C2", 0.0, 2), ("L1", WAVELENGTH_L1, 1),
                            ("L2", WAVELENGTH_L2, 2)):
        if freq == 2 and not dual:
            continue
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
    return EpochFloat(ep.prn, keys, x, Q, A, y, R, np.asarray(ep.elevation_rover, float))


def _chi2_consistent(res, alpha: float) -> bool:
    """The float ambiguities agree with the best integer vector: s_best = (â − ǎ)ᵀ Q_â⁻¹
    (â − ǎ) ≤ χ²_n(1 − α) (n ambiguities; module doc, single-frequency policy)."""
    return bool(res.sq_norm_best <= chi2.ppf(1.0 - alpha, res.fixed.size))


def _fixable(q, cfg: RtkConfig, p_given: float = 1.0) -> float:
    """Bootstrapping success rate (gnss.lambda_ils.bootstrap_success_rate) of float
    ambiguities with covariance q (cycles²) times p_given (a preceding step's rate);
    compared with cfg.min_success_rate by the caller (module doc)."""
    if cfg.min_success_rate <= 0.0:
        return 1.0
    return p_given * bootstrap_success_rate(0.5 * (q + q.T))


def _fix_satellites(fl: EpochFloat, sats, cfg: RtkConfig, col: dict, strict: bool):
    """LAMBDA on the DD ambiguities of the satellites ``sats``: WL → L1 cascade when
    dual-frequency, L1 directly otherwise (module doc). strict: the χ² test of
    _chi2_consistent and a bootstrapping success rate ≥ min_success_rate are required
    besides the ratio test. Returns (integers
    {(prn, f): n} or None, ratio)."""
    x, Q = fl.x, fl.Q
    i1 = np.array([col[(p, 1)] for p in sats])
    ints = None
    if not cfg.dual_frequency:
        q1 = Q[np.ix_(i1, i1)]
        l1 = resolve_integers(x[i1], q1)
        if ratio_test(l1, cfg.ratio_threshold) and \
                (not strict or (_chi2_consistent(l1, cfg.fix_chi2_alpha)
                                and _fixable(q1, cfg) >= cfg.min_success_rate)):
            ints = {(p, 1): int(n1) for p, n1 in zip(sats, l1.fixed)}
        return ints, l1.ratio
    i2 = np.array([col[(p, 2)] for p in sats])
    C_wl = np.zeros((len(sats), x.size))
    C_wl[np.arange(len(sats)), i1] = 1.0
    C_wl[np.arange(len(sats)), i2] = -1.0
    wl = resolve_integers(C_wl @ x, C_wl @ Q @ C_wl.T)
    if not ratio_test(wl, cfg.ratio_threshold):
        return None, wl.ratio
    xw, Qw = _condition(x, Q, C_wl, wl.fixed.astype(float))
    l1 = resolve_integers(xw[i1], Qw[np.ix_(i1, i1)])
    ratio = min(l1.ratio, wl.ratio)
    if ratio_test(l1, cfg.ratio_threshold) and (not strict or (
            _chi2_consistent(wl, cfg.fix_chi2_alpha)
            and _chi2_consistent(l1, cfg.fix_chi2_alpha)
            and _fixable(Qw[np.ix_(i1, i1)], cfg, _fixable(C_wl @ Q @ C_wl.T, cfg))
            >= cfg.min_success_rate)):
        ints = {}
        for p, n1, w in zip(sats, l1.fixed, wl.fixed):
            ints[(p, 1)] = int(n1)
            ints[(p, 2)] = int(n1 - w)
    return ints, ratio


def _held_integers(fl: EpochFloat, sats, held: dict, cfg: RtkConfig, col: dict):
    """Continuous AR: the held integers of the satellites ``sats`` when they agree with the
    float ambiguities (and, dual-frequency, wide lanes) to within hold_tolerance_cycles
    and cover ≥ min_fix_satellites satellites; else None."""
    x = fl.x
    freqs = (1, 2) if cfg.dual_frequency else (1,)
    usable = [p for p in sats if all((p, f) in held for f in freqs)]
    if len(usable) + 1 < cfg.min_fix_satellites:
        return None
    cand = {(p, f): held[(p, f)] for p in usable for f in freqs}
    dev = max(abs(x[col[k]] - n) for k, n in cand.items())
    if cfg.dual_frequency:
        dev = max(dev, max(abs(x[col[(p, 1)]] - x[col[(p, 2)]] - (cand[(p, 1)] - cand[(p, 2)]))
                           for p in usable))
    return cand if dev < cfg.hold_tolerance_cycles else None


def resolve_epoch(fl: EpochFloat, held: dict, cfg: RtkConfig, eligible=None):
    """Ambiguity resolution of one epoch (module doc): the full set (WL then L1 when
    dual-frequency, L1 alone otherwise), else the held integers (continuous AR), else
    partial AR — the lowest-elevation satellite dropped one at a time while
    ≥ min_fix_satellites remain, each subset under the ratio and χ² tests. Returns
    (x_fixed or None, Q_x fixed, ratio, integers {(prn, f): n} or None,
    n_fixed_ambiguities, partial: bool)."""
    col = {k: 3 + i for i, k in enumerate(fl.keys)}
    freqs = (1, 2) if cfg.dual_frequency else (1,)
    sats = [int(p) for p in fl.prn if all((int(p), f) in col for f in freqs)
            and (eligible is None or int(p) in eligible)]
    if len(sats) + 1 < cfg.min_fix_satellites:
        return None, None, 0.0, None, 0, False
    ints, ratio = _fix_satellites(fl, sats, cfg, col, strict=not cfg.dual_frequency)
    if ints is None and cfg.continuous and held:
        ints = _held_integers(fl, sats, held, cfg, col)
    partial = False
    if ints is None and cfg.partial_fixing and fl.elevation is not None:
        elev = {int(p): e for p, e in zip(fl.prn, fl.elevation)}
        subset = sorted(sats, key=lambda p: -elev[p])          # highest first
        while len(subset) > cfg.min_fix_satellites - 1 and len(subset) > 1:
            subset = subset[:-1]
            ints_p, ratio_p = _fix_satellites(fl, subset, cfg, col, strict=True)
            if ints_p is not None:
                ints, ratio, partial = ints_p, ratio_p, True
                break
    if ints is None:
        return None, None, ratio, None, 0, False
    keys = list(ints)
    C = np.zeros((len(keys), fl.x.size))
    C[np.arange(len(keys)), [col[k] for k in keys]] = 1.0
    xf, Qf = _condition(fl.x, fl.Q, C, np.array([ints[k] for k in keys], float))
    return xf, Qf, ratio, ints, len(keys), partial


# ------------------------------------------------------------------------- session


def process_rtk(base: ObsData, rover: ObsData, nav, base_ecef,
                config: RtkConfig | None = None, progress=None,
                rover_spp=None) -> RtkSolution:
    """Kinematic RTK over a base/rover session (module doc). rover_spp: the rover's
    gnss.spp.SppSession when already solved (else solved here), the linearisation point."""
    cfg = config or RtkConfig()
    base, rover = observed_frequencies(base, cfg), observed_frequencies(rover, cfg)
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


def observed_frequencies(obs: ObsData, cfg: RtkConfig) -> ObsData:
    """obs as a receiver tracking only cfg.frequencies would record it: single-frequency
    (["L1"]) drops C2/L2/D2/S2 and LLI2, so the slip detectors see L1 only, as with an
    L1-only receiver (geometry-free and Melbourne-Wübbena need L2; LLI, gaps and the
    Doppler-predicted phase remain)."""
    if cfg.dual_frequency:
        return obs
    nan = np.full(obs.L2.shape, np.nan)
    return dataclasses.replace(obs, C2=nan, L2=nan, D2=nan, S2=nan,
                               LLI2=np.zeros_like(obs.LLI2))


def dd_hydrostatic_delay(ep, base_llh, rover_ecef) -> np.ndarray:
    """∇ΔT (m,) m: DD (k − reference) of the rover − base hydrostatic Saastamoinen slant
    delay (humidity 0) at the epoch's base/rover elevations; base_llh (lat, lon, h) rad/m,
    rover_ecef (3,) m (module doc)."""
    lat, _, h = ecef_to_geodetic(*rover_ecef)
    return _dd_hydrostatic_kernel(lat, h, float(base_llh[0]), float(base_llh[2]),
                                  np.ascontiguousarray(ep.elevation_rover, float),
                                  float(ep.ref_elevation_rover),
                                  np.ascontiguousarray(ep.elevation_base, float),
                                  float(ep.ref_elevation_base))


@njit(cache=True)
def _dd_hydrostatic_kernel(lat, h, base_lat, base_h, el_r, ref_el_r, el_b, ref_el_b):
    """dd_hydrostatic_delay compiled: the SD T_rover − T_base of every satellite and of the
    reference (saastamoinen_delay_scalar, humidity 0, bit-identical to the vectorised
    model), then k − reference."""
    ref = saastamoinen_delay_scalar(lat, h, ref_el_r, 0.0) - \
        saastamoinen_delay_scalar(base_lat, base_h, ref_el_b, 0.0)
    out = np.empty(el_r.size)
    for k in range(el_r.size):
        out[k] = (saastamoinen_delay_scalar(lat, h, el_r[k], 0.0)
                  - saastamoinen_delay_scalar(base_lat, base_h, el_b[k], 0.0)) - ref
    return out


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
                      ref_prn=np.full(n, -1, np.int64), integers=[None] * n,
                      partial=np.zeros(n, bool), cov_enu=np.full((n, 3, 3), np.nan))
    state = AmbiguityState()
    held: dict = {}
    lock: dict = {}                  # satellite → consecutive DD epochs without reset
    prev: set = set()
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
            prev = set()
        held = remap_integers(held, state.ref, ep.ref_prn) if state.ref >= 0 else {}
        state.remap_reference(ep.ref_prn)
        slipped = {int(p) for p in ep.prn[slip_rows]}
        present = {(int(p), f) for p in ep.prn for f in (1, 2)} - \
                  {(p, f) for p in slipped for f in (1, 2)}
        state.drop(present)
        held = {k: v for k, v in held.items() if k in present}
        tracked = {int(p) for p in ep.prn} | {int(ep.ref_prn)}
        lock = {p: (lock.get(p, 0) + 1 if p in prev and p not in slipped else 1)
                for p in tracked}
        prev = tracked
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
        need = cfg.lock_epochs
        eligible = None if need <= 1 else (
            {p for p, c in lock.items() if c >= need} if lock[int(ep.ref_prn)] >= need
            else set())
        xf, Qf, ratio, ints, nfix, partial = resolve_epoch(fl, held, cfg, eligible)
        if ints is not None:
            held = ints
            dx, Qx, q = xf[:3], Qf[:3, :3], Q_FIXED
            if cfg.holds_fixes:
                state.hold(ints, cfg.hold_variance_cycles2)
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
        out.cov_enu[i] = Ce @ Qx @ Ce.T
        out.sigma_enu[i] = np.sqrt(np.diag(out.cov_enu[i]))
        out.partial[i] = partial and ints is not None
        out.ambiguities_fixed[i] = nfix
        out.ref_prn[i] = ep.ref_prn
        out.integers[i] = dict(ints) if ints is not None else None
    if progress is not None:
        progress(1.0)
    return out
