"""The one state index map (001 eq. 4.1.13 and 5.1.17).

x = [r^n(3) v^b(3) a^b(3) θ(3) ω^b(3) b_ω(3) b_a(3) | S_ω(3) S_a(3)]
r^n: ENU position in the origin tangent frame (m); v^b, a^b: body-frame velocity (m/s)
and acceleration (m/s², a^b = C_n^b r̈^n); θ = [pitch, roll, heading] (rad); ω^b = ω_nb^b
(rad/s); b_ω (rad/s), b_a (m/s²); S_ω, S_a: dimensionless scale factors (diagonal).
The 21-state variant is the first 21 entries; tightly coupled filters append ambiguity
states after the last IMU state.

Process noise w = [jerk j^b(3) m/s³, angular acceleration ω̇(3) rad/s², b_ω drift(3),
b_a drift(3), S_ω drift(3), S_a drift(3)]: discrete per-step values (001 Table 6-2).
"""

POS = slice(0, 3)
VEL = slice(3, 6)
ACC = slice(6, 9)
ATT = slice(9, 12)
RATE = slice(12, 15)
BG = slice(15, 18)
BA = slice(18, 21)
SG = slice(21, 24)
SA = slice(24, 27)

I_POS, I_VEL, I_ACC, I_ATT, I_RATE, I_BG, I_BA, I_SG, I_SA = 0, 3, 6, 9, 12, 15, 18, 21, 24
I_PITCH, I_ROLL, I_HEADING = 9, 10, 11
N_STATES_21 = 21
N_STATES_27 = 27

# process-noise vector layout
W_JERK = slice(0, 3)
W_ANGACC = slice(3, 6)
W_BG = slice(6, 9)
W_BA = slice(9, 12)
W_SG = slice(12, 15)
W_SA = slice(15, 18)
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


def n_noise_for(n_states: int) -> int:
    """Number of process-noise components for a 21- or 27-state IMU state."""
    return N_NOISE_27 if n_states >= N_STATES_27 else N_NOISE_21
