"""The state index maps: the GMIKF's total state (001 eq. 4.1.13 and 5.1.17) and the
error-state INS's error state and navigation vector (001 §2.6.4.3, gmis.errins).

GMIKF total state:
x = [r^n(3) v^b(3) a^b(3) θ(3) ω^b(3) b_ω(3) b_a(3) | S_ω(3) S_a(3)]
r^n: ENU position in the origin tangent frame (m); v^b, a^b: body-frame velocity (m/s)
and acceleration (m/s², a^b = C_n^b r̈^n); θ = [pitch, roll, heading] (rad); ω^b = ω_nb^b
(rad/s); b_ω (rad/s), b_a (m/s²); S_ω, S_a: dimensionless scale factors (diagonal).
The 21-state variant is the first 21 entries; tightly coupled filters append ambiguity
states after the last IMU state. The first N_DYNAMIC (r, v, a, θ, ω) have a non-identity
transition; the rest are random walks.

Process noise w = [jerk j^b(3) m/s³, angular acceleration ω̇(3) rad/s², b_ω drift(3),
b_a drift(3), S_ω drift(3), S_a drift(3)]: configured as per-step values at 100 Hz (001
Table 6-2), used as spectral densities (gmis.run_filter.GmikfConfig.q_psd).
The first N_KINEMATIC_NOISE (j, ω̇) enter through Λ; each drift I_W_DRIFT + i drives the
random-walk state N_DYNAMIC + i.
"""


def _block(i0: int) -> slice:
    """The 3-vector starting at index i0."""
    return slice(i0, i0 + 3)


I_POS, I_VEL, I_ACC, I_ATT, I_RATE, I_BG, I_BA, I_SG, I_SA = 0, 3, 6, 9, 12, 15, 18, 21, 24
I_PITCH, I_ROLL, I_HEADING = 9, 10, 11
POS, VEL, ACC, ATT, RATE = _block(I_POS), _block(I_VEL), _block(I_ACC), _block(I_ATT), \
    _block(I_RATE)
BG, BA, SG, SA = _block(I_BG), _block(I_BA), _block(I_SG), _block(I_SA)
N_DYNAMIC = 15
N_STATES_21 = 21
N_STATES_27 = 27

# process-noise vector layout
I_W_JERK, I_W_ANGACC, I_W_BG, I_W_BA, I_W_SG, I_W_SA = 0, 3, 6, 9, 12, 15
I_W_DRIFT = I_W_BG
W_JERK, W_ANGACC = _block(I_W_JERK), _block(I_W_ANGACC)
W_BG, W_BA, W_SG, W_SA = _block(I_W_BG), _block(I_W_BA), _block(I_W_SG), _block(I_W_SA)
N_KINEMATIC_NOISE = 6
N_NOISE_21 = 12
N_NOISE_27 = 18

STATE_NAMES_27 = (
    "e", "n", "u", "vx", "vy", "vz", "ax", "ay", "az", "pitch", "roll", "heading",
    "wx", "wy", "wz", "bgx", "bgy", "bgz", "bax", "bay", "baz",
    "sgx", "sgy", "sgz", "sax", "say", "saz",
)
STATE_UNITS_27 = (
    "m", "m", "m", "m/s", "m/s", "m/s", "m/s^2", "m/s^2", "m/s^2", "rad", "rad", "rad",
    "rad/s", "rad/s", "rad/s", "rad/s", "rad/s", "rad/s", "m/s^2", "m/s^2", "m/s^2",
    "-", "-", "-", "-", "-", "-",
)
NOISE_NAMES_27 = (
    "jerk_x", "jerk_y", "jerk_z", "angacc_x", "angacc_y", "angacc_z",
    "bg_drift_x", "bg_drift_y", "bg_drift_z", "ba_drift_x", "ba_drift_y", "ba_drift_z",
    "sg_drift_x", "sg_drift_y", "sg_drift_z", "sa_drift_x", "sa_drift_y", "sa_drift_z",
)

# error-state INS (gmis.errins): error state δx, estimate minus truth
I_DR, I_DV, I_PHI, I_DBG, I_DBA = 0, 3, 6, 9, 12   # δr^n m, δv^n m/s, φ rad, δb_ω, δb_a
N_ERR = 15
ERR_R, ERR_V, ERR_PHI = _block(I_DR), _block(I_DV), _block(I_PHI)
# its navigation vector: r^n(3) m, v^n(3) m/s, C_b^n row-major(9), b_ω(3) rad/s, b_a(3) m/s²
I_NAV_R, I_NAV_V, I_NAV_C, I_NAV_BG, I_NAV_BA = 0, 3, 6, 15, 18
NAV_SIZE = 21
NAV_R, NAV_V, NAV_BG, NAV_BA = _block(I_NAV_R), _block(I_NAV_V), _block(I_NAV_BG), \
    _block(I_NAV_BA)
NAV_C = slice(I_NAV_C, I_NAV_C + 9)


def n_noise_for(n_states: int) -> int:
    """Number of process-noise components for a 21- or 27-state IMU state."""
    return N_NOISE_27 if n_states >= N_STATES_27 else N_NOISE_21
