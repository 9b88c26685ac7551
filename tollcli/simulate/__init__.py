"""Synthetic drives with known truth: constellations, streets, errors, faults and the logs they make."""
