"""Speed-over-ground / course measurement (gmis.speed_course), the Gauss-Markov GNSS
fix-error step (gmis.gnss_error_states) and the CSV columns that carry them."""

import numpy as np
import pytest

from gmis.errors import GmisInputError
from gmis.gnss_error_states import predict_gnss_error_states
from gmis.measurement_models import gnss_velocity_model_and_jacobian_into
from gmis.readers import read_gnss_solution
from gmis.recipe import GnssSection, NoiseSection
from gmis.speed_course import (
    MIN_PREDICTED_SPEED_M_S,
    speed_course_from_enu,
    speed_course_model_and_jacobian_into,
)
from tests.test_system_model import central_difference, random_state

LEVER = np.array([0.3, 1.0, 1.5])


def _h(x):
    out = np.zeros(2)
    assert speed_course_model_and_jacobian_into(x, LEVER, out, 0, np.zeros((2, x.size)), 0)
    return out


@pytest.mark.parametrize("n", [21, 27])
def test_speed_course_jacobian_matches_central_differences(n):
    rng = np.random.default_rng(20)
    for _ in range(30):
        x = random_state(rng, n)
        out, jac = np.zeros(2), np.zeros((2, n))
        assert speed_course_model_and_jacobian_into(x, LEVER, out, 0, jac, 0)
        step = np.full(n, 1e-6)

        def h_unwrapped(xx, ref=out[1]):
            got = _h(xx)
            got[1] = ref + (got[1] - ref + np.pi) % (2 * np.pi) - np.pi
            return got
        fd = central_difference(h_unwrapped, x, step)
        assert np.abs(jac - fd).max() < 1e-6
        assert np.linalg.norm(jac - fd) / np.linalg.norm(jac) < 1e-6


def test_speed_course_is_the_horizontal_part_of_the_antenna_velocity():
    rng = np.random.default_rng(21)
    for _ in range(20):
        x = random_state(rng, 21)
        v = np.zeros(3)
        gnss_velocity_model_and_jacobian_into(x, LEVER, v, 0, np.zeros((3, 21)), 0)
        speed, course = speed_course_from_enu(v[None, :])
        np.testing.assert_allclose(_h(x), [speed[0], course[0]], rtol=0, atol=1e-12)
    # the vertical velocity does not enter: a climb at the same horizontal velocity
    x = random_state(rng, 21)
    x[9:11] = 0.0                      # level: v^b z is vertical
    base = _h(x)
    x[5] += 3.0
    np.testing.assert_allclose(_h(x), base, atol=1e-12)


def test_no_rows_below_the_minimum_predicted_speed():
    x = np.zeros(21)
    x[4] = 0.5 * MIN_PREDICTED_SPEED_M_S
    out, jac = np.full(2, -1.0), np.full((2, 21), -1.0)
    assert not speed_course_model_and_jacobian_into(x, np.zeros(3), out, 0, jac, 0)
    assert np.all(out == -1.0) and np.all(jac == -1.0)


def test_gauss_markov_step_is_phi_p_phi_plus_q():
    rng = np.random.default_rng(5)
    n, i0 = 24, 21
    a = rng.normal(size=(n, n))
    p = a @ a.T
    x = rng.normal(size=n)
    tau, sd, dt = np.array([5.0, 5.0, 20.0]), np.array([1.5, 1.5, 3.0]), 0.1
    phi = np.eye(n)
    phi[i0:, i0:] = np.diag(np.exp(-dt / tau))
    q = np.zeros((n, n))
    q[i0:, i0:] = np.diag(sd ** 2 * (1 - np.exp(-2 * dt / tau)))
    want_p, want_x = phi @ p @ phi.T + q, phi @ x
    predict_gnss_error_states(x, p, dt, i0, 1.0 / tau, sd ** 2)
    np.testing.assert_allclose(p, want_p, rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(x, want_x, rtol=1e-14)
    # stationary: the variance of a state at σ_b² stays σ_b² over any step
    p = np.diag(np.r_[np.ones(i0), sd ** 2])
    for step in (0.01, 0.1, 3.0):
        predict_gnss_error_states(np.zeros(n), p, step, i0, 1.0 / tau, sd ** 2)
    np.testing.assert_allclose(np.diag(p)[i0:], sd ** 2, rtol=1e-12)


def _csv(path, sigma=True, speed=(15.0, 0.4)):
    cols = "time_gps_s,lat_deg,lon_deg,h_m,sigma_e_m,sigma_n_m,sigma_u_m,speed_m_s,course_deg"
    cols += ",sigma_speed_m_s,sigma_course_deg" if sigma else ""
    rows = []
    for i, s in enumerate(speed):
        row = f"{100 + 0.1 * i},40.0,-105.0,1600.0,1.5,1.5,3.0,{s},350.0"
        rows.append(row + (",0.1,2.0" if sigma else ""))
    path.write_text(cols + "\n" + "\n".join(rows) + "\n")
    return path


def test_csv_speed_course_columns(tmp_path):
    sol = read_gnss_solution(_csv(tmp_path / "g.csv"), gnss=GnssSection(course_min_speed_m_s=1.0))
    assert sol.vel_enu is None
    np.testing.assert_allclose(sol.speed_course[:, 0], [15.0, 0.4])
    np.testing.assert_allclose(sol.speed_course[:, 1], np.radians(350.0))
    np.testing.assert_allclose(sol.speed_course_sigma[0], [0.1, np.radians(2.0)])
    assert np.isnan(sol.speed_course_sigma[1, 1])   # slower than course_min_speed_m_s
    assert sol.speed_course_sigma[1, 0] == 0.1


def test_csv_speed_course_sigma_must_come_from_the_file_or_the_recipe(tmp_path, capsys):
    path = _csv(tmp_path / "g.csv", sigma=False)
    with pytest.raises(GmisInputError, match=r"sigma_speed_m_s.*\[noise\].gnss_speed_m_s"):
        read_gnss_solution(path)
    noise = NoiseSection(gnss_speed_sigma_m_s=0.2, gnss_course_sigma_rad=np.radians(3.0))
    sol = read_gnss_solution(path, noise=noise)
    np.testing.assert_allclose(sol.speed_course_sigma[0], [0.2, np.radians(3.0)])
    assert "σ from [noise].gnss_course_deg = 3 deg" in capsys.readouterr().err


def test_csv_speed_course_with_enu_velocity_is_refused(tmp_path):
    path = tmp_path / "g.csv"
    path.write_text("time_gps_s,lat_deg,lon_deg,h_m,sigma_e_m,sigma_n_m,sigma_u_m,ve_m_s,"
                    "vn_m_s,vu_m_s,sigma_ve_m_s,sigma_vn_m_s,sigma_vu_m_s,speed_m_s,"
                    "course_deg,sigma_speed_m_s,sigma_course_deg\n"
                    "100,40,-105,1600,1,1,2,1,1,0,0.1,0.1,0.1,1.4,45,0.1,2\n")
    with pytest.raises(GmisInputError, match="one velocity form"):
        read_gnss_solution(path)
