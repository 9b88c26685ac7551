"""``geoobjects build --gantries/--zones``: virtual gantries across roads, from points (a GeoJSON Point per gantry, or
OpenStreetMap nodes tagged ``barrier=toll_booth`` or ``highway=toll_gantry``) or lines drawn across a road, and charging
zones from polygons (``geoobjects/city.py`` says what they are).

A point becomes a straight line across the nearest road, ``width_m`` long (its ``width_m`` property, else
:data:`WIDTH_M`), perpendicular to the road there, drawn from the road's right to its left: a vehicle driving the road in
the direction it is drawn crosses it ``left_to_right``. Its HAL is the design HAL unless another road crosses the line's
extension closer than 2 × HAL: then half the distance from the line's end to that road, less :data:`CLEARANCE_M` (the
evidence area reaches HAL past the line's ends; a position valid at that HAL inside it is within HAL of the truth, so the
vehicle can never be on the other road). A gantry left with a HAL below ``hal_min_m`` is
skipped, and said why.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from tollcli.errors import DataError
from tollcli.geoobjects.city import DEPTH_M, DIRECTIONS, ZONE_HAL_M

#: a gantry line's length across the road when its point does not say, m
WIDTH_M = 20.0
#: how far from its road a gantry's point may be, m
SNAP_M = 50.0
#: kept between the evidence area and another road, m
CLEARANCE_M = 2.0


def road_lines(path: str) -> tuple[list[str], list]:
    """Every road of a road file (GeoJSON and the other vector files, or OpenStreetMap: its drivable ways) as
    (ids, WGS-84 LineStrings)."""
    from tollcli.geoobjects.osm import is_osm

    if is_osm(path):
        from tollcli.geoobjects.osm import read_osm_roads

        osm = read_osm_roads(path)
        lines = [shapely.LineString(np.c_[osm.lon_deg[a:b], osm.lat_deg[a:b]]) for a, b in zip(osm.offsets[:-1], osm.offsets[1:])]
        return [f"way/{w}" for w in osm.ways["way_id"]], lines
    from tollcli.geoobjects.road_files import read_road_features
    from tollcli.spatial import feature_geometry

    ids, lines = [], []
    for i, f in enumerate(read_road_features(path)):
        geom, _ = feature_geometry(f)
        if geom is None or geom.is_empty:
            continue
        parts = list(geom.geoms) if geom.geom_type == "MultiLineString" else [geom] if geom.geom_type == "LineString" else []
        for part in parts:
            ids.append(str(((f.get("properties") or {}).get("id")) or f"#{i}"))
            lines.append(part)
    if not lines:
        raise DataError(f"{path}: no road lines")
    return ids, lines


def gantry_sites(path: str) -> list[dict]:
    """The gantries a file gives: GeoJSON Points or two-point LineStrings (with their properties), or OpenStreetMap nodes
    tagged barrier=toll_booth or highway=toll_gantry."""
    from tollcli.geoobjects.osm import is_osm

    if is_osm(path):
        import osmium

        out = []
        try:
            for obj in osmium.FileProcessor(path).with_filter(osmium.filter.KeyFilter("barrier", "highway")):
                if obj.is_node() and (obj.tags.get("barrier") == "toll_booth" or obj.tags.get("highway") == "toll_gantry"):
                    out.append({"geometry": shapely.Point(obj.lon, obj.lat),
                                "properties": {"id": f"node/{obj.id}", "name": obj.tags.get("name", f"node/{obj.id}")}})  # fmt: skip
        except RuntimeError as exc:
            raise DataError(f"{path}: not a readable OpenStreetMap file ({exc})") from None
        if not out:
            raise DataError(f"{path}: no node tagged barrier=toll_booth or highway=toll_gantry")
        return out
    from tollcli.spatial import feature_geometry, read_features

    out = []
    for i, f in enumerate(read_features(path)):
        geom, why = feature_geometry(f)
        props = dict((f.get("properties") or {}) if isinstance(f, dict) else {})
        props.setdefault("id", f"#{i}")
        if geom is None or geom.geom_type not in ("Point", "LineString") or (geom.geom_type == "LineString" and len(geom.coords) != 2):
            raise DataError(f"{path}: feature {props['id']}: a gantry is a Point on a road or a two-point line across it ({why or (geom.geom_type if geom is not None else 'none')})")
        out.append({"geometry": geom, "properties": props})
    if not out:
        raise DataError(f"{path}: no gantry")
    return out


def build_gantries(sites: list[dict], road_ids: list[str], roads_wgs84: list, hal_m: float, hal_min_m: float,
                   direction: str = "both") -> tuple[list[dict], list[dict]]:  # fmt: skip
    """Gantry features (WGS-84 geometries as shapely) and the sites skipped with why."""
    from tollcli.spatial import local_frame, project

    lons = [s["geometry"].centroid.x for s in sites]
    crs = local_frame(float(np.mean(lons)))
    roads = project(np.asarray(roads_wgs84, dtype=object), crs)
    tree = shapely.STRtree(roads)
    features, skipped = [], []
    for site in sites:
        props = site["properties"]
        gid = str(props["id"])
        geom = project(np.asarray([site["geometry"]], dtype=object), crs)[0]
        if geom.geom_type == "Point":
            k = int(tree.nearest(geom))
            if roads[k].distance(geom) > SNAP_M:
                skipped.append({"id": gid, "reason": f"no road within {SNAP_M:g} m of the point"})
                continue
            at = roads[k].project(geom)
            p = roads[k].interpolate(at)
            a, b = roads[k].interpolate(max(at - 1.0, 0.0)), roads[k].interpolate(min(at + 1.0, roads[k].length))
            tx, ty = b.x - a.x, b.y - a.y
            norm = math.hypot(tx, ty) or 1.0
            half = float(props.get("width_m", WIDTH_M)) / 2
            nx, ny = -ty / norm * half, tx / norm * half  # the road's left, half a width
            line = shapely.LineString([(p.x - nx, p.y - ny), (p.x + nx, p.y + ny)])  # right to left: driving the road as drawn crosses left_to_right
        else:
            line = geom
            crossing = tree.query(line, predicate="intersects")
            if not len(crossing):
                skipped.append({"id": gid, "reason": "the line crosses no road"})
                continue
            k = int(min(crossing, key=lambda j: roads[j].distance(line.interpolate(0.5, normalized=True))))
        hal, bound = _gantry_hal(line, k, roads, tree, road_ids, hal_m)
        if hal < hal_min_m:
            skipped.append({"id": gid, "reason": f"road {bound} crosses the gantry line's extension {2 * hal + CLEARANCE_M:.1f} m from its end: "
                                                 f"HAL {hal:.1f} m is below {hal_min_m:g} m"})  # fmt: skip
            continue
        out_props = {k2: v for k2, v in props.items() if k2 not in ("width_m",)}
        out_props.update(kind="gantry", id=gid, name=str(props.get("name", gid)), direction=str(props.get("direction", direction)),
                         hal_m=round(hal, 1), depth_m=float(props.get("depth_m", DEPTH_M)), road=road_ids[k])  # fmt: skip
        if out_props["direction"] not in DIRECTIONS:
            raise DataError(f"gantry {gid}: direction {out_props['direction']!r}: one of {', '.join(DIRECTIONS)}")
        if bound:
            out_props["hal_bound"] = bound
        features.append({"type": "Feature", "properties": out_props,
                         "geometry": project(np.asarray([line], dtype=object), crs, inverse=True)[0]})  # fmt: skip
    return features, skipped


def _gantry_hal(line, road: int, roads, tree, road_ids: list[str], hal_m: float) -> tuple[float, str]:
    """The largest HAL ≤ ``hal_m`` that keeps every other road crossing the line's extension at least 2 × HAL (and
    :data:`CLEARANCE_M`) from the line's ends — the evidence area reaches HAL past them, a position valid at that HAL is
    within HAL of the truth — and the road that bounds it ('' when none does)."""
    (x0, y0), (x1, y1) = line.coords
    length = math.hypot(x1 - x0, y1 - y0)
    ux, uy = (x1 - x0) / length, (y1 - y0) / length
    reach = 2 * hal_m + CLEARANCE_M
    extended = shapely.LineString([(x0 - ux * reach, y0 - uy * reach), (x1 + ux * reach, y1 + uy * reach)])
    best, bound = hal_m, ""
    for j in tree.query(extended, predicate="intersects"):
        if j == road or road_ids[j] == road_ids[road]:
            continue
        hit = extended.intersection(roads[j])
        for point in getattr(hit, "geoms", [hit]):
            if point.is_empty:
                continue
            s = (point.x - x0) * ux + (point.y - y0) * uy
            gap = -s if s < 0 else s - length if s > length else 0.0
            if (gap - CLEARANCE_M) / 2 < best:
                best, bound = (gap - CLEARANCE_M) / 2, road_ids[j]
    return best, bound


def build_zones(path: str, hal_m: float = ZONE_HAL_M) -> list[dict]:
    """Zone features from the polygons of a GeoJSON file (their ``hal_m``, else ``hal_m``)."""
    from tollcli.spatial import feature_geometry, read_features

    out = []
    for i, f in enumerate(read_features(path)):
        geom, why = feature_geometry(f)
        props = dict((f.get("properties") or {}) if isinstance(f, dict) else {})
        props.setdefault("id", f"#{i}")
        if geom is None or geom.geom_type not in ("Polygon", "MultiPolygon") or not geom.is_valid:
            raise DataError(f"{path}: feature {props['id']}: a zone is a valid Polygon ({why or (geom.geom_type if geom is not None else 'none')})")
        props.update(kind="zone", id=str(props["id"]), name=str(props.get("name", props["id"])), hal_m=float(props.get("hal_m", hal_m)))
        out.append({"type": "Feature", "properties": props, "geometry": geom})
    if not out:
        raise DataError(f"{path}: no zone polygon")
    return out
