"""GNSS outages at given times: the ``[outages]`` recipe table, ``--gnss-outage
START:DURATION`` / ``--window START:DURATION`` specs, and the scoring of a solution against
the GNSS it did not see.

A window is (start, end) in the data's GPS seconds of week; GNSS position and velocity
(and heading, unless kept) inside it are withheld from the filter
(gmis.run_preparation.prepare_run ``gnss_outages``). Scoring (``score_windows``): the
solution's primary-antenna position is interpolated (linearly, in ENU) to every withheld
GNSS epoch and compared with that epoch's GNSS position; per window and over all withheld
epochs: the maximum and RMS horizontal error and the RMS and maximum |vertical| error (m).
Unlike the drift of gmis.outages (error growth relative to the window start against a
reference trajectory), this needs no reference: the withheld GNSS solution is the reference,
so on an RTK-fixed track it is good to a few cm.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from gmis.errors import GmisInputError


@dataclass(frozen=True)
class OutagesSection:
    """[outages] of a recipe: windows (start GPS s of week, duration s) and whether the
    heading stream is withheld with GNSS position/velocity."""
    windows: tuple = ()
    remove_heading: bool = True

    def spans(self):
        return [(a, a + d) for a, d in self.windows]


def parse_window_spec(spec: str, option: str = "--gnss-outage"):
    """'START:DURATION' (GPS s of week, s) → (start, end); GmisInputError otherwise."""
    parts = str(spec).split(":")
    if len(parts) != 2:
        raise GmisInputError(f"expected START:DURATION (GPS seconds of week : seconds), got "
                             f"{spec!r}", option)
    try:
        start, duration = float(parts[0]), float(parts[1])
    except ValueError:
        raise GmisInputError(f"expected START:DURATION with two numbers, got {spec!r}",
                             option) from None
    check_window(start, duration, option)
    return start, start + duration


def check_window(start, duration, where):
    if not (math.isfinite(start) and math.isfinite(duration)):
        raise GmisInputError(f"window start and duration must be finite, got "
                             f"{start}:{duration}", where)
    if not 0.0 <= start < 604800.0:
        raise GmisInputError(f"window start {start:g} is not a GPS second of week "
                             "[0, 604800)", where)
    if not duration > 0.0:
        raise GmisInputError(f"window duration must be > 0 s, got {duration:g}", where)


def parse_outages_table(table, fail) -> OutagesSection:
    """[outages] (docs/formats.md): ``windows = [[start_gps_s, duration_s], ...]``,
    ``remove_heading = true``; fail(key, message) raises the recipe error."""
    windows = table.get("windows", [])
    if not isinstance(windows, list) or any(
            not isinstance(w, list) or len(w) != 2 or any(
                isinstance(v, bool) or not isinstance(v, (int, float)) for v in w)
            for w in windows):
        fail("windows", "expected a list of [start_gps_s, duration_s] pairs")
    out = []
    for a, d in windows:
        try:
            check_window(float(a), float(d), "outages.windows")
        except GmisInputError as exc:
            fail("windows", str(exc).split(": ", 1)[-1])
        out.append((float(a), float(d)))
    remove_heading = table.get("remove_heading", True)
    if not isinstance(remove_heading, bool):
        fail("remove_heading", "expected true or false")
    unknown = sorted(set(table) - {"windows", "remove_heading"})
    if unknown:
        fail(unknown[0], "unknown key in [outages] (valid: windows, remove_heading)")
    spans = sorted((a, a + d) for a, d in out)
    for (a0, b0), (a1, _) in itertools.pairwise(spans):
        if a1 < b0:
            fail("windows", f"windows starting at {a0:g} and {a1:g} overlap")
    return OutagesSection(tuple(out), remove_heading)


def _interp_rows(t, tp, fp):
    return np.column_stack([np.interp(t, tp, fp[:, i]) for i in range(fp.shape[1])])


def score_windows(t_sol, enu_antenna, gnss_t, gnss_enu, windows):
    """Errors of the antenna solution at the withheld GNSS epochs (module docstring).
    Returns (rows, all_row): one dict per window and one over all withheld epochs, each
    with n, horizontal_max_m, horizontal_rms_m, vertical_rms_m, vertical_max_m."""
    rows = []
    errs = []
    for a, b in windows:
        sel = (gnss_t >= a) & (gnss_t <= b) & (gnss_t >= t_sol[0]) & (gnss_t <= t_sol[-1])
        if not sel.any():
            raise GmisInputError(f"outage window {a:.3f}-{b:.3f} s holds no GNSS epoch "
                                 "inside the solution's time span", "outages")
        sol = _interp_rows(gnss_t[sel], t_sol, enu_antenna)
        e = sol - gnss_enu[sel]
        errs.append(e)
        rows.append(_stats(e) | {"start_gps_s": a, "end_gps_s": b})
    return rows, _stats(np.vstack(errs))


def _stats(e):
    h = np.hypot(e[:, 0], e[:, 1])
    return {"n": int(e.shape[0]), "horizontal_max_m": float(h.max()),
            "horizontal_rms_m": float(np.sqrt(np.mean(h ** 2))),
            "vertical_rms_m": float(np.sqrt(np.mean(e[:, 2] ** 2))),
            "vertical_max_m": float(np.abs(e[:, 2]).max())}


__all__ = ["OutagesSection", "check_window", "parse_outages_table", "parse_window_spec",
           "score_windows"]
