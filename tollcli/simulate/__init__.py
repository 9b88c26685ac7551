"""Synthetic drives with known truth: constellations, streets, errors, faults and the logs they make.

Uses charging, integrity, GNSS, the readers and the floor (not the job, its neighbour).
"""
