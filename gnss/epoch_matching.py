"""Matching the epochs of two receivers (or of a receiver and a solution) by time.

Receivers that do not steer their clocks tag epochs a few ms off the nominal second, so
epochs are paired by the nearest time tag within a tolerance (RTKLIB's 25 ms by default).
A time exactly midway between two reference epochs goes to the later one.
"""

import numpy as np

DEFAULT_TOLERANCE_S = 0.025


def nearest_epoch(t_ref, t) -> np.ndarray:
    """Index into the sorted times t_ref (s) of the epoch nearest to each t (s)."""
    t_ref = np.asarray(t_ref, float)
    t = np.asarray(t, float)
    j = np.clip(np.searchsorted(t_ref, t), 0, max(t_ref.size - 1, 0))
    j_lo = np.maximum(j - 1, 0)
    return np.where(np.abs(t_ref[j_lo] - t) < np.abs(t_ref[j] - t), j_lo, j)


def match_epochs(t_ref, t, tolerance_s: float = DEFAULT_TOLERANCE_S) -> np.ndarray:
    """nearest_epoch, with −1 where the nearest epoch is farther than tolerance_s."""
    j = nearest_epoch(t_ref, t)
    return np.where(np.abs(np.asarray(t_ref, float)[j] - np.asarray(t, float))
                    <= tolerance_s, j, -1)
