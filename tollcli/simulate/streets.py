"""Streets lined with buildings (paper 001 Table I, thesis Table 7.1) and which satellites they hide.

A street is ``street_width_m`` wide (20 m) with the vehicle on its axis and the
antenna ``antenna_height_m`` (1.5 m, thesis §4.3.6) above the road. Along each
side, buildings follow one another; after each building a gap opens with
probability ``p_gap`` (0.1). Sizes are drawn from normal laws truncated to the
paper's bounds (redrawn, not clipped, outside them; the second parameter of the
paper's N(·, ·) is read as a standard deviation, both as printed in metres):

=========  ======================  ======================  =====================
env        height H_B              width W_B               gap width W_G
=========  ======================  ======================  =====================
urban      N(15, 3), 4 ≤ H ≤ 25    N(20, 25), W ≥ 10       N(15, 25), W ≥ 10
rural      N(6, 1.5), 4 ≤ H ≤ 20   N(20, 25), W ≥ 10       N(15, 25), W ≥ 10
open       no buildings
=========  ======================  ======================  =====================

Line of sight: the ray to a satellite at elevation ``e`` and azimuth ``α`` relative
to the street direction meets the façade plane of the side it points to after a
horizontal distance d = (w/2)/|sin α|, at along-street offset d·cos α and height
h_ant + d·tan e. The satellite is hidden when the building standing there is
taller (façade-plane model: rays through a gap are not checked against the sides
of the buildings behind it). Only line-of-sight satellites are received.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import truncnorm

STREET_WIDTH_M = 20.0
ANTENNA_HEIGHT_M = 1.5
P_GAP = 0.1


@dataclass(frozen=True)
class Environment:
    name: str
    height_m: tuple[float, float, float, float] | None  # mean, sd, low, high
    width_m: tuple[float, float, float, float] = (20.0, 25.0, 10.0, np.inf)
    gap_m: tuple[float, float, float, float] = (15.0, 25.0, 10.0, np.inf)
    p_gap: float = P_GAP


ENVIRONMENTS = {
    "urban": Environment("urban", (15.0, 3.0, 4.0, 25.0)),
    "rural": Environment("rural", (6.0, 1.5, 4.0, 20.0)),
    "open": Environment("open", None),
}


def _draw(law: tuple[float, float, float, float], n: int, rng: np.random.Generator) -> np.ndarray:
    mean, sd, low, high = law
    return truncnorm.ppf(rng.random(n), (low - mean) / sd, (high - mean) / sd, loc=mean, scale=sd)


@dataclass(frozen=True)
class Side:
    """Buildings along one side of the street, by arc length: [start_m, end_m) with height_m."""

    start_m: np.ndarray
    end_m: np.ndarray
    height_m: np.ndarray

    def height_at(self, s_m: np.ndarray) -> np.ndarray:
        """Height of the building at arc length ``s_m`` (0 in a gap or beyond the ends)."""
        if self.start_m.size == 0:
            return np.zeros(np.shape(s_m))
        i = np.searchsorted(self.start_m, s_m, side="right") - 1
        j = np.maximum(i, 0)
        return np.where((i >= 0) & (s_m < self.end_m[j]), self.height_m[j], 0.0)


def buildings(env: Environment, start_m: float, end_m: float, rng: np.random.Generator) -> Side:
    """One side's buildings covering arc lengths [start_m, end_m]."""
    if env.height_m is None:
        empty = np.zeros(0)
        return Side(empty, empty, empty)
    starts, ends, heights = [], [], []
    s = start_m
    while s < end_m:  # a block of buildings at a time (a few draws per kilometre)
        n = int((end_m - s) / 15.0) + 16
        width = _draw(env.width_m, n, rng)
        gap = np.where(rng.random(n) < env.p_gap, _draw(env.gap_m, n, rng), 0.0)
        height = _draw(env.height_m, n, rng)
        step = np.cumsum(width + gap)
        b_start = s + np.concatenate([[0.0], step[:-1]])
        starts.append(b_start)
        ends.append(b_start + width)
        heights.append(height)
        s = s + step[-1]
    return Side(np.concatenate(starts), np.concatenate(ends), np.concatenate(heights))


@dataclass(frozen=True)
class Street:
    env: Environment
    left: Side
    right: Side
    width_m: float = STREET_WIDTH_M
    antenna_height_m: float = ANTENNA_HEIGHT_M


def make_street(env_name: str, length_m: float, rng: np.random.Generator, width_m: float = STREET_WIDTH_M,
                antenna_height_m: float = ANTENNA_HEIGHT_M) -> Street:  # fmt: skip
    """Both sides of a street ``length_m`` long, with margin for rays reaching ahead and behind."""
    if env_name not in ENVIRONMENTS:
        raise ValueError(f"environment {env_name!r}: one of {', '.join(ENVIRONMENTS)}")
    env = ENVIRONMENTS[env_name]
    reach = _reach_m(env, width_m, antenna_height_m)
    left = buildings(env, -reach, length_m + reach, rng)
    right = buildings(env, -reach, length_m + reach, rng)
    return Street(env, left, right, width_m, antenna_height_m)


def _reach_m(env: Environment, width_m: float, antenna_height_m: float, mask_deg: float = 5.0) -> float:
    """Farthest along-street offset at which a building can hide a satellite above the mask."""
    if env.height_m is None:
        return 0.0
    return max(env.height_m[3] - antenna_height_m, 0.0) / np.tan(np.radians(mask_deg)) + width_m


def line_of_sight(street: Street, s_m: np.ndarray, heading_deg: np.ndarray, elev_deg: np.ndarray,
                  azim_deg: np.ndarray) -> np.ndarray:  # fmt: skip
    """True where the satellite is not hidden; ``s_m``, ``heading_deg`` (E,), angles (E, S)."""
    if street.env.height_m is None:
        return np.ones(np.shape(elev_deg), dtype=bool)
    rel = np.radians(np.asarray(azim_deg) - np.asarray(heading_deg)[:, None])
    sin_a, cos_a = np.sin(rel), np.cos(rel)
    half = street.width_m / 2.0
    with np.errstate(divide="ignore", invalid="ignore"):
        d = half / np.abs(sin_a)
        offset = d * cos_a
    ray_h = street.antenna_height_m + d * np.tan(np.radians(elev_deg))
    along = np.asarray(s_m)[:, None] + np.where(np.isfinite(offset), offset, 0.0)
    on_right = sin_a > 0  # azimuth clockwise from the direction of travel
    h = np.where(on_right, street.right.height_at(along), street.left.height_at(along))
    return ~np.isfinite(d) | (h <= ray_h)
