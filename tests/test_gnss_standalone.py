"""gnss on its own (issue 12): with every gmis module made unimportable, the package
imports and its RTK runs on the shared 0759/3040 session (RINEX 2.10, 3.3 km baseline)."""

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tests.shared_data import RTKLIB_TEST as DATA

REPO = Path(__file__).resolve().parents[1]

BLOCK_GMIS = """
import sys
class _BlockGmis:
    def find_spec(self, name, path=None, target=None):
        if name == "gmis" or name.startswith("gmis."):
            raise ImportError(f"gmis is blocked in this test: {name}")
        return None
sys.meta_path.insert(0, _BlockGmis())
"""


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", BLOCK_GMIS + textwrap.dedent(code)],
                          cwd=REPO, capture_output=True, text=True, timeout=900, check=False)


def test_the_blocker_blocks_gmis():
    out = _run("import gmis.earth\n")
    assert out.returncode != 0 and "gmis is blocked" in out.stderr


def test_gnss_modules_import_without_gmis():
    out = _run("""
        import pkgutil, gnss
        for m in pkgutil.iter_modules(gnss.__path__):
            __import__(f"gnss.{m.name}")
        for name in gnss.__all__:                  # every export resolves, no np
            assert getattr(gnss, name).__module__.startswith("gnss."), name
        assert "np" not in gnss.__all__
        assert not any(k == "gmis" or k.startswith("gmis.") for k in sys.modules)
        print("ok", len(gnss.__all__))
    """)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("ok")


def test_rtk_runs_without_gmis_on_the_shared_session():
    if not DATA.is_dir():
        pytest.skip(f"real data folder {DATA} absent (../shared/data/rtklib-test)")
    out = _run(f"""
        import numpy as np
        from gnss import process_rtk, read_nav, read_obs
        base = read_obs({str(DATA / "07590920.05o")!r})
        rover = read_obs({str(DATA / "30400920.05o")!r})
        nav = read_nav({str(DATA / "07590920.05n")!r})
        sol = process_rtk(base, rover, nav, [-3976219.5082, 3382372.5671, 3652512.9849])
        fixed = sol.q == 1
        b = np.linalg.norm(sol.ecef[fixed].mean(axis=0) - [-3976219.5082, 3382372.5671,
                                                             3652512.9849])
        assert not any(k == "gmis" or k.startswith("gmis.") for k in sys.modules)
        print(sol.t_gps.size, fixed.sum(), f"{{b:.3f}}")
    """)
    assert out.returncode == 0, out.stderr
    n, n_fixed, baseline = out.stdout.split()
    assert int(n) == 120 and int(n_fixed) >= 110
    assert abs(float(baseline) - 3335.0) < 5.0


def test_write_pos_with_a_nan_ratio_reads_back(tmp_path):
    """A held fix has no ratio test (NaN): write_pos writes 0.0 as RTKLIB does, so gmis
    reads its own tc.pos / solution.pos back."""
    from types import SimpleNamespace

    import numpy as np

    from gnss.pos_file import read_pos, write_pos

    sol = SimpleNamespace(t_gps=np.array([2400 * 604800.0 + 1.0, 2400 * 604800.0 + 2.0]),
                          llh=np.array([[0.7, -1.8, 100.0], [0.7, -1.8, 100.5]]),
                          q=np.array([1, 1]), n_sat=np.array([8, 8]),
                          sigma_enu=np.full((2, 3), 0.01), ratio=np.array([5.0, np.nan]))
    back = read_pos(write_pos(tmp_path / "x.pos", sol))
    assert back["ratio"].tolist() == [5.0, 0.0]
    assert np.allclose(back["llh"][:, 2], [100.0, 100.5])
