"""gmis: generic multisensor integration (GMIKF) post-processing engine."""

__version__ = "0.1.0"
