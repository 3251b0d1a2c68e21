"""Simulated drives and checks shared by several test modules (one definition each).

- ``default_scenario_cut(seconds)``: the embedded default scenario cut to its first
  segments lasting at least ``seconds`` s.
- ``square_drive_segments()``: a ~2 min drive (20 s static, 10 m/s, two 90° turns, stop).
- ``simulate_random_dynamics(folder)``: the random-dynamics scenario simulated, read and
  prepared; ``true_sigmas(recipe)``: its true noise σ per VCE component.
- ``scenario_toml(name, segments, ...)``: a scenario file's text (GNSS at 5 Hz, 2 cm / 5 cm/s,
  a heading antenna) for tests that simulate their own short drive.
- ``assert_ensemble_nees_in_band(imu_rate, gnss_rate)``: the ensemble NEES test of the
  default drive's motion over NEES_SEEDS seeds (benchmarks/monte_carlo_scale_factors.py).
"""

from benchmarks.monte_carlo_scale_factors import (
    ensemble_nees_in_band,
    monte_carlo,
    scenario_variant,
)
from gmis.pipeline import prepare_run
from gmis.recipe import load_recipe
from gmis.simulate import scenario_path, simulate_scenario


def default_scenario_cut(seconds: float) -> dict:
    """The default scenario's segments up to the first that brings the drive to
    ``seconds`` s (segments without a duration_s count 10 s)."""
    return scenario_variant("default", cut_s=seconds)[0]


def square_drive_segments() -> list[dict]:
    """Static 20 s, accelerate to 10 m/s, cruise, ±90° turns, stop, static 10 s."""
    return [
        {"type": "static", "duration_s": 20.0},
        {"type": "accelerate", "speed_m_s": 10.0, "accel_m_s2": 2.0},
        {"type": "cruise", "duration_s": 15.0},
        {"type": "turn", "angle_deg": 90.0, "rate_deg_s": 15.0},
        {"type": "cruise", "duration_s": 20.0},
        {"type": "turn", "angle_deg": -90.0, "rate_deg_s": 15.0},
        {"type": "cruise", "duration_s": 15.0},
        {"type": "accelerate", "speed_m_s": 0.0, "accel_m_s2": 2.0},
        {"type": "static", "duration_s": 10.0},
    ]


def scenario_toml(name: str, segments: list[dict], seed: int = 1, gnss: dict | None = None,
                  gnss_outages=(), start_gps_s: float | None = None) -> str:
    """A scenario file (docs/formats.md "Scenario") as text: IMU440 at 100 Hz near
    Boulder, the given [[segment]] tables, GNSS at 5 Hz with σ 2 / 2 / 4 cm and 5 cm/s
    (``gnss`` overrides or adds [gnss] keys, e.g. velocity_latency_s), [[gnss.outage]]
    (start_s, end_s) pairs, and a dual-antenna heading at 5 Hz."""
    from tests.conftest import toml_value

    def table(header, items):
        return [header] + [f"{k} = {toml_value(v)}" for k, v in items.items()] + [""]

    head = {"name": name, "seed": seed, "imu_rate_hz": 100.0}
    if start_gps_s is not None:
        head["start_gps_s"] = start_gps_s
    lines = table("[scenario]", head)
    lines += table("[origin]", {"lat_deg": 40.0, "lon_deg": -105.0, "h_m": 1600.0})
    lines += table("[imu]", {"grade": "IMU440"})
    for seg in segments:
        lines += table("[[segment]]", seg)
    lines += table("[gnss]", {"rate_hz": 5.0, "position_sigma_m": [0.02, 0.02, 0.04],
                              "velocity_sigma_m_s": 0.05, "lever_arm_m": [0.0, 0.5, 1.5],
                              **(gnss or {})})
    for a, b in gnss_outages:
        lines += table("[[gnss.outage]]", {"start_s": a, "end_s": b})
    lines += table("[heading]", {"rate_hz": 5.0, "sigma_deg": 0.5,
                                 "lever_arm_m": [0.0, -1.0, 1.5]})
    return "\n".join(lines)


def simulate_random_dynamics(folder):
    """(SimulationResult, Recipe, PreparedRun) of the random-dynamics drive: jerk/angular
    acceleration are white per-step noises with known σ (the simulator's recipe [noise]
    holds the true values of every component)."""
    sim = simulate_scenario(scenario_path("random_dynamics"), folder)
    recipe = load_recipe(sim.recipe_path)
    return sim, recipe, prepare_run(recipe)


def true_sigmas(recipe) -> dict:
    """True σ per VCE component of a simulated recipe (aiding scales 1)."""
    nz = recipe.noise
    out = {"gnss_position": 1.0, "gnss_velocity": 1.0, "heading": 1.0}
    for i, a in enumerate("xyz"):
        out[f"gyro_{a}"] = nz.gyro_sigma_rad_s[i]
        out[f"accel_{a}"] = nz.accel_sigma_m_s2[i]
        out[f"jerk_{a}"] = nz.jerk_sigma_m_s3[i]
        out[f"angacc_{a}"] = nz.angular_acceleration_sigma_rad_s2[i]
    return out


NEES_SEEDS = range(1, 9)      # N = 8 runs: band χ²(24)/8 = [1.55, 4.92]
NEES_STATIC_S = 60.0          # the alignment (the scenario's 300 s cut to 60 s)
NEES_MIN_FRACTION = 0.90      # issue 13 acceptance: ensemble mean in band on ≥ 90 % of epochs


def assert_ensemble_nees_in_band(imu_rate=None, gnss_rate=None):
    """Ensemble NEES of the default drive's motion (issue 13 acceptance, a valid statistic).

    Drive: the default scenario with its 300 s alignment cut to NEES_STATIC_S = 60 s, then
    all of its motion (5 min: turns, stops, banked road, climb), at the given IMU and
    GNSS/heading rates (Hz; None: the scenario's 100 Hz / 5 Hz). The scenario's GNSS
    outage (430-445 s from the start) falls after this 360 s drive's end: it is aided
    throughout (the benchmark's 20-seed runs of the whole drive cover the outage). Runs: seeds NEES_SEEDS (N = 8), every
    random stream of the simulation re-seeded per run (benchmarks/monte_carlo_scale_factors.py,
    which runs the same drive with --static-s 60 --bias-drawn-from-prior accel).

    Statistic: at each 1 Hz epoch k (the first IMU epoch of each second) the mean over the
    N runs of the NEES of r^n, v^b and θ (3 dof each). For a consistent filter each run's
    NEES_k is χ²(3) and the runs are independent, so N·mean ~ χ²(3N) at EVERY epoch,
    whatever the correlation of the errors in time (the single-seed time average this
    replaces treated 27 samples 10 s apart as independent; tilt errors are correlated for
    longer, and it fell outside its band on 20-35 % of seeds of a consistent filter). The
    mean must lie inside the two-sided 95 % band χ²(3N)/N on ≥ 90 % of the moving, aided
    epochs: true horizontal speed > 0.5 m/s and not inside a GNSS outage or the 5 s after
    it (MonteCarlo.moving_aided; here 225 of the 361 epochs, t = 61-114, 127-253 and
    270-313 s). The alignment and the two stops are left out (the acceptance is about the
    aided motion; at rest see docs/DESIGN.md "Process noise at rest").

    Biases: the accelerometer turn-on biases are drawn per seed from the filter's prior
    N(0, BS²) (BS = 1 mg, the bias instability): the χ² law holds for an initial error
    drawn from N(0, P₀), and at rest the tilt and the horizontal b_a are not separable
    (f_h = g·tilt + b_h), so the prior of b_a is what sets the tilt's σ until the vehicle
    moves. The scenario's fixed b_a with prior σ 3 |b₀| puts every run at a third of its
    σ along that direction: conservative by construction (docs/DESIGN.md "Process noise at
    rest"). The gyro biases stay the scenario's, prior σ 3 |b₀| = 270-540 °/h: the filter
    starts b_ω at the alignment window's mean rate (gmis/alignment.py) and processes the
    same samples again, so the prior must be diffuse against the 35 °/h that 60 s of
    4.5 °/√h ARW give; drawn from a 10 °/h prior, b_ω starts 3.5 σ off. Measured on this
    drive, 40 seeds, 100 Hz: both biases drawn — moving θ NEES mean 3.27, in the χ²(120)/40
    band on 88.9 % of the epochs, b_ω RMS z 1.05-1.63; b_a only drawn (the choice here) —
    3.15, 93.8 %, b_ω RMS z 0.81-0.98. Scale factors: the scenario's 200-1000 ppm with prior
    σ 3 |S|, their share of the r/v/θ errors small.

    Why N = 8 (the issue's floor): the band [1.55, 4.92] is wider than the benchmark's 20
    seeds' [2.02, 4.16] but still a χ² band: with the filter's IMU σ halved (100 Hz) the
    moving epochs inside are r / v^b / θ 77.3 / 4.9 / 3.6 % (200 Hz / 1 Hz: 79.1 / 12.0 /
    9.8 %). At the true noise, 8-seed subsets of 40 seeds pass all three blocks in 95.6 %
    (100 Hz / 5 Hz) and 99.2 % (200 Hz / 1 Hz) of 2 000 random draws, and 5 of 5 disjoint
    groups pass at each rate: the 1 Hz epochs are correlated, so that rate is set mainly by
    the drive's length, and N mainly sets the power. Cost ~1.8 s CPU per 100 Hz run and
    ~3.2 s per 200 Hz run of this 6-min drive."""
    sc, bias_prior = scenario_variant("default", imu_rate, gnss_rate, static_s=NEES_STATIC_S,
                                      bias_drawn_from_prior="accel")
    mc = monte_carlo(sc, NEES_SEEDS, quiet=True, bias_prior=bias_prior)
    lo, hi, blocks = ensemble_nees_in_band(mc.nees, mc.moving_aided)
    assert mc.moving_aided.sum() > 200, mc.moving_aided.sum()
    for name, (inside, below, above, mean) in blocks.items():
        assert inside >= NEES_MIN_FRACTION, (name, inside, below, above, mean, lo, hi)
