"""simulate_scenario: scenario → dataset folder (docs/formats.md) + recipe + truth."""

import os
import shutil
from dataclasses import dataclass

import numpy as np

from gmis.errors import GmisInputError
from gmis.run_filter import GmikfConfig
from gmis.simulate.scenario import load_scenario, validate_scenario
from gmis.simulate.sensors import DEG, simulate_gnss, simulate_heading, simulate_imu
from gmis.simulate.trajectory import simulate_trajectory
from gmis.simulate.writer import (
    GNSS_HEADER,
    HEADING_HEADER,
    IMU_HEADER,
    RAD2DEG,
    REFERENCE_HEADER,
    commit_output_dir,
    dump_toml,
    prepare_output_dir,
    write_csv,
)

RNG_STREAMS = ("dynamics", "imu_bias", "imu_noise", "gnss", "heading")
POSITIVE_FLOOR = 1e-9  # the recipe needs σ > 0; a noise-free channel is written as this


@dataclass
class SimulationTruth:
    """Every true array of a run, as stored in truth.npz (keys = attribute names)."""
    arrays: dict

    def __getattr__(self, name):
        try:
            return self.__dict__["arrays"][name]
        except KeyError:
            raise AttributeError(name) from None


@dataclass
class SimulationResult:
    dataset_dir: str
    recipe_path: str
    truth: SimulationTruth
    scenario: dict


def _rngs(seed):
    children = np.random.SeedSequence(seed).spawn(len(RNG_STREAMS))
    return {name: np.random.Generator(np.random.PCG64(c)) for name, c in
            zip(RNG_STREAMS, children)}


def _random_process_sigmas(scenario):
    """Step-weighted RMS of the random segments' per-step σ (jerk m/s³, ang. acc. °/s²)."""
    segs = [s for s in scenario["segment"] if s["type"] == "random"]
    if not segs:
        return None, None
    w = np.array([s["duration_s"] for s in segs])
    jerk = np.sqrt(np.average(np.array([s["sigma_jerk_m_s3"] for s in segs]) ** 2, axis=0,
                              weights=w))
    ang = np.sqrt(np.average(np.array([s["sigma_angacc_deg_s2"] for s in segs]) ** 2, axis=0,
                             weights=w))
    return jerk, ang


def _gauss_markov_noise(m, noise):
    """A sensor whose three axes have a Gauss-Markov drift and no random walk gets the
    recipe's Gauss-Markov bias model with the true τ and stationary σ (noise updated in
    place, its random-walk drift removed); returns the sensors done."""
    done = []
    for kind, sigma, tau, rw, key, scale in (
            ("gyro", m.gyro_gm_sigma, m.gyro_gm_tau, m.gyro_rw_sigma, "gyro_bias_sigma_deg_s",
             RAD2DEG),
            ("accel", m.accel_gm_sigma, m.accel_gm_tau, m.accel_rw_sigma,
             "accel_bias_sigma_m_s2", 1.0)):
        if np.all(sigma > 0) and not np.any(rw):
            noise.pop(f"{kind}_bias_drift_{'deg_s' if kind == 'gyro' else 'm_s2'}")
            noise[f"{kind}_bias_model"] = "gauss_markov"
            noise[f"{kind}_bias_tau_s"] = [float(x) for x in tau]
            noise[key] = [float(x) * scale for x in sigma]
            done.append(kind)
    return done


def build_recipe(scenario, imu_sim, truth_arrays, raw_gnss=None):
    sc, origin = scenario["scenario"], scenario["origin"]
    m = imu_sim.model
    floored = []

    def pos(key, values):
        values = np.atleast_1d(np.asarray(values, float))
        if np.any(values <= 0.0):
            floored.append(key)
            values = np.maximum(values, POSITIVE_FLOOR)
        out = [float(v) for v in values]
        return out if len(out) > 1 else out[0]

    gyro_equiv = np.sqrt(m.gyro_white_sigma ** 2 + m.gyro_quant ** 2 / 12.0)
    accel_equiv = np.sqrt(m.accel_white_sigma ** 2 + m.accel_quant ** 2 / 12.0)
    # the recipe's drifts are 1σ per step of 1/q_rate_hz (100 Hz, 001 Table 6-2), whatever
    # the IMU rate; the simulated random walk steps at the IMU rate (σ_rw = BS √(δt/T))
    to_q_step = np.sqrt(sc["imu_rate_hz"] / GmikfConfig.q_rate_hz)
    noise = {}
    jerk, ang = _random_process_sigmas(scenario)
    if jerk is not None:
        # the random segments hold a N(0, σ²) jerk / angular acceleration over each IMU
        # step δt (spectral density σ² δt); the recipe's σ is per step of 1/q_rate_hz, as
        # the GMIKF reads it (GmikfConfig.q_psd: q = σ_q² / q_rate_hz): σ_q = σ / to_q_step
        # (the same at 100 Hz; at 200 Hz the per-step σ written unconverted gave the
        # filter twice the true jerk density: NEES of a^b and ω 0.74-0.77)
        noise["jerk_m_s3"] = pos("jerk_m_s3", jerk / to_q_step)
        noise["angular_acceleration_deg_s2"] = pos("angular_acceleration_deg_s2",
                                                   ang / to_q_step)
    noise.update({
        "gyro_deg_s": pos("gyro_deg_s", gyro_equiv * RAD2DEG),
        "accel_m_s2": pos("accel_m_s2", accel_equiv),
        "gyro_bias_drift_deg_s": [float(x) for x in m.gyro_rw_sigma * to_q_step * RAD2DEG],
        "accel_bias_drift_m_s2": [float(x) for x in m.accel_rw_sigma * to_q_step],
        "gyro_scale_drift": [0.0, 0.0, 0.0],
        "accel_scale_drift": [0.0, 0.0, 0.0],
        "heading_deg": pos("heading_deg", scenario["heading"]["sigma_deg"]),
        "gnss_position_m": pos("gnss_position_m", scenario["gnss"]["position_sigma_m"]),
        "gnss_velocity_m_s": pos("gnss_velocity_m_s", scenario["gnss"]["velocity_sigma_m_s"]),
    })
    gm_sensors = _gauss_markov_noise(m, noise)
    gyro_bs = m.gyro_rw_sigma / np.sqrt(1.0 / sc["imu_rate_hz"]
                                        / scenario["imu"]["bias_correlation_time_s"])
    accel_bs = m.accel_rw_sigma / np.sqrt(1.0 / sc["imu_rate_hz"]
                                          / scenario["imu"]["bias_correlation_time_s"])
    gps = np.asarray(scenario["gnss"]["position_sigma_m"])
    initial = {
        "position_m": [float(x) for x in np.maximum(3.0 * gps, 0.05)],
        "velocity_m_s": [0.1, 0.1, 0.1],
        "acceleration_m_s2": [0.1, 0.1, 0.1],
        "attitude_deg": [1.0, 1.0, max(2.0, 3.0 * scenario["heading"]["sigma_deg"])],
        "angular_rate_deg_s": [0.1, 0.1, 0.1],
        "gyro_bias_deg_s": [float(x) for x in np.maximum(
            3.0 * np.maximum(np.abs(m.gyro_bias0), gyro_bs + m.gyro_gm_sigma) * RAD2DEG, 1e-3)],
        "accel_bias_m_s2": [float(x) for x in np.maximum(
            3.0 * np.maximum(np.abs(m.accel_bias0), accel_bs + m.accel_gm_sigma), 1e-3)],
        "gyro_scale": [float(x) for x in np.maximum(3.0 * np.abs(m.gyro_scale), 1e-3)],
        "accel_scale": [float(x) for x in np.maximum(3.0 * np.abs(m.accel_scale), 1e-3)],
    }
    filt = {"mode": "loose",
            "states": 27 if np.any(m.gyro_scale) or np.any(m.accel_scale) else 21}
    first = scenario["segment"][0]
    if first["type"] == "static":
        filt["static_alignment_s"] = first["duration_s"]
    t0 = float(truth_arrays["time_gps_s"][0])
    recipe = {
        "dataset": {"name": sc["name"],
                    "description": (sc["description"] or "simulated road test")
                    + f" (gmis.simulate, seed {sc['seed']})"},
        "paths": {"imu": "imu.csv", "gnss_solution": "gnss.csv", "heading": "heading.csv",
                  "reference": "reference.csv"},
        "time": {"gps_week": sc["gps_week"], "start_gps_s": t0,
                 "end_gps_s": float(truth_arrays["time_gps_s"][-1])},
        "origin": dict(origin),
        "imu": {"rate_hz": sc["imu_rate_hz"], "format": "rate", "gyro_unit": "rad/s",
                "accel_unit": "m/s^2", "delimiter": ",", "time_column": "time_gps_s",
                "gyro_columns": ["gyro_x", "gyro_y", "gyro_z"],
                "accel_columns": ["accel_x", "accel_y", "accel_z"], "axes": ["x", "y", "z"]},
        "antennas": {"primary_lever_arm_m": scenario["gnss"]["lever_arm_m"],
                     "secondary_lever_arm_m": scenario["heading"]["lever_arm_m"]},
        "filter": filt,
        "noise": noise,
        "initial_sigma": initial,
    }
    if raw_gnss is not None:  # (paths, base) from gmis.simulate.raw_gnss
        recipe["paths"].update(raw_gnss[0])
        recipe["base"] = raw_gnss[1]
        rg = scenario["raw_gnss"]
        # σ90 of the undifferenced observables (σ² = σ90²(1 + 1/sin²β), 001 eq. 5.1.8)
        noise.update({"code_m": pos("code_m", rg["sigma90_code_m"]),
                      "phase_l1_m": pos("phase_l1_m", rg["sigma90_phase_m"]),
                      "phase_l2_m": pos("phase_l2_m", rg["sigma90_phase_m"]),
                      "doppler_m_s": pos("doppler_m_s", rg["sigma90_doppler_m_s"])})
        if rg.get("differential_atmosphere", 0.0) == 0.0:
            # the simulated troposphere is identical at base and rover: nothing to model
            filt["tc_troposphere"] = "none"
    comments = {
        "noise": "TRUE simulated per-sample/per-step 1-sigma values: gyro/accel = white "
                 "noise (+ quantisation q/sqrt(12));\nbias drift = per-step random walk "
                 "BS*sqrt(dt/T); jerk/angular acceleration = per-step sigma of the random "
                 "segments" + (f".\nFloored to {POSITIVE_FLOOR} (noise-free in the "
                               f"simulation): {', '.join(floored)}" if floored else "")
                 + (f"\nGauss-Markov bias states ({', '.join(gm_sensors)}): the simulated τ "
                    "and stationary sigma" if gm_sensors else "")
                 + ("\nGauss-Markov bias drift together with a random walk (or on some axes "
                    "only) is simulated but not representable here."
                    if (np.any(m.gyro_gm_sigma) and "gyro" not in gm_sensors)
                    or (np.any(m.accel_gm_sigma) and "accel" not in gm_sensors) else ""),
        "dataset": "Simulated by gmis.simulate from scenario.toml in this folder",
    }
    return dump_toml(recipe, comments)


def simulate_scenario(scenario, out_dir, seed=None, progress=None, overwrite=False):
    """Simulate a scenario (path or dict) into the dataset folder out_dir.

    seed overrides the scenario's seed. progress(fraction) is called as the run advances.
    Returns SimulationResult(dataset_dir, recipe_path, truth, scenario)."""
    report = progress or (lambda fraction: None)
    scenario_dir = None
    if isinstance(scenario, (str, os.PathLike)):
        scenario_dir = os.path.dirname(os.path.abspath(os.fspath(scenario)))
        scn = load_scenario(scenario)
        source = os.path.basename(os.fspath(scenario))
    elif isinstance(scenario, dict):
        source = "scenario"
        scn = validate_scenario(scenario, source)
    else:
        raise GmisInputError("scenario must be a path or a dict", "simulate_scenario")
    if seed is not None:
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise GmisInputError(f"seed must be a non-negative integer, got {seed!r}",
                                 "simulate_scenario")
        scn["scenario"]["seed"] = int(seed)
    report(0.0)
    sc = scn["scenario"]
    rate = sc["imu_rate_hz"]
    rngs = _rngs(sc["seed"])
    traj, frame = simulate_trajectory(scn, rngs["dynamics"], source)
    report(0.3)
    imu = simulate_imu(traj, frame, scn["imu"], rate, rngs["imu_bias"], rngs["imu_noise"])
    gnss = simulate_gnss(traj, frame, scn["gnss"], rate, rngs["gnss"])
    if gnss.index.size < 2:     # the dataset's recipe (loosely coupled) could not run
        raise GmisInputError(f"[[gnss.outage]] windows leave {gnss.index.size} GNSS epoch(s) "
                             f"of the {traj.t_s[-1]:.1f} s scenario; the dataset's recipe "
                             "needs a GNSS solution (at least 2 epochs)", source=str(source))
    head = simulate_heading(traj, scn["heading"], rate, rngs["heading"])
    report(0.5)
    t_gps = sc["start_gps_s"] + traj.t_s
    m = imu.model
    jerk_sigma, angacc_sigma = _random_process_sigmas(scn)
    arrays = {
        "time_gps_s": t_gps, "t_s": traj.t_s, "r_enu": traj.r_enu, "llh": traj.llh,
        "v_b": traj.v_b, "a_b": traj.a_b, "euler": traj.euler, "omega_b": traj.omega_b,
        "v_enu": traj.v_enu,
        "random_jerk_white": traj.random_jerk_white,
        "random_angacc_white": traj.random_angacc_white,
        "random_jerk_applied": traj.random_jerk_applied,
        "random_angacc_applied": traj.random_angacc_applied,
        "static_windows_s": np.array(traj.static_windows, float).reshape(-1, 2),
        "origin_llh": np.array([scn["origin"]["lat_deg"] * DEG, scn["origin"]["lon_deg"] * DEG,
                                scn["origin"]["h_m"]]),
        "imu_gyro": imu.gyro, "imu_accel": imu.accel,
        "gyro_bias": imu.gyro_bias, "accel_bias": imu.accel_bias,
        "gyro_scale": m.gyro_scale, "accel_scale": m.accel_scale,
        "gyro_noise": imu.gyro_noise, "accel_noise": imu.accel_noise,
        "gyro_white_sigma": m.gyro_white_sigma, "accel_white_sigma": m.accel_white_sigma,
        "gyro_bias_rw_sigma": m.gyro_rw_sigma, "accel_bias_rw_sigma": m.accel_rw_sigma,
        "gyro_gm_sigma": m.gyro_gm_sigma, "gyro_gm_tau": m.gyro_gm_tau,
        "accel_gm_sigma": m.accel_gm_sigma, "accel_gm_tau": m.accel_gm_tau,
        "gyro_quantization": m.gyro_quant, "accel_quantization": m.accel_quant,
        "gnss_index": gnss.index, "gnss_time_gps_s": t_gps[gnss.index],
        "gnss_true_r_enu": gnss.true_r_enu, "gnss_true_v_enu": gnss.true_vel_enu,
        "gnss_pos_noise_enu": gnss.pos_noise_enu, "gnss_vel_noise_enu": gnss.vel_noise_enu,
        "gnss_pos_sigma": gnss.pos_sigma, "gnss_vel_sigma": gnss.vel_sigma,
        "gnss_lever_arm": np.asarray(scn["gnss"]["lever_arm_m"], float),
        "heading_index": head.index, "heading_time_gps_s": t_gps[head.index],
        "heading_noise": head.noise, "heading_sigma": np.array(head.sigma),
        "jerk_sigma": np.zeros(3) if jerk_sigma is None else jerk_sigma,
        "angacc_sigma": np.zeros(3) if angacc_sigma is None else angacc_sigma * DEG,
    }
    truth = SimulationTruth(arrays)
    dataset_dir, tmp = prepare_output_dir(out_dir, overwrite)
    try:
        tfmt = "%.6f"
        write_csv(os.path.join(tmp, "imu.csv"), IMU_HEADER,
                  [t_gps, *imu.gyro.T, *imu.accel.T], [tfmt] + ["%.10e"] * 6)
        report(0.6)
        gi = gnss.index
        ones = np.ones(gi.size)
        write_csv(os.path.join(tmp, "gnss.csv"), GNSS_HEADER,
                  [t_gps[gi] + scn["gnss"]["latency_s"],  # stamped late by the latency
                   gnss.llh[:, 0] * RAD2DEG, gnss.llh[:, 1] * RAD2DEG, gnss.llh[:, 2],
                   *(ones[None, :] * gnss.pos_sigma[:, None]), *gnss.vel_enu.T,
                   *(ones[None, :] * gnss.vel_sigma[:, None])],
                  [tfmt, "%.11f", "%.11f", "%.5f"] + ["%.5g"] * 3 + ["%.5f"] * 3
                  + ["%.5g"] * 3)
        write_csv(os.path.join(tmp, "heading.csv"), HEADING_HEADER,
                  [t_gps[head.index], head.heading * RAD2DEG,
                   np.full(head.index.size, head.sigma * RAD2DEG)],
                  [tfmt, "%.7f", "%.6g"])
        heading_wrapped = np.mod(traj.euler[:, 2], 2.0 * np.pi)
        write_csv(os.path.join(tmp, "reference.csv"), REFERENCE_HEADER,
                  [t_gps, traj.llh[:, 0] * RAD2DEG, traj.llh[:, 1] * RAD2DEG, traj.llh[:, 2],
                   *traj.v_enu.T, traj.euler[:, 0] * RAD2DEG, traj.euler[:, 1] * RAD2DEG,
                   heading_wrapped * RAD2DEG],
                  [tfmt, "%.11f", "%.11f", "%.5f"] + ["%.6f"] * 3 + ["%.8f"] * 3)
        report(0.85)
        np.savez(os.path.join(tmp, "truth.npz"), **arrays)
        raw = None
        if "raw_gnss" in scn:
            from gmis.simulate.raw_gnss import simulate_dataset_raw_gnss
            raw = simulate_dataset_raw_gnss(scn, traj, frame, sc["seed"], tmp, scenario_dir)
        with open(os.path.join(tmp, "recipe.toml"), "w") as fh:
            fh.write(build_recipe(scn, imu, arrays, raw))
        with open(os.path.join(tmp, "scenario.toml"), "w") as fh:
            fh.write(dump_toml(scn, {"scenario": "Normalised scenario of this dataset "
                                                 "(all defaults filled in); re-simulating it "
                                                 "reproduces the dataset"}))
        commit_output_dir(tmp, dataset_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    report(1.0)
    return SimulationResult(dataset_dir, os.path.join(dataset_dir, "recipe.toml"), truth, scn)
