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
from numba import njit
from scipy.linalg import cho_factor, cho_solve

from gmis.dense import cholesky_inplace
from gmis.epochs import EpochIndex
from gmis.gmikf import (
    COV_BLOCK_START,
    GROUP_NAMES,
    N_SLOTS,
    EpochRecords,
    gmikf_chunk_ws,
    make_workspace,
)
from gmis.run_filter import (
    FilterDivergedError,
    FilterRecords,
    GmikfConfig,
    GmikfRunner,
    Measurements,
    check_finite,
)
from gmis.state import ATT, I_HEADING, n_noise_for

I_ATT0 = ATT.start

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


def smoother_output_rate_hz(recipe) -> float:
    """The smoothed solution's epochs per second: [filter].smoother_rate_hz, at most the
    IMU rate (a higher rate gives every IMU epoch, output_epochs)."""
    return min(recipe.filter.smoother_rate_hz, recipe.imu.rate_hz)


def output_epochs(t, imu_row, rate_hz: float, block: int = 1 << 16):
    """Rows of the epochs the smoother combines: the first IMU epoch of every 1/rate_hz s
    window (every IMU epoch for rate_hz ≤ 0) and the last IMU epoch. imu_row an array or
    a gmis.epochs.RowIndex, read in blocks of epochs (no (E,) temporaries)."""
    parts, t_first, k_last, last = [], None, None, None
    for e0 in range(0, len(imu_row), block):
        rows = np.flatnonzero(np.asarray(imu_row[e0:e0 + block]) >= 0) + e0
        if rows.size == 0:
            continue
        last = rows[-1]
        if not (rate_hz and rate_hz > 0):
            parts.append(rows)
            continue
        if t_first is None:
            t_first = t[rows[0]]
        k = np.floor((t[rows] - t_first) * rate_hz + 1e-9)
        first = np.r_[k_last is None or k[0] != k_last, k[1:] != k[:-1]]
        parts.append(rows[first])
        k_last = k[-1]
    if last is None:
        return np.zeros(0, dtype=np.int64)
    sel = np.concatenate(parts)
    if sel[-1] != last:
        sel = np.r_[sel, last]
    return sel


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


def _record_buffers(length: int, n: int, nw: int, streak=None) -> EpochRecords:
    """Kernel records for `length` epochs (the backward filter's block scratch). streak:
    the backward filter's per-group run of rejected epochs, shared by all its blocks (the
    lock-out recovery counts consecutive rejections across block boundaries, as the
    forward filter does across its chunks); None: a fresh one."""
    f = np.zeros
    arrays = {"x": f((length, n)), "sd": f((length, n)), "cov_blocks": f((length, 3, 3, 3)),
              "innov": f((length, N_SLOTS)), "innov_var": f((length, N_SLOTS)),
              "rejected": f((length, N_SLOTS), dtype=np.int8), "vz": f((length, N_SLOTS)),
              "rz": f((length, N_SLOTS)), "vw": f((length, nw)), "rw": f((length, nw)),
              "rx": f(length), "nobs": f(length, dtype=np.int64),
              "rvar": f((length, N_SLOTS)), "helmert_s": f((N_SLOTS + nw, N_SLOTS + nw)),
              "helmert_totals": f(2), "helmert_trunc": f(N_SLOTS + nw + 1),
              "streak": f(len(GROUP_NAMES), dtype=np.int64) if streak is None else streak,
              "reopened": f(length, dtype=np.int8)}
    return EpochRecords(**{k: arrays[k] for k in EpochRecords._fields if k in arrays})


@njit(cache=True)
def _pack_state(x, p, row):
    """row ← [x, upper triangle of P row by row] (StateSpool layout)."""
    n = x.shape[0]
    k = n
    for i in range(n):
        row[i] = x[i]
        for j in range(i, n):
            row[k] = p[i, j]
            k += 1


@njit(cache=True)
def _unpack_state(row, x, p):
    n = x.shape[0]
    k = n
    for i in range(n):
        x[i] = row[i]
        for j in range(i, n):
            p[i, j] = row[k]
            p[j, i] = row[k]
            k += 1


@njit(cache=True)
def forward_block(out, j0, j1, e_next, t_prev, inp, cfg, x, p, rec, buf):
    """The forward kernel up to and including epoch out[j] for j in [j0, j1), x and P
    after each of them packed into buf[j − j0]; returns (next epoch, its t_prev). One
    workspace for all the short chunks (allocating it costs ~40 µs, half an output
    epoch's filtering at 10 Hz output / 100 Hz IMU)."""
    ws = make_workspace(x.shape[0], cfg.q_psd.shape[0])
    for j in range(j0, j1):
        e1 = out[j] + 1
        if e1 > e_next:
            t_prev = gmikf_chunk_ws(e_next, e1, inp, cfg, x, p, rec, t_prev, ws)
            e_next = e1
        _pack_state(x, p, buf[j - j0])
    return e_next, t_prev


@njit(cache=True)
def combine_two_filter_into(x_f, p_f, x_b, p_b, s, u, w, x_s, p_s):
    """combine_two_filter in compiled form (module docstring): S = P_f + P_b = L Lᵀ,
    V = L⁻¹ P_f, x_s = x_f + Vᵀ L⁻¹ d, P_s = P_f − Vᵀ V; scratch s (n, n), u (n, 1),
    w (n, n) (V). False if S is not positive definite."""
    n = x_f.shape[0]
    for i in range(n):
        for j in range(n):
            s[i, j] = p_f[i, j] + p_b[i, j]
        d = x_b[i] - x_f[i]
        if i >= I_ATT0 and i < I_ATT0 + 3:
            d = (d + np.pi) % (2.0 * np.pi) - np.pi
        u[i, 0] = d
    if not cholesky_inplace(s, n):
        return False
    for i in range(n):              # forward substitution: u ← L⁻¹ d, w ← L⁻¹ P_f
        acc = u[i, 0]
        for k in range(i):
            acc -= s[i, k] * u[k, 0]
        u[i, 0] = acc / s[i, i]
        for j in range(n):
            acc = p_f[i, j]
            for k in range(i):
                acc -= s[i, k] * w[k, j]
            w[i, j] = acc / s[i, i]
    for i in range(n):
        acc = x_f[i]
        for k in range(n):
            acc += w[k, i] * u[k, 0]
        x_s[i] = acc
        for j in range(i, n):
            acc = p_f[i, j]
            for k in range(n):
                acc -= w[k, i] * w[k, j]
            p_s[i, j] = acc
            p_s[j, i] = acc
    x_s[I_HEADING] = x_s[I_HEADING] % (2.0 * np.pi)
    return True


@njit(cache=True)
def backward_block(inp_b, phantoms, j_hi, fwd_buf, j_lo, cfg, x_b, p_b, rec_b, t_prev,
                   xs, sds, xbs, sdbs, cov):
    """The backward kernel over one block of reversed epochs (inp_b); after each phantom
    epoch phantoms[m] (output epoch j = j_hi − m, its forward state in fwd_buf[j − j_lo])
    the predicted backward state is combined with the forward one into xs[j], sds[j],
    cov[j] (r^n, v^b, θ blocks); xbs, sdbs: the backward state. Returns (t_prev, the first
    output epoch whose combination failed or −1)."""
    n = x_b.shape[0]
    x_f = np.empty(n)
    p_f = np.empty((n, n))
    s = np.empty((n, n))
    u = np.empty((n, 1))
    w = np.empty((n, n))
    x_s = np.empty(n)
    p_s = np.empty((n, n))
    ws = make_workspace(n, cfg.q_psd.shape[0])
    pos = np.int64(0)       # not the literal 0: that would compile a second gmikf_chunk (~95 s)
    for m in range(phantoms.shape[0]):
        t_prev = gmikf_chunk_ws(pos, phantoms[m] + 1, inp_b, cfg, x_b, p_b, rec_b, t_prev,
                                ws)
        pos = phantoms[m] + 1
        j = j_hi - m
        _unpack_state(fwd_buf[j - j_lo], x_f, p_f)
        if not combine_two_filter_into(x_f, p_f, x_b, p_b, s, u, w, x_s, p_s):
            return t_prev, j
        for i in range(n):
            xs[j, i] = x_s[i]
            sds[j, i] = np.sqrt(max(p_s[i, i], 0.0))
            xbs[j, i] = x_b[i]
            sdbs[j, i] = np.sqrt(max(p_b[i, i], 0.0))
        for b in range(3):
            i0 = COV_BLOCK_START[b]
            for a in range(3):
                for c in range(3):
                    cov[j, b, a, c] = p_s[i0 + a, i0 + c]
    return t_prev, -1


def _backward_inputs(inp, still, out, j_lo, j_hi, e_hi, e0: int = 0,
                     e_total: int | None = None):
    """EpochInputs of the backward filter over the original epochs e_hi down to out[j_lo]
    (descending), a phantom (no measurements) before each output epoch out[j], j in
    [j_lo, j_hi]; and the phantoms' positions in that sequence (j_hi first). still of the
    entry for epoch e is the forward flag of the interval (t_e, t_e+1], still[e + 1].
    e0: inp's per-epoch arrays and still start at epoch e0 (the run's inputs of a block,
    GmikfRunner.inputs_from; still then reaches epoch e_hi + 1 when there is one);
    e_total: the run's epoch count (default: still's length)."""
    e_total = still.shape[0] + e0 if e_total is None else e_total
    desc = np.arange(e_hi, out[j_lo] - 1, -1)
    is_out = np.zeros(desc.size, dtype=np.int64)
    is_out[e_hi - out[j_lo:j_hi + 1]] = 1
    src = np.repeat(desc, 1 + is_out)
    first = np.r_[True, src[1:] != src[:-1]]
    phantom = first & np.repeat(is_out.astype(bool), 1 + is_out)
    meas_ok = ~phantom

    at = src - e0

    def rows(a):
        return np.where(meas_ok, a[at], -1)

    seg = inp._replace(
        t=np.ascontiguousarray(inp.t[at]), imu_idx=rows(inp.imu_idx),
        pos_idx=rows(inp.pos_idx), vel_idx=rows(inp.vel_idx), hdg_idx=rows(inp.hdg_idx),
        still=np.ascontiguousarray(still[np.minimum(src + 1, e_total - 1) - e0]),
        nhc_on=np.ascontiguousarray(inp.nhc_on[at] & meas_ok),
        zupt_on=np.ascontiguousarray(inp.zupt_on[at] & meas_ok),
        sog_idx=rows(inp.sog_idx) if inp.sog_idx.size else inp.sog_idx)
    return seg, np.flatnonzero(phantom)


def refuse_unsmoothable(config: GmikfConfig):
    """One line for what the two-filter smoother does not handle: the Gauss-Markov
    fix-error states (their backward model is not built)."""
    if config.gnss_error_states:
        from gmis.errors import GmisInputError
        raise GmisInputError("filter.smoother: the two-filter smoother does not handle the "
                             "Gauss-Markov fix-error states ([gnss].error_correlation_time_s) "
                             "yet; run without --smooth or without them")


BLOCK_OUTPUT_EPOCHS = 512  # output epochs per compiled block (spool I/O granularity)


def run_two_filter(epochs: EpochIndex, meas: Measurements, x0, config: GmikfConfig, frame,
                   stationary=None, rate_hz: float = 10.0, progress=None,
                   diffuse_factor: float = DIFFUSE_FACTOR):
    """Forward GMIKF (its full per-epoch records, as run_gmikf) and the two-filter smoothed
    states at the output epochs (output_epochs(rate_hz)); returns (FilterRecords,
    SmoothedStates)."""
    refuse_unsmoothable(config)
    runner = GmikfRunner(epochs, meas, x0, config, frame, stationary)
    out = np.ascontiguousarray(output_epochs(epochs.t, epochs.imu, rate_hz), dtype=np.int64)
    spool = StateSpool(runner.n)
    try:
        _forward_pass(runner, out, spool, progress)
        smoothed = _backward_pass(runner, out, spool, diffuse_factor, progress)
    finally:
        spool.close()
    return runner.rec, smoothed


def _forward_pass(runner: GmikfRunner, out, spool: StateSpool, progress):
    settings = runner.kernel_settings()
    buf = np.empty((BLOCK_OUTPUT_EPOCHS, spool.width))
    e_next, t_prev = runner.e_next, runner.t_prev
    for j0 in range(0, out.size, BLOCK_OUTPUT_EPOCHS):
        j1 = min(j0 + BLOCK_OUTPUT_EPOCHS, out.size)
        e_start = e_next
        e_next, t_prev = forward_block(out, j0, j1, e_next, t_prev, runner.inputs, settings,
                                       runner.x, runner.p, runner.records, buf)
        check_finite(runner.x, runner.p, runner.rec, e_start, e_next)
        spool.file.write(buf[:j1 - j0].tobytes())
        spool.count += j1 - j0
        if progress is not None:
            progress(0.5 * e_next / runner.e_total)
    runner.e_next, runner.t_prev = e_next, t_prev
    runner.advance(runner.e_total)


def backward_prior(runner: GmikfRunner, diffuse_factor: float) -> np.ndarray:
    """P_b(E), the backward filter's prior at the last epoch (around x_f(E)): diagonal,
    each variance (diffuse_factor·σ0)² or diffuse_factor² × the forward filter's own
    variance there, whichever is larger. The second term matters when the data end
    without aiding (an outage at the end): the forward σ is then metres, and a prior of
    3·σ0 around a state that far off would make the smoothed solution as confident as
    the prior. Double counting at E: σ_s = σ_f / √(1 + 1/factor²), 5 % for 3."""
    p0 = (diffuse_factor * np.asarray(runner.config.p0_sd, float)) ** 2
    p0 = np.r_[p0, np.zeros(runner.n - p0.size)] if p0.size < runner.n else p0[:runner.n]
    return np.diag(np.maximum(p0, diffuse_factor ** 2 * np.diag(runner.p)))


def _backward_pass(runner: GmikfRunner, out, spool: StateSpool, diffuse_factor,
                   progress) -> SmoothedStates:
    n, k_out = runner.n, out.size
    settings = runner.kernel_settings()._replace(compute_vce=0)
    x_b = runner.x.copy()
    p_b = backward_prior(runner, diffuse_factor)
    xs, sds = np.empty((k_out, n)), np.empty((k_out, n))
    xbs, sdbs = np.empty((k_out, n)), np.empty((k_out, n))
    cov = np.empty((k_out, 3, 3, 3))
    nw = n_noise_for(runner.n_imu)
    e_hi, t_prev = runner.e_total - 1, np.nan
    streak = np.zeros(len(GROUP_NAMES), dtype=np.int64)   # carried across the blocks
    for j_hi in range(k_out - 1, -1, -BLOCK_OUTPUT_EPOCHS):
        j_lo = max(0, j_hi - BLOCK_OUTPUT_EPOCHS + 1)
        spool.file.seek(j_lo * spool.bytes_per_epoch)
        fwd_buf = np.frombuffer(spool.file.read((j_hi - j_lo + 1) * spool.bytes_per_epoch),
                                dtype=np.float64).reshape(-1, spool.width)
        inp_b, phantoms = _backward_inputs(runner.inputs, runner.rec.still, out, j_lo, j_hi,
                                           e_hi)
        rec_b = _record_buffers(inp_b.t.size, n, nw, streak)
        t_prev, failed = backward_block(inp_b, phantoms, j_hi, fwd_buf, j_lo, settings, x_b,
                                        p_b, rec_b, t_prev, xs, sds, xbs, sdbs, cov)
        if failed >= 0 or not (np.isfinite(x_b).all() and np.isfinite(p_b).all()):
            e = int(out[max(failed, j_lo)])
            raise FilterDivergedError(
                f"backward filter of the smoother diverged near epoch {e} (t = "
                f"{runner.rec.t[e]:.3f} s): non-finite or non-positive-definite covariance; "
                "no solution written")
        e_hi = int(out[j_lo])
        if progress is not None:
            progress(0.5 + 0.5 * (k_out - j_lo) / k_out)
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
