"""Road-test simulator (gmis.simulate): truth self-consistency, sensor models, determinism,
scenario validation."""

import copy
import filecmp
import os
import tomllib

import numpy as np
import pytest

from gmis.earth import make_nav_frame
from gmis.errors import GmisInputError
from gmis.frames import dcm_body_to_nav, euler_rate_matrix
from gmis.imu_model import imu_measurement
from gmis.simulate import (
    default_scenario_path,
    load_scenario,
    scenario_path,
    simulate_scenario,
    validate_scenario,
)
from gmis.simulate.sensors import antenna_position_velocity
from gmis.simulate.trajectory import plan_motion, simulate_trajectory

DEG = np.pi / 180.0


@pytest.fixture(scope="module")
def default_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "default"
    return simulate_scenario(default_scenario_path(), out)


@pytest.fixture(scope="module")
def sideslip_truth():
    """Truth of the tightly_coupled scenario (default drive, [vehicle] sideslip K = 0.4
    °/(m/s²)): (scenario, truth)."""
    scn = load_scenario(scenario_path("tightly_coupled"))
    assert scn["vehicle"]["sideslip_deg_per_m_s2"] == 0.4
    truth, _ = simulate_trajectory(scn, np.random.default_rng(0))
    return scn, truth


@pytest.fixture(params=["default", "sideslip"])
def truth_case(request):
    """(name, scenario, truth) for the default drive and the same drive with sideslip."""
    if request.param == "default":
        run = request.getfixturevalue("default_run")
        return "default", run.scenario, run.truth
    return ("sideslip",) + request.getfixturevalue("sideslip_truth")


def _jerk_discontinuities(scenario):
    """Times (s, relative) where the deterministic body jerk may jump: with sideslip,
    v_x = K ψ̇ s² is only C¹, so its second derivative jumps at the ends of every yaw-rate
    ramp (ψ⃛ of the raised cosine jumps there)."""
    if scenario["vehicle"]["sideslip_deg_per_m_s2"] == 0.0:
        return np.empty(0)
    plan = plan_motion(scenario)
    return np.array([t for ev in plan.heading.events
                     for t in (ev.t0, ev.t0 + ev.ramp_s, ev.end - ev.ramp_s, ev.end)])


def _cubic_midpoints(x):
    """Values at the interval midpoints k+1/2 from 4-point Lagrange interpolation of the
    samples (one-sided at the ends)."""
    mid = np.empty((x.shape[0] - 1,) + x.shape[1:])
    mid[1:-1] = (-x[:-3] + 9.0 * x[1:-2] + 9.0 * x[2:-1] - x[3:]) / 16.0
    mid[0] = (5.0 * x[0] + 15.0 * x[1] - 5.0 * x[2] + x[3]) / 16.0
    mid[-1] = (5.0 * x[-1] + 15.0 * x[-2] - 5.0 * x[-3] + x[-4]) / 16.0
    return mid


def _integrate_pose(t, v_b, omega, r0, theta0, linear_omega=False):
    """RK4 of ṙ = C_b^n(θ) v^b, θ̇ = C(θ) ω from the samples only (001 eq. 4.1.14, 4.1.17)."""
    v_mid = _cubic_midpoints(v_b)
    w_mid = 0.5 * (omega[:-1] + omega[1:]) if linear_omega else _cubic_midpoints(omega)
    r = np.empty_like(v_b)
    th = np.empty_like(v_b)
    r[0], th[0] = r0, theta0

    def f(theta, v, w):
        return (dcm_body_to_nav(theta[0], theta[1], theta[2]) @ v,
                euler_rate_matrix(theta[0], theta[1]) @ w)

    for k in range(t.size - 1):
        h = t[k + 1] - t[k]
        k1r, k1t = f(th[k], v_b[k], omega[k])
        k2r, k2t = f(th[k] + 0.5 * h * k1t, v_mid[k], w_mid[k])
        k3r, k3t = f(th[k] + 0.5 * h * k2t, v_mid[k], w_mid[k])
        k4r, k4t = f(th[k] + h * k3t, v_b[k + 1], omega[k + 1])
        r[k + 1] = r[k] + h / 6.0 * (k1r + 2 * k2r + 2 * k3r + k4r)
        th[k + 1] = th[k] + h / 6.0 * (k1t + 2 * k2t + 2 * k3t + k4t)
    return r, th


def test_default_drive_truth_is_self_consistent(truth_case):
    """Integrating the true v^b and ω samples reproduces position (< 1 mm) and attitude
    (< 1e-6 rad) over the whole default drive, without and with sideslip."""
    name, _, tr = truth_case
    assert tr.t_s[-1] >= 590.0
    r, th = _integrate_pose(tr.t_s, tr.v_b, tr.omega_b, tr.r_enu[0], tr.euler[0])
    pos_err = np.max(np.linalg.norm(r - tr.r_enu, axis=1))
    att_err = np.max(np.abs(th - tr.euler))
    print(f"{name} drive: max position error {pos_err * 1e3:.4f} mm, "
          f"max attitude error {att_err:.3e} rad, path length "
          f"{np.sum(np.linalg.norm(np.diff(tr.r_enu, axis=0), axis=1)):.0f} m")
    assert pos_err < 1e-3
    assert att_err < 1e-6
    # the drive really moves and turns: not a trivially consistent trajectory
    assert np.ptp(tr.euler[:, 2]) > np.pi / 2 and np.max(np.abs(tr.euler[:, 1])) > 3.0 * DEG
    assert np.max(np.linalg.norm(tr.v_b, axis=1)) > 11.0


def test_body_acceleration_is_rotated_second_derivative_of_position(truth_case):
    """a^b = C_n^b d²r^n/dt² (001 eq. 4.1.15), checked by central differences of r; with
    sideslip, stencils straddling a jerk discontinuity (finite differences need a smooth
    r⃛ there) are left out."""
    name, scenario, tr = truth_case
    dt = tr.t_s[1] - tr.t_s[0]
    r = tr.r_enu
    d1 = (r[3:-1] - 2.0 * r[2:-2] + r[1:-3]) / dt ** 2
    d2 = (r[4:] - 2.0 * r[2:-2] + r[:-4]) / (4.0 * dt ** 2)
    acc_n = (4.0 * d1 - d2) / 3.0  # Richardson: O(dt⁴)
    idx = np.arange(2, r.shape[0] - 2, 10)
    kinks = _jerk_discontinuities(scenario)
    if kinks.size:
        near = np.min(np.abs(tr.t_s[idx][:, None] - kinks[None, :]), axis=1) <= 2.0 * dt
        assert np.count_nonzero(near) <= kinks.size
        idx = idx[~near]
    c_bn = np.array([dcm_body_to_nav(*e) for e in tr.euler[idx]])
    acc_b = np.einsum("kji,kj->ki", c_bn, acc_n[idx - 2])
    err = np.max(np.abs(acc_b - tr.a_b[idx]))
    vel_err = np.max(np.abs(np.gradient(tr.r_enu, dt, axis=0)[1:-1] - tr.v_enu[1:-1]))
    print(f"{name}: a^b vs finite differences: {err:.2e} m/s² at {idx.size} epochs; "
          f"v^n: {vel_err:.2e} m/s")
    assert err < 1e-5 and vel_err < 1e-3
    assert np.max(np.abs(tr.a_b)) > 1.0


def test_sideslip_lateral_velocity_follows_the_model(default_run, sideslip_truth):
    """v_x = K ψ̇ s² (β = K·a_lat, a_lat = ψ̇ s) with ψ̇ recovered from the true ω and θ by
    001 eq. 2.2.6 (θ̇ = C(θ) ω); non-zero in the turns, zero elsewhere; v_z = 0; attitude
    and speed identical to the drive without sideslip."""
    scn, tr = sideslip_truth
    k_rad = scn["vehicle"]["sideslip_deg_per_m_s2"] * DEG
    heading_rate = np.array([(euler_rate_matrix(e[0], e[1]) @ w)[2]
                             for e, w in zip(tr.euler, tr.omega_b)])
    speed = tr.v_b[:, 1]
    expected = k_rad * heading_rate * speed ** 2
    model_err = np.max(np.abs(tr.v_b[:, 0] - expected))
    v_x_max = np.max(np.abs(tr.v_b[:, 0]))
    turning = np.abs(heading_rate) > 5.0 * DEG
    beta_max = np.max(np.abs(tr.v_b[turning, 0] / speed[turning])) / DEG
    print(f"sideslip K = {scn['vehicle']['sideslip_deg_per_m_s2']} °/(m/s²): max |v_x| "
          f"{v_x_max:.4f} m/s, max |β| {beta_max:.3f}°, |v_x − Kψ̇s²| ≤ {model_err:.1e} m/s")
    assert model_err < 1e-9
    assert 0.1 < v_x_max < 0.4 and 0.5 < beta_max < 2.0
    assert np.all(np.abs(tr.v_b[turning, 0]) > 0.02)
    # K > 0: velocity to the body right in a right (clockwise, ψ̇ > 0) turn
    assert np.all(np.sign(tr.v_b[turning, 0]) == np.sign(heading_rate[turning]))
    assert np.all(tr.v_b[np.abs(heading_rate) < 1e-12, 0] == 0.0)
    assert np.all(tr.v_b[:, 2] == 0.0)
    ref = default_run.truth
    np.testing.assert_array_equal(tr.euler, ref.euler)
    np.testing.assert_array_equal(tr.omega_b, ref.omega_b)
    np.testing.assert_array_equal(tr.v_b[:, 1], ref.v_b[:, 1])
    assert np.all(ref.v_b[:, 0] == 0.0)
    assert np.max(np.linalg.norm(tr.r_enu - ref.r_enu, axis=1)) > 0.1  # the slip moves it


def test_random_segment_truth_is_self_consistent(tmp_path):
    scn = load_scenario(scenario_path("random_dynamics"))
    scn["segment"][-1]["duration_s"] = 60.0
    fractions = []
    res = simulate_scenario(scn, tmp_path / "rnd", progress=fractions.append)
    assert fractions[0] == 0.0 and fractions[-1] == 1.0 and fractions == sorted(fractions)
    with open(res.recipe_path, "rb") as fh:
        noise = tomllib.load(fh)["noise"]
    assert noise["jerk_m_s3"] == [3.0, 4.0, 2.0]
    assert noise["angular_acceleration_deg_s2"] == [5.0, 5.0, 15.0]
    tr = res.truth
    k0 = np.flatnonzero(np.isfinite(tr.random_jerk_white[:, 0]))[0]
    sl = slice(k0, None)
    # ω is piecewise linear (ω̇ held over each step), so linear interpolation is exact
    r, th = _integrate_pose(tr.t_s[sl], tr.v_b[sl], tr.omega_b[sl], tr.r_enu[k0],
                            tr.euler[k0], linear_omega=True)
    pos_err = np.max(np.linalg.norm(r - tr.r_enu[sl], axis=1))
    att_err = np.max(np.abs(th - tr.euler[sl]))
    dt = tr.t_s[1] - tr.t_s[0]
    ang_err = np.max(np.abs(np.diff(tr.omega_b[sl], axis=0) / dt
                            - tr.random_angacc_applied[sl][:-1]))
    white = tr.random_jerk_white[sl][:-1]
    print(f"random segment: position {pos_err * 1e3:.4f} mm, attitude {att_err:.2e} rad, "
          f"ω̇ {ang_err:.1e}; jerk white σ {np.std(white, axis=0)}")
    assert pos_err < 1e-3 and att_err < 1e-6 and ang_err < 1e-9
    assert np.allclose(np.std(white, axis=0), [3.0, 4.0, 2.0], rtol=0.05)
    applied = tr.random_jerk_applied[sl][:-1]
    # the reversion is weak: the applied jerk is dominated by the white draw
    assert np.all(np.std(applied - white, axis=0) < 0.2 * np.std(white, axis=0))


def test_imu_outputs_follow_the_measurement_model(default_run):
    """y = imu_measurement(truth, b_k, S) + n_k, quantised (001 eq. 4.1.39/4.1.40)."""
    tr = default_run.truth
    o = default_run.scenario["origin"]
    frame = make_nav_frame(o["lat_deg"] * DEG, o["lon_deg"] * DEG, o["h_m"])
    qg, qa = tr.gyro_quantization, tr.accel_quantization
    assert np.all(qg > 0) and np.all(qa > 0)
    for k in (0, 1000, 40000, 52000, tr.t_s.size - 1):
        model = imu_measurement(tr.r_enu[k], tr.v_b[k], tr.a_b[k], tr.euler[k], tr.omega_b[k],
                                tr.gyro_bias[k], tr.accel_bias[k], tr.gyro_scale,
                                tr.accel_scale, frame)
        expected_g = qg * np.round((model[:3] + tr.gyro_noise[k]) / qg)
        expected_a = qa * np.round((model[3:] + tr.accel_noise[k]) / qa)
        np.testing.assert_allclose(tr.imu_gyro[k], expected_g, atol=1e-12)
        np.testing.assert_allclose(tr.imu_accel[k], expected_a, atol=1e-12)
    # static epoch: accelerometers see +g up, gyros see the earth rate. Noise and bias are
    # removed with their stored truth; what remains is (I+S)(model) + quantisation error.
    static = slice(0, 29000)
    lat = o["lat_deg"] * DEG
    clean_a = tr.imu_accel[static] - tr.accel_noise[static] - tr.accel_bias[static]
    clean_g = tr.imu_gyro[static] - tr.gyro_noise[static] - tr.gyro_bias[static]
    mean_a = clean_a.mean(axis=0) / (1.0 + tr.accel_scale)
    mean_g = clean_g.mean(axis=0) / (1.0 + tr.gyro_scale)
    w_e = 7.2921151467e-5
    expected_w = np.array([0.0, w_e * np.cos(lat), w_e * np.sin(lat)])  # heading north
    print(f"static mean accel {mean_a} m/s², gyro {mean_g} rad/s (earth rate {expected_w})")
    assert 9.80 < mean_a[2] < 9.81 and np.all(np.abs(mean_a[:2]) < 1e-5)
    assert np.all(np.abs(mean_g - expected_w) < 2e-6)
    assert abs(mean_g[1] - expected_w[1]) < 0.05 * expected_w[1]


def test_gnss_and_heading_follow_lever_arm_model(default_run):
    tr = default_run.truth
    idx = tr.gnss_index
    pos, vel = antenna_position_velocity(tr.r_enu[idx], tr.v_b[idx], tr.euler[idx],
                                         tr.omega_b[idx], tr.gnss_lever_arm)
    # independent check of 001 eq. 4.1.41/4.1.42 at one moving epoch
    k = idx[np.argmax(np.abs(tr.omega_b[idx, 2]))]
    c = dcm_body_to_nav(*tr.euler[k])
    j = np.flatnonzero(idx == k)[0]
    np.testing.assert_allclose(pos[j], tr.r_enu[k] + c @ tr.gnss_lever_arm, atol=1e-12)
    np.testing.assert_allclose(vel[j], c @ (tr.v_b[k] + np.cross(tr.omega_b[k],
                                                               tr.gnss_lever_arm)), atol=1e-12)
    assert abs(np.linalg.norm(vel[j]) - np.linalg.norm(tr.v_b[k])) > 0.01  # lever arm matters
    np.testing.assert_allclose(tr.gnss_true_r_enu, pos)
    t_rel = tr.t_s[idx]
    assert not np.any((t_rel >= 430.0) & (t_rel < 445.0))          # outage respected
    assert np.all(np.diff(t_rel)[t_rel[1:] < 430.0] == pytest.approx(0.2))
    sd = np.std(tr.gnss_pos_noise_enu, axis=0)
    assert np.allclose(sd, [0.02, 0.02, 0.04], rtol=0.1)
    # file contents: noisy antenna positions read back equal truth + noise (to print precision)
    data = np.loadtxt(os.path.join(default_run.dataset_dir, "gnss.csv"), delimiter=",",
                      skiprows=1)
    assert data.shape == (idx.size, 13)
    np.testing.assert_allclose(data[:, 0], tr.time_gps_s[idx], atol=1e-6)
    hd = np.loadtxt(os.path.join(default_run.dataset_dir, "heading.csv"), delimiter=",",
                    skiprows=1)
    err = (hd[:, 1] * DEG - tr.euler[tr.heading_index, 2] + np.pi) % (2 * np.pi) - np.pi
    assert np.std(err) == pytest.approx(0.5 * DEG, rel=0.1)


def test_dataset_folder_and_recipe(default_run):
    d = default_run.dataset_dir
    assert sorted(os.listdir(d)) == ["gnss.csv", "heading.csv", "imu.csv", "recipe.toml",
                                     "reference.csv", "scenario.toml", "truth.npz"]
    with open(default_run.recipe_path, "rb") as fh:
        recipe = tomllib.load(fh)
    assert recipe["paths"]["imu"] == "imu.csv"
    assert recipe["antennas"]["primary_lever_arm_m"] == [0.3, 1.0, 1.5]
    # true per-sample σ: ARW 4.5 °/√h at 100 Hz = 0.75 °/s; VRW 1.0 m/s/√h = 0.1667 m/s²
    q = np.array(recipe["noise"]["gyro_deg_s"])
    assert np.allclose(q, np.sqrt(0.75 ** 2 + 0.02 ** 2 / 12), rtol=1e-9)
    assert np.allclose(recipe["noise"]["accel_m_s2"],
                       np.sqrt((1.0 / 60 / 0.1) ** 2 + (0.5e-3 * 9.80665) ** 2 / 12), rtol=1e-9)
    assert recipe["noise"]["gyro_bias_drift_deg_s"][0] == pytest.approx(10 / 3600 * 0.01)
    assert "jerk_m_s3" not in recipe["noise"]
    assert recipe["filter"]["static_alignment_s"] == 300.0
    with open(os.path.join(d, "imu.csv")) as fh:
        header = fh.readline().strip()
    assert header == "time_gps_s,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z"
    imu = np.loadtxt(os.path.join(d, "imu.csv"), delimiter=",", skiprows=1, max_rows=5000)
    np.testing.assert_allclose(imu[:, 1:4], default_run.truth.imu_gyro[:5000], rtol=1e-9)
    ref = np.loadtxt(os.path.join(d, "reference.csv"), delimiter=",", skiprows=1)
    assert ref.shape == (default_run.truth.t_s.size, 10)
    assert np.all(np.diff(ref[:, 0]) > 0)
    # the written scenario reproduces the run
    assert load_scenario(os.path.join(d, "scenario.toml")) == default_run.scenario


def test_same_seed_identical_files_other_seed_differs(tmp_path):
    scn = load_scenario(default_scenario_path())
    scn["segment"] = scn["segment"][:6]
    scn["segment"][0]["duration_s"] = 5.0
    a = simulate_scenario(scn, tmp_path / "a")
    b = simulate_scenario(scn, tmp_path / "b")
    c = simulate_scenario(scn, tmp_path / "c", seed=7)
    names = ["imu.csv", "gnss.csv", "heading.csv", "reference.csv", "recipe.toml",
             "truth.npz", "scenario.toml"]
    match, mismatch, errors = filecmp.cmpfiles(a.dataset_dir, b.dataset_dir, names,
                                               shallow=False)
    assert match == names, (mismatch, errors)
    assert not filecmp.cmp(os.path.join(a.dataset_dir, "imu.csv"),
                           os.path.join(c.dataset_dir, "imu.csv"), shallow=False)
    assert not np.allclose(a.truth.gyro_noise, c.truth.gyro_noise)
    np.testing.assert_array_equal(a.truth.r_enu, c.truth.r_enu)  # deterministic motion
    assert c.scenario["scenario"]["seed"] == 7


def test_existing_output_is_kept_on_failure_and_replaced_on_overwrite(tmp_path):
    scn = load_scenario(default_scenario_path())
    scn["segment"] = scn["segment"][:2]
    scn["segment"][0]["duration_s"] = 2.0
    out = tmp_path / "ds"
    simulate_scenario(scn, out)
    with pytest.raises(GmisInputError, match="not empty"):
        simulate_scenario(scn, out)
    bad = copy.deepcopy(scn)
    bad["segment"].append({"type": "static", "duration_s": 5.0})  # static while moving
    with pytest.raises(GmisInputError, match="static segment while moving"):
        simulate_scenario(bad, out, overwrite=True)
    assert sorted(os.listdir(tmp_path)) == ["ds"]  # no temporary leftovers
    simulate_scenario(scn, out, seed=3, overwrite=True)
    assert load_scenario(out / "scenario.toml")["scenario"]["seed"] == 3


def _minimal():
    return {
        "scenario": {"name": "x", "seed": 1, "imu_rate_hz": 100.0},
        "origin": {"lat_deg": 43.0, "lon_deg": -79.0, "h_m": 100.0},
        "segment": [{"type": "static", "duration_s": 1.0}],
        "imu": {"grade": "IMU440"},
        "gnss": {"rate_hz": 5.0, "position_sigma_m": 0.02, "velocity_sigma_m_s": 0.05,
                 "lever_arm_m": [0, 0, 1]},
        "heading": {"rate_hz": 5.0, "sigma_deg": 0.5, "lever_arm_m": [0, -1, 1]},
    }


@pytest.mark.parametrize("mutate, key", [
    (lambda s: s["scenario"].update(colour="red"), "colour"),
    (lambda s: s["scenario"].update(imu_rate_hz=50.0), "imu_rate_hz"),
    (lambda s: s["scenario"].update(seed="one"), "seed"),
    (lambda s: s["segment"][0].update(duration_s=-3.0), "duration_s"),
    (lambda s: s["segment"].append({"type": "jump", "duration_s": 1.0}), "type"),
    (lambda s: s["segment"].append({"type": "turn", "angle_deg": 90.0}), "rate_deg_s"),
    (lambda s: s["imu"].update(grade="HG0000"), "grade"),
    (lambda s: s["imu"].update(gyro_arw_deg_sqrt_h=[1.0, 2.0]), "gyro_arw_deg_sqrt_h"),
    (lambda s: s["gnss"].update(rate_hz=3.0), "rate_hz"),
    (lambda s: s["gnss"].update(outage=[{"start_s": 5.0, "end_s": 4.0}]), "end_s"),
    (lambda s: s["heading"].pop("sigma_deg"), "sigma_deg"),
    (lambda s: s.pop("origin"), "origin"),
    (lambda s: s.update(vehicle={"sideslip_deg_per_m_s2": 5.5}), "sideslip_deg_per_m_s2"),
    (lambda s: s.update(vehicle={"sideslip_deg_per_m_s2": -6.0}), "sideslip_deg_per_m_s2"),
    (lambda s: s.update(vehicle={"sideslip_deg_per_m_s2": float("nan")}),
     "sideslip_deg_per_m_s2"),
    (lambda s: s.update(vehicle={"sideslip_deg_per_m_s2": "0.4"}), "sideslip_deg_per_m_s2"),
    (lambda s: s.update(vehicle={"sideslip_deg": 0.4}), "[vehicle]: unknown key(s) sideslip_deg"),
    (lambda s: s["segment"][:0].append(None) or s["segment"].insert(
        0, {"type": "random", "duration_s": 5.0, "sigma_jerk_m_s3": 1.0,
            "sigma_angacc_deg_s2": 1.0}), "random"),
])
def test_bad_scenarios_name_the_key(mutate, key):
    raw = _minimal()
    validate_scenario(copy.deepcopy(raw), "bad.toml")  # the base is valid
    mutate(raw)
    with pytest.raises(GmisInputError) as info:
        validate_scenario(raw, "bad.toml")
    message = str(info.value)
    print(message)
    assert message.startswith("bad.toml:") and key in message


def test_bad_toml_file_names_the_file(tmp_path):
    p = tmp_path / "broken.toml"
    p.write_text("[scenario\nname = 1\n")
    with pytest.raises(GmisInputError, match="broken.toml"):
        load_scenario(p)
    with pytest.raises(GmisInputError, match="not found"):
        load_scenario(tmp_path / "missing.toml")


def test_embedded_scenarios_are_valid():
    for name in ("default", "random_dynamics", "tactical"):
        scn = load_scenario(scenario_path(name))
        assert scn["segment"]
    tac = load_scenario(scenario_path("tactical"))
    assert tac["imu"]["grade"] == "HG1700" and tac["scenario"]["imu_rate_hz"] == 200.0


def test_a_scenario_without_gnss_is_refused_before_writing(tmp_path):
    """An outage covering every GNSS epoch wrote a dataset its own recipe could not run
    (helper review 2026-12-06): one line, nothing written."""
    from gmis.errors import GmisInputError
    from gmis.simulate import simulate_scenario
    from tests.test_turn_on_the_spot import turn_scenario

    (tmp_path / "s.toml").write_text(turn_scenario(gnss_outages=[(0.0, 500.0)]))
    with pytest.raises(GmisInputError, match=r"leave 0 GNSS epoch\(s\)"):
        simulate_scenario(tmp_path / "s.toml", tmp_path / "ds")
    assert not (tmp_path / "ds").exists()
