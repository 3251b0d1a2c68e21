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

IMU_GRADES = {
    "HG9900": {"grade": "navigation",
                   "gyro_arw_deg_sqrt_h": 0.002,
                   "accel_vrw_m_s_sqrt_h": 0.005 * MG_PER_SQRT_HZ_TO_M_S_SQRT_H,
                   "gyro_bias_instability_deg_h": 0.003, "accel_bias_instability_mg": 0.025,
                   "gyro_quantization_deg_s": 0.0, "accel_quantization_mg": 0.0},
    "HG1700": {"grade": "tactical",
                   "gyro_arw_deg_sqrt_h": 0.088, "accel_vrw_m_s_sqrt_h": 0.2,
                   "gyro_bias_instability_deg_h": 1.0, "accel_bias_instability_mg": 1.0,
                   "gyro_quantization_deg_s": 0.0, "accel_quantization_mg": 0.0},
    "VG800": {"grade": "tactical",
                  "gyro_arw_deg_sqrt_h": 0.1, "accel_vrw_m_s_sqrt_h": 0.5,
                  "gyro_bias_instability_deg_h": 3.0, "accel_bias_instability_mg": 1.0,
                  "gyro_quantization_deg_s": 0.025, "accel_quantization_mg": 0.5},
    "SMDIMU": {"grade": "industrial",
                   "gyro_arw_deg_sqrt_h": 2.0, "accel_vrw_m_s_sqrt_h": 0.08,
                   "gyro_bias_instability_deg_h": 20.0, "accel_bias_instability_mg": 0.075,
                   "gyro_quantization_deg_s": 0.0, "accel_quantization_mg": 0.0},
    "VN-100": {"grade": "industrial",
                   "gyro_arw_deg_sqrt_h": 0.035 * DEG_S_PER_SQRT_HZ_TO_DEG_SQRT_H,
                   "accel_vrw_m_s_sqrt_h": 0.14 * MG_PER_SQRT_HZ_TO_M_S_SQRT_H,
                   "gyro_bias_instability_deg_h": 10.0, "accel_bias_instability_mg": 0.04,
                   "gyro_quantization_deg_s": 0.02, "accel_quantization_mg": 0.5},
    "IMU440": {"grade": "industrial",
                   "gyro_arw_deg_sqrt_h": 4.5, "accel_vrw_m_s_sqrt_h": 1.0,
                   "gyro_bias_instability_deg_h": 10.0, "accel_bias_instability_mg": 1.0,
                   "gyro_quantization_deg_s": 0.02, "accel_quantization_mg": 0.5},
    "BP3010": {"grade": "consumer",
                   "gyro_arw_deg_sqrt_h": 12.02, "accel_vrw_m_s_sqrt_h": 0.47,
                   "gyro_bias_instability_deg_h": 96.9, "accel_bias_instability_mg": 0.450,
                   "gyro_quantization_deg_s": 0.0, "accel_quantization_mg": 0.0},
    "iPhone4": {"grade": "consumer",
                    "gyro_arw_deg_sqrt_h": 144.0, "accel_vrw_m_s_sqrt_h": 8.0,
                    "gyro_bias_instability_deg_h": 75.0 * 3600.0, "accel_bias_instability_mg": 20.0,
                    "gyro_quantization_deg_s": 0.0, "accel_quantization_mg": 0.0},
}

GRADE_NAMES = tuple(IMU_GRADES)
