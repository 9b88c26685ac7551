"""Where the simulated vehicle is: a trajectory at a fixed rate along a route.

A route is a polyline in WGS-84: the LineString(s) of a GeoJSON file (``--route``),
optionally the road features named by ``via`` ids chained in that order (each
reversed when that joins it better to the previous one), or a straight line from a
start point along a heading. The vehicle drives it at constant speed, except where it
stops (``stops``: start time and length of each stop in traffic; it brakes and pulls away at
``ACCEL_MPS2``) and — with ``turn_radius_m`` — where it turns: the route's corners become arcs of that radius, taken
at most at the speed that keeps the sideways acceleration at ``LATERAL_ACCEL_MPS2`` (braking before the corner and
pulling away after it at ``ACCEL_MPS2``); the trajectory gives per epoch the time, position, arc length, heading and
speed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from tollcli.errors import DataError
from tollcli.geodesy import enu_shift2geodetic
from tollcli.spatial import feature_geometry, metric_crs, project, read_features

PERPIGNAN = (42.0 + 41.0 / 60.0, 2.0 + 53.0 / 60.0)  # the thesis's user location [42°41', 2°53']
#: braking and pulling away at a stop, m/s² (town traffic)
ACCEL_MPS2 = 1.5
#: the sideways acceleration a driver turns at, at most (m/s²): with ``turn_radius_m`` the vehicle slows for a corner
LATERAL_ACCEL_MPS2 = 2.0


@dataclass(frozen=True)
class Trajectory:
    """Truth per epoch (arrays of length E)."""

    t_s: np.ndarray  # seconds from the start
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    height_m: np.ndarray
    s_m: np.ndarray  # arc length along the route
    heading_deg: np.ndarray  # direction of travel, clockwise from north
    speed_mps: np.ndarray


def epoch_times(duration_s: float, rate_hz: float) -> np.ndarray:
    n = int(round(duration_s * rate_hz))
    return np.arange(n) / rate_hz


def speed_profile(t_s: np.ndarray, speed_mps: float, stops: list[tuple[float, float]] = ()) -> tuple[np.ndarray, np.ndarray]:
    """(arc length m, speed m/s) at times ``t_s``: ``speed_mps`` but around each stop (start s, length s), where the
    vehicle brakes to a standstill at the start (at ``ACCEL_MPS2``), stands, then pulls away at ``ACCEL_MPS2``."""
    t = np.asarray(t_s, float)
    if not stops:
        return speed_mps * t, np.full(t.shape, float(speed_mps))
    ramp = speed_mps / ACCEL_MPS2

    def speed_at(x: np.ndarray) -> np.ndarray:
        v = np.full(x.shape, float(speed_mps))
        for start, length in stops:
            v = np.where((x >= start - ramp) & (x < start), np.minimum(v, ACCEL_MPS2 * (start - x)), v)
            v = np.where((x >= start) & (x <= start + length), 0.0, v)
            v = np.where((x > start + length) & (x < start + length + ramp), np.minimum(v, ACCEL_MPS2 * (x - start - length)), v)
        return v

    fine = np.arange(0.0, t.max(initial=0.0) + 0.02, 0.01)  # the speed integrated on a 0.01 s grid
    vf = speed_at(fine)
    arc = np.concatenate([[0.0], np.cumsum(0.5 * (vf[1:] + vf[:-1]) * 0.01)])
    return np.interp(t, fine, arc), speed_at(t)


def stopped_time_s(speed_mps: float, stops: list[tuple[float, float]]) -> float:
    """How much longer a route takes with ``stops`` than at constant speed (s)."""
    return sum(length + speed_mps / ACCEL_MPS2 for _, length in stops)


def straight(lat_deg: float, lon_deg: float, heading_deg: float, speed_mps: float, duration_s: float,
             rate_hz: float = 1.0, height_m: float = 50.0, stops: list[tuple[float, float]] = ()) -> Trajectory:  # fmt: skip
    """A straight drive from a start point (local east-north plane: fine for tens of kilometres)."""
    t = epoch_times(duration_s, rate_hz)
    s, v = speed_profile(t, speed_mps, list(stops))
    h = np.radians(heading_deg)
    lat, lon = enu_shift2geodetic(lat_deg, lon_deg, s * np.sin(h), s * np.cos(h))
    n = t.size
    return Trajectory(t, lat, lon, np.full(n, height_m), s, np.full(n, heading_deg % 360.0), v)


def stationary(lat_deg: float, lon_deg: float, heading_deg: float, speed_mps: float, duration_s: float,
               rate_hz: float = 1.0, height_m: float = 50.0) -> Trajectory:  # fmt: skip
    """The papers' set-up: the street runs past a fixed point of the Earth (the satellites see one place)."""
    t = epoch_times(duration_s, rate_hz)
    n = t.size
    return Trajectory(t, np.full(n, lat_deg), np.full(n, lon_deg), np.full(n, height_m), speed_mps * t,
                      np.full(n, heading_deg % 360.0), np.full(n, speed_mps))  # fmt: skip


def load_route(path: str, via: list[str] | None = None) -> list:
    """The route's WGS-84 LineStrings, in driving order."""
    features = read_features(path)
    lines, ids = [], []
    for i, feature in enumerate(features):
        geom, why = feature_geometry(feature)
        if geom is None or geom.geom_type not in ("LineString", "MultiLineString"):
            continue
        props = feature.get("properties") or {}
        parts = list(geom.geoms) if geom.geom_type == "MultiLineString" else [geom]
        lines.extend(parts)
        ids.extend([str(props.get("id", i))] * len(parts))
    if not lines:
        raise DataError(f"{path}: no LineString to drive along")
    if not via:
        return lines
    by_id = {}
    for gid, line in zip(ids, lines):
        by_id.setdefault(gid, line)
    missing = [v for v in via if v not in by_id]
    if missing:
        raise DataError(f"{path}: no road with id {missing[0]!r} for --via")
    return [by_id[v] for v in via]


def _chain(metric_lines: list) -> np.ndarray:
    """One polyline (N, 2) through the lines in order, each reversed if its far end is nearer."""
    coords = np.asarray(metric_lines[0].coords)[:, :2]
    if len(metric_lines) > 1:
        nxt = np.asarray(metric_lines[1].coords)[:, :2]
        ends = [coords[0], coords[-1]]
        d = [min(np.hypot(*(e - nxt[0])), np.hypot(*(e - nxt[-1]))) for e in ends]
        if d[0] < d[1]:
            coords = coords[::-1]
    for line in metric_lines[1:]:
        c = np.asarray(line.coords)[:, :2]
        if np.hypot(*(c[-1] - coords[-1])) < np.hypot(*(c[0] - coords[-1])):
            c = c[::-1]
        if np.hypot(*(c[0] - coords[-1])) < 1e-6:
            c = c[1:]
        coords = np.vstack([coords, c])
    return coords


def _true_heading_deg(s: np.ndarray, cum: np.ndarray, xy: np.ndarray, crs: str) -> np.ndarray:
    """The direction of travel at arc lengths ``s`` from true north (what a receiver's course is): the bearing between
    the route's points 0.5 m behind and ahead, taken back to latitude and longitude (the metric frame's grid north
    is off true north by the meridian convergence, over a degree in a UTM zone's edge)."""
    from tollcli.geodesy import geodetic2enu_shift

    k = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(cum) - 2)
    d = np.diff(xy, axis=0)[k]
    unit = d / np.hypot(d[:, 0], d[:, 1])[:, None]
    x, y = np.interp(s, cum, xy[:, 0]), np.interp(s, cum, xy[:, 1])
    ends = project(shapely.points(np.r_[x - 0.5 * unit[:, 0], x + 0.5 * unit[:, 0]], np.r_[y - 0.5 * unit[:, 1], y + 0.5 * unit[:, 1]]),
                   crs, inverse=True)  # fmt: skip
    lon, lat = shapely.get_x(ends), shapely.get_y(ends)
    n = s.size
    east, north = geodetic2enu_shift(lat[:n], lon[:n], lat[n:], lon[n:])
    return np.degrees(np.arctan2(east, north)) % 360.0


def round_corners(xy: np.ndarray, radius_m: float, step_m: float = 1.0) -> np.ndarray:
    """The polyline (N, 2, metres) with each corner replaced by an arc of ``radius_m`` tangent to both of its legs
    (smaller where the legs are too short for it: the arc may take at most half of each), points every ``step_m``."""
    out = [xy[0]]
    for i in range(1, len(xy) - 1):
        a, b, c = xy[i - 1], xy[i], xy[i + 1]
        u, w = b - a, c - b
        lu, lw = np.hypot(*u), np.hypot(*w)
        turn = np.arctan2(u[0] * w[1] - u[1] * w[0], u @ w)  # signed, counter-clockwise positive
        if lu == 0 or lw == 0 or abs(turn) < np.radians(1.0):
            out.append(b)
            continue
        tangent = min(radius_m * np.tan(abs(turn) / 2.0), 0.5 * lu, 0.5 * lw)
        r = tangent / np.tan(abs(turn) / 2.0)
        start = b - u / lu * tangent
        normal = np.array([-u[1], u[0]]) / lu * np.sign(turn)  # towards the inside of the turn
        centre = start + normal * r
        a0 = np.arctan2(*(start - centre)[::-1])
        k = max(2, int(np.ceil(r * abs(turn) / step_m)))
        angles = a0 + np.sign(turn) * abs(turn) * np.linspace(0.0, 1.0, k + 1)
        out.extend(centre + r * np.column_stack([np.cos(angles), np.sin(angles)]))
    out.append(xy[-1])
    return np.asarray(out)


def turning_profile(t_s: np.ndarray, cum: np.ndarray, xy: np.ndarray, speed_mps: float,
                    stops: list[tuple[float, float]] = ()) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(arc length m, speed m/s) at times ``t_s`` along the polyline ``xy`` (arc lengths ``cum``): ``speed_mps`` but
    where its curvature κ asks for less (v ≤ √(LATERAL_ACCEL_MPS2 / κ), braking before at ``ACCEL_MPS2``), pulling
    away at ``ACCEL_MPS2``, and standing still at each stop (start s, length s) after braking to it."""
    heading = np.unwrap(np.arctan2(*np.diff(xy, axis=0).T[::-1]))
    mid = 0.5 * (cum[1:] + cum[:-1])
    grid = np.arange(0.0, cum[-1] + 0.5, 0.5)
    turn_rate = np.abs(np.gradient(np.interp(grid, mid, heading), grid)) if mid.size > 1 else np.zeros(grid.size)
    limit = np.minimum(speed_mps, np.sqrt(LATERAL_ACCEL_MPS2 / np.maximum(turn_rate, 1e-9)))
    for i in range(grid.size - 2, -1, -1):  # brake in time: at most what slowing at ACCEL_MPS2 reaches the next limit from
        limit[i] = min(limit[i], np.sqrt(limit[i + 1] ** 2 + 2.0 * ACCEL_MPS2 * (grid[i + 1] - grid[i])))
    dt = 0.01
    n = int(np.ceil((float(np.max(t_s, initial=0.0)) + dt) / dt)) + 1
    arc, speed = np.zeros(n), np.zeros(n)
    x, v = 0.0, float(limit[0])
    caps = (limit**2).tolist()  # v² is linear in the arc length while braking at a constant rate: interpolated so
    last = len(caps) - 1
    for k in range(n):  # a simulator's set-up, not a log's hot path: 0.01 s steps
        tk = k * dt
        i = min(int(x / 0.5), last)
        f = x / 0.5 - i
        cap = (caps[i] + (caps[min(i + 1, last)] - caps[i]) * min(f, 1.0)) ** 0.5
        for start, length in stops:
            if start <= tk <= start + length:
                cap = 0.0
            elif tk < start:
                cap = min(cap, ACCEL_MPS2 * (start - tk))
        v = min(v + ACCEL_MPS2 * dt, cap) if cap >= v else max(cap, 0.0)
        arc[k], speed[k] = x, v
        x += v * dt
    fine = np.arange(n) * dt
    return np.interp(t_s, fine, arc), np.interp(t_s, fine, speed)


def along_route(lines_wgs84: list, speed_mps: float, rate_hz: float = 1.0, duration_s: float | None = None,
                height_m: float = 50.0, stops: list[tuple[float, float]] = (), turn_radius_m: float | None = None) -> Trajectory:  # fmt: skip
    """Drive the polyline once at constant speed but for ``stops`` (or for ``duration_s``, stopping at its end); with
    ``turn_radius_m``, round its corners to that radius and slow for them (:func:`turning_profile`)."""
    crs = metric_crs(lines_wgs84)
    metric = list(project(np.asarray(lines_wgs84, dtype=object), crs))
    xy = _chain(metric)
    seg = np.hypot(*np.diff(xy, axis=0).T)
    keep = np.concatenate([[True], seg > 0])
    xy = xy[keep]
    if turn_radius_m:
        xy = round_corners(xy, turn_radius_m)
        seg = np.hypot(*np.diff(xy, axis=0).T)
        xy = xy[np.concatenate([[True], seg > 1e-9])]
        seg = seg[seg > 1e-9]
    cum = np.concatenate([[0.0], np.cumsum(seg[seg > 0])])
    length = cum[-1]
    if length <= 0:
        raise DataError("the route has no length")
    whole = length / speed_mps + stopped_time_s(speed_mps, list(stops))
    if turn_radius_m:  # slower in the turns: time enough for the whole route at the slowest turn's pace, cut below
        whole = length / min(speed_mps, np.sqrt(LATERAL_ACCEL_MPS2 * turn_radius_m)) + stopped_time_s(speed_mps, list(stops))
    total = whole if duration_s is None else min(duration_s, whole)
    t = epoch_times(total, rate_hz)
    if turn_radius_m:
        s, v = turning_profile(t, cum, xy, speed_mps, list(stops))
    else:
        s, v = speed_profile(t, speed_mps, list(stops))
    inside = s <= length
    t, s, v = t[inside], s[inside], v[inside]
    x = np.interp(s, cum, xy[:, 0])
    y = np.interp(s, cum, xy[:, 1])
    pts = project(shapely.points(x, y), crs, inverse=True)
    lon, lat = shapely.get_x(pts), shapely.get_y(pts)
    heading = _true_heading_deg(s, cum, xy, crs)
    n = t.size
    return Trajectory(t, lat, lon, np.full(n, height_m), s, heading, v)
