"""Iterative VCE tuning of the GMIKF (001 §5.3, §6.2.4).

Each iteration runs the filter with residuals and redundancy on, estimates σ̂²_0 for every
component (vce.estimate) and sets the next sigma to σ·sqrt(σ̂²_0), except for components
that are not estimated (drift noises unless switched on) or whose mean redundancy is
below ``min_redundancy`` (0.1, 001 §5.3: 'high-leverage' observations keep their value).
The joint Helmert solve keeps only the components it determines (precision
sqrt(2 (S⁻¹)_jj) ≤ ``max_sd``, 001 §5.2.1); the others use the simplified ratio, and each
iteration records which estimator every component used. The job stops when
|σ̂²_0 − 1| < tol for every estimated component and the estimated set did not change
from the previous iteration, or after ``max_iterations`` runs. Every iteration is kept for the tables and convergence plots.
"""

from __future__ import annotations

import dataclasses
import functools
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gmis.noise_registry import BY_COMPONENT, noise_overrides_from_components
from gmis.readers import load_dataset
from gmis.recipe import Recipe
from gmis.run_filter import FilterRecords
from gmis.run_preparation import (
    PreparedRun,
    prepare_run,
    release_prepared_inputs,
    run_prepared,
    streams_imu,
)
from vce import blockwise
from vce.components import (
    GNSS_ERROR_COMPONENTS,
    VarianceComponent,
    dd_components,
    gmikf_components,
)
from vce.estimate import (
    ESTIMATOR_HELD,
    ESTIMATOR_SIMPLIFIED,
    ComponentEstimate,
    corrected_totals,
    elementary_indices,
    estimate_dd_component,
    joint_helmert,
)
from vce.spooled_records import spool_component_residuals, spooled_run


@dataclass
class IterationRecord:
    iteration: int                      # 1-based
    sigma: np.ndarray                   # sigma used in this run (SI, or scale)
    estimates: list[ComponentEstimate]
    next_sigma: np.ndarray
    status: list[str]                   # "estimated" | "low redundancy" | "no data" | "held (constraint)"
    stationary_epochs: int
    sigma0_sq: np.ndarray               # Helmert σ̂²_0 (used for next_sigma); NaN if held
    estimator: list[str] = field(default_factory=list)  # "helmert" | "simplified" | "held"
    sigma0_sd: np.ndarray | None = None  # 1σ precision of σ̂²_0 (001 §5.2.1: 2σ⁴S⁻¹)
    sigma0_sd_joint: np.ndarray | None = None  # sqrt(2 (S⁻¹)_jj) with every candidate joint
    dropped: list = field(default_factory=list)  # (component, reason) left the joint solve


@dataclass
class TuningResult:
    components: list[VarianceComponent]
    history: list[IterationRecord]
    converged: bool
    tol: float
    final_sigma: np.ndarray             # sigma of the last run (SI / scale)
    residuals_first: dict = field(default_factory=dict)   # name → (t, standardized)
    residuals_final: dict = field(default_factory=dict)
    windows_final: dict = field(default_factory=dict)     # name → (t, σ̂²_0, Σr)
    records_final: FilterRecords | None = None

    def table_rows(self):
        """One row per (iteration, component): the layout of 001 Tables 6-4..6-7."""
        rows = []
        for it in self.history:
            k = len(self.components)
            estimator = it.estimator or [""] * k
            sd = it.sigma0_sd if it.sigma0_sd is not None else np.full(k, np.nan)
            sdj = it.sigma0_sd_joint if it.sigma0_sd_joint is not None else np.full(k, np.nan)
            for c, s, est, nxt, st, h0, how, p, pj in zip(
                    self.components, it.sigma, it.estimates, it.next_sigma, it.status,
                    it.sigma0_sq, estimator, sd, sdj):
                rows.append({
                    "estimator": how, "sigma0_sq_sd": p, "sigma0_sq_sd_joint": pj,
                    "iteration": it.iteration, "component": c.name, "unit": c.unit,
                    "sigma": s / c.to_si, "mean_redundancy": est.mean_redundancy,
                    "sum_redundancy": est.sum_r, "sigma0_sq": h0,
                    "sigma0_sq_simplified": est.sigma0_sq,
                    "observations": est.n_obs, "blunders": est.n_blunders,
                    "next_sigma": nxt / c.to_si, "status": st,
                    "f_statistic": est.f_stat, "f_critical": est.f_crit,
                    "f_test": "pass" if est.f_pass else "FAIL"})
        return rows


NHC_SLOT = {"nhc_lateral": 0, "nhc_vertical": 1}
ZERO_MOTION = {"zupt": "zupt_sd", "zaru": "zaru_sd"}   # component → GmikfConfig σ field


def _initial_sigma(prep: PreparedRun, comps, tc_config=None):
    cfg = prep.config
    out = np.empty(len(comps))
    for j, c in enumerate(comps):
        if c.kind == "dd":
            out[j] = tc_config.sigma(c.index[0])
        elif c.is_scale:
            out[j] = 1.0
        elif c.name in NHC_SLOT:
            out[j] = cfg.nhc_sd[NHC_SLOT[c.name]]
        elif c.name in ZERO_MOTION:
            out[j] = getattr(cfg, ZERO_MOTION[c.name])[0]
        elif c.name in GNSS_ERROR_COMPONENTS:
            out[j] = cfg.gnss_error_sigma_m[GNSS_ERROR_COMPONENTS.index(c.name)]
        elif c.kind == "measurement":
            out[j] = cfg.imu_sd[c.index[0]]
        else:
            out[j] = cfg.q_sd[c.index[0]]
    return out


def apply_sigma(prep: PreparedRun, comps, sigma):
    """Filter config and measurements for one iteration's sigmas."""
    imu_sd = prep.config.imu_sd.copy()
    q_sd = prep.config.q_sd.copy()
    nhc_sd = prep.config.nhc_sd.copy()
    zero_motion = {f: getattr(prep.config, f).copy() for f in ZERO_MOTION.values()}
    gnss_error_sigma = prep.config.gnss_error_sigma_m.copy()
    meas = dataclasses.replace(prep.meas)
    for c, s in zip(comps, sigma):
        if c.kind == "dd":
            continue
        if c.is_scale:
            if c.name == "gnss_position":
                meas.pos_sd = prep.meas.pos_sd * s
            elif c.name == "gnss_velocity":
                meas.vel_sd = prep.meas.vel_sd * s
            elif c.name == "heading":
                meas.heading_sd = prep.meas.heading_sd * s
            elif c.name in ("gnss_speed", "gnss_course"):      # gmis.speed_course
                col = 0 if c.name == "gnss_speed" else 1
                meas.speed_course_sd = meas.speed_course_sd.copy()
                meas.speed_course_sd[:, col] = prep.meas.speed_course_sd[:, col] * s
        elif c.name in NHC_SLOT:
            nhc_sd[NHC_SLOT[c.name]] = s
        elif c.name in ZERO_MOTION:
            zero_motion[ZERO_MOTION[c.name]][:] = s
        elif c.name in GNSS_ERROR_COMPONENTS:
            gnss_error_sigma[GNSS_ERROR_COMPONENTS.index(c.name)] = s
        elif c.kind == "measurement":
            imu_sd[list(c.index)] = s
        else:
            q_sd[list(c.index)] = s
    n_axes = max([6] + [k + 1 for c in comps if c.kind == "process" for k in c.index])
    cfg = dataclasses.replace(prep.config, imu_sd=imu_sd, q_sd=q_sd, nhc_sd=nhc_sd,
                              gnss_error_sigma_m=gnss_error_sigma, **zero_motion,
                              vce_mode=1,
                              vce_noise_axes=n_axes)
    return cfg, meas


def tc_config_field(comp) -> str:
    """TcConfig field of a DD group component (gmis.noise_registry)."""
    return BY_COMPONENT[comp.name][0].slots[0]


def helmert_sigma0(helmert_s, helmert_totals, comps, estimates, status, max_sd=0.1):
    """Helmert's estimate (001 eq. 2.7.6 with the trace form of docs/DESIGN.md) of the
    variance factors of the estimated components, solved jointly with a free factor for
    the predicted-state group x (whose covariance Φ P Φᵀ inherits any mis-scaling of Q
    and R); only the components the data determine (precision sqrt(2 (S⁻¹)_jj) ≤ max_sd,
    001 §5.2.1) stay in the joint solve, the others fall back to the simplified ratio
    (vce.estimate.joint_helmert, which also says per component which estimator it used).
    Returns the factors (NaN where held)."""
    return _joint(helmert_s, helmert_totals, comps, estimates, status, max_sd).sigma0_sq


def _joint(helmert_s, helmert_totals, comps, estimates, status, max_sd,
           simplified_only=None):
    return joint_helmert(helmert_s, helmert_totals, [elementary_indices(c) for c in comps],
                         estimates, [st == "estimated" for st in status],
                         [c.name for c in comps], max_sd, simplified_only)


def _components(prep: PreparedRun, estimate_drifts: bool):
    """(tightly coupled inputs or None, the variance components of the run)."""
    if prep.recipe.filter.mode == "tight":
        from gmis.tc import prepare_tight
        tight_inputs = prepare_tight(prep)
        comps = gmikf_components(prep.config.n_imu, has_position=False, has_velocity=False,
                                 has_heading=tight_inputs.heading.size > 0,
                                 include_drifts=estimate_drifts,
                                 has_nonholonomic=prep.config.nhc_enabled,
                                 has_zero_motion=prep.config.zupt_enabled) \
            + dd_components(tight_inputs.config.velocity_observable)
        return tight_inputs, comps
    return None, gmikf_components(prep.config.n_imu, has_position=prep.meas.pos_enu.size > 0,
                                  has_velocity=prep.meas.vel_enu.size > 0,
                                  has_heading=prep.meas.heading.size > 0,
                                  include_drifts=estimate_drifts,
                                  has_nonholonomic=prep.config.nhc_enabled,
                                  has_zero_motion=prep.config.zupt_enabled,
                                  has_speed_course=len(prep.meas.speed_course) > 0,
                                  has_gnss_error_states=prep.config.gnss_error_states)


def _status(comp, est, min_redundancy) -> str:
    """Whether a component's σ is re-estimated this iteration (001 §5.3)."""
    if not np.isfinite(est.sigma0_sq) or est.n_obs == 0:
        return "no data"
    if comp.name in NHC_SLOT:
        # a pseudo-observation of a time-correlated, mostly deterministic violation
        # (sideslip): not white noise, so its σ stays the user's choice; it enters
        # the joint Helmert solution with factor 1 (docs/DESIGN.md)
        return "held (constraint)"
    if est.mean_redundancy < min_redundancy:
        return "low redundancy"
    return "estimated"


def tune(recipe: Recipe | PreparedRun, max_iterations: int = 30, tol: float = 0.02,
         min_redundancy: float = 0.1, estimate_drifts: bool = False,
         initial_sigma: dict | None = None, progress=None,
         window_s: float = 60.0, max_sd: float = 0.1) -> TuningResult:
    """Run the iterative VCE job. initial_sigma: {component name: sigma (SI / scale)}
    overrides the recipe's starting values (e.g. 3× the truth in recovery tests)."""
    # VCE never compares with the reference trajectory: not read (docs/DESIGN.md "Bounded
    # memory"); the IMU samples stay on disk in the plain loosely coupled case
    prep = recipe if isinstance(recipe, PreparedRun) else prepare_run(
        recipe, dataset=load_dataset(recipe, with_reference=False,
                                     imu_on_disk=streams_imu(recipe)))
    tight = prep.recipe.filter.mode == "tight"
    if not tight and not isinstance(recipe, PreparedRun):
        # the job's own preparation: prep.meas holds the aiding rows in ENU; the
        # dataset's copies go (gmis.run_preparation.release_prepared_inputs)
        release_prepared_inputs(prep)
    tight_inputs, comps = _components(prep, estimate_drifts)
    sigma = _initial_sigma(prep, comps, tight_inputs.config if tight else None)
    names = [c.name for c in comps]
    for key, value in (initial_sigma or {}).items():
        if key not in names:
            raise KeyError(f"initial_sigma: unknown component {key!r}; known: {names}")
        sigma[names.index(key)] = float(value)
    history = []
    result = TuningResult(components=comps, history=history, converged=False, tol=tol,
                          final_sigma=sigma.copy())
    # records and residuals on disk (vce.spooled_records); removed with the result
    result.spool = tempfile.TemporaryDirectory(prefix="gmis-vce-")
    spool = Path(result.spool.name)
    # components that left the joint Helmert solve (precision > max_sd or a non-positive
    # factor) stay on the simplified ratio for the rest of the job: near the max_sd
    # threshold a component otherwise alternates between the two estimators (e.g. 1.17
    # joint / 0.86 simplified) and the job never converges (docs/DESIGN.md)
    left_joint = np.zeros(len(comps), bool)
    last_factor = np.ones(len(comps))        # f of each component's last estimate
    for it in range(1, max_iterations + 1):
        shutil.rmtree(spool / f"it{it - 1}", ignore_errors=True)
        cfg, meas = apply_sigma(prep, comps, sigma)
        sub = None if progress is None else \
            (lambda f, it=it: progress((it - 1 + f) / max_iterations))
        if tight:
            from gmis.tc import run_tight
            tc_cfg = dataclasses.replace(
                tight_inputs.config, **{tc_config_field(c): float(s)
                                        for c, s in zip(comps, sigma) if c.kind == "dd"})
            h_scale = next((float(s) for c, s in zip(comps, sigma) if c.name == "heading"),
                           1.0)
            rec, tc_rec, _ = run_tight(prep, progress=sub, inputs=tight_inputs,
                                       gmikf_config=cfg, tc_config=tc_cfg,
                                       heading_scale=h_scale)
        else:
            rec = spooled_run(functools.partial(run_prepared, prep, cfg, progress=sub,
                                                meas=meas),
                              comps, len(prep.epochs), spool / f"it{it}")
            tc_rec = None
        still = rec.still
        # what the kernel divided v_w² by (gmis.run_filter vce_step_var: 1 for the
        # fix-error axes)
        q_var = np.r_[cfg.q_sd ** 2, np.ones(3 if cfg.gnss_error_states else 0)]
        estimates, status = [], []
        for c in comps:
            est = (estimate_dd_component(tc_rec, c) if c.kind == "dd"
                   else blockwise.estimate(rec, c, q_var, still,
                                           outlier_alpha=cfg.outlier_alpha))
            estimates.append(est)
            status.append(_status(c, est, min_redundancy))
        loop = [j for j, c in enumerate(comps) if c.kind != "dd"]
        sigma0 = np.full(len(comps), np.nan)
        sigma0_sd = np.full(len(comps), np.nan)
        sigma0_sd_joint = np.full(len(comps), np.nan)
        estimator = [ESTIMATOR_HELD] * len(comps)
        totals = corrected_totals(rec, cfg.outlier_alpha)
        joint = _joint(rec.helmert_s, totals, [comps[j] for j in loop],
                       [estimates[j] for j in loop], [status[j] for j in loop], max_sd,
                       left_joint[loop])
        sigma0[loop] = joint.sigma0_sq
        sigma0_sd[loop] = joint.precision
        sigma0_sd_joint[loop] = joint.precision_joint
        for a, j in enumerate(loop):
            estimator[j] = joint.estimator[a]
            left_joint[j] |= joint.estimator[a] == ESTIMATOR_SIMPLIFIED
        for j, c in enumerate(comps):      # DD groups: Σ vᵀR⁻¹v / Σ r (block redundancy)
            if c.kind == "dd" and status[j] == "estimated":
                sigma0[j] = estimates[j].sigma0_sq
                sigma0_sd[j] = sigma0[j] * np.sqrt(2.0 / estimates[j].sum_r)
                estimator[j] = ESTIMATOR_SIMPLIFIED
        nxt = sigma.copy()
        for j in range(len(comps)):
            if status[j] == "estimated":
                # σ² ← σ² f (001 eq. 2.7.6 iterated); half the step in log σ² when f
                # crossed 1 since the previous iteration (an overshoot: with correlated
                # components the joint solve can alternate around the fixed point, e.g.
                # gyro factors 1.22 / 0.91 / 1.04 / 0.98 …). The fixed point (f = 1)
                # and the convergence test on f are unchanged.
                overshoot = (sigma0[j] - 1.0) * (last_factor[j] - 1.0) < 0.0
                nxt[j] = sigma[j] * sigma0[j] ** (0.25 if overshoot else 0.5)
                last_factor[j] = sigma0[j]
        history.append(IterationRecord(it, sigma.copy(), estimates, nxt, status,
                                       int(still.sum()), sigma0, estimator, sigma0_sd,
                                       sigma0_sd_joint, joint.dropped))
        if it == 1:
            result.residuals_first = spool_component_residuals(
                rec, comps, q_var, still, tc_rec, spool, "first")
        # converged: every estimated component met the tolerance AND the set of estimated
        # (not held) components is the one of the previous iteration — when it changes,
        # the σ̂²_0 jump of the changed set is iterated out, not emitted
        same_set = it == 1 or ([how == ESTIMATOR_HELD for how in estimator]
                               == [how == ESTIMATOR_HELD for how in history[-2].estimator])
        done = same_set and all(abs(h0 - 1.0) < tol for h0, how in zip(sigma0, estimator)
                                if how != ESTIMATOR_HELD)
        result.final_sigma = sigma.copy()
        if done or it == max_iterations:
            result.converged = done
            result.residuals_final = spool_component_residuals(
                rec, comps, q_var, still, tc_rec, spool, "final")
            result.windows_final = {c.name: blockwise.sliding_window(rec, c, q_var, window_s,
                                                                     still) for c in comps}
            result.records_final = rec
            break
        sigma = nxt
    return result


def tuned_noise_overrides(result: TuningResult, recipe: Recipe) -> tuple[dict, dict]:
    """(NoiseSection field values (SI) for Recipe.with_noise, aiding scales) from the
    final sigmas, mapped through gmis.noise_registry."""
    return noise_overrides_from_components(recipe.noise, result.components,
                                           result.final_sigma)
