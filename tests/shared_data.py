"""Where the read-only validation data lives: ../shared/data beside the repository (as in
CI and a developer checkout), else /work/shared/data. Tests skip when neither exists."""

from pathlib import Path

_CANDIDATES = (Path(__file__).resolve().parents[2] / "shared" / "data" / "rtklib-test",
               Path("/work/shared/data/rtklib-test"))
RTKLIB_TEST = next((p for p in _CANDIDATES if p.is_dir()), _CANDIDATES[0])
