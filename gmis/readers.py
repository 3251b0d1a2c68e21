"""Readers for the dataset files of docs/formats.md → plain numpy dataclasses (SI, rad).

The CSV parser reads a file's text once and converts it with one ``np.fromstring`` call
(a 360 000-row IMU file loads in well under a second); only when that fast path finds a
problem does it walk the lines to report the exact line number. Every problem raises
:class:`gmis.errors.GmisInputError` naming the file (and the line where there is one);
recoverable oddities (IMU gaps) are collected as ``warnings`` on the returned object.
"""

from __future__ import annotations

import difflib
import sys
import warnings as _warnings
from dataclasses import replace
from itertools import repeat
from pathlib import Path

import numpy as np

from gmis.errors import GmisInputError
from gmis.noise_registry import NOISE
from gmis.recipe import DEG, GnssSection, ImuSection, NoiseSection, Recipe
from gmis.sensor_data import (
    Dataset,
    GnssSolution,
    HeadingData,
    ImuData,
    ReferenceTrajectory,
)
from gmis.text_blocks import LineNumbers
from gnss.constants import SECONDS_PER_WEEK

RATE_TOLERANCE = 0.05  # measured IMU rate may differ from [imu].rate_hz by this fraction
GAP_SAMPLES = 5.0  # an IMU interval longer than this many nominal samples is a gap
# A gap longer than this stops the run (docs/formats.md "IMU gaps"): the filter would
# predict across it with no IMU and, for minutes, diverge to NaN. Shorter gaps are
# listed as warnings (stderr and summary.json) and bridged with the measured interval.
MAX_GAP_S = 1.0
MAX_LISTED_WARNINGS = 20


# ----------------------------------------------------------------------------- CSV table


class _Table:
    """A parsed numeric text table: ``names`` (None without a header), ``line_numbers``
    (LineNumbers of the rows) and the values kept as the parsed blocks ((rows, columns)
    float64 each); :meth:`column` joins one column of them (a fresh compact array), so
    a table never holds a second whole copy of itself."""

    def __init__(self, path, names, blocks, line_numbers, n_cols: int | None = None):
        self.path = Path(path)
        self.names = names
        self._blocks = [np.asarray(b, dtype=np.float64) for b in blocks]
        self.line_numbers = line_numbers if isinstance(line_numbers, LineNumbers) \
            else LineNumbers.of(line_numbers)
        self.n_rows = sum(b.shape[0] for b in self._blocks)
        self.n_cols = n_cols if n_cols is not None else \
            (self._blocks[0].shape[1] if self._blocks else 0)
        self.time_span = None   # (first, last) time of the file when read_table kept a window

    @property
    def data(self) -> np.ndarray:
        """(rows, columns) float64, the whole table (a new array)."""
        if not self._blocks:
            return np.empty((0, self.n_cols))
        return np.concatenate(self._blocks) if len(self._blocks) > 1 else self._blocks[0]

    def fail(self, message: str, row: int | None = None):
        where = f" (line {int(self.line_numbers[row])})" if row is not None else ""
        raise GmisInputError(f"{message}{where}", source=str(self.path))

    def index_of(self, column: str | int, what: str) -> int:
        if isinstance(column, int):
            if column >= self.n_cols:
                self.fail(f"{what}: column index {column} out of range; the file has "
                          f"{self.n_cols} columns")
            return column
        if self.names is None:
            self.fail(f"{what}: column {column!r} requested by name but the file has no "
                      "header line")
        if column not in self.names:
            close = difflib.get_close_matches(column, self.names, n=1, cutoff=0.5)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            self.fail(f"missing column {column!r}{hint}; header has: " + ", ".join(self.names))
        return self.names.index(column)

    def take(self, columns, what: str = "column") -> np.ndarray:
        """(rows, len(columns)) float64 of those columns, filled block by block while the
        table lets go of each block: the table is empty afterwards, and since a fresh
        array's pages count only once written, memory stays about one table. Non-finite
        values fail as in :meth:`column`, column by column in the order given."""
        index = [self.index_of(c, what) for c in columns]
        out = np.empty((self.n_rows, len(index)))
        r = 0
        blocks, self._blocks = self._blocks, []
        while blocks:
            b = blocks.pop(0)
            out[r:r + b.shape[0]] = b[:, index]
            r += b.shape[0]
            del b
        bad = ~np.isfinite(out)
        if bad.any():
            for j, c in enumerate(index):
                rows = np.flatnonzero(bad[:, j])
                if rows.size:
                    name = self.names[c] if self.names else f"#{c}"
                    self.fail(f"non-finite value {out[rows[0], j]} in column {name!r}",
                              int(rows[0]))
        return out

    def column(self, column: str | int, what: str = "column") -> np.ndarray:
        j = self.index_of(column, what)
        values = np.concatenate([b[:, j] for b in self._blocks]) if self._blocks \
            else np.empty(0)
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            name = self.names[j] if self.names else f"#{j}"
            self.fail(f"non-finite value {values[bad[0]]} in column {name!r}", int(bad[0]))
        return values


def _is_content(line: str) -> bool:
    """Not blank and not a ``#`` comment."""
    stripped = line.strip()
    return bool(stripped) and not stripped.startswith("#")


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _split(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return line.split()
    return [tok.strip() for tok in line.split(delimiter)]


def _content(lines: list[str], text: str, first_line: int, skip: int = 0):
    """(content lines, their 1-based line numbers or None when they are all the lines
    from ``skip`` on) of one block of ``text``."""
    body = lines[skip:] if skip else lines
    if "#" not in text[text.find(body[0]) if body else 0:] and all(body) \
            and not any(map(str.isspace, body)):
        return body, None
    keep = [i for i in range(skip, len(lines)) if _is_content(lines[i])]
    return [lines[i] for i in keep], [first_line + i for i in keep]


def _column_counts(lines: list[str], delimiter: str | None) -> np.ndarray:
    if delimiter is not None:
        return np.fromiter(map(str.count, lines, repeat(delimiter)), dtype=np.int64,
                           count=len(lines)) + 1
    return np.fromiter(map(len, map(str.split, lines)), dtype=np.int64, count=len(lines))


def _parse_block(lines: list[str], ncol: int, delimiter: str | None) -> np.ndarray | None:
    """(rows, ncol) float64 of lines with the right column count, or None if one value
    does not parse (the caller then locates it)."""
    sep = delimiter if delimiter is not None else " "
    with _warnings.catch_warnings():
        _warnings.simplefilter("error")
        try:
            values = np.fromstring(sep.join(lines), dtype=np.float64, sep=sep)
        except (DeprecationWarning, ValueError):
            return None
    if values.size != len(lines) * ncol:
        return None
    return values.reshape(len(lines), ncol)


def _time_of_line(delimiter, ncol: int, index: int, to_time):
    """line → its time (to_time of the value in column index), None when the line does
    not have ncol values or that value is not a number (gmis.text_window's probes)."""
    def time_of(line: str):
        tokens = _split(line, delimiter)
        if len(tokens) != ncol:
            return None
        try:
            value = float(tokens[index])
        except ValueError:
            return None
        t = float(to_time(np.array([value]))[0])
        return t if np.isfinite(t) else None
    return time_of


def _text_window(path, delimiter, header, time_window):
    """(TextWindow, names, ncol, delimiter) of read_table's time_window, or None."""
    from gmis.text_window import HEAD_BYTES, time_window_bytes

    column, to_time, start, end, margin_s, *rest = time_window
    max_step_s = rest[0] if rest else None
    if start is None and end is None:
        return None
    try:
        with open(path, "rb") as fh:
            raw = fh.read(HEAD_BYTES)
    except OSError:
        return None
    lines = raw.decode("utf-8-sig", errors="replace").splitlines()
    if len(raw) == HEAD_BYTES:
        lines = lines[:-1]                   # the last may be cut
    first = next((line for line in lines if _is_content(line)), None)
    if first is None:
        return None
    if delimiter == "auto":
        delimiter = "," if "," in first else None
    tokens = _split(first, delimiter)
    has_header = header == "required" or not all(_is_number(tok) for tok in tokens)
    names = tokens if has_header else None
    if isinstance(column, int):
        index = column
    elif names is not None and column in names:
        index = names.index(column)
    else:
        return None
    if index >= len(tokens) or (names is not None and (len(set(names)) != len(names)
                                                       or not all(names))):
        return None                    # the whole read reports what is wrong
    window = time_window_bytes(path, _time_of_line(delimiter, len(tokens), index, to_time),
                               _is_content, start, end, margin_s, header=has_header,
                               max_step_s=max_step_s)
    return None if window is None else (window, names, len(tokens), delimiter)


def read_table(path, delimiter: str | None = ",", header: str = "required",
               block_bytes: int | None = None, on_block=None, time_window=None) -> _Table:
    """Read a delimited numeric text file: ``#`` comment and blank lines are skipped, the
    first other line is the header (``header="required"``) or, with ``header="optional"``,
    a header only if it is not all numbers. ``delimiter=None`` splits on whitespace;
    ``"auto"`` picks "," if the first content line has one, else whitespace.

    The file is read in blocks of lines (gmis.text_blocks), each parsed by one
    ``np.fromstring`` call into a float64 block: memory is the table plus one block of
    text. Only when a block fails does a second pass walk the file line by line to report
    the first wrong column count (anywhere in the file), else the first non-numeric
    value, with its line number.

    on_block(names, values): called with each parsed (rows, columns) block in file order
    instead of keeping it (the returned table then holds no values, only the names, the
    row count and the line numbers); the errors are the same, raised after the blocks
    before the failing one were handed over.

    time_window (time column, to_time, start, end, margin_s[, max_step_s]): the rows of a
    file in time order that a [time] window needs — to_time(column values) → times in the
    window's base, start/end (None: open), max_step_s the largest step that is no gap
    (a gap or a disorder at either cut reads the whole file: gmis.text_window). A large file is then read only from the line where
    start − margin_s is reached to the one past end + margin_s (gmis.text_window, by
    bisection over byte offsets; the table's ``time_span`` holds the times of the file's
    first and last data lines, its line numbers stay those of the file); a small file, or
    one the bisection cannot trust, is read whole (``time_span`` None)."""
    from gmis.text_blocks import BLOCK_BYTES, count_lines_before, line_blocks

    path = Path(path)
    names = None
    ncol = None
    blocks = []
    numbers = LineNumbers()
    failed = False
    byte_range = None
    found = None if time_window is None or not path.is_file() else \
        _text_window(path, delimiter, header, time_window)
    if found is not None:
        window, names, ncol, delimiter = found
        byte_range = (window.byte_start, window.byte_end)
        numbers = LineNumbers(lines_before=lambda: count_lines_before(path, byte_range[0]))

    def line_number(n: int) -> int:
        return n + numbers.base if byte_range is not None else n

    for lines, first_line, text in line_blocks(path, block_bytes or BLOCK_BYTES, byte_range):
        skip = 0
        if ncol is None:              # the header (or first data line) is in this block
            k = next((i for i, line in enumerate(lines) if _is_content(line)), None)
            if k is None:
                continue
            if delimiter == "auto":
                delimiter = "," if "," in lines[k] else None
            first = _split(lines[k], delimiter)
            has_header = header == "required" or not all(_is_number(tok) for tok in first)
            if has_header:
                names = first
                if any(not name for name in names):
                    raise GmisInputError(f"empty column name in header (line "
                                         f"{first_line + k})", source=str(path))
                duplicates = sorted({n for n in names if names.count(n) > 1})
                if duplicates:
                    raise GmisInputError(f"duplicate column name(s) {duplicates} in header "
                                         f"(line {first_line + k})", source=str(path))
                skip = k + 1
            else:
                skip = k
            ncol = len(first)
        data_lines, line_nos = _content(lines, text, first_line, skip)
        if not data_lines:
            continue
        counts = _column_counts(data_lines, delimiter)
        wrong = np.flatnonzero(counts != ncol)
        if wrong.size:
            k = int(wrong[0])
            number = line_nos[k] if line_nos is not None else first_line + skip + k
            raise GmisInputError(f"line {line_number(number)}: {counts[k]} columns, "
                                 f"expected {ncol}"
                                 + (" (as in the header)" if names is not None else ""),
                                 source=str(path))
        if failed:
            continue                  # only the column counts of the rest are checked
        values = _parse_block(data_lines, ncol, delimiter)
        if values is None:
            failed = True
            blocks = []
            continue
        if line_nos is None:
            numbers.add_run(first_line + skip, len(data_lines))
        else:
            numbers.add_lines(line_nos)
        if on_block is None:
            blocks.append(values)
        else:
            on_block(names, values)
        del values
    if ncol is None:
        raise GmisInputError("empty file (no header and no data lines)", source=str(path))
    if failed:
        _locate_bad_token(path, delimiter, header, block_bytes or BLOCK_BYTES, byte_range,
                          line_number)
        raise GmisInputError("could not parse the numeric data", source=str(path))
    if numbers.size == 0:
        raise GmisInputError("no data lines after the header", source=str(path))
    table = _Table(path, names, blocks, numbers, ncol)
    table.n_rows = numbers.size
    if found is not None:
        table.time_span = (found[0].first_time, found[0].last_time)
    return table


def _locate_bad_token(path, delimiter, header, block_bytes, byte_range=None,
                      line_number=int):
    """Slow path: find the first token that is not a number and report its line (in the
    bytes byte_range only, all data lines, when given)."""
    from gmis.text_blocks import line_blocks

    started = byte_range is not None
    for lines, first_line, _ in line_blocks(path, block_bytes, byte_range):
        for i, line in enumerate(lines):
            if not _is_content(line):
                continue
            if not started:           # the header line (or the first data line)
                started = True
                if header == "required" or not all(_is_number(tok) for tok in
                                                   _split(line, delimiter)):
                    continue
            for j, token in enumerate(_split(line, delimiter)):
                try:
                    float(token)
                except ValueError:
                    shown = repr(token) if token else "empty value"
                    raise GmisInputError(f"line {line_number(first_line + i)}: non-numeric "
                                         f"value {shown} in column {j + 1}",
                                         source=str(path)) from None


def _check_time(table: _Table, t: np.ndarray) -> None:
    """Strictly increasing time, with the offending line named."""
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0.0)
    if bad.size:
        k = int(bad[0]) + 1
        kind = "duplicate time" if dt[k - 1] == 0.0 else "time goes backwards"
        table.fail(f"{kind} at line {int(table.line_numbers[k])}: t={t[k]:.6f} s follows "
                   f"t={t[k - 1]:.6f} s at line {int(table.line_numbers[k - 1])}; time must "
                   "be strictly increasing")


def _check_latlon(table: _Table, lat_deg: np.ndarray, lon_deg: np.ndarray) -> None:
    bad = np.flatnonzero(np.abs(lat_deg) > 90.0)
    if bad.size:
        table.fail(f"latitude {lat_deg[bad[0]]} deg out of range [-90, 90]", int(bad[0]))
    bad = np.flatnonzero((lon_deg < -180.0) | (lon_deg > 360.0))
    if bad.size:
        table.fail(f"longitude {lon_deg[bad[0]]} deg out of range [-180, 360]", int(bad[0]))


def _check_positive(table: _Table, values: np.ndarray, name: str) -> None:
    bad = np.flatnonzero(values <= 0.0)
    if bad.size:
        table.fail(f"{name} must be > 0, got {values[bad[0]]}", int(bad[0]))


def _check_known_columns(table: _Table, allowed: list[str]) -> None:
    for name in table.names:
        if name not in allowed:
            close = difflib.get_close_matches(name, allowed, n=1, cutoff=0.5)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            table.fail(f"unknown column {name!r}{hint}; allowed: " + ", ".join(allowed))


def _optional_group(table: _Table, names: list[str]) -> np.ndarray | None:
    """All of ``names`` (stacked (M,3)) or None if none present; a partial group is an error."""
    present = [n for n in names if n in table.names]
    if not present:
        return None
    if len(present) != len(names):
        missing = [n for n in names if n not in present]
        table.fail(f"columns {present} given without {missing}; give all of {names} or none")
    return np.column_stack([table.column(n) for n in names])


def _wrap_lon_rad(lon_deg: np.ndarray) -> np.ndarray:
    return np.where(lon_deg > 180.0, lon_deg - 360.0, lon_deg) * DEG


# ----------------------------------------------------------------------------- readers


def read_imu(path, imu: ImuSection, window=None, on_disk: bool = False) -> ImuData:
    """IMU file → rates in body RFU (rad/s, m/s²). Increments (format="increment") are
    divided by the interval ending at each sample (the nominal 1/rate_hz for the first
    sample and across gaps). Rate must match ``imu.rate_hz`` within 5 %.

    window: (start, end) GPS s (None = open) → only those samples are converted and
    kept; the result then has ``file_span`` = the first and last time of the whole file.
    A file of more than gmis.text_window.WINDOW_MIN_BYTES is then parsed only from
    WINDOW_MARGIN_S (+ 2 samples) before the window to as much after it (found by
    bisection over byte offsets), and only those time tags are checked (order, rate,
    gaps, clock: jittery tags are fitted to a uniform clock over the tags read, so times
    may differ from a whole-file read by up to one interval); a smaller file, one whose
    order a bisection cannot trust, or one with a gap or disorder at a cut is parsed
    whole and all its tags are checked.

    on_disk: the samples go block by block to a temporary file (gmis.imu_spool) and
    only the time tags stay in memory; gyro / accel are then SpooledColumns (the same
    values, the same errors)."""
    delimiter = "," if imu.delimiter == "," else None
    all_indices = all(isinstance(c, int) for c in
                      (imu.time_column, *imu.gyro_columns, *imu.accel_columns))
    if imu.time_base == "tag":
        raise GmisInputError("[imu].time_base = \"tag\" needs the .tag file: "
                             "gmis.readers_rtklib / load_dataset", source=str(path))
    if on_disk:
        return _read_imu_to_disk(path, imu, window, delimiter, all_indices)
    table = read_table(path, delimiter, header="optional" if all_indices else "required",
                       time_window=_imu_time_window(imu, window))
    t = table.column(imu.time_column, "[imu].time_column")
    for c in imu.gyro_columns:        # named like this in a wrong-column message
        table.index_of(c, "[imu].gyro_columns")
    raw = table.take([*imu.gyro_columns, *imu.accel_columns], "[imu].accel_columns")
    t = _to_gps_seconds_of_week(t, imu.time_base) + imu.time_offset_s
    return imu_from_raw(table, imu, t, raw, window)


WINDOW_MARGIN_S = 1.0   # IMU time read on either side of a [time] window (+ 2 samples)


def _imu_time_window(imu: ImuSection, window):
    """read_table's time_window of an IMU file for the [time] window (start, end)."""
    if window is None:
        return None
    def to_time(t):
        return _to_gps_seconds_of_week(t, imu.time_base) + imu.time_offset_s
    # a step the reader would warn about as a gap (GAP_SAMPLES) at either cut reads the
    # whole file, so the gap warnings and line numbers are the whole file's
    return (imu.time_column, to_time, window[0], window[1],
            WINDOW_MARGIN_S + 2.0 / imu.rate_hz, GAP_SAMPLES / imu.rate_hz)


def _read_imu_to_disk(path, imu: ImuSection, window, delimiter, all_indices) -> ImuData:
    """read_imu with the samples streamed to disk: each parsed block's time column is
    kept, its six sample columns appended to a raw ImuSpool; the errors are raised after
    the whole file was read, in read_imu's order (the time column's index, its first
    non-finite value, the gyro / accel columns' indices, then the first non-finite value
    of each sample column in column order)."""
    from gmis.imu_spool import ImuSpool

    raw = ImuSpool()
    state = {}
    t_parts = []
    first_bad = {}                   # sample column position → (row, value)
    seen = [0]

    def resolve(names, n_cols):
        probe = _Table(path, names, [], LineNumbers(), n_cols)
        try:
            state["time"] = probe.index_of(imu.time_column, "[imu].time_column")
        except GmisInputError as exc:
            state["error"] = exc
            return
        try:
            for c in imu.gyro_columns:
                probe.index_of(c, "[imu].gyro_columns")
            state["cols"] = [probe.index_of(c, "[imu].accel_columns")
                             for c in (*imu.gyro_columns, *imu.accel_columns)]
        except GmisInputError as exc:
            state["late_error"] = exc     # raised after the time column's checks

    def on_block(names, values):
        if not state:
            resolve(names, values.shape[1])
        if "error" in state:
            return
        r0 = seen[0]
        seen[0] += values.shape[0]
        t_parts.append(values[:, state["time"]].copy())
        if "cols" not in state:
            return
        block = values[:, state["cols"]]
        bad = ~np.isfinite(block)
        if bad.any():
            for j in range(6):
                rows = np.flatnonzero(bad[:, j])
                if rows.size and j not in first_bad:
                    first_bad[j] = (r0 + int(rows[0]), block[rows[0], j])
        raw.append(block)

    try:
        table = read_table(path, delimiter, header="optional" if all_indices else "required",
                           on_block=on_block, time_window=_imu_time_window(imu, window))
        if "error" in state:
            raise state["error"]
        t = np.concatenate(t_parts) if t_parts else np.empty(0)
        del t_parts[:]
        bad_t = np.flatnonzero(~np.isfinite(t))
        if bad_t.size:
            j = state["time"]
            name = table.names[j] if table.names else f"#{j}"
            table.fail(f"non-finite value {t[bad_t[0]]} in column {name!r}", int(bad_t[0]))
        if "late_error" in state:
            raise state["late_error"]
        for j, c in enumerate(state["cols"]):
            if j in first_bad:
                name = table.names[c] if table.names else f"#{c}"
                row, value = first_bad[j]
                table.fail(f"non-finite value {value} in column {name!r}", row)
        raw.finish()
        t = _to_gps_seconds_of_week(t, imu.time_base) + imu.time_offset_s
        return imu_from_raw(table, imu, t, raw, window)
    finally:
        raw.remove()


def _to_gps_seconds_of_week(t: np.ndarray, time_base: str) -> np.ndarray:
    """[imu].time_base / [gnss].time_base: "gps" (unchanged), "gps_1980" (s since
    1980-01-06 → seconds of week), "unix_utc" (Unix seconds, UTC → GPST seconds of week,
    the leap seconds of gmis.leap_seconds added: 18 s since 2017-01-01)."""
    if time_base == "gps":
        return t
    if time_base == "unix_utc":
        from gmis.leap_seconds import unix_utc_to_gps_s
        t = unix_utc_to_gps_s(t)
    return t - np.floor(t[0] / SECONDS_PER_WEEK) * SECONDS_PER_WEEK


def read_imu_tagged(path, tag_path, imu: ImuSection, window=None,
                    on_disk: bool = False) -> ImuData:
    """Raw tick-counter IMU CSV + RTKLIB .tag (gmis.readers_rtklib) → ImuData (body RFU,
    GPS seconds of week). Partial first/last lines are noted on stderr and in warnings.
    window, on_disk: as in read_imu (here the samples are converted in memory, then
    written to the spool)."""
    from gmis.readers_rtklib import read_tick_imu_csv, read_time_tag

    tag = read_time_tag(tag_path)
    t, gyro, accel, line_numbers, notes = read_tick_imu_csv(path, tag, imu.time_offset_s)
    table = _Table(Path(path), None, [], line_numbers, n_cols=7)
    data = imu_from_columns(table, imu, t, gyro, accel, window)
    del gyro, accel
    if on_disk:
        from gmis.imu_spool import spool_array
        spool = spool_array(data.z)
        data = replace(data, gyro=spool.columns(0), accel=spool.columns(3))
    for note in notes:
        print(f"gmis: note: {note}", file=sys.stderr)
    return replace(data, warnings=tuple(notes) + data.warnings)


def imu_from_columns(table: _Table, imu: ImuSection, t, gyro, accel, window=None) -> ImuData:
    """imu_from_raw of gyro (N,3) and accel (N,3) in the file's units."""
    raw = np.empty((t.size, 6))
    raw[:, :3] = gyro
    raw[:, 3:] = accel
    return imu_from_raw(table, imu, t, raw, window)


ROTATE_ROWS = 65536   # rows per in-place sensor → body rotation step


def imu_from_raw(table: _Table, imu: ImuSection, t, raw, window=None) -> ImuData:
    """Time/rate checks, gap warnings, units → SI and sensor → body RFU (read_imu) of
    raw (N, 6) [gyro, accel] in the file's units, converted in place (it becomes the
    ImuData's storage, ImuData.z); with a window (start, end) only the samples
    start <= t <= end are converted and kept."""
    if t.size < 2:
        table.fail(f"only {t.size} IMU sample(s); need at least 2")
    _check_time(table, t)
    warnings = []
    if imu.uniform_clock:
        from gmis.imu_clock import uniform_clock_times
        t, clock = uniform_clock_times(t)
        note = clock.note(str(table.path))
        if note is not None:          # printed with the dataset's warnings (announce)
            warnings.append(note)

    dt = np.diff(t)
    nominal_dt = 1.0 / imu.rate_hz
    measured_rate = 1.0 / float(np.median(dt))
    if abs(measured_rate / imu.rate_hz - 1.0) > RATE_TOLERANCE:
        table.fail(f"measured IMU rate {measured_rate:.4g} Hz differs from [imu].rate_hz = "
                   f"{imu.rate_hz:g} Hz by more than {RATE_TOLERANCE:.0%}")

    gaps = np.flatnonzero(dt > GAP_SAMPLES * nominal_dt)
    for k in gaps[:MAX_LISTED_WARNINGS]:
        warnings.append(f"{table.path}: gap of {dt[k]:.3f} s ({dt[k] / nominal_dt:.0f} samples)"
                        f" after t={t[k]:.3f} s (line {int(table.line_numbers[k])})")
    if gaps.size > MAX_LISTED_WARNINGS:
        warnings.append(f"{table.path}: {gaps.size - MAX_LISTED_WARNINGS} more gaps not listed")

    interval = None
    if imu.format == "increment":
        interval = np.empty_like(t)
        interval[0] = nominal_dt
        interval[1:] = np.where(dt > 1.5 * nominal_dt, nominal_dt, dt)
    del dt
    span = table.time_span if getattr(table, "time_span", None) is not None \
        else (float(t[0]), float(t[-1]))
    keep = _window_slice(t, window)
    if not isinstance(raw, np.ndarray):     # an ImuSpool of the raw rows (read_imu on_disk)
        return _converted_on_disk(imu, t, raw, keep, interval, warnings, span)
    if keep is not None:
        t, raw = t[keep].copy(), raw[keep].copy()
        interval = None if interval is None else interval[keep]
    z = raw               # converted in place, row blocks: the same values as whole arrays
    z[:, :3] *= imu.gyro_to_si
    z[:, 3:] *= imu.accel_to_si
    if interval is not None:
        z /= interval[:, None]
    m_t = imu.sensor_to_body.T
    for r in range(0, t.size, ROTATE_ROWS):
        rows = z[r:r + ROTATE_ROWS]
        rows[:, :3] = rows[:, :3] @ m_t
        rows[:, 3:] = rows[:, 3:] @ m_t
    return ImuData(t=np.ascontiguousarray(t), gyro=z[:, :3], accel=z[:, 3:],
                   warnings=tuple(warnings), file_span=span)


def _converted_on_disk(imu: ImuSection, t, raw, keep, interval, warnings, span) -> ImuData:
    """imu_from_raw's conversion of the raw rows of an ImuSpool (those of the window
    slice keep), block by block into a new ImuSpool: the same operations on the same row
    blocks of ROTATE_ROWS (counted from the window's first row) as the in-place
    conversion, so the same values."""
    from gmis.imu_spool import ImuSpool

    lo, hi = (0, t.size) if keep is None else (keep.start, keep.stop)
    if keep is not None:
        t = t[keep].copy()
        interval = None if interval is None else interval[keep]
    m_t = imu.sensor_to_body.T
    out = ImuSpool()
    try:
        for r in range(0, hi - lo, ROTATE_ROWS):
            z = raw.rows(lo + r, min(hi, lo + r + ROTATE_ROWS))
            z[:, :3] *= imu.gyro_to_si
            z[:, 3:] *= imu.accel_to_si
            if interval is not None:
                z /= interval[r:r + z.shape[0], None]
            z[:, :3] = z[:, :3] @ m_t
            z[:, 3:] = z[:, 3:] @ m_t
            out.append(z)
    except BaseException:
        out.remove()
        raise
    out.finish()
    return ImuData(t=np.ascontiguousarray(t), gyro=out.columns(0), accel=out.columns(3),
                   warnings=tuple(warnings), file_span=span)


def _window_slice(t: np.ndarray, window) -> slice | None:
    """The rows start <= t <= end of increasing t (a slice), or None for all of them."""
    if window is None:
        return None
    start, end = window
    lo = 0 if start is None else int(np.searchsorted(t, start, side="left"))
    hi = t.size if end is None else int(np.searchsorted(t, end, side="right"))
    if lo == 0 and hi == t.size:
        return None
    return slice(lo, hi)


GNSS_COLUMNS = ["time_gps_s", "lat_deg", "lon_deg", "h_m", "sigma_e_m", "sigma_n_m",
                "sigma_u_m", "ve_m_s", "vn_m_s", "vu_m_s", "sigma_ve_m_s", "sigma_vn_m_s",
                "sigma_vu_m_s", "speed_m_s", "course_deg", "sigma_speed_m_s",
                "sigma_course_deg"]


def _sigma_from_recipe(table: _Table, noise: NoiseSection, name: str, columns: str,
                       given=frozenset()):
    """The recipe's [noise] σ for a file without sigma columns: refused unless the recipe
    gives it (NoiseSection.is_explicit) — the registry default is RTK grade (2/2/4 cm),
    ~100× too tight for a consumer receiver's own fix; a note says which σ are used."""
    key = NOISE[name].toml_key
    if not noise.is_explicit(name, given):
        table.fail(f"{columns}: no sigma columns; give [noise].{key} ({NOISE[name].unit}, "
                   "E N U) in the recipe or add the columns")
    value = getattr(noise, name)
    print(f"gmis: note: {table.path}: no {columns} columns: σ from [noise].{key} = "
          f"[{', '.join(f'{v:g}' for v in value)}] {NOISE[name].unit}", file=sys.stderr)
    return np.tile(np.asarray(value, dtype=float), (table.n_rows, 1))


def read_gnss_solution(path, noise: NoiseSection | None = None,
                       gnss: GnssSection | None = None,
                       noise_given=frozenset()) -> GnssSolution:
    """GNSS position (+ optional velocity) solution; missing sigma columns are taken from
    ``noise.gnss_position_sigma_m`` / ``gnss_velocity_sigma_m_s`` only when the recipe
    gives them (in noise_given, Recipe.noise_given, or not the registry default; else an
    error). Time stamps: [gnss].time_base → GPS seconds of week, then
    + [gnss].time_offset_s (docs/formats.md)."""
    noise = noise or NoiseSection()
    gnss = gnss or GnssSection()
    table = read_table(path, "auto")
    _check_known_columns(table, GNSS_COLUMNS)
    t = table.column("time_gps_s")
    lat, lon, h = (table.column(c) for c in ("lat_deg", "lon_deg", "h_m"))
    _check_time(table, t)
    t = _to_gps_seconds_of_week(t, gnss.time_base) + gnss.time_offset_s
    _check_latlon(table, lat, lon)
    llh = np.column_stack([lat * DEG, _wrap_lon_rad(lon), h])

    pos_sigma = _optional_group(table, ["sigma_e_m", "sigma_n_m", "sigma_u_m"])
    if pos_sigma is None:
        pos_sigma = _sigma_from_recipe(table, noise, "gnss_position_sigma_m",
                                       "sigma_e_m, sigma_n_m, sigma_u_m", noise_given)
    else:
        _check_positive(table, pos_sigma.min(axis=1), "position sigma")
    vel = _optional_group(table, ["ve_m_s", "vn_m_s", "vu_m_s"])
    vel_sigma = _optional_group(table, ["sigma_ve_m_s", "sigma_vn_m_s", "sigma_vu_m_s"])
    if vel is None and vel_sigma is not None:
        table.fail("velocity sigma columns given without ve_m_s, vn_m_s, vu_m_s")
    if vel is not None and vel_sigma is None:
        vel_sigma = _sigma_from_recipe(table, noise, "gnss_velocity_sigma_m_s",
                                       "sigma_ve_m_s, sigma_vn_m_s, sigma_vu_m_s", noise_given)
    elif vel_sigma is not None:
        _check_positive(table, vel_sigma.min(axis=1), "velocity sigma")
    sog, sog_sigma = _speed_course(table, noise, gnss, noise_given)
    if sog is not None and vel is not None:
        table.fail("speed_m_s, course_deg given with ve_m_s, vn_m_s, vu_m_s: give one "
                   "velocity form")
    return GnssSolution(t=t, llh=llh, pos_sigma=pos_sigma, vel_enu=vel, vel_sigma=vel_sigma,
                        speed_course=sog, speed_course_sigma=sog_sigma)


def _speed_course(table: _Table, noise: NoiseSection, gnss: GnssSection, given):
    """(speed m/s, course rad) and their σ (M, 2) from speed_m_s, course_deg and
    sigma_speed_m_s, sigma_course_deg (absent σ: the recipe's [noise].gnss_speed_m_s /
    gnss_course_deg, refused unless given); the course σ of epochs slower than
    [gnss].course_min_speed_m_s is NaN (course not used). (None, None) without the
    columns."""
    sog = _optional_group(table, ["speed_m_s", "course_deg"])
    sog_sigma = _optional_group(table, ["sigma_speed_m_s", "sigma_course_deg"])
    if sog is None:
        if sog_sigma is not None:
            table.fail("sigma_speed_m_s, sigma_course_deg given without speed_m_s, "
                       "course_deg")
        return None, None
    if np.any(sog[:, 0] < 0):
        table.fail("speed_m_s must be >= 0", int(np.flatnonzero(sog[:, 0] < 0)[0]))
    sog = np.column_stack([sog[:, 0], np.mod(sog[:, 1] * DEG, 2.0 * np.pi)])
    if sog_sigma is None:
        sog_sigma = np.empty_like(sog)
        for i, (name, column) in enumerate((("gnss_speed_sigma_m_s", "sigma_speed_m_s"),
                                            ("gnss_course_sigma_rad", "sigma_course_deg"))):
            key, unit = NOISE[name].toml_key, NOISE[name].unit
            if not noise.is_explicit(name, given):
                table.fail(f"{column}: no sigma column; give [noise].{key} ({unit}) in the "
                           "recipe or add the column")
            value = getattr(noise, name)
            print(f"gmis: note: {table.path}: no {column} column: σ from [noise].{key} = "
                  f"{value / NOISE[name].to_si:g} {unit}", file=sys.stderr)
            sog_sigma[:, i] = value
    else:
        _check_positive(table, sog_sigma.min(axis=1), "speed/course sigma")
        sog_sigma = np.column_stack([sog_sigma[:, 0], sog_sigma[:, 1] * DEG])
    sog_sigma[sog[:, 0] < gnss.course_min_speed_m_s, 1] = np.nan
    return sog, sog_sigma


def read_heading(path, noise: NoiseSection | None = None) -> HeadingData:
    """Heading solution (deg in the file) → rad; missing sigma → ``noise.heading_sigma_rad``."""
    noise = noise or NoiseSection()
    table = read_table(path, "auto")
    _check_known_columns(table, ["time_gps_s", "heading_deg", "sigma_heading_deg"])
    t = table.column("time_gps_s")
    heading = table.column("heading_deg") * DEG
    _check_time(table, t)
    if "sigma_heading_deg" in table.names:
        sigma = table.column("sigma_heading_deg")
        _check_positive(table, sigma, "sigma_heading_deg")
        sigma = sigma * DEG
    else:
        sigma = np.full(t.size, noise.heading_sigma_rad)
    return HeadingData(t=t, heading=heading, sigma=sigma)


REFERENCE_COLUMNS = ["time_gps_s", "lat_deg", "lon_deg", "h_m", "ve_m_s", "vn_m_s", "vu_m_s",
                     "pitch_deg", "roll_deg", "heading_deg"]


def _reference_window(start, end):
    """read_table's time_window of a reference file for start <= t <= end (None: open)."""
    if start is None and end is None:
        return None
    return (REFERENCE_COLUMNS[0], lambda t: t, start, end, 0.0)


def read_reference(path, window=None) -> ReferenceTrajectory:
    """Reference trajectory (truth at the IMU centre), angles → rad; llh, vel_enu and euler
    are (K, 3) column views of one (K, 10) array (80 bytes per epoch, no copies).
    window (start, end) GPS s: a large file is parsed only there (read_table's
    time_window; the rows outside are the caller's to crop, as load_dataset does)."""
    table = read_table(path, "auto",
                       time_window=None if window is None else _reference_window(*window))
    _check_known_columns(table, REFERENCE_COLUMNS)
    for name in REFERENCE_COLUMNS:
        table.index_of(name, "column")
    v = table.take(REFERENCE_COLUMNS)        # (K, 10) in the order of REFERENCE_COLUMNS
    t = v[:, 0].copy()
    _check_time(table, t)
    _check_latlon(table, v[:, 1], v[:, 2])
    v[:, 1] *= DEG                           # converted in place: llh, vel_enu and
    v[:, 2] = _wrap_lon_rad(v[:, 2])         # euler are column views of the one table
    v[:, 7:10] *= DEG
    return ReferenceTrajectory(t=t, llh=v[:, 1:4], vel_enu=v[:, 4:7], euler=v[:, 7:10])


def read_reference_blocks(path, consume, start: float | None = None,
                          end: float | None = None, block_bytes: int | None = None) -> int:
    """read_reference and load_dataset's [time] crop without the whole table: the file is
    parsed block by block (read_table's on_block) and consume(t, llh, vel_enu, euler) gets
    each block's rows inside start <= t <= end, converted as read_reference converts them
    (the same elementwise operations, so the same values); returns the number of rows
    handed over. The checks are read_reference's and check_dataset's reference
    height, each reporting the first offending row of the rows read as they do
    (non-finite column by column, then time order, latitude, longitude, height), raised
    once the file is read: a consumer must treat what it got as void on an error. The
    rows read are the whole file's, or with start / end and a large file only the
    window's lines (read_table's time_window)."""
    from gmis.plausibility import check_reference_height

    state = {"cols": None, "header_ok": None, "row": 0, "prev_t": None,
             "nonfinite": {}, "time": None, "lat": None, "lon": None, "height": None}
    kept = [0]

    def on_block(names, v):
        if state["header_ok"] is None:
            state["header_ok"] = all(n in REFERENCE_COLUMNS for n in names) and \
                all(n in names for n in REFERENCE_COLUMNS)
            if state["header_ok"]:
                state["cols"] = [names.index(n) for n in REFERENCE_COLUMNS]
        if not state["header_ok"]:
            return                    # the header's error is raised after the file
        r0 = state["row"]
        state["row"] += v.shape[0]
        v = v[:, state["cols"]]       # (k, 10) in the order of REFERENCE_COLUMNS
        bad = ~np.isfinite(v)
        if bad.any():
            for j in np.flatnonzero(bad.any(axis=0)):
                if j not in state["nonfinite"]:
                    k = int(np.flatnonzero(bad[:, j])[0])
                    state["nonfinite"][int(j)] = (r0 + k, v[k, j])
        t = v[:, 0].copy()
        prev = state["prev_t"]
        dt = np.diff(t) if prev is None else np.diff(np.r_[prev, t])
        first = r0 + (1 if prev is None else 0)      # the row of dt[0]'s later sample
        worse = np.flatnonzero(dt <= 0.0)
        if worse.size and state["time"] is None:
            i = int(worse[0])
            later = t[i + 1] if prev is None else t[i]
            earlier = t[i] if prev is None else (prev if i == 0 else t[i - 1])
            state["time"] = (first + i, float(later), float(earlier))
        state["prev_t"] = float(t[-1]) if t.size else prev
        for key, rows in (("lat", np.abs(v[:, 1]) > 90.0),
                          ("lon", (v[:, 2] < -180.0) | (v[:, 2] > 360.0))):
            hit = np.flatnonzero(rows)
            if hit.size and state[key] is None:
                state[key] = (r0 + int(hit[0]), v[int(hit[0]), 1 if key == "lat" else 2])
        v[:, 1] *= DEG                # as read_reference converts its (K, 10) table
        v[:, 2] = _wrap_lon_rad(v[:, 2])
        v[:, 7:10] *= DEG
        keep = np.ones(t.size, dtype=bool)
        if start is not None:
            keep &= t >= start
        if end is not None:
            keep &= t <= end
        if not keep.all():
            v, t = v[keep], t[keep]
        h = v[:, 3]
        out = np.flatnonzero((h < HEIGHT_RANGE_M[0]) | (h > HEIGHT_RANGE_M[1]))
        if out.size and state["height"] is None:
            state["height"] = h[int(out[0])]
        kept[0] += t.size
        consume(t, v[:, 1:4], v[:, 4:7], v[:, 7:10])

    from gmis.plausibility import HEIGHT_RANGE_M

    table = read_table(path, "auto", block_bytes=block_bytes, on_block=on_block,
                       time_window=_reference_window(start, end))
    _check_known_columns(table, REFERENCE_COLUMNS)
    for name in REFERENCE_COLUMNS:
        table.index_of(name, "column")
    for j in range(len(REFERENCE_COLUMNS)):            # as _Table.take: column by column
        if j in state["nonfinite"]:
            row, value = state["nonfinite"][j]
            table.fail(f"non-finite value {value} in column {REFERENCE_COLUMNS[j]!r}", row)
    if state["time"] is not None:
        k, t_k, t_prev = state["time"]
        kind = "duplicate time" if t_k == t_prev else "time goes backwards"
        table.fail(f"{kind} at line {int(table.line_numbers[k])}: t={t_k:.6f} s follows "
                   f"t={t_prev:.6f} s at line {int(table.line_numbers[k - 1])}; time must "
                   "be strictly increasing")
    if state["lat"] is not None:
        table.fail(f"latitude {state['lat'][1]} deg out of range [-90, 90]", state["lat"][0])
    if state["lon"] is not None:
        table.fail(f"longitude {state['lon'][1]} deg out of range [-180, 360]",
                   state["lon"][0])
    if state["height"] is not None:
        check_reference_height(path, np.array([state["height"]]))
    return kept[0]


# ----------------------------------------------------------------------------- dataset


def _crop(obj, start: float | None, end: float | None):
    """Same dataclass with every per-epoch array restricted to start <= t <= end."""
    keep = np.ones(obj.t.size, dtype=bool)
    if start is not None:
        keep &= obj.t >= start
    if end is not None:
        keep &= obj.t <= end
    if keep.all():
        return obj
    changes = {}
    for name, value in vars(obj).items():
        if isinstance(value, np.ndarray) and value.shape[:1] == obj.t.shape:
            changes[name] = value[keep]
    return replace(obj, **changes)


def _scaled_sigmas(noise: NoiseSection, gnss, heading):
    """Per-epoch σ × [noise].gnss_position_scale / gnss_velocity_scale / heading_scale."""
    if gnss is not None and (noise.gnss_position_sigma_scale != 1.0
                             or noise.gnss_velocity_sigma_scale != 1.0):
        gnss = replace(gnss, pos_sigma=gnss.pos_sigma * noise.gnss_position_sigma_scale,
                       vel_sigma=None if gnss.vel_sigma is None
                       else gnss.vel_sigma * noise.gnss_velocity_sigma_scale)
    if heading is not None and noise.heading_sigma_scale != 1.0:
        heading = replace(heading, sigma=heading.sigma * noise.heading_sigma_scale)
    return gnss, heading


def load_dataset(recipe: Recipe, with_reference: bool = True,
                 imu_on_disk: bool = False) -> Dataset:
    """Read every file the recipe names and crop to [time].start_gps_s..end_gps_s
    (inclusive). Streams that do not overlap the IMU time span are an error (usually a
    time-base mismatch: seconds of week vs seconds since the GPS epoch).
    with_reference=False leaves the reference trajectory unread (Dataset.reference None):
    a job that never compares with it (`gmis vce`) does not hold its 88 bytes per row.
    imu_on_disk=True: the IMU samples are kept in a temporary file (read_imu on_disk;
    the streamed `gmis run` and `gmis vce`), 8 bytes per sample in memory (the times)."""
    start, end = recipe.time.start_gps_s, recipe.time.end_gps_s
    cut = (start, end) if start is not None or end is not None else None
    if recipe.imu.time_base == "tag":
        imu = read_imu_tagged(recipe.paths.imu, recipe.paths.imu_tag, recipe.imu, cut,
                              on_disk=imu_on_disk)
    else:
        imu = read_imu(recipe.paths.imu, recipe.imu, cut, on_disk=imu_on_disk)
    file_t0, file_t1 = imu.file_span if imu.file_span is not None else \
        (float(imu.t[0]), float(imu.t[-1]))
    window = f"[time] window {start}..{end} s"
    if imu.t.size < 2:
        raise GmisInputError(f"time.start_gps_s: fewer than 2 IMU samples in the {window}; "
                             f"the IMU file spans {file_t0:.3f}..{file_t1:.3f} s",
                             source=str(recipe.path))

    # a gap that straddles an edge of the [time] window counts up to that edge
    if end is not None and file_t1 > end and end - imu.t[-1] > MAX_GAP_S:
        raise GmisInputError(f"IMU gap after t={imu.t[-1]:.3f} s runs past [time].end_gps_s "
                             f"= {end} ({end - imu.t[-1]:.3f} s without IMU data, limit "
                             f"{MAX_GAP_S:g} s); end the window before the gap",
                             source=str(recipe.paths.imu))
    if start is not None and file_t0 < start and imu.t[0] - start > MAX_GAP_S:
        raise GmisInputError(f"IMU gap before t={imu.t[0]:.3f} s starts before "
                             f"[time].start_gps_s = {start} ({imu.t[0] - start:.3f} s without "
                             f"IMU data, limit {MAX_GAP_S:g} s); start the window after it",
                             source=str(recipe.paths.imu))
    dt = np.diff(imu.t)
    long_gaps = np.flatnonzero(dt > MAX_GAP_S)
    if long_gaps.size:
        k = int(long_gaps[0])
        raise GmisInputError(
            f"IMU gap of {dt[k]:.3f} s after t={imu.t[k]:.3f} s is longer than the limit of "
            f"{MAX_GAP_S:g} s" + (f" ({long_gaps.size} such gaps)" if long_gaps.size > 1 else "")
            + "; process the parts separately with [time] start_gps_s/end_gps_s",
            source=str(recipe.paths.imu))

    def stream(path, reader, *args):
        if path is None:
            return None
        data = _crop(reader(path, *args), start, end)
        overlap = (data.t >= imu.t[0]) & (data.t <= imu.t[-1])
        if not overlap.any():
            raise GmisInputError(
                f"no epochs within the IMU time span {imu.t[0]:.3f}..{imu.t[-1]:.3f} s"
                + (f" and the {window}" if start is not None or end is not None else "")
                + (f" (file spans {data.t[0]:.3f}..{data.t[-1]:.3f} s)" if data.t.size else "")
                + "; do all files use the same time base?", source=str(path))
        return data

    gnss = stream(recipe.paths.gnss_solution, read_gnss_solution, recipe.noise, recipe.gnss,
                  recipe.noise_given)
    if recipe.paths.gnss_pos is not None:
        from gmis.readers_rtklib import read_gnss_pos

        def read_pos_shifted(path, *args):
            pos = read_gnss_pos(path, *args)
            return replace(pos, t=pos.t + recipe.gnss.time_offset_s) \
                if recipe.gnss.time_offset_s else pos
        gnss = stream(recipe.paths.gnss_pos, read_pos_shifted,
                      recipe.gnss_pos.q_sigma_factor, recipe.noise, recipe.noise_given)
    heading = stream(recipe.paths.heading, read_heading, recipe.noise)
    gnss, heading = _scaled_sigmas(recipe.noise, gnss, heading)
    reference = None
    if recipe.paths.reference is not None and with_reference:
        reference = _crop(read_reference(recipe.paths.reference, cut), start, end)
    ds = Dataset(recipe=recipe, imu=imu, gnss=gnss, heading=heading, reference=reference,
                 warnings=imu.warnings)
    from gmis.plausibility import announce, check_dataset

    ds = replace(ds, warnings=ds.warnings + tuple(check_dataset(ds)))
    announce(ds.warnings)
    return ds

