"""Tightly coupled GMIKF: DD code, L1/L2 phase and Doppler updates with in-filter
ambiguity resolution (001 §4.1.3.2 ii, §4.3.4, ch. 5-6).

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
- Observation groups (VCE components): code, phase L1, phase L2 and the velocity
  observable, each with the elevation-dependent DD covariance σ²·M (001 eq.
  5.1.8-5.1.11). The velocity observable (4th group, column 3) is selectable
  (TcConfig.velocity_observable): DD Doppler (m/s) or DD time-differenced L1 phase
  ("tdcp", m, covariance 2σ_tdcp²·M; gmis.tc_models). For TDCP the filter keeps the last
  epoch it processed; a time step ≤ 0 or longer than tdcp_max_gap_intervals nominal GNSS
  intervals disables TDCP at that epoch.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from gmis.epochs import merge_streams
from gmis.errors import GmisInputError
from gmis.filter_defaults import OUTLIER_ALPHA
from gmis.run_filter import GmikfRunner, Measurements
from gmis.tc_models import (
    OBS_CODE,
    OBS_DOPPLER,
    OBS_L1,
    OBS_L2,
    OBS_NAMES,
    OBS_TDCP,
    VELOCITY_OBSERVABLES,
    antenna_ecef,
    dd_model_and_jacobian,
    group_names,
    tdcp_model_and_jacobian,
)
from gnss.constants import WAVELENGTH_L1, WAVELENGTH_L2
from gnss.double_difference import elevation_cofactor
from gnss.lambda_ils import LambdaInputError, ratio_test, resolve_integers
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

    def __post_init__(self):
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
class TcEpoch:
    """One GNSS epoch prepared for the filter (times on the dataset's time base)."""
    t: float
    prn: np.ndarray              # (n_s,)
    sat_pos: np.ndarray          # (n_s, 3) ECEF at the rover's transmit time, m
    sat_vel: np.ndarray          # (n_s, 3) m/s
    base_range: np.ndarray       # (n_s,) m
    base_rate: np.ndarray        # (n_s,) m/s
    elevation_base: np.ndarray   # (n_s,) rad
    sd: dict                     # "code","l1","l2" (m), "doppler" (m/s): rover − base
    slip: np.ndarray             # (n_s,) bool
    base_troposphere: np.ndarray | None = None  # (n_s,) base hydrostatic slant delay, m


@dataclass
class TcRecords:
    t: np.ndarray
    epoch_index: np.ndarray      # (G,) row in the GMIKF records
    n_sat: np.ndarray
    ref_prn: np.ndarray
    fixed: np.ndarray            # (G,) bool: a validated fix constrains this epoch
    ratio: np.ndarray
    n_fixed: np.ndarray
    fix_rejected: np.ndarray     # ratio test passed, χ² protection rejected
    rejected_obs: np.ndarray     # (G, 4) outliers per group
    vpv: np.ndarray              # (G, 4) vᵀR⁻¹v per group (VCE)
    redundancy: np.ndarray       # (G, 4) tr(R D⁻¹) per group
    n_obs: np.ndarray            # (G, 4)
    innov_std: list = field(default_factory=list)   # per epoch: (kinds, d/√D)
    integers: list = field(default_factory=list)    # per epoch: {(prn, f): DD integer}
    residuals: list = field(default_factory=list)   # per epoch: (g, kinds, prn, v/σ_v)


CRIT_TABLE_DOF = 128
HELD_VARIANCE_CYCLES2 = 1e-6     # a DD ambiguity this certain is held, not searched again
HELD_TOLERANCE_CYCLES = 1e-3


def _critical(table, alpha, dof):
    """χ²(dof) critical value at level alpha from a precomputed table."""
    return table[dof] if dof < table.size else float(stats.chi2.ppf(1 - alpha, dof))


def dd_cofactor_matrix(m_sd_k, m_sd_ref):
    """M of 001 eq. 5.1.10 for DD rows k (vs one reference): diag(m_k) + m_ref."""
    return np.diag(m_sd_k) + m_sd_ref


class TcFilter:
    """DD updates and ambiguity resolution on a GmikfRunner's augmented state."""

    def __init__(self, runner: GmikfRunner, prn_all, n_imu: int, lever_arm, frame,
                 config: TcConfig, nominal_interval_s: float | None = None):
        self.r = runner
        self.prn_all = np.asarray(prn_all)
        self.slot = {int(p): i for i, p in enumerate(self.prn_all)}
        self.n_s = self.prn_all.size
        self.n_imu = n_imu
        self.amb_index = np.vstack([n_imu + np.arange(self.n_s),
                                    n_imu + self.n_s + np.arange(self.n_s)])
        self.initialized = np.zeros((2, self.n_s), bool)
        self.lever = np.asarray(lever_arm, float)
        self.frame = frame
        self.cfg = config
        self.ref = -1
        self.nominal_interval_s = nominal_interval_s
        self.prev: TcEpoch | None = None      # the last epoch processed (TDCP)
        # critical values, looked up per epoch (scipy's ppf costs ~0.1 ms per call)
        dof = np.arange(1, CRIT_TABLE_DOF + 1)
        a_out = config.outlier_alpha
        self._z_outlier = float(stats.norm.ppf(1 - a_out / 2)) if a_out > 0 else np.inf
        self._chi2_outlier = np.concatenate([[0.0], stats.chi2.ppf(1 - a_out, dof)]) \
            if a_out > 0 else np.full(dof.size + 1, np.inf)
        self._chi2_fix = np.concatenate([[0.0], stats.chi2.ppf(1 - config.fix_chi2_alpha,
                                                                 dof)])
        self._tdcp_prev = None                # (Δt, prev sat_pos, prev base_range) at t_k

    # --------------------------------------------------------------- bookkeeping
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
            self._update(ep, rec, g)
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
        where = {int(p): i for i, p in enumerate(prev.prn)}
        idx = np.array([where.get(int(p), -1) for p in ep.prn])
        have = idx >= 0
        ok = have & np.isfinite(ep.sd["l1"]) & ~ep.slip
        ok[have] &= np.isfinite(prev.sd["l1"][idx[have]])
        return np.where(ok, idx, -1), dt

    def _update(self, ep: TcEpoch, rec: TcRecords, g: int):
        cfg = self.cfg
        x, p = self.r.x, self.r.p
        r_ant, _ = antenna_ecef(x, self.lever, self.frame)
        los = ep.sat_pos - r_ant
        rho = np.linalg.norm(los, axis=1)
        up = r_ant / np.linalg.norm(r_ant)
        elev = np.arcsin((los / rho[:, None]) @ up)
        mask = np.radians(cfg.elevation_mask_deg)
        ok = np.isfinite(ep.sd["code"]) & (elev >= mask) & (ep.elevation_base >= mask)
        slots = np.array([self.slot[int(q)] for q in ep.prn])
        for k in np.flatnonzero(ep.slip):
            for f in (0, 1):
                self._reset(f, slots[k])
        if ok.sum() < 2:
            rec.n_sat[g] = int(ok.sum())
            return
        phase_ok = ok & np.isfinite(ep.sd["l1"])
        cand = np.flatnonzero(phase_ok if phase_ok.sum() >= 2 else ok)
        cur = np.flatnonzero(ep.prn == self.ref)
        if cur.size and cur[0] in cand and elev[cur[0]] >= mask + np.radians(5.0):
            j = int(cur[0])
        else:
            j = int(cand[np.argmax(elev[cand])])
        self.ref = int(ep.prn[j])
        ks = np.array([k for k in np.flatnonzero(ok) if k != j])
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
            for k in ks:
                if np.isfinite(ep.sd[key][k]) and not self.initialized[f, slots[k]]:
                    self._init_ambiguity(f, slots[k], slots[j],
                                         ep.sd[key][k] - ep.sd[key][j],
                                         ep.sd["code"][k] - ep.sd["code"][j])
        kinds, sat_k, z, r_mat, group_rows = self._dd_rows(
            ep, [k for k in range(4) if cfg.use[k]], slots, j, ks, m_sd)
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
            s_mat = hj @ p @ hj.T + r_mat
            zc = self._z_outlier
            for kind, idx in group_rows.items():
                dg = d[idx]
                sg = s_mat[np.ix_(idx, idx)]
                zstat = np.abs(dg) / np.sqrt(np.diag(sg))
                chi2 = dg @ np.linalg.solve(sg, dg)
                bad = zstat > zc
                if not bad.any() and chi2 > _critical(self._chi2_outlier, cfg.outlier_alpha,
                                                      idx.size):
                    bad[:] = True
                keep[idx[bad]] = False
                rec.rejected_obs[g, kind] = int(bad.sum())
        if not keep.all():
            hj, d, r_mat, kinds = hj[keep], d[keep], r_mat[np.ix_(keep, keep)], kinds[keep]
            sat_k = sat_k[keep]
            m = d.size
            if m == 0:
                return
        # ---- float update
        pht = p @ hj.T
        dmat = hj @ pht + r_mat
        dinv_d = np.linalg.solve(dmat, d)
        gain = np.linalg.solve(dmat, pht.T).T
        x += gain @ d
        p -= gain @ pht.T
        p[:] = 0.5 * (p + p.T)
        x[11] %= 2 * np.pi
        # VCE per group: v = −R D⁻¹ d, vᵀR⁻¹v, r = tr(R (D⁻¹)_gg)
        dinv = np.linalg.inv(dmat)
        v = -r_mat @ dinv_d
        for kind in range(4):
            idx = np.flatnonzero(kinds == kind)
            if idx.size == 0:
                continue
            rg = r_mat[np.ix_(idx, idx)]
            rec.vpv[g, kind] = v[idx] @ np.linalg.solve(rg, v[idx])
            rec.redundancy[g, kind] = np.trace(rg @ dinv[np.ix_(idx, idx)])
            rec.n_obs[g, kind] = idx.size
        rec.innov_std.append((kinds.copy(), d / np.sqrt(np.diag(dmat))))
        # standardized residuals v/σ_v, Q_v = R D⁻¹ R (correlated DD groups)
        qv_diag = np.einsum("ij,jk,ki->i", r_mat, dinv, r_mat)
        rec.residuals.append((g, kinds.copy(), ep.prn[sat_k].copy(),
                              v / np.sqrt(np.maximum(qv_diag, 1e-300))))
        # ---- ambiguity resolution
        self._resolve(ep, rec, g, slots, j, ks, m_sd)

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
        pairs = [(f, k) for f in (0, 1) for k in ks
                 if self.initialized[f, slots[k]] and self.initialized[f, slots[j]]]
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
            if dof > 0 and chi2 > _critical(self._chi2_fix, cfg.fix_chi2_alpha, dof):
                rec.fix_rejected[g] = True
                return
            rec.fixed[g] = True
            rec.n_fixed[g] = len(pairs)
            rec.integers.append({(int(ep.prn[k]), f + 1): int(v)
                                 for (f, k), v in zip(pairs, np.round(a))})
            return
        try:
            res = resolve_integers(a, 0.5 * (qa + qa.T))
        except LambdaInputError:
            return
        rec.ratio[g] = res.ratio
        if not ratio_test(res, cfg.ratio_threshold):
            return
        fixed = res.fixed.astype(float)
        # constrain a copy and test the DD phase residuals (wrong-fix protection)
        r_c = np.eye(len(pairs)) * 1e-8
        s_c = qa + r_c
        gain = np.linalg.solve(s_c, dmat @ p).T
        x_new = x + gain @ (fixed - a)
        p_new = p - gain @ (dmat @ p)
        chi2, dof = self._phase_chi2(ep, x_new, slots, j, ks, m_sd)
        if dof > 0 and chi2 > _critical(self._chi2_fix, cfg.fix_chi2_alpha, dof):
            rec.fix_rejected[g] = True
            return
        x[:] = x_new
        p[:] = 0.5 * (p_new + p_new.T)
        rec.fixed[g] = True
        rec.n_fixed[g] = len(pairs)
        rec.integers.append({(int(ep.prn[k]), f + 1): int(v)
                             for (f, k), v in zip(pairs, res.fixed)})

    def _dd_rows(self, ep, kinds_wanted, slots, j, ks, m_sd):
        """DD rows of the wanted observable kinds against reference j: kinds, satellite
        indices, observed DD z, the block-diagonal covariance σ90²·M per group
        (001 eq. 5.1.10) and each group's row indices. Phase rows need both ambiguity
        states initialised."""
        keys = ("code", "l1", "l2", "doppler")
        kinds, sat_k, z, blocks = [], [], [], []
        for kind in kinds_wanted:
            if kind == OBS_TDCP and self.cfg.tdcp:
                rows, z_rows = self._tdcp_rows(ep, j, ks)
                if rows.size:
                    kinds += [kind] * rows.size
                    sat_k += list(rows)
                    z += list(z_rows)
                    blocks.append((kind, 2.0 * self.cfg.sigma(kind) ** 2
                                   * dd_cofactor_matrix(m_sd[rows], m_sd[j])))
                continue
            key = keys[kind]
            rows = [k for k in ks if np.isfinite(ep.sd[key][k]) and np.isfinite(ep.sd[key][j])]
            if kind in (OBS_L1, OBS_L2):
                rows = [k for k in rows if self.initialized[kind - 1, slots[k]]
                        and self.initialized[kind - 1, slots[j]]]
            if not rows:
                continue
            rows = np.array(rows)
            kinds += [kind] * rows.size
            sat_k += list(rows)
            z += list(ep.sd[key][rows] - ep.sd[key][j])
            blocks.append((kind, self.cfg.sigma(kind) ** 2
                           * dd_cofactor_matrix(m_sd[rows], m_sd[j])))
        m = len(z)
        r_mat = np.zeros((m, m))
        group_rows = {}
        pos = 0
        for kind, cov in blocks:
            n_k = cov.shape[0]
            r_mat[pos:pos + n_k, pos:pos + n_k] = cov
            group_rows[kind] = np.arange(pos, pos + n_k)
            pos += n_k
        return np.array(kinds, dtype=np.int64), np.array(sat_k, dtype=np.int64), \
            np.array(z, dtype=float), r_mat, group_rows

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
        z = (l1[rows] - l1[j]) - (l1p[idx[rows]] - l1p[idx[j]])
        safe = np.maximum(idx, 0)
        prev_pos = np.where((idx >= 0)[:, None], prev.sat_pos[safe], np.nan)
        prev_range = np.where(idx >= 0, prev.base_range[safe], np.nan)
        self._tdcp_prev = (dt, prev_pos, prev_range)
        return rows, z

    def _phase_chi2(self, ep, x, slots, j, ks, m_sd):
        """χ² of the DD phase residuals at state x against the measurement covariance only:
        do the fixed integers fit the phases? (wrong-fix protection)"""
        kinds, sat_k, z, r_mat, _ = self._dd_rows(ep, [OBS_L1, OBS_L2], slots, j, ks, m_sd)
        if z.size == 0:
            return 0.0, 0
        h, _ = dd_model_and_jacobian(x, kinds, sat_k, np.full(z.size, j), ep.sat_pos,
                                     ep.sat_vel, ep.base_range, ep.base_rate,
                                     self.amb_index[:, slots], WAVELENGTHS, self.lever,
                                     self.frame)
        res = z - h - self._troposphere_dd(x, ep, kinds, sat_k, j)
        return float(res @ np.linalg.solve(r_mat, res)), res.size

    def _troposphere_dd(self, x, ep, kinds, sat_k, j):
        """DD of the modelled rover − base hydrostatic slant delay (m) for code/phase rows,
        the rover side evaluated at the state's antenna position (its ∂/∂x, ~3e-4 m per m
        of height, is left out of H). Zero when the epoch carries no base delays."""
        out = np.zeros(kinds.size)
        if ep.base_troposphere is None:
            return out
        r_ant, _ = antenna_ecef(x, self.lever, self.frame)
        sd = slant_hydrostatic_delay(r_ant, ep.sat_pos) - ep.base_troposphere
        ranging = (kinds == OBS_CODE) | (kinds == OBS_L1) | (kinds == OBS_L2)
        out[ranging] = sd[sat_k[ranging]] - sd[j]
        return out


def new_tc_records(g_count: int, epoch_index) -> TcRecords:
    z = np.zeros
    return TcRecords(t=np.zeros(g_count), epoch_index=np.asarray(epoch_index),
                     n_sat=z(g_count, int), ref_prn=np.full(g_count, -1),
                     fixed=z(g_count, bool), ratio=z(g_count), n_fixed=z(g_count, int),
                     fix_rejected=z(g_count, bool), rejected_obs=z((g_count, 4), int),
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
    "run_tightly_coupled",
]


# ----------------------------------------------------------------------------- data


def prepare_tc_epochs(rover, base, nav, base_ecef, time_offset_s: float,
                      t_span=(-np.inf, np.inf), slip_config=None,
                      time_tolerance_s: float = 0.025, hydrostatic_troposphere: bool = False):
    """TcEpochs from rover/base observations (gnss.rinex.ObsData) and a broadcast nav.

    time_offset_s: subtracted from the RINEX absolute GPS time to reach the dataset's time
    base (week·604800 when the other files carry seconds of week). Satellite states come
    from the pseudorange-derived transmit times (so receiver clock offsets do not bias
    them), rotated for the Sagnac effect; the rover's approximate position for that is its
    single-point solution. Slip flags: LLI, gaps, geometry-free and Melbourne-Wübbena on
    each receiver (gnss.rtk.receiver_slip_flags).

    hydrostatic_troposphere: store the base's modelled hydrostatic slant delays
    (gnss.troposphere.saastamoinen_delay with humidity 0, 1/cos z mapping) so the filter
    models the rover − base delay with the rover side at its current antenna position
    (TcFilter._troposphere_dd), as RTKLIB's relative mode does; it matters when the
    antennas' heights differ (≈0.3 mm per metre of height difference at the zenith, ×3.9 at
    15° elevation). Evaluating the rover side at the single-point position instead adds its
    metre-level height noise to the DD phases. Default off: the troposphere cancels."""
    from gnss.cycle_slips import SlipConfig
    from gnss.ephemeris import satellite_states_at_reception
    from gnss.rtk import receiver_slip_flags
    from gnss.spp import solve_spp_session

    base_ecef = np.asarray(base_ecef, float)
    t_ds = rover.t_gps - time_offset_s
    keep_ep = np.flatnonzero((t_ds >= t_span[0]) & (t_ds <= t_span[1]))
    if keep_ep.size == 0:
        raise GmisInputError(
            f"no rover epoch inside the IMU time span {t_span[0]:.3f}..{t_span[1]:.3f} s "
            f"(rover file spans {t_ds[0]:.3f}..{t_ds[-1]:.3f} s after removing "
            f"{time_offset_s:.0f} s); do the files share a time base?", source=rover.path)
    spp = solve_spp_session(rover, nav)
    approx = spp.position.copy()
    good = np.flatnonzero(spp.ok)
    if good.size == 0:
        raise GmisInputError("no rover epoch has a single-point solution", source=rover.path)
    fill = good[np.clip(np.searchsorted(good, np.arange(approx.shape[0])), 0, good.size - 1)]
    approx[~spp.ok] = spp.position[fill[~spp.ok]]
    cfg = slip_config or SlipConfig()
    slip_r = receiver_slip_flags(rover, cfg)
    slip_b = receiver_slip_flags(base, cfg)
    jb = np.clip(np.searchsorted(base.t_gps, rover.t_gps), 0, base.t_gps.size - 1)
    jb_lo = np.maximum(jb - 1, 0)
    jb = np.where(np.abs(base.t_gps[jb_lo] - rover.t_gps) < np.abs(base.t_gps[jb] -
                                                                   rover.t_gps), jb_lo, jb)
    epochs = []
    # slip flags of epochs (or satellites) that form no TcEpoch are carried to the
    # satellite's next TcEpoch: a slip must reset its ambiguity and break its TDCP
    pend_r = np.zeros(rover.prn.size, bool)
    pend_b = np.zeros(base.prn.size, bool)
    b_last = jb[keep_ep[0]] - 1
    for i in keep_ep:
        b = jb[i]
        pend_r |= slip_r[i]
        if abs(base.t_gps[b] - rover.t_gps[i]) > time_tolerance_s:
            continue
        if b > b_last:
            pend_b |= slip_b[b_last + 1:b + 1].any(axis=0)
            b_last = b
        cols = []
        for s, prn in enumerate(rover.prn):
            cb = base.sat_index(prn)
            if cb >= 0 and np.isfinite(rover.C1[i, s]) and np.isfinite(base.C1[b, cb]):
                cols.append((s, cb, prn))
        if len(cols) < 2:
            continue
        sr = np.array([c[0] for c in cols])
        sb = np.array([c[1] for c in cols])
        prn = np.array([c[2] for c in cols])
        st_r, _, _ = satellite_states_at_reception(nav, prn, np.full(prn.size, rover.t_gps[i]),
                                                   rover.C1[i, sr], approx[i])
        st_b, _, _ = satellite_states_at_reception(nav, prn, np.full(prn.size, base.t_gps[b]),
                                                   base.C1[b, sb], base_ecef)
        los_b = st_b.position - base_ecef
        rng_b = np.linalg.norm(los_b, axis=1)
        e_b = los_b / rng_b[:, None]
        up_b = base_ecef / np.linalg.norm(base_ecef)
        sd = {
            "code": rover.C1[i, sr] - base.C1[b, sb],
            "l1": WAVELENGTH_L1 * (rover.L1[i, sr] - base.L1[b, sb]),
            "l2": WAVELENGTH_L2 * (rover.L2[i, sr] - base.L2[b, sb]),
            "doppler": -WAVELENGTH_L1 * (rover.D1[i, sr] - base.D1[b, sb]),
        }
        base_trop = slant_hydrostatic_delay(base_ecef, st_b.position) \
            if hydrostatic_troposphere else None
        valid_sat = np.all(np.isfinite(st_r.position), axis=1)
        if valid_sat.sum() < 2:
            continue
        epochs.append(TcEpoch(
            t=float(np.round(t_ds[i], 6)), prn=prn[valid_sat],
            sat_pos=st_r.position[valid_sat], sat_vel=st_r.velocity[valid_sat],
            base_range=rng_b[valid_sat],
            base_rate=np.einsum("ij,ij->i", e_b, st_b.velocity)[valid_sat],
            elevation_base=np.arcsin(e_b @ up_b)[valid_sat],
            sd={k: v[valid_sat] for k, v in sd.items()},
            slip=(pend_r[sr] | pend_b[sb])[valid_sat],
            base_troposphere=None if base_trop is None else base_trop[valid_sat]))
        pend_r[sr[valid_sat]] = False
        pend_b[sb[valid_sat]] = False
    return epochs


# ----------------------------------------------------------------------------- recipe glue


def gnss_time_offset(recipe, imu_t, rover) -> float:
    """Seconds to subtract from RINEX absolute GPS time to reach the dataset's time base:
    0 when the IMU file already uses absolute GPS seconds, else week·604800 ([time].gps_week
    or the rover file's first week)."""
    if imu_t[0] > 2 * 604800.0:
        return 0.0
    week = recipe.time.gps_week if recipe.time.gps_week is not None else int(rover.week[0])
    return week * 604800.0


def read_raw_gnss(recipe):
    """Rover, base (and heading) observations and the nav file named by the recipe."""
    from gnss.rinex import read_nav, read_obs
    paths = recipe.paths
    missing = [k for k in ("rover_obs", "base_obs", "nav") if getattr(paths, k) is None]
    if missing or recipe.base is None:
        what = ", ".join(f"[paths].{k}" for k in missing) + (", [base]" if recipe.base is None
                                                              else "")
        raise GmisInputError(f"filter.mode = \"tight\" needs {what.strip(', ')}",
                             source=str(recipe.path))
    rover = read_obs(paths.rover_obs)
    base = read_obs(paths.base_obs)
    nav = read_nav(paths.nav)
    heading = read_obs(paths.heading_obs) if paths.heading_obs is not None else None
    return rover, base, nav, heading


@dataclass
class TightInputs:
    """Iteration-invariant inputs of a tightly coupled run (for VCE iterations)."""
    epochs: list
    heading_t: np.ndarray
    heading: np.ndarray
    heading_sd: np.ndarray
    stationary_fn: object
    config: TcConfig
    info: dict


_HEADING_CACHE: dict = {}


def dual_antenna_heading_for(recipe, rover=None, heading_obs=None, nav=None):
    """gnss.heading solution of the recipe's primary/heading antennas (memoised per file
    set, since both the initialisation and the filter input need it)."""
    from gnss.heading import dual_antenna_heading
    from gnss.rinex import read_nav, read_obs
    key = (str(recipe.paths.rover_obs), str(recipe.paths.heading_obs), str(recipe.paths.nav),
           tuple(recipe.antennas.primary_lever_arm_m),
           tuple(recipe.antennas.secondary_lever_arm_m or ()))
    if key not in _HEADING_CACHE:
        rover = rover if rover is not None else read_obs(recipe.paths.rover_obs)
        heading_obs = heading_obs if heading_obs is not None else \
            read_obs(recipe.paths.heading_obs)
        nav = nav if nav is not None else read_nav(recipe.paths.nav)
        _HEADING_CACHE.clear()
        _HEADING_CACHE[key] = dual_antenna_heading(
            rover, heading_obs, nav, recipe.antennas.primary_lever_arm_m,
            recipe.antennas.secondary_lever_arm_m)
    return _HEADING_CACHE[key]


def raw_gnss_initialisation(recipe, frame, imu_t, window_s):
    """Initial heading (rad, circular mean of fixed dual-antenna epochs in the window, or
    None) and primary-antenna ENU position (m, mean single-point solution in the window)
    for a tightly coupled recipe without GNSS-solution / heading files."""
    from gmis.earth import ecef_to_enu
    from gnss.spp import solve_spp_session
    rover, _, nav, heading_obs = read_raw_gnss(recipe)
    offset = gnss_time_offset(recipe, imu_t, rover)
    t_end = imu_t[0] + max(window_s, 1.0)
    heading0 = None
    if heading_obs is not None and recipe.antennas.secondary_lever_arm_m is not None:
        hs = dual_antenna_heading_for(recipe, rover, heading_obs, nav)
        sel = (hs.q == 1) & (hs.t_gps - offset <= t_end) & np.isfinite(hs.heading)
        if not sel.any():
            sel = (hs.q == 1) & np.isfinite(hs.heading)
        if sel.any():
            heading0 = float(np.arctan2(np.sin(hs.heading[sel]).mean(),
                                        np.cos(hs.heading[sel]).mean()) % (2 * np.pi))
    spp = solve_spp_session(rover, nav)
    sel = spp.ok & (spp.t_gps - offset <= t_end)
    if not sel.any():
        sel = spp.ok
    if not sel.any():
        raise GmisInputError("no rover epoch has a single-point solution for the initial "
                             "position", source=rover.path)
    ant0 = ecef_to_enu(frame, spp.position[sel].mean(axis=0))
    return heading0, ant0


def prepare_tight(prep) -> TightInputs:
    """Read the RINEX files, form the DD epoch inputs and the heading stream: dual-antenna
    RINEX (gnss.heading, fixed epochs) when [paths].heading_obs is given, else the heading
    file. TcConfig from the recipe's [noise] (σ90 of code, phase, Doppler, TDCP) and
    [filter].tc_velocity_observable; the rover − base hydrostatic troposphere is removed from
    the single differences unless [filter].tc_troposphere = "none"."""
    from gmis.motion import gnss_horizontal_speed, stationary_epochs
    recipe = prep.recipe
    rover, base, nav, heading_obs = read_raw_gnss(recipe)
    imu = prep.dataset.imu
    offset = gnss_time_offset(recipe, imu.t, rover)
    epochs_tc = prepare_tc_epochs(
        rover, base, nav, recipe.base.ecef_m, offset, (imu.t[0], imu.t[-1]),
        hydrostatic_troposphere=recipe.filter.tc_troposphere == "hydrostatic")
    cfg = prep.tc_config()
    info = {"gnss_epochs": len(epochs_tc), "time_offset_s": offset,
            "velocity_observable": cfg.velocity_observable,
            "troposphere": recipe.filter.tc_troposphere}
    if heading_obs is not None and recipe.antennas.secondary_lever_arm_m is not None:
        hs = dual_antenna_heading_for(recipe, rover, heading_obs, nav)
        ok = (hs.q == 1) & np.isfinite(hs.heading)
        h_t, h, h_sd = np.round(hs.t_gps[ok] - offset, 6), hs.heading[ok], hs.sigma_heading[ok]
        info.update(heading_source="dual-antenna RINEX (gnss.heading)",
                    heading_fix_rate=hs.fix_rate)
    elif prep.dataset.heading is not None:
        h_t, h, h_sd = prep.dataset.heading.t, prep.dataset.heading.heading, \
            prep.dataset.heading.sigma
        info["heading_source"] = "heading file"
    else:
        h_t = h = h_sd = np.zeros(0)
        info["heading_source"] = "none"
    in_span = (h_t >= imu.t[0]) & (h_t <= imu.t[-1])

    def still(epochs):
        if prep.meas.pos_enu.size == 0:
            return None
        t_pos = prep.epochs.t[prep.epochs.pos >= 0]
        speed = gnss_horizontal_speed(t_pos, prep.meas.pos_enu,
                                      prep.meas.vel_enu if prep.meas.vel_enu.size else None)
        return stationary_epochs(epochs, t_pos, speed)

    return TightInputs(epochs_tc, h_t[in_span], h[in_span], h_sd[in_span], still, cfg, info)


def run_tight(prep, progress=None, inputs: TightInputs | None = None, gmikf_config=None,
              tc_config: TcConfig | None = None, heading_scale: float = 1.0):
    """Tightly coupled run of a prepared recipe. Returns (FilterRecords, TcRecords, info)."""
    inp = inputs or prepare_tight(prep)
    imu = prep.dataset.imu
    rec, tc_rec, prns = run_tightly_coupled(
        imu.t, np.hstack([imu.gyro, imu.accel]), inp.heading_t, inp.heading,
        inp.heading_sd * heading_scale, inp.epochs, prep.x0, gmikf_config or prep.config,
        tc_config or inp.config, prep.frame, stationary_fn=inp.stationary_fn,
        progress=progress)
    info = dict(inp.info)
    info["prns"] = [int(p) for p in prns]
    return rec, tc_rec, info
