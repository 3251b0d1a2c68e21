"""summary.json of a `gmis run` (docs/formats.md): the run's figures (alignment,
rejections, stillness, outages, timing, warnings) and its errors against the reference."""

from __future__ import annotations

import math

import numpy as np


def run_summary(prep, totals, timing) -> dict:
    """summary.json of a run; totals: gmis.run_statistics.RecordTotals of its records."""
    from gmis.run_statistics import reopen_warning
    from gmis.state import I_HEADING
    recipe = prep.recipe
    n_imu = int((prep.epochs.imu >= 0).sum())
    duration = float(prep.dataset.imu.t[-1] - prep.dataset.imu.t[0])
    t_start, t_read, t_filter = timing
    summary = {
        "recipe": str(recipe.path),
        # the [noise] fragment (e.g. a `gmis vce` tuned_noise.toml) the recipe applies
        **({"noise_override": str(recipe.paths.noise_override)}
           if recipe.paths.noise_override is not None else {}),
        "dataset": recipe.dataset.name,
        "mode": recipe.filter.mode,
        "states": recipe.filter.states,
        "origin_lat_lon_h": [math.degrees(prep.frame[0]), math.degrees(prep.frame[1]),
                             float(prep.frame[2])],
        "epochs": len(prep.epochs),
        "imu_epochs": n_imu,
        "duration_s": duration,
        "alignment": {"pitch_deg": math.degrees(prep.alignment.pitch),
                      "roll_deg": math.degrees(prep.alignment.roll),
                      "heading_deg": math.degrees(prep.x0[I_HEADING]) % 360.0,
                      "gyro_bias_deg_s": np.degrees(prep.alignment.gyro_bias).tolist(),
                      "samples": prep.alignment.n_samples},
        "rejected_observations": totals.rejected_counts(),
        "stationary_epochs": int(prep.stationary.sum()),
        "gnss_samples_removed_by_outages": prep.gnss_removed,
        "gnss_outage_windows_gps_s": [list(w) for w in prep.outage_windows],
        "timing_s": {"read_and_prepare": t_read - t_start, "filter": t_filter - t_read,
                     "imu_epochs_per_s": n_imu / max(t_filter - t_read, 1e-9),
                     "real_time_ratio": duration / max(t_filter - t_read, 1e-9)},
        "warnings": list(prep.dataset.warnings),
    }
    summary.update(estimated_settings(prep))
    events = totals.reopen_events()
    summary["covariance_reopened"] = events
    new = [reopen_warning(events, duration)] + totals.consistency_warnings(
        prep.config.outlier_alpha)
    new = [w for w in new if w is not None]
    if new:
        from gmis.plausibility import announce
        summary["warnings"].extend(new)
        announce(new)
    return summary


def estimated_settings(prep) -> dict:
    """The settings the preparation estimated from the data, as summary.json entries:
    "nonholonomic_lever_arm" (gmis.nhc_offset_estimation), "gnss_time_offset"
    (gmis.latency_estimation), "gnss_velocity_time_offset" (gmis.gnss_velocity_lag)."""
    out = {}
    gnss = prep.recipe.gnss
    if prep.nhc_offset is not None:
        out["nonholonomic_lever_arm"] = prep.nhc_offset.summary()
    if prep.gnss_time_offset is not None:
        out["gnss_time_offset"] = prep.gnss_time_offset.summary(
            gnss.time_offset_s - prep.gnss_time_offset.offset_s)
    if prep.gnss_velocity_lag is not None:
        out["gnss_velocity_time_offset"] = prep.gnss_velocity_lag.summary(
            gnss.velocity_time_offset_s)
    return out


def error_summaries(summary, errs, t, gnss_fix, skip_s, tight: bool):
    """The summary's error figures; gnss_fix: (E,) bool, or the position RowIndex."""
    from gmis.run_statistics import recently_fixed_rows, summarize_errors

    summary["errors_vs_reference"] = summarize_errors(errs, skip_s=skip_s)
    aided = recently_fixed_rows(errs, t, gnss_fix, 1.0)
    summary["errors_vs_reference_gnss_aided"] = summarize_errors(errs, skip_s, aided)
    summary["errors_vs_reference_gnss_aided"]["definition"] = (
        "epochs at most 1 s after a DD update with ≥ 5 satellites" if tight
        else "epochs at most 1 s after a GNSS position update (outages excluded)")


__all__ = ["error_summaries", "run_summary"]
