"""gmis.solution_antenna: the antenna position from the IMU centre and the attitude, and
the RTKLIB solution.pos written at the antenna, read back by gnss.pos_file.read_pos."""

from __future__ import annotations

import numpy as np
import pytest

from gmis.earth import make_nav_frame
from gmis.enu_rows import enu_to_geodetic_rows
from gmis.readers import GnssSolution
from gmis.solution_antenna import antenna_enu, quality, write_solution_pos
from gnss.pos_file import read_pos


def test_antenna_enu_follows_heading():
    enu = np.zeros((2, 3))
    # heading 90° (east): body forward = east, body right = south
    euler = np.array([[0.0, 0.0, np.pi / 2], [0.0, 0.0, 0.0]])
    ant = antenna_enu(enu, euler, [1.0, 2.0, 0.5])  # 1 m right, 2 m forward, 0.5 m up
    np.testing.assert_allclose(ant[0], [2.0, -1.0, 0.5], atol=1e-12)
    np.testing.assert_allclose(ant[1], [1.0, 2.0, 0.5], atol=1e-12)


def test_quality_grades():
    sd = np.array([[0.01, 0.02, 0.1], [0.2, 0.05, 1.0], [0.6, 0.1, 1.0]])
    assert quality(sd).tolist() == [1, 2, 5]


def test_solution_pos_round_trip(tmp_path):
    frame = make_nav_frame(np.radians(40.0966), np.radians(-105.1474), 1601.0)
    n = 30
    t = 243261.0 + 0.1 * np.arange(n)
    enu = np.column_stack([np.arange(n) * 0.3, np.sin(np.arange(n)), np.full(n, 0.2)])
    llh = enu_to_geodetic_rows(frame, enu)
    sd = np.tile([0.012, 0.011, 0.03], (n, 1))
    sd[20:] = [0.3, 0.2, 0.5]
    gnss = GnssSolution(t=t[::3], llh=llh[::3], pos_sigma=sd[::3], ns=np.arange(10) + 10)
    path = write_solution_pos(tmp_path / "solution.pos", t, 2374, llh, sd, gnss, ["test"])
    back = read_pos(path)
    np.testing.assert_allclose(back["t_gps"], 2374 * 604800.0 + t, atol=1e-6)
    np.testing.assert_allclose(np.degrees(back["llh"][:, :2]), np.degrees(llh[:, :2]),
                               atol=1e-9)
    np.testing.assert_allclose(back["llh"][:, 2], llh[:, 2], atol=1e-4)
    assert back["q"].tolist() == [1] * 20 + [2] * 10
    assert back["ns"][:3].tolist() == [10, 10, 11]  # nearest input epoch within 0.5 s
    np.testing.assert_allclose(back["columns"]["sdn(m)"], sd[:, 1], atol=1e-4)
    np.testing.assert_allclose(back["columns"]["sde(m)"], sd[:, 0], atol=1e-4)
    np.testing.assert_allclose(back["columns"]["sdu(m)"], sd[:, 2], atol=1e-4)
    assert path.read_text().startswith("% test")
    with pytest.raises(KeyError):
        back["columns"]["vn(m/s)"]
