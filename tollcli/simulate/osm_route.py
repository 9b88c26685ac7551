"""Routes on an OpenStreetMap road network for simulated drives: a list of way ids, or the shortest path.

:func:`route_by_ways` chains the given ways in order (each reversed when its far end meets the previous
one); :func:`shortest_route` snaps two points to their nearest road nodes and follows the shortest path
by length over the drivable ways (scipy's Dijkstra on the node graph, ``oneway`` respected). Both give
WGS-84 LineStrings in driving order for :func:`tollcli.simulate.route.along_route`.
"""

from __future__ import annotations

import numpy as np
import shapely
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

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


def shortest_route(path: str, start: tuple[float, float], end: tuple[float, float]) -> list:
    """The shortest drivable path from ``start`` to ``end`` (LAT, LON degrees) as one LineString."""
    osm = read_osm_roads(path)
    nodes, inverse = np.unique(osm.node_id, return_inverse=True)
    lon = np.zeros(nodes.size)
    lat = np.zeros(nodes.size)
    lon[inverse], lat[inverse] = osm.lon_deg, osm.lat_deg
    a, b, w = _edges(osm, inverse, lat, lon)
    graph = coo_matrix((w, (a, b)), shape=(nodes.size, nodes.size)).tocsr()
    source, target = (_snap(p, lat, lon, name) for p, name in ((start, "--from"), (end, "--to")))
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
