"""A dependency-free progress line on stderr for long runs.

``with Progress(total, "filter") as p: p.update(n)`` counts items; the same object is a
``callback(fraction)`` for code that reports progress as a fraction in [0, 1]. Output is
refreshed at most every ``min_interval`` seconds (default 0.2 s) and only when the stream
is a terminal and ``quiet`` is False.
"""

from __future__ import annotations

import math
import sys
import time
from typing import Self


def _format_seconds(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "--:--"
    seconds = round(seconds)
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h:d}:{m:02d}:{s:02d}" if h else f"{m:02d}:{s:02d}"


class Progress:
    """Progress of ``total`` items (or of a fraction when total=1.0): percentage, elapsed
    time, rate (items/s) and ETA."""

    def __init__(self, total: float = 1.0, label: str = "", quiet: bool = False,
                 stream=None, min_interval: float = 0.2, clock=time.monotonic):
        self.total = float(total) if total and total > 0 else 1.0
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        isatty = getattr(self.stream, "isatty", None)
        self.enabled = not quiet and bool(isatty and isatty())
        self.min_interval = min_interval
        self.clock = clock
        self.done = 0.0
        self.start = clock()
        self._last_draw = -float("inf")
        self._drawn = False

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close(success=exc[0] is None)

    def update(self, n: float = 1.0) -> None:
        """Add ``n`` completed items."""
        self.set(self.done + n)

    def set(self, done: float) -> None:
        """Set the number of completed items."""
        self.done = min(max(float(done), 0.0), self.total)
        now = self.clock()
        if now - self._last_draw >= self.min_interval or self.done >= self.total:
            self._last_draw = now
            self._draw(now)

    def __call__(self, fraction: float) -> None:
        """Callback form: ``fraction`` of the work done, in [0, 1]."""
        self.set(float(fraction) * self.total)

    def line(self, now: float | None = None) -> str:
        now = self.clock() if now is None else now
        elapsed = now - self.start
        fraction = self.done / self.total
        rate = self.done / elapsed if elapsed > 0 else float("nan")
        eta = (self.total - self.done) / rate if math.isfinite(rate) and rate > 0 \
            else float("nan")
        label = f"{self.label}: " if self.label else ""
        rate_text = f"{rate:.3g}/s" if self.total != 1.0 else f"{100 * rate:.3g}%/s"
        return (f"{label}{100 * fraction:5.1f}%  elapsed {_format_seconds(elapsed)}  "
                f"{rate_text}  ETA {_format_seconds(eta)}")

    def _draw(self, now: float) -> None:
        if not self.enabled:
            return
        self.stream.write("\r" + self.line(now) + "\033[K")
        self.stream.flush()
        self._drawn = True

    def close(self, success: bool = True) -> None:
        if self.enabled and self._drawn:
            if success:
                self.done = self.total
                self._draw(self.clock())
            self.stream.write("\n")
            self.stream.flush()
            self._drawn = False
