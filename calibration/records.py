"""Static IMU records: CSV or gzip CSV with a header naming each column and its unit.

Columns: a time column (``time_s`` or ``t_s``; only its median spacing is used, for the
rate) and sensor columns ``gyro_<axis>_<unit>`` / ``accel_<axis>_<unit>`` with unit one of
``deg_s``, ``rad_s``, ``deg_h`` (gyro) and ``g``, ``mg``, ``m_s2`` (accel) — the layout of
``../shared/data/imu-static-adis16405/``. Values are converted to SI (rad/s, m/s²).
Bad input raises :class:`gmis.errors.GmisInputError` naming the file and the line or column.
"""

from __future__ import annotations

import gzip
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gmis.errors import GmisInputError

G0 = 9.80665
DEG = np.pi / 180.0
UNITS = {"gyro": {"deg_s": DEG, "rad_s": 1.0, "deg_h": DEG / 3600.0},
         "accel": {"g": G0, "mg": G0 * 1e-3, "m_s2": 1.0}}
SI_UNIT = {"gyro": "rad/s", "accel": "m/s^2"}
_COLUMN = re.compile(r"^(gyro|accel)_([a-z0-9]+)_(.+)$")
TIME_COLUMNS = ("time_s", "t_s")


@dataclass(frozen=True)
class StaticRecord:
    path: str
    dt: float  # sample interval, s
    axes: dict[str, np.ndarray]  # "gyro_x" → SI samples
    units: dict[str, str]  # "gyro_x" → the file's unit ("deg_s")

    @property
    def n(self) -> int:
        return next(iter(self.axes.values())).size


def _read_text(path: Path) -> str:
    if not path.exists():
        raise GmisInputError("file not found", source=str(path))
    if not path.is_file():
        raise GmisInputError("not a file", source=str(path))
    try:
        raw = path.read_bytes()
        if raw[:2] == b"\x1f\x8b":
            raw = gzip.decompress(raw)
        return raw.decode("utf-8-sig")
    except (OSError, EOFError, UnicodeDecodeError) as exc:
        raise GmisInputError(f"cannot read ({exc})", source=str(path)) from None


def read_static_record(path, rate_hz: float | None = None) -> StaticRecord:
    path = Path(path)
    text = _read_text(path)
    lines = text.splitlines()
    header_at = next((i for i, line in enumerate(lines)
                      if line.strip() and not line.lstrip().startswith("#")), None)
    if header_at is None:
        raise GmisInputError("empty file", source=str(path))
    names = [s.strip() for s in lines[header_at].split(",")]
    body = [line for line in lines[header_at + 1:] if line.strip()
            and not line.lstrip().startswith("#")]
    if len(body) < 16:
        raise GmisInputError(f"only {len(body)} data lines; a calibration needs long "
                             "static records", source=str(path))
    ncol = len(names)
    counts = np.fromiter((line.count(",") + 1 for line in body), dtype=np.int64, count=len(body))
    bad = np.flatnonzero(counts != ncol)
    if bad.size:
        k = int(bad[0])
        raise GmisInputError(f"line {_line_number(lines, header_at, body, k)}: {counts[k]} "
                             f"columns, expected {ncol}", source=str(path))
    try:
        values = np.fromstring(",".join(body), dtype=float, sep=",")
    except ValueError:
        values = np.empty(0)
    if values.size != len(body) * ncol:
        for k, line in enumerate(body):
            try:
                [float(v) for v in line.split(",")]
            except ValueError:
                raise GmisInputError(f"line {_line_number(lines, header_at, body, k)}: "
                                     "not a number", source=str(path)) from None
        raise GmisInputError("could not parse the numeric data", source=str(path))
    data = values.reshape(len(body), ncol)
    axes, units, time_col = {}, {}, None
    for j, name in enumerate(names):
        if name in TIME_COLUMNS:
            time_col = j
            continue
        match = _COLUMN.match(name)
        if not match:
            continue
        kind, axis, unit = match.groups()
        if unit not in UNITS[kind]:
            raise GmisInputError(f"column {name!r}: unknown unit {unit!r}; use one of "
                                 + ", ".join(UNITS[kind]), source=str(path))
        column = data[:, j]
        nonfinite = np.flatnonzero(~np.isfinite(column))
        if nonfinite.size:
            raise GmisInputError(f"line {_line_number(lines, header_at, body, int(nonfinite[0]))}"
                                 f": non-finite value in column {name!r}", source=str(path))
        axes[f"{kind}_{axis}"] = column * UNITS[kind][unit]
        units[f"{kind}_{axis}"] = unit
    if not axes:
        raise GmisInputError("no gyro_<axis>_<unit> or accel_<axis>_<unit> column in the "
                             "header: " + ", ".join(names), source=str(path))
    if rate_hz is not None:
        if not rate_hz > 0:
            raise GmisInputError(f"rate must be > 0, got {rate_hz}", source="--rate")
        dt = 1.0 / rate_hz
    elif time_col is not None:
        steps = np.diff(data[:, time_col])
        dt = float(np.median(steps))
        if not dt > 0:
            raise GmisInputError(f"column {names[time_col]!r}: time does not increase",
                                 source=str(path))
    else:
        raise GmisInputError("no time column (time_s) and no --rate given", source=str(path))
    return StaticRecord(str(path), dt, axes, units)


def _line_number(lines, header_at, body, k) -> int:
    """1-based file line of body[k] (body skips comments/blank lines; rare, so linear)."""
    target = body[k]
    seen = -1
    for i in range(header_at + 1, len(lines)):
        if lines[i].strip() and not lines[i].lstrip().startswith("#"):
            seen += 1
            if seen == k and lines[i] == target:
                return i + 1
    return header_at + 2 + k
