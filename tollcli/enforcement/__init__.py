"""Enforcement and recovery: where a vehicle is, signs of tampering and evasion, roadside cross-checks.

Uses integrity, GNSS, the readers and the floor (not charging, its neighbour).
"""
