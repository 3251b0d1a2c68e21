"""An RTKLIB .pos without σ columns is refused unless the recipe gives the σ (issue 20:
no RTK-grade registry default silently replaces a missing sigma)."""

import numpy as np
import pytest

from gmis.errors import GmisInputError
from gmis.readers_rtklib import read_gnss_pos
from gmis.recipe import NoiseSection

HEADER = ("%  GPST            latitude(deg) longitude(deg) height(m) Q  ns  {sd}age(s) ratio "
          "vn(m/s) ve(m/s) vu(m/s) {sdv}")
POS_SD = "sdn(m) sde(m) sdu(m) sdne(m) sdeu(m) sdun(m) "
VEL_SD = "sdvn sdve sdvu sdvne sdveu sdvun"


def write_pos(path, with_pos_sd, with_vel_sd):
    head = HEADER.format(sd=POS_SD if with_pos_sd else "", sdv=VEL_SD if with_vel_sd else "")
    rows = []
    for i in range(3):
        row = f"2025/07/08 19:34:{18 + i * 0.25:06.3f} 40.0966268 -105.1474483 1601.47 1 21 "
        row += "0.010 0.020 0.030 0.001 0.000 0.000 " if with_pos_sd else ""
        row += "0.0 0.0 0.5 1.5 -0.1"
        row += " 0.05 0.06 0.07 0 0 0" if with_vel_sd else ""
        rows.append(row)
    path.write_text("\n".join([head] + rows) + "\n")
    return path


def test_pos_without_velocity_sigma_is_refused(tmp_path):
    path = write_pos(tmp_path / "s.pos", True, False)
    with pytest.raises(GmisInputError, match=r"sdve, sdvn, sdvu.*\[noise\].gnss_velocity_m_s"):
        read_gnss_pos(path)


def test_pos_without_position_sigma_is_refused(tmp_path):
    path = write_pos(tmp_path / "s.pos", False, True)
    with pytest.raises(GmisInputError, match=r"sde\(m\).*\[noise\].gnss_position_m"):
        read_gnss_pos(path)


def test_pos_missing_sigma_taken_from_the_recipe_with_a_note(tmp_path, capsys):
    path = write_pos(tmp_path / "s.pos", True, False)
    noise = NoiseSection(gnss_velocity_sigma_m_s=(0.3, 0.3, 0.6))
    sol = read_gnss_pos(path, noise=noise)
    np.testing.assert_allclose(sol.vel_sigma, np.tile([0.3, 0.3, 0.6], (3, 1)))
    np.testing.assert_allclose(sol.pos_sigma[0], [0.020, 0.010, 0.030])
    assert "σ from [noise].gnss_velocity_m_s" in capsys.readouterr().err
    # the registry default given explicitly in the recipe counts as given
    sol = read_gnss_pos(path, noise=NoiseSection(),
                        noise_given=frozenset({"gnss_velocity_sigma_m_s"}))
    np.testing.assert_allclose(sol.vel_sigma[0], NoiseSection().gnss_velocity_sigma_m_s)
