"""IMU sample times from a uniform sample clock when the logged time tags jitter.

Many road-test loggers stamp each IMU sample with the host's time when the sample arrived
(a millisecond tick counter, a serial-port read time), not with the IMU's sampling instant.
The IMU itself samples on its own uniform clock, so the logged intervals scatter about the
true interval (8-11 ms at 100 Hz on the real car drive of ../shared/data, where the ticks
stay within ~1 ms of one straight line). Integrating the kinematic model over the logged
intervals makes every step's Δt wrong by up to ±20 %: the rotation ω Δt and the velocity
increment f Δt get a zero-mean error per step that random-walks over an outage (heading
error ≈ |ω| σ_t √N for N samples, ~0.5° after 15 s of turning at 0.5 rad/s with 0.5 ms).

``uniform_clock_times`` models the tags as t_k = a + b n_k + ε_k, where n_k is the sample
count since the first sample (a logged interval of about m nominal intervals counts m, so
dropped samples keep their time), a and b the clock offset and period (one least-squares
line per piece between gaps longer than ``MAX_COUNTED_GAP`` intervals) and ε the logging
jitter. When the tags fit that model — residual RMS ≤ ``MAX_RMS_FRACTION`` and max
≤ ``MAX_ABS_FRACTION`` of the interval, no interval ambiguous to count — the sample times
become a + b n_k; otherwise the tags are kept and a note says why. Tags whose intervals
are already uniform (every interval within ``UNIFORM_SPREAD`` of a whole number of the
median interval: simulated data, hardware-timed logs, with or without gaps) are returned
unchanged, bit for bit.

``[imu].uniform_clock = false`` keeps the logged tags.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

UNIFORM_SPREAD = 1e-3      # max |Δt / median − round| of tags already uniform
MAX_RMS_FRACTION = 0.25    # residual RMS / interval accepted as jitter about one clock
MAX_ABS_FRACTION = 0.75    # residual max / interval accepted
AMBIGUOUS = 0.35           # |Δt / interval − round| above this: the count is ambiguous
MAX_COUNTED_GAP = 5        # longer intervals start a new clock piece (gmis.readers gaps)
MIN_PIECE = 10             # pieces with fewer samples keep their tags


@dataclass(frozen=True)
class ClockFit:
    """What uniform_clock_times found (times in s)."""

    applied: bool
    interval_s: float          # median logged interval
    rate_hz: float             # fitted clock rate (first piece), 0 when not applied
    residual_rms_s: float
    residual_max_s: float
    interval_p01_s: float
    interval_p99_s: float
    pieces: int
    reason: str = ""           # why the tags were kept (applied False)

    def note(self, source: str) -> str | None:
        """One line for the terminal, None when the tags were uniform already."""
        if not self.reason and not self.applied:
            return None
        spread = (f"1-99 % of the intervals {self.interval_p01_s * 1e3:.1f}-"
                  f"{self.interval_p99_s * 1e3:.1f} ms")
        if not self.applied:
            return (f"{source}: IMU time tags jitter ({spread}) and were kept: {self.reason}")
        return (f"{source}: IMU time tags jitter ({spread}) about a uniform "
                f"{self.rate_hz:.4f} Hz sample clock (residual {self.residual_rms_s * 1e3:.2f}"
                f" ms RMS, max {self.residual_max_s * 1e3:.2f} ms, {self.pieces} piece(s)): "
                "sample times taken from the fitted clock ([imu].uniform_clock = false keeps "
                "the tags)")


def uniform_clock_times(t: np.ndarray) -> tuple[np.ndarray, ClockFit]:
    """(times, ClockFit) for strictly increasing IMU tags t (N,) s; see the module doc.
    The returned times are t itself (same object) unless the fit was applied."""
    t = np.asarray(t, dtype=float)
    dt = np.diff(t)
    interval = float(np.median(dt))
    p01, p99 = (float(v) for v in np.percentile(dt, [1.0, 99.0]))
    plain = ClockFit(False, interval, 0.0, 0.0, 0.0, p01, p99, 0)
    ratio = dt / interval
    counts = np.rint(ratio)
    counted = ratio <= MAX_COUNTED_GAP + 0.5
    if float(np.max(np.abs(ratio - counts)[counted], initial=0.0)) <= UNIFORM_SPREAD:
        return t, plain          # uniform already (dropped samples and gaps aside)
    ambiguous = counted & (np.abs(ratio - counts) > AMBIGUOUS) & (counts >= 1)
    if np.any(ambiguous | (counts < 1)):
        k = int(np.flatnonzero(ambiguous | (counts < 1))[0])
        return t, _kept(plain, f"interval {dt[k] * 1e3:.2f} ms after sample {k} is not a "
                               "whole number of the median interval")
    starts = np.r_[0, np.flatnonzero(~counted) + 1]
    ends = np.r_[starts[1:], t.size]
    out = t.copy()
    res_all = []
    rate = 0.0
    fitted = 0
    for a, b in zip(starts, ends):
        if b - a < MIN_PIECE:
            continue
        n = np.r_[0.0, np.cumsum(counts[a:b - 1])]
        tt = t[a:b]
        n_mean, t_mean = n.mean(), tt.mean()
        period = float(np.sum((n - n_mean) * (tt - t_mean)) / np.sum((n - n_mean) ** 2))
        line = t_mean + period * (n - n_mean)
        res_all.append(tt - line)
        out[a:b] = line
        if fitted == 0:
            rate = 1.0 / period
        fitted += 1
    if fitted == 0:
        return t, _kept(plain, "no piece long enough to fit a clock")
    res = np.concatenate(res_all)
    rms, mx = float(np.sqrt(np.mean(res ** 2))), float(np.max(np.abs(res)))
    fit = ClockFit(True, interval, rate, rms, mx, p01, p99, fitted)
    if rms > MAX_RMS_FRACTION * interval or mx > MAX_ABS_FRACTION * interval:
        return t, _kept(fit, f"they wander from a uniform clock by {mx * 1e3:.2f} ms (RMS "
                             f"{rms * 1e3:.2f} ms), more than logging jitter")
    if np.any(np.diff(out) <= 0.0):
        return t, _kept(fit, "the fitted clock does not increase across a gap")
    return out, fit


def _kept(fit: ClockFit, reason: str) -> ClockFit:
    return ClockFit(False, fit.interval_s, 0.0, fit.residual_rms_s, fit.residual_max_s,
                    fit.interval_p01_s, fit.interval_p99_s, fit.pieces, reason)
