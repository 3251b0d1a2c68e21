"""Navigation-solution figures of a `gmis run` folder: trajectory top view, speed, 1σ of
position/velocity/attitude, IMU biases and scale factors with ±3σ envelopes, and errors
against the reference with the filter's ±3σ envelopes (when errors.csv exists).

Units on the figures: m, m/s, deg, deg/s, m/s², ppm (scale factors); the state itself is
SI/rad (gmis.state: b_ω at 15:18, b_a at 18:21, S_ω at 21:24, S_a at 24:27).
"""

from __future__ import annotations

import math

import numpy as np

from gmis.report.plotting import (
    AXIS_COLORS,
    MAX_POINTS,
    FigureFile,
    fill_decimated,
    new_figure,
    plot_decimated,
    saved_figure,
    subplot_grid,
    time_axis,
    time_label,
)
from gmis.state import BA, BG, SA, SG

DEG = 180.0 / math.pi
ENU = ("E", "N", "U")
ATT = ("pitch", "roll", "heading")
XYZ = ("x", "y", "z")


def trajectory_figure(run, out_dir, formats) -> FigureFile:
    enu = run.solution["enu"]
    step = max(1, enu.shape[0] // (4 * MAX_POINTS))
    fig = new_figure(6.0, 5.2)
    ax = subplot_grid(fig, 1, 1, left=0.8, bottom=0.5, top=0.35, right=0.2)[0, 0]
    ax.plot(enu[::step, 0], enu[::step, 1], color="tab:blue", linewidth=0.8, label="GMIKF")
    ax.plot(enu[0, 0], enu[0, 1], "o", color="tab:green", label="start")
    ax.plot(enu[-1, 0], enu[-1, 1], "s", color="tab:red", label="end")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.legend()
    ax.set_title("Trajectory, top view (ENU at the origin of the run)")
    return saved_figure(fig, out_dir, formats, "trajectory", "Trajectory (top view)",
                        "Estimated horizontal trajectory, East vs North (m) in the local ENU "
                        "frame of the run; equal axis scales.", "solution")


def speed_figure(run, out_dir, formats) -> FigureFile:
    sol = run.solution
    t0 = float(sol["t"][0])
    ts = time_axis(sol["t"], t0)
    v = sol["vel_enu"]
    fig = new_figure(7.5, 2.8)
    ax = subplot_grid(fig, 1, 1, left=0.6, right=0.6, top=0.3, bottom=0.5)[0, 0]
    plot_decimated(ax, ts, np.hypot(v[:, 0], v[:, 1]), color="tab:blue",
                   label="horizontal speed")
    plot_decimated(ax, ts, v[:, 2], color="tab:orange", label="vertical velocity v_U")
    ax.set_xlabel(time_label(t0))
    ax.set_ylabel("speed (m/s)")
    sec = ax.secondary_yaxis("right", functions=(lambda s: s * 3.6, lambda k: k / 3.6))
    sec.set_ylabel("(km/h)")
    ax.legend(loc="upper left")
    ax.set_title("Speed")
    return saved_figure(fig, out_dir, formats, "speed", "Speed",
                        "Horizontal speed √(v_E² + v_N²) and vertical velocity v_U (m/s; right "
                        "axis km/h) vs time (s).", "solution")


def sigma_figure(run, out_dir, formats) -> FigureFile:
    sol = run.solution
    t0 = float(sol["t"][0])
    ts = time_axis(sol["t"], t0)
    fig = new_figure(7.5, 6.0)
    axes = subplot_grid(fig, 3, 1, left=0.75, top=0.4, bottom=0.5, hgap=0.12,
                        sharex=True)[:, 0]
    for ax, (key, names, scale, unit, title) in zip(axes, (
            ("enu_sd", ENU, 1.0, "m", "position"), ("vel_enu_sd", ENU, 1.0, "m/s", "velocity"),
            ("euler_sd", ATT, DEG, "deg", "attitude"))):
        for i, name in enumerate(names):
            plot_decimated(ax, ts, sol[key][:, i] * scale, color=AXIS_COLORS[i], label=name)
        ax.set_yscale("log")
        ax.set_ylabel(f"{title} 1σ ({unit})")
        ax.legend(ncol=3, loc="upper right")
    axes[-1].set_xlabel(time_label(t0))
    fig.suptitle("Estimated 1σ: position (ENU), velocity (ENU), attitude")
    return saved_figure(fig, out_dir, formats, "solution_sigma",
                        "Position, velocity and attitude 1σ",
                        "Filter standard deviations vs time (s): ENU position (m), ENU velocity "
                        "(m/s, eq. 4.1.31), pitch/roll/heading (deg); log scale.", "solution")


def _state_panels(ax, ts, x, sd, scale, label):
    fill_decimated(ax, ts, (x - 3 * sd) * scale, (x + 3 * sd) * scale, color="tab:blue",
                   alpha=0.25, linewidth=0, label="±3σ")
    plot_decimated(ax, ts, x * scale, color="tab:blue", label=label)


def sensor_error_figure(run, out_dir, formats) -> list:
    """Gyro/accelerometer biases and (27-state) scale factors with ±3σ envelopes."""
    sol = run.solution
    x, sd = sol["x"], sol["sd"]
    t0 = float(sol["t"][0])
    ts = time_axis(sol["t"], t0)
    groups = [("imu_biases", "IMU biases", ((BG, "gyro bias b_ω", "deg/s", DEG),
                                            (BA, "accel bias b_a", "m/s²", 1.0)))]
    if x.shape[1] >= 27:
        groups.append(("imu_scale_factors", "IMU scale factors",
                       ((SG, "gyro scale factor S_ω", "ppm", 1e6),
                        (SA, "accel scale factor S_a", "ppm", 1e6))))
    figures = []
    for stem, title, rows in groups:
        fig = new_figure(7.5, 4.6)
        axes = subplot_grid(fig, 2, 3, left=0.75, top=0.5, bottom=0.5, hgap=0.35, wgap=0.85,
                            sharex=True)
        for r, (sl, name, unit, scale) in enumerate(rows):
            for c in range(3):
                ax = axes[r, c]
                k = sl.start + c
                _state_panels(ax, ts, x[:, k], sd[:, k], scale, "estimate")
                ax.set_title(f"{name}, {XYZ[c]}")
                ax.set_ylabel(f"({unit})")
            axes[r, 0].legend(loc="upper right")
        for ax in axes[-1]:
            ax.set_xlabel("time since start (s)")
        fig.suptitle(f"{title} with ±3σ envelopes (start = {t0:.2f} s GPS)")
        units = ", ".join(f"{name} ({unit})" for _, name, unit, _ in rows)
        figures.append(saved_figure(fig, out_dir, formats, stem, title,
                                    f"Estimated {units} per body axis (x right, y forward, z up) "
                                    "vs time (s), shaded ±3σ from the filter covariance.",
                                    "solution"))
    return figures


def error_figure(run, out_dir, formats) -> FigureFile | None:
    """Errors vs reference (errors.csv) with the filter's ±3σ interpolated to those times."""
    err = run.errors
    if err is None or err["time_gps_s"].size == 0:
        return None
    sol = run.solution
    t = err["time_gps_s"]
    t0 = float(sol["t"][0])
    ts = time_axis(t, t0)
    fig = new_figure(7.5, 6.6)
    axes = subplot_grid(fig, 3, 3, left=0.75, top=0.5, bottom=0.5, hgap=0.35, wgap=0.85,
                        sharex=True)
    rows = (("d{}_m", ("e", "n", "u"), "enu_sd", 1.0, "position error", "m"),
            ("d{}_m_s", ("ve", "vn", "vu"), "vel_enu_sd", 1.0, "velocity error", "m/s"),
            ("d{}_deg", ("pitch", "roll", "heading"), "euler_sd", DEG, "attitude error", "deg"))
    for r, (fmt, cols, sd_key, scale, name, unit) in enumerate(rows):
        for c, col in enumerate(cols):
            ax = axes[r, c]
            sd = np.interp(t, sol["t"], sol[sd_key][:, c]) * scale
            fill_decimated(ax, ts, -3 * sd, 3 * sd, color="0.6", alpha=0.4, linewidth=0,
                           label="±3σ")
            e = err[fmt.format(col)]
            plot_decimated(ax, ts, e, color=AXIS_COLORS[c], label="error")
            span = max(np.nanmax(np.abs(e)), np.nanpercentile(3 * sd, 95))
            if np.isfinite(span) and span > 0:
                ax.set_ylim(-1.25 * span, 1.25 * span)
            axis = (ENU if r < 2 else ATT)[c]
            ax.set_title(f"{name}, {axis}")
            ax.set_ylabel(f"({unit})")
        axes[r, 0].legend(loc="upper right")
    for ax in axes[-1]:
        ax.set_xlabel("time since start (s)")
    fig.suptitle(f"Errors against the reference with the filter's ±3σ (start = {t0:.2f} s GPS)")
    return saved_figure(fig, out_dir, formats, "errors_vs_reference",
                        "Errors against the reference",
                        "Solution minus reference: ENU position (m), ENU velocity (m/s), pitch/"
                        "roll/heading (deg) vs time (s); shaded: ±3σ of the filter covariance. "
                        "The y-range covers the whole error and the 95th percentile of 3σ (3σ "
                        "may exceed it during GNSS outages).", "solution")
