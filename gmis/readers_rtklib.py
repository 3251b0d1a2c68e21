"""RTKLIB-side inputs: the .tag time-tag file of a raw log, a raw IMU CSV whose time is a
millisecond tick counter mapped to GPST by that .tag file, and an RTKLIB .pos solution as
the loosely coupled GNSS input. Formats and recipe keys: docs/formats.md ("RTKLIB inputs").

Times are returned as GPS seconds of week (the time base of the rest of gmis); every
problem is a GmisInputError naming the file and line.
"""

from __future__ import annotations

import struct
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gmis.errors import GmisInputError
from gmis.sensor_data import GnssSolution
from gmis.text_blocks import LineNumbers
from gnss.constants import SECONDS_PER_WEEK, UNIX_TO_GPS_EPOCH_S

TAG_HEADER_BYTES = 60
TAG_MAGIC = b"TIMETAG RTKLIB"
_TAG_PREFIX = struct.Struct("<IId")  # tick_f, time (s), sec (s)
TICK_CSV_FIELDS = 7  # accX, accY, accZ [g], gyroX, gyroY, gyroZ [deg/s], t [ms]


@dataclass(frozen=True)
class TimeTag:
    """An RTKLIB .tag file: start_gps_s = log start, GPS seconds since 1980-01-06;
    tick_ms (K,) and file_pos (K,) the (tick, byte offset) pairs."""

    start_gps_s: float
    tick_f: int
    tick_ms: np.ndarray
    file_pos: np.ndarray

    @property
    def gps_week(self) -> int:
        return int(self.start_gps_s // SECONDS_PER_WEEK)


def read_time_tag(path) -> TimeTag:
    """Read an RTKLIB demo5 time-tag file (60-byte header "TIMETAG RTKLIB ...", uint32
    tick_f, uint32 time + float64 sec = start in GPST as a Unix-style count, then
    (uint32 tick_ms, uint32 file_pos) pairs, little-endian)."""
    src = str(path)
    p = Path(path)
    if not p.is_file():
        raise GmisInputError("time-tag file not found" if not p.exists() else "not a file",
                             source=src)
    raw = p.read_bytes()
    if len(raw) < TAG_HEADER_BYTES + _TAG_PREFIX.size or not raw.startswith(TAG_MAGIC):
        raise GmisInputError("header: not an RTKLIB time-tag file (expected a 60-byte "
                             "header starting 'TIMETAG RTKLIB' and the start time)", source=src)
    tick_f, time_s, sec = _TAG_PREFIX.unpack_from(raw, TAG_HEADER_BYTES)
    if not (np.isfinite(sec) and 0.0 <= sec < 1.0):
        raise GmisInputError(f"header: start-time fraction {sec!r} s is not in [0, 1)",
                             source=src)
    start = time_s - UNIX_TO_GPS_EPOCH_S + sec
    if start < 0.0:
        raise GmisInputError(f"header: start time {time_s} s (Unix-style) is before the GPS "
                             "epoch 1980-01-06", source=src)
    body = raw[TAG_HEADER_BYTES + _TAG_PREFIX.size:]
    n = len(body) // 8
    pairs = np.frombuffer(body[:8 * n], dtype="<u4").reshape(n, 2)
    if n == 0:
        raise GmisInputError("no (tick, file position) records after the header", source=src)
    ticks = pairs[:, 0].astype(np.int64)
    back = np.flatnonzero(np.diff(ticks) < 0)
    if back.size:
        raise GmisInputError(f"record {int(back[0]) + 2}: tick {ticks[back[0] + 1]} ms goes "
                             f"back from {ticks[back[0]]} ms", source=src)
    return TimeTag(float(start), int(tick_f), ticks, pairs[:, 1].astype(np.int64))


def _tick_block(lines, keep):
    """(rows, 7) float64 of the non-blank lines ``keep`` of a block when every one of them
    is a complete, finite record (one np.fromstring), else None (the caller then parses
    line by line)."""
    import warnings

    chosen = lines if len(keep) == len(lines) else [lines[i] for i in keep]
    if any(line.count(",") != TICK_CSV_FIELDS - 1 for line in chosen):
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            v = np.fromstring(",".join(chosen), dtype=np.float64, sep=",")
        except (DeprecationWarning, ValueError):
            return None
    if v.size != len(chosen) * TICK_CSV_FIELDS or not np.isfinite(v).all():
        return None
    return v.reshape(len(chosen), TICK_CSV_FIELDS)


CUT_LINE_NEIGHBOURS = 100       # samples an end line is compared with
CUT_LINE_MADS = 20.0            # ... and how far (scaled MADs) it must lie to be a cut line
CUT_LINE_FLOOR = (0.05,) * 3 + (1.0,) * 3   # g, deg/s: below this a jump is never a cut


def _drop_cut_end_lines(a, numbers, src, notes):
    """A first or last line cut by the logger inside its first field parses as seven
    numbers ("19,..." of "0.019,..."): such a line is dropped with a note when one of its
    six sensor values lies more than CUT_LINE_MADS scaled MADs (at least CUT_LINE_FLOOR)
    from the median of its CUT_LINE_NEIGHBOURS neighbours — a wild value no sensor at
    rest or in a car gives between two samples. Lines elsewhere are left to the
    plausibility checks."""
    k = CUT_LINE_NEIGHBOURS
    if a.shape[0] < k + 2:
        return a, numbers
    floor = np.asarray(CUT_LINE_FLOOR)
    drop = []
    for row, near in ((0, a[1:k + 1, :6]), (a.shape[0] - 1, a[-k - 1:-1, :6])):
        med = np.median(near, axis=0)
        spread = np.maximum(1.4826 * np.median(np.abs(near - med), axis=0), floor / 3)
        far = np.abs(a[row, :6] - med) > np.maximum(CUT_LINE_MADS * spread, floor)
        if far.any():
            drop.append(row)
            which = "first" if row == 0 else "last"
            notes.append(f"{src}: line {numbers[row]}: {which} line's values lie far from the "
                         f"next {k} samples' (a line cut inside its first field): skipped")
    if not drop:
        return a, numbers
    keep = np.ones(a.shape[0], bool)
    keep[drop] = False
    return a[keep], LineNumbers.of(np.asarray(numbers)[keep])


def read_tick_imu_csv(path, tag: TimeTag, time_offset_s: float = 0.0):
    """Raw IMU CSV (no header; accX,accY,accZ [g], gyroX,gyroY,gyroZ [deg/s], t [ms]) →
    (t_sow (N,) s, gyro (N,3) deg/s, accel (N,3) g, line numbers (gmis.readers.LineNumbers
    of the N rows), notes). The file is read in blocks (gmis.text_blocks), each complete
    block by one np.fromstring; only a block with a partial line is parsed line by line.

    Time: the linear mapping of the data's author — the first sample at the tag's start
    time, the last at start + last tag tick / 1000 — plus time_offset_s (s). A partial
    (wrong field count or unparsable) first or last line is dropped with a note; anywhere
    else it is an error naming the line."""
    from gmis.text_blocks import line_blocks

    src = str(path)
    notes = []
    blocks = []
    numbers = LineNumbers()
    pending = None        # line number of a partial line that is last only if nothing follows
    seen = 0              # non-blank lines so far

    def parse(line):
        f = line.split(",")
        if len(f) != TICK_CSV_FIELDS:
            return None
        try:
            v = [float(x) for x in f]
        except ValueError:
            return None
        return v if all(np.isfinite(v)) else None

    def middle_error(line_no):
        raise GmisInputError(f"line {line_no}: expected {TICK_CSV_FIELDS} numbers "
                             "accX,accY,accZ,gyroX,gyroY,gyroZ,t_ms", source=src)

    def slow(lines, first_line, indices):
        """Line by line: a partial line is skipped at the start of the file, kept pending
        (the last line of the file, or an error when another line follows) elsewhere."""
        nonlocal pending, seen
        rows, rows_line = [], []
        for i in indices:
            if pending is not None:
                middle_error(pending)
            v = parse(lines[i])
            if v is None:
                if seen == 0:
                    notes.append(f"{src}: line {first_line + i}: partial first line skipped")
                else:
                    pending = first_line + i
            else:
                rows.append(v)
                rows_line.append(first_line + i)
            seen += 1
        if rows:
            blocks.append(np.array(rows, dtype=np.float64).reshape(-1, TICK_CSV_FIELDS))
            numbers.add_lines(rows_line)

    for lines, first_line, _ in line_blocks(path):
        keep = [i for i, line in enumerate(lines) if line.strip()]
        if not keep:
            continue
        if seen == 0:                 # the file's first line may be partial
            slow(lines, first_line, keep[:1])
            keep = keep[1:]
        if not keep:
            continue
        if pending is not None:
            middle_error(pending)
        tail = []
        values = _tick_block(lines, keep)
        if values is None and len(keep) > 1:   # a partial last line of the file?
            values = _tick_block(lines, keep[:-1])
            tail = keep[-1:]
        if values is None:
            slow(lines, first_line, keep)
            continue
        fast = keep[:len(keep) - len(tail)]
        blocks.append(values)
        if len(fast) == fast[-1] - fast[0] + 1:
            numbers.add_run(first_line + fast[0], len(fast))
        else:
            numbers.add_lines(first_line + i for i in fast)
        seen += len(fast)
        slow(lines, first_line, tail)
    if pending is not None:
        notes.append(f"{src}: line {pending}: partial last line skipped")
    n_rows = sum(b.shape[0] for b in blocks)
    if n_rows < 2:
        raise GmisInputError(f"only {n_rows} complete IMU line(s); need at least 2",
                             source=src)
    a = np.concatenate(blocks) if len(blocks) > 1 else blocks[0]
    blocks.clear()
    if a.shape[0] > 2 and a[-1, 6] <= a[-2, 6]:
        # the log cut inside the last line's tick ("...,8104" of "...,810412"): that line's
        # tick is not a tick; its values are dropped with it
        notes.append(f"{src}: line {numbers[a.shape[0] - 1]}: last line's tick "
                     f"{a[-1, 6]:.0f} ms does not follow {a[-2, 6]:.0f} ms (a line cut "
                     "inside its tick): skipped")
        a = a[:-1]
        numbers = LineNumbers.of(np.asarray(numbers)[:-1])
    # the author's linear map runs from the log's first to its last tick, whether or not
    # a cut end line's sensor values are kept (its tick, the last field, is whole)
    ms_first, ms_last = a[0, 6], a[-1, 6]
    a, numbers = _drop_cut_end_lines(a, numbers, src, notes)
    line_numbers = numbers
    ms = a[:, 6]
    bad = np.flatnonzero(np.diff(ms) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise GmisInputError(f"line {line_numbers[k]}: tick {ms[k]:.0f} ms does not increase "
                             f"(previous {ms[k - 1]:.0f} ms)", source=src)
    span_s = tag.tick_ms[-1] / 1000.0
    if span_s <= 0.0:
        raise GmisInputError("time tag: last tick is 0 ms; cannot map the IMU ticks",
                             source=src)
    t = tag.start_gps_s + (ms - ms_first) / (ms_last - ms_first) * span_s + time_offset_s
    week = np.floor(t[0] / SECONDS_PER_WEEK)
    return t - week * SECONDS_PER_WEEK, a[:, 3:6], a[:, 0:3], line_numbers, notes


# ----------------------------------------------------------------------------- .pos input

DEFAULT_Q_SIGMA_FACTOR = (1.0, 3.0, 0.0, 0.0, 0.0, 0.0)  # Q=1..6; 0 = excluded


def _sigma_from_recipe(src, columns, noise, name, noise_given, n):
    """(n, 3) σ from the recipe's [noise] value ``name`` for a .pos file without the σ
    columns; refused (GmisInputError) unless the recipe gives it."""
    from gmis.noise_registry import NOISE

    key, unit = NOISE[name].toml_key, NOISE[name].unit
    if not noise.is_explicit(name, noise_given):
        raise GmisInputError(f"header: no {', '.join(columns)} columns; give [noise].{key} "
                             f"({unit}, E N U) in the recipe", source=src)
    value = getattr(noise, name)
    print(f"gmis: note: {src}: no {', '.join(columns)} columns: σ from [noise].{key} = "
          f"[{', '.join(f'{v:g}' for v in value)}] {unit}", file=sys.stderr)
    return np.tile(np.asarray(value, dtype=float), (n, 1))


def read_gnss_pos(path, q_sigma_factor=DEFAULT_Q_SIGMA_FACTOR, noise=None,
                  noise_given=frozenset()):
    """RTKLIB .pos → gmis.readers.GnssSolution (GPS seconds of week, ENU sigmas).

    Position σ: (sde, sdn, sdu) — the diagonal of the NEU covariance; the cross terms
    sdne/sdeu/sdun are read but not used (the loosely coupled update takes per-axis σ).
    Velocity (ve, vn, vu) and σ (sdve, sdvn, sdvu) when the file has vn(m/s)...; σ columns
    absent → the recipe's [noise].gnss_position_m / gnss_velocity_m_s, only when the recipe
    gives them (NoiseSection.is_explicit with noise_given, Recipe.noise_given; a note says
    so), else an error: the registry default is RTK grade. Quality: q_sigma_factor[Q−1] multiplies both σ of an epoch
    of quality Q; 0 excludes it (Q=0 and Q>6 are always excluded)."""
    from gmis.recipe import NoiseSection
    from gnss.errors import GnssInputError
    from gnss.pos_file import read_pos

    noise = noise or NoiseSection()
    src = str(path)
    try:
        sol = read_pos(path)
    except GnssInputError as exc:
        raise GmisInputError(str(exc).removeprefix(f"{src}: "), source=src) from None
    except OSError as exc:
        raise GmisInputError(f"cannot read: {exc.strerror}", source=src) from None
    col, q = sol["columns"], sol["q"]
    n = q.size
    factor = np.zeros(n)
    ok = (q >= 1) & (q <= len(q_sigma_factor))
    factor[ok] = np.asarray(q_sigma_factor, float)[q[ok] - 1]
    keep = factor > 0.0
    if not keep.any():
        raise GmisInputError(f"no epoch with a used quality (Q counts: "
                             f"{dict(zip(*np.unique(q, return_counts=True)))}; "
                             "[gnss_pos].q_sigma_factor)", source=src)

    def group(names, sigma_name=None):
        present = [c in col for c in names]
        if not any(present):
            if sigma_name is None:
                return None
            return _sigma_from_recipe(src, names, noise, sigma_name, noise_given, n)
        if not all(present):
            raise GmisInputError(f"header has {[c for c in names if c in col]} without "
                                 f"{[c for c in names if c not in col]}", source=src)
        return np.abs(np.column_stack([col[c] for c in names]))

    pos_sigma = group(("sde(m)", "sdn(m)", "sdu(m)"), "gnss_position_sigma_m")
    vel = vel_sigma = None
    if any(c in col for c in ("vn(m/s)", "ve(m/s)", "vu(m/s)")):
        group(("ve(m/s)", "vn(m/s)", "vu(m/s)"))  # all three or none
        vel = np.column_stack([col["ve(m/s)"], col["vn(m/s)"], col["vu(m/s)"]])
        vel_sigma = group(("sdve", "sdvn", "sdvu"), "gnss_velocity_sigma_m_s")
    for name, s in (("position", pos_sigma), ("velocity", vel_sigma)):
        if s is not None:
            bad = np.flatnonzero(keep & ~(s.min(axis=1) > 0.0))
            if bad.size:
                raise GmisInputError(f"record {int(bad[0]) + 1}: {name} sigma must be > 0",
                                     source=src)
    t = sol["t_gps"]
    week = np.floor(t[0] / SECONDS_PER_WEEK)
    f = factor[keep, None]
    return GnssSolution(
        t=t[keep] - week * SECONDS_PER_WEEK, llh=sol["llh"][keep],
        pos_sigma=pos_sigma[keep] * f,
        vel_enu=None if vel is None else vel[keep],
        vel_sigma=None if vel_sigma is None else vel_sigma[keep] * f,
        q=q[keep], ns=sol["ns"][keep], gps_week=int(week))
