"""[gnss] keys of issue 20 (speed/course, Gauss-Markov fix errors, latency estimation):
parsed, and refused in one line where they cannot apply."""

import math

import pytest

from gmis.errors import GmisInputError
from gmis.recipe import load_recipe

BASE = """[dataset]
name = "t"
[paths]
imu = "i.csv"
gnss_solution = "g.csv"
[imu]
rate_hz = 100.0
[antennas]
primary_lever_arm_m = [0.0, 0.0, 1.0]
"""


def _load(tmp_path, text):
    path = tmp_path / "r.toml"
    (tmp_path / "i.csv").write_text("")
    (tmp_path / "g.csv").write_text("")
    path.write_text(BASE + text)
    return load_recipe(path)


def test_keys_are_parsed(tmp_path):
    r = _load(tmp_path, "[gnss]\nestimate_time_offset = true\ntime_offset_search_s = 0.5\n"
                        "course_min_speed_m_s = 2.0\nerror_correlation_time_s = 5.0\n"
                        "error_sigma_m = [1.5, 1.5, 3.0]\n[noise]\ngnss_speed_m_s = 0.2\n"
                        "gnss_course_deg = 2.0\n")
    g = r.gnss
    assert g.estimate_time_offset and g.time_offset_search_s == 0.5
    assert g.course_min_speed_m_s == 2.0
    assert g.error_correlation_time_s == 5.0 and g.error_sigma_m == (1.5, 1.5, 3.0)
    assert r.noise.gnss_speed_sigma_m_s == 0.2
    assert r.noise.gnss_course_sigma_rad == pytest.approx(math.radians(2.0), rel=1e-12)
    from gmis.engine_configs import gmikf_config
    cfg = gmikf_config(r)
    assert cfg.gnss_error_states and cfg.gnss_error_tau_s.tolist() == [5.0] * 3


@pytest.mark.parametrize("text, message", [
    ("[gnss]\nerror_correlation_time_s = 5.0\n", r"gnss.error_sigma_m: .*go together"),
    ("[gnss]\nerror_sigma_m = [1.0, 1.0, 1.0]\n",
     r"gnss.error_correlation_time_s: .*go together"),
    (("[gnss]\nerror_correlation_time_s = 5.0\nerror_sigma_m = [1.0, 1.0, 1.0]\n"
     "[filter]\nsmoother = \"two_filter\"\n"), r"smoother does not handle"),
    ("[gnss]\ntime_offset_search_s = 0.0\n", r"gnss.time_offset_search_s"),
])
def test_bad_keys_are_refused(tmp_path, text, message):
    with pytest.raises(GmisInputError, match=message):
        _load(tmp_path, text)
