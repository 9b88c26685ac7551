"""Tolled roads of a GeoJSON (or GeoPackage, Shapefile…) network cut into sections at their junctions.

A toll charges a section: the stretch of a tolled road between two junctions, and a per-km rate its
length. OpenStreetMap ways are cut at shared nodes (``osm_network.py``); a vector file has no nodes, so a
tolled road is cut wherever another road on its level meets its interior: one of that road's points
(an end or a vertex) within ``connect_tol_m`` of it, or a crossing of the two lines on one level (an at-grade
junction drawn without a shared vertex). Roads on another level (``layer``, ``bridge``, ``tunnel``) never cut
it. The pieces of a road ``ID`` cut at k junctions are the sections ``ID/1`` … ``ID/k+1`` in the order of its
points; a tariff's fee for ``ID`` applies to each of them (``tariffs.py``).
"""

from __future__ import annotations

import numpy as np
import shapely

from tollcli.spatial import metric_crs, project


def section_id(road_id: str, k: int) -> str:
    """The id of the k-th (1-based) section cut from road ``road_id``."""
    return f"{road_id}/{k}"


def road_of(section: str) -> str:
    """The road a section was cut from (``ID/2`` → ``ID``; a section never cut is its own road)."""
    road, sep, k = str(section).rpartition("/")
    return road if sep and road and k.isdigit() else str(section)


def cut_at_junctions(roads, connect_tol_m: float, levels: np.ndarray, tolled: np.ndarray):
    """``roads`` (a :class:`tollcli.geoobjects.build.Roads` without topology) with every tolled road cut at the
    junctions on its interior; free roads are kept whole (they only bound and cut geo-objects)."""
    lines = np.asarray(roads.lines, dtype=object)
    metric = project(lines, metric_crs(lines))  # topology only: one UTM zone is plenty for a metre's tolerance
    todo = np.flatnonzero(tolled)
    left, right = shapely.STRtree(metric).query(metric[todo], predicate="dwithin", distance=connect_tol_m)
    left = todo[left]
    by_road = np.argsort(left, kind="stable")  # grouped by road (the order within each kept)
    left, right = left[by_road], right[by_road]
    keep = (left != right) & (levels[left] == levels[right])
    left, right = left[keep], right[keep]
    first, last = np.searchsorted(left, np.arange(len(lines)), side="left"), np.searchsorted(left, np.arange(len(lines)), side="right")
    ids, props, out = [], [], []
    for i in range(len(lines)):  # the pairs come grouped by road, roads in order: a road's are right[first:last]
        cuts = _junction_positions(metric[i], metric[right[first[i] : last[i]]], connect_tol_m) if tolled[i] else []
        pieces = _split(lines[i], metric[i], cuts, connect_tol_m) if cuts else [lines[i]]
        for k, piece in enumerate(pieces, start=1):
            ids.append(roads.ids[i] if len(pieces) == 1 else section_id(roads.ids[i], k))
            props.append(dict(roads.props[i]))
            out.append(piece)
    return type(roads)(ids, props, out, None)


def _junction_positions(line, others, tol_m: float) -> list[float]:
    """Distances along ``line`` (metric) where the ``others`` meet its interior, merged within ``tol_m``."""
    at = []
    for other in others:
        vertices = shapely.points(shapely.get_coordinates(other))
        near = vertices[shapely.distance(line, vertices) <= tol_m]
        at += shapely.line_locate_point(line, near).tolist()
        crossing = shapely.intersection(line, other)
        if not crossing.is_empty:
            at += shapely.line_locate_point(line, shapely.points(shapely.get_coordinates(crossing))).tolist()
    inner = sorted(s for s in at if tol_m < s < line.length - tol_m)
    merged: list[float] = []
    for s in inner:
        if not merged or s - merged[-1] > tol_m:
            merged.append(s)
    return merged


def _split(wgs84, metric, cuts_m: list[float], tol_m: float) -> list:
    """The WGS-84 line cut at distances ``cuts_m`` along its metric twin: at the line's own vertex where one lies
    within ``tol_m`` of the cut (a shared vertex: coordinates kept exactly), else at a point interpolated on the
    segment (an at-grade crossing without a vertex)."""
    lonlat = np.asarray(wgs84.coords)
    xy = np.asarray(metric.coords)
    along = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))))
    points = [p.tolist() for p in lonlat]
    positions = along.tolist()
    for s in cuts_m:
        k = int(np.argmin(np.abs(along - s)))
        if abs(along[k] - s) <= tol_m:
            continue  # a vertex of the line: cut there
        seg = int(np.searchsorted(along, s)) - 1
        f = (s - along[seg]) / (along[seg + 1] - along[seg])
        new = (lonlat[seg] + f * (lonlat[seg + 1] - lonlat[seg])).tolist()
        where = positions.index(along[seg + 1])
        points.insert(where, new)
        positions.insert(where, s)
    positions_arr = np.asarray(positions)
    cut_idx = sorted({int(np.argmin(np.abs(positions_arr - s))) for s in cuts_m})
    bounds = [0, *[c for c in cut_idx if 0 < c < len(points) - 1], len(points) - 1]
    return [shapely.LineString(points[a : b + 1]) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]
