"""Where the read-only validation data lives: ../shared/data beside the repository root (as
in CI and a developer checkout). Tests that need it skip with a clear reason when it is
absent (a fresh clone has no shared/ folder)."""

from pathlib import Path

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
RTKLIB_TEST = SHARED_DATA / "rtklib-test"
RINEX_CORPUS = SHARED_DATA / "rinex-corpus-georinex"
