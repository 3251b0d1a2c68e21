"""gnss.geodesy against pymap3d (WGS-84 geodetic ⇄ ECEF ⇄ ENU), gnss.epoch_matching, and
the gnss input error reaching the gmis CLI as one line with exit status 2."""

import numpy as np
import pymap3d
import pytest

from gnss.epoch_matching import match_epochs, nearest_epoch
from gnss.errors import GnssInputError
from gnss.geodesy import (
    ecef_to_enu_matrix,
    ecef_to_enu_rows,
    ecef_to_geodetic,
    ecef_to_geodetic_rows,
    geodetic_to_ecef,
    geodetic_to_ecef_rows,
)

SITES = [(43.77, -79.50, 180.0), (-33.9, 151.2, 40.0), (78.2, 15.6, 10.0),
         (0.0, 0.0, 0.0), (-89.5, -170.0, 3000.0)]


@pytest.mark.parametrize("lat, lon, h", SITES)
def test_geodetic_ecef_against_pymap3d(lat, lon, h):
    xyz = geodetic_to_ecef(np.radians(lat), np.radians(lon), h)
    np.testing.assert_allclose(xyz, pymap3d.geodetic2ecef(lat, lon, h), atol=1e-6)
    la, lo, hh = ecef_to_geodetic(*xyz)
    ref = pymap3d.ecef2geodetic(*xyz)
    assert abs(np.degrees(la) - ref[0]) < 1e-10 and abs(np.degrees(lo) - ref[1]) < 1e-10
    assert abs(hh - ref[2]) < 1e-6


def test_rows_equal_the_scalar_functions_and_pymap3d_enu():
    rng = np.random.default_rng(3)
    llh = np.column_stack([rng.uniform(-1.5, 1.5, 40), rng.uniform(-np.pi, np.pi, 40),
                           rng.uniform(-100, 5000, 40)])
    xyz = geodetic_to_ecef_rows(llh)
    assert np.array_equal(xyz, np.array([geodetic_to_ecef(*r) for r in llh]))
    back = ecef_to_geodetic_rows(xyz)
    assert np.array_equal(back, np.array([ecef_to_geodetic(*r) for r in xyz]))
    np.testing.assert_allclose(back[:, :2], llh[:, :2], atol=1e-12)     # rad
    np.testing.assert_allclose(back[:, 2], llh[:, 2], atol=1e-6)        # m
    origin = xyz[0]
    lat0, lon0, h0 = np.degrees(llh[0, 0]), np.degrees(llh[0, 1]), llh[0, 2]
    pts = xyz[:5] + rng.normal(0, 1e3, (5, 3))
    enu = ecef_to_enu_rows(pts, origin)
    ref = np.array([pymap3d.ecef2enu(*p, lat0, lon0, h0) for p in pts])
    np.testing.assert_allclose(enu, ref, atol=1e-6)
    c = ecef_to_enu_matrix(llh[0, 0], llh[0, 1])
    np.testing.assert_allclose(c @ c.T, np.eye(3), atol=1e-15)


def test_nearest_and_matched_epochs():
    t_ref = np.array([0.0, 1.0, 2.0, 3.0])
    t = np.array([-5.0, 0.01, 0.5, 1.49, 1.51, 2.98, 9.0])
    assert nearest_epoch(t_ref, t).tolist() == [0, 0, 1, 1, 2, 3, 3]   # midway → later
    assert match_epochs(t_ref, t).tolist() == [-1, 0, -1, -1, -1, 3, -1]
    assert match_epochs(t_ref, t, tolerance_s=0.6).tolist() == [-1, 0, 1, 1, 2, 3, -1]
    assert nearest_epoch(np.array([5.0]), np.array([1.0, 9.0])).tolist() == [0, 0]


def test_gnss_input_error_is_the_cli_one_liner(tmp_path, capsys):
    from gmis.cli import main
    from gmis.errors import GmisInputError
    assert issubclass(GmisInputError, GnssInputError)
    err = GnssInputError("no epochs", "x.obs")
    assert str(err) == "x.obs: no epochs" and err.source == "x.obs"
    bad = tmp_path / "rover.05o"
    bad.write_text("not a rinex file\n")
    recipe = tmp_path / "recipe.toml"
    recipe.write_text(f'[paths]\nrover_obs = "{bad.name}"\nbase_obs = "{bad.name}"\n'
                      f'nav = "{bad.name}"\n[base]\necef_m = [-3976219.5, 3382372.6, 3652513.0]\n')
    assert main(["rtk", str(recipe), "-o", str(tmp_path / "out"), "--quiet"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gmis: error: ") and "rover.05o" in lines[0]
    assert not (tmp_path / "out").exists()
