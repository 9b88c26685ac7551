"""Geo-objects: constant-HAL buffers around tolled road segments (paper 001 §II; thesis §3.4).

A road network is a GeoJSON FeatureCollection of LineStrings (centre lines) with
properties ``id``, ``name``, ``road_class``, optional ``hal_m``, optional
``direction`` and ``tolled`` (default true). Non-tolled roads only bound HAL.

:func:`build_geoobjects` works, for every tolled segment, in a metric frame chosen for it
(a transverse Mercator on the nearest whole-degree meridian, :func:`tollcli.spatial.local_frame`:
ground distances to ≤ 0.05 % at any extent) and:

1. HAL = min(HAL_max, its own ``hal_m`` if given, ½ · distance to the nearest road it
   is not connected to, other than its opposite carriageway: ``carriageways.py``). "Connected" means touching within ``connect_tol_m`` on the same
   level (``layer``, ``bridge``, ``tunnel``) — or, for a map with topology, sharing a node
   (a junction); connected roads meet the segment by construction and would
   otherwise force HAL to zero. A road that crosses without meeting (a bridge, a tunnel)
   does not bound HAL: the segment is cut back around it instead (step 2).
2. The parts of the centre line within ``trim_factor · HAL`` of a road it meets are
   cut (at a right-angle junction: the end, by ``trim_factor · HAL``; at a shallow merge,
   as far as the roads stay that close), so that the buffer does not reach into the roads
   leaving the junction; the parts within ``trim_factor · HAL`` of a crossing road are
   removed the same way.
3. The geo-object is the centre line buffered by HAL (round caps): a position
   inside it, valid with HPL = HAL, is within HAL of the tolled road.

The output is GeoJSON in WGS-84 (RFC 7946) with the metric frame used recorded
per feature (``crs_metric``), so recognition can project positions the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from tollcli.charging.carriageways import opposite_pairs
from tollcli.errors import DataError
from tollcli.spatial import feature_geometry, local_frame, metric_crs, project, read_features

HAL_MAX_M = 50.0
CONNECT_TOL_M = 1.0
TRIM_FACTOR = 2.0


@dataclass
class Finding:
    """One problem of a geo-object file, tied to a feature."""

    feature: str  # id, or "#<index>" when the feature has none
    problem: str

    def __str__(self) -> str:
        return f"{self.feature}: {self.problem}"


def _feature_id(feature, index: int) -> str:
    props = feature.get("properties") if isinstance(feature, dict) else None
    fid = props.get("id") if isinstance(props, dict) else None
    return str(fid) if fid not in (None, "") else f"#{index}"


def _roads(features: list[dict], path: str):
    """(ids, properties, WGS-84 lines) of the road features; DataError on unusable ones."""
    ids, props, lines = [], [], []
    for i, feature in enumerate(features):
        fid = _feature_id(feature, i)
        geom, why = feature_geometry(feature)
        if geom is None:
            raise DataError(f"{path}: feature {fid}: {why}")
        if geom.geom_type == "MultiLineString" and len(geom.geoms) == 1:
            geom = geom.geoms[0]
        if geom.geom_type != "LineString" or geom.is_empty:
            raise DataError(f"{path}: feature {fid}: a road must be a LineString, got {geom.geom_type}")
        if geom.length == 0:
            raise DataError(f"{path}: feature {fid}: a road of zero length (all its points are the same)")
        lon, lat = np.asarray(geom.coords)[:, 0], np.asarray(geom.coords)[:, 1]
        if (np.abs(lon) > 180).any() or (np.abs(lat) > 90).any():
            raise DataError(f"{path}: feature {fid}: coordinates are not longitude/latitude degrees")
        ids.append(fid)
        props.append(dict(feature.get("properties") or {}) if isinstance(feature.get("properties"), dict) else {})
        lines.append(geom)
    if len(set(ids)) != len(ids):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        raise DataError(f"{path}: duplicate road ids {', '.join(dup)}")
    if not lines:
        raise DataError(f"{path}: no roads")
    return ids, props, lines


def road_level(props: dict) -> int:
    """A road's vertical level: its ``layer``, else +1 on a bridge, −1 in a tunnel, else 0 (OpenStreetMap rules)."""
    layer = props.get("layer")
    try:
        return int(layer)
    except (TypeError, ValueError):
        pass
    if flag_set(props.get("bridge")):
        return 1
    return -1 if flag_set(props.get("tunnel")) else 0


def flag_set(value) -> bool:
    """A road tag that is set (``bridge``, ``tunnel``): anything but absent, false, 0, "", "no" or "false"."""
    return value not in (None, False, "", 0) and str(value).lower() not in ("no", "0", "false")


@dataclass
class Roads:
    """Centre lines (WGS-84) with their ids and properties; ``junctions``: pairs (i, j) of roads that meet (share a
    node) when the source knows its topology (OpenStreetMap), else None: roads touching in 2-D on one level meet."""

    ids: list[str]
    props: list[dict]
    lines: list
    junctions: set[tuple[int, int]] | None = None


def build_geoobjects(path: str, hal_max_m: float = HAL_MAX_M, connect_tol_m: float = CONNECT_TOL_M,
                     trim_factor: float = TRIM_FACTOR) -> dict:  # fmt: skip
    """A roads file → a GeoJSON FeatureCollection of geo-objects (dict, WGS-84)."""
    ids, props, lines = _roads(read_features(path), path)
    doc, _ = build_from_roads(Roads(ids, props, lines), path, hal_max_m, connect_tol_m, trim_factor)
    return doc


def build_from_roads(roads: Roads, path: str, hal_max_m: float = HAL_MAX_M, connect_tol_m: float = CONNECT_TOL_M,
                     trim_factor: float = TRIM_FACTOR, hal_min_m: float | None = None) -> tuple[dict, list[dict]]:  # fmt: skip
    """Geo-objects of the tolled roads, each built in its own metric frame (:func:`tollcli.spatial.local_frame`).

    Roads that cross a tolled one without meeting it (another level, or no shared node) do not bound its HAL:
    the tolled centre line is cut back within ``trim_factor`` · HAL of them, so no position on the crossing road can
    count for it; the crossing road ids and the length cut are recorded per geo-object (``crossings``, ``cut_m``).
    With ``hal_min_m`` (networks built from a map), a road that would push HAL below it is cut around the same way,
    and a tolled road left with nothing to charge is skipped — returned as ``{"id", "reason"}`` — instead of an error.
    """
    props, lines = roads.props, roads.lines
    tolled = np.array([p.get("tolled", True) is not False for p in props])
    if not tolled.any():
        raise DataError(f"{path}: no tolled road (every feature has tolled: false)")
    lines = np.asarray(lines, dtype=object)
    centre_lon = shapely.get_coordinates(shapely.centroid(lines))[:, 0]
    frames = np.array([local_frame(lon) for lon in centre_lon], dtype=object)
    levels = np.array([road_level(p) for p in props])
    features: dict[int, dict] = {}
    skipped: list[dict] = []
    for frame in sorted(set(frames[tolled])):
        group = np.flatnonzero(tolled & (frames == frame))
        built, gone = _build_in_frame(group, frame, roads, lines, levels, path, hal_max_m, connect_tol_m, trim_factor, hal_min_m)
        features.update(built)
        skipped += gone
    order = sorted(features)
    return {"type": "FeatureCollection", "features": [features[i] for i in order]}, sorted(skipped, key=lambda s: s["id"])


#: buffered geo-objects are densified to this vertex spacing (m) before going back to longitude/latitude, so that
#: a straight edge in the metric frame stays within a millimetre of the edge between its vertices in any frame
SEGMENT_M = 100.0


def _build_in_frame(group, frame, roads, lines, levels, path, hal_max_m, connect_tol_m, trim_factor, hal_min_m):
    ids, props = roads.ids, roads.props
    metric = project(lines, frame)
    tree = shapely.STRtree(metric)
    left, right = tree.query(metric[group], predicate="dwithin", distance=2 * hal_max_m)
    left = group[left]
    other = left != right
    left, right = left[other], right[other]
    dist = shapely.distance(metric[left], metric[right])
    if roads.junctions is None:
        meets = (dist <= connect_tol_m) & (levels[left] == levels[right])
    else:
        meets = np.array([(a, b) in roads.junctions or (b, a) in roads.junctions for a, b in zip(left.tolist(), right.tolist())], bool)
    cut_within = connect_tol_m if hal_min_m is None else max(connect_tol_m, 2 * hal_min_m)
    opposite = opposite_pairs(left, right, metric, props, meets)  # carriageways of one road: told apart by direction
    crossing = ~meets & ~opposite & (dist <= cut_within)
    bounding = ~meets & ~crossing & ~opposite
    own = np.array([float(p["hal_m"]) if p.get("hal_m") not in (None, "") else np.inf for p in props])
    hal = np.minimum(np.full(len(metric), hal_max_m), own)
    np.minimum.at(hal, left[bounding], dist[bounding] / 2.0)
    built, skipped = {}, []
    for i in group:
        line = metric[i]
        touching = right[(left == i) & meets]
        crossers = right[(left == i) & crossing]
        why = ""
        if hal_min_m is not None and hal[i] < hal_min_m:
            why = f"HAL {hal[i]:.1f} m below the minimum {hal_min_m:g} m (another road {2 * hal[i]:.1f} m away)"
        core, cut_m = line, 0.0
        if not why and touching.size:  # the roads it meets: cut within trim·HAL of them (at a right angle: the end)
            core = shapely.difference(line, shapely.buffer(shapely.union_all(metric[touching]), trim_factor * hal[i], quad_segs=16))
            if core.is_empty or core.length < 1.0:
                why = f"too short ({line.length:.1f} m) to trim {trim_factor:g} × HAL {hal[i]:.1f} m at its junctions"
        if not why and crossers.size:  # the roads it crosses without meeting: cut around them the same way
            kept = shapely.difference(core, shapely.buffer(shapely.union_all(metric[crossers]), trim_factor * hal[i], quad_segs=16))
            cut_m = core.length - kept.length
            core = kept
            if core.is_empty or core.length < 1.0:
                why = f"nothing left after cutting {cut_m:.1f} m around the roads crossing it ({', '.join(sorted(ids[j] for j in crossers))})"
        if why:
            if hal_min_m is None:
                raise DataError(f"{path}: feature {ids[i]}: {why}")
            skipped.append({"id": ids[i], "reason": why})
            continue
        polygon = shapely.segmentize(shapely.buffer(core, hal[i], quad_segs=16), SEGMENT_M)
        properties = {
            "id": ids[i], "name": props[i].get("name", ""), "road_class": props[i].get("road_class", ""),
            "direction": props[i].get("direction"), "hal_m": round(float(hal[i]), 3), "crs_metric": frame,
            "length_m": round(core.length, 1), "section_length_m": round(line.length, 1),
        }  # fmt: skip
        if crossers.size:
            properties.update(crossings=sorted(ids[j] for j in crossers), cut_m=round(cut_m, 1))
        partners = right[(left == i) & opposite]
        if partners.size:  # a carriageway: its positions count only in its direction of travel, along this axis
            axis = shapely.get_coordinates(project([line], frame, inverse=True)[0])
            properties.update(opposite=sorted(ids[j] for j in partners), axis=np.round(axis, 7).tolist())
        for key in PASSED_THROUGH:
            if props[i].get(key) not in (None, ""):
                properties[key] = props[i][key]
        built[int(i)] = {"type": "Feature", "properties": properties,
                         "geometry": shapely.geometry.mapping(project([polygon], frame, inverse=True)[0])}  # fmt: skip
    return built, skipped


#: road properties a geo-object keeps (OpenStreetMap ways, reference, travel direction, tunnel flag)
PASSED_THROUGH = ("osm_way_ids", "ref", "oneway", "tunnel", "tunnel_m", "maxspeed")


def _crs_problem(crs, seen: dict) -> str:
    """Why a feature's ``crs_metric`` cannot be used ('' when absent or a known projected CRS in metres)."""
    if crs is None:
        return ""
    if crs not in seen:
        from pyproj import CRS
        from pyproj.exceptions import CRSError

        try:
            parsed = CRS.from_user_input(crs)
            metres = parsed.is_projected and all(a.unit_name in ("metre", "meter") for a in parsed.axis_info)
            seen[crs] = "" if metres else f"crs_metric {crs!r} is not a projected CRS in metres"
        except (CRSError, TypeError, ValueError):
            seen[crs] = f"crs_metric {crs!r} is not a known coordinate reference system"
    return seen[crs]


def check_geoobjects(path: str, hal_min_m: float = 5.0) -> list[Finding]:
    """Problems of a geo-object file, each tied to a feature id (empty list: the file is usable)."""
    findings: list[Finding] = []
    crs_seen: dict = {}
    features = read_features(path)
    ids: list[str] = []
    partners: dict[str, set] = {}
    polys = []
    for i, feature in enumerate(features):
        fid = _feature_id(feature, i)
        props = feature.get("properties") if isinstance(feature, dict) and isinstance(feature.get("properties"), dict) else {}
        if fid.startswith("#"):
            findings.append(Finding(fid, "missing id"))
        if fid in ids:
            findings.append(Finding(fid, "duplicate id"))
        ids.append(fid)
        geom, why = feature_geometry(feature)
        if geom is None:
            findings.append(Finding(fid, why))
            polys.append(None)
            continue
        if geom.is_empty or geom.geom_type not in ("Polygon", "MultiPolygon"):
            findings.append(Finding(fid, f"geometry must be a non-empty Polygon, got {geom.geom_type}{' (empty)' if geom.is_empty else ''}"))
            polys.append(None)
            continue
        bounds = np.asarray(geom.bounds)
        if (np.abs(bounds[[0, 2]]) > 180).any() or (np.abs(bounds[[1, 3]]) > 90).any():
            findings.append(Finding(fid, "coordinates are not WGS-84 longitude/latitude (wrong CRS?)"))
            polys.append(None)
            continue
        if not geom.is_valid:
            findings.append(Finding(fid, f"invalid geometry: {shapely.is_valid_reason(geom)}"))
        partners[fid] = set(map(str, props.get("opposite") or ()))
        if "axis" in props and not _is_axis(props["axis"]):
            findings.append(Finding(fid, "axis must be a list of ≥ 2 [longitude, latitude] points (the direction of travel)"))
        crs_problem = _crs_problem(props.get("crs_metric"), crs_seen)
        if crs_problem:
            findings.append(Finding(fid, crs_problem))
        hal = props.get("hal_m")
        try:
            hal_value = float(hal)
        except (TypeError, ValueError):
            findings.append(Finding(fid, f"hal_m missing or not a number ({hal!r})"))
        else:
            if not hal_value >= hal_min_m:
                findings.append(Finding(fid, f"hal_m {hal_value:g} m below the minimum {hal_min_m:g} m"))
        polys.append(geom if geom.is_valid else None)
    usable = [(fid, p) for fid, p in zip(ids, polys) if p is not None]
    if len(usable) > 1:
        crs = metric_crs([p for _, p in usable])
        metric = project([p for _, p in usable], crs)
        a, b = shapely.STRtree(metric).query(metric, predicate="intersects")
        for i, j in zip(a, b):
            if i < j and usable[j][0] not in partners.get(usable[i][0], ()):  # opposite carriageways may overlap
                area = shapely.intersection(metric[i], metric[j]).area
                if area > 1.0:
                    findings.append(Finding(usable[i][0], f"overlaps {usable[j][0]} ({area:.0f} m²)"))
    return findings


def _is_axis(value) -> bool:
    try:
        xy = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return False
    return xy.ndim == 2 and xy.shape[0] >= 2 and xy.shape[1] == 2 and bool(np.isfinite(xy).all()) \
        and bool((np.abs(xy[:, 0]) <= 180).all() and (np.abs(xy[:, 1]) <= 90).all())
