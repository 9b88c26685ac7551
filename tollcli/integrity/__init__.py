"""Positioning integrity: WLSR RAIM (classic and ETC), its parameters and error models."""
