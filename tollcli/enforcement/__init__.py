"""Enforcement and recovery: where a vehicle is, signs of tampering and evasion, roadside cross-checks."""
