"""True trajectory of a simulated land vehicle (ENU tangent frame at the origin).

Deterministic segments (static, accelerate, cruise, turn, climb) are generated
analytically. Four scalar channels — speed s, pitch p, roll γ, heading ψ — are sums of
smooth "events":

- rate trapezoid (accelerate: ṡ; turn: ψ̇): raised-cosine ramp up over T_r, hold, raised-cosine
  ramp down, so the rate is C¹ and its derivative (longitudinal jerk, yaw angular
  acceleration) is continuous and finite;
- smooth step (roll/pitch changes): Δ·(u − sin 2πu / 2π), u = (t − t0)/T, with zero first
  and second derivative at both ends;
- bank (turn with roll): a smooth step to the bank angle during the yaw-rate ramp-up and
  back during the ramp-down.

Every channel is therefore C² (angular acceleration and longitudinal jerk continuous).

The vehicle moves along its body forward axis up to a sideslip angle proportional to the
lateral acceleration (linear-tyre steady-state model, small angle),

    β = K·a_lat,   a_lat = ψ̇·s,   v^b = [s·β, s, 0] = [K ψ̇ s², s, 0]

with K = [vehicle] sideslip_deg_per_m_s2 in rad/(m/s²) (β > 0: velocity to the body
right of the forward axis; K = 0, the default, is the exact non-holonomic vehicle). ψ̇ is
the Euler heading rate (the channel derivative), not the body z rate; the two differ by
O(p, γ) only. v_x is C¹ (ψ̇ is C¹), so with K ≠ 0 the body jerk is discontinuous where a
turn's yaw-rate ramps start and end.

From s, θ, θ̇, θ̈ everything follows in closed form: ω_nb^b = C(θ)⁻¹ θ̇ (inverse of 001 eq.
2.2.6, written out below), v̇_x = K(ψ̈ s² + 2 ψ̇ s ṡ),

    a^b = v̇^b + ω×v^b = [v̇_x − ω_z s,  ṡ + ω_z v_x,  ω_x s − ω_y v_x]

(001 eq. 4.1.15, so a^b = C_n^b r̈^n; for K = 0 it is [−ω_z s, ṡ, ω_x s]) and
v^n = C_b^n v^b = s·c_y + v_x·c_x (eq. 4.1.14, c_x, c_y the first two columns of C_b^n,
eq. 2.2.4). Position is the integral of v^n, done per IMU interval with 3-point
Gauss-Legendre quadrature (exact for degree-5 polynomials; the integrand is smooth except
at the C¹ points of v_x), so its accumulated error is < 1e-8 m (5e-9 m over the
tightly_coupled drive with sideslip, against 8 sub-intervals per step).

Random segments integrate the GMIKF kinematics (001 eq. 4.1.14-4.1.18)

    ṙ = C_b^n v,  v̇ = a − ω×v,  ȧ = j − ω×a,  θ̇ = C(θ) ω,  ω̇ = α

exactly (RK4, 8 substeps per IMU interval) with inputs held constant over each IMU step
[t_k, t_k+1) — the discrete-time process of the filter's system model:

    j_k = w_j,k − 2Ω a_k − Ω² (v_k − [0, s_nom, 0])          w_j,k ~ N(0, diag σ_jerk²)
    α_k = w_α,k − 2Ω ω_k − Ω² [p_k, γ_k, 0]                  w_α,k ~ N(0, diag σ_angacc²)

with w drawn independently per IMU step and axis (body frame) and Ω = 1/reversion_time_s
(0 = no reversion: pure per-step white jerk/angular acceleration). The weak, critically
damped reversion keeps speed near s_nom and the vehicle near level; its share of j and α is
small (recorded separately: the truth keeps both the white draws w and the applied inputs).
"""

from dataclasses import dataclass, field

import numpy as np
from numba import njit

from gmis.earth import enu_to_geodetic, make_nav_frame
from gmis.errors import GmisInputError
from gmis.frames import dcm_body_to_nav_into, euler_rate_matrix_into
from gmis.state import ACC, ATT, POS, RATE, VEL

DEG = np.pi / 180.0
RK4_SUBSTEPS = 8
_GL_NODES = np.array([-np.sqrt(0.6), 0.0, np.sqrt(0.6)])
_GL_WEIGHTS = np.array([5.0, 8.0, 5.0]) / 9.0


@dataclass
class RateTrapezoid:
    """Channel rate r(t): raised-cosine ramp 0→peak over ramp_s, hold hold_s, ramp down."""
    t0: float
    ramp_s: float
    hold_s: float
    peak: float

    @property
    def end(self):
        return self.t0 + 2.0 * self.ramp_s + self.hold_s

    def evaluate(self, t):
        """(value increment, rate, rate derivative) at times t (arrays)."""
        tr, th, pk = self.ramp_s, self.hold_s, self.peak
        tau = t - self.t0
        val = np.zeros_like(t)
        d1 = np.zeros_like(t)
        d2 = np.zeros_like(t)
        up = (tau >= 0.0) & (tau < tr)
        x = np.pi * tau[up] / tr
        val[up] = 0.5 * pk * (tau[up] - tr / np.pi * np.sin(x))
        d1[up] = 0.5 * pk * (1.0 - np.cos(x))
        d2[up] = 0.5 * pk * np.pi / tr * np.sin(x)
        hold = (tau >= tr) & (tau < tr + th)
        val[hold] = pk * (0.5 * tr + tau[hold] - tr)
        d1[hold] = pk
        down = (tau >= tr + th) & (tau < 2.0 * tr + th)
        u = tau[down] - tr - th
        x = np.pi * u / tr
        val[down] = pk * (0.5 * tr + th) + 0.5 * pk * (u + tr / np.pi * np.sin(x))
        d1[down] = 0.5 * pk * (1.0 + np.cos(x))
        d2[down] = -0.5 * pk * np.pi / tr * np.sin(x)
        val[tau >= 2.0 * tr + th] = pk * (tr + th)
        return val, d1, d2


@dataclass
class SmoothStep:
    """Channel value moves by delta over duration_s: Δ·(u − sin(2πu)/2π)."""
    t0: float
    duration_s: float
    delta: float

    @property
    def end(self):
        return self.t0 + self.duration_s

    def evaluate(self, t):
        u = np.clip((t - self.t0) / self.duration_s, 0.0, 1.0)
        val = self.delta * (u - np.sin(2.0 * np.pi * u) / (2.0 * np.pi))
        d1 = self.delta / self.duration_s * (1.0 - np.cos(2.0 * np.pi * u))
        d2 = self.delta / self.duration_s ** 2 * 2.0 * np.pi * np.sin(2.0 * np.pi * u)
        return val, d1, d2


@dataclass
class Channel:
    initial: float
    events: list = field(default_factory=list)

    def evaluate(self, t):
        """value and rate of the channel at times t (sorted array)."""
        val, d1, _ = self.evaluate_with_second(t)
        return val, d1

    def evaluate_with_second(self, t):
        """value, first and second time derivative of the channel at times t (sorted)."""
        val = np.full_like(t, self.initial)
        d1 = np.zeros_like(t)
        d2 = np.zeros_like(t)
        for ev in self.events:
            lo, hi = np.searchsorted(t, [ev.t0, ev.end])
            if lo < hi:
                v, r, a = ev.evaluate(t[lo:hi])
                val[lo:hi] += v
                d1[lo:hi] += r
                d2[lo:hi] += a
            if hi < t.size:
                v, _, _ = ev.evaluate(t[hi:hi + 1])
                val[hi:] += v[0]
        return val, d1, d2


@dataclass
class RandomSegment:
    t0: float
    duration_s: float
    sigma_jerk: np.ndarray        # (3,) m/s³ per step
    sigma_angacc: np.ndarray      # (3,) rad/s² per step
    speed_nominal: float          # m/s
    reversion_rate: float         # Ω = 1/τ (1/s), 0 = none


@dataclass
class MotionPlan:
    speed: Channel
    pitch: Channel
    roll: Channel
    heading: Channel
    deterministic_end_s: float
    random_segments: list
    static_windows: list          # [(start, end)] relative s, vehicle at rest
    sideslip_rad_per_m_s2: float = 0.0   # K: sideslip β = K·ψ̇·s (rad per m/s²)


def plan_motion(scenario, source="scenario"):
    """Turn the validated segment list into channel events (times relative to start, s)."""
    init = scenario["initial"]
    speed = Channel(init["speed_m_s"])
    pitch = Channel(init["pitch_deg"] * DEG)
    roll = Channel(init["roll_deg"] * DEG)
    heading = Channel(init["heading_deg"] * DEG)
    s_cur, p_cur, r_cur = speed.initial, pitch.initial, roll.initial
    t = 0.0
    randoms, statics = [], []
    for n, seg in enumerate(scenario["segment"]):
        kind = seg["type"]
        where = f"[[segment]] #{n + 1} ({kind})"
        if kind == "static":
            if s_cur != 0.0:
                raise GmisInputError(f"{where}: static segment while moving at {s_cur} m/s; "
                                     "decelerate to speed_m_s = 0 first", source)
            statics.append((t, t + seg["duration_s"]))
            t += seg["duration_s"]
        elif kind == "accelerate":
            ds = seg["speed_m_s"] - s_cur
            if ds == 0.0:
                continue
            acc = seg["accel_m_s2"]
            ramp = min(seg["ramp_s"], abs(ds) / acc)
            ev = RateTrapezoid(t, ramp, abs(ds) / acc - ramp, np.copysign(acc, ds))
            speed.events.append(ev)
            s_cur = seg["speed_m_s"]
            t = ev.end
        elif kind == "cruise":
            if "roll_deg" in seg and seg["roll_deg"] * DEG != r_cur:
                roll.events.append(SmoothStep(t, seg["ramp_s"], seg["roll_deg"] * DEG - r_cur))
                r_cur = seg["roll_deg"] * DEG
            t += seg["duration_s"]
        elif kind == "climb":
            if seg["pitch_deg"] * DEG != p_cur:
                pitch.events.append(SmoothStep(t, seg["ramp_s"],
                                               seg["pitch_deg"] * DEG - p_cur))
                p_cur = seg["pitch_deg"] * DEG
            t += seg["duration_s"]
        elif kind == "turn":
            angle, rate = seg["angle_deg"] * DEG, seg["rate_deg_s"] * DEG
            ramp = min(seg["ramp_s"], abs(angle) / rate)
            ev = RateTrapezoid(t, ramp, abs(angle) / rate - ramp, np.copysign(rate, angle))
            heading.events.append(ev)
            if seg["bank_deg"] != 0.0:
                bank = seg["bank_deg"] * DEG
                roll.events.append(SmoothStep(ev.t0, ramp, bank))
                roll.events.append(SmoothStep(ev.end - ramp, ramp, -bank))
            t = ev.end
        elif kind == "random":
            s_nom = seg.get("speed_m_s", s_cur)
            tau = seg["reversion_time_s"]
            randoms.append(RandomSegment(t, seg["duration_s"],
                                         np.array(seg["sigma_jerk_m_s3"], float),
                                         np.array(seg["sigma_angacc_deg_s2"], float) * DEG,
                                         s_nom, 0.0 if tau == 0.0 else 1.0 / tau))
            t += seg["duration_s"]
    det_end = randoms[0].t0 if randoms else t
    sideslip = scenario.get("vehicle", {}).get("sideslip_deg_per_m_s2", 0.0) * DEG
    return MotionPlan(speed, pitch, roll, heading, det_end, randoms, statics, sideslip)


def body_rate_from_euler_rates(theta, theta_dot):
    """ω_nb^b = C(θ)⁻¹ θ̇, the inverse of 001 eq. 2.2.6 in closed form (rows: x, y, z)."""
    p, r = theta[:, 0], theta[:, 1]
    sp, cp, sr, cr = np.sin(p), np.cos(p), np.sin(r), np.cos(r)
    pd, rd, hd = theta_dot[:, 0], theta_dot[:, 1], theta_dot[:, 2]
    return np.column_stack([cr * pd + sr * cp * hd, rd - sp * hd, sr * pd - cr * cp * hd])


def lateral_sideslip_velocity(k_rad, speed, speed_rate, heading_rate, heading_acc):
    """Body lateral velocity v_x = s·β = K ψ̇ s² (m/s) and its rate v̇_x = K(ψ̈ s² + 2ψ̇ s ṡ)
    (m/s²) for sideslip β = K·a_lat, a_lat = ψ̇ s; K in rad/(m/s²) (module doc)."""
    v_x = k_rad * heading_rate * speed * speed
    v_x_dot = k_rad * (heading_acc * speed * speed + 2.0 * heading_rate * speed * speed_rate)
    return v_x, v_x_dot


def _deterministic_state(plan, t):
    s, sd = plan.speed.evaluate(t)
    p, pd = plan.pitch.evaluate(t)
    r, rd = plan.roll.evaluate(t)
    h, hd, hdd = plan.heading.evaluate_with_second(t)
    theta = np.column_stack([p, r, h])
    omega = body_rate_from_euler_rates(theta, np.column_stack([pd, rd, hd]))
    col_y = np.column_stack([np.sin(h) * np.cos(p), np.cos(h) * np.cos(p), np.sin(p)])
    if plan.sideslip_rad_per_m_s2 == 0.0:
        # exact non-holonomic vehicle; kept separate so K = 0 is bit-identical to v^b = [0,s,0]
        v_b = np.column_stack([np.zeros_like(s), s, np.zeros_like(s)])
        a_b = np.column_stack([-omega[:, 2] * s, sd, omega[:, 0] * s])
        v_n = s[:, None] * col_y
        return v_b, a_b, theta, omega, v_n
    v_x, v_x_dot = lateral_sideslip_velocity(plan.sideslip_rad_per_m_s2, s, sd, hd, hdd)
    v_b = np.column_stack([v_x, s, np.zeros_like(s)])
    # a^b = v̇^b + ω×v^b with v^b = [v_x, s, 0] (001 eq. 4.1.15)
    a_b = np.column_stack([v_x_dot - omega[:, 2] * s,
                           sd + omega[:, 2] * v_x,
                           omega[:, 0] * s - omega[:, 1] * v_x])
    sp, cp, sr, cr = np.sin(p), np.cos(p), np.sin(r), np.cos(r)
    sh, ch = np.sin(h), np.cos(h)
    col_x = np.column_stack([cr * ch + sr * sh * sp, -cr * sh + sr * ch * sp, -sr * cp])
    v_n = s[:, None] * col_y + v_x[:, None] * col_x   # C_b^n v^b, eq. 2.2.4 columns x and y
    return v_b, a_b, theta, omega, v_n


def _deterministic_positions(plan, t):
    """r^n(t_k) = ∫ v^n dt, 3-point Gauss-Legendre on every interval [t_k, t_k+1]."""
    dt = np.diff(t)
    mid = 0.5 * (t[:-1] + t[1:])
    incr = np.zeros((t.size - 1, 3))
    for x, w in zip(_GL_NODES, _GL_WEIGHTS):
        *_, v_n = _deterministic_state(plan, mid + 0.5 * dt * x)
        incr += (0.5 * w * dt)[:, None] * v_n
    r = np.zeros((t.size, 3))
    np.cumsum(incr, axis=0, out=r[1:])
    return r


@njit(cache=True)
def _kinematics_derivative(y, jerk, angacc, out):
    """001 eq. 4.1.14-4.1.18 for y = [r, v^b, a^b, θ, ω] with inputs j, α."""
    c = np.empty((3, 3))
    dcm_body_to_nav_into(y[9], y[10], y[11], c)
    e = np.empty((3, 3))
    euler_rate_matrix_into(y[9], y[10], e)
    for i in range(3):
        out[i] = c[i, 0] * y[3] + c[i, 1] * y[4] + c[i, 2] * y[5]
        out[9 + i] = e[i, 0] * y[12] + e[i, 1] * y[13] + e[i, 2] * y[14]
        out[12 + i] = angacc[i]
    w0, w1, w2 = y[12], y[13], y[14]
    out[3] = y[6] - (w1 * y[5] - w2 * y[4])
    out[4] = y[7] - (w2 * y[3] - w0 * y[5])
    out[5] = y[8] - (w0 * y[4] - w1 * y[3])
    out[6] = jerk[0] - (w1 * y[8] - w2 * y[7])
    out[7] = jerk[1] - (w2 * y[6] - w0 * y[8])
    out[8] = jerk[2] - (w0 * y[7] - w1 * y[6])


@njit(cache=True)
def integrate_random_dynamics(y0, dt, white_jerk, white_angacc, reversion_rate, speed_nominal,
                              n_sub):
    """Propagate y = [r, v^b, a^b, θ, ω] over K IMU steps with per-step inputs (see module
    doc). Returns states (K+1, 15), applied jerk (K, 3) and angular acceleration (K, 3)."""
    n = white_jerk.shape[0]
    ys = np.empty((n + 1, 15))
    ys[0] = y0
    jerk_applied = np.empty((n, 3))
    angacc_applied = np.empty((n, 3))
    y = y0.copy()
    k1 = np.empty(15)
    k2 = np.empty(15)
    k3 = np.empty(15)
    k4 = np.empty(15)
    tmp = np.empty(15)
    j = np.empty(3)
    al = np.empty(3)
    h = dt / n_sub
    for k in range(n):
        om = reversion_rate[k]
        for i in range(3):
            v_err = y[3 + i] - (speed_nominal[k] if i == 1 else 0.0)
            j[i] = white_jerk[k, i] - 2.0 * om * y[6 + i] - om * om * v_err
        al[0] = white_angacc[k, 0] - 2.0 * om * y[12] - om * om * y[9]
        al[1] = white_angacc[k, 1] - 2.0 * om * y[13] - om * om * y[10]
        al[2] = white_angacc[k, 2] - 2.0 * om * y[14]
        jerk_applied[k] = j
        angacc_applied[k] = al
        for _ in range(n_sub):
            _kinematics_derivative(y, j, al, k1)
            tmp[:] = y + 0.5 * h * k1
            _kinematics_derivative(tmp, j, al, k2)
            tmp[:] = y + 0.5 * h * k2
            _kinematics_derivative(tmp, j, al, k3)
            tmp[:] = y + h * k3
            _kinematics_derivative(tmp, j, al, k4)
            y += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        ys[k + 1] = y
    return ys, jerk_applied, angacc_applied


@njit(cache=True)
def enu_to_geodetic_many(frame, r):
    out = np.empty((r.shape[0], 3))
    for k in range(r.shape[0]):
        lat, lon, h = enu_to_geodetic(frame, r[k])
        out[k, 0] = lat
        out[k, 1] = lon
        out[k, 2] = h
    return out


@njit(cache=True)
def body_to_nav_many(theta, vec_b):
    out = np.empty_like(vec_b)
    c = np.empty((3, 3))
    for k in range(theta.shape[0]):
        dcm_body_to_nav_into(theta[k, 0], theta[k, 1], theta[k, 2], c)
        for i in range(3):
            out[k, i] = c[i, 0] * vec_b[k, 0] + c[i, 1] * vec_b[k, 1] + c[i, 2] * vec_b[k, 2]
    return out


@dataclass
class TrajectoryTruth:
    """True motion at the IMU sample times (001 state definitions, eq. 4.1.13).

    t_s (N,) s from the scenario start; r_enu (N,3) m; llh (N,3) [rad, rad, m];
    v_b (N,3) m/s; a_b (N,3) m/s² (= C_n^b r̈^n); euler (N,3) [pitch, roll, heading] rad
    with heading unwrapped (continuous); omega_b (N,3) rad/s (ω_nb^b); v_enu (N,3) m/s;
    random_* (N,3): per-step white draws w and applied inputs of random segments, for the
    step [t_k, t_k+1) (NaN outside random segments and on the last sample)."""
    t_s: np.ndarray
    r_enu: np.ndarray
    llh: np.ndarray
    v_b: np.ndarray
    a_b: np.ndarray
    euler: np.ndarray
    omega_b: np.ndarray
    v_enu: np.ndarray
    random_jerk_white: np.ndarray
    random_angacc_white: np.ndarray
    random_jerk_applied: np.ndarray
    random_angacc_applied: np.ndarray
    static_windows: list


def simulate_trajectory(scenario, rng, source="scenario"):
    """True trajectory at the IMU rate; rng draws the random-segment inputs."""
    plan = plan_motion(scenario, source)
    rate = scenario["scenario"]["imu_rate_hz"]
    dt = 1.0 / rate
    k0 = int(np.ceil(plan.deterministic_end_s * rate - 1e-6))
    n_random = [round(seg.duration_s * rate) for seg in plan.random_segments]
    n = k0 + sum(n_random) + 1
    t = np.arange(n) * dt
    td = t[:k0 + 1]
    v_b = np.empty((n, 3))
    a_b = np.empty((n, 3))
    theta = np.empty((n, 3))
    omega = np.empty((n, 3))
    r = np.empty((n, 3))
    v_b[:k0 + 1], a_b[:k0 + 1], theta[:k0 + 1], omega[:k0 + 1], _ = _deterministic_state(plan, td)
    r[:k0 + 1] = _deterministic_positions(plan, td) if k0 > 0 else 0.0
    nan3 = np.full((n, 3), np.nan)
    w_j, w_a, j_app, a_app = nan3.copy(), nan3.copy(), nan3.copy(), nan3.copy()
    if plan.random_segments:
        steps = sum(n_random)
        wj = np.empty((steps, 3))
        wa = np.empty((steps, 3))
        rev = np.empty(steps)
        s_nom = np.empty(steps)
        i = 0
        for seg, m in zip(plan.random_segments, n_random):
            wj[i:i + m] = rng.standard_normal((m, 3)) * seg.sigma_jerk
            wa[i:i + m] = rng.standard_normal((m, 3)) * seg.sigma_angacc
            rev[i:i + m] = seg.reversion_rate
            s_nom[i:i + m] = seg.speed_nominal
            i += m
        y0 = np.concatenate([r[k0], v_b[k0], a_b[k0], theta[k0], omega[k0]])
        ys, ja, aa = integrate_random_dynamics(y0, dt, wj, wa, rev, s_nom, RK4_SUBSTEPS)
        r[k0:], v_b[k0:], a_b[k0:] = ys[:, POS], ys[:, VEL], ys[:, ACC]
        theta[k0:], omega[k0:] = ys[:, ATT], ys[:, RATE]
        w_j[k0:-1], w_a[k0:-1], j_app[k0:-1], a_app[k0:-1] = wj, wa, ja, aa
        if np.any(np.abs(theta[k0:, :2]) > 80.0 * DEG) or not np.all(np.isfinite(ys)):
            raise GmisInputError("[[segment]] random: the random dynamics diverged (|pitch| or "
                                 "|roll| > 80°); lower sigma_angacc_deg_s2 or shorten "
                                 "reversion_time_s", source)
    o = scenario["origin"]
    frame = make_nav_frame(o["lat_deg"] * DEG, o["lon_deg"] * DEG, o["h_m"])
    llh = enu_to_geodetic_many(frame, r)
    v_enu = body_to_nav_many(theta, v_b)
    return TrajectoryTruth(t, r, llh, v_b, a_b, theta, omega, v_enu, w_j, w_a, j_app, a_app,
                           plan.static_windows), frame
