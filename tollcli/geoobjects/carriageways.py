"""Opposite carriageways of one road: geo-objects that recognise a position by its direction of travel too.

A motorway (and many city streets) is mapped as two one-way carriageways 10–30 m apart. Built as
two roads, each would bound the other's HAL at half that distance — 5–15 m, below what single-
frequency RAIM can protect — and nothing could be charged. Two tolled sections are *opposite
carriageways* when both are one-way, carry the same ``ref`` or ``name``, do not meet, and run
antiparallel where they are closest (directions more than ``ANTIPARALLEL_DEG`` apart). They then
do not bound each other's HAL and their geo-objects may overlap; instead a position counts for
such a geo-object only when the vehicle's course (RMC, or the Doppler velocity) is within
``DIRECTION_TOL_DEG`` of the carriageway's direction at the nearest point of its axis, at a speed
of at least ``MIN_COURSE_SPEED_MPS`` (a course at walking pace is noise). A vehicle on the other
carriageway drives the other way: its positions never count, wherever they fall.

Each such geo-object records ``opposite`` (the ids of its partners) and ``axis`` (its centre
line, longitude/latitude, in the direction of travel).
"""

from __future__ import annotations

import numpy as np
import shapely

#: carriageways closer to antiparallel than this (180° − their angle ≤ 180° − ANTIPARALLEL_DEG) are opposite
ANTIPARALLEL_DEG = 150.0
#: a position counts for a directed geo-object when the course is within this of the road's direction
DIRECTION_TOL_DEG = 45.0
#: below this speed the course is not trusted: a directed geo-object does not count the position
MIN_COURSE_SPEED_MPS = 3.0


def is_oneway(props: dict) -> bool:
    """A road travelled one way, in the order of its points (OpenStreetMap ``oneway``, or ``direction = forward``)."""
    return props.get("oneway") in (True, "yes", "true", "1") or str(props.get("direction") or "").lower() in ("forward", "oneway", "one-way")


def heading_deg(lines, x, y, step_m: float = 2.0) -> np.ndarray:
    """The direction of travel (degrees clockwise from grid north) of each line at the point nearest to (x, y).

    ``lines``: LineStrings in a metric frame (one per point, broadcast with numpy); x, y in that frame.
    """
    lines = np.asarray(lines, dtype=object)
    at = shapely.line_locate_point(lines, shapely.points(x, y))
    length = shapely.length(lines)
    a = shapely.get_coordinates(shapely.line_interpolate_point(lines, np.clip(at - step_m, 0, length)))
    b = shapely.get_coordinates(shapely.line_interpolate_point(lines, np.clip(at + step_m, 0, length)))
    return np.degrees(np.arctan2(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1])) % 360.0


def opposite_pairs(left: np.ndarray, right: np.ndarray, metric: np.ndarray, props: list[dict], meets: np.ndarray) -> np.ndarray:
    """Which (left, right) road pairs are opposite carriageways of one road (a bool per pair)."""
    out = np.zeros(left.size, bool)
    for k, (i, j) in enumerate(zip(left.tolist(), right.tolist())):
        a, b = props[i], props[j]
        if meets[k] or not (a.get("tolled", True) and b.get("tolled", True) and is_oneway(a) and is_oneway(b)):
            continue
        same = any(a.get(key) and a.get(key) == b.get(key) for key in ("ref", "name"))
        if not same:
            continue
        near = shapely.get_coordinates(shapely.shortest_line(metric[i], metric[j]))
        ha = heading_deg([metric[i]], near[:1, 0], near[:1, 1])[0]
        hb = heading_deg([metric[j]], near[1:, 0], near[1:, 1])[0]
        out[k] = abs((ha - hb + 180.0) % 360.0 - 180.0) >= ANTIPARALLEL_DEG
    return out


def direction_check(axes: np.ndarray, px: np.ndarray, py: np.ndarray, course_deg: np.ndarray, speed_mps: np.ndarray) -> np.ndarray:
    """Per position on a directed geo-object: '' when the course agrees with the axis, 'wrong_direction' or
    'direction_unknown' (no course, or too slow to trust it). Vectorized over positions."""
    out = np.full(px.size, "", dtype=object)
    if px.size == 0:
        return out
    road = heading_deg(axes, px, py)
    course, speed = np.asarray(course_deg, float), np.asarray(speed_mps, float)
    known = np.isfinite(course) & np.isfinite(speed) & (speed >= MIN_COURSE_SPEED_MPS)
    off = np.abs((course - road + 180.0) % 360.0 - 180.0)
    out[~known] = "direction_unknown"
    out[known & ~(off <= DIRECTION_TOL_DEG)] = "wrong_direction"
    return out
