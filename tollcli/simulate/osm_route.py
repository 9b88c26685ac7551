"""Routes on an OpenStreetMap road network for simulated drives: a list of way ids, or the shortest path.

:func:`route_by_ways` chains the given ways in order (each reversed when its far end meets the previous
one); :func:`shortest_route` snaps two points to their nearest road nodes and follows the shortest path
by length over the drivable ways (scipy's Dijkstra on the node graph, ``oneway`` respected); :func:`tour` chains
shortest paths to random places of the network until the drive is long enough (a town drive with its turns). All give
WGS-84 LineStrings in driving order for :func:`tollcli.simulate.route.along_route`.
"""

from __future__ import annotations

import numpy as np
import shapely
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra

from tollcli.errors import DataError, UsageError
from tollcli.geodesy import great_circle_distance_m
from tollcli.geoobjects.osm import OsmRoads, read_osm_roads

#: a point further than this from every road node is not on the network (m)
SNAP_MAX_M = 200.0


def route_by_ways(path: str, way_ids: list[str]) -> list:
    """The ways ``way_ids`` (OSM ids) of the map, in that order, as LineStrings."""
    osm = read_osm_roads(path)
    index = {int(w): k for k, w in enumerate(osm.ways["way_id"].tolist())}
    lines = []
    for text in way_ids:
        try:
            k = index[int(text)]
        except (ValueError, KeyError):
            raise DataError(f"{path}: no drivable way with id {text!r} for --via") from None
        a, b = osm.offsets[k], osm.offsets[k + 1]
        lines.append(shapely.LineString(np.column_stack([osm.lon_deg[a:b], osm.lat_deg[a:b]])))
    return lines


def _graph(path: str):
    """The map's node coordinates (lat, lon degrees) and its directed graph of drivable road lengths (m)."""
    osm = read_osm_roads(path)
    nodes, inverse = np.unique(osm.node_id, return_inverse=True)
    lon = np.zeros(nodes.size)
    lat = np.zeros(nodes.size)
    lon[inverse], lat[inverse] = osm.lon_deg, osm.lat_deg
    a, b, w = _edges(osm, inverse, lat, lon)
    return lat, lon, coo_matrix((w, (a, b)), shape=(nodes.size, nodes.size)).tocsr()


def tour(path: str, start: tuple[float, float], length_m: float, seed: int = 0, min_leg_m: float = 600.0) -> list:
    """Shortest paths chained from ``start`` (LAT, LON degrees) to random places of the map at least ``min_leg_m``
    along the roads away, until they are ``length_m`` long: LineStrings in driving order (the same ``seed``, the
    same tour)."""
    lat, lon, graph = _graph(path)
    rng = np.random.default_rng(seed)
    _, label = connected_components(graph, directed=True, connection="strong")
    inside = label == np.bincount(label).argmax()  # the largest part of the map every place of which reaches every other
    here = int(np.flatnonzero(inside)[_snap(start, lat[inside], lon[inside], "start")])
    lines, total = [], 0.0
    while total < length_m:
        dist, previous = dijkstra(graph, indices=here, return_predecessors=True)
        far = np.flatnonzero(inside & np.isfinite(dist) & (dist >= min_leg_m))
        if far.size == 0:
            raise DataError(f"{path}: no road {min_leg_m:g} m or more away from {lat[here]:.5f},{lon[here]:.5f} to drive to")
        there = int(far[rng.integers(far.size)])
        chain = [there]
        while chain[-1] != here:
            chain.append(previous[chain[-1]])
        chain = chain[::-1]
        lines.append(shapely.LineString(np.column_stack([lon[chain], lat[chain]])))
        total += float(dist[there])
        here = there
    return lines


def shortest_route(path: str, start: tuple[float, float], end: tuple[float, float]) -> list:
    """The shortest drivable path from ``start`` to ``end`` (LAT, LON degrees) as one LineString."""
    lat, lon, graph = _graph(path)
    source, target = (_snap(p, lat, lon, name) for p, name in ((start, "--from"), (end, "--to")))
    if source == target:
        raise DataError(f"{path}: --from {start[0]:g},{start[1]:g} and --to {end[0]:g},{end[1]:g} are the same point of the road network")
    dist, previous = dijkstra(graph, indices=source, return_predecessors=True)
    if not np.isfinite(dist[target]):
        raise DataError(f"{path}: no drivable path from {start} to {end} (one-way streets or disconnected roads)")
    chain = [target]
    while chain[-1] != source:
        chain.append(previous[chain[-1]])
    chain = chain[::-1]
    return [shapely.LineString(np.column_stack([lon[chain], lat[chain]]))]


def _edges(osm: OsmRoads, inverse: np.ndarray, lat: np.ndarray, lon: np.ndarray):
    """Directed edges (from node, to node, length m) of consecutive way nodes; both ways unless ``oneway``."""
    same_way = np.ones(len(inverse) - 1, bool)
    same_way[osm.offsets[1:-1] - 1] = False
    i = np.flatnonzero(same_way)
    way_of = np.repeat(np.arange(len(osm.offsets) - 1), np.diff(osm.offsets))[i]
    oneway = osm.ways["oneway"].to_numpy(str)[way_of]
    u, v = inverse[i], inverse[i + 1]
    length = great_circle_distance_m(lat[u], lon[u], lat[v], lon[v])
    forward = oneway != "-1"
    backward = ~np.isin(oneway, ["yes", "true", "1"])
    a = np.concatenate([u[forward], v[backward]])
    b = np.concatenate([v[forward], u[backward]])
    return a, b, np.concatenate([length[forward], length[backward]]) + 1e-6


def _snap(point: tuple[float, float], lat: np.ndarray, lon: np.ndarray, name: str) -> int:
    d = great_circle_distance_m(point[0], point[1], lat, lon)
    k = int(np.argmin(d))
    if d[k] > SNAP_MAX_M:
        raise UsageError(f"{name} {point[0]:g},{point[1]:g}: no road within {SNAP_MAX_M:g} m")
    return k
