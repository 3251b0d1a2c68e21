"""Python driver of the GMIKF: configuration, initial state, chunked numba loop, records.

The numerical core is :func:`gmis.gmikf.gmikf_chunk_ws`; this module only prepares arrays,
calls it chunk by chunk (for progress reporting) and packs the per-epoch records
(the kernel writes them through :data:`gmis.gmikf.EpochRecords`, a view of the same arrays).
"""

from dataclasses import dataclass, field, replace

import numpy as np

from gmis.critical_values import chi2_quantile, normal_quantile
from gmis.epochs import EpochIndex, RowIndex, dense_epochs
from gmis.errors import GmisInputError
from gmis.filter_defaults import IMU_OUTLIER_TEST, OUTLIER_ALPHA, Q_RATE_HZ, REOPEN_AFTER_EPOCHS
from gmis.gmikf import (
    GROUP_NAMES,
    N_SLOTS,
    EpochInputs,
    EpochRecords,
    KernelSettings,
    gmikf_chunk_ws,
    make_workspace,
)
from gmis.gnss_error_states import N_GNSS_ERROR_STATES
from gmis.imu_spool import ImuSpool
from gmis.measurement_models import SCALE_REGRESSOR_HALF
from gmis.motion import StopDetector, gnss_horizontal_speed, stop_epochs
from gmis.state import ATT, N_KINEMATIC_NOISE, POS, STATE_NAMES_27, VEL, n_noise_for


class FilterDivergedError(GmisInputError):
    """The filter produced a non-finite state or covariance: the run stops (the CLI prints
    one line and exits non-zero) instead of writing NaN positions."""


@dataclass
class GmikfConfig:
    """Everything the loop needs besides the data. Units: SI and radians.

    q_sd: process-noise 1σ per step of 1/q_rate_hz s [j(3) m/s³, ω̇(3) rad/s², b_ω
    drift(3) rad/s, b_a drift(3) m/s², (S_ω(3), S_a(3) drift)] — length n_imu − 9; the
    kernel turns them into spectral densities (:meth:`q_psd`) and builds every epoch's
    Q_d from its own Δt (docs/DESIGN.md "Process noise from Δt").
    q_rate_hz: the rate the q_sd values are per-step at (001 Table 6-2: 100 Hz); it does
    NOT follow the IMU rate.
    imu_sd: (6,) gyro rad/s, accel m/s². p0_sd: (n_imu,) initial 1σ.
    nhc_sd: (2,) lateral/vertical 1σ (m/s) of the non-holonomic pseudo-observations, applied
    at the first epoch of every nhc_interval_s; zeros = constraint off. nhc_lever_arm: (3,)
    constraint point from the IMU (m, body RFU).
    """
    n_imu: int
    q_sd: np.ndarray
    imu_sd: np.ndarray
    lever_arm: np.ndarray
    p0_sd: np.ndarray
    outlier_alpha: float = OUTLIER_ALPHA
    vce_mode: int = 0            # 0 off, 1 residuals/redundancy, 2 + r_x (tests)
    static_q_scale: float = 0.0  # jerk/ang. acc. noise factor at rest (001 Table 4-3)
    vce_noise_axes: int = 6      # process-noise axes with VCE residuals (6: no drifts)
    chunk: int = 4096
    nhc_sd: np.ndarray = field(default_factory=lambda: np.zeros(2))
    nhc_interval_s: float = 0.5
    nhc_lever_arm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    q_rate_hz: float = Q_RATE_HZ

    def q_psd(self) -> np.ndarray:
        """Spectral densities of q_sd (δt = 1/q_rate_hz): white jerk / angular acceleration
        q = σ² δt ((m/s³)²·s, (rad/s²)²·s), random-walk drifts q = σ²/δt (unit²/s); a step
        of δt gets back exactly the per-step σ² (docs/DESIGN.md "Process noise from Δt")."""
        dt = 1.0 / self.q_rate_hz
        q = self.q_sd ** 2
        return np.concatenate([q[:N_KINEMATIC_NOISE] * dt, q[N_KINEMATIC_NOISE:] / dt])
    # True: the IMU rows do not update S (gmis.gmikf.drop_imu_scale_gain, the fix of the
    # scale-factor runaway); recipes set it (gmis.engine_configs.gmikf_config). False keeps
    # the plain EKF update (the dense-formula tests of tests/test_vce_redundancy.py).
    consider_scale_imu: bool = False
    # an aiding group rejected at this many consecutive epochs re-opens the covariance and
    # is accepted again (gmis.lockout_recovery); 0 = never
    reopen_after: int = REOPEN_AFTER_EPOCHS
    # the IMU rows take part in the outlier tests (001 §5.2.3.1 tests every group; off by
    # default, docs/DESIGN.md "Robustness on real data")
    imu_outlier_test: bool = IMU_OUTLIER_TEST
    # 1/τ (1/s) per drift state (b_ω, b_a[, S_ω, S_a]): 0 = random walk, > 0 = first-order
    # Gauss-Markov with that correlation time (gmis.system_model); None = all random walks
    drift_inv_tau: np.ndarray | None = None
    # ZUPT/ZARU at detected stops (gmis.motion.stop_epochs), every zupt_interval_s: 1σ of
    # v^b (m/s) and ω (rad/s); zeros = off
    zupt_sd: np.ndarray = field(default_factory=lambda: np.zeros(3))
    zaru_sd: np.ndarray = field(default_factory=lambda: np.zeros(3))
    zupt_interval_s: float = 0.1
    stop_detector: StopDetector = field(default_factory=StopDetector)
    # (3,) m body RFU, L_secondary − L_primary when the heading stream is gnss.heading's
    # level-vehicle conversion ψ_b − α (gmis.measurement_models: attitude-aware row); 0 = ψ
    heading_baseline: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # time-correlated GNSS fix errors (gmis.gnss_error_states): correlation time τ (s) and
    # stationary 1σ (m) per ENU axis; τ = 0: white fixes, no error states
    gnss_error_tau_s: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gnss_error_sigma_m: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def gnss_error_states(self) -> bool:
        return bool(np.all(self.gnss_error_tau_s > 0))

    @property
    def zupt_enabled(self) -> bool:
        return bool(np.all(self.zupt_sd > 0) and np.all(self.zaru_sd > 0))

    @property
    def nhc_enabled(self) -> bool:
        return bool(np.all(self.nhc_sd > 0))

    def __post_init__(self):
        self.q_sd = np.asarray(self.q_sd, dtype=float)
        self.imu_sd = np.asarray(self.imu_sd, dtype=float)
        self.lever_arm = np.asarray(self.lever_arm, dtype=float)
        self.p0_sd = np.asarray(self.p0_sd, dtype=float)
        self.nhc_sd = np.asarray(self.nhc_sd, dtype=float).reshape(2)
        self.nhc_lever_arm = np.asarray(self.nhc_lever_arm, dtype=float).reshape(3)
        self.zupt_sd = np.asarray(self.zupt_sd, dtype=float).reshape(3)
        self.zaru_sd = np.asarray(self.zaru_sd, dtype=float).reshape(3)
        self.heading_baseline = np.asarray(self.heading_baseline, dtype=float).reshape(3)
        if not (np.all(self.nhc_sd > 0) or np.all(self.nhc_sd == 0)):
            raise ValueError(f"nhc_sd must be both > 0 (constraint on) or both 0 (off), "
                             f"got {self.nhc_sd.tolist()}")
        if not self.nhc_interval_s > 0:
            raise ValueError(f"nhc_interval_s must be > 0, got {self.nhc_interval_s}")
        if self.n_imu not in (21, 27):
            raise ValueError("n_imu must be 21 or 27")
        if self.q_sd.shape != (n_noise_for(self.n_imu),):
            raise ValueError(f"q_sd must have {n_noise_for(self.n_imu)} entries")
        if not self.q_rate_hz > 0:
            raise ValueError(f"q_rate_hz must be > 0, got {self.q_rate_hz}")
        self.drift_inv_tau = np.zeros(self.n_imu - 15) if self.drift_inv_tau is None else \
            np.asarray(self.drift_inv_tau, dtype=float).reshape(self.n_imu - 15)
        if not np.all(np.isfinite(self.drift_inv_tau) & (self.drift_inv_tau >= 0)):
            raise ValueError(f"drift_inv_tau must be finite and >= 0, got {self.drift_inv_tau}")
        self.gnss_error_tau_s = np.asarray(self.gnss_error_tau_s, dtype=float).reshape(3)
        self.gnss_error_sigma_m = np.asarray(self.gnss_error_sigma_m, dtype=float).reshape(3)
        if not (np.all(self.gnss_error_tau_s > 0) and np.all(self.gnss_error_sigma_m > 0)
                or np.all(self.gnss_error_tau_s == 0)):
            raise ValueError("gnss_error_tau_s must be all > 0 with gnss_error_sigma_m > 0, "
                             f"or all 0; got {self.gnss_error_tau_s.tolist()}, "
                             f"{self.gnss_error_sigma_m.tolist()}")


@dataclass
class Measurements:
    """Aiding and IMU data on one time base, in the navigation frame (ENU, m, rad)."""
    imu_z: np.ndarray                       # (N, 6) gyro rad/s, accel m/s², body RFU
    pos_enu: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    pos_sd: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    vel_enu: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    vel_sd: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    heading: np.ndarray = field(default_factory=lambda: np.zeros(0))
    heading_sd: np.ndarray = field(default_factory=lambda: np.zeros(0))
    # speed over ground (m/s) and course (rad) of a receiver without vertical velocity
    # (gmis.speed_course) and their 1σ; a course σ of NaN = course absent at that row
    speed_course: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    speed_course_sd: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))


@dataclass
class FilterRecords:
    """Per-epoch records (columnar). Slots: see gmis.gmikf.SLOT_NAMES."""
    t: np.ndarray
    x: np.ndarray            # (E, n) state after the update
    sd: np.ndarray           # (E, n) 1σ after the update
    cov_blocks: np.ndarray   # (E, 3, 3, 3) covariance of r^n, v^b, θ
    innov: np.ndarray        # (E, N_SLOTS) innovation d = z − h(x⁻), NaN = absent
    innov_var: np.ndarray    # (E, N_SLOTS) diag D
    rejected: np.ndarray     # (E, N_SLOTS) int8, 1 = rejected by the outlier tests
    vz: np.ndarray           # (E, N_SLOTS) measurement residual (VCE mode)
    rz: np.ndarray           # (E, N_SLOTS) redundancy index
    vw: np.ndarray           # (E, nw) process-noise residual
    rw: np.ndarray           # (E, nw)
    rx: np.ndarray           # (E,) state-prediction redundancy (vce_mode 2)
    nobs: np.ndarray         # (E,) observations used
    rvar: np.ndarray         # (E, N_SLOTS) measurement variance R_ii used (NaN = absent)
    imu_row: np.ndarray      # (E,) IMU row or -1
    still: np.ndarray | None = None  # (E,) epochs treated as stationary
    helmert_s: np.ndarray | None = None  # (N_SLOTS+nw)² Σ_k tr(D⁻¹C_i D⁻¹C_j) (vce_mode ≥ 1)
    helmert_totals: np.ndarray | None = None  # [Σ dᵀD⁻¹d, Σ m] over predicted epochs
    # (N_SLOTS+nw+1,) outlier-test truncation weights Σ w_i of the elementary components,
    # then w of Σ dᵀD⁻¹d: E[Σ dᵀD⁻¹C_iD⁻¹d] = Σ r_i − τ w_i (gmis.gmikf.truncation_terms)
    helmert_trunc: np.ndarray | None = None
    streak: np.ndarray | None = None     # (n_groups,) running rejection streak per group
    reopened: np.ndarray | None = None   # (E,) int8 bitmask of groups re-opened at e
    nll: np.ndarray | None = None        # (E,) log det D + dᵀD⁻¹d per update (0 = none)


# EpochInputs fields indexed by epoch (the others are data streams indexed by row)
PER_EPOCH_INPUTS = ("t", "imu_idx", "pos_idx", "vel_idx", "hdg_idx", "still", "nhc_on",
                    "zupt_on", "sog_idx")


def nonholonomic_epochs(t, interval_s: float):
    """(E,) bool: the first epoch of every interval_s window of the time base t (s)."""
    t = np.asarray(t, dtype=float)
    on = np.zeros(t.size, dtype=np.bool_)
    if t.size:
        on[0] = True
        # in blocks of epochs (each with the epoch before it): no (E,) float temporaries
        for a in range(1, t.size, NHC_BLOCK):
            k = np.floor((t[a - 1:a + NHC_BLOCK] - t[0]) / interval_s + 1e-9)
            on[a:a + NHC_BLOCK] = k[1:] != k[:-1]
    return on


NHC_BLOCK = 1 << 16


def zupt_update_epochs(epochs: EpochIndex, meas: Measurements, config: GmikfConfig):
    """(stopped, updates): (E,) bool, the stopped epochs (gmis.motion.stop_epochs with the
    GNSS speed of the position/velocity rows) and those of them that carry ZUPT/ZARU, the
    first of every zupt_interval_s; all False when ZUPT/ZARU are off."""
    on = np.zeros(len(epochs), dtype=np.bool_)
    if not config.zupt_enabled:
        return on, on
    has_pos = epochs.pos >= 0
    gnss_t = np.empty(int(has_pos.sum()))
    gnss_t[epochs.pos[has_pos]] = epochs.t[has_pos]
    vel = meas.vel_enu if len(meas.vel_enu) == gnss_t.size else None
    speed = gnss_horizontal_speed(gnss_t, np.asarray(meas.pos_enu).reshape(-1, 3), vel)
    stopped = stop_epochs(epochs, np.asarray(meas.imu_z, float), gnss_t, speed,
                          config.stop_detector)
    return stopped, stopped & nonholonomic_epochs(epochs.t, config.zupt_interval_s)


def initial_covariance(p0_sd):
    return np.diag(np.asarray(p0_sd, dtype=float) ** 2)


class GmikfRunner:
    """The GMIKF loop state between chunks: x, P, the per-epoch records and the numba
    arguments. ``advance(e_end)`` processes epochs up to (not including) e_end; other
    updates (e.g. the tightly coupled DD update in gmis.tc) may change ``x`` and ``p`` in
    place between calls.

    sink: None keeps the records of every epoch in ``rec`` (E rows). A callable
    sink(e0, chunk) makes the records a buffer of ``config.chunk`` epochs: the kernel
    writes them at buffer-relative epochs (its per-epoch inputs are views starting at the
    buffer's first epoch, the data streams stay whole), and every full buffer is handed
    to the sink as a FilterRecords of epochs [e0, e0 + len) before it is reused — memory
    independent of the duration (docs/DESIGN.md "Bounded memory"). The accumulated
    records (helmert_s, helmert_totals, helmert_trunc, streak) are whole in both modes."""

    def __init__(self, epochs: EpochIndex, meas: Measurements, x0, config: GmikfConfig,
                 frame, stationary=None, p0=None, sink=None):
        if config.gnss_error_states and np.asarray(x0).shape[0] == config.n_imu:
            x0, p0 = with_gnss_error_states(x0, config, p0)
        n = np.asarray(x0).shape[0]
        self.n, self.n_imu = n, config.n_imu
        nw = n_noise_for(config.n_imu)
        self.nw = nw
        # VCE process-noise axes: the IMU's, then in a VCE run the fix-error driving noise
        # of gmis.gnss_error_states (σ_b² a variance component; its records after the IMU's)
        self.nw_vce = nw + (N_GNSS_ERROR_STATES if config.gnss_error_states
                            and config.vce_mode > 0 else 0)
        if sink is None:              # whole records: whole index arrays
            epochs = dense_epochs(epochs)
        e_total = len(epochs)
        self.e_total = e_total
        self.sink = sink
        rows = e_total if sink is None else max(1, min(int(config.chunk), e_total))
        self.config = config
        self.frame = np.asarray(frame, dtype=float)
        self.x = np.array(x0, dtype=float)
        self.p = initial_covariance(config.p0_sd) if p0 is None else np.array(p0, float)
        if self.p.shape != (n, n):
            raise ValueError(f"P0 must be {n}×{n}")
        self.p0_var = np.ascontiguousarray(np.diag(self.p), dtype=float).copy()
        self.chi2_crit = np.zeros(N_SLOTS + 1)
        alpha = config.outlier_alpha
        self.outlier_on = alpha > 0
        if self.outlier_on:
            self.chi2_crit[1:] = chi2_quantile(1 - alpha, np.arange(1, N_SLOTS + 1))
            self.z_crit = float(normal_quantile(1 - alpha / 2))
        else:
            self.z_crit = np.inf
        rec = FilterRecords(
            t=epochs.t, x=np.empty((rows, n)), sd=np.empty((rows, n)),
            cov_blocks=np.empty((rows, 3, 3, 3)), innov=np.empty((rows, N_SLOTS)),
            innov_var=np.empty((rows, N_SLOTS)),
            rejected=np.zeros((rows, N_SLOTS), dtype=np.int8),
            vz=np.empty((rows, N_SLOTS)), rz=np.empty((rows, N_SLOTS)),
            vw=np.empty((rows, self.nw_vce)), rw=np.empty((rows, self.nw_vce)),
            rx=np.empty(rows),
            nobs=np.zeros(rows, dtype=np.int64), imu_row=epochs.imu,
            rvar=np.empty((rows, N_SLOTS)))
        rec.still = np.zeros(e_total, dtype=np.bool_) if stationary is None else \
            np.ascontiguousarray(stationary, dtype=np.bool_)
        stopped, zupt_on = zupt_update_epochs(epochs, meas, config)
        rec.still = rec.still | stopped   # a detected stop is static (001 Table 4-3) too
        rec.helmert_s = np.zeros((N_SLOTS + self.nw_vce, N_SLOTS + self.nw_vce))
        rec.helmert_totals = np.zeros(2)
        rec.helmert_trunc = np.zeros(N_SLOTS + self.nw_vce + 1)
        rec.streak = np.zeros(len(GROUP_NAMES), dtype=np.int64)
        rec.reopened = np.zeros(rows, dtype=np.int8)
        rec.nll = np.zeros(rows)
        self.rec = rec

        def f64(a, shape):
            return np.ascontiguousarray(a, dtype=float).reshape(shape)

        self.nhc_on = nonholonomic_epochs(epochs.t, config.nhc_interval_s) \
            if config.nhc_enabled else np.zeros(e_total, dtype=np.bool_)
        # IMU samples on disk (gmis.imu_spool): in sink mode every record buffer gets the
        # rows of its own epochs (inputs_from); otherwise they are read whole
        self.imu_spool = meas.imu_z if isinstance(meas.imu_z, ImuSpool) and sink is not None \
            else None
        imu_z = np.zeros((0, 6)) if self.imu_spool is not None else meas.imu_z
        # compact epoch indices (gmis.epochs.RowIndex): each buffer gets its own rows
        self.compact = {name: idx for name, idx in (
            ("imu_idx", epochs.imu), ("pos_idx", epochs.pos), ("vel_idx", epochs.vel),
            ("hdg_idx", epochs.heading)) if isinstance(idx, RowIndex)}

        def index(name, idx):
            return np.zeros(0, dtype=np.int64) if name in self.compact else idx
        self.inputs = EpochInputs(
            epochs.t, index("imu_idx", epochs.imu), index("pos_idx", epochs.pos),
            index("vel_idx", epochs.vel), index("hdg_idx", epochs.heading),
            f64(imu_z, (-1, 6)), config.imu_sd, f64(meas.pos_enu, (-1, 3)),
            f64(meas.pos_sd, (-1, 3)), f64(meas.vel_enu, (-1, 3)), f64(meas.vel_sd, (-1, 3)),
            f64(meas.heading, (-1,)), f64(meas.heading_sd, (-1,)), rec.still, self.nhc_on,
            zupt_on, np.ascontiguousarray(epochs.sog, dtype=np.int64),
            f64(meas.speed_course, (-1, 2)), f64(meas.speed_course_sd, (-1, 2)))
        self.records = EpochRecords(*(getattr(rec, name) for name in EpochRecords._fields))
        # one workspace for the whole run: it carries the fix-error driving noise that
        # VCE accumulates between position updates across chunks (gmis.gnss_error_states),
        # and the tightly coupled filter calls advance at every GNSS epoch
        # (gmis.gmikf.make_workspace, ~35 µs per call)
        self.workspace = make_workspace(n, nw)
        self.e_next = 0
        self.t_prev = np.nan
        self.rows = rows
        self.buffer_start = 0      # first epoch of the record buffer (sink mode)
        self._buffer_inputs = self.inputs if self.imu_spool is None and not self.compact \
            else self.inputs_from(0)
        self._settings = None          # (config, its KernelSettings) of advance

    def advance(self, e_end: int):
        """Process epochs [e_next, e_end)."""
        e_end = min(e_end, self.e_total)
        if e_end <= self.e_next:
            return
        # built once per config (the tightly coupled filter advances at every GNSS epoch:
        # the namedtuple, q_psd and the 1/τ arrays cost more than a short chunk)
        if self._settings is None or self._settings[0] is not self.config:
            self._settings = (self.config, self.kernel_settings())
        settings = self._settings[1]
        if self.sink is None:
            self.t_prev = gmikf_chunk_ws(self.e_next, e_end, self.inputs, settings, self.x,
                                         self.p, self.records, self.t_prev, self.workspace)
            e0, self.e_next = self.e_next, e_end
            check_finite(self.x, self.p, self.rec, e0, e_end)
            return
        while self.e_next < e_end:
            b0 = self.buffer_start
            stop = min(e_end, b0 + self.rows)
            self.t_prev = gmikf_chunk_ws(self.e_next - b0, stop - b0, self._buffer_inputs,
                                         settings, self.x, self.p, self.records, self.t_prev,
                                         self.workspace)
            e0, self.e_next = self.e_next, stop
            check_finite(self.x, self.p, self.chunk_records(b0, stop - b0), e0 - b0,
                         stop - b0, offset=b0)
            if stop == b0 + self.rows or stop == self.e_total:
                self._hand_over(b0, stop)

    def _hand_over(self, b0: int, stop: int):
        """Give the full buffer of epochs [b0, stop) to the sink and start the next one."""
        self.sink(b0, self.chunk_records(b0, stop - b0))
        self.rec.reopened[:] = 0     # the kernel only sets the bits of events
        self.buffer_start = stop
        self._buffer_inputs = self.inputs_from(stop)

    def finish_buffer(self):
        """Sink mode: process the epochs left in the current record buffer and hand it
        over (also when the epochs were processed outside advance, on buffer_inputs)."""
        b0 = self.buffer_start
        stop = min(self.e_total, b0 + self.rows)
        if self.e_next < stop:
            self.advance(stop)
        elif b0 < stop:
            self._hand_over(b0, stop)

    @property
    def buffer_inputs(self) -> EpochInputs:
        """Sink mode: the kernel inputs of the current record buffer (inputs_from its
        first epoch): a kernel called on them and on ``records`` works at buffer-relative
        epochs, as advance does."""
        return self._buffer_inputs

    def inputs_from(self, e0: int, e1: int | None = None) -> EpochInputs:
        """The kernel inputs with the per-epoch arrays starting at epoch e0 (views; the
        compact epoch indices as the buffer's entries, gmis.epochs.RowIndex). With
        the IMU samples on disk: imu_z = the rows of the buffer's epochs [e0, e0 + rows)
        and SCALE_REGRESSOR_HALF rows either side (the neighbours of
        gmis.measurement_models.imu_scale_column_from_neighbours; clipped at the data's
        ends, so its bounds tests see the same rows), imu_idx relative to the first.
        e1: the end of the epochs whose rows are wanted (default: the buffer's end)."""
        inp = self.inputs
        e1 = min(self.e_total, e0 + self.rows) if e1 is None else min(self.e_total, e1)
        views = {name: getattr(inp, name)[e0:] for name in PER_EPOCH_INPUTS
                 if name not in self.compact}
        for name, idx in self.compact.items():      # the buffer's rows of a RowIndex
            views[name] = idx.dense(e0, e1)
        if self.imu_spool is not None:
            idx = views["imu_idx"][:e1 - e0]
            on = idx[idx >= 0]
            lo = hi = 0
            if on.size:
                lo = max(0, int(on.min()) - SCALE_REGRESSOR_HALF)
                hi = min(self.imu_spool.n, int(on.max()) + SCALE_REGRESSOR_HALF + 1)
            views["imu_idx"] = np.where(idx >= 0, idx - lo, -1)
            views["imu_z"] = self.imu_spool.rows(lo, hi)
        return inp._replace(**views)

    def chunk_records(self, e0: int, length: int) -> FilterRecords:
        """The records of epochs [e0, e0 + length) as a FilterRecords (views: of the whole
        records, or of the buffer in sink mode, valid until it is reused)."""
        rec = self.rec
        b = 0 if self.sink is None else e0
        per_epoch = {name: getattr(rec, name)[e0 - b:e0 - b + length] for name in
                     ("x", "sd", "cov_blocks", "innov", "innov_var", "rejected", "vz", "rz",
                      "vw", "rw", "rx", "nobs", "rvar", "reopened")}
        return replace(rec, t=rec.t[e0:e0 + length], imu_row=rec.imu_row[e0:e0 + length],
                       still=rec.still[e0:e0 + length], **per_epoch)

    def kernel_settings(self) -> KernelSettings:
        """The numba settings of this run (also used by the backward filter of
        gmis.smoother)."""
        cfg = self.config
        return KernelSettings(
            int(self.n_imu), cfg.q_psd(), self.vce_step_var(), float(cfg.static_q_scale),
            cfg.lever_arm, self.frame,
            cfg.nhc_sd, cfg.nhc_lever_arm, self.chi2_crit, float(self.z_crit),
            bool(self.outlier_on), int(cfg.vce_mode),
            int(min(cfg.vce_noise_axes, self.nw_vce)),
            bool(cfg.consider_scale_imu), cfg.zupt_sd, cfg.zaru_sd,
            int(cfg.reopen_after if self.outlier_on else 0), self.p0_var,
            bool(cfg.imu_outlier_test), cfg.drift_inv_tau, cfg.heading_baseline,
            np.where(cfg.gnss_error_tau_s > 0, 1.0 / np.maximum(cfg.gnss_error_tau_s, 1e-300),
                     0.0), cfg.gnss_error_sigma_m ** 2)

    def vce_step_var(self) -> np.ndarray:
        """The variances VCE divides v_w² by (KernelSettings.q_step_var): the configured
        per-step q_sd², then 1 for the fix-error axes (their v_w is recorded in m)."""
        return np.r_[self.config.q_sd ** 2, np.ones(self.nw_vce - self.nw)]

    def record_state(self, e: int):
        """Overwrite epoch e's state records with the current x, P (after an extra update)."""
        rec = self.rec
        rec.x[e] = self.x
        rec.sd[e] = np.sqrt(np.maximum(np.diag(self.p), 0.0))
        for b, sl in enumerate((POS, VEL, ATT)):
            rec.cov_blocks[e, b] = self.p[sl, sl]


def with_gnss_error_states(x0, config: GmikfConfig, p0=None):
    """x0 and P0 with the three GNSS fix-error states b (gmis.gnss_error_states) appended:
    b = 0 with its stationary variance σ_b². The initial position of every gmis start is
    taken from the fixes, r0 = z − b (less the lever arm), so its error carries −b:
    P_rr += σ_b² and P_rb = −σ_b² (per ENU axis)."""
    n_imu = config.n_imu
    x = np.r_[np.asarray(x0, dtype=float), np.zeros(3)]
    p = np.zeros((n_imu + 3, n_imu + 3))
    p[:n_imu, :n_imu] = initial_covariance(config.p0_sd) if p0 is None else p0
    var = config.gnss_error_sigma_m ** 2
    for i in range(3):
        p[n_imu + i, n_imu + i] = var[i]
        p[POS.start + i, POS.start + i] += var[i]
        p[POS.start + i, n_imu + i] = p[n_imu + i, POS.start + i] = -var[i]
    return x, p


def check_finite(x, p, rec: FilterRecords, e0: int, e1: int, offset: int = 0):
    """Raise FilterDivergedError if x, P or the records of epochs [e0, e1) hold a
    non-finite number, naming the first such epoch and state (rec's epoch e is the run's
    epoch e + offset)."""
    if np.isfinite(x).all() and np.isfinite(p).all():
        return
    bad = ~np.isfinite(rec.x[e0:e1]) | ~np.isfinite(rec.sd[e0:e1])
    rows = np.flatnonzero(bad.any(axis=1))
    e = e0 + int(rows[0]) if rows.size else e1 - 1
    cols = np.flatnonzero(bad[e - e0]) if rows.size else \
        np.flatnonzero(~np.isfinite(x) | ~np.isfinite(np.diag(p)))
    names = [STATE_NAMES_27[c] if c < len(STATE_NAMES_27) else f"x[{c}]" for c in cols]
    raise FilterDivergedError(
        f"filter diverged: non-finite state/covariance at epoch {e + offset} "
        f"(t = {rec.t[e]:.3f} s), "
        f"states {', '.join(names) or 'P off-diagonal'}; no solution written")


def run_gmikf(epochs: EpochIndex, meas: Measurements, x0, config: GmikfConfig, frame,
              progress=None, stationary=None, sink=None) -> FilterRecords:
    """Run the GMIKF over all epochs from x0 (n_imu,). progress(fraction) is called
    between chunks. stationary: (E,) bool, epochs at rest (see gmis.motion).

    sink: None returns the records of every epoch; sink(e0, chunk) receives them chunk
    by chunk instead (GmikfRunner) and the returned FilterRecords holds the last chunk's
    per-epoch rows only, with the accumulated helmert_s, helmert_totals, helmert_trunc and
    streak."""
    runner = GmikfRunner(epochs, meas, x0, config, frame, stationary, sink=sink)
    for e0 in range(0, runner.e_total, config.chunk):
        runner.advance(e0 + config.chunk)
        if progress is not None:
            progress(min(1.0, (e0 + config.chunk) / runner.e_total))
    return runner.rec
