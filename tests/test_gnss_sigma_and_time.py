"""Issue 20 items 3-4: a GNSS solution without sigma columns takes its σ only from the
recipe (never the RTK-grade registry default); [gnss] time base (UTC with leap seconds)
and time offset."""

import calendar

import numpy as np
import pytest

from gmis.errors import GmisInputError
from gmis.leap_seconds import gps_minus_utc_s, unix_utc_to_gps_s
from gmis.readers import load_dataset
from gmis.readers_rtklib import SECONDS_PER_WEEK
from gmis.recipe import load_recipe
from tests.conftest import T0, write_csv_text

COLUMNS = ["time_gps_s", "lat_deg", "lon_deg", "h_m"]


def _no_sigma_gnss(dataset, t=None):
    t = T0 + np.arange(0.0, 3.0, 0.2) if t is None else t
    rows = np.column_stack([t, np.full(t.size, 43.7735), np.full(t.size, -79.5019),
                            np.full(t.size, 180.0)])
    return write_csv_text(dataset.root / "gnss_plain.csv", COLUMNS, rows)


def _recipe(dataset, noise=None, gnss=None):
    doc = dataset.modified("paths", gnss_solution="gnss_plain.csv")
    if noise is not None:
        doc["noise"] = noise
    if gnss is not None:
        doc["gnss"] = gnss
    return load_recipe(dataset.write(doc))


def test_missing_sigma_columns_without_recipe_sigma_is_refused(dataset):
    path = _no_sigma_gnss(dataset)
    with pytest.raises(GmisInputError) as err:
        load_dataset(_recipe(dataset))
    text = str(err.value)
    assert str(path) in text and "[noise].gnss_position_m" in text and "\n" not in text


def test_missing_sigma_columns_take_the_recipe_sigma_with_a_note(dataset, capsys):
    _no_sigma_gnss(dataset)
    ds = load_dataset(_recipe(dataset, noise={"gnss_position_m": [1.5, 1.5, 3.0]}))
    assert ds.gnss.pos_sigma == pytest.approx(np.tile([1.5, 1.5, 3.0], (15, 1)))
    assert "σ from [noise].gnss_position_m = [1.5, 1.5, 3]" in capsys.readouterr().err


def test_recipe_sigma_equal_to_the_default_counts_when_given(dataset):
    _no_sigma_gnss(dataset)
    ds = load_dataset(_recipe(dataset, noise={"gnss_position_m": [0.02, 0.02, 0.04]}))
    assert ds.gnss.pos_sigma[0] == pytest.approx([0.02, 0.02, 0.04])


def test_missing_velocity_sigma_is_refused_too(dataset):
    t = T0 + np.arange(0.0, 3.0, 0.2)
    rows = np.column_stack([t, np.full(t.size, 43.7735), np.full(t.size, -79.5019),
                            np.full(t.size, 180.0), np.ones((t.size, 3)),
                            np.ones((t.size, 3))])
    write_csv_text(dataset.root / "gnss_plain.csv",
                   COLUMNS + ["sigma_e_m", "sigma_n_m", "sigma_u_m", "ve_m_s", "vn_m_s",
                              "vu_m_s"], rows)
    with pytest.raises(GmisInputError, match=r"\[noise\].gnss_velocity_m_s"):
        load_dataset(_recipe(dataset))
    ds = load_dataset(_recipe(dataset, noise={"gnss_velocity_m_s": [0.3, 0.3, 0.6]}))
    assert ds.gnss.vel_sigma[0] == pytest.approx([0.3, 0.3, 0.6])


def test_leap_seconds_table():
    def unix(y, m, d, hh=0, mm=0, ss=0):
        return calendar.timegm((y, m, d, hh, mm, ss))
    assert gps_minus_utc_s(unix(1980, 1, 6)) == 0
    assert gps_minus_utc_s(unix(1985, 6, 30, 23, 59, 59)) == 3
    assert gps_minus_utc_s(unix(1985, 7, 1)) == 4
    assert gps_minus_utc_s(unix(2016, 12, 31, 23, 59, 59)) == 17
    assert gps_minus_utc_s(unix(2017, 1, 1)) == 18
    assert gps_minus_utc_s(unix(2026, 12, 1)) == 18
    # 2016-07-01 12:00 UTC: GPS week 1903, day 5, 12 h + 17 s
    gps = unix_utc_to_gps_s(unix(2016, 7, 1, 12))
    assert gps == pytest.approx(1903 * SECONDS_PER_WEEK + 5 * 86400 + 43200 + 17)


def test_gnss_utc_time_base_and_offset_land_on_gps_time(dataset):
    week = 2400  # T0 is a seconds-of-week value in that week (2026)
    unix = T0 + week * SECONDS_PER_WEEK + 315964800.0 - 18.0 + 0.05
    _no_sigma_gnss(dataset, unix + np.arange(0.0, 3.0, 0.2))
    ds = load_dataset(_recipe(dataset, noise={"gnss_position_m": [1.0, 1.0, 2.0]},
                              gnss={"time_base": "unix_utc", "time_offset_s": -0.05}))
    assert ds.gnss.t[0] == pytest.approx(T0, abs=1e-6)
    assert np.diff(ds.gnss.t) == pytest.approx(0.2)
    # without the time base the stamps are Unix seconds: no overlap with the IMU
    with pytest.raises(GmisInputError, match="same time base"):
        load_dataset(_recipe(dataset, noise={"gnss_position_m": [1.0, 1.0, 2.0]}))


def test_gnss_time_offset_shifts_the_stamps(dataset):
    base = load_dataset(load_recipe(dataset.write()))
    doc = dataset.modified("gnss", time_offset_s=0.1)
    shifted = load_dataset(load_recipe(dataset.write(doc)))
    common = base.gnss.t[base.gnss.t + 0.1 <= base.imu.t[-1]]
    assert shifted.gnss.t[:common.size] == pytest.approx(common + 0.1)


def test_bad_gnss_section_keys_are_refused(dataset):
    for gnss, key in (({"time_base": "utc"}, "gnss.time_base"),
                      ({"time_offset_s": 120.0}, "gnss.time_offset_s"),
                      ({"latency_s": 0.1}, "latency_s")):
        doc = dataset.modified("gnss", **gnss)
        with pytest.raises(GmisInputError, match=key.replace(".", r"\.")):
            load_recipe(dataset.write(doc))
