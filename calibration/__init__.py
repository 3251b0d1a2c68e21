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

__all__ = [
           "GmwmFit",
           "allan_variance",
           "average_wv",
           "fit_gmwm",
           "line_fits",
           "model_wv",
           "multi_signal",
           "nested_models",
           "parse_model",
           "robust_wavelet_variance",
           "select_model",
           "simulate",
           "wavelet_variance",
]
