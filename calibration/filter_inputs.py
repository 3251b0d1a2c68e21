"""The identified model as GMIKF noise inputs (002 §IV, 001 §5.3.2) and the 001 §5.3.5
comparison table.

At the recipe's IMU interval δt (the calibration's is Δt), per axis, SI:
* measurement σ (``[noise].gyro_deg_s`` / ``accel_m_s2``): the white part rescaled to δt,
  σ² = σ²_WN Δt/δt, plus the quantisation noise's per-sample variance 2Q²; an AR1 with
  correlation time below ``white_below_s`` (default 1 s, and at least the IMU interval)
  counts as white noise of variance ξ²/(1−φ)² (its over-bound, 000 eq. 4.5: the same
  spectral density at f = 0, so the same angle/velocity random walk over spans ≫ τ — within
  τ/T over a span T). Such an AR1 is colour in the measurement noise, not a bias the filter
  can track between 5 Hz GNSS updates; left in the bias part it forced the one Gauss-Markov
  bias state to its τ (ADIS16405 gyro z: τ_b 0.06 s from the 0.05 s AR1 next to a 45 s AR1
  and a RW; accels τ_b 0.55-4.7 s from their 0.22-0.28 s AR1s), and with a RW beside it the
  filter was over-confident at the end of the drive (benchmarks/gm_bias_study.py);
* bias drift as a random walk per step (``[noise].gyro_bias_drift_deg_s`` /
  ``accel_bias_drift_m_s2``): γ²δ/Δt per step of δ with γ² the model's RW plus every AR1 of the bias
  part (τ ≥ max(δt, white_below_s)) over-bounded by a RW matched at scale τ = 4 (000 eqs. 4.7-4.8) — without the AR1 part a
  RW+AR1 model's random-walk alternative under-states the drift (bias NEES 5.5-28 in
  benchmarks/gm_bias_study.py --with-rw). The recipe's drift keys are per step of
  δ = 1/``gmis.filter_defaults.Q_RATE_HZ`` (100 Hz, whatever the IMU rate: docs/formats.md), so the
  fragment writes ``bias_drift_sigma_per_recipe_step``; ``bias_drift_sigma_per_step`` is
  the same drift per IMU interval δt (δ = δt for a 100 Hz IMU);
* every AR1 as a first-order Gauss-Markov bias b_{k+1} = e^{−δt/τ} b_k + w_k: τ (s),
  stationary σ² = ξ²/(1−φ²), per-step var w = σ²(1 − e^{−2δt/τ}).
* the filter's bias state (one per axis, gmis's GMIKF and error-state INS): a first-order
  Gauss-Markov bias (``[noise].gyro_bias_model = "gauss_markov"``, ``gyro_bias_tau_s``,
  ``gyro_bias_sigma_deg_s``) when every axis of the sensor has an AR1 with
  τ ≥ max(δt, white_below_s). A single AR1 and no RW is taken exactly. Otherwise (AR1 + RW, or several AR1s) one
  state cannot be the model, and the state is the Gauss-Markov process that OVER-BOUNDS
  the bias part on the lags the filter sees (:func:`gauss_markov_overbound`): with the
  bias structure function D(h) = E[(b_{t+h} − b_t)²] = Σ_k 2s²_k(1 − φ_k^h) + γ²h of
  those AR1s and the RW, (σ_b, τ_b) with 2σ_b²(1 − e^{−h/τ_b}) ≥ D(h) for every
  lag δt ≤ h ≤ ``horizon_s`` (the drive's duration: beyond it a RW outgrows any GM) and
  σ_b² ≥ Σs²_k + γ²·horizon (the bias' own variance), the smallest mean log excess; the
  excess (mean and max of D_GM/D) is reported. The
  fragment says what is over-bounded and keeps the random-walk alternative as a comment.
"""

from __future__ import annotations

import numpy as np

from calibration import processes as P
from calibration.allan import equivalent_white_sigma
from calibration.gmwm import GmwmFit
from gmis.filter_defaults import Q_RATE_HZ

DEG = np.pi / 180.0


RECIPE_STEP_S = 1.0 / Q_RATE_HZ  # the [noise] drift keys are 1σ per step of this
HORIZON_S = 3600.0  # default lag range of the Gauss-Markov over-bound: a 1 h drive
WHITE_BELOW_S = 1.0  # AR1s with a shorter correlation time count as white measurement noise
_LAGS = 240  # log-spaced lags δt..horizon where the over-bound is enforced
_TAUS = 600  # candidate correlation times δt..10³·horizon


def rw_overbound_of_ar1(phi: float, sigma2: float) -> float:
    """γ² with ν_RW(4) = ν_AR1(4) (000 eq. 4.8)."""
    return float(P.ar1_wv(phi, sigma2, np.array([4.0]))[0] / P.rw_wv(1.0, 4.0))


def bias_structure_function(ar1, gamma2: float, lag_samples) -> np.ndarray:
    """D(h) = E[(b_{t+h} − b_t)²] = Σ_k 2 s²_k (1 − φ_k^h) + γ² h of the bias part (AR1s
    ``ar1`` = [(φ, ξ²), …], s² = ξ²/(1−φ²), and a RW γ²), lag h in samples, u²."""
    h = np.asarray(lag_samples, float)
    d = gamma2 * h
    for phi, xi2 in ar1:
        d = d + 2.0 * xi2 / (1.0 - phi * phi) * -np.expm1(h * np.log(phi))
    return d


def gauss_markov_overbound(ar1, gamma2: float, dt: float, imu_dt: float,
                           horizon_s: float = HORIZON_S) -> dict:
    """The first-order Gauss-Markov bias (τ_b s, σ_b u) whose structure function
    2σ_b²(1 − e^{−h/τ_b}) is ≥ D(h) (:func:`bias_structure_function`) at every lag
    δt ≤ h ≤ horizon_s with the smallest mean log(D_GM/D) over log-spaced lags; for each
    τ_b on a grid the smallest σ_b² is max_h D/(2(1 − e^{−h/τ_b})), and at least the
    bias' variance Σ s²_k + γ²·horizon (the filter's Gauss-Markov variance is stationary).
    Returns τ_b, σ_b and the over-bound factors D_GM/D (mean over the lags, max, at the
    horizon)."""
    if not horizon_s > imu_dt:
        raise ValueError(f"horizon {horizon_s} s must exceed the IMU interval {imu_dt} s")
    lags = np.geomspace(imu_dt, horizon_s, _LAGS)
    d = bias_structure_function(ar1, gamma2, lags / dt)
    taus = np.geomspace(imu_dt, 1e3 * horizon_s, _TAUS)
    shape = -np.expm1(-lags[None, :] / taus[:, None])  # (T, H): 1 − e^{−h/τ}
    # the filter's prior and stationary variance must also cover the bias' own variance
    # s² + γ²t up to the horizon (the RW starts at 0 with the record, the AR1s stationary):
    # an increment over-bound alone leaves var b_t up to 2σ_b² − s² (b_a NEES 5-9 at 590 s)
    marginal = sum(xi2 / (1.0 - phi * phi) for phi, xi2 in ar1) + gamma2 * horizon_s / dt
    s2 = np.maximum(np.max(d[None, :] / (2.0 * shape), axis=1), marginal)
    excess = np.mean(np.log(2.0 * s2[:, None] * shape / d[None, :]), axis=1)
    k = int(np.argmin(excess))
    ratio = 2.0 * s2[k] * shape[k] / d
    return {"model": "gauss_markov", "tau_s": float(taus[k]),
            "stationary_sigma": float(np.sqrt(s2[k])), "horizon_s": float(horizon_s),
            "overbound_mean": float(np.exp(excess[k])), "overbound_max": float(ratio.max()),
            "overbound_at_horizon": float(ratio[-1])}


def filter_noise(fit: GmwmFit, imu_dt: float, horizon_s: float = HORIZON_S,
                 white_below_s: float = WHITE_BELOW_S) -> dict:
    return filter_noise_of(fit.model, fit.theta, fit.wv.dt, imu_dt, horizon_s, white_below_s)


def filter_noise_of(model, theta, dt: float, imu_dt: float, horizon_s: float = HORIZON_S,
                    white_below_s: float = WHITE_BELOW_S) -> dict:
    """The filter inputs of ``model``/``theta`` identified at sample interval dt (s) for
    a filter at IMU interval imu_dt (s); AR1s with τ < max(imu_dt, white_below_s) count as
    white measurement noise (listed in ``white_ar1``); see the module docstring."""
    blocks = {}
    ar1, wn, white_ar1 = [], 0.0, []
    for p, b in zip(model, P.split_theta(model, theta)):
        if p == "AR1" and P.tau_seconds(b[0], dt) < max(imu_dt, white_below_s):
            wn += b[1] / (1.0 - b[0]) ** 2
            white_ar1.append({"tau_s": P.tau_seconds(b[0], dt),
                              "white_sigma_per_sample": float(np.sqrt(b[1]) / (1.0 - b[0]))})
        elif p == "AR1":
            ar1.append(b)
        elif p == "WN":
            wn += b[0]
        else:
            blocks[p] = b
    white = wn * dt / imu_dt + 2.0 * blocks.get("QN", [0.0])[0]
    gamma2_rw = float(blocks["RW"][0]) if "RW" in blocks else 0.0
    gamma2 = gamma2_rw + sum(rw_overbound_of_ar1(b[0], b[1]) for b in ar1)
    source = " + ".join((["RW"] if "RW" in blocks else [])
                        + (["AR1 over-bound (000 eq. 4.8)"] if ar1 else [])) or "none"
    gm = []
    for phi, s2 in ar1:
        tau = P.tau_seconds(phi, dt)
        var = s2 / (1.0 - phi * phi)
        phi_r = float(np.exp(-imu_dt / tau)) if tau > 0 else 0.0
        gm.append({"tau_s": tau, "phi_at_imu_rate": phi_r, "stationary_sigma": float(np.sqrt(var)),
                   "driving_sigma_per_step": float(np.sqrt(var * (1.0 - phi_r ** 2)))})
    if not gm:
        state = None
    elif len(gm) == 1 and "RW" not in blocks:
        state = {"model": "gauss_markov", "tau_s": gm[0]["tau_s"],
                 "stationary_sigma": gm[0]["stationary_sigma"], "not_represented": [],
                 "over_bounded": []}
    else:
        state = gauss_markov_overbound([(float(b[0]), float(b[1])) for b in ar1], gamma2_rw,
                                       dt, imu_dt, horizon_s)
        state["not_represented"] = (["RW"] if "RW" in blocks else []) + ["AR1"] * (len(gm) - 1)
        state["over_bounded"] = ["AR1"] * len(gm) + (["RW"] if "RW" in blocks else [])
    return {"imu_dt_s": imu_dt, "sample_dt_s": dt, "measurement_sigma": float(np.sqrt(white)),
            "bias_drift_sigma_per_step": float(np.sqrt(gamma2 * imu_dt / dt)),
            "bias_drift_sigma_per_recipe_step": float(np.sqrt(gamma2 * RECIPE_STEP_S / dt)),
            "bias_drift_source": source, "gauss_markov": gm, "bias_state": state,
            "white_ar1": white_ar1, "white_below_s": float(white_below_s)}


SAMPLE_BOUND_MARGIN = 1.1   # a model σ this much above the samples' own spread is capped


def _within_block_variance(x, block: int) -> float:
    """Mean variance (ddof 1) of x inside consecutive blocks of ``block`` samples: the
    per-sample noise with the slow bias terms (drift over a block) left out."""
    x = np.asarray(x, dtype=float)
    n = (x.size // block) * block
    if n < 2 * block:
        return float(np.var(x, ddof=1))
    return float(np.mean(np.var(x[:n].reshape(-1, block), axis=1, ddof=1)))


def cap_to_sample_spread(noise: dict, signals, allan, dt: float, imu_dt: float,
                         block_s: float = 1.0) -> dict:
    """The measurement σ no larger than the data support. Two bounds, the larger taken:
    (a) the white part's: at τ = block_s the Allan variance is N²/τ plus non-negative
    terms, so N² ≤ AVAR(τ)·τ and the white σ at the IMU interval is at most
    √(AVAR(τ)·τ/δt) — the angle random walk the filter integrates; (b) the samples' own
    variance inside block_s blocks (quantisation 2Q² and short correlated noise included,
    the slow bias terms barely moving), rescaled to δt like the white part. Both are
    averaged over the replicates. A fit on scales from 0.16 s up (the leading scales
    dropped by the scale test) can extrapolate its QN far beyond both (ADIS16405 gyro z:
    0.909 deg/s against an ADEV(1 s) of 0.041 deg/s, i.e. 0.41 at 100 Hz; helper review
    2026-12-06): a σ more than SAMPLE_BOUND_MARGIN above the bound is capped at it, the
    fitted value kept as "measurement_sigma_fitted". allan: the replicates'
    calibration.allan.AllanVariance."""
    block = max(2, round(block_s / dt))
    spread2 = float(np.mean([_within_block_variance(x, block) for x in signals])) * dt / imu_dt
    white2 = float(np.mean([np.interp(np.log(block_s), np.log(av.tau_s), av.avar) * block_s
                            for av in allan])) / imu_dt
    bound = float(np.sqrt(max(spread2, white2)))
    out = dict(noise)
    out["measurement_sigma_data_bound"] = bound
    if noise["measurement_sigma"] > SAMPLE_BOUND_MARGIN * bound:
        out["measurement_sigma_fitted"] = noise["measurement_sigma"]
        out["measurement_sigma"] = bound
    return out


def noise_fragment(noise_by_axis: dict[str, dict], source: str) -> str:
    """A ``[noise]`` TOML table (recipe units: deg for gyros) for [paths].noise_override.
    A sensor whose three axes have a bias_state (filter_noise) gets the Gauss-Markov keys
    and its random-walk drift as a comment; otherwise the random-walk drift; every AR1 is
    listed in the comments."""
    def vec(kind, key, scale):
        return "[" + ", ".join(repr(float(noise_by_axis[f"{kind}_{a}"][key]) / scale)
                               for a in "xyz") + "]"

    kinds = [k for k in ("gyro", "accel") if all(f"{k}_{a}" in noise_by_axis for a in "xyz")]
    lines = [f"# IMU noise identified by gmis calibrate ({source});",
             "# vectors are the record's x, y, z axes — reorder if the recipe's body axes differ.",
             "[noise]"]
    for kind, white_key, drift_key, sigma_key, scale in (
            ("gyro", "gyro_deg_s", "gyro_bias_drift_deg_s", "gyro_bias_sigma_deg_s", DEG),
            ("accel", "accel_m_s2", "accel_bias_drift_m_s2", "accel_bias_sigma_m_s2", 1.0)):
        if kind not in kinds:
            continue
        lines.append(f"{white_key} = {vec(kind, 'measurement_sigma', scale)}")
        capped = [a for a in "xyz" if "measurement_sigma_fitted" in noise_by_axis[f"{kind}_{a}"]]
        if capped:
            lines.append(f"# {white_key} of axis {', '.join(capped)}: capped at the samples' "
                         "Allan variance at 1 s / own spread in 1-s blocks (the fit's "
                         "quantisation noise, extrapolated below its smallest scale, exceeded "
                         "it)")
        drift = (f"{drift_key} = {vec(kind, 'bias_drift_sigma_per_recipe_step', scale)}"
                 f"   # per step of {RECIPE_STEP_S:g} s, whatever the IMU rate")
        states = [noise_by_axis[f"{kind}_{a}"].get("bias_state") for a in "xyz"]
        if not all(states):
            lines.append(drift)
            continue
        tau = "[" + ", ".join(repr(float(b["tau_s"])) for b in states) + "]"
        sig = "[" + ", ".join(repr(float(b["stationary_sigma"]) / scale) for b in states) + "]"
        over = [b for b in states if b["over_bounded"]]
        lines += [f'{kind}_bias_model = "gauss_markov"   '
                  + ("# over-bound of each axis' AR1s + RW" if over else "# each axis' AR1"),
                  f"{kind}_bias_tau_s = {tau}", f"{sigma_key} = {sig}"]
        missing = sorted({p for b in states for p in b["not_represented"]})
        if missing:
            lines.append(f"# not represented by the Gauss-Markov bias state: "
                         f"{', '.join(missing)} of the selected model")
        if over:
            h = over[0]["horizon_s"]
            lines.append(f"# over-bounded instead: 2 sigma^2 (1 - exp(-h/tau)) >= the model's "
                         f"E[(b(t+h) - b(t))^2] for lags h <= {h:g} s (excess D_GM/D mean "
                         + "/".join(f"{b['overbound_mean']:.2f}" for b in over)
                         + "); beyond that horizon the RW outgrows it")
        lines.append(f"# random-walk alternative: {kind}_bias_model = \"random_walk\", "
                     f"{drift}")
    lines.append("# first-order Gauss-Markov biases at the IMU rate (tau_s, stationary sigma SI):")
    for axis, noise in noise_by_axis.items():
        for k, gm in enumerate(noise["gauss_markov"], 1):
            lines.append(f"#   {axis} GM{k}: tau_s = {gm['tau_s']:.6g}, stationary_sigma = "
                         f"{gm['stationary_sigma']:.6g}, driving_sigma_per_step = "
                         f"{gm['driving_sigma_per_step']:.6g}")
    return "\n".join(lines) + "\n"


def comparison_rows(axis_results: dict[str, dict], imu_dt: float, datasheet: dict | None,
                    vce: dict | None = None):
    """001 Tables 5-7/5-8 layout: rows (method), columns x/y/z, per sensor kind;
    equivalent white σ at the IMU rate (gyro deg/s, accel m/s²). vce: the IMU σ a
    `gmis vce` run tuned on a drive with the same sensor (datasheet.read_vce_noise;
    "n/a" without one)."""
    rows = []
    for kind, scale, unit in (("gyro", DEG, "deg/s"), ("accel", 1.0, "m/s^2")):
        axes = [f"{kind}_{a}" for a in "xyz" if f"{kind}_{a}" in axis_results]
        if not axes:
            continue
        if datasheet and kind in datasheet:
            spec = datasheet[kind]
            s = equivalent_white_sigma(spec.get("random_walk"), spec.get("bias_instability"),
                                       spec.get("quantization"), imu_dt) / scale
            rows.append([kind, "manufacturer specification", unit] + [s] * len(axes))
        allan = []
        for a in axes:
            f = axis_results[a]["allan"]
            allan.append(equivalent_white_sigma(
                f["random_walk"], f["bias_instability"], f["quantization"], imu_dt) / scale)
        rows.append([kind, "Allan variance", unit] + allan)
        # AWV: the averaged wavelet variance of several replicates; one file: plain GMWM
        label = "GMWM (AWV)" if "awv" in axis_results[axes[0]] else "GMWM"
        rows.append([kind, label, unit]
                    + [axis_results[a]["filter"]["measurement_sigma"] / scale for a in axes])
        if vce and kind in vce:
            rows.append([kind, "VCE on a drive", unit]
                        + [float(vce[kind]["xyz".index(a[-1])]) / scale for a in axes])
        else:
            rows.append([kind, "VCE on a drive", unit] + ["n/a"] * len(axes))
    return rows
