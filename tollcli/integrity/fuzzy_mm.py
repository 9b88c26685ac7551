"""Map-matching integrity: the zero-order Sugeno fuzzy inference of Binjammaz (2015), vectorized.

Inputs per epoch (ALGORITHMS.md §7, thesis Tables 5-2/5-3):

* Δθ, degrees: |road heading − GPS heading| (wrapped to [0°, 180°]) — good < 90°, bad ≥ 90°;
* ΔD, metres: |distance along the matched road − distance from the GPS positions| — low ≤ 4,
  average ≤ 8, high > 8;
* ΔS, km/h (the thesis gives no unit; km/h is taken, since 5 and 10 m/s would be huge):
  |speed from the matched positions − average Doppler speed| — low ≤ 5, average ≤ 10, high > 10.

The 18 rules map each combination to a constant (40 good heading + 30/20/10 distance + 30/20/10
speed); the integrity scale is their firing-strength-weighted average (0–100) and an alarm is
raised below 71. Memberships are crisp steps at the breakpoints (the reference: it reproduces the
thesis's table and worked cases); ``ramp`` > 0 replaces each step by a linear ramp of that width
centred on the breakpoint (the thesis's Figure 5-11 shapes are not recoverable).
"""

from __future__ import annotations

import numpy as np

THETA_BREAK_DEG = 90.0
D_BREAKS_M = (4.0, 8.0)
S_BREAKS_KMH = (5.0, 10.0)
ALARM_BELOW = 71.0
WEIGHTS = {"theta": {"good": 40, "bad": 0}, "d": {"low": 30, "average": 20, "high": 10}, "s": {"low": 30, "average": 20, "high": 10}}

#: thesis Table 5-3: (Δθ, ΔD, ΔS) → output label; the score is the sum of the weights (R1 = 100 … R18 = 20)
RULES = (
    ("good", "low", "low", "very high"), ("good", "low", "average", "very high"), ("good", "average", "low", "very high"),
    ("good", "low", "high", "high"), ("good", "average", "average", "high"), ("good", "high", "low", "high"),
    ("good", "average", "high", "average"), ("good", "high", "average", "average"), ("good", "high", "high", "low"),
    ("bad", "low", "low", "low"), ("bad", "low", "average", "low"), ("bad", "average", "low", "low"),
    ("bad", "low", "high", "low"), ("bad", "average", "average", "low"), ("bad", "high", "low", "low"),
    ("bad", "average", "high", "low"), ("bad", "high", "average", "low"), ("bad", "high", "high", "low"),
)  # fmt: skip
SCORES = np.array([WEIGHTS["theta"][t] + WEIGHTS["d"][d] + WEIGHTS["s"][s] for t, d, s, _ in RULES], dtype=float)
LEVELS = np.array([label for *_, label in RULES], dtype=object)


def _step_up(x: np.ndarray, at: float, ramp: float, closed: bool) -> np.ndarray:
    """Membership of "x is above ``at``": 0 → 1. Crisp: ``x > at`` (``x >= at`` when ``closed``)."""
    if ramp <= 0:
        return (x >= at if closed else x > at).astype(float)
    return np.clip((x - (at - ramp / 2)) / ramp, 0.0, 1.0)


def memberships(delta_theta_deg, delta_d_m, delta_s_kmh, ramp: float = 0.0) -> dict[str, dict[str, np.ndarray]]:
    """Membership degrees of every label, arrays broadcast together (NaN inputs give NaN)."""
    th = np.asarray(delta_theta_deg, dtype=float)
    d = np.asarray(delta_d_m, dtype=float)
    s = np.asarray(delta_s_kmh, dtype=float)
    bad = _step_up(th, THETA_BREAK_DEG, ramp, closed=True)  # Δθ = 90° is bad
    d_over_low = _step_up(d, D_BREAKS_M[0], ramp, closed=False)  # ΔD = 4 is low
    d_over_avg = _step_up(d, D_BREAKS_M[1], ramp, closed=False)  # ΔD = 8 is average
    s_over_low = _step_up(s, S_BREAKS_KMH[0], ramp, closed=False)
    s_over_avg = _step_up(s, S_BREAKS_KMH[1], ramp, closed=False)
    out = {
        "theta": {"good": 1.0 - bad, "bad": bad},
        "d": {"low": 1.0 - d_over_low, "average": d_over_low - d_over_avg, "high": d_over_avg},
        "s": {"low": 1.0 - s_over_low, "average": s_over_low - s_over_avg, "high": s_over_avg},
    }
    for name, x in (("theta", th), ("d", d), ("s", s)):
        for label in out[name]:
            out[name][label] = np.where(np.isnan(x), np.nan, np.clip(out[name][label], 0.0, 1.0))
    return out


def firing_strengths(mu: dict[str, dict[str, np.ndarray]]) -> np.ndarray:
    """(…, 18) product firing strength of each rule."""
    return np.stack([mu["theta"][t] * mu["d"][d] * mu["s"][s] for t, d, s, _ in RULES], axis=-1)


def integrity_scale(delta_theta_deg, delta_d_m, delta_s_kmh, ramp: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The integrity scale (0–100), the level of the strongest rule, and that rule's number (1–18; 0 where undefined)."""
    w = firing_strengths(memberships(delta_theta_deg, delta_d_m, delta_s_kmh, ramp))
    total = w.sum(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(total > 0, (w * SCORES).sum(axis=-1) / total, np.nan)
    defined = np.isfinite(scale)
    strongest = np.argmax(np.nan_to_num(w, nan=-1.0), axis=-1)
    rule = np.where(defined, strongest + 1, 0)
    level = np.where(defined, LEVELS[strongest], "")
    return scale, level, rule


def alarm(scale) -> np.ndarray:
    """True where the map-matching result is rejected (scale below 71, or no scale)."""
    s = np.asarray(scale, dtype=float)
    return ~(s >= ALARM_BELOW)
