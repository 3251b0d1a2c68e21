"""GNSS raw processing: RINEX, ephemeris, SPP, double differences, cycle slips, LAMBDA, RTK,
dual-antenna heading. The ground floor of the repository: it imports nothing from gmis.

Main entry points (the modules hold the rest):
    read_obs, read_nav            RINEX observation / navigation files (gnss.rinex)
    solve_spp_session             single-point positions of a session (gnss.spp)
    form_double_differences       DD epochs of a base/rover session (gnss.double_difference)
    process_rtk, RtkConfig        kinematic RTK with LAMBDA fixing (gnss.rtk)
    dual_antenna_heading          moving-baseline heading (gnss.heading)
    resolve_integers, ratio_test  LAMBDA integer least squares (gnss.lambda_ils)
    detect_cycle_slips            slip detectors on one satellite arc (gnss.cycle_slips)
    match_epochs, nearest_epoch   epoch matching by time tag (gnss.epoch_matching)
    read_pos, write_pos           RTKLIB-like .pos files (gnss.pos_file)
    geodetic_to_ecef, ecef_to_geodetic, ecef_to_enu_matrix   WGS-84 (gnss.geodesy)
    GnssInputError                the one bad-input error (gnss.errors)
"""

import importlib

# name → module; resolved on first use (PEP 562) so that importing one gnss module, e.g.
# gnss.errors from gmis.errors, does not import the whole package (numba, the readers)
_EXPORTS = {
    "SlipConfig": "cycle_slips", "detect_cycle_slips": "cycle_slips",
    "form_double_differences": "double_difference",
    "match_epochs": "epoch_matching", "nearest_epoch": "epoch_matching",
    "GnssInputError": "errors",
    "ecef_to_enu_matrix": "geodesy", "ecef_to_geodetic": "geodesy",
    "geodetic_to_ecef": "geodesy",
    "HeadingSolution": "heading", "dual_antenna_heading": "heading",
    "ratio_test": "lambda_ils", "resolve_integers": "lambda_ils",
    "read_pos": "pos_file", "write_pos": "pos_file",
    "NavData": "rinex", "ObsData": "rinex", "read_nav": "rinex", "read_obs": "rinex",
    "RtkConfig": "rtk", "RtkSolution": "rtk", "process_rtk": "rtk",
    "SppSession": "spp", "filled_positions": "spp", "solve_spp_session": "spp",
}


def __getattr__(name):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'gnss' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"gnss.{_EXPORTS[name]}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_EXPORTS))


__all__ = [
    "GnssInputError",
    "HeadingSolution",
    "NavData",
    "ObsData",
    "RtkConfig",
    "RtkSolution",
    "SlipConfig",
    "SppSession",
    "detect_cycle_slips",
    "dual_antenna_heading",
    "ecef_to_enu_matrix",
    "ecef_to_geodetic",
    "filled_positions",
    "form_double_differences",
    "geodetic_to_ecef",
    "match_epochs",
    "nearest_epoch",
    "process_rtk",
    "ratio_test",
    "read_nav",
    "read_obs",
    "read_pos",
    "resolve_integers",
    "solve_spp_session",
    "write_pos",
]
