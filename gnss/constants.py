"""GPS constants (IS-GPS-200, Table 20-IV and §20.3.3) and signal definitions. SI units."""

C_LIGHT = 299792458.0  # speed of light (m/s)
GM_GPS = 3.986005e14  # WGS84 earth gravitational constant used by GPS (m³/s²)
OMEGA_EARTH = 7.2921151467e-5  # WGS84 earth rotation rate (rad/s)
F_RELATIVISTIC = -4.442807633e-10  # F = -2 sqrt(GM)/c² (s/m^½), IS-GPS-200 20.3.3.3.3.1
PI_GPS = 3.1415926535898  # the value of π prescribed by IS-GPS-200 for orbit computation

SECONDS_PER_WEEK = 604800.0
GPS_EPOCH_ISO = "1980-01-06T00:00:00"  # t = 0 of the absolute GPS time base used in gnss
UNIX_TO_GPS_EPOCH_S = 315964800.0  # 1980-01-06 − 1970-01-01 (s): Unix time of the GPS epoch

FREQ_L1 = 1575.42e6  # Hz
FREQ_L2 = 1227.60e6  # Hz
WAVELENGTH_L1 = C_LIGHT / FREQ_L1  # ≈ 0.1903 m
WAVELENGTH_L2 = C_LIGHT / FREQ_L2  # ≈ 0.2442 m
GAMMA_L1_L2 = (FREQ_L1 / FREQ_L2) ** 2  # γ = (f1/f2)², IS-GPS-200 20.3.3.3.3.2
