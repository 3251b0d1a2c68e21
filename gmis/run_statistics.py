"""Summary statistics of a run: error RMS / 95 % / max per axis against the reference,
GNSS-aided epochs, outlier counts per measurement slot and the key figures of a tightly
coupled run (fix rate, satellites, σ̂²_0 per DD group)."""

from __future__ import annotations

import math

import numpy as np

from gmis.gmikf import GROUP_NAMES, GROUP_SIZE, GROUP_START, SLOT_NAMES
from gmis.run_filter import FilterRecords
from gmis.streamed_statistics import block_sum
from gmis.tc_models import group_names

STAT_BLOCK = 1 << 16      # error rows per block of the summary statistics


def error_statistics(err, names, scale=1.0, unit="", block: int = STAT_BLOCK):
    """{axis name: rms, p95, max of |err|·scale, unit} of the columns of err: an (K, n)
    array, or a callable giving a fresh iterator over its kept rows in blocks ((k, n)
    arrays: spooled errors). Exact and in bounded memory (gmis.streamed_statistics:
    block sums for the RMS, radix selection for the 95 % value, as np.percentile gives
    it); an array is cut into blocks of ``block`` rows, so it and its spool give the
    same figures."""
    from gmis.streamed_statistics import rms_p95_max

    blocks = err if callable(err) else \
        (lambda: (err[i:i + block] for i in range(0, err.shape[0], block)))
    stats = {}
    for i, name in enumerate(names):
        figures = rms_p95_max(lambda i=i: (b[:, i] for b in blocks()), scale)
        stats[name] = {**figures, "unit": unit}
    return stats


def seconds_since_last_fix(t, has_fix):
    """Per epoch: time (s) since the latest epoch with GNSS position information
    (inf before the first)."""
    last = np.maximum.accumulate(np.where(has_fix, t, -np.inf))
    return t - last


def fix_epochs_of(has_fix) -> np.ndarray:
    """The increasing epochs with GNSS position information of a (E,) bool array or of
    the position RowIndex (gmis.epochs) itself (its epochs with a row)."""
    at = getattr(has_fix, "at", None)
    if at is not None:
        return at
    return np.flatnonzero(np.asarray(has_fix))


def recently_fixed_rows(errs, t, has_fix, max_s: float = 1.0):
    """keep(j0, j1) for summarize_errors: the error rows [j0, j1) whose epoch (errs idx)
    lies at most max_s after the latest epoch with GNSS position information —
    seconds_since_last_fix(t, has_fix)[idx] <= max_s for epoch times t in order, read
    a block of rows at a time (no (K,) arrays)."""
    fixes = fix_epochs_of(has_fix)
    rows = errs.rows if hasattr(errs, "rows") else (lambda key, j0, j1: errs[key][j0:j1])

    def keep(j0, j1):
        idx = rows("idx", j0, j1)
        if fixes.size == 0:                     # never fixed: seconds since = inf
            return np.zeros(idx.size, dtype=bool)
        j = np.searchsorted(fixes, idx, side="right") - 1
        last = np.where(j >= 0, t[fixes[np.maximum(j, 0)]], -np.inf)
        return t[idx] - last <= max_s
    return keep


def summarize_errors(errs, skip_s: float = 0.0, keep=None):
    """RMS / 95 % / max per axis after skipping the first skip_s seconds (and only where
    ``keep`` is True, when given: a (K,) bool array or keep(j0, j1) → the flags of rows
    [j0, j1)). errs: the dict of reference_errors, or its spooled form (LazyColumns):
    read in blocks of STAT_BLOCK rows, so memory holds one block and a bit per row."""
    rows = errs.rows if hasattr(errs, "rows") else \
        (lambda key, j0, j1: errs[key][j0:j1])
    nees_rows = errs["nees"].rows if hasattr(errs["nees"], "rows") else \
        (lambda key, j0, j1: errs["nees"][key][j0:j1])
    n = len(errs["idx"]) if not hasattr(errs, "rows") else errs.n_rows
    if n == 0:
        return {"epochs_compared": 0,
                "note": f"no reference epochs after the first {skip_s:g} s (static alignment)"}
    t_keep = float(rows("t", 0, 1)[0]) + skip_s
    packed, count = [], 0              # the kept rows as bits: 1/8 byte per row
    for j0 in range(0, n, STAT_BLOCK):
        j1 = min(n, j0 + STAT_BLOCK)
        k = rows("t", j0, j1) >= t_keep
        if keep is not None:
            k &= keep[j0:j1] if isinstance(keep, np.ndarray) else keep(j0, j1)
        count += int(np.count_nonzero(k))
        packed.append(np.packbits(k))
    if count == 0:
        return {"epochs_compared": 0,
                "note": f"no reference epochs after the first {skip_s:g} s (static alignment)"}

    def kept(read, key):
        def blocks():
            for b, j0 in enumerate(range(0, n, STAT_BLOCK)):
                j1 = min(n, j0 + STAT_BLOCK)
                yield read(key, j0, j1)[np.unpackbits(packed[b], count=j1 - j0).view(bool)]
        return blocks

    nees = {}
    for name in errs["nees"]:
        total, _ = block_sum(kept(nees_rows, name))
        nees[name] = total / count
    return {
        "position": error_statistics(kept(rows, "pos"), ["e", "n", "u"], 1.0, "m"),
        "velocity": error_statistics(kept(rows, "vel"), ["e", "n", "u"], 1.0, "m/s"),
        "attitude": error_statistics(kept(rows, "att"), ["pitch", "roll", "heading"],
                                     180 / math.pi, "deg"),
        "nees_mean": nees,
        "epochs_compared": count,
    }


SLOT_GROUP = np.repeat(np.arange(len(GROUP_NAMES)), GROUP_SIZE)
assert np.array_equal(np.r_[0, np.cumsum(GROUP_SIZE)[:-1]], GROUP_START)
REJECTION_WARN_FACTOR = 10.0   # rejections above this × the test level α are reported
NIS_WARN_BAND = (0.5, 2.0)     # mean d²/D per group outside it is reported
MAX_REOPEN_TIMES = 20          # epoch times of lock-out recoveries listed per group


class RecordTotals:
    """What the summary needs from the per-epoch records, accumulated chunk by chunk
    (:meth:`add`): rejections per slot, per group the observations with a valid
    innovation, their rejections and Σ d²/D, and the lock-out recoveries (count and first
    MAX_REOPEN_TIMES epoch times)."""

    def __init__(self):
        n_groups = len(GROUP_NAMES)
        self.rejected_slot = np.zeros(len(SLOT_NAMES), dtype=np.int64)
        self.group_obs = np.zeros(n_groups, dtype=np.int64)
        self.group_rejected = np.zeros(n_groups, dtype=np.int64)
        self.group_nis_sum = np.zeros(n_groups)
        self.reopen_count = np.zeros(n_groups, dtype=np.int64)
        self.reopen_times = [[] for _ in range(n_groups)]

    @classmethod
    def of(cls, rec: FilterRecords) -> RecordTotals:
        totals = cls()
        totals.add(rec)
        return totals

    def add(self, rec: FilterRecords):
        rejected = rec.rejected.sum(axis=0, dtype=np.int64)
        self.rejected_slot += rejected
        for g in range(len(GROUP_NAMES)):
            cols = SLOT_GROUP == g
            d = rec.innov[:, cols]
            v = rec.innov_var[:, cols]
            ok = np.isfinite(d) & np.isfinite(v) & (v > 0)
            self.group_obs[g] += int(ok.sum())
            self.group_rejected[g] += int(rejected[cols].sum())
            self.group_nis_sum[g] += float(np.sum(d[ok] ** 2 / v[ok]))
        reopened = getattr(rec, "reopened", None)
        if reopened is not None and np.any(reopened):
            for g in range(len(GROUP_NAMES)):
                hit = np.flatnonzero((reopened.astype(np.int64) >> g) & 1)
                self.reopen_count[g] += hit.size
                room = MAX_REOPEN_TIMES - len(self.reopen_times[g])
                self.reopen_times[g] += [float(t) for t in rec.t[hit[:max(room, 0)]]]

    def rejected_counts(self) -> dict:
        return {name: int(n) for name, n in zip(SLOT_NAMES, self.rejected_slot)}

    def reopen_events(self, max_times: int = MAX_REOPEN_TIMES) -> dict:
        return {name: {"count": int(self.reopen_count[g]),
                       "first_times_s": self.reopen_times[g][:max_times]}
                for g, name in enumerate(GROUP_NAMES) if self.reopen_count[g]}

    def consistency_warnings(self, outlier_alpha: float, min_obs: int = 50) -> list:
        """See consistency_warnings."""
        out = []
        for g, name in enumerate(GROUP_NAMES):
            n = int(self.group_obs[g])
            if n < min_obs:
                continue
            rejected = int(self.group_rejected[g])
            if outlier_alpha > 0 and rejected > REJECTION_WARN_FACTOR * outlier_alpha * n:
                out.append(f"{name}: {rejected} of {n} observations rejected "
                           f"({100.0 * rejected / n:.2g} %, test level "
                           f"{100 * outlier_alpha:g} %)")
            nis = float(self.group_nis_sum[g] / n)
            if not NIS_WARN_BAND[0] <= nis <= NIS_WARN_BAND[1]:
                out.append(f"{name}: mean normalised innovation d²/D = {nis:.3g} (≈ 1 when "
                           f"the noise model fits; "
                           f"{'sigmas too small' if nis > 1 else 'sigmas too large'}"
                           "; `gmis vce` estimates them)")
        return out


def rejected_counts(rec: FilterRecords):
    """Observations rejected by the outlier tests per GMIKF measurement slot."""
    return RecordTotals.of(rec).rejected_counts()


def consistency_warnings(rec: FilterRecords, outlier_alpha: float, min_obs: int = 50):
    """Lines for the terminal and summary.json: per measurement group with at least
    min_obs observations, (a) rejections above REJECTION_WARN_FACTOR × α (a consistent
    filter rejects ≈ α of good data), (b) the mean normalised innovation d²/D outside
    NIS_WARN_BAND (≈ 1 when the noise model fits; the group's σ are too small above,
    too large below)."""
    return RecordTotals.of(rec).consistency_warnings(outlier_alpha, min_obs)


def covariance_reopen_events(rec: FilterRecords, max_times: int = MAX_REOPEN_TIMES):
    """Lock-out recoveries (gmis.lockout_recovery) per aiding group: how many, and the
    first ``max_times`` epoch times (s); {} when none happened."""
    return RecordTotals.of(rec).reopen_events(max_times)


def reopen_warning(events: dict, duration_s: float):
    """One line for the terminal and summary.json, or None."""
    if not events:
        return None
    parts = [f"{name} {e['count']}x (first at t={e['first_times_s'][0]:.2f} s)"
             for name, e in events.items()]
    return (f"covariance re-opened after consecutive rejections ({', '.join(parts)}) in "
            f"{duration_s:.0f} s: the noise model does not fit these data everywhere; "
            "consider `gmis vce` (see summary.json covariance_reopened)")


def fix_refusals(tc_rec) -> dict:
    """Epochs whose fix was refused, per reason (gmis.tc_filter): bootstrapping success
    rate below TcConfig.min_success_rate (a candidate set); the phase χ² or per-satellite
    test (fix_rejected: a candidate whose ratio test passed, or integers already held);
    a candidate whose satellites the per-satellite test could not tell apart."""
    return {"low_success_rate": int(tc_rec.low_success_rate.sum()),
            "phase_test": int(tc_rec.fix_rejected.sum()),
            "unidentifiable": int(tc_rec.unidentifiable.sum())}


def tc_summary(tc_rec, info):
    """Key figures of a tightly coupled run (fix rate, satellites, outliers, σ̂²_0 per
    observable group = Σ vᵀR⁻¹v / Σ r over the run)."""
    names = group_names(info.get("velocity_observable", "doppler"))
    solved = tc_rec.n_sat >= 2
    out = dict(info)
    out.update({
        "fix_rate": float(tc_rec.fixed[solved].mean()) if solved.any() else 0.0,
        "fixes_rejected_by_chi2": int(tc_rec.fix_rejected.sum()),
        "fixes_refused": fix_refusals(tc_rec),
        "satellites_median": float(np.median(tc_rec.n_sat[solved])) if solved.any() else 0,
        "satellites_min": int(tc_rec.n_sat[solved].min()) if solved.any() else 0,
        "rejected_observations": {n: int(v) for n, v in zip(names, tc_rec.rejected_obs.sum(0))},
        "sigma0_sq": {n: (float(q / r) if r > 0 else None) for n, q, r in
                      zip(names, tc_rec.vpv.sum(0), tc_rec.redundancy.sum(0))},
        "mean_redundancy": {n: (float(r / k) if k else None) for n, r, k in
                            zip(names, tc_rec.redundancy.sum(0), tc_rec.n_obs.sum(0))},
    })
    return out


__all__ = ["RecordTotals", "error_statistics", "fix_epochs_of", "fix_refusals",
           "recently_fixed_rows", "rejected_counts", "seconds_since_last_fix",
           "summarize_errors", "tc_summary"]
