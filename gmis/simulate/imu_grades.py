"""IMU grade presets: 001 Table 4-1 ("Specifications of the used IMUs") as data.

Each preset gives, per sensor triad, the white-noise density, the bias stability and (where
the table lists one) the resolution, converted to the units the scenario TOML uses:

- gyro_arw_deg_sqrt_h      angle random walk (°/√h). Table entries given as a white-noise
                           density in °/s/√Hz are converted with 1 °/s/√Hz = 60 °/√h.
- accel_vrw_m_s_sqrt_h     velocity random walk (m/s/√h). Entries in mg/√Hz are converted
                           with 1 mg/√Hz = 9.80665e-3 m/s/√s = 0.588399 m/s/√h.
- gyro_bias_instability_deg_h, accel_bias_instability_mg: the "Bias" column (1σ bias
                           stability, Allan variance). The iPhone 4 gyro entry is printed
                           in °/s (75 °/s); it is kept as printed (270000 °/h) — an
                           obviously unusable consumer gyro, faithfully reproduced.
- gyro_quantization_deg_s, accel_quantization_mg: the "Resolution" column (0 = not listed).

Per-sample white-noise σ = density/√δt (001 Table 4-3 note); the bias stability enters as a
random walk with per-step σ = BS·√(δt/T), T the correlation time of the bias-stability
figure (001 Table 4-3 note and §5.3.2.2: T ≈ 100 s for the IMU440CA).
"""

G0 = 9.80665  # m/s² per g (conventional)
MG_PER_SQRT_HZ_TO_M_S_SQRT_H = 1e-3 * G0 * 60.0
DEG_S_PER_SQRT_HZ_TO_DEG_SQRT_H = 60.0

GRADE_FIELDS = ("grade", "gyro_arw_deg_sqrt_h", "accel_vrw_m_s_sqrt_h",
                "gyro_bias_instability_deg_h", "accel_bias_instability_mg",
                "gyro_quantization_deg_s", "accel_quantization_mg")
_MG = MG_PER_SQRT_HZ_TO_M_S_SQRT_H
_DEG = DEG_S_PER_SQRT_HZ_TO_DEG_SQRT_H
#   name        grade         gyro ARW    accel VRW   gyro BI        accel BI  gyro q accel q
_ROWS = (
    ("HG9900",  "navigation", 0.002,      0.005 * _MG, 0.003,        0.025,    0.0,   0.0),
    ("HG1700",  "tactical",   0.088,      0.2,        1.0,           1.0,      0.0,   0.0),
    ("VG800",   "tactical",   0.1,        0.5,        3.0,           1.0,      0.025, 0.5),
    ("SMDIMU",  "industrial", 2.0,        0.08,       20.0,          0.075,    0.0,   0.0),
    ("VN-100",  "industrial", 0.035 * _DEG, 0.14 * _MG, 10.0,        0.04,     0.02,  0.5),
    ("IMU440",  "industrial", 4.5,        1.0,        10.0,          1.0,      0.02,  0.5),
    ("BP3010",  "consumer",   12.02,      0.47,       96.9,          0.450,    0.0,   0.0),
    ("iPhone4", "consumer",   144.0,      8.0,        75.0 * 3600.0, 20.0,     0.0,   0.0),
)
IMU_GRADES = {row[0]: dict(zip(GRADE_FIELDS, row[1:], strict=True)) for row in _ROWS}

GRADE_NAMES = tuple(IMU_GRADES)
