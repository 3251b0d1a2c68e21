"""Where the read-only validation data lives: ``../shared/data`` beside the repository root
(as in CI and a developer checkout) — nowhere else. When it is absent the tests that need it
skip with :data:`SKIP_REASON`; there is no fallback to a fixed path on some machine."""

from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
RTKLIB_TEST = SHARED_DATA / "rtklib-test"
DRIVE_BOULDER = SHARED_DATA / "drive-boulder-0708"
RINEX_CORPUS = SHARED_DATA / "rinex-corpus-georinex"
SKIP_REASON = f"real data folder ../shared/data ({SHARED_DATA}) absent beside the repository"


def require(path: Path) -> Path:
    """``path`` if it exists, else skip the calling test naming the missing data."""
    if not path.exists():
        pytest.skip(f"{SKIP_REASON}: {path.relative_to(SHARED_DATA.parent)} missing")
    return path
