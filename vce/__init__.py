"""Helmert variance component estimation in the GMIKF (001 §2.7.2, ch. 5)."""
