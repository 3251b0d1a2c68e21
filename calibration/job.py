"""The ``gmis calibrate`` command's work: static records → calibration folder.

Per axis: each replicate's WV (classical, or robust with ``robust=True``) and Allan line
fits; the AWV ν̄ (004 Algorithm 1; SR-AWV when robust, DR-AWV with ``trim`` > 0); model
selection over the nested models of ``largest`` on ν̄ (000 eq. 3.22); the selected model
fitted to ν̄ (AWV) and to every replicate, the AGMWM and the between-replicate spread; the
filter inputs at the IMU rate. Written all-or-nothing (gmis.results.results_directory):
calibration.json, noise_fragment.toml, model_selection.csv, comparison.csv, figures/*.png.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calibration import allan as A
from calibration import figures
from calibration import filter_inputs as F
from calibration import processes as P
from calibration.despike import despike as despike_signal
from calibration.despike import despiked_wavelet_variance
from calibration.gmwm import fit_gmwm
from calibration.model_selection import choose, select_model
from calibration.multisignal import average_wv, multi_signal
from calibration.records import SI_UNIT, read_static_record
from calibration.robust import robust_wavelet_variance
from calibration.scale_selection import choose_smallest_scale
from calibration.wavelet_variance import wavelet_variance
from gmis.errors import GmisInputError

DEFAULT_LARGEST = "WN+QN+3*AR1+RW"
PER_SQRT_S_TO_PER_SQRT_H = 60.0  # N in u/s·√s = u/√s → u/√h
DISPLAY = {"gyro": (180.0 / np.pi, "deg/s", "deg/sqrt(h)"), "accel": (1.0, "m/s^2", "m/s/sqrt(h)")}


def _fit_dict(fit) -> dict:
    return {"model": fit.name, "objective": fit.objective, "se_method": fit.se_method,
            "tau_range_s": [float(fit.wv.tau_s[0]), float(fit.wv.tau_s[-1])],
            "processes": fit.processes()}


def _allan_dict(fits) -> dict:
    return {k: (None if v is None else v.coefficient) for k, v in fits.items()} | {
        "tau_range_s": {k: (None if v is None else list(v.tau_range_s))
                        for k, v in fits.items()}}


STATIC_BLOCK_S = 10.0
STATIC_ACCEL_CHANGE_M_S2 = 0.3    # block means of |f| further apart than this: moving
STATIC_GYRO_RATE_RAD_S = float(np.radians(2.0))   # a block-mean rate above this: turning


def not_static(record) -> str | None:
    """A warning when a record does not look static (Allan / GMWM model a sensor at rest:
    motion in the record becomes "noise"): the 10-s block means of the specific-force norm
    spread by more than 0.3 m/s², or a block-mean angular rate above 2°/s. None when it
    looks static or has not both sensors' three axes."""
    ax = record.axes
    block = max(2, round(STATIC_BLOCK_S / record.dt))
    n = (record.n // block) * block
    if n < 2 * block:
        return None
    why = []
    if all(f"accel_{a}" in ax for a in "xyz"):
        norm = np.sqrt(sum(np.asarray(ax[f"accel_{a}"][:n], float) ** 2 for a in "xyz"))
        means = norm.reshape(-1, block).mean(axis=1)
        if np.ptp(means) > STATIC_ACCEL_CHANGE_M_S2:
            why.append(f"its 10-s mean specific force varies by {np.ptp(means):.2f} m/s^2")
    if all(f"gyro_{a}" in ax for a in "xyz"):
        rate = np.sqrt(sum(np.asarray(ax[f"gyro_{a}"][:n], float).reshape(-1, block)
                           .mean(axis=1) ** 2 for a in "xyz"))
        if rate.max() > STATIC_GYRO_RATE_RAD_S:
            why.append(f"its 10-s mean angular rate reaches {np.degrees(rate.max()):.1f} deg/s")
    if not why:
        return None
    return (f"{record.path}: not a static record ({'; '.join(why)}): the Allan / GMWM noise "
            "model of a moving sensor takes its motion for noise")


def calibrate(files, out_dir, largest: str = DEFAULT_LARGEST, robust: bool = False,
              trim: float = 0.0, imu_rate_hz: float | None = None,
              rate_hz: float | None = None, datasheet: dict | None = None,
              select: bool = True, axes=None, figure_axes=None, progress=None,
              vce=None, despike: bool = False, horizon_s: float = F.HORIZON_S,
              min_scale_s: float | None = None, auto_scale: bool = True) -> dict:
    """Calibrate the axes of one or several static replicates; returns the summary.
    vce: the comparison table's VCE row, a gmis vce [noise] fragment (path) or
    datasheet.read_vce_noise's dict. despike: replace isolated spikes by their neighbours'
    median before the WVs and Allan variances, and subtract the replacement's own WV bias
    (calibration.despike; the count per replicate is in calibration.json). horizon_s: the lags (s, the drive's duration) on
    which a Gauss-Markov bias state over-bounds an AR1+RW model (filter_inputs).
    min_scale_s: fit only the scales τ ≥ this (000 §4.2 removes scales the process set
    cannot describe, e.g. shaped by the sensor's own decimation filter); without it and
    with auto_scale the leading scales are dropped by calibration.scale_selection's F test
    on the AWV with the largest model (the tests per axis are in calibration.json)."""
    from gmis.results import results_directory, write_json

    try:
        largest_model = P.parse_model(largest)
    except ValueError as exc:
        raise GmisInputError(str(exc), source="--model") from None
    if not 0.0 <= trim < 0.5:
        raise GmisInputError(f"must be in [0, 0.5), got {trim}", source="--trim")
    if not files:
        raise GmisInputError("no input file", source="calibrate")
    if imu_rate_hz is not None and not imu_rate_hz > 0:
        raise GmisInputError(f"must be > 0, got {imu_rate_hz}", source="--imu-rate")
    if isinstance(vce, (str, Path)):
        from calibration.datasheet import read_vce_noise

        vce = read_vce_noise(vce)
    if isinstance(datasheet, (str, Path)):
        from calibration.datasheet import read_datasheet

        datasheet = read_datasheet(datasheet)
    records = []
    for i, f in enumerate(files):
        records.append(read_static_record(f, rate_hz))
        _report(progress, 0.15 * (i + 1) / len(files))
    moving = [w for w in (not_static(r) for r in records) if w]
    if moving:
        from gmis.plausibility import announce
        announce(moving)
    dt = records[0].dt
    for r in records[1:]:
        if abs(r.dt / dt - 1.0) > 1e-6:
            raise GmisInputError(f"sample interval {r.dt:g} s differs from the first file's "
                                 f"{dt:g} s", source=r.path)
    common = [a for a in records[0].axes if all(a in r.axes for r in records)]
    if axes:
        missing = [a for a in axes if a not in common]
        if missing:
            raise GmisInputError(f"axis {missing[0]!r} not in every file; have "
                                 + ", ".join(common), source="--axes")
        common = list(axes)
    imu_dt = 1.0 / imu_rate_hz if imu_rate_hz else dt
    if not horizon_s > imu_dt:
        raise GmisInputError(f"must exceed the IMU interval {imu_dt:g} s, got {horizon_s:g}",
                             source="--horizon")
    estimate = robust_wavelet_variance if robust else wavelet_variance
    results, selection_rows, figs_todo = {}, [], []
    for k, axis in enumerate(common):
        kind = axis.split("_")[0]
        signals = [r.axes[axis] for r in records]
        replaced = None
        if despike:
            done = [despiked_wavelet_variance(x, dt, estimate) for x in signals]
            wvs, replaced = [d[0] for d in done], [d[1] for d in done]
            signals = [despike_signal(x)[0] for x in signals]  # for the Allan variances
        else:
            wvs = [estimate(x, dt) for x in signals]
        if min_scale_s is not None:
            wvs = [w.select(w.tau_s >= min_scale_s * (1.0 - 1e-9)) for w in wvs]
            if wvs[0].tau.size < 2:
                raise GmisInputError(f"leaves {wvs[0].tau.size} scale(s)", source="--min-scale")
        avs = [A.allan_variance(x, dt) for x in signals]
        allan_fits = [A.line_fits_of(av) for av in avs]
        bar = average_wv(wvs, trim) if len(wvs) > 1 else wvs[0]
        scale_tests, excluded = None, None
        if min_scale_s is None and auto_scale:
            dropped, scale_tests, _ = choose_smallest_scale(bar, largest_model)
            if dropped:
                excluded = bar.select(np.arange(dropped))
                wvs = [w.select(np.arange(dropped, w.tau.size)) for w in wvs]
                bar = average_wv(wvs, trim) if len(wvs) > 1 else wvs[0]
            scale_tests = [t.as_dict() for t in scale_tests]
        if select:
            table = select_model(bar, largest_model)
            chosen, note = choose(table, bar)
            model = P.parse_model(chosen.model)
            selection_rows += [[axis, i + 1, row.model, row.n_params, row.objective,
                                row.penalty, row.wvic] for i, row in enumerate(table)]
        else:
            model, note = largest_model, ""
        if len(wvs) > 1:
            ms = multi_signal(wvs, model, trim=trim)
            fit, rep_fits = ms.awv, ms.replicate_fits
            extra = {"agmwm_theta": ms.agmwm_theta.tolist(),
                     "between_replicate_sd": ms.spread.tolist(), "method": ms.method}
        else:
            fit = fit_gmwm(bar, model)
            rep_fits, extra = [fit], {"method": "RGMWM" if robust else "GMWM"}
        noise = F.cap_to_sample_spread(F.filter_noise(fit, imu_dt, horizon_s), signals, avs,
                                       dt, imu_dt)
        results[axis] = {
            "unit": SI_UNIT[kind], "selected_model": fit.name, "selection_note": note,
            "parameter_labels": fit.labels,
            "awv" if len(wvs) > 1 else "fit": _fit_dict(fit),
            "replicates": [{"file": r.path, "fit": _fit_dict(f),
                            "allan": _allan_dict(a)} for r, f, a in
                           zip(records, rep_fits, allan_fits)],
            "allan": {name: _mean_coef(allan_fits, name) for name in
                      ("quantization", "random_walk", "bias_instability",
                       "rate_random_walk", "rate_ramp")},
            # how many replicates each Allan mean averages (a line fit needs its slope
            # region in the record: not every replicate has every one)
            "allan_replicates_used": {name: sum(f.get(name) is not None for f in allan_fits)
                                      for name in ("quantization", "random_walk",
                                                   "bias_instability", "rate_random_walk",
                                                   "rate_ramp")},
            "filter": noise, "despiked_samples": replaced, "scale_tests": scale_tests,
            **extra}
        figs_todo.append((axis, kind, wvs, bar, fit, avs, allan_fits[0], excluded))
        _report(progress, 0.15 + 0.8 * (k + 1) / len(common))
    fragment = F.noise_fragment({a: r["filter"] for a, r in results.items()},
                                f"{len(records)} replicate(s), {results[common[0]].get('method')}")
    comparison = F.comparison_rows(results, imu_dt, datasheet, vce)
    summary = {"files": [r.path for r in records], "sample_interval_s": dt,
               "imu_interval_s": imu_dt, "samples": [r.n for r in records],
               "estimator": "robust WV (biweight)" if robust else "classical MODWT WV",
               "largest_model": P.model_name(largest_model), "bias_horizon_s": horizon_s,
               "min_scale_s": min_scale_s,
               "scale_selection": ("given (--min-scale)" if min_scale_s is not None else
                                   "F test" if auto_scale else "all scales"),
               "axes": results}
    with results_directory(out_dir) as tmp:
        write_json(tmp / "calibration.json", summary)
        (tmp / "noise_fragment.toml").write_text(fragment)
        _write_rows(tmp / "model_selection.csv",
                    ["axis", "rank", "model", "n_params", "objective", "penalty", "wvic"],
                    selection_rows)
        _write_rows(tmp / "comparison.csv", ["sensor", "method", "unit", "x", "y", "z"],
                    comparison)
        fig_dir = tmp / "figures"
        fig_dir.mkdir()
        for axis, kind, wvs, bar, fit, avs, af, excluded in figs_todo:
            if figure_axes is not None and axis not in figure_axes:
                continue
            unit = SI_UNIT[kind]
            figures.wv_figure(fig_dir / f"{axis}_wv.png", axis, unit, fit,
                              "AWV fit" if len(wvs) > 1 else "GMWM fit", excluded)
            figures.adev_figure(fig_dir / f"{axis}_adev.png", axis, unit, avs, af)
            if len(wvs) > 1:
                figures.overlay_figure(fig_dir / f"{axis}_replicates.png", axis, unit, wvs,
                                       bar, fit)
    _report(progress, 1.0)
    return {a: _axis_summary(a, r) for a, r in results.items()}


def _axis_summary(axis: str, r: dict) -> dict:
    scale, unit, rw_unit = DISPLAY[axis.split("_")[0]]
    dt = r["filter"]["sample_dt_s"]
    fast = max(r["filter"]["imu_dt_s"], r["filter"]["white_below_s"])
    # the white part's spectral density at f = 0 (the random walk it integrates to): the
    # WN and every AR1 the filter counts as white (τ below max(IMU interval,
    # white_below_s); S_AR1(0) = ξ²/(1−φ)²); quantisation noise has S(0) = 0
    white = sum(p["sigma2"] if p["process"] == "WN" else p["sigma2"] / (1.0 - p["phi"]) ** 2
                for p in r["awv" if "awv" in r else "fit"]["processes"]
                if p["process"] == "WN" or (p["process"] == "AR1" and p["tau_s"] < fast))
    out = {"model": r["selected_model"],
           "sigma_at_imu_rate": r["filter"]["measurement_sigma"] * scale,
           "allan_random_walk": (r["allan"]["random_walk"] or np.nan) * scale
           * PER_SQRT_S_TO_PER_SQRT_H}
    if white > 0.0:
        out["gmwm_random_walk"] = float(np.sqrt(white * dt) * scale * PER_SQRT_S_TO_PER_SQRT_H)
    out["unit"] = f"sigma {unit}, random walks {rw_unit}"
    return out


def _mean_coef(fits, name):
    vals = [f[name].coefficient for f in fits if f.get(name) is not None]
    return float(np.mean(vals)) if vals else None


def _write_rows(path: Path, header, rows) -> None:
    with open(path, "w") as fh:
        fh.write(",".join(header) + "\n")
        fh.writelines(",".join(f"{v:.8g}" if isinstance(v, float) else str(v) for v in row)
                     + "\n" for row in rows)


def _report(progress, fraction):
    if progress is not None:
        progress(fraction)
