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

from gnss.cycle_slips import SlipConfig, detect_cycle_slips
from gnss.double_difference import form_double_differences
from gnss.epoch_matching import match_epochs, nearest_epoch
from gnss.errors import GnssInputError
from gnss.geodesy import ecef_to_enu_matrix, ecef_to_geodetic, geodetic_to_ecef
from gnss.heading import HeadingSolution, dual_antenna_heading
from gnss.lambda_ils import ratio_test, resolve_integers
from gnss.pos_file import read_pos, write_pos
from gnss.rinex import NavData, ObsData, read_nav, read_obs
from gnss.rtk import RtkConfig, RtkSolution, process_rtk
from gnss.spp import SppSession, filled_positions, solve_spp_session

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
