"""Stochastic IMU calibration from static records (seeds 000 ch. 3-4, 002, 004): Allan
variance and line fits, Haar wavelet variance, GMWM / RGMWM with model selection,
multi-signal AWV / AGMWM / SR-AWV / DR-AWV, and the identified model as filter inputs."""

from calibration.allan import allan_variance, line_fits
from calibration.gmwm import GmwmFit, fit_gmwm
from calibration.model_selection import nested_models, select_model
from calibration.multisignal import average_wv, multi_signal
from calibration.processes import model_wv, parse_model, simulate
from calibration.robust import robust_wavelet_variance
from calibration.wavelet_variance import wavelet_variance

__all__ = ["allan_variance", "line_fits", "GmwmFit", "fit_gmwm", "nested_models",
           "select_model", "average_wv", "multi_signal", "model_wv", "parse_model",
           "simulate", "robust_wavelet_variance", "wavelet_variance"]
