"""The bytes of a time-ordered text table that a [time] window needs (docs/DESIGN.md
"Bounded memory", issue 18): a run of 10 s out of a 3 h IMU log parses 10 s of text.

The data lines of an IMU log are in time order (the readers refuse anything else), so
the line where a time is first reached can be found by bisection over byte offsets: seek
to an offset, skip to the next line start, parse that line's time. ~2·log2(file size /
PROBE_BYTES) probes of PROBE_BYTES each find both ends. The bytes read are then the
window's lines plus ``margin_s`` on either side (the increment format needs the sample
before the first; the readers' gap checks see the samples next to the edges), and the
file's first and last data line give its time span for the messages.

Only the lines read are checked (order, rate, gaps): a window run does not vouch for the
rest of the file. Anything a bisection cannot trust — a probe line that does not parse,
probe times out of order, a window with fewer than two lines — returns None, and the
caller reads the whole file as before (so its errors are the whole-file errors).
"""

from __future__ import annotations

import codecs
import itertools
from dataclasses import dataclass

PROBE_BYTES = 1 << 16          # bytes read per probe (a few hundred lines)
HEAD_BYTES = 1 << 20           # the header must start in the file's first MiB
WINDOW_MIN_BYTES = 8 << 20     # smaller files are read whole (as fast as the probes)
GAP_FACTOR = 5.0               # a step > this × the median step at a cut is a gap


@dataclass(frozen=True)
class TextWindow:
    """Bytes [byte_start, byte_end) of the file hold the window's lines (both at line
    starts); first_time / last_time: the times of the file's first and last data line."""

    byte_start: int
    byte_end: int
    first_time: float
    last_time: float


def _data_start(fh, is_content) -> tuple[int, str] | None:
    """(byte offset just after the header line, the header line) — the first line for
    which is_content is true — or None when it is not in the first HEAD_BYTES."""
    head = fh.read(HEAD_BYTES)
    offset = len(codecs.BOM_UTF8) if head.startswith(codecs.BOM_UTF8) else 0
    while True:
        end = head.find(b"\n", offset)
        if end < 0:
            return None
        try:
            line = head[offset:end].decode("utf-8").rstrip("\r")
        except UnicodeDecodeError:
            return None
        if is_content(line):
            return end + 1, line
        offset = end + 1


def head_line_start(fh, after: int) -> int:
    """Start of the line that ends just before byte ``after`` (a line start)."""
    lo = max(0, after - PROBE_BYTES)
    fh.seek(lo)
    chunk = fh.read(after - 1 - lo)
    cut = chunk.rfind(b"\n")
    if cut >= 0:
        return lo + cut + 1
    return len(codecs.BOM_UTF8) if lo == 0 and chunk.startswith(codecs.BOM_UTF8) else lo


def _line_at(fh, offset: int, data_start: int, size: int, is_content):
    """(start, end) byte offsets and text of the first content line that starts at or
    after ``offset`` (offset ≥ data_start; a line start or inside a line), or None when
    there is none before the end of the file; 'bad' when it cannot be decoded."""
    pos = offset
    if pos > data_start:           # inside a line, or at a line start: back up one byte
        pos -= 1                   # so that a line starting exactly at offset is found
        fh.seek(pos)
        chunk = fh.read(PROBE_BYTES)
        cut = chunk.find(b"\n")
        if cut < 0:
            return None if pos + len(chunk) >= size else "bad"
        pos += cut + 1
    while pos < size:
        fh.seek(pos)
        chunk = fh.read(PROBE_BYTES)
        end = chunk.find(b"\n")
        if end < 0:
            if pos + len(chunk) < size:
                return "bad"       # a line longer than a probe
            end = len(chunk)
        try:
            line = chunk[:end].decode("utf-8").rstrip("\r")
        except UnicodeDecodeError:
            return "bad"
        if is_content(line):
            return pos, pos + end + 1, line
        pos += end + 1
    return None


def _last_line(fh, data_start: int, size: int, is_content):
    """Text of the last content line of the file (None when it is not in the last
    PROBE_BYTES or cannot be decoded)."""
    lo = max(data_start, size - PROBE_BYTES)
    fh.seek(lo)
    try:
        text = fh.read(size - lo).decode("utf-8")
    except UnicodeDecodeError:
        return None
    lines = text.splitlines()
    if lo > data_start:
        lines = lines[1:]          # the first may be cut
    for line in reversed(lines):
        if is_content(line):
            return line
    return None


def _times_around(fh, cut: int, data_start: int, size: int, time_of_line, is_content):
    """(times of the content lines in the PROBE_BYTES before ``cut``, times of those in
    the PROBE_BYTES from it) — whole lines only; None when one does not parse."""
    lo = max(data_start, cut - PROBE_BYTES)
    fh.seek(lo)
    before = fh.read(cut - lo)
    after = fh.read(min(PROBE_BYTES, size - cut))
    try:
        head = before.decode("utf-8").splitlines()
        tail = after.decode("utf-8").splitlines()
    except UnicodeDecodeError:
        return None
    if lo > data_start:
        head = head[1:]                       # the first may be cut
    if cut + len(after) < size:
        tail = tail[:-1]                      # the last may be cut
    out = []
    for lines in (head, tail):
        times = []
        for line in lines:
            if is_content(line):
                t = time_of_line(line)
                if t is None:
                    return None
                times.append(t)
        out.append(times)
    return out


def _cut_is_clean(fh, cut: int, data_start: int, size: int, time_of_line, is_content,
                  max_step_s) -> bool:
    """The lines on both sides of a cut are in strictly increasing time and the step
    across the cut is no gap: at most max_step_s, or (max_step_s None) GAP_FACTOR × the
    median step before it. A time tag that jumped ahead (the end search stops on it) or
    a gap at the window's edge then sends the caller to the whole file, whose errors and
    gap warnings are the reference."""
    if cut <= data_start or cut >= size:
        return True
    around = _times_around(fh, cut, data_start, size, time_of_line, is_content)
    if around is None:
        return False
    before, after = around
    times = before + after
    if any(b <= a for a, b in itertools.pairwise(times)):
        return False
    if not before or not after:
        return True
    step = after[0] - before[-1]
    if max_step_s is None:
        if len(before) < 3:
            return True
        steps = sorted(b - a for a, b in itertools.pairwise(before))
        max_step_s = GAP_FACTOR * steps[len(steps) // 2]
    return step <= max_step_s


def _content_lines(fh, b0: int, b1: int, is_content, at_least: int) -> bool:
    """Whether bytes [b0, b1) hold at least ``at_least`` content lines (read up to
    PROBE_BYTES; more bytes than that: yes)."""
    if b1 - b0 > PROBE_BYTES:
        return True
    fh.seek(b0)
    try:
        lines = fh.read(b1 - b0).decode("utf-8").splitlines()
    except UnicodeDecodeError:
        return True                            # the reader reports it
    return sum(1 for line in lines if is_content(line)) >= at_least


def time_window_bytes(path, time_of_line, is_content, start, end, margin_s: float,
                      min_bytes: int | None = None, header: bool | None = None,
                      max_step_s: float | None = None) -> TextWindow | None:
    """The byte range of the data lines with start − margin_s ≤ time ≤ end + margin_s
    (start / end None: open) of a text table whose data lines are in time order, or None
    (read the whole file).

    time_of_line(line: str) → float time of a data line in the window's time base, or
    None when the line does not parse; is_content(line) → False for blank and comment
    lines (the first content line is the header or the first data line). header: whether
    that first content line is a header (None: when time_of_line cannot parse it).
    max_step_s: the largest step between two lines that is not a gap (None: GAP_FACTOR ×
    the median step next to the cut); a larger one at either cut reads the whole file."""
    import os

    size = os.path.getsize(path)
    if size < (WINDOW_MIN_BYTES if min_bytes is None else min_bytes):
        return None
    if start is not None and end is not None and start > end:
        return None
    with open(path, "rb") as fh:
        found = _data_start(fh, is_content)
        if found is None:
            return None
        after_header, first_line = found
        t_first = None if header else time_of_line(first_line)
        if t_first is None:                        # a header: data start after it
            data_start = after_header
            first = _line_at(fh, data_start, data_start, size, is_content)
            if not isinstance(first, tuple):
                return None
            t_first = time_of_line(first[2])
            if t_first is None:
                return None
        else:                                      # no header: data from that line on
            data_start = head_line_start(fh, after_header)
        last = _last_line(fh, data_start, size, is_content)
        t_last = None if last is None else time_of_line(last)
        if t_last is None or not t_last > t_first:
            return None
        probes = []

        def first_offset_reaching(target: float, inclusive: bool) -> int | None:
            """Start of the first data line with time ≥ target (> with inclusive=False)."""
            lo, hi = data_start, size                 # time(line at lo) < target <= ...
            while hi - lo > PROBE_BYTES:
                mid = (lo + hi) // 2
                line = _line_at(fh, mid, data_start, size, is_content)
                if line is None:
                    hi = mid
                    continue
                if line == "bad":
                    return None
                t = time_of_line(line[2])
                if t is None:
                    return None
                probes.append((line[0], t))
                if t < target or (not inclusive and t == target):
                    lo = line[1]
                else:
                    hi = mid
            fh.seek(lo)                               # the last stretch, line by line
            stretch = fh.read(min(size, hi + 2 * PROBE_BYTES) - lo)  # lines ≤ PROBE_BYTES
            pos = lo
            for raw in stretch.splitlines(keepends=True):
                if not raw.endswith(b"\n") and pos + len(raw) < size:
                    return None                       # cut by the read: too long a line
                try:
                    text = raw.decode("utf-8")
                except UnicodeDecodeError:
                    return None
                if is_content(text):
                    t = time_of_line(text.rstrip("\r\n"))
                    if t is None:
                        return None
                    if t > target or (inclusive and t == target):
                        return pos
                pos += len(raw)
            return size if pos >= size else None

        b0 = data_start if start is None else first_offset_reaching(start - margin_s, True)
        b1 = size if end is None else first_offset_reaching(end + margin_s, False)
        if b0 is None or b1 is None or b1 < b0:
            return None
        probes.sort()
        times = [t for _, t in probes]
        if any(b < a for a, b in itertools.pairwise(times)):
            return None                               # out of order: read it all
        if b0 == data_start and b1 == size:
            return None
        if not _content_lines(fh, b0, b1, is_content, 2):
            return None                               # < 2 lines: the whole-file errors
        for cut in (b0, b1):
            if not _cut_is_clean(fh, cut, data_start, size, time_of_line, is_content,
                                 max_step_s):
                return None
    return TextWindow(b0, b1, float(t_first), float(t_last))


__all__ = ["PROBE_BYTES", "WINDOW_MIN_BYTES", "TextWindow", "time_window_bytes"]
