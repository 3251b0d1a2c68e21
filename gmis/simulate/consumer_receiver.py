"""A consumer receiver's own filtered fix for a simulated dataset (issue 20 item 6): the
GNSS file of gmis.simulate.simulate_scenario replaced by one that a u-blox-like unit
would log — position with time-correlated errors, speed over ground and course instead
of an ENU velocity, time stamps late by a latency, no heading stream.

Per ENU axis the fix error is a first-order Gauss-Markov process (the model of
gmis.gnss_error_states) sampled exactly at the fix epochs,
    b_0 ~ N(0, σ_b²),  b_{k+1} = φ_k b_k + σ_b √(1 − φ_k²) ε_k,  φ_k = e^{−Δt_k/τ},
plus white noise of σ_w (the per-epoch σ written in the file). Speed and course are the
true antenna speed and course (gmis.speed_course.speed_course_from_enu) plus white noise
σ_s, σ_χ. Every row is stamped t + latency_s (the receiver reports late). Reproducible
from the seed (numpy default_rng).
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass

import numpy as np

from gmis.earth import make_nav_frame
from gmis.simulate.trajectory import enu_to_geodetic_many
from gmis.simulate.writer import dump_toml, write_csv
from gmis.speed_course import speed_course_from_enu

RAD2DEG = 180.0 / np.pi
HEADER = ("time_gps_s,lat_deg,lon_deg,h_m,sigma_e_m,sigma_n_m,sigma_u_m,speed_m_s,course_deg,"
          "sigma_speed_m_s,sigma_course_deg")


@dataclass(frozen=True)
class ConsumerReceiver:
    """Error model of the receiver's fixes (σ m, τ s, latency s, speed m/s, course deg)."""

    error_sigma_m: tuple = (1.5, 1.5, 1.5)
    error_tau_s: float = 5.0
    white_sigma_m: tuple = (0.1, 0.1, 0.2)
    latency_s: float = 0.1
    speed_sigma_m_s: float = 0.1
    course_sigma_deg: float = 0.5


def gauss_markov_errors(t, sigma, tau, rng):
    """(M, 3) exact samples at times t (s) of three independent stationary first-order
    Gauss-Markov processes with 1σ sigma (3,) and correlation time tau (s)."""
    sigma = np.asarray(sigma, float)
    out = np.empty((t.size, 3))
    out[0] = rng.standard_normal(3) * sigma
    phi = np.exp(-np.diff(t) / tau)
    eps = rng.standard_normal((t.size - 1, 3))
    for k in range(t.size - 1):
        out[k + 1] = phi[k] * out[k] + sigma * np.sqrt(1.0 - phi[k] ** 2) * eps[k]
    return out


def write_consumer_receiver(sim, model: ConsumerReceiver, seed: int, recipe_gnss=None):
    """Rewrite gnss.csv and recipe.toml of the simulated dataset ``sim``
    (gmis.simulate.SimulationResult): the receiver's fixes (module doc), the heading
    stream dropped, [gnss] = recipe_gnss (dict of keys, e.g. the error model) or none.
    Returns the truth: {"t_true", "error_enu", "speed_noise", "course_noise"}."""
    tr = sim.truth
    rng = np.random.default_rng(seed)
    t_true = np.asarray(tr.gnss_time_gps_s, float)
    r_true = np.asarray(tr.gnss_true_r_enu, float)
    v_true = np.asarray(tr.gnss_true_v_enu, float)
    err = gauss_markov_errors(t_true, model.error_sigma_m, model.error_tau_s, rng)
    err += rng.standard_normal(err.shape) * np.asarray(model.white_sigma_m, float)
    speed, course = speed_course_from_enu(v_true)
    n_s = rng.standard_normal(t_true.size) * model.speed_sigma_m_s
    n_c = rng.standard_normal(t_true.size) * np.radians(model.course_sigma_deg)
    frame = make_nav_frame(*np.asarray(tr.origin_llh, float))
    llh = enu_to_geodetic_many(frame, r_true + err)
    ones = np.ones(t_true.size)
    folder = sim.dataset_dir
    write_csv(os.path.join(folder, "gnss.csv"), HEADER,
              [t_true + model.latency_s, llh[:, 0] * RAD2DEG, llh[:, 1] * RAD2DEG, llh[:, 2],
               *(ones[None, :] * np.asarray(model.white_sigma_m, float)[:, None]),
               np.abs(speed + n_s), np.mod(course + n_c, 2 * np.pi) * RAD2DEG,
               ones * model.speed_sigma_m_s, ones * model.course_sigma_deg],
              ["%.6f", "%.11f", "%.11f", "%.5f"] + ["%.5g"] * 3 + ["%.5f", "%.5f"]
              + ["%.5g"] * 2)
    with open(sim.recipe_path, "rb") as fh:
        recipe = tomllib.load(fh)
    recipe["paths"].pop("heading", None)
    recipe["antennas"].pop("secondary_lever_arm_m", None)
    for key in ("heading_deg", "gnss_position_m", "gnss_velocity_m_s"):
        recipe["noise"].pop(key, None)
    if recipe_gnss:
        recipe["gnss"] = dict(recipe_gnss)
    with open(sim.recipe_path, "w") as fh:
        fh.write(dump_toml(recipe))
    return {"t_true": t_true, "error_enu": err, "speed_noise": n_s, "course_noise": n_c}
