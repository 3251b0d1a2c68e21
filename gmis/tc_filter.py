"""Tightly coupled GMIKF filter: DD code, L1/L2 phase and Doppler updates with in-filter
ambiguity resolution (001 §4.1.3.2 ii, §4.3.4, ch. 5-6). The epochs it consumes come from
gmis.tc_epochs; the recipe glue (reading the files once, the heading stream) is gmis.tc.

Design (docs/DESIGN.md "Tightly coupled"):
- The IMU, heading and kinematic model run in the numba loop (gmis.gmikf) through
  GmikfRunner; at every GNSS epoch the loop stops after that epoch's IMU/heading update and
  the DD update below is applied to the same state (a sequential update at one epoch,
  equivalent to one stacked update for independent measurement groups).
- Ambiguities are rover−base SINGLE-difference states N_f,k (cycles) per satellite and
  frequency, appended after the IMU states. The DD model uses N_f,k − N_f,ref, so a change
  of reference satellite needs no state transformation; the common part of the SD states
  is unobservable and harmless. A new or slipped satellite's state is (re)initialised from
  the DD phase − code relative to the current reference with a code-level variance.
- Fixing: the DD float ambiguities a = D N (D: SD→DD) with Q_a = D P_NN Dᵀ go to LAMBDA
  (gnss.lambda_ils) with the ratio test; a candidate fix is applied as a constraint to a
  copy of the state and accepted only if the DD phase residuals then pass a χ² test
  (wrong-fix protection). An accepted fix constrains the filter (fix-and-hold: the
  ambiguity covariance collapses, later epochs keep it until a slip).
- Partial AR (TcConfig.partial_ar, default on; `gmis rtk --tight` follows [rtk]): when the
  full set fails the ratio test, the candidates are the DD ambiguities whose float σ is
  ≤ partial_max_sigma_cycles (0.25: converged or held; code-level floats of new satellites
  are not), and gnss.lambda_ils.partial_fix drops the one with the largest variance at a
  time while ≥ min_fix_ambiguities remain; the first subset passing the ratio test goes
  through the same χ² protection, the others stay float (conditioned on it via the state).
- Leave-one-satellite-out stage (TcConfig.leave_one_out, default on; with partial_ar):
  when the variance stage finds no subset (e.g. a half-cycle-biased satellite among
  floats of 2-9 cycles that fix only through the decorrelation), each satellite with both
  frequencies is left out in turn (all its DD ambiguities) and the rest goes to LAMBDA +
  ratio test (leave_one_satellite_out); used only when exactly ONE omission passes (the
  failure is that satellite's alone), then through the χ² and per-satellite tests. The
  left-out satellite is excluded from fixing and holding, per frequency, until its own
  DD float is within RELEASE_FRACTION_CYCLES (0.1) of an integer with σ ≤
  RELEASE_SIGMA_CYCLES (0.05) — with the others held, its phases then agree with an
  integer — or a slip flag / in-filter slip reset clears it. Single-frequency satellites
  are not in its pool (their code-level floats do not fix reliably in one epoch).
- Per-satellite phase test (TcConfig.satellite_test, default on; satellite_phase_test):
  the fixed DD phase rows of every new fix and of every held epoch are re-fitted with a
  position correction and each satellite's T_k = Ω − Ω₋ₖ (χ²(n_k) under correct
  integers) is tested at satellite_test_alpha / n_tested (Bonferroni; 1e-4: at the group
  test's 1e-3 it named 2 correct held satellites in the 1201 epochs of the simulated IMU
  drive, tests/test_tc.py's scene, costing 2 fixed epochs). A new fix failing it is
  rejected; a held satellite failing it is reset and excluded (same release rule), so a
  wrong integer the group χ² misses cannot stay held. Redundancy-aware: a NEW fix is
  refused (TcRecords.unidentifiable) unless the test can name the culprit
  (satellites_identifiable): the fixed rows keep ≥ 1 dof beyond the 3 position unknowns
  and every satellite with a newly fixed ambiguity can be left out with ≥ 1 dof left —
  or only one satellite is new (integers already held were validated before and are
  trusted; the misclosure is then the new one's). With L1 only and no integer held, a
  5-satellite set (4 DD rows, redundancy 1: a bias detectable, not identifiable) is not
  fixed; L1+L2 sets of ≥ 4 satellites pass. The held path keeps its integers when the
  geometry later drops below this (they were validated when identifiable).
- Success-rate gate (TcConfig.min_success_rate, default 0 = off; single-frequency filters
  only): a candidate fix whose integer-bootstrapping success rate from its float covariance
  (gnss.lambda_ils.bootstrap_success_rate) is below the threshold is refused before the χ²
  and per-satellite tests (TcRecords.low_success_rate). Off by default: it needs an honest
  float covariance; at the default σ it refuses every L1 fix (docs/DESIGN.md GNSS side).
- In-filter cycle slips (TcConfig.phase_slip_reset, default on): a slip the RINEX-level
  detectors missed (e.g. (1, 1): Melbourne-Wübbena blind, geometry-free marginal) is found
  in the time-differenced SD phase of consecutive epochs (TcFilter._tdcp_slip_test: a
  position-change + clock-change fit, the largest residual above λ/2 is a slip). Without
  it such a slip on a held ambiguity is absorbed by the position (GNSS-only: no DD phase
  was even rejected by the innovation test; 0.44 m position error in the test scene).
  Repair (TcConfig.slip_repair, default off; needs the test): the jump is estimated from the fit of
  the other satellites, n̂ = (y_k − a_k x̂₋ₖ)/λ with σ_n = s₀ √(1 + a_k N₋ₖ⁻¹ a_kᵀ)/λ (s₀
  the others' a-posteriori σ, ≥ 2 dof); when σ_n ≤ 0.1 cycle, n̂ is within 3σ_n of a
  non-zero integer n and — with both frequencies — the SD geometry-free jump agrees with
  λ1 n1 − λ2 n2 to 27 mm (half the 0.054 m of a (1, 1) slip), the SD ambiguity state gets
  + n and stays held (the reference too: its SD state carries every DD). Otherwise only the affected ambiguity is reset and fixed
  again; a slip of the reference moves the reference to a satellite whose ambiguity is
  held, so the other held DD ambiguities carry over. Counted in TcRecords.slip_resets /
  slip_repairs / reference_slips.
- WL → L1 cascade (TcConfig.wide_lane_cascade, default off): when the joint L1+L2 set
  fails the ratio test, the wide lanes N1 − N2 of the satellites with both frequencies are
  fixed first (LAMBDA + ratio), the float vector conditioned on them, then their L1 (001
  §6.1, the GNSS-only processor's order; wide_lane_cascade()); the result goes through the
  same χ² protection, before partial AR is tried. TcRecords.cascade marks such fixes.
- Observation groups (VCE components): code, phase L1, phase L2 and the velocity
  observable, each with the elevation-dependent DD covariance σ²·M (001 eq.
  5.1.8-5.1.11). The velocity observable (4th group, column 3) is selectable
  (TcConfig.velocity_observable): DD Doppler (m/s) or DD time-differenced L1 phase
  ("tdcp", m, covariance 2σ_tdcp²·M; gmis.tc_models). For TDCP the filter keeps the last
  epoch it processed; a time step ≤ 0 or longer than tdcp_max_gap_intervals nominal GNSS
  intervals disables TDCP at that epoch.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from gmis.critical_values import chi2_quantile
from gmis.dd_update_kernels import (
    group_outlier_test,
    group_vce_terms,
    satellite_statistics,
    tdcp_fit_rows,
    tdcp_snooping_step,
)
from gmis.epochs import merge_streams
from gmis.errors import GmisInputError
from gmis.filter_defaults import OUTLIER_ALPHA
from gmis.kalman_update_reference import OutlierCriticalValues, kalman_update
from gmis.run_filter import GmikfRunner, Measurements
from gmis.state import I_HEADING, I_POS
from gmis.tc_epochs import TcEpoch
from gmis.tc_models import (
    OBS_CODE,
    OBS_DOPPLER,
    OBS_L1,
    OBS_L2,
    OBS_NAMES,
    OBS_TDCP,
    VELOCITY_OBSERVABLES,
    antenna_position_ecef,
    dd_model_and_jacobian,
    group_names,
    tdcp_model_and_jacobian,
)
from gnss.constants import WAVELENGTH_L1, WAVELENGTH_L2
from gnss.double_difference import (
    between_satellites,
    dd_cofactor,
    elevation_cofactor,
    geodetic_up,
    select_reference_satellite,
)
from gnss.lambda_ils import (
    LambdaInputError,
    bootstrap_success_rate,
    partial_fix,
    ratio_test,
    resolve_integers,
)
from gnss.troposphere import slant_hydrostatic_delay

WAVELENGTHS = np.array([WAVELENGTH_L1, WAVELENGTH_L2])


@dataclass
class TcConfig:
    """Units: m, m/s, cycles, degrees."""
    sigma_code_m: float = 0.5           # σ90 of undifferenced code (001 Table 6-2)
    sigma_phase_l1_m: float = 0.02
    sigma_phase_l2_m: float = 0.02
    sigma_doppler_m_s: float = 0.1
    sigma_tdcp_m: float | None = None   # σ of the undifferenced L1 phase in a TDCP; None: L1
    velocity_observable: str = "doppler"   # 4th group: "doppler" | "tdcp"
    tdcp_max_gap_intervals: float = 2.5    # TDCP only across gaps ≤ this × nominal interval
    use: tuple = (True, True, True, True)   # code, L1, L2, velocity observable
    elevation_mask_deg: float = 15.0
    ratio_threshold: float = 3.0
    fix_chi2_alpha: float = 0.001       # wrong-fix protection test level
    outlier_alpha: float = OUTLIER_ALPHA
    min_fix_ambiguities: int = 4
    init_ambiguity_sigma_cycles: float = 30.0
    partial_ar: bool = True             # subset fixing when the full set fails (module doc)
    partial_max_sigma_cycles: float = 0.25  # partial AR candidates: float σ at most this
    leave_one_out: bool = True          # with partial_ar: leave-one-satellite-out stage
    satellite_test: bool = True         # per-satellite phase test of fixes and holds
    satellite_test_alpha: float = 1e-4  # its family-wise level (Bonferroni over satellites)
    phase_slip_reset: bool = True       # in-filter TDCP slip test (module doc)
    slip_repair: bool = False           # with phase_slip_reset: repair unambiguous jumps
    wide_lane_cascade: bool = False     # WL → L1 fixing when the joint L1+L2 set fails
    min_success_rate: float = 0.0       # L1 only: bootstrapping P_s of a new fix ≥ this (0: off)

    def __post_init__(self):
        if not 0.0 <= self.min_success_rate < 1.0:
            raise GmisInputError(f"TcConfig.min_success_rate: {self.min_success_rate!r} out "
                                 "of range [0, 1)")
        if self.velocity_observable not in VELOCITY_OBSERVABLES:
            raise GmisInputError(f"TcConfig.velocity_observable: invalid value "
                                 f"{self.velocity_observable!r}; allowed: "
                                 + ", ".join(repr(v) for v in VELOCITY_OBSERVABLES))

    @property
    def tdcp(self) -> bool:
        return self.velocity_observable == "tdcp"

    @property
    def group_names(self) -> tuple:
        return group_names(self.velocity_observable)

    def sigma(self, kind: int) -> float:
        velocity = (self.sigma_tdcp_m if self.sigma_tdcp_m is not None
                    else self.sigma_phase_l1_m) if self.tdcp else self.sigma_doppler_m_s
        return (self.sigma_code_m, self.sigma_phase_l1_m, self.sigma_phase_l2_m,
                velocity)[kind]


@dataclass
class TcRecords:
    t: np.ndarray
    epoch_index: np.ndarray      # (G,) row in the GMIKF records
    n_sat: np.ndarray
    ref_prn: np.ndarray
    fixed: np.ndarray            # (G,) bool: a validated fix constrains this epoch
    ratio: np.ndarray
    n_fixed: np.ndarray
    fix_rejected: np.ndarray     # ratio test passed (or held), χ² or per-satellite test rejected
    partial: np.ndarray          # (G,) bool: the fix was a subset (partial AR)
    slip_resets: np.ndarray      # (G,) int: ambiguities reset by the in-filter slip test
    reference_slips: np.ndarray  # (G,) int: reference moved away from a slipped satellite
    slip_repairs: np.ndarray     # (G,) int: ambiguities repaired by the in-filter slip test
    cascade: np.ndarray          # (G,) bool: the fix came from the WL → L1 cascade
    unidentifiable: np.ndarray   # (G,) bool: a candidate fix refused, its satellites untestable
    low_success_rate: np.ndarray  # (G,) bool: a candidate fix refused, P_s < min_success_rate
    success_rate: np.ndarray     # (G,) bootstrapping P_s of the candidate set (NaN: none)
    rejected_obs: np.ndarray     # (G, 4) outliers per group
    vpv: np.ndarray              # (G, 4) vᵀR⁻¹v per group (VCE)
    redundancy: np.ndarray       # (G, 4) tr(R D⁻¹) per group
    n_obs: np.ndarray            # (G, 4)
    innov_std: list = field(default_factory=list)   # per epoch: (kinds, d/√D)
    integers: list = field(default_factory=list)    # per epoch: {(prn, f): DD integer}
    residuals: list = field(default_factory=list)   # per epoch: (g, kinds, prn, v/σ_v)


HELD_VARIANCE_CYCLES2 = 1e-6     # a DD ambiguity this certain is held, not searched again
HELD_TOLERANCE_CYCLES = 1e-3
REFERENCE_MARGIN_DEG = 5.0       # the reference satellite is kept while above mask + this
SLIP_TEST_MIN_SATELLITES = 6     # TDCP slip test: 4 unknowns, redundancy ≥ 2 to name one
SLIP_TEST_MIN_REDUNDANCY = 0.05  # a row this little redundant cannot be tested
SLIP_REPAIR_MIN_DOF = 2          # s₀ of the others from at least this many dof
SLIP_REPAIR_GF_TOLERANCE_M = 0.027   # half of |λ1 − λ2|: a (1, 1) slip moves GF by 0.054 m
SLIP_REPAIR_MAX_SIGMA_CYCLES = 0.1   # rounding wrong then needs a > 5σ error
SLIP_REPAIR_FRACTION_SIGMAS = 3.0    # n̂ within 3σ_n of its integer
RELEASE_FRACTION_CYCLES = 0.1    # an excluded satellite returns when its DD floats are
RELEASE_SIGMA_CYCLES = 0.05      # this close to integers with at most this σ
SATELLITE_TEST_MIN_REDUNDANCY = 1   # the position fit without satellite k keeps ≥ this dof

class TcFilter:
    """DD updates and ambiguity resolution on a GmikfRunner's augmented state."""

    def __init__(self, runner: GmikfRunner, prn_all, n_imu: int, lever_arm, frame,
                 config: TcConfig, nominal_interval_s: float | None = None):
        self.r = runner
        self.prn_all = np.asarray(prn_all)
        self._prn_order = np.argsort(self.prn_all, kind="stable")
        self._prn_sorted = self.prn_all[self._prn_order]
        self.n_s = self.prn_all.size
        self.n_imu = n_imu
        self.amb_index = np.vstack([n_imu + np.arange(self.n_s),
                                    n_imu + self.n_s + np.arange(self.n_s)])
        self.initialized = np.zeros((2, self.n_s), bool)
        self.excluded = np.zeros((2, self.n_s), bool)   # left out of fixing (module doc)
        self.lever = np.asarray(lever_arm, float)
        self.frame = frame
        self.cfg = config
        self.ref = -1
        self.nominal_interval_s = nominal_interval_s
        self.prev: TcEpoch | None = None      # the last epoch processed (TDCP)
        # critical values, looked up per epoch
        self._outlier_crit = OutlierCriticalValues.at(config.outlier_alpha)
        self._fix_crit = OutlierCriticalValues.at(config.fix_chi2_alpha)
        self._satellite_crit = {}             # (α, satellites tested, dof) → χ² critical value
        self._tdcp_prev = None                # (Δt, prev sat_pos, prev base_range) at t_k
        self._phase_rows = None               # (epoch, reference, DD phase rows) of _update
        self._phase_fit = None                # (epoch, reference, x, rows, residuals, H) of _phase_chi2

    # --------------------------------------------------------------- bookkeeping
    def _slots(self, prn) -> np.ndarray:
        """Ambiguity slot (index into prn_all) of each PRN in prn."""
        return self._prn_order[np.searchsorted(self._prn_sorted, prn)]

    def _index_in_prev(self, ep: TcEpoch) -> np.ndarray:
        """Index of each of ep's satellites in the previous epoch, −1 where absent."""
        where = np.full(self.n_s, -1, dtype=np.int64)
        where[self._slots(self.prev.prn)] = np.arange(self.prev.prn.size)
        return where[self._slots(ep.prn)]

    def _geometry(self, ep: TcEpoch):
        """Antenna ECEF position at the current state, line-of-sight vectors (n_s, 3),
        ranges (n_s,) and rover elevations (n_s,) rad of ep's satellites."""
        r_ant = antenna_position_ecef(self.r.x, self.lever, self.frame)
        los = ep.sat_pos - r_ant
        rho = np.linalg.norm(los, axis=1)
        elev = np.arcsin((los / rho[:, None]) @ geodetic_up(r_ant))
        return r_ant, los, rho, elev

    def _reset(self, f, s):
        i = self.amb_index[f, s]
        p = self.r.p
        p[i, :] = 0.0
        p[:, i] = 0.0
        self.initialized[f, s] = False

    def _init_ambiguity(self, f, s, ref_s, dd_phase_m, dd_code_m):
        """Initialise N_f,s relative to the reference's state from DD phase − code."""
        i = self.amb_index[f, s]
        base = self.r.x[self.amb_index[f, ref_s]] if self.initialized[f, ref_s] else 0.0
        if s == ref_s:
            self.r.x[i] = 0.0
        else:
            self.r.x[i] = base + (dd_phase_m - dd_code_m) / WAVELENGTHS[f]
        self.r.p[i, :] = 0.0
        self.r.p[:, i] = 0.0
        self.r.p[i, i] = self.cfg.init_ambiguity_sigma_cycles ** 2
        self.initialized[f, s] = True

    # --------------------------------------------------------------- the update
    def update(self, ep: TcEpoch, rec: TcRecords, g: int):
        """DD update of one GNSS epoch; the epoch is kept as the TDCP predecessor."""
        try:
            geometry = self._geometry(ep)   # the slip test changes ambiguity states only
            if self.cfg.phase_slip_reset:
                self._tdcp_slip_test(ep, rec, g, geometry)
            self._update(ep, rec, g, geometry)
        finally:
            self.prev = ep

    def _tdcp_pairs(self, ep: TcEpoch):
        """Index of each current satellite in the previous epoch (−1: no TDCP possible:
        absent, L1 missing at either epoch, or a slip flagged at t_k), and Δt; None when
        there is no usable previous epoch."""
        prev = self.prev
        if prev is None:
            return None, 0.0
        dt = ep.t - prev.t
        limit = (np.inf if self.nominal_interval_s is None
                 else self.cfg.tdcp_max_gap_intervals * self.nominal_interval_s)
        if not 0.0 < dt <= limit:
            return None, dt
        idx = self._index_in_prev(ep)
        have = idx >= 0
        ok = have & np.isfinite(ep.sd["l1"]) & ~ep.slip
        ok[have] &= np.isfinite(prev.sd["l1"][idx[have]])
        return np.where(ok, idx, -1), dt

    def _update(self, ep: TcEpoch, rec: TcRecords, g: int, geometry):
        cfg = self.cfg
        x, p = self.r.x, self.r.p
        elev = geometry[3]
        mask = np.radians(cfg.elevation_mask_deg)
        ok = np.isfinite(ep.sd["code"]) & (elev >= mask) & (ep.elevation_base >= mask)
        slots = self._slots(ep.prn)
        for k in np.flatnonzero(ep.slip):
            for f in (0, 1):
                self._reset(f, slots[k])
            self.excluded[:, slots[k]] = False
        if ok.sum() < 2:
            rec.n_sat[g] = int(ok.sum())
            return
        phase_ok = ok & np.isfinite(ep.sd["l1"])
        self.ref = select_reference_satellite(
            ep.prn, elev, phase_ok if phase_ok.sum() >= 2 else ok, self.ref,
            cfg.elevation_mask_deg, REFERENCE_MARGIN_DEG)
        j = int(np.flatnonzero(ep.prn == self.ref)[0])
        ks = np.flatnonzero(ok & (np.arange(ok.size) != j))
        m_sd = elevation_cofactor(elev) + elevation_cofactor(ep.elevation_base)
        # (re)initialise ambiguities of satellites with phase
        for f, key in ((0, "l1"), (1, "l2")):
            if not cfg.use[OBS_L1 + f] or not np.isfinite(ep.sd[key][j]):
                continue            # a frequency not used gets no ambiguity states
            if not self.initialized[f, slots[j]]:
                # the reference starts a new common level: every other state of this
                # frequency is re-expressed by its own DD next
                for s in range(self.n_s):
                    self.initialized[f, s] = False
                self._init_ambiguity(f, slots[j], slots[j], 0.0, 0.0)
            new = np.isfinite(ep.sd[key][ks]) & ~self.initialized[f, slots[ks]]
            for k in ks[new]:
                self._init_ambiguity(f, slots[k], slots[j],
                                     between_satellites(ep.sd[key], k, j),
                                     between_satellites(ep.sd["code"], k, j))
        kinds, sat_k, z, r_mat = self._dd_rows(
            ep, [k for k in range(4) if cfg.use[k]], slots, j, ks, m_sd)
        # the phase rows of this epoch for the χ² of _resolve / _apply_fix: the same rows
        # and blocks _dd_rows(ep, [OBS_L1, OBS_L2]) would build (an unused frequency has no
        # initialised ambiguities, hence no rows, either way)
        phase = np.flatnonzero((kinds == OBS_L1) | (kinds == OBS_L2))
        self._phase_rows = (ep, j, (kinds[phase], sat_k[phase], z[phase],
                                    r_mat[np.ix_(phase, phase)]))
        m = z.size
        rec.n_sat[g] = ks.size + 1
        rec.ref_prn[g] = self.ref
        if m == 0:
            return
        h, hj = self._predict(x, ep, kinds, sat_k, j, slots)
        d = z - h
        # ---- outlier tests per group (001 §5.2.3.1)
        keep = np.ones(m, bool)
        if cfg.outlier_alpha > 0:
            keep, rejected = group_outlier_test(d, hj @ p @ hj.T + r_mat, kinds,
                                                len(OBS_NAMES), self._outlier_crit)
            for kind, n_bad in rejected.items():
                rec.rejected_obs[g, kind] = n_bad
        if not keep.all():
            hj, d, r_mat, kinds = hj[keep], d[keep], r_mat[np.ix_(keep, keep)], kinds[keep]
            sat_k = sat_k[keep]
            m = d.size
            if m == 0:
                return
        # ---- float update, VCE terms per group (gmis.kalman_update_reference)
        dmat, dinv_d = kalman_update(x, p, hj, d, r_mat)
        x[I_HEADING] %= 2 * np.pi
        vce = group_vce_terms(r_mat, dmat, dinv_d, kinds, 4)
        for kind in np.flatnonzero(vce.n_obs):
            rec.vpv[g, kind] = vce.vpv[kind]
            rec.redundancy[g, kind] = vce.redundancy[kind]
            rec.n_obs[g, kind] = vce.n_obs[kind]
        rec.innov_std.append((kinds.copy(), d / np.sqrt(np.diag(dmat))))
        rec.residuals.append((g, kinds.copy(), ep.prn[sat_k].copy(), vce.standardized))
        # ---- ambiguity resolution
        self._resolve(ep, rec, g, slots, j, ks, m_sd)

    def _tdcp_slip_test(self, ep: TcEpoch, rec: TcRecords, g: int, geometry):
        """In-filter cycle-slip test from the time-differenced SD phase (module doc), per
        frequency over the satellites with an initialised ambiguity in both epochs:

            y_k = Δ(SD Φ_k) − [|s_k(t) − r̂| − |s_k(t⁻) − r̂|] + Δρ_base,k = −e_kᵀ δ + c + v_k

        (m; r̂ the predicted antenna position, δ its change, c the receiver clock change)
        by least squares; while ≥ 6 satellites remain, data snooping picks the row with the
        largest w_k = v_k / √r_k (r_k its redundancy number) and takes it as a slip when the
        estimated jump v_k / r_k exceeds half a wavelength: that satellite leaves the fit and
        only its ambiguity of this frequency is reset. A slipped reference hands over to the highest satellite whose
        ambiguity is initialised, unflagged and ≥ mask + margin high, so every held DD
        ambiguity carries over (the states are single differences)."""
        prev, cfg = self.prev, self.cfg
        if prev is None:
            return
        dt = ep.t - prev.t
        limit = (np.inf if self.nominal_interval_s is None
                 else cfg.tdcp_max_gap_intervals * self.nominal_interval_s)
        if not 0.0 < dt <= limit:
            return
        r_ant, los, rho, elev = geometry
        idx = self._index_in_prev(ep)
        slots = self._slots(ep.prn)
        repairs, resets = {}, []          # (f, k) → jump cycles; (f, k, rows still in fit)
        for f, key in ((0, "l1"), (1, "l2")):
            rows, y, a = tdcp_fit_rows(idx, ep.slip, ep.sd[key], prev.sd[key],
                                       self.initialized[f, slots], rho, los, prev.sat_pos,
                                       r_ant, ep.base_range, prev.base_range)
            if rows.size < SLIP_TEST_MIN_SATELLITES:
                continue
            active = np.ones(rows.size, bool)
            while active.sum() >= SLIP_TEST_MIN_SATELLITES:
                aa, ya = a[active], y[active]
                best, v_best, r_best = tdcp_snooping_step(aa, ya)  # data snooping (w-test)
                if r_best < SLIP_TEST_MIN_REDUNDANCY or \
                        abs(v_best / r_best) <= 0.5 * WAVELENGTHS[f]:
                    break                   # the estimated jump v/r is below half a cycle
                jump = self._repairable_jump(aa, ya, best, f)
                worst = int(np.flatnonzero(active)[best])
                active[worst] = False
                k = int(rows[worst])
                if jump is not None:
                    repairs[(f, k)] = jump
                    continue
                resets.append((f, k, rows[active]))
        # a repair must also fit the geometry-free jump when both frequencies are tracked
        for (f, k), jump in list(repairs.items()):
            gf = self._geometry_free_jump(ep, idx, k)
            if gf is None:
                continue
            n = np.zeros(2)
            for ff in (0, 1):
                n[ff] = repairs.get((ff, k), 0)
            if any(kk == k for _, kk, _ in resets) or \
                    abs(gf - WAVELENGTHS @ np.array([n[0], -n[1]])) > SLIP_REPAIR_GF_TOLERANCE_M:
                del repairs[(f, k)]
                resets.append((f, k, np.array([q for q in range(ep.prn.size) if q != k])))
        for (f, k), jump in repairs.items():
            self.r.x[self.amb_index[f, slots[k]]] += jump
            rec.slip_repairs[g] += 1
        for f, k, remaining in resets:
            rec.slip_resets[g] += 1
            if int(ep.prn[k]) == self.ref:
                margin = np.radians(cfg.elevation_mask_deg + REFERENCE_MARGIN_DEG)
                slipped = {kk for ff, kk, _ in resets if ff == f}
                heirs = [q for q in remaining if elev[q] >= margin and q not in slipped
                         and self.initialized[f, slots[q]]]
                if heirs:
                    self.ref = int(ep.prn[max(heirs, key=lambda q: elev[q])])
                    rec.reference_slips[g] += 1
            self._reset(f, slots[k])
            self.excluded[f, slots[k]] = False

    def _geometry_free_jump(self, ep, idx, k):
        """Change of the SD geometry-free phase λ1φ1 − λ2φ2 (m) of satellite k between the
        previous and this epoch (geometry, clocks and, over 1 s, the ionosphere cancel),
        None without both phases at both epochs."""
        i = idx[k]
        if i < 0:
            return None
        now = ep.sd["l1"][k] - ep.sd["l2"][k]
        before = self.prev.sd["l1"][i] - self.prev.sd["l2"][i]
        return float(now - before) if np.isfinite(now) and np.isfinite(before) else None

    def _repairable_jump(self, a, y, k, f):
        """The integer jump (cycles) of the slip detected on row k of the TDCP fit (design
        a, observations y of the active rows, m) when it is unambiguous, else None (module
        doc): the fit of the other rows gives x̂₋ₖ and s₀² = |y₋ₖ − A₋ₖ x̂₋ₖ|² / (n − 1 − 4);
        n̂ = (y_k − a_k x̂₋ₖ) / λ (= v_k / (r_k λ)), σ_n = s₀ √(1 + a_k N₋ₖ⁻¹ a_kᵀ) / λ.
        Repaired when slip_repair is on, dof ≥ SLIP_REPAIR_MIN_DOF, σ_n ≤
        SLIP_REPAIR_MAX_SIGMA_CYCLES and |n̂ − round(n̂)| ≤ SLIP_REPAIR_FRACTION_SIGMAS σ_n."""
        if not self.cfg.slip_repair:
            return None
        others = np.ones(y.size, bool)
        others[k] = False
        dof = int(others.sum()) - a.shape[1]
        if dof < SLIP_REPAIR_MIN_DOF:
            return None
        ao, yo = a[others], y[others]
        n_inv = np.linalg.inv(ao.T @ ao)
        xo = n_inv @ (ao.T @ yo)
        s0 = np.sqrt(np.sum((yo - ao @ xo) ** 2) / dof)
        lam = WAVELENGTHS[f]
        n_hat = (y[k] - a[k] @ xo) / lam
        sigma_n = s0 * np.sqrt(1.0 + a[k] @ n_inv @ a[k]) / lam
        n = int(np.round(n_hat))
        if n == 0 or sigma_n > SLIP_REPAIR_MAX_SIGMA_CYCLES or \
                abs(n_hat - n) > SLIP_REPAIR_FRACTION_SIGMAS * sigma_n:
            return None
        return n

    def _predict(self, x, ep, kinds, sat_k, j, slots):
        """h and H of the DD rows: code/phase/Doppler from dd_model_and_jacobian, TDCP rows
        (velocity group when velocity_observable = "tdcp") from tdcp_model_and_jacobian."""
        m = kinds.size
        tdcp = (kinds == OBS_TDCP) if self.cfg.tdcp else np.zeros(m, bool)
        h = np.empty(m)
        hj = np.empty((m, x.size))
        rest = ~tdcp
        if rest.any():
            h[rest], hj[rest] = dd_model_and_jacobian(
                x, kinds[rest], sat_k[rest], np.full(rest.sum(), j), ep.sat_pos, ep.sat_vel,
                ep.base_range, ep.base_rate, self.amb_index[:, slots], WAVELENGTHS,
                self.lever, self.frame)
        if tdcp.any():
            dt, prev_pos, prev_range = self._tdcp_prev
            h[tdcp], hj[tdcp] = tdcp_model_and_jacobian(
                x, dt, sat_k[tdcp], np.full(tdcp.sum(), j), ep.sat_pos, ep.base_range,
                prev_pos, prev_range, self.lever, self.frame)
        return h + self._troposphere_dd(x, ep, kinds, sat_k, j), hj

    def _resolve(self, ep, rec, g, slots, j, ks, m_sd):
        cfg = self.cfg
        x, p = self.r.x, self.r.p
        self._release_excluded(slots, j, ks)
        pairs = [(f, k) for f in (0, 1) for k in ks
                 if self.initialized[f, slots[k]] and self.initialized[f, slots[j]]]
        left_out = any(self.excluded[f, slots[k]] for f, k in pairs)
        pairs = [(f, k) for f, k in pairs if not self.excluded[f, slots[k]]]
        if len(pairs) < cfg.min_fix_ambiguities:
            return
        n = x.size
        dmat = np.zeros((len(pairs), n))
        for row, (f, k) in enumerate(pairs):
            dmat[row, self.amb_index[f, slots[k]]] = 1.0
            dmat[row, self.amb_index[f, slots[j]]] = -1.0
        a = dmat @ x
        qa = dmat @ p @ dmat.T
        if np.all(np.diag(qa) < HELD_VARIANCE_CYCLES2) and \
                np.all(np.abs(a - np.round(a)) < HELD_TOLERANCE_CYCLES):
            # every DD ambiguity is already held at an integer: nothing to search (ratio
            # recorded as NaN = held); the held integers must still fit the phases
            rec.ratio[g] = np.nan
            chi2, dof = self._phase_chi2(ep, x, slots, j, ks, m_sd)
            if dof > 0 and chi2 > self._fix_crit.chi2(dof):
                rec.fix_rejected[g] = True
                return
            bad, _ = self._satellite_test(ep, x, slots, j, pairs, m_sd)
            if bad is not None:
                # a held satellite whose phases do not fit the others: its integers are
                # released (reset) and it stays out of fixing until its float agrees
                for f in (0, 1):
                    self._reset(f, slots[bad])
                self.excluded[:, slots[bad]] = True
                rec.fix_rejected[g] = True
                return
            rec.fixed[g] = True
            rec.n_fixed[g] = len(pairs)
            rec.partial[g] = left_out
            rec.integers.append({(int(ep.prn[k]), f + 1): int(v)
                                 for (f, k), v in zip(pairs, np.round(a))})
            return
        qs = 0.5 * (qa + qa.T)
        try:
            res = resolve_integers(a, qs)
        except LambdaInputError:
            return
        rec.ratio[g] = res.ratio
        subset, ints = np.arange(len(pairs)), res.fixed
        cascade, dropped = None, None
        if not ratio_test(res, cfg.ratio_threshold) and cfg.wide_lane_cascade:
            cascade = wide_lane_cascade(pairs, a, qs, cfg.ratio_threshold,
                                        cfg.min_fix_ambiguities)
            if cascade is not None:
                subset, ints, rec.ratio[g] = cascade
        if not ratio_test(res, cfg.ratio_threshold) and cascade is None:
            if not cfg.partial_ar:
                return
            # only converged float ambiguities are candidates (an early subset of
            # code-level floats can pass the ratio test with wrong integers)
            cand = np.flatnonzero(np.diag(qs) <= cfg.partial_max_sigma_cycles ** 2)
            part = None
            if cand.size >= max(cfg.min_fix_ambiguities, 2):
                try:
                    part = partial_fix(a[cand], qs[np.ix_(cand, cand)],
                                       cfg.ratio_threshold, cfg.min_fix_ambiguities)
                except LambdaInputError:
                    part = None
            if part is not None and part.passed:
                subset, ints = cand[part.subset], part.result.fixed
                rec.ratio[g] = part.result.ratio
            else:
                # pool: the ambiguities of satellites with both frequencies (module doc:
                # single-frequency sets are left to the variance stage)
                both = {k for f, k in pairs if f == 1} & {k for f, k in pairs if f == 0}
                pool = np.array([i for i, (_, k) in enumerate(pairs) if k in both],
                                dtype=np.int64)
                out = (leave_one_satellite_out([pairs[i] for i in pool], a[pool],
                                               qs[np.ix_(pool, pool)], cfg.ratio_threshold,
                                               cfg.min_fix_ambiguities)
                       if cfg.leave_one_out and pool.size else None)
                if out is None:
                    return
                dropped, subset, res_loo = out
                subset = pool[subset]
                ints, rec.ratio[g] = res_loo.fixed, res_loo.ratio
        if self._apply_fix(ep, rec, g, slots, j, ks, m_sd, dmat[subset], a[subset],
                           qa[np.ix_(subset, subset)], ints, [pairs[i] for i in subset]):
            if dropped is not None:
                self.excluded[:, slots[dropped]] = True
            rec.n_fixed[g] = subset.size
            rec.partial[g] = subset.size < len(pairs) or left_out
            rec.cascade[g] = cascade is not None
            rec.integers.append({(int(ep.prn[pairs[i][1]]), pairs[i][0] + 1): int(v)
                                 for i, v in zip(subset, ints)})

    def _apply_fix(self, ep, rec, g, slots, j, ks, m_sd, dmat, a, qa, integers,
                   fixed_pairs) -> bool:
        """Constrain a copy of the state to the DD integers (dmat x = integers; fixed_pairs
        [(f, k)] their rows) and accept it if the DD phase residuals then pass the χ² test
        and the per-satellite test (wrong-fix protection). Before either, the set must be
        fixable at all: its integer-bootstrapping success rate from the float covariance
        qa (gnss.lambda_ils.bootstrap_success_rate) at least TcConfig.min_success_rate,
        else the candidate is refused (TcRecords.low_success_rate) whatever its ratio."""
        x, p = self.r.x, self.r.p
        if self.cfg.min_success_rate > 0.0 and not self.cfg.use[OBS_L2]:
            try:
                p_s = bootstrap_success_rate(0.5 * (qa + qa.T))
            except LambdaInputError:
                p_s = 0.0
            rec.success_rate[g] = p_s
            if p_s < self.cfg.min_success_rate:
                rec.low_success_rate[g] = True
                return False
        fixed = integers.astype(float)
        r_c = np.eye(a.size) * 1e-8
        s_c = qa + r_c
        gain = np.linalg.solve(s_c, dmat @ p).T
        x_new = x + gain @ (fixed - a)
        p_new = p - gain @ (dmat @ p)
        chi2, dof = self._phase_chi2(ep, x_new, slots, j, ks, m_sd)
        if dof > 0 and chi2 > self._fix_crit.chi2(dof):
            rec.fix_rejected[g] = True
            return False
        # integers already held (validated at an earlier epoch) are trusted: only the
        # satellites with a newly fixed ambiguity need to be told apart
        held = (np.diag(qa) < HELD_VARIANCE_CYCLES2) & (np.abs(a - fixed) < HELD_TOLERANCE_CYCLES)
        untrusted = {k for (_, k), h in zip(fixed_pairs, held) if not h}
        bad, identifiable = self._satellite_test(ep, x_new, slots, j, fixed_pairs, m_sd,
                                                 untrusted)
        if bad is not None or not identifiable:
            rec.fix_rejected[g] = bad is not None   # a test's rejection, not a refusal
            rec.unidentifiable[g] = not identifiable
            return False
        x[:] = x_new
        p[:] = 0.5 * (p_new + p_new.T)
        rec.fixed[g] = True
        return True

    def _release_excluded(self, slots, j, ks):
        """An excluded ambiguity (satellite left out by the leave-one-out stage or named by
        the held-path satellite test; per frequency) returns to fixing when its DD float
        against reference j is within RELEASE_FRACTION_CYCLES of an integer with σ ≤
        RELEASE_SIGMA_CYCLES: its own phases, with the others held, now agree with an
        integer. A slip flag or an in-filter slip reset clears the exclusion as well."""
        x, p = self.r.x, self.r.p
        for k in ks:
            for f in (0, 1):
                s = slots[k]
                if not (self.excluded[f, s] and self.initialized[f, s]
                        and self.initialized[f, slots[j]]):
                    continue
                i, r = self.amb_index[f, s], self.amb_index[f, slots[j]]
                a = x[i] - x[r]
                var = p[i, i] + p[r, r] - 2.0 * p[i, r]
                if abs(a - np.round(a)) <= RELEASE_FRACTION_CYCLES and \
                        var <= RELEASE_SIGMA_CYCLES ** 2:
                    self.excluded[f, s] = False

    def _satellite_test(self, ep, x, slots, j, fixed_pairs, m_sd, untrusted=None):
        """Per-satellite test (satellite_phase_test) of the DD phase rows in fixed_pairs
        [(f, k)] at state x: (k, identifiable) — k the index of a satellite whose fixed
        phases do not fit the others, else None; identifiable from satellites_identifiable
        with the satellites in ``untrusted`` (indices k; None: all) as the ones a wrong
        integer may sit on (e.g. with L1 only, 5 satellites, none held: 4 DD rows for 3
        position unknowns, not identifiable). Off ((None, True)) when
        TcConfig.satellite_test is False."""
        if not self.cfg.satellite_test or not fixed_pairs:
            return None, True
        fixed = set(fixed_pairs)
        fit = self._phase_fit      # residuals of _phase_chi2 at this epoch and state, if any
        if fit is not None and fit[0] is ep and fit[1] == j and np.array_equal(fit[2], x):
            kinds, sat_k, r_mat, res, hj = fit[3:]
            if not fixed <= {(int(kd) - OBS_L1, int(k)) for kd, k in zip(kinds, sat_k)}:
                fit = None
        else:
            fit = None
        if fit is None:
            sats = np.array(sorted({k for _, k in fixed_pairs}))
            kinds, sat_k, z, r_mat = self._dd_rows(ep, [OBS_L1, OBS_L2], slots, j, sats,
                                                      m_sd)
            res, hj = self._phase_residuals(ep, x, slots, j, kinds, sat_k, z)
        use = np.array([(int(kd) - OBS_L1, int(k)) in fixed for kd, k in zip(kinds, sat_k)],
                       dtype=bool)
        identifiable = satellites_identifiable(sat_k[use], untrusted)
        if use.sum() < 3 + SATELLITE_TEST_MIN_REDUNDANCY + 1:
            return None, identifiable       # no satellite can be left out and tested
        return satellite_phase_test(res[use], hj[use, I_POS:I_POS + 3],
                                    r_mat[np.ix_(use, use)], sat_k[use],
                                    self.cfg.satellite_test_alpha,
                                    self._satellite_crit), identifiable

    def _dd_rows(self, ep, kinds_wanted, slots, j, ks, m_sd):
        """DD rows of the wanted observable kinds against reference j: kinds, satellite
        indices, observed DD z and the block-diagonal covariance σ90²·M per group
        (001 eq. 5.1.10), the rows of a group consecutive. Phase rows need both ambiguity
        states initialised."""
        keys = ("code", "l1", "l2", "doppler")
        kinds, sat_k, z, blocks = [], [], [], []
        for kind in kinds_wanted:
            if kind == OBS_TDCP and self.cfg.tdcp:
                rows, z_rows = self._tdcp_rows(ep, j, ks)
                if rows.size:
                    kinds.append(np.full(rows.size, kind, dtype=np.int64))
                    sat_k.append(rows)
                    z.append(z_rows)
                    blocks.append(2.0 * self.cfg.sigma(kind) ** 2
                                  * dd_cofactor(m_sd[rows], m_sd[j]))
                continue
            key = keys[kind]
            sel = np.isfinite(ep.sd[key][ks]) & np.isfinite(ep.sd[key][j])
            if kind in (OBS_L1, OBS_L2):
                sel &= self.initialized[kind - 1, slots[ks]] & self.initialized[kind - 1,
                                                                                slots[j]]
            rows = ks[sel]
            if rows.size == 0:
                continue
            kinds.append(np.full(rows.size, kind, dtype=np.int64))
            sat_k.append(rows)
            z.append(between_satellites(ep.sd[key], rows, j))
            blocks.append(self.cfg.sigma(kind) ** 2 * dd_cofactor(m_sd[rows], m_sd[j]))
        if not z:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 0))
        z = np.concatenate(z).astype(float, copy=False)
        m = z.size
        r_mat = np.zeros((m, m))
        pos = 0
        for cov in blocks:
            n_k = cov.shape[0]
            r_mat[pos:pos + n_k, pos:pos + n_k] = cov
            pos += n_k
        return np.concatenate(kinds), np.concatenate(sat_k).astype(np.int64, copy=False), \
            z, r_mat

    def _tdcp_rows(self, ep, j, ks):
        """Satellites k ≠ j with a DD TDCP against the current reference j and the observed
        z_kj = λ1[∇Δφ1(t_k) − ∇Δφ1(t_{k−1})] (m; both DDs with reference j, from the SD
        phases of both epochs). Sets self._tdcp_prev for the model."""
        none = np.zeros(0, np.int64), np.zeros(0)
        idx, dt = self._tdcp_pairs(ep)
        if idx is None or idx[j] < 0:
            return none
        rows = np.array([k for k in ks if idx[k] >= 0], dtype=np.int64)
        if rows.size == 0:
            return none
        prev = self.prev
        l1, l1p = ep.sd["l1"], prev.sd["l1"]
        z = between_satellites(l1, rows, j) - between_satellites(l1p, idx[rows], idx[j])
        safe = np.maximum(idx, 0)
        prev_pos = np.where((idx >= 0)[:, None], prev.sat_pos[safe], np.nan)
        prev_range = np.where(idx >= 0, prev.base_range[safe], np.nan)
        self._tdcp_prev = (dt, prev_pos, prev_range)
        return rows, z

    def _phase_chi2(self, ep, x, slots, j, ks, m_sd):
        """χ² of the DD phase residuals at state x against the measurement covariance only:
        do the fixed integers fit the phases? (wrong-fix protection)"""
        cached = self._phase_rows
        if cached is not None and cached[0] is ep and cached[1] == j:
            kinds, sat_k, z, r_mat = cached[2]
        else:
            kinds, sat_k, z, r_mat = self._dd_rows(ep, [OBS_L1, OBS_L2], slots, j, ks,
                                                      m_sd)
        if z.size == 0:
            return 0.0, 0
        res, hj = self._phase_residuals(ep, x, slots, j, kinds, sat_k, z)
        self._phase_fit = (ep, j, x.copy(), kinds, sat_k, r_mat, res, hj)
        return float(res @ np.linalg.solve(r_mat, res)), res.size

    def _phase_residuals(self, ep, x, slots, j, kinds, sat_k, z):
        """DD phase residuals z − h(x) − ∇ΔT (m) of the rows (kinds, sat_k) against reference
        j, and their Jacobian ∂h/∂x."""
        h, hj = dd_model_and_jacobian(x, kinds, sat_k, np.full(z.size, j), ep.sat_pos,
                                      ep.sat_vel, ep.base_range, ep.base_rate,
                                      self.amb_index[:, slots], WAVELENGTHS, self.lever,
                                      self.frame)
        return z - h - self._troposphere_dd(x, ep, kinds, sat_k, j), hj

    def _troposphere_dd(self, x, ep, kinds, sat_k, j):
        """DD of the modelled rover − base hydrostatic slant delay (m) for code/phase rows,
        the rover side evaluated at the state's antenna position (its ∂/∂x, ~3e-4 m per m
        of height, is left out of H). Zero when the epoch carries no base delays."""
        out = np.zeros(kinds.size)
        if ep.base_troposphere is None:
            return out
        r_ant = antenna_position_ecef(x, self.lever, self.frame)
        sd = slant_hydrostatic_delay(r_ant, ep.sat_pos) - ep.base_troposphere
        ranging = (kinds == OBS_CODE) | (kinds == OBS_L1) | (kinds == OBS_L2)
        out[ranging] = sd[sat_k[ranging]] - sd[j]
        return out


def wide_lane_cascade(pairs, a, q, ratio_threshold: float, min_fix_ambiguities: int):
    """WL → L1 fixing of the DD ambiguities a (cycles), covariance q, in ``pairs`` order
    [(f, k)] (f 0 = L1, 1 = L2; 001 §6.1, as gnss.rtk): the wide lanes N1 − N2 of the
    satellites with both frequencies by LAMBDA + ratio test, the float vector conditioned
    on them (â_c = â − Q_a,w Q_w⁻¹ (â_w − ň_w)), then their L1 by LAMBDA + ratio test;
    N2 = N1 − N_WL. Returns (indices into pairs, integers, min ratio) or None when a step
    fails or fewer than min_fix_ambiguities ambiguities would be fixed."""
    where = {fk: i for i, fk in enumerate(pairs)}
    both = [k for (f, k) in pairs if f == 0 and (1, k) in where]
    if 2 * len(both) < max(min_fix_ambiguities, 2):
        return None
    i1 = np.array([where[(0, k)] for k in both])
    i2 = np.array([where[(1, k)] for k in both])
    c = np.zeros((len(both), a.size))
    c[np.arange(len(both)), i1] = 1.0
    c[np.arange(len(both)), i2] = -1.0
    try:
        wl = resolve_integers(c @ a, c @ q @ c.T)
    except LambdaInputError:
        return None
    if not ratio_test(wl, ratio_threshold):
        return None
    gain = np.linalg.solve(c @ q @ c.T, c @ q).T
    a_c = a - gain @ (c @ a - wl.fixed)
    q_c = q - gain @ c @ q
    q1 = q_c[np.ix_(i1, i1)]
    try:
        l1 = resolve_integers(a_c[i1], 0.5 * (q1 + q1.T))
    except LambdaInputError:
        return None
    if not ratio_test(l1, ratio_threshold):
        return None
    n1 = np.asarray(l1.fixed)
    return (np.concatenate([i1, i2]), np.concatenate([n1, n1 - np.asarray(wl.fixed)]),
            min(wl.ratio, l1.ratio))


def leave_one_satellite_out(pairs, a, q, ratio_threshold: float, min_fix_ambiguities: int):
    """Leave-one-satellite-out stage of partial AR (module doc). For each satellite k of
    ``pairs`` [(f, k)], the DD floats a (cycles; covariance q, pairs order) without k's
    ambiguities go to LAMBDA + ratio test. When exactly one satellite's omission lets the
    rest pass (the full set's failure is explained by that satellite alone) returns (k,
    indices into pairs of the rest, their LambdaResult); otherwise (none, or several:
    the failure is not one satellite's) None. Subsets below max(min_fix_ambiguities, 2)
    are not tried."""
    passing = []
    for k in sorted({kk for _, kk in pairs}):
        sub = np.array([i for i, (_, kk) in enumerate(pairs) if kk != k], dtype=np.int64)
        if sub.size < max(min_fix_ambiguities, 2):
            continue
        try:
            res = resolve_integers(a[sub], q[np.ix_(sub, sub)])
        except LambdaInputError:
            continue
        if ratio_test(res, ratio_threshold):
            passing.append((k, sub, res))
    return passing[0] if len(passing) == 1 else None


def satellites_identifiable(sat_k, untrusted=None, n_unknowns: int = 3) -> bool:
    """Can satellite_phase_test tell which satellite of a fixed set carries a wrong integer?
    sat_k (m,) the satellite of each fixed DD phase row; untrusted: the satellites a wrong
    integer may sit on (those with a newly fixed ambiguity; None: all of sat_k; held
    integers validated earlier are trusted); n_unknowns the position unknowns of the
    re-fit. True when the set has redundancy m − n_unknowns ≥ SATELLITE_TEST_MIN_REDUNDANCY
    and either at most one satellite is untrusted (the misclosure is then its alone) or
    every untrusted satellite k can be left out with ≥ SATELLITE_TEST_MIN_REDUNDANCY dof
    remaining: m − n_k − n_unknowns ≥ SATELLITE_TEST_MIN_REDUNDANCY (n_k: rows of k).
    Otherwise some T_k is not defined and, at total redundancy 1, every single-row
    satellite's statistic is the same number (one misclosure: a bias is detectable, not
    identifiable — Baarda's w-tests fully correlated), so a fix with a wrong integer on
    one satellite can pass or fail without naming it. Used as a fix requirement (module
    doc): with nothing held, L1+L2 sets of ≥ 4 satellites and L1 sets of ≥ 6 pass it."""
    rows = [int(k) for k in sat_k]        # a few dozen rows: plain Python beats numpy's calls
    if len(rows) - n_unknowns < SATELLITE_TEST_MIN_REDUNDANCY:
        return False
    counts = Counter(rows)
    if untrusted is not None:
        counts = {k: c for k, c in counts.items() if k in untrusted}
        if len(counts) <= 1:
            return True
    return all(len(rows) - c - n_unknowns >= SATELLITE_TEST_MIN_REDUNDANCY
               for c in counts.values())


def satellite_phase_test(res, a_pos, r_mat, sat_k, alpha: float, crit_cache=None):
    """Per-satellite outlier test of fixed DD phases (001 §5.2 style, on the fixed
    solution). res (m,) residuals z − h(x) (m) of the DD phase rows with fixed
    ambiguities, a_pos (m, 3) their partials ∂h/∂p (position), r_mat (m, m) their
    covariance σ²M, sat_k (m,) each row's satellite. The residuals are fitted by a
    position correction δp (weights R⁻¹); Ω = vᵀR⁻¹v of that fit, Ω₋ₖ the same without
    satellite k's rows; T_k = Ω − Ω₋ₖ is χ²(n_k) when the integers are right (n_k rows
    of k). A satellite is tested when the fit without it keeps ≥
    SATELLITE_TEST_MIN_REDUNDANCY dof. Returns the satellite with the largest
    T_k / χ²(1 − α/n_tested, n_k) when that exceeds 1 (Bonferroni over the n_tested
    satellites), else None. crit_cache: optional dict for the critical values."""
    crit_cache = {} if crit_cache is None else crit_cache
    # one fit for all satellites: Ω − Ω₋ₖ = u_kᵀ (M_kk)⁻¹ u_k with u = R⁻¹v and
    # M = R⁻¹ Q_v R⁻¹ (Q_v = R − A N⁻¹ Aᵀ), the group statistic of k's rows (Baarda's test of
    # a bias in those rows equals the fall of vᵀR⁻¹v when they are left out); compiled in
    # gmis.dd_update_kernels.satellite_statistics
    res = np.ascontiguousarray(res, dtype=float)
    a_pos = np.ascontiguousarray(a_pos, dtype=float)
    r_mat = np.ascontiguousarray(r_mat, dtype=float)
    sat_k = np.ascontiguousarray(sat_k, dtype=np.int64)
    return worst_satellite(res, a_pos, r_mat, sat_k,
                           satellite_statistics(res, a_pos, r_mat, sat_k), alpha, crit_cache)


def worst_satellite(res, a_pos, r_mat, sat_k, statistics, alpha: float, crit_cache):
    """The decision of satellite_phase_test from its one-fit statistics (sats, n_rows,
    T_k, regular, vᵀR⁻¹v; gmis.dd_update_kernels.satellite_statistics): the satellites
    whose omission keeps ≥ SATELLITE_TEST_MIN_REDUNDANCY dof are tested, an irregular
    one by an explicit refit (T_k = Ω − Ω₋ₖ); returns the one with the largest
    T_k / χ²(1 − α/n_tested, n_k) when that exceeds 1, else None."""
    sats, n_rows, t_all, regular, vu = statistics
    every = np.arange(res.size)

    def omega(rows):
        w_r = np.linalg.inv(r_mat[np.ix_(rows, rows)])
        aa, rr = a_pos[rows], res[rows]
        v_r = rr - aa @ np.linalg.lstsq(aa.T @ w_r @ aa, aa.T @ w_r @ rr, rcond=None)[0]
        return float(v_r @ w_r @ v_r)

    tests = []
    for i, k in enumerate(sats):
        n_k = int(n_rows[i])
        if res.size - n_k - a_pos.shape[1] < SATELLITE_TEST_MIN_REDUNDANCY:
            continue
        # k's rows not redundant (the rest leaves the position undetermined): refit
        t_k = float(t_all[i]) if regular[i] else float(vu) - omega(every[sat_k != k])
        tests.append((int(k), n_k, t_k))
    worst, worst_excess = None, 1.0
    for k, n_k, t in tests:
        key = (alpha, len(tests), n_k)
        if key not in crit_cache:
            crit_cache[key] = float(chi2_quantile(1.0 - alpha / len(tests), n_k))
        if t / crit_cache[key] > worst_excess:
            worst, worst_excess = k, t / crit_cache[key]
    return worst


def new_tc_records(g_count: int, epoch_index) -> TcRecords:
    z = np.zeros
    return TcRecords(t=np.zeros(g_count), epoch_index=np.asarray(epoch_index),
                     n_sat=z(g_count, int), ref_prn=np.full(g_count, -1),
                     fixed=z(g_count, bool), ratio=z(g_count), n_fixed=z(g_count, int),
                     fix_rejected=z(g_count, bool), partial=z(g_count, bool),
                     slip_resets=z(g_count, int), reference_slips=z(g_count, int),
                     slip_repairs=z(g_count, int), cascade=z(g_count, bool),
                     unidentifiable=z(g_count, bool),
                     low_success_rate=z(g_count, bool),
                     success_rate=np.full(g_count, np.nan),
                     rejected_obs=z((g_count, 4), int),
                     vpv=z((g_count, 4)), redundancy=z((g_count, 4)),
                     n_obs=z((g_count, 4), int))


def run_tightly_coupled(imu_t, imu_z, heading_t, heading, heading_sd, tc_epochs, x0,
                        gmikf_config, tc_config: TcConfig, frame, stationary_fn=None,
                        progress=None):
    """Run the tightly coupled GMIKF. x0/P0 are the IMU part (n_imu); ambiguity states are
    appended for every PRN seen. stationary_fn(epochs) → (E,) bool or None marks epochs at
    rest. Returns (GMIKF FilterRecords, TcRecords, prn list)."""
    if not tc_epochs:
        raise GmisInputError("no GNSS epoch with base and rover observations in the IMU "
                             "time span")
    prn_all = np.unique(np.concatenate([ep.prn for ep in tc_epochs]))
    n_imu = gmikf_config.n_imu
    n = n_imu + 2 * prn_all.size
    g_t = np.array([ep.t for ep in tc_epochs])
    epochs = merge_streams(imu_t, pos_t=g_t, heading_t=heading_t)
    g_rows = np.flatnonzero(epochs.pos >= 0)
    g_of_row = epochs.pos[g_rows]
    no_pos = np.full(len(epochs), -1, dtype=np.int64)
    epochs_no_lc = type(epochs)(t=epochs.t, imu=epochs.imu, pos=no_pos, vel=no_pos,
                                heading=epochs.heading)
    meas = Measurements(imu_z=imu_z, heading=heading, heading_sd=heading_sd)
    x_full = np.zeros(n)
    x_full[:n_imu] = x0
    p0 = np.zeros((n, n))
    p0[:n_imu, :n_imu] = np.diag(np.asarray(gmikf_config.p0_sd) ** 2)
    stationary = stationary_fn(epochs_no_lc) if stationary_fn is not None else None
    runner = GmikfRunner(epochs_no_lc, meas, x_full, gmikf_config, frame, stationary, p0)
    nominal = float(np.median(np.diff(g_t))) if g_t.size > 1 else None
    tcf = TcFilter(runner, prn_all, n_imu, gmikf_config.lever_arm, frame, tc_config,
                   nominal_interval_s=nominal)
    tc_rec = new_tc_records(len(tc_epochs), g_rows)
    tc_rec.t = g_t
    for count, (row, g) in enumerate(zip(g_rows, g_of_row)):
        runner.advance(row + 1)
        tcf.update(tc_epochs[g], tc_rec, g)
        runner.record_state(row)
        if progress is not None and count % 50 == 0:
            progress(count / max(len(g_rows), 1))
    runner.advance(len(epochs))
    if progress is not None:
        progress(1.0)
    return runner.rec, tc_rec, prn_all


__all__ = [
    "OBS_CODE",
    "OBS_DOPPLER",
    "OBS_NAMES",
    "OBS_TDCP",
    "TcConfig",
    "TcEpoch",
    "TcFilter",
    "TcRecords",
    "new_tc_records",
    "run_tightly_coupled",
]
