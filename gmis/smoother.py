"""Fixed-interval two-filter smoother of the GMIKF (docs/DESIGN.md "Two-filter smoother").

The GMIKF treats the IMU as a measurement at every epoch, so a Rauch-Tung-Striebel pass
would need x, P, P⁻ and Φ of every IMU epoch (27×27 each, ~17 KB per epoch). The
two-filter form needs x and P at the OUTPUT epochs only:

    forward filter      x_f(k), P_f(k)  after the update at k (measurements ≤ t_k)
    backward filter     the same kernel over the reversed epochs: Δt < 0 in the kinematic
                        prediction (f and Φ hold for either sign), Q from |Δt|; started
                        diffuse at the last epoch; x_b(k), P_b(k) PREDICTED to t_k, i.e.
                        from the measurements > t_k only, so no measurement counts twice
    combination         P_s = (P_f⁻¹ + P_b⁻¹)⁻¹,  x_s = P_s (P_f⁻¹ x_f + P_b⁻¹ x_b),
                        computed as  S = P_f + P_b,
                                     x_s = x_f + P_f S⁻¹ (x_b − x_f),
                                     P_s = P_f − P_f S⁻¹ P_f
                        (the same matrices without inverting the near-singular P_f, P_b);
                        Euler-angle differences wrapped to [−π, π), heading to [0, 2π)

The forward x, P of the output epochs are spooled to a temporary file
(:class:`StateSpool`, (n + n(n+1)/2) float64 per output epoch) and read back in reverse
while the backward filter runs, so the smoother's own memory does not grow with the drive.
The backward filter's predicted state at output epoch k comes from a "phantom" epoch at
t_k without measurements, processed just before the real epoch k (which then has Δt = 0
and only updates).
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from gmis.epochs import EpochIndex
from gmis.gmikf import N_SLOTS, EpochRecords, gmikf_chunk
from gmis.run_filter import FilterRecords, GmikfConfig, GmikfRunner, Measurements
from gmis.state import ATT, I_HEADING, POS, VEL, n_noise_for

SMOOTHERS = ("none", "two_filter")
DIFFUSE_FACTOR = 3.0  # backward prior 1σ = this × the recipe's initial 1σ (docs/DESIGN.md)


@dataclass
class SmoothedStates:
    """The smoothed solution at the output epochs ``idx`` (rows of the epoch index)."""
    idx: np.ndarray          # (K,) epoch rows
    t: np.ndarray            # (K,) s
    x: np.ndarray            # (K, n) smoothed state
    sd: np.ndarray           # (K, n) smoothed 1σ
    cov_blocks: np.ndarray   # (K, 3, 3, 3) covariance of r^n, v^b, θ
    x_backward: np.ndarray   # (K, n) backward filter, predicted to t_k
    sd_backward: np.ndarray  # (K, n)
    spool_bytes_per_epoch: int = 0


def output_epochs(t, imu_row, rate_hz: float):
    """Rows of the epochs the smoother combines: the first IMU epoch of every 1/rate_hz s
    window (every IMU epoch for rate_hz ≤ 0) and the last IMU epoch."""
    rows = np.flatnonzero(np.asarray(imu_row) >= 0)
    if rows.size == 0:
        return rows
    if rate_hz and rate_hz > 0:
        k = np.floor((t[rows] - t[rows[0]]) * rate_hz + 1e-9)
        first = np.r_[True, k[1:] != k[:-1]]
        sel = rows[first]
        if sel[-1] != rows[-1]:
            sel = np.r_[sel, rows[-1]]
        return sel
    return rows


class StateSpool:
    """x and the upper triangle of P of successive epochs in an anonymous temporary file
    (float64, n + n(n+1)/2 per epoch), read back by position."""

    def __init__(self, n: int):
        self.n = n
        self.iu = np.triu_indices(n)
        self.width = n + self.iu[0].size
        self.bytes_per_epoch = 8 * self.width
        self.file = tempfile.TemporaryFile(prefix="gmis-smoother-")  # noqa: SIM115 (closed by close())
        self.count = 0

    def append(self, x, p):
        self.file.write(np.concatenate([x, p[self.iu]]).astype(np.float64).tobytes())
        self.count += 1

    def read(self, i: int):
        self.file.seek(i * self.bytes_per_epoch)
        rec = np.frombuffer(self.file.read(self.bytes_per_epoch), dtype=np.float64)
        n = self.n
        p = np.zeros((n, n))
        p[self.iu] = rec[n:]
        p = p + np.triu(p, 1).T
        return rec[:n].copy(), p

    def close(self):
        self.file.close()


def wrap_angle_differences(d):
    """d[θ] of a state difference wrapped to [−π, π) (pitch, roll, heading)."""
    d[ATT] = (d[ATT] + np.pi) % (2.0 * np.pi) - np.pi
    return d


def combine_two_filter(x_f, p_f, x_b, p_b):
    """(x_s, P_s) of the forward (updated) and backward (predicted) estimates at one epoch
    (module docstring)."""
    d = wrap_angle_differences(x_b - x_f)
    c = cho_factor(p_f + p_b, lower=True, check_finite=False)
    x_s = x_f + p_f @ cho_solve(c, d, check_finite=False)
    p_s = p_f - p_f @ cho_solve(c, p_f, check_finite=False)
    p_s = 0.5 * (p_s + p_s.T)
    x_s[I_HEADING] %= 2.0 * np.pi
    return x_s, p_s


def _record_buffers(length: int, n: int, nw: int) -> EpochRecords:
    """Kernel records for `length` epochs (the backward filter's segment scratch)."""
    f = np.zeros
    arrays = {"x": f((length, n)), "sd": f((length, n)), "cov_blocks": f((length, 3, 3, 3)),
              "innov": f((length, N_SLOTS)), "innov_var": f((length, N_SLOTS)),
              "rejected": f((length, N_SLOTS), dtype=np.int8), "vz": f((length, N_SLOTS)),
              "rz": f((length, N_SLOTS)), "vw": f((length, nw)), "rw": f((length, nw)),
              "rx": f(length), "nobs": f(length, dtype=np.int64),
              "rvar": f((length, N_SLOTS)), "helmert_s": f((N_SLOTS + nw, N_SLOTS + nw)),
              "helmert_totals": f(2)}
    return EpochRecords(**{k: arrays[k] for k in EpochRecords._fields})


def _backward_segment(inp, still, src, phantom_last: bool):
    """EpochInputs of the backward filter over the original epochs src (descending); the
    last entry is the phantom (no measurements) when phantom_last. still of the entry for
    epoch e is the forward flag of the interval (t_e, t_e+1], i.e. still[e + 1]."""
    e_total = still.shape[0]
    meas_ok = np.ones(src.size, dtype=np.bool_)
    if phantom_last:
        meas_ok[-1] = False

    def rows(a):
        return np.where(meas_ok, a[src], -1)

    return inp._replace(
        t=inp.t[src], imu_idx=rows(inp.imu_idx), pos_idx=rows(inp.pos_idx),
        vel_idx=rows(inp.vel_idx), hdg_idx=rows(inp.hdg_idx),
        still=np.ascontiguousarray(still[np.minimum(src + 1, e_total - 1)]),
        nhc_on=np.ascontiguousarray(inp.nhc_on[src] & meas_ok),
        zupt_on=np.ascontiguousarray(inp.zupt_on[src] & meas_ok))


def run_two_filter(epochs: EpochIndex, meas: Measurements, x0, config: GmikfConfig, frame,
                   stationary=None, rate_hz: float = 10.0, progress=None,
                   diffuse_factor: float = DIFFUSE_FACTOR):
    """Forward GMIKF (its full per-epoch records, as run_gmikf) and the two-filter smoothed
    states at the output epochs (output_epochs(rate_hz)); returns (FilterRecords,
    SmoothedStates)."""
    runner = GmikfRunner(epochs, meas, x0, config, frame, stationary)
    out = output_epochs(epochs.t, epochs.imu, rate_hz)
    n = runner.n
    spool = StateSpool(n)
    try:
        for j, e in enumerate(out):
            runner.advance(int(e) + 1)
            spool.append(runner.x, runner.p)
            if progress is not None and j % 1000 == 0:
                progress(0.5 * (e + 1) / runner.e_total)
        runner.advance(runner.e_total)
        smoothed = _backward_and_combine(runner, out, spool, diffuse_factor, progress)
    finally:
        spool.close()
    return runner.rec, smoothed


def _backward_and_combine(runner: GmikfRunner, out, spool: StateSpool, diffuse_factor,
                          progress) -> SmoothedStates:
    n, k_out = runner.n, out.size
    settings = runner.kernel_settings()._replace(compute_vce=0)
    inp, still = runner.inputs, runner.rec.still
    x_b = runner.x.copy()
    p_b = np.diag((diffuse_factor * np.asarray(runner.config.p0_sd, float)) ** 2)
    seg_len = int(np.max(np.diff(np.r_[out, runner.e_total - 1]), initial=0)) + 2
    rec_b = _record_buffers(seg_len, n, n_noise_for(runner.n_imu))
    xs, sds = np.empty((k_out, n)), np.empty((k_out, n))
    xbs, sdbs = np.empty((k_out, n)), np.empty((k_out, n))
    cov = np.empty((k_out, 3, 3, 3))
    hi = runner.e_total - 1
    t_prev = np.nan
    for j in range(k_out - 1, -1, -1):
        e = int(out[j])
        src = np.r_[np.arange(hi, e, -1), e]
        seg = _backward_segment(inp, still, src, True)
        t_prev = gmikf_chunk(0, src.size, seg, settings, x_b, p_b, rec_b, t_prev)
        if not (np.isfinite(x_b).all() and np.isfinite(p_b).all()):
            from gmis.run_filter import FilterDivergedError
            raise FilterDivergedError(f"backward filter of the smoother diverged at epoch {e} "
                                      f"(t = {runner.rec.t[e]:.3f} s); no solution written")
        hi = e
        x_f, p_f = spool.read(j)
        x_s, p_s = combine_two_filter(x_f, p_f, x_b, p_b)
        xs[j], sds[j] = x_s, np.sqrt(np.maximum(np.diag(p_s), 0.0))
        xbs[j], sdbs[j] = x_b, np.sqrt(np.maximum(np.diag(p_b), 0.0))
        for b, sl in enumerate((POS, VEL, ATT)):
            cov[j, b] = p_s[sl, sl]
        if progress is not None and j % 1000 == 0:
            progress(0.5 + 0.5 * (k_out - j) / k_out)
    return SmoothedStates(idx=out, t=runner.rec.t[out], x=xs, sd=sds, cov_blocks=cov,
                          x_backward=xbs, sd_backward=sdbs,
                          spool_bytes_per_epoch=spool.bytes_per_epoch)


def smoothed_records(rec: FilterRecords, sm: SmoothedStates) -> FilterRecords:
    """FilterRecords of the output epochs carrying the smoothed x, 1σ and covariance
    blocks (the measurement records are the forward filter's at those epochs), for the
    solution writers and reference errors."""
    from dataclasses import replace

    i = sm.idx
    per_epoch = {name: getattr(rec, name)[i] for name in
                 ("innov", "innov_var", "rejected", "vz", "rz", "vw", "rw", "rx", "nobs",
                  "rvar", "imu_row")}
    still = rec.still[i] if rec.still is not None else None
    return replace(rec, t=rec.t[i], x=sm.x, sd=sm.sd, cov_blocks=sm.cov_blocks,
                   still=still, **per_epoch)


__all__ = ["SMOOTHERS", "SmoothedStates", "StateSpool", "combine_two_filter",
           "output_epochs", "run_two_filter", "smoothed_records"]
